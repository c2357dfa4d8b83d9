"""Isotropic bending with natural curvature (bending stiffness A1).

Per vertex ``v`` joining edges ``e`` and ``f`` (Bergou et al. 2010; material frames averaged over both edges):

    kb     = 2 t_e x t_f / (1 + t_e . t_f)                 curvature binormal, |kb| = 2 tan(phi/2)
    kappa1 = 1/2 kb . (m2_e + m2_f),  kappa2 = -1/2 kb . (m1_e + m1_f)
    E_v    = A1 / (2 D_v) [(kappa1 - kappa1_bar)^2 + (kappa2 - kappa2_bar)^2]

with ``D_v`` the rest Voronoi length (half the two rest edge lengths); at the weld vertex of a welded ring edge
f's frame is first turned by the weld rotation (see ``energies.twist``). With the rest material frame on the
Frenet frame, ``kappa_bar = (kappa0 D, 0)`` and, writing ``m1 = cos(alpha) n + sin(alpha) b``, the
continuum limit is the paper's bending term ``A1/2 (kappa^2 - 2 kappa kappa0 cos(alpha) + kappa0^2)`` (Eq. 17).
``kappa1, kappa2`` are integrated (dimensionless) curvatures; energies are in units of A1 / length.
"""
import numpy as np
from numba import njit

from ..stencils import (
    add_column, add_cross_matrix, add_identity, add_outer, add_sym_outer, edge_vectors, expand_vertex_hessian,
    scatter_band, scatter_vertex_gradient, vadd, vcross, vdot, vertex_dofs, vscale, vsub,
)


@njit(cache=True)
def welded(m1, m2, psi):
    """The frame (m1, m2) turned by psi about the tangent (a weld; identity for psi = 0)."""
    if psi == 0.0:
        return m1, m2
    c, s = np.cos(psi), np.sin(psi)
    return vadd(vscale(c, m1), vscale(s, m2)), vsub(vscale(c, m2), vscale(s, m1))


@njit(cache=True)
def material_curvature(ed, vertex_edges, weld, v):
    """Integrated material curvatures (kappa1, kappa2) at vertex v; ``ed`` from ``geometry.edge_frames``."""
    te, _, m1e, m2e = edge_vectors(ed, vertex_edges[v, 0])
    tf, _, m1f, m2f = edge_vectors(ed, vertex_edges[v, 1])
    m1f, m2f = welded(m1f, m2f, weld[v])
    kb = vscale(2.0 / (1.0 + vdot(te, tf)), vcross(te, tf))
    return 0.5 * vdot(kb, vadd(m2e, m2f)), -0.5 * vdot(kb, vadd(m1e, m1f))


@njit(cache=True)
def _bend_local(ed, vertex_edges, weld, v, kbar1, kbar2, stiff, order, g8, H8, work):
    """Energy of vertex v; with order >= 1 its gradient in (e, f, theta_e, theta_f), order >= 2 the Hessian.

    ``ed`` holds the per-edge tangents, lengths and material frames (``geometry.edge_frames``); ``work`` is a
    (5, 8) scratch buffer, so nothing is allocated per vertex."""
    te, le, m1e, m2e = edge_vectors(ed, vertex_edges[v, 0])
    tf, lf, m1f, m2f = edge_vectors(ed, vertex_edges[v, 1])
    m1f, m2f = welded(m1f, m2f, weld[v])   # d/dtheta_f is unchanged: m1f' = m2f, m2f' = -m1f
    chi = 1.0 + vdot(te, tf)
    kb = vscale(2.0 / chi, vcross(te, tf))
    k1 = 0.5 * vdot(kb, vadd(m2e, m2f))
    k2 = -0.5 * vdot(kb, vadd(m1e, m1f))
    r1 = k1 - kbar1
    r2 = k2 - kbar2
    energy = 0.5 * stiff * (r1 * r1 + r2 * r2)
    if order == 0:
        return energy

    tt = vscale(1.0 / chi, vadd(te, tf))
    dd1 = vscale(1.0 / chi, vadd(m1e, m1f))
    dd2 = vscale(1.0 / chi, vadd(m2e, m2f))
    tf_x_dd2 = vcross(tf, dd2)
    te_x_dd2 = vcross(te, dd2)
    tf_x_dd1 = vcross(tf, dd1)
    te_x_dd1 = vcross(te, dd1)
    # gradients of kappa1, kappa2 with respect to e, f, theta_e, theta_f
    dk1e = vscale(1.0 / le, vadd(vscale(-k1, tt), tf_x_dd2))
    dk1f = vscale(1.0 / lf, vsub(vscale(-k1, tt), te_x_dd2))
    dk2e = vscale(1.0 / le, vsub(vscale(-k2, tt), tf_x_dd1))
    dk2f = vscale(1.0 / lf, vadd(vscale(-k2, tt), te_x_dd1))
    kb_m1e = vdot(kb, m1e)
    kb_m1f = vdot(kb, m1f)
    kb_m2e = vdot(kb, m2e)
    kb_m2f = vdot(kb, m2f)
    dk1 = work[0]
    dk2 = work[1]
    for i in range(3):
        dk1[i] = dk1e[i]
        dk1[3 + i] = dk1f[i]
        dk2[i] = dk2e[i]
        dk2[3 + i] = dk2f[i]
    dk1[6] = -0.5 * kb_m1e
    dk1[7] = -0.5 * kb_m1f
    dk2[6] = -0.5 * kb_m2e
    dk2[7] = -0.5 * kb_m2f
    for i in range(8):
        g8[i] = stiff * (r1 * dk1[i] + r2 * dk2[i])
    if order == 1:
        return energy

    # Gauss-Newton part: stiff (grad k1 grad k1^T + grad k2 grad k2^T)
    for i in range(8):
        for j in range(8):
            H8[i, j] = stiff * (dk1[i] * dk1[j] + dk2[i] * dk2[j])
    # curvature part: stiff (r1 Hess k1 + r2 Hess k2)
    s1 = stiff * r1
    s2 = stiff * r2
    le2 = le * le
    lf2 = lf * lf
    lelf = le * lf
    # kappa1, ee block
    add_outer(H8, 0, 0, s1 * 2.0 * k1 / le2, tt, tt)
    add_sym_outer(H8, 0, 0, -s1 / le2, tf_x_dd2, tt)
    add_identity(H8, 0, 0, -s1 * k1 / (chi * le2))
    add_outer(H8, 0, 0, s1 * k1 / (chi * le2), te, te)
    add_sym_outer(H8, 0, 0, s1 / (4.0 * le2), kb, m2e)
    # kappa1, ff block
    add_outer(H8, 3, 3, s1 * 2.0 * k1 / lf2, tt, tt)
    add_sym_outer(H8, 3, 3, s1 / lf2, te_x_dd2, tt)
    add_identity(H8, 3, 3, -s1 * k1 / (chi * lf2))
    add_outer(H8, 3, 3, s1 * k1 / (chi * lf2), tf, tf)
    add_sym_outer(H8, 3, 3, s1 / (4.0 * lf2), kb, m2f)
    # kappa2, ee block
    add_outer(H8, 0, 0, s2 * 2.0 * k2 / le2, tt, tt)
    add_sym_outer(H8, 0, 0, s2 / le2, tf_x_dd1, tt)
    add_identity(H8, 0, 0, -s2 * k2 / (chi * le2))
    add_outer(H8, 0, 0, s2 * k2 / (chi * le2), te, te)
    add_sym_outer(H8, 0, 0, -s2 / (4.0 * le2), kb, m1e)
    # kappa2, ff block
    add_outer(H8, 3, 3, s2 * 2.0 * k2 / lf2, tt, tt)
    add_sym_outer(H8, 3, 3, -s2 / lf2, te_x_dd1, tt)
    add_identity(H8, 3, 3, -s2 * k2 / (chi * lf2))
    add_outer(H8, 3, 3, s2 * k2 / (chi * lf2), tf, tf)
    add_sym_outer(H8, 3, 3, -s2 / (4.0 * lf2), kb, m1f)
    # ef block (and its transpose as fe)
    Bef = work[2:5, 0:3]
    Bef[:, :] = 0.0
    add_identity(Bef, 0, 0, -(s1 * k1 + s2 * k2) / (chi * lelf))
    add_outer(Bef, 0, 0, -(s1 * k1 + s2 * k2) / (chi * lelf), te, tf)
    add_outer(Bef, 0, 0, 2.0 * (s1 * k1 + s2 * k2) / lelf, tt, tt)
    add_outer(Bef, 0, 0, -s1 / lelf, tf_x_dd2, tt)
    add_outer(Bef, 0, 0, s1 / lelf, tt, te_x_dd2)
    add_cross_matrix(Bef, 0, 0, -s1 / lelf, dd2)
    add_outer(Bef, 0, 0, s2 / lelf, tf_x_dd1, tt)
    add_outer(Bef, 0, 0, -s2 / lelf, tt, te_x_dd1)
    add_cross_matrix(Bef, 0, 0, s2 / lelf, dd1)
    for i in range(3):
        for j in range(3):
            H8[i, 3 + j] += Bef[i, j]
            H8[3 + j, i] += Bef[i, j]
    # theta-theta
    H8[6, 6] += s1 * (-0.5 * kb_m2e) + s2 * (0.5 * kb_m1e)
    H8[7, 7] += s1 * (-0.5 * kb_m2f) + s2 * (0.5 * kb_m1f)
    # edge-theta
    ichi = 1.0 / chi
    add_column(H8, 0, 6, s1 / le, vsub(vscale(0.5 * kb_m1e, tt), vscale(ichi, vcross(tf, m1e))))
    add_column(H8, 0, 7, s1 / le, vsub(vscale(0.5 * kb_m1f, tt), vscale(ichi, vcross(tf, m1f))))
    add_column(H8, 3, 6, s1 / lf, vadd(vscale(0.5 * kb_m1e, tt), vscale(ichi, vcross(te, m1e))))
    add_column(H8, 3, 7, s1 / lf, vadd(vscale(0.5 * kb_m1f, tt), vscale(ichi, vcross(te, m1f))))
    add_column(H8, 0, 6, s2 / le, vsub(vscale(0.5 * kb_m2e, tt), vscale(ichi, vcross(tf, m2e))))
    add_column(H8, 0, 7, s2 / le, vsub(vscale(0.5 * kb_m2f, tt), vscale(ichi, vcross(tf, m2f))))
    add_column(H8, 3, 6, s2 / lf, vadd(vscale(0.5 * kb_m2e, tt), vscale(ichi, vcross(te, m2e))))
    add_column(H8, 3, 7, s2 / lf, vadd(vscale(0.5 * kb_m2f, tt), vscale(ichi, vcross(te, m2f))))
    return energy


@njit(cache=True)
def bend_energy(ed, vertex_edges, weld, kappa_bar, voronoi, A1):
    """Total bending energy; ``ed = geometry.edge_frames(q, edge_nodes, d1)``."""
    g8 = np.empty(8)
    H8 = np.empty((8, 8))
    work = np.empty((5, 8))
    total = 0.0
    for v in range(vertex_edges.shape[0]):
        total += _bend_local(ed, vertex_edges, weld, v, kappa_bar[v, 0], kappa_bar[v, 1], A1 / voronoi[v], 0, g8, H8,
                             work)
    return total


@njit(cache=True)
def bend_gradient(ed, vertex_nodes, vertex_edges, weld, kappa_bar, voronoi, A1, grad):
    """Add the bending energy gradient to ``grad`` (length n_dof); returns the energy."""
    g8 = np.empty(8)
    H8 = np.empty((8, 8))
    work = np.empty((5, 8))
    total = 0.0
    for v in range(vertex_edges.shape[0]):
        total += _bend_local(ed, vertex_edges, weld, v, kappa_bar[v, 0], kappa_bar[v, 1], A1 / voronoi[v], 1, g8, H8,
                             work)
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
        total += _bend_local(ed, vertex_edges, weld, v, kappa_bar[v, 0], kappa_bar[v, 1], A1 / voronoi[v], 2, g8, H8,
                             work)
        scatter_vertex_gradient(grad, vertex_nodes[v, 0], vertex_nodes[v, 1], vertex_nodes[v, 2],
                                vertex_edges[v, 0], vertex_edges[v, 1], g8)
        expand_vertex_hessian(H8, H11)
        vertex_dofs(vertex_nodes, vertex_edges, v, dofs)
        scatter_band(ab, kl, ku, perm, dofs, H11, 1.0)
    return total
