"""Geometry of a discrete rod: edges, tangents, curvature binormals, frames and reference twist.

Everything here is a small numba kernel on flat float64 arrays. Conventions (see DESIGN.md):

* the state vector ``q`` interleaves node positions and edge angles: node ``k`` owns ``q[4k:4k+3]``,
  edge ``j`` (from node ``j`` to node ``j+1``, wrapping on a ring) owns ``q[4j+3]`` = theta_j;
* each edge carries a reference frame ``(d1, d2 = t x d1)`` moved by parallel transport in time, and a
  material frame ``m1 = cos(theta) d1 + sin(theta) d2``, ``m2 = -sin(theta) d1 + cos(theta) d2``;
* a vertex joins an edge ``e`` (before) and an edge ``f`` (after); its reference twist is the signed angle,
  about ``t_f``, from ``d1_e`` parallel-transported onto ``t_f`` to ``d1_f``. It is stored unwrapped
  (continuous in time), which is what carries the holonomy and the linking number of a closed ring.

All angles are in radians, right-handed.
"""
import numpy as np
from numba import njit

from .stencils import two_sum, vangle, vcross, vdot, vec, vnorm, vscale, vsub, vtransport

# ---------------------------------------------------------------------------------------------
# small vector helpers (3-vectors as length-3 arrays)
# ---------------------------------------------------------------------------------------------


@njit(cache=True, inline="always")
def dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, inline="always")
def cross3(a, b):
    out = np.empty(3)
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out


@njit(cache=True, inline="always")
def norm3(a):
    return np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@njit(cache=True)
def parallel_transport(u, t1, t2):
    """Rotate ``u`` by the smallest rotation taking unit vector ``t1`` onto unit vector ``t2``.

    Rodrigues' formula with axis ``b = t1 x t2``: ``u c + b x u + b (b.u) / (1 + c)``, ``c = t1.t2``.
    Undefined for antiparallel tangents (c = -1); callers must never ask for that (an edge that
    reverses in one step is a failed step).
    """
    b = cross3(t1, t2)
    c = dot3(t1, t2)
    bxu = cross3(b, u)
    s = dot3(b, u) / (1.0 + c)
    out = np.empty(3)
    for k in range(3):
        out[k] = u[k] * c + bxu[k] + b[k] * s
    return out


@njit(cache=True)
def signed_angle(u, v, axis):
    """Signed angle from ``u`` to ``v`` about unit ``axis`` (right-handed), in (-pi, pi]."""
    w = cross3(u, v)
    return np.arctan2(dot3(w, axis), dot3(u, v))


@njit(cache=True)
def wrap_to_pi(a):
    """Map an angle to (-pi, pi]."""
    return a - 2.0 * np.pi * np.floor((a + np.pi) / (2.0 * np.pi))


# ---------------------------------------------------------------------------------------------
# per-edge and per-vertex geometry
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def edge_vector(q, edge_nodes, j):
    a = 4 * edge_nodes[j, 0]
    b = 4 * edge_nodes[j, 1]
    e = np.empty(3)
    for k in range(3):
        e[k] = q[b + k] - q[a + k]
    return e


@njit(cache=True)
def edge_array(q, edge_nodes, q_lo=None, lo=False):
    """Edge vectors ``e_j = x_b - x_a`` of all edges, shape (n_edges, 3): the one place where the solvers form
    edges from positions (every kernel that needs edges takes this array).

    Positions are ``x = q + q_lo`` with the optional ``q_lo`` (n_dof,) the low parts of a compensated pair
    (``RodState.q_lo``, |q_lo| <= ulp(q) / 2): ``e = (q_b - q_a) + (lo_b - lo_a)``. The difference of the high
    parts of neighbouring nodes is exact or rounded relative to the edge itself, so an edge carries the rounding
    of its own length (eps |e|) rather than that of the coordinates (eps |x|, issue 17): a rod far from the origin,
    or long against its edges, keeps the relative accuracy of its deformation.

    With ``lo`` the array has 6 columns: the same rounded edge (bitwise) and, in columns 3-5, its low part, the
    exact ``(q_b - q_a) + (lo_b - lo_a)`` minus the rounded edge (TwoSum): what the kernels need to form the
    curvature and the elongation without cancellation (``stencils.curvature_binormal_of``,
    ``stencils.elongation``). Every kernel reads columns 0-2 as the edge."""
    return edge_array_into(q, edge_nodes, q_lo, lo, np.empty((edge_nodes.shape[0], 6 if lo else 3)))


@njit(cache=True)
def edge_array_into(q, edge_nodes, q_lo, lo, out):
    """``edge_array`` written into ``out`` (n_edges, 3 or more columns; with ``lo`` at least 6), returned: a
    solver's work array reused across evaluations instead of a fresh one per call (issue 17). Columns beyond
    those ``edge_array`` fills are left as they are."""
    n = edge_nodes.shape[0]
    for j in range(n):
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        for k in range(3):
            if q_lo is None:
                out[j, k] = q[b + k] - q[a + k]
                if lo:
                    out[j, k], out[j, 3 + k] = two_sum(q[b + k], -q[a + k])
            else:
                hi, err = two_sum(q[b + k], -q[a + k])
                d = q_lo[b + k] - q_lo[a + k]
                out[j, k] = hi + d       # = (q_b - q_a) + (lo_b - lo_a), as without ``lo``
                if lo:
                    s, err2 = two_sum(hi, d)
                    out[j, 3 + k] = err2 + err
    return out


@njit(cache=True)
def add_compensated_one(q, q_lo, i, s):
    """``(q[i], q_lo[i]) += s`` as a compensated pair (one coordinate of ``add_compensated``): the step kept to
    the rounding of the low part, for kernels that move coordinates one at a time (the explicit solver)."""
    hi = q[i] + s
    bb = hi - q[i]
    err = (q[i] - (hi - bb)) + (s - bb)
    lo = q_lo[i] + err
    h2 = hi + lo
    q_lo[i] = lo - (h2 - hi)
    q[i] = h2


@njit(cache=True)
def add_compensated(q, q_lo, a, delta, out, out_lo):
    """``(out, out_lo) <- (q, q_lo) + a delta`` as compensated pairs (TwoSum, then renormalised so that
    |out_lo| <= ulp(out) / 2): the step is added to the position without losing the part of it below the
    rounding of the coordinate. ``out`` may be ``q`` (and ``out_lo`` ``q_lo``)."""
    for i in range(q.shape[0]):
        out[i] = q[i]
        out_lo[i] = q_lo[i]
        add_compensated_one(out, out_lo, i, a * delta[i])




@njit(cache=True)
def tangents(q, edge_nodes):
    """Unit tangents of all edges, shape (n_edges, 3)."""
    n = edge_nodes.shape[0]
    t = np.empty((n, 3))
    for j in range(n):   # tuples, not edge_vector's arrays: no allocation per edge
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        e = (q[b] - q[a], q[b + 1] - q[a + 1], q[b + 2] - q[a + 2])
        le = vnorm(e)
        for k in range(3):
            t[j, k] = e[k] / le
    return t


@njit(cache=True)
def edge_lengths(q, edge_nodes):
    n = edge_nodes.shape[0]
    out = np.empty(n)
    for j in range(n):
        out[j] = norm3(edge_vector(q, edge_nodes, j))
    return out


@njit(cache=True)
def curvature_binormal(te, tf):
    """Discrete curvature binormal ``kb = 2 te x tf / (1 + te.tf)`` (|kb| = 2 tan(phi/2), phi the turning angle)."""
    return 2.0 * cross3(te, tf) / (1.0 + dot3(te, tf))


@njit(cache=True)
def curvature_binormals(t, vertex_edges):
    nv = vertex_edges.shape[0]
    kb = np.empty((nv, 3))
    for v in range(nv):   # curvature_binormal on tuples (same operations, no allocation)
        te = vec(t, vertex_edges[v, 0])
        tf = vec(t, vertex_edges[v, 1])
        c = vcross(te, tf)
        den = 1.0 + vdot(te, tf)
        for k in range(3):
            kb[v, k] = 2.0 * c[k] / den
    return kb


@njit(cache=True)
def material_frames(q, t, d1):
    """Material directors (m1, m2) of all edges from theta = q[4j+3] and reference director d1."""
    n = d1.shape[0]
    m1 = np.empty((n, 3))
    m2 = np.empty((n, 3))
    for j in range(n):
        d2 = cross3(t[j], d1[j])
        c = np.cos(q[4 * j + 3])
        s = np.sin(q[4 * j + 3])
        for k in range(3):
            m1[j, k] = c * d1[j, k] + s * d2[k]
            m2[j, k] = -s * d1[j, k] + c * d2[k]
    return m1, m2


@njit(cache=True)
def edge_frames(q, edge_nodes, d1, E=None, out=None):
    """Per-edge data shared by the bending and twisting kernels, shape (n_edges, 16):
    ``[t (3), |e|, m1 (3), m2 (3), e (3), e_lo (3)]`` -- one pass, one sine and cosine per edge. The edges are
    ``E`` (``edge_array``) when given, else formed from ``q`` (with their low parts, as ``edge_array(q, ...,
    lo=True)``); ``e_lo`` is the low part of the edge (columns 3-5 of a 6-column ``E``, else 0), from which the
    kernels form the curvature binormal without cancellation (``stencils.curvature_binormal_of``). The angles
    theta always come from ``q``. ``out``: a (n_edges, 16) work array to fill and return (a solver's, reused
    across evaluations), else a new one."""
    n = edge_nodes.shape[0]
    if out is None:
        out = np.empty((n, 16))
    Ee = edge_array(q, edge_nodes, None, True) if E is None else E
    for j in range(n):
        e0 = Ee[j, 0]
        e1 = Ee[j, 1]
        e2 = Ee[j, 2]
        for k in range(3):
            out[j, 10 + k] = Ee[j, k]
            out[j, 13 + k] = Ee[j, 3 + k] if Ee.shape[1] >= 6 else 0.0
        le = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        t0, t1, t2 = e0 / le, e1 / le, e2 / le
        p0, p1, p2 = d1[j, 0], d1[j, 1], d1[j, 2]
        # d2 = t x d1
        r0 = t1 * p2 - t2 * p1
        r1 = t2 * p0 - t0 * p2
        r2 = t0 * p1 - t1 * p0
        c = np.cos(q[4 * j + 3])
        s = np.sin(q[4 * j + 3])
        out[j, 0] = t0
        out[j, 1] = t1
        out[j, 2] = t2
        out[j, 3] = le
        out[j, 4] = c * p0 + s * r0
        out[j, 5] = c * p1 + s * r1
        out[j, 6] = c * p2 + s * r2
        out[j, 7] = -s * p0 + c * r0
        out[j, 8] = -s * p1 + c * r1
        out[j, 9] = -s * p2 + c * r2
    return out


@njit(cache=True)
def reference_twist_angle(te, d1e, tf, d1f):
    """Signed angle about tf from d1e (transported from te to tf) to d1f, in (-pi, pi]."""
    return signed_angle(parallel_transport(d1e, te, tf), d1f, tf)


@njit(cache=True)
def reference_twists(t, d1, vertex_edges):
    """``reference_twist_angle`` of every vertex (edges e, f = vertex_edges[v]), in one pass; shape (n_vertices,)."""
    nv = vertex_edges.shape[0]
    out = np.empty(nv)
    for v in range(nv):
        a = vertex_edges[v, 0]
        b = vertex_edges[v, 1]
        tb = vec(t, b)   # reference_twist_angle on tuples (same operations, no allocation)
        out[v] = vangle(vtransport(vec(d1, a), vec(t, a), tb), vec(d1, b), tb)
    return out


@njit(cache=True)
def transport_frames(q, edge_nodes, vertex_edges, t_old, d1_old, twist_old, t_new, d1_new, twist_new, E=None):
    """Move the reference frames from the tangents ``t_old`` to the tangents of ``q`` (parallel transport in time);
    the edges are ``E`` (``edge_array``) when given, else formed from ``q``.

    Writes the new tangents, reference directors and reference twist (kept continuous with ``twist_old``:
    the change is taken in (-pi, pi], so that 2 pi windings and ring holonomy are never lost).
    Returns False if an edge reversed or vanished (a failed step), True otherwise.
    """
    n = edge_nodes.shape[0]
    for j in range(n):
        if E is None:
            a = 4 * edge_nodes[j, 0]
            b = 4 * edge_nodes[j, 1]
            e = (q[b] - q[a], q[b + 1] - q[a + 1], q[b + 2] - q[a + 2])
        else:
            e = (E[j, 0], E[j, 1], E[j, 2])
        le = vnorm(e)
        if not (le > 0.0) or not np.isfinite(le):
            return False
        tj = vscale(1.0 / le, e)
        to = vec(t_old, j)
        if 1.0 + vdot(to, tj) < 1e-12:
            return False
        d = vtransport(vec(d1_old, j), to, tj)
        # re-orthonormalise against round-off drift
        d = vsub(d, vscale(vdot(d, tj), tj))
        d = vscale(1.0 / vnorm(d), d)
        for k in range(3):
            t_new[j, k] = tj[k]
            d1_new[j, k] = d[k]
    for v in range(vertex_edges.shape[0]):
        a = vertex_edges[v, 0]
        b = vertex_edges[v, 1]
        tb = vec(t_new, b)
        ang = vangle(vtransport(vec(d1_new, a), vec(t_new, a), tb), vec(d1_new, b), tb)
        twist_new[v] = twist_old[v] + wrap_to_pi(ang - twist_old[v])
    return True


@njit(cache=True)
def frenet_directors(t, kb, vertex_edges, n_edges, min_kb):
    """Discrete Frenet normal per edge from the curvature binormals of the vertices around it.

    The binormal of an edge is the average of the curvature binormals at its two vertices, projected normal to
    the edge; at the end edge of an open rod (one vertex) it is extrapolated linearly from the two nearest
    vertices, ``1.5 kb_1 - 0.5 kb_2``, so that it is second-order accurate at the edge midpoint there too. The
    normal is ``n = b x t``. Returns ``(n, defined)``; ``defined[j]`` is False where the binormal (per vertex)
    is shorter than ``min_kb``: the Frenet frame is undefined there, e.g. on a straight stretch.
    """
    nv = vertex_edges.shape[0]
    acc = np.zeros((n_edges, 3))
    count = np.zeros(n_edges)
    for v in range(nv):
        for side in range(2):
            j = vertex_edges[v, side]
            count[j] += 1.0
            for k in range(3):
                acc[j, k] += kb[v, k]
    # open rod: vertex 0 is the only one on edge 0, vertex nv-1 the only one on the last edge
    if nv >= 2 and count[vertex_edges[0, 0]] == 1.0 and count[vertex_edges[nv - 1, 1]] == 1.0:
        j0 = vertex_edges[0, 0]
        j1 = vertex_edges[nv - 1, 1]
        for k in range(3):
            acc[j0, k] = 1.5 * kb[0, k] - 0.5 * kb[1, k]
            acc[j1, k] = 1.5 * kb[nv - 1, k] - 0.5 * kb[nv - 2, k]
    nrm = np.zeros((n_edges, 3))
    defined = np.zeros(n_edges, dtype=np.bool_)
    for j in range(n_edges):   # on tuples: the same operations without an allocation per edge
        tj = vec(t, j)
        b = vec(acc, j)
        s = vdot(b, tj)
        b = (b[0] - s * tj[0], b[1] - s * tj[1], b[2] - s * tj[2])
        lb = vnorm(b) / max(count[j], 1.0)
        if lb > min_kb:
            nb = vnorm(b)
            b = (b[0] / nb, b[1] / nb, b[2] / nb)
            c = vcross(b, tj)
            for k in range(3):
                nrm[j, k] = c[k]
            defined[j] = True
    return nrm, defined


@njit(cache=True)
def add_transport_jacobian(q, edge_nodes, dE_dtheta, ab, kl, ku, perm, E=None):
    """Add the frame-transport part of the force Jacobian (non-symmetric) to the band matrix ``ab``.

    The reference frames move by parallel transport *in time*, so the angles theta are coordinates of a chart
    that is re-based at every step. Differentiating the elastic force in that chart gives the symmetric Hessian
    of the energy plus, for every edge whose twisting moment ``dE/dtheta_j`` is not zero, the skew term
    ``dE/dtheta_j / (2 |e_j|^2) [t_j]_x`` on the edge vector (the holonomy of parallel transport). It vanishes
    where the theta equations balance without external twisting moments, and is what makes a follower
    twisting moment a circulatory load.
    """
    for j in range(edge_nodes.shape[0]):
        g = dE_dtheta[j]
        if g == 0.0:
            continue
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        if E is None:
            e0 = q[b] - q[a]
            e1 = q[b + 1] - q[a + 1]
            e2 = q[b + 2] - q[a + 2]
        else:
            e0 = E[j, 0]
            e1 = E[j, 1]
            e2 = E[j, 2]
        transport_jacobian_edge(ab, kl + ku, perm, a, b, g, e0, e1, e2)


@njit(cache=True, inline="always")
def transport_jacobian_edge(ab, off, perm, a, b, g, e0, e1, e2):
    """``add_transport_jacobian`` of one edge (its first DOFs ``a``, ``b``, its vector ``e``, its twisting moment
    ``g``): the 3x3 block C = c [e]_x, c = g / (2 |e|^3), with signs (+, -, -, +) on (a, a), (a, b), (b, a), (b, b),
    its 6 non-zeros written straight into the band (issue 17: the dense 6 x 6 scatter through the permutation, zero
    diagonals included, cost as much as the assembly's own scatter; bitwise the same band up to the sign of a zero).
    The assembly of all three terms adds it inside its vertex pass (``energies.vertex``)."""
    le = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    c = 0.5 * g / (le * le * le)   # [t]_x / |e|^2 = [e]_x / |e|^3
    _transport_entries(ab, off, perm[a], perm[a + 1], perm[a + 2], perm[b], perm[b + 1], perm[b + 2],
                       (0.0, -c * e2, c * e1, c * e2, 0.0, -c * e0, -c * e1, c * e0, 0.0))


@njit(cache=True, inline="always")
def _transport_entries(ab, off, pa0, pa1, pa2, pb0, pb1, pb2, C):
    """ab += [[C, -C], [-C, C]] at band positions (pa0, pa1, pa2, pb0, pb1, pb2), C's off-diagonal entries only
    (C = c [e]_x, row-major 9-tuple), column by column in the order of the dense scatter."""
    pa = (pa0, pa1, pa2)
    pb = (pb0, pb1, pb2)
    for s in range(3):
        ja = pa[s]
        for r in range(3):
            if r != s:
                h = C[3 * r + s]
                ab[np.uint64(off + pa[r] - ja), np.uint64(ja)] += h
                ab[np.uint64(off + pb[r] - ja), np.uint64(ja)] += -h
    for s in range(3):
        jb = pb[s]
        for r in range(3):
            if r != s:
                h = C[3 * r + s]
                ab[np.uint64(off + pa[r] - jb), np.uint64(jb)] += -h
                ab[np.uint64(off + pb[r] - jb), np.uint64(jb)] += h


@njit(cache=True)
def rod_topology(n_edges, closed):
    """``(edge_nodes, vertex_nodes, vertex_edges)`` (int64) of an open rod or a ring with ``n_edges`` edges, in one
    pass (``rod.topology``; bitwise the NumPy construction it replaced, ``tests/test_setup.py``)."""
    n_nodes = n_edges if closed else n_edges + 1
    nv = n_edges if closed else n_edges - 1
    edge_nodes = np.empty((n_edges, 2), dtype=np.int64)
    for j in range(n_edges):
        edge_nodes[j, 0] = j
        edge_nodes[j, 1] = (j + 1) % n_nodes
    vertex_nodes = np.empty((nv, 3), dtype=np.int64)
    vertex_edges = np.empty((nv, 2), dtype=np.int64)
    for i in range(nv):
        v = i if closed else i + 1          # a ring's vertex v sits at node v, an open rod's at nodes 1..n-1
        vertex_nodes[i, 0] = (v - 1) % n_nodes
        vertex_nodes[i, 1] = v
        vertex_nodes[i, 2] = (v + 1) % n_nodes
        vertex_edges[i, 0] = (v - 1) % n_edges
        vertex_edges[i, 1] = v
    return edge_nodes, vertex_nodes, vertex_edges


@njit(cache=True, error_model="numpy")   # a coincident pair of nodes gives a nan tangent, refused by the caller
def shape_edges(x, edge_nodes, vertex_edges):
    """The edges of a shape's node positions ``x`` (n_nodes, 3), in one pass, for ``rod_from_shape``:
    ``(le, t, finite, scale, j_min, v_min, cos_min)`` -- edge lengths ``|e|``, unit tangents ``e / |e|`` (the same
    operations, bitwise, as ``np.linalg.norm(e, axis=1)`` and ``e / le[:, None]``), whether every coordinate is
    finite, ``max(max |x|, max |e|)``, the shortest edge (first index), and the vertex with the smallest cosine
    of its turning angle ``t_e . t_f`` with that cosine (the checks for coincident nodes and folds). With a
    non-finite coordinate only ``finite`` (False) is meaningful."""
    n = edge_nodes.shape[0]
    le = np.empty(n)
    t = np.empty((n, 3))
    finite = True
    xmax = 0.0
    for i in range(x.shape[0]):
        for k in range(3):
            a = abs(x[i, k])
            if not a < np.inf:
                finite = False
            if a > xmax:
                xmax = a
    if not finite:
        return le, t, False, np.nan, 0, -1, np.nan
    lmax = 0.0
    j_min = 0
    for j in range(n):
        a = edge_nodes[j, 0]
        b = edge_nodes[j, 1]
        e0 = x[b, 0] - x[a, 0]
        e1 = x[b, 1] - x[a, 1]
        e2 = x[b, 2] - x[a, 2]
        lj = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        le[j] = lj
        t[j, 0] = e0 / lj
        t[j, 1] = e1 / lj
        t[j, 2] = e2 / lj
        if lj > lmax:
            lmax = lj
        if lj < le[j_min]:
            j_min = j
    v_min = -1
    cos_min = np.inf
    for v in range(vertex_edges.shape[0]):
        e = vertex_edges[v, 0]
        f = vertex_edges[v, 1]
        c = t[e, 0] * t[f, 0] + t[e, 1] * t[f, 1] + t[e, 2] * t[f, 2]
        if c < cos_min:
            cos_min = c
            v_min = v
    return le, t, True, max(xmax, lmax), j_min, v_min, cos_min
