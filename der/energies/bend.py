"""Bending with natural curvature (stiffnesses A1, A1' per vertex), material curvatures per edge frame.

Per vertex ``v`` joining edges ``e`` and ``f`` (Bergou et al. 2008, Sec. 4.2), with ``j`` either edge:

    kb        = 2 t_e x t_f / (1 + t_e . t_f)               curvature binormal, |kb| = 2 tan(phi/2)
    kappa^j   = (kb . m2_j, -kb . m1_j)                      material curvature in edge j's own frame
    E_v       = A1 / (4 D_v) sum_{j = e, f} |kappa^j - kappa_bar^j|^2

with ``D_v`` the rest Voronoi length (half the two rest edge lengths) and ``kappa_bar^j`` the natural value
measured in the same frame on the rest shape (``Rod.kappa_bar_edges``). Each edge's frame enters alone: a
material twist between the two edges does not shorten the curvature vector (an average of the two frames
would, by cos(twist / 2), and soften the bending of a naturally twisted rod by cos^2). At the weld vertex of a
welded ring edge f's frame is first turned by the weld rotation (see ``energies.twist``).

With the rest material frame on the Frenet frame, ``kappa_bar^j = (kappa0 D, 0)`` to O(h^2) and, writing
``m1 = cos(alpha) n + sin(alpha) b``, each side is ``|kappa^j - kappa_bar^j|^2 = D^2 (kappa^2 - 2 kappa kappa0
cos(alpha) + kappa0^2)``: the two sides sum to twice that, so ``E_v`` is ``D`` times the paper's bending
density ``A1/2 (kappa^2 - 2 kappa kappa0 cos(alpha) + kappa0^2)`` (Eq. 17). ``kappa^j`` are integrated
(dimensionless) curvatures; energies are in units of A1 / length.

The local kernel takes the stiffness of each curvature component (``b1 = A1_v / D_v`` for kappa1 = kb . m2,
bending towards m1 about m2; ``b2 = A1'_v / D_v`` for kappa2 = -kb . m1, bending towards m2 about m1):

    E_v = 1 / (4 D_v) sum_{j = e, f} [A1_v (kappa1^j - kappa1_bar^j)^2 + A1'_v (kappa2^j - kappa2_bar^j)^2]

The ``A1`` argument of the loops is a float (isotropic, uniform: the results are bitwise those of a scalar
stiffness), an (n_vertices,) array or an (n_vertices, 2) array of (A1, A1') (``energies.stiffness``).
"""
import numpy as np
from numba import njit

from .stiffness import bending_at
from ..stencils import (
    add_column, add_cross_matrix, add_identity, add_outer, add_sym_outer, curvature_binormal_of, edge_vectors,
    expand_vertex_hessian, scatter_band, scatter_vertex_gradient, vadd, vcross, vdot, vertex_dofs, vscale, vsub,
)


@njit(cache=True)
def welded(m1, m2, psi):
    """The frame (m1, m2) turned by psi about the tangent (a weld; identity for psi = 0)."""
    if psi == 0.0:
        return m1, m2
    c, s = np.cos(psi), np.sin(psi)
    return vadd(vscale(c, m1), vscale(s, m2)), vsub(vscale(c, m2), vscale(s, m1))


# ---- the formulas of one vertex, one home each: called by the kernels below and by the fused vertex pass
# (``energies.vertex._bend_twist_local``), which then computes the same floating-point operations in the same
# order (the solver's Newton paths follow round-off; ``tools/kernel_fingerprint.py`` checks it bitwise).
# Editing one of them: numba's cache keys a kernel on its own file only, so also touch energies/vertex.py (its
# fused kernels inline these, and scene.evaluate calls them) or clear the caches, else they run stale.


@njit(cache=True, inline="always")
def _vertex_curvatures(ed, vertex_edges, weld, v):
    """The frames of vertex v's two edges (edge f's turned by the weld), its curvature binormal and material
    curvatures: ``(te, le, m1e, m2e, tf, lf, m1f, m2f, kb, k1e, k2e, k1f, k2f)`` with ``k1_j = kb . m2_j``,
    ``k2_j = -kb . m1_j``. The weld leaves d/dtheta_f unchanged: m1f' = m2f, m2f' = -m1f."""
    te, le, m1e, m2e = edge_vectors(ed, vertex_edges[v, 0])
    tf, lf, m1f, m2f = edge_vectors(ed, vertex_edges[v, 1])
    m1f, m2f = welded(m1f, m2f, weld[v])
    kb = curvature_binormal_of(ed, vertex_edges[v, 0], vertex_edges[v, 1])
    k1e = vdot(kb, m2e)
    k2e = -vdot(kb, m1e)
    k1f = vdot(kb, m2f)
    k2f = -vdot(kb, m1f)
    return te, le, m1e, m2e, tf, lf, m1f, m2f, kb, k1e, k2e, k1f, k2f


@njit(cache=True, inline="always")
def _curvature_residuals(k1e, k2e, k1f, k2f, kappa_bar, v):
    """The material curvatures of vertex v less their natural values ``kappa_bar[v]``."""
    return k1e - kappa_bar[v, 0], k2e - kappa_bar[v, 1], k1f - kappa_bar[v, 2], k2f - kappa_bar[v, 3]


@njit(cache=True, inline="always")
def _bend_weights_energy(b1, b2, r1e, r2e, r1f, r2f):
    """``(w1, w2, E_v)``: E_v = 1/2 sum_c w_c r_c^2 with w = b / 2 (the two edge sides share the vertex's
    Voronoi cell)."""
    w1 = 0.5 * b1
    w2 = 0.5 * b2
    return w1, w2, 0.5 * (w1 * (r1e * r1e + r1f * r1f) + w2 * (r2e * r2e + r2f * r2f))


@njit(cache=True, inline="always")
def _bend_gradient_of(te, le, m1e, m2e, tf, lf, m1f, m2f, k1e, k2e, k1f, k2f, r1e, r2e, r1f, r2f, w1, w2, g8):
    """``g8`` <- the bending gradient of a vertex in (e, f, theta_e, theta_f) from ``_vertex_curvatures``,
    ``_curvature_residuals`` and ``_bend_weights_energy``; returns what its Hessian reuses: ``(s1e, s2e, s1f,
    s2f, ichi, tt, Ue, Uf, K, dd, tf x dd, te x dd)`` with s_c = w_c r_c, ichi = 1 / chi, tt = (te + tf) / chi,
    U = sum_c s_c u_c (edge e and edge f parts), K = sum_c s_c k_c and dd = 2 U / chi.

    Every component is ``kb . u`` with ``u`` one material vector of one edge (``m2_e``, ``-m1_e``, ``m2_f``,
    ``-m1_f``): d(kb . u)/de = (-(kb . u) tt + 2 tf x u / chi) / |e|, d/df = (-(kb . u) tt - 2 te x u / chi) / |f|
    (a material vector of either edge turns with its own tangent only, normal to kb); d k1_j / dtheta_j = k2_j,
    d k2_j / dtheta_j = -k1_j. Weighted by s_c and summed, the edge parts need only K and U."""
    s1e = w1 * r1e
    s2e = w2 * r2e
    s1f = w1 * r1f
    s2f = w2 * r2f
    chi = 1.0 + vdot(te, tf)
    ichi = 1.0 / chi
    tt = vscale(ichi, vadd(te, tf))
    Ue = vsub(vscale(s1e, m2e), vscale(s2e, m1e))
    Uf = vsub(vscale(s1f, m2f), vscale(s2f, m1f))
    K = s1e * k1e + s2e * k2e + s1f * k1f + s2f * k2f
    dd = vscale(2.0 * ichi, vadd(Ue, Uf))
    tf_x_dd = vcross(tf, dd)
    te_x_dd = vcross(te, dd)
    ge = vscale(1.0 / le, vadd(vscale(-K, tt), tf_x_dd))
    gf = vscale(1.0 / lf, vsub(vscale(-K, tt), te_x_dd))
    for i in range(3):
        g8[i] = ge[i]
        g8[3 + i] = gf[i]
    g8[6] = s1e * k2e - s2e * k1e
    g8[7] = s1f * k2f - s2f * k1f
    return s1e, s2e, s1f, s2f, ichi, tt, Ue, Uf, K, dd, tf_x_dd, te_x_dd


@njit(cache=True)
def material_curvatures(ed, vertex_edges, weld, v):
    """Integrated material curvatures at vertex v in the frame of each edge: ``(k1_e, k2_e, k1_f, k2_f)``
    with ``k1_j = kb . m2_j``, ``k2_j = -kb . m1_j``; ``ed`` from ``geometry.edge_frames``."""
    _, _, _, _, _, _, _, _, _, k1e, k2e, k1f, k2f = _vertex_curvatures(ed, vertex_edges, weld, v)
    return k1e, k2e, k1f, k2f


@njit(cache=True)
def material_curvatures_all(ed, vertex_edges, weld):
    """``material_curvatures`` of every vertex in one pass, shape (n_vertices, 4)."""
    nv = vertex_edges.shape[0]
    out = np.empty((nv, 4))
    for v in range(nv):
        k1e, k2e, k1f, k2f = material_curvatures(ed, vertex_edges, weld, v)
        out[v, 0] = k1e
        out[v, 1] = k2e
        out[v, 2] = k1f
        out[v, 3] = k2f
    return out


@njit(cache=True)
def material_curvature(ed, vertex_edges, weld, v):
    """Mean of the two edges' material curvatures (kappa1, kappa2) at vertex v (what ``Rod.kappa_bar`` holds)."""
    k1e, k2e, k1f, k2f = material_curvatures(ed, vertex_edges, weld, v)
    return 0.5 * (k1e + k1f), 0.5 * (k2e + k2f)


@njit(cache=True, inline="always")
def _bend_energy_local(ed, vertex_edges, weld, v, kappa_bar, b1, b2):
    """Energy of vertex v alone (what ``_bend_local`` returns; small enough to be inlined in the energy loop)."""
    _, _, m1e, m2e, _, _, m1f, m2f, kb, k1e, k2e, k1f, k2f = _vertex_curvatures(ed, vertex_edges, weld, v)
    r1e, r2e, r1f, r2f = _curvature_residuals(k1e, k2e, k1f, k2f, kappa_bar, v)
    # (grouped as b / 4 rather than _bend_weights_energy's w / 2: kept as it was, bitwise)
    return 0.25 * (b1 * (r1e * r1e + r1f * r1f) + b2 * (r2e * r2e + r2f * r2f))


@njit(cache=True)
def _bend_local(ed, vertex_edges, weld, v, kappa_bar, b1, b2, order, g8, H8, work):
    """Energy of vertex v; with order >= 1 its gradient in (e, f, theta_e, theta_f), order >= 2 the Hessian.

    ``kappa_bar[v]`` holds the natural ``(k1_e, k2_e, k1_f, k2_f)`` of the vertex; ``b1``, ``b2`` the
    stiffnesses of the two components (A1 / D_v). ``ed`` holds the per-edge tangents, lengths and material
    frames (``geometry.edge_frames``); ``work`` is a (5, 8) scratch buffer (nothing is allocated per vertex).

    Every component is ``kb . u`` with ``u`` one material vector of one edge (``m2_e``, ``-m1_e``, ``m2_f``,
    ``-m1_f``). Its gradient and Hessian are linear in ``u`` apart from the frame terms, so the curvature
    part of the Hessian, sum_c s_c Hess(kb . u_c), is assembled once from the weighted sums ``K = sum s_c k_c``
    and ``U = sum s_c u_c`` rather than per component.
    """
    te, le, m1e, m2e, tf, lf, m1f, m2f, kb, k1e, k2e, k1f, k2f = _vertex_curvatures(ed, vertex_edges, weld, v)
    r1e, r2e, r1f, r2f = _curvature_residuals(k1e, k2e, k1f, k2f, kappa_bar, v)
    w1, w2, energy = _bend_weights_energy(b1, b2, r1e, r2e, r1f, r2f)
    if order == 0:
        return energy

    s1e, s2e, s1f, s2f, ichi, tt, Ue, Uf, K, dd, tf_x_dd, te_x_dd = _bend_gradient_of(
        te, le, m1e, m2e, tf, lf, m1f, m2f, k1e, k2e, k1f, k2f, r1e, r2e, r1f, r2f, w1, w2, g8)
    if order == 1:
        return energy

    # Gauss-Newton part: sum_c w_c grad k_c grad k_c^T, one component at a time
    for i in range(8):
        for j in range(8):
            H8[i, j] = 0.0
    dk = work[0]
    for c in range(4):
        if c == 0:
            kc, u, wc, on_e, dth = k1e, m2e, w1, True, k2e
        elif c == 1:
            kc, u, wc, on_e, dth = k2e, vscale(-1.0, m1e), w2, True, -k1e
        elif c == 2:
            kc, u, wc, on_e, dth = k1f, m2f, w1, False, k2f
        else:
            kc, u, wc, on_e, dth = k2f, vscale(-1.0, m1f), w2, False, -k1f
        a = vscale(-kc, tt)
        tf_x_u = vscale(2.0 * ichi, vcross(tf, u))
        te_x_u = vscale(2.0 * ichi, vcross(te, u))
        for i in range(3):
            dk[i] = (a[i] + tf_x_u[i]) / le
            dk[3 + i] = (a[i] - te_x_u[i]) / lf
        dk[6] = dth if on_e else 0.0
        dk[7] = 0.0 if on_e else dth
        for i in range(8):
            wi = wc * dk[i]
            for j in range(i, 8):
                H8[i, j] += wi * dk[j]
    for i in range(8):
        for j in range(i):
            H8[i, j] = H8[j, i]
    # curvature part: sum_c s_c Hess(kb . u_c), from K, U (dd = 2 U / chi) and the frame terms of each edge
    le2 = le * le
    lf2 = lf * lf
    lelf = le * lf
    # ee block
    add_outer(H8, 0, 0, 2.0 * K / le2, tt, tt)
    add_sym_outer(H8, 0, 0, -1.0 / le2, tf_x_dd, tt)
    add_identity(H8, 0, 0, -K * ichi / le2)
    add_outer(H8, 0, 0, K * ichi / le2, te, te)
    add_sym_outer(H8, 0, 0, 0.5 / le2, kb, Ue)
    # ff block
    add_outer(H8, 3, 3, 2.0 * K / lf2, tt, tt)
    add_sym_outer(H8, 3, 3, 1.0 / lf2, te_x_dd, tt)
    add_identity(H8, 3, 3, -K * ichi / lf2)
    add_outer(H8, 3, 3, K * ichi / lf2, tf, tf)
    add_sym_outer(H8, 3, 3, 0.5 / lf2, kb, Uf)
    # ef block (and its transpose as fe)
    Bef = work[2:5, 0:3]
    Bef[:, :] = 0.0
    add_identity(Bef, 0, 0, -K * ichi / lelf)
    add_outer(Bef, 0, 0, -K * ichi / lelf, te, tf)
    add_outer(Bef, 0, 0, 2.0 * K / lelf, tt, tt)
    add_outer(Bef, 0, 0, -1.0 / lelf, tf_x_dd, tt)
    add_outer(Bef, 0, 0, 1.0 / lelf, tt, te_x_dd)
    add_cross_matrix(Bef, 0, 0, -1.0 / lelf, dd)
    for i in range(3):
        for j in range(3):
            H8[i, 3 + j] += Bef[i, j]
            H8[3 + j, i] += Bef[i, j]
    # theta-theta: d2 k1_j / dtheta_j^2 = -k1_j, d2 k2_j / dtheta_j^2 = -k2_j
    H8[6, 6] += -(s1e * k1e + s2e * k2e)
    H8[7, 7] += -(s1f * k1f + s2f * k2f)
    # edge-theta: the gradient of kb . V with V = sum_c s_c du_c/dtheta over the components of that edge
    Ve = vsub(vscale(-s1e, m1e), vscale(s2e, m2e))
    Vf = vsub(vscale(-s1f, m1f), vscale(s2f, m2f))
    Pe = vdot(kb, Ve)
    Pf = vdot(kb, Vf)
    add_column(H8, 0, 6, 1.0 / le, vadd(vscale(-Pe, tt), vscale(2.0 * ichi, vcross(tf, Ve))))
    add_column(H8, 3, 6, 1.0 / lf, vsub(vscale(-Pe, tt), vscale(2.0 * ichi, vcross(te, Ve))))
    add_column(H8, 0, 7, 1.0 / le, vadd(vscale(-Pf, tt), vscale(2.0 * ichi, vcross(tf, Vf))))
    add_column(H8, 3, 7, 1.0 / lf, vsub(vscale(-Pf, tt), vscale(2.0 * ichi, vcross(te, Vf))))
    return energy


@njit(cache=True)
def bend_energy(ed, vertex_edges, weld, kappa_bar, voronoi, A1):
    """Total bending energy; ``ed = geometry.edge_frames(q, edge_nodes, d1)``; ``kappa_bar`` (n_vertices, 4) the
    natural ``(k1_e, k2_e, k1_f, k2_f)`` of each vertex, ``Rod.natural_curvature_edges().reshape(-1, 4)``
    (flat rows index faster than a 3-d array in the hot loop)."""
    total = 0.0
    for v in range(vertex_edges.shape[0]):
        a1, a2 = bending_at(A1, v)
        total += _bend_energy_local(ed, vertex_edges, weld, v, kappa_bar, a1 / voronoi[v], a2 / voronoi[v])
    return total


@njit(cache=True)
def bend_gradient(ed, vertex_nodes, vertex_edges, weld, kappa_bar, voronoi, A1, grad):
    """Add the bending energy gradient to ``grad`` (length n_dof); returns the energy."""
    g8 = np.empty(8)
    H8 = np.empty((8, 8))
    work = np.empty((5, 8))
    total = 0.0
    for v in range(vertex_edges.shape[0]):
        a1, a2 = bending_at(A1, v)
        total += _bend_local(ed, vertex_edges, weld, v, kappa_bar, a1 / voronoi[v], a2 / voronoi[v], 1, g8, H8, work)
        scatter_vertex_gradient(grad, vertex_nodes[v, 0], vertex_nodes[v, 1], vertex_nodes[v, 2],
                                vertex_edges[v, 0], vertex_edges[v, 1], g8)
    return total


@njit(cache=True)
def bend_hessian(ed, vertex_nodes, vertex_edges, weld, kappa_bar, voronoi, A1, grad, ab, kl, ku, perm):
    """Add gradient to ``grad`` and Hessian to the band matrix ``ab``; returns the energy."""
    g8 = np.empty(8)
    H8 = np.empty((8, 8))
    H11 = np.empty((11, 11))
    work = np.empty((5, 8))
    dofs = np.empty(11, dtype=np.int64)
    total = 0.0
    for v in range(vertex_edges.shape[0]):
        a1, a2 = bending_at(A1, v)
        total += _bend_local(ed, vertex_edges, weld, v, kappa_bar, a1 / voronoi[v], a2 / voronoi[v], 2, g8, H8, work)
        scatter_vertex_gradient(grad, vertex_nodes[v, 0], vertex_nodes[v, 1], vertex_nodes[v, 2],
                                vertex_edges[v, 0], vertex_edges[v, 1], g8)
        expand_vertex_hessian(H8, H11)
        vertex_dofs(vertex_nodes, vertex_edges, v, dofs)
        scatter_band(ab, kl, ku, perm, dofs, H11, 1.0)
    return total
