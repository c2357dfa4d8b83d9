"""Twisting with natural twist (twisting stiffness A2: a float, or one per vertex).

Per vertex ``v`` joining edges ``e`` and ``f``:

    m_v = theta_f - theta_e + reference_twist_v           integrated material twist (radians)
    E_v = A2 / (2 D_v) (m_v - twist_bar_v)^2

``D_v`` is the rest Voronoi length. With the rest material frame on the Frenet frame, ``twist_bar`` is the
discrete Frenet twist (``omega0 D`` in the continuum) and ``m = (alpha' + omega) D``, so the continuum limit is
the paper's twisting term ``A2/2 (alpha' + omega - omega0)^2`` (Eq. 17). The reference twist depends on the
centreline through the parallel-transported reference frames: ``dm/de = kb / (2|e|)``, ``dm/df = kb / (2|f|)``.

``weld`` (per vertex, radians; ``Rod.weld``) is zero except at vertex 0 of a ring welded with a twist: there
edge f's material frame, continued from edge e, is turned by the weld rotation, ``m_v = theta_f + weld_v -
theta_e + reference_twist_v``. The bending kernel turns that frame by the same angle.
"""
import numpy as np
from numba import njit

from .stiffness import twisting_at
from ..stencils import (
    add_cross_matrix, add_outer, add_sym_outer, curvature_binormal_of, edge_vectors, expand_vertex_hessian,
    scatter_band, scatter_vertex_gradient, vadd, vdot, vertex_dofs, vscale,
)


# Editing one of them: numba's cache keys a kernel on its own file only, so also touch energies/vertex.py (its
# fused kernels inline these, and scene.evaluate calls them) or clear the caches, else they run stale.
@njit(cache=True, inline="always")
def _material_twist(q, vertex_edges, reference_twist, weld, v):
    """``material_twist``'s formula, its one home (inlined here and in ``energies.vertex._bend_twist_local``)."""
    return q[4 * vertex_edges[v, 1] + 3] - q[4 * vertex_edges[v, 0] + 3] + reference_twist[v] + weld[v]


@njit(cache=True)
def material_twist(q, vertex_edges, reference_twist, weld, v):
    """Integrated material twist m_v (radians) at vertex v (``weld``: see the module docstring)."""
    return _material_twist(q, vertex_edges, reference_twist, weld, v)


@njit(cache=True, inline="always")
def _twist_rate_row(kb, le, lf, D, c):
    """``D[c]`` <- the gradient of the material twist in (e, f, theta_e, theta_f): ``dm/de = kb / (2|e|)``,
    ``dm/df = kb / (2|f|)``, -1, 1 (its one home: also a row of ``energies.vertex._bend_twist_local``)."""
    for i in range(3):
        D[c, i] = 0.5 * kb[i] / le
        D[c, 3 + i] = 0.5 * kb[i] / lf
    D[c, 6] = -1.0
    D[c, 7] = 1.0


@njit(cache=True)
def _twist_local(q, ed, vertex_edges, reference_twist, weld, v, mbar, stiff, order, g8, H8, work, add=False):
    """Energy of vertex v; with order >= 1 its gradient in (e, f, theta_e, theta_f), order >= 2 the Hessian.
    ``ed`` from ``geometry.edge_frames`` (only its tangents and lengths are used). With ``add`` the gradient and
    Hessian are added to ``g8``, ``H8`` (another term's, e.g. the bending of the same vertex) instead of
    overwriting them."""
    r = _material_twist(q, vertex_edges, reference_twist, weld, v) - mbar
    energy = 0.5 * stiff * r * r
    if order == 0:
        return energy
    te, le, _, _ = edge_vectors(ed, vertex_edges[v, 0])
    tf, lf, _, _ = edge_vectors(ed, vertex_edges[v, 1])
    chi = 1.0 + vdot(te, tf)
    kb = curvature_binormal_of(ed, vertex_edges[v, 0], vertex_edges[v, 1])
    _twist_rate_row(kb, le, lf, work, 0)
    dm = work[0]
    for i in range(8):
        if add:
            g8[i] += stiff * r * dm[i]
        else:
            g8[i] = stiff * r * dm[i]
    if order == 1:
        return energy
    for i in range(8):
        for j in range(8):
            if add:
                H8[i, j] += stiff * dm[i] * dm[j]
            else:
                H8[i, j] = stiff * dm[i] * dm[j]
    s = stiff * r
    tt = vscale(1.0 / chi, vadd(te, tf))
    add_sym_outer(H8, 0, 0, -s / (4.0 * le * le), kb, vadd(te, tt))
    add_sym_outer(H8, 3, 3, -s / (4.0 * lf * lf), kb, vadd(tf, tt))
    Bef = work[2:5, 0:3]
    Bef[:, :] = 0.0
    add_cross_matrix(Bef, 0, 0, s / (le * lf * chi), te)
    add_outer(Bef, 0, 0, -s / (2.0 * le * lf), kb, tt)
    for i in range(3):
        for j in range(3):
            H8[i, 3 + j] += Bef[i, j]
            H8[3 + j, i] += Bef[i, j]
    return energy


@njit(cache=True)
def twist_energy(q, vertex_edges, reference_twist, weld, twist_bar, voronoi, A2):
    """Total twisting energy (it depends on the centreline only through the reference twist)."""
    total = 0.0
    for v in range(vertex_edges.shape[0]):
        r = material_twist(q, vertex_edges, reference_twist, weld, v) - twist_bar[v]
        total += 0.5 * twisting_at(A2, v) / voronoi[v] * r * r
    return total


@njit(cache=True)
def twist_gradient(q, ed, vertex_nodes, vertex_edges, reference_twist, weld, twist_bar, voronoi, A2, grad):
    """Add the twisting energy gradient to ``grad``; returns the energy. ``ed = geometry.edge_frames(...)``."""
    g8 = np.empty(8)
    H8 = np.empty((8, 8))
    work = np.empty((5, 8))
    total = 0.0
    for v in range(vertex_edges.shape[0]):
        total += _twist_local(q, ed, vertex_edges, reference_twist, weld, v, twist_bar[v],
                              twisting_at(A2, v) / voronoi[v], 1, g8, H8, work)
        scatter_vertex_gradient(grad, vertex_nodes[v, 0], vertex_nodes[v, 1], vertex_nodes[v, 2],
                                vertex_edges[v, 0], vertex_edges[v, 1], g8)
    return total


@njit(cache=True)
def twist_hessian(q, ed, vertex_nodes, vertex_edges, reference_twist, weld, twist_bar, voronoi, A2, grad, ab,
                  kl, ku, perm):
    """Add gradient to ``grad`` and Hessian to the band matrix ``ab``; returns the energy."""
    g8 = np.empty(8)
    H8 = np.empty((8, 8))
    H11 = np.empty((11, 11))
    work = np.empty((5, 8))
    dofs = np.empty(11, dtype=np.int64)
    total = 0.0
    for v in range(vertex_edges.shape[0]):
        total += _twist_local(q, ed, vertex_edges, reference_twist, weld, v, twist_bar[v],
                              twisting_at(A2, v) / voronoi[v], 2, g8, H8, work)
        scatter_vertex_gradient(grad, vertex_nodes[v, 0], vertex_nodes[v, 1], vertex_nodes[v, 2],
                                vertex_edges[v, 0], vertex_edges[v, 1], g8)
        expand_vertex_hessian(H8, H11)
        vertex_dofs(vertex_nodes, vertex_edges, v, dofs)
        scatter_band(ab, kl, ku, perm, dofs, H11, 1.0)
    return total
