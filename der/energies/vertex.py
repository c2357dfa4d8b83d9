"""Bending and twisting of each vertex stencil assembled together (the Newton matrix of a rod with both).

The two energies share the vertex's 11 DOFs: adding their local Hessians before the stencil is expanded and
scattered halves the scattering into the band (issue 17). ``stretch_bend_twist_hessian`` also adds the
stretching of each edge into the stencil of one vertex on it (its 6 DOFs are among the 11), which saves the
edges' own scatter. The math is that of ``energies.bend`` and ``energies.twist``; ``bend_hessian`` followed by
``twist_hessian`` gives the same matrix to round-off (the local sums are added in another order).

The pass of all three terms (the solver's, issue 17) forms the bending and twisting of a vertex in one local
kernel (``_bend_twist_local``: the frames, curvatures and binormal formed once, the gradient bitwise that of the
order-1 pass, the Hessian as its 36 upper entries with every term summed per entry), maps them to the stencil's 66
upper entries and writes each into both triangles of the band; it zeroes each band column just before its first
entry and adds each edge's frame-transport term after the last vertex on it, so the band is read and written once
(measured: ``tools/bench_kernels.py``, README "At scale").
"""
import numpy as np
from numba import njit
# numba's cache keys a kernel on its own file only: this file was edited with the compensated edges of
# issue 17 (geometry.edge_array's low parts, stencils.curvature_binormal_of / elongation) so that its
# kernels are compiled again with them. The same holds for the one-vertex formulas it inlines from bend.py,
# twist.py and stretch.py (``_vertex_curvatures``, ``_bend_gradient_of``, ``_twist_rate_row``,
# ``_stretch_tension``, ...): after editing one of them, edit this file too (or clear the caches).

from ..geometry import edge_array, transport_jacobian_edge
from ..linalg import zero_band_column
from ..stencils import (
    elongation,
    band_positions, expand_vertex_hessian, scatter_band, scatter_band_symmetric_at, scatter_vertex_gradient, vadd,
    vcross, vdot, vertex_dofs, vscale, vsub,
)
from .bend import _bend_gradient_of, _bend_local, _bend_weights_energy, _curvature_residuals, _vertex_curvatures
from .stiffness import bending_at, twisting_at
from .stretch import _stretch_energy_of, _stretch_hessian_entry, _stretch_local, _stretch_tension
from .twist import _material_twist, _twist_local, _twist_rate_row


@njit(cache=True)
def bend_twist_hessian(q, ed, vertex_nodes, vertex_edges, reference_twist, weld, kappa_bar, twist_bar, voronoi, A1,
                       A2, grad, ab, kl, ku, perm):
    """Add the bending and twisting gradients to ``grad`` and their Hessians to the band matrix ``ab``; returns
    ``(bending energy, twisting energy)``. Arguments as for ``bend_hessian`` and ``twist_hessian``."""
    g8 = np.empty(8)
    H8 = np.empty((8, 8))
    H11 = np.empty((11, 11))
    work = np.empty((5, 8))
    dofs = np.empty(11, dtype=np.int64)
    e_bend = 0.0
    e_twist = 0.0
    for v in range(vertex_edges.shape[0]):
        a1, a2 = bending_at(A1, v)
        e_bend += _bend_local(ed, vertex_edges, weld, v, kappa_bar, a1 / voronoi[v], a2 / voronoi[v], 2, g8, H8, work)
        e_twist += _twist_local(q, ed, vertex_edges, reference_twist, weld, v, twist_bar[v],
                                twisting_at(A2, v) / voronoi[v], 2, g8,
                                H8, work, True)   # added onto the bending of the same vertex
        scatter_vertex_gradient(grad, vertex_nodes[v, 0], vertex_nodes[v, 1], vertex_nodes[v, 2],
                                vertex_edges[v, 0], vertex_edges[v, 1], g8)
        expand_vertex_hessian(H8, H11)
        vertex_dofs(vertex_nodes, vertex_edges, v, dofs)
        scatter_band(ab, kl, ku, perm, dofs, H11, 1.0)
    return e_bend, e_twist


@njit(cache=True)
def stretch_bend_twist_hessian(q, ed, edge_nodes, vertex_nodes, vertex_edges, l_bar, k_stretch, lam, reference_twist,
                               weld, kappa_bar, twist_bar, voronoi, A1, A2, grad, ab, kl, ku, perm, E=None,
                               transport=True):
    """``bend_twist_hessian`` plus the stretching of every edge (as ``stretch_hessian``), each edge added into the
    stencil of the first vertex that holds it (its edge after, else before), and with ``transport`` the
    frame-transport term of every edge (``geometry.add_transport_jacobian``; its twisting moment read from
    ``grad``, which must come in zeroed), added after the last vertex on the edge. ``ab`` need not come zeroed:
    each column is zeroed just before its first entry. The local Hessians are formed as their upper triangles and
    written into both triangles of the band (``_bend_twist_local``): the energy part is exactly symmetric. Returns
    ``(stretch, bending, twisting)`` energies. ``E``: the edge vectors (``geometry.edge_array``; formed from ``q``
    if None)."""
    Ee = edge_array(q, edge_nodes) if E is None else E
    # the order as a literal: numba compiles the pass once per order and prunes the other order's branches, so the
    # residual's order-1 pass does not carry the Hessian's code (~15 s more compilation than one version for both
    # orders; their speeds differed by less than this machine's noise in tools/bench_kernels.py, 3-10 %)
    return _stretch_bend_twist(q, ed, edge_nodes, vertex_nodes, vertex_edges, l_bar, k_stretch, lam, reference_twist,
                               weld, kappa_bar, twist_bar, voronoi, A1, A2, grad, ab, kl, ku, perm, Ee, 2,
                               np.empty((0, 3)), np.empty(0), transport)


@njit(cache=True)
def stretch_bend_twist_gradient(q, ed, edge_nodes, vertex_nodes, vertex_edges, l_bar, k_stretch, lam,
                                reference_twist, weld, kappa_bar, twist_bar, voronoi, A1, A2, grad, E=None, F=None,
                                M=None):
    """The gradient and energies of ``stretch_bend_twist_hessian`` without its band: the same pass, the same local
    sums in the same order, so the forces are bitwise those of the assembly (a solver may then evaluate its
    residual first and assemble the band only for a step it takes, issue 17).

    With ``F`` (n_edges, 3) and ``M`` (n_vertices,) also the internal force on every edge and the moment magnitude
    at every vertex, bitwise those of ``diagnostics._edge_forces`` (the solver's load scale) on the same edges:
    that pass's work is then done here."""
    ab = np.empty((0, 0))
    perm = np.empty(0, dtype=np.int64)
    Ee = edge_array(q, edge_nodes) if E is None else E
    if F is None or M is None:
        return _stretch_bend_twist(q, ed, edge_nodes, vertex_nodes, vertex_edges, l_bar, k_stretch, lam,
                                   reference_twist, weld, kappa_bar, twist_bar, voronoi, A1, A2, grad, ab, 0, 0,
                                   perm, Ee, 1, np.empty((0, 3)), np.empty(0), False)
    return _stretch_bend_twist(q, ed, edge_nodes, vertex_nodes, vertex_edges, l_bar, k_stretch, lam, reference_twist,
                               weld, kappa_bar, twist_bar, voronoi, A1, A2, grad, ab, 0, 0, perm, Ee, 1, F, M, False)


@njit(cache=True)
def _stretch_bend_twist(q, ed, edge_nodes, vertex_nodes, vertex_edges, l_bar, k_stretch, lam, reference_twist,
                        weld, kappa_bar, twist_bar, voronoi, A1, A2, grad, ab, kl, ku, perm, E, order, F, M, transport):
    """The pass of ``stretch_bend_twist_hessian`` (order 2) and ``stretch_bend_twist_gradient`` (order 1; with a
    non-empty ``F`` also the edge forces and vertex moments of ``diagnostics._edge_forces``). ``E``: the edge
    vectors (an array: the wrappers form it when they are given None).

    Compiled as a function of its own, called by both wrappers, and so is ``_bend_twist_local``: inlined into
    their callers at numba's level (``inline="always"``), every caller and every call site compiled the whole
    pass again, the order-2 stencil included in the order-1 kernel, and the first run's warm-up took 387 s of
    CPU instead of 218 s (s9-compile, ``python tools/compile_time.py --against a64a219``). One call per
    evaluation and one per vertex cost nothing measurable (``tools/bench_kernels.py``, docs/scaling.md)."""
    Ee = E
    n_edges = edge_nodes.shape[0]
    g8 = np.empty(8)
    H8 = np.empty((8, 8))
    H11 = np.empty((11, 11))
    g6 = np.empty(6)
    H6 = np.empty((6, 6))
    work = np.empty((5, 8))
    dofs = np.empty(11, dtype=np.int64)
    pos = np.empty(11, dtype=np.int64)
    d6 = np.empty(6, dtype=np.int64)
    owner = np.full(n_edges, -1, dtype=np.int64)   # the vertex that carries edge j's stretching
    side = np.zeros(n_edges, dtype=np.int64)       # 0: it is that vertex's edge before, 1: after
    # order 2: the last vertex on edge j, after which its twisting moment dE/dtheta_j is complete and its
    # frame-transport term is added (geometry.add_transport_jacobian, inside this pass: the band's columns are then
    # in cache, not read again in a pass of their own, issue 17)
    last = np.empty(n_edges if order >= 2 else 0, dtype=np.int64)
    # order 2: the band's columns already zeroed. Each is zeroed just before the first stencil that adds to it (in
    # cache for its additions, rather than in a pass of its own that leaves the band's start out of cache at 10^5
    # edges, issue 17); the columns no stencil reaches after the pass
    zeroed = np.zeros(ab.shape[1] if order >= 2 else 0, dtype=np.bool_)
    for v in range(vertex_edges.shape[0]):
        for s in (1, 0):
            j = vertex_edges[v, s]
            if owner[j] < 0:
                owner[j] = v
                side[j] = s
            if order >= 2:
                last[j] = v
    want_f = order == 1 and F.shape[0] > 0
    g6s = np.empty((2, 6))      # with F: the stretching of the (up to two) edges a vertex carries, computed first
    e6s = np.empty(2)
    g8t = np.empty(8)           # with F: the twisting gradient apart, before it is added onto the bending's
    e_stretch = e_bend = e_twist = 0.0
    for v in range(vertex_edges.shape[0]):
        if want_f:
            # an edge force starts from its stretching (as in diagnostics._edge_forces), then each vertex on the
            # edge in turn adds its bending and its twisting; the gradient's sums below are unchanged
            for s in range(2):
                j = vertex_edges[v, s]
                if owner[j] == v and side[j] == s:
                    e6s[s] = _stretch_local(Ee, j, l_bar[j], k_stretch[j], lam[j], 1, g6s[s], H6)
                    for i in range(3):
                        F[j, i] = g6s[s, 3 + i]
        a1, a2 = bending_at(A1, v)
        if order >= 2:
            # the gradient bitwise as the order-1 calls below compute it, and the Hessian's upper triangle
            eb, et = _bend_twist_local(q, ed, vertex_edges, reference_twist, weld, v, kappa_bar, a1 / voronoi[v],
                                       a2 / voronoi[v], twist_bar[v], twisting_at(A2, v) / voronoi[v], g8, H8, work)
            e_bend += eb
            e_twist += et
        else:
            eb = _bend_local(ed, vertex_edges, weld, v, kappa_bar, a1 / voronoi[v], a2 / voronoi[v], 1, g8, H8, work)
            e_bend += eb
        if want_f:
            st = twisting_at(A2, v) / voronoi[v]
            et = _twist_local(q, ed, vertex_edges, reference_twist, weld, v, twist_bar[v], st, 1, g8t, H8, work)
            ja = vertex_edges[v, 0]
            jb = vertex_edges[v, 1]
            for i in range(3):
                F[ja, i] += g8[i]
                F[jb, i] += g8[3 + i]
            for i in range(3):
                F[ja, i] += g8t[i]
                F[jb, i] += g8t[3 + i]
            for i in range(8):
                g8[i] += g8t[i]
            m2 = 0.0
            m2 += 2.0 * eb * (max(a1, a2) / voronoi[v])
            m2 += 2.0 * et * st
            M[v] = np.sqrt(m2)
            e_twist += et
        elif order < 2:
            e_twist += _twist_local(q, ed, vertex_edges, reference_twist, weld, v, twist_bar[v],
                                    twisting_at(A2, v) / voronoi[v], order, g8,
                                    H8, work, True)
        scatter_vertex_gradient(grad, vertex_nodes[v, 0], vertex_nodes[v, 1], vertex_nodes[v, 2],
                                vertex_edges[v, 0], vertex_edges[v, 1], g8)
        if order >= 2:
            _expand_upper(H8, H11)
        for s in range(2):
            j = vertex_edges[v, s]
            if owner[j] != v or side[j] != s:
                continue
            if want_f:
                e_stretch += e6s[s]
                for i in range(6):
                    g6[i] = g6s[s, i]
            elif order >= 2:
                # its Hessian's upper triangle straight onto that of H11 (edge before: x0, x1; after: x1, x2)
                e_stretch += _stretch_local_upper(Ee, j, l_bar[j], k_stretch[j], lam[j], g6, H11, 4 * s)
            else:
                e_stretch += _stretch_local(Ee, j, l_bar[j], k_stretch[j], lam[j], order, g6, H6)
            a = 4 * edge_nodes[j, 0]
            c = 4 * edge_nodes[j, 1]
            for i in range(3):
                grad[a + i] += g6[i]
                grad[c + i] += g6[3 + i]
        if order >= 2:
            vertex_dofs(vertex_nodes, vertex_edges, v, dofs)
            contiguous = band_positions(perm, dofs, pos)
            for a in range(11):
                p = pos[a]
                if not zeroed[p]:
                    zero_band_column(ab, p)
                    zeroed[p] = True
            scatter_band_symmetric_at(ab, kl, ku, pos, contiguous, H11)
            for s in range(2):
                j = vertex_edges[v, s]
                if not transport or last[j] != v or (s == 1 and j == vertex_edges[v, 0]):
                    continue
                g = grad[4 * j + 3]
                if g != 0.0:
                    transport_jacobian_edge(ab, kl + ku, perm, 4 * edge_nodes[j, 0], 4 * edge_nodes[j, 1], g,
                                            Ee[j, 0], Ee[j, 1], Ee[j, 2])
    if order >= 2:
        for p in range(zeroed.shape[0]):
            if not zeroed[p]:
                zero_band_column(ab, p)
    for j in range(n_edges):   # edges on no vertex (a single-edge rod)
        if owner[j] < 0:
            e_stretch += _stretch_local(Ee, j, l_bar[j], k_stretch[j], lam[j], order, g6, H6)
            a = 4 * edge_nodes[j, 0]
            c = 4 * edge_nodes[j, 1]
            for i in range(3):
                d6[i] = a + i
                d6[3 + i] = c + i
                grad[a + i] += g6[i]
                grad[c + i] += g6[3 + i]
                if want_f:
                    F[j, i] = g6[3 + i]
            if order >= 2:
                scatter_band(ab, kl, ku, perm, d6, H6, 1.0)
    return e_stretch, e_bend, e_twist


# ---- the Newton matrix of a vertex stencil, its upper triangle only (issue 17) --------------------------------
# The local Hessian is symmetric: computing its 36 upper entries in (e, f, theta_e, theta_f) rather than 64 (every
# term of bending and twisting summed per entry, in registers, instead of one pass over the 8 x 8 array per term),
# mapping them to the stencil's 66 upper entries rather than 121 and writing each into the band twice (row and
# column) halves the local arithmetic of the assembly. The band's energy part is then exactly symmetric (before,
# its two triangles differed by round-off: (s a_i) b_j against (s a_j) b_i). The curvatures, residuals, energies
# and gradients are those of ``energies.bend`` and ``energies.twist``, from their own helpers (bitwise); the
# Hessian has their formulas regrouped per entry (to round-off), so it is written out here.


@njit(cache=True)
def _bend_twist_local(q, ed, vertex_edges, reference_twist, weld, v, kappa_bar, b1, b2, mbar, stiff, g8, H, D):
    """The bending (stiffnesses ``b1``, ``b2``, as ``energies.bend._bend_local``) and twisting (``mbar``,
    ``stiff``, as ``energies.twist._twist_local``) of vertex ``v``: returns their energies, ``g8`` <- the sum of
    their gradients in (e, f, theta_e, theta_f), bitwise what ``_bend_local`` at order 1 followed by
    ``_twist_local`` at order 1 with ``add`` give (the same operations in the same order: the order-1 pass's
    forces), and ``H[i, j]`` (i <= j; the strictly lower part is not written) <- the upper triangle of the sum of
    their Hessians, with the quantities they share formed once. ``D``: a (5, 8) scratch array (the gradients of
    the four curvature components and of the twist, the rows of the Gauss-Newton part)."""
    te, le, m1e, m2e, tf, lf, m1f, m2f, kb, k1e, k2e, k1f, k2f = _vertex_curvatures(ed, vertex_edges, weld, v)
    r1e, r2e, r1f, r2f = _curvature_residuals(k1e, k2e, k1f, k2f, kappa_bar, v)
    w1, w2, e_bend = _bend_weights_energy(b1, b2, r1e, r2e, r1f, r2f)
    s1e, s2e, s1f, s2f, ichi, tt, Ue, Uf, K, dd, X, Z = _bend_gradient_of(
        te, le, m1e, m2e, tf, lf, m1f, m2f, k1e, k2e, k1f, k2f, r1e, r2e, r1f, r2f, w1, w2, g8)
    # twisting (as _twist_local): m = theta_f - theta_e + reference twist (+ weld), dm/de = kb / (2|e|), ...
    r = _material_twist(q, vertex_edges, reference_twist, weld, v) - mbar
    e_twist = 0.5 * stiff * r * r
    _twist_rate_row(kb, le, lf, D, 4)
    for i in range(8):
        g8[i] += stiff * r * D[4, i]
    st = stiff * r
    ile = 1.0 / le
    ilf = 1.0 / lf
    # Gauss-Newton rows: d(kb . u_c) for u = m2_e, -m1_e, m2_f, -m1_f (weights w1, w2, w1, w2) and dm (stiff)
    c2 = 2.0 * ichi
    for c in range(4):
        if c == 0:
            kc, u, dth, col = k1e, m2e, k2e, 6
        elif c == 1:
            kc, u, dth, col = k2e, vscale(-1.0, m1e), -k1e, 6
        elif c == 2:
            kc, u, dth, col = k1f, m2f, k2f, 7
        else:
            kc, u, dth, col = k2f, vscale(-1.0, m1f), -k1f, 7
        pe = vcross(tf, u)
        pf = vcross(te, u)
        for i in range(3):
            D[c, i] = ile * (c2 * pe[i] - kc * tt[i])
            D[c, 3 + i] = ilf * (-kc * tt[i] - c2 * pf[i])
        D[c, 6] = 0.0
        D[c, 7] = 0.0
        D[c, col] = dth
    for i in range(8):
        d0 = w1 * D[0, i]
        d1 = w2 * D[1, i]
        d2 = w1 * D[2, i]
        d3 = w2 * D[3, i]
        d4 = stiff * D[4, i]
        for j in range(i, 8):
            H[i, j] = d0 * D[0, j] + d1 * D[1, j] + d2 * D[2, j] + d3 * D[3, j] + d4 * D[4, j]
    # curvature parts (bending's from K, U = sum_c s_c u_c and the frame terms; twisting's from st)
    ae = vadd(te, tt)
    af = vadd(tf, tt)
    Y = vsub(X, vscale(K, tt))                   # ee: -(Y tt^T + tt Y^T) (with 2K tt tt^T)
    Zp = vadd(Z, vscale(K, tt))                  # ff: +(Z' tt^T + tt Z'^T)
    P = vsub(vscale(0.5, Ue), vscale(0.25 * st, ae))   # ee: kb P^T + P kb^T
    Q = vsub(vscale(0.5, Uf), vscale(0.25 * st, af))   # ff: kb Q^T + Q kb^T
    W = vsub(vsub(vscale(2.0 * K, tt), X), vscale(0.5 * st, kb))   # ef: W tt^T + tt Z^T
    cx = vsub(vscale(st * ichi, te), dd)         # ef: [cx]_x
    Kc = K * ichi
    ie2 = ile * ile
    if2 = ilf * ilf
    ief = ile * ilf
    for i in range(3):
        for j in range(i, 3):
            ee = -(Y[i] * tt[j] + tt[i] * Y[j]) + (kb[i] * P[j] + P[i] * kb[j]) + Kc * te[i] * te[j]
            ff = (Zp[i] * tt[j] + tt[i] * Zp[j]) + (kb[i] * Q[j] + Q[i] * kb[j]) + Kc * tf[i] * tf[j]
            if i == j:
                ee -= Kc
                ff -= Kc
            H[i, j] += ie2 * ee
            H[3 + i, 3 + j] += if2 * ff
        for j in range(3):
            ef = W[i] * tt[j] + tt[i] * Z[j] - Kc * te[i] * tf[j]
            if i == j:
                ef -= Kc
            H[i, 3 + j] += ief * ef
    H[0, 4] += ief * -cx[2]
    H[0, 5] += ief * cx[1]
    H[1, 3] += ief * cx[2]
    H[1, 5] += ief * -cx[0]
    H[2, 3] += ief * -cx[1]
    H[2, 4] += ief * cx[0]
    # theta-theta: d2 k1_j / dtheta_j^2 = -k1_j, d2 k2_j / dtheta_j^2 = -k2_j
    H[6, 6] += -(s1e * k1e + s2e * k2e)
    H[7, 7] += -(s1f * k1f + s2f * k2f)
    # edge-theta: the gradient of kb . V with V = sum_c s_c du_c/dtheta over the components of that edge
    Ve = vsub(vscale(-s1e, m1e), vscale(s2e, m2e))
    Vf = vsub(vscale(-s1f, m1f), vscale(s2f, m2f))
    Pe = vdot(kb, Ve)
    Pf = vdot(kb, Vf)
    tfVe = vcross(tf, Ve)
    teVe = vcross(te, Ve)
    tfVf = vcross(tf, Vf)
    teVf = vcross(te, Vf)
    for i in range(3):
        H[i, 6] += ile * (c2 * tfVe[i] - Pe * tt[i])
        H[3 + i, 6] += ilf * (-Pe * tt[i] - c2 * teVe[i])
        H[i, 7] += ile * (c2 * tfVf[i] - Pf * tt[i])
        H[3 + i, 7] += ilf * (-Pf * tt[i] - c2 * teVf[i])
    return e_bend, e_twist


@njit(cache=True, inline="always")
def _stretch_local_upper(E, j, l_bar, k, lam, g6, H11, o):
    """``energies.stretch._stretch_local`` at order 2 with its 6 x 6 Hessian's upper triangle added straight into
    H11 at stencil positions (o, o+1, o+2, o+4, o+5, o+6): the same operations, so the energy, ``g6`` and every
    entry added are bitwise those of ``_stretch_local``."""
    g, le = elongation(E, j, l_bar)
    energy = _stretch_energy_of(g, k, lam)
    tension, t = _stretch_tension(E, j, g, le, k, lam, g6)
    c = tension / le
    for i in range(3):
        for jj in range(3):
            h = _stretch_hessian_entry(k, c, t, i, jj)
            if i <= jj:
                H11[o + i, o + jj] += h             # x_a x_a
                H11[o + 4 + i, o + 4 + jj] += h     # x_b x_b
            H11[o + i, o + 4 + jj] += -h            # x_a x_b
    return energy


@njit(cache=True, inline="always")
def _expand_upper(H8, H11):
    """The upper triangle of ``stencils.expand_vertex_hessian`` (B^T H8 B) from the upper triangle of H8."""
    for i in range(3):
        for j in range(3):
            ee = H8[min(i, j), max(i, j)]
            ef = H8[i, 3 + j]
            ff = H8[3 + min(i, j), 3 + max(i, j)]
            H11[i, 4 + j] = -ee + ef                             # x0 x1
            H11[i, 8 + j] = -ef                                  # x0 x2
            H11[4 + i, 8 + j] = ef - ff                          # x1 x2
            if i <= j:
                H11[i, j] = ee                                   # x0 x0
                H11[4 + i, 4 + j] = ee - ef - H8[j, 3 + i] + ff  # x1 x1
                H11[8 + i, 8 + j] = ff                           # x2 x2
        H11[i, 3] = -H8[i, 6]                                    # x0 theta_e
        H11[i, 7] = -H8[i, 7]                                    # x0 theta_f
        H11[3, 4 + i] = H8[i, 6] - H8[3 + i, 6]                  # theta_e x1
        H11[3, 8 + i] = H8[3 + i, 6]                             # theta_e x2
        H11[4 + i, 7] = H8[i, 7] - H8[3 + i, 7]                  # x1 theta_f
        H11[7, 8 + i] = H8[3 + i, 7]                             # theta_f x2
    H11[3, 3] = H8[6, 6]
    H11[3, 7] = H8[6, 7]
    H11[7, 7] = H8[7, 7]
