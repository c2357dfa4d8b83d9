"""Allocation-free helpers shared by the energy kernels.

3-vectors are numba tuples ``(x, y, z)`` so that the per-stencil algebra stays in registers; local
Hessians are written into small preallocated buffers. A vertex stencil has 11 degrees of freedom,
ordered as in the global state vector: ``[x0 (3), theta_e, x1 (3), theta_f, x2 (3)]``. The kernels
differentiate with respect to 8 local variables ``[e (3), f (3), theta_e, theta_f]`` with
``e = x1 - x0`` and ``f = x2 - x1``; ``expand_vertex`` maps those derivatives to the 11 DOFs.
"""
import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def vec(a, i):
    return (a[i, 0], a[i, 1], a[i, 2])


@njit(cache=True, inline="always")
def vsub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(cache=True, inline="always")
def vadd(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@njit(cache=True, inline="always")
def vscale(s, a):
    return (s * a[0], s * a[1], s * a[2])


@njit(cache=True, inline="always")
def vdot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, inline="always")
def vcross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True, inline="always")
def vnorm(a):
    return np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@njit(cache=True, inline="always")
def vtransport(u, t1, t2):
    """Parallel transport of u from unit t1 to unit t2 (tuples; see geometry.parallel_transport)."""
    b = vcross(t1, t2)
    c = vdot(t1, t2)
    bxu = vcross(b, u)
    s = vdot(b, u) / (1.0 + c)
    return (u[0] * c + bxu[0] + b[0] * s, u[1] * c + bxu[1] + b[1] * s, u[2] * c + bxu[2] + b[2] * s)


@njit(cache=True, inline="always")
def vangle(u, v, axis):
    """Signed angle from u to v about unit axis (tuples), in (-pi, pi]."""
    return np.arctan2(vdot(vcross(u, v), axis), vdot(u, v))


@njit(cache=True, inline="always")
def node(q, k):
    return (q[4 * k], q[4 * k + 1], q[4 * k + 2])


@njit(cache=True, inline="always")
def material(d1, t, theta):
    """(m1, m2) from reference director d1, tangent t and angle theta."""
    d2 = vcross(t, d1)
    c = np.cos(theta)
    s = np.sin(theta)
    m1 = (c * d1[0] + s * d2[0], c * d1[1] + s * d2[1], c * d1[2] + s * d2[2])
    m2 = (-s * d1[0] + c * d2[0], -s * d1[1] + c * d2[1], -s * d1[2] + c * d2[2])
    return m1, m2


# --- writing 3x3 blocks into a local matrix ----------------------------------------------------


@njit(cache=True, inline="always")
def add_outer(H, r, c, s, a, b):
    """H[r:r+3, c:c+3] += s * a b^T"""
    for i in range(3):
        for j in range(3):
            H[r + i, c + j] += s * a[i] * b[j]


@njit(cache=True, inline="always")
def add_sym_outer(H, r, c, s, a, b):
    """H[r:r+3, c:c+3] += s * (a b^T + b a^T)"""
    for i in range(3):
        for j in range(3):
            H[r + i, c + j] += s * (a[i] * b[j] + b[i] * a[j])


@njit(cache=True, inline="always")
def add_identity(H, r, c, s):
    for i in range(3):
        H[r + i, c + i] += s


@njit(cache=True, inline="always")
def add_cross_matrix(H, r, c, s, a):
    """H[r:r+3, c:c+3] += s * [a]_x, where [a]_x b = a x b."""
    H[r + 0, c + 1] -= s * a[2]
    H[r + 0, c + 2] += s * a[1]
    H[r + 1, c + 0] += s * a[2]
    H[r + 1, c + 2] -= s * a[0]
    H[r + 2, c + 0] -= s * a[1]
    H[r + 2, c + 1] += s * a[0]


@njit(cache=True, inline="always")
def add_column(H, r, c, s, a):
    """H[r:r+3, c] += s * a and the symmetric entries H[c, r:r+3]."""
    for i in range(3):
        H[r + i, c] += s * a[i]
        H[c, r + i] += s * a[i]


# --- from (e, f, theta_e, theta_f) to the 11 stencil DOFs --------------------------------------


@njit(cache=True)
def expand_vertex_hessian(H8, H11):
    """H11 = B^T H8 B: the Hessian in (e, f, theta_e, theta_f) mapped to the 11 stencil DOFs, block by block
    (x0 -> -e, x1 -> e - f, x2 -> f)."""
    for i in range(3):
        for j in range(3):
            ee = H8[i, j]
            ef = H8[i, 3 + j]
            fe = H8[3 + i, j]
            ff = H8[3 + i, 3 + j]
            H11[i, j] = ee                              # x0 x0
            H11[i, 4 + j] = -ee + ef                    # x0 x1
            H11[i, 8 + j] = -ef                         # x0 x2
            H11[4 + i, j] = -ee + fe                    # x1 x0
            H11[4 + i, 4 + j] = ee - ef - fe + ff       # x1 x1
            H11[4 + i, 8 + j] = ef - ff                 # x1 x2
            H11[8 + i, j] = -fe                         # x2 x0
            H11[8 + i, 4 + j] = fe - ff                 # x2 x1
            H11[8 + i, 8 + j] = ff                      # x2 x2
        for c8, c11 in ((6, 3), (7, 7)):
            e_t = H8[i, c8]
            f_t = H8[3 + i, c8]
            H11[i, c11] = -e_t
            H11[4 + i, c11] = e_t - f_t
            H11[8 + i, c11] = f_t
            t_e = H8[c8, i]
            t_f = H8[c8, 3 + i]
            H11[c11, i] = -t_e
            H11[c11, 4 + i] = t_e - t_f
            H11[c11, 8 + i] = t_f
    H11[3, 3] = H8[6, 6]
    H11[3, 7] = H8[6, 7]
    H11[7, 3] = H8[7, 6]
    H11[7, 7] = H8[7, 7]


@njit(cache=True)
def vertex_dofs(vertex_nodes, vertex_edges, v, out):
    """Global DOF indices of the 11 stencil DOFs of vertex v."""
    k0 = vertex_nodes[v, 0]
    k1 = vertex_nodes[v, 1]
    k2 = vertex_nodes[v, 2]
    for i in range(3):
        out[i] = 4 * k0 + i
        out[4 + i] = 4 * k1 + i
        out[8 + i] = 4 * k2 + i
    out[3] = 4 * vertex_edges[v, 0] + 3
    out[7] = 4 * vertex_edges[v, 1] + 3


@njit(cache=True)
def edge_dofs(edge_nodes, j, out):
    """Global DOF indices of the 6 node DOFs of edge j: [x_a (3), x_b (3)]."""
    a = edge_nodes[j, 0]
    b = edge_nodes[j, 1]
    for i in range(3):
        out[i] = 4 * a + i
        out[3 + i] = 4 * b + i


@njit(cache=True, inline="always")
def edge_vectors(ed, j):
    """(t, |e|, m1, m2) of edge j from an ``edge_frames`` array."""
    return ((ed[j, 0], ed[j, 1], ed[j, 2]), ed[j, 3], (ed[j, 4], ed[j, 5], ed[j, 6]),
            (ed[j, 7], ed[j, 8], ed[j, 9]))


# ---- compensated arithmetic (issue 17): the curvature and the elongation without cancellation ----
# An edge is carried as a pair (E, E_lo), the rounded vector and its low part (``geometry.edge_array`` with
# ``lo=True``, ``geometry.edge_frames`` columns 10-15). A quantity that is a small difference of two edge-sized
# numbers -- the turning f - e of two neighbouring edges, the elongation |e| - l -- is formed from both parts
# with error-free transformations, so that it carries the rounding of its own size and not eps |e|.

@njit(cache=True, inline="always")
def two_sum(a, b):
    """(s, err) with s = fl(a + b) and a + b = s + err exactly (Knuth's TwoSum)."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


@njit(cache=True, inline="always")
def _split(a):
    c = 134217729.0 * a          # 2^27 + 1 (Dekker)
    hi = c - (c - a)
    return hi, a - hi


@njit(cache=True, inline="always")
def two_prod(a, b):
    """(p, err) with p = fl(a b) and a b = p + err exactly (Dekker's product, no FMA needed)."""
    p = a * b
    ah, al = _split(a)
    bh, bl = _split(b)
    return p, ((ah * bh - p) + ah * bl + al * bh) + al * bl


@njit(cache=True, inline="always")
def elongation(E, j, l_bar):
    """(g, |e|): the elongation g = |e_j| - l_bar of edge j and its length. With the low parts (``E`` of 6
    columns, ``geometry.edge_array(..., lo=True)``) g = (|e|^2 - l^2) / (|e| + l), the difference of squares
    formed exactly (TwoProd, TwoSum): g then carries the rounding of its own size, not that of |e| (eps |e|, which
    the axial penalty c A1 / h^3 turns into a tension eps c A1 / h^2 and a residual floor growing like n). With 3
    columns the plain |e| - l."""
    e0 = E[j, 0]
    e1 = E[j, 1]
    e2 = E[j, 2]
    le = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    if E.shape[1] < 6:
        return le - l_bar, le
    p0, r0 = two_prod(e0, e0)
    p1, r1 = two_prod(e1, e1)
    p2, r2 = two_prod(e2, e2)
    s, c1 = two_sum(p0, p1)
    s, c2 = two_sum(s, p2)
    ll, rl = two_prod(l_bar, l_bar)
    d, c3 = two_sum(s, -ll)
    lo = (r0 + r1 + r2 + c1 + c2 + c3 - rl) + 2.0 * (e0 * E[j, 3] + e1 * E[j, 4] + e2 * E[j, 5])
    return (d + lo) / (le + l_bar), le


@njit(cache=True, inline="always")
def curvature_binormal_of(ed, je, jf):
    """Curvature binormal ``kb = 2 t_e x t_f / (1 + t_e . t_f)`` of the vertex joining edges ``je`` (e) and ``jf``
    (f), from an ``edge_frames`` array, in the cancellation-free form ``2 e x (f - e) / (|e||f| + e . f)``: the
    turning ``f - e`` is formed from the high and low parts of the two edges (columns 10-15; TwoSum), so kb has
    the relative accuracy of its own size (|kb| ~ h kappa). From unit tangents it carried eps absolute, which a
    bending force A1 / h^2 turns into a residual floor growing like n (issue 17)."""
    d0h, d0l = two_sum(ed[jf, 10], -ed[je, 10])
    d1h, d1l = two_sum(ed[jf, 11], -ed[je, 11])
    d2h, d2l = two_sum(ed[jf, 12], -ed[je, 12])
    d = (d0h + (d0l + (ed[jf, 13] - ed[je, 13])), d1h + (d1l + (ed[jf, 14] - ed[je, 14])),
         d2h + (d2l + (ed[jf, 15] - ed[je, 15])))
    e = (ed[je, 10], ed[je, 11], ed[je, 12])
    f = (ed[jf, 10], ed[jf, 11], ed[jf, 12])
    return vscale(2.0 / (ed[je, 3] * ed[jf, 3] + vdot(e, f)), vcross(e, d))


@njit(cache=True, inline="always")
def scatter_vertex_gradient(grad, k0, k1, k2, ie, jf, g8):
    """Add the local gradient in (e, f, theta_e, theta_f) to the nodes k0, k1, k2 and edges ie, jf
    (e = x1 - x0, f = x2 - x1)."""
    a = 4 * k0
    b = 4 * k1
    c = 4 * k2
    for i in range(3):
        grad[a + i] -= g8[i]
        grad[b + i] += g8[i] - g8[3 + i]
        grad[c + i] += g8[3 + i]
    grad[4 * ie + 3] += g8[6]
    grad[4 * jf + 3] += g8[7]


@njit(cache=True)
def scatter_gradient(g, dofs, local, scale):
    for a in range(dofs.shape[0]):
        g[dofs[a]] += scale * local[a]


@njit(cache=True)
def scatter_band(ab, kl, ku, perm, dofs, H, scale):
    """Add ``scale * H`` at rows/columns ``dofs`` of a LAPACK general-band matrix.

    ``ab[kl + ku + i - j, j] = A[i, j]`` with ``i, j`` the permuted (banded) positions ``perm[dof]``.
    """
    m = dofs.shape[0]
    off = kl + ku
    # column by column: a column of ``ab`` (Fortran order) is contiguous, and the stencil's rows are consecutive
    # positions of it (row by row wrote one entry per column, 2 kl + ku + 1 doubles apart, and the band
    # outgrew the cache at 10^4 nodes)
    base = perm[dofs[0]]
    contiguous = True
    for a in range(1, m):
        if perm[dofs[a]] != base + a:
            contiguous = False
            break
    # The band row off + i - j of every entry is in [0, 2 kl + ku] by construction (the solver's kl, ku cover
    # every stencil: |i - j| <= kl, ku), so the indices are passed unsigned: numba then drops its per-entry test
    # for a negative index (wraparound), which sat in the innermost loop (issue 17; bitwise the same band,
    # tests/test_scale.py).
    if contiguous:
        # an open rod's stencils are consecutive DOFs: a dense block, no index lookups in the inner loop
        for b in range(m):
            r0 = off - b
            j = np.uint64(base + b)
            for a in range(m):
                ab[np.uint64(r0 + a), j] += scale * H[a, b]
        return
    for b in range(m):
        j = perm[dofs[b]]
        col = np.uint64(j)
        for a in range(m):
            i = perm[dofs[a]]
            ab[np.uint64(off + i - j), col] += scale * H[a, b]


@njit(cache=True)
def band_positions(perm, dofs, out):
    """out[a] <- perm[dofs[a]], the banded positions of a stencil's DOFs; returns True when they are consecutive
    (``out[a] = out[0] + a``: an open rod's stencil, a dense block of the band)."""
    m = dofs.shape[0]
    contiguous = True
    for a in range(m):
        out[a] = perm[dofs[a]]
        if out[a] != out[0] + a:
            contiguous = False
    return contiguous


@njit(cache=True)
def scatter_band_symmetric_at(ab, kl, ku, pos, contiguous, H):
    """Add the symmetric matrix whose upper triangle is ``H[a, b]`` (a <= b; the rest of H is not read) at the
    banded positions ``pos`` (``band_positions``): each off-diagonal entry into both triangles of the band."""
    m = pos.shape[0]
    off = kl + ku
    if contiguous:
        base = pos[0]
        for b in range(m):
            jb = np.uint64(base + b)
            for a in range(b):
                h = H[a, b]
                ab[np.uint64(off + a - b), jb] += h
                ab[np.uint64(off + b - a), np.uint64(base + a)] += h
            ab[np.uint64(off), jb] += H[b, b]
        return
    for b in range(m):
        pb = pos[b]
        jb = np.uint64(pb)
        for a in range(b):
            pa = pos[a]
            h = H[a, b]
            ab[np.uint64(off + pa - pb), jb] += h
            ab[np.uint64(off + pb - pa), np.uint64(pa)] += h
        ab[np.uint64(off), jb] += H[b, b]
