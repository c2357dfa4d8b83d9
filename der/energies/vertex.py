"""Bending and twisting of each vertex stencil assembled together (the Newton matrix of a rod with both).

The two energies share the vertex's 11 DOFs: adding their local Hessians before the stencil is expanded and
scattered halves the scattering into the band (issue 17). ``stretch_bend_twist_hessian`` also adds the
stretching of each edge into the stencil of one vertex on it (its 6 DOFs are among the 11), which saves the
edges' own scatter. The math is that of ``energies.bend`` and ``energies.twist``; ``bend_hessian`` followed by
``twist_hessian`` gives the same matrix to round-off (the local sums are added in another order).
"""
import numpy as np
from numba import njit
# numba's cache keys a kernel on its own file only: this file was edited with the compensated edges of
# issue 17 (geometry.edge_array's low parts, stencils.curvature_binormal_of / elongation) so that its
# kernels are compiled again with them.

from ..geometry import edge_array
from ..stencils import (
    band_positions, expand_vertex_hessian, scatter_band, scatter_band_at, scatter_vertex_gradient, vertex_dofs,
)
from .bend import _bend_local
from .stiffness import bending_at, twisting_at
from .stretch import _stretch_local
from .twist import _twist_local


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


# positions of an edge's 6 DOFs [x_a (3), x_b (3)] in the vertex stencil [x0, theta_e, x1, theta_f, x2]
_EDGE_IN_STENCIL = ((0, 1, 2, 4, 5, 6), (4, 5, 6, 8, 9, 10))


@njit(cache=True)
def stretch_bend_twist_hessian(q, ed, edge_nodes, vertex_nodes, vertex_edges, l_bar, k_stretch, lam, reference_twist,
                               weld, kappa_bar, twist_bar, voronoi, A1, A2, grad, ab, kl, ku, perm, E=None):
    """``bend_twist_hessian`` plus the stretching of every edge (as ``stretch_hessian``), each edge added into the
    stencil of the first vertex that holds it (its edge after, else before). Returns ``(stretch, bending,
    twisting)`` energies. ``E``: the edge vectors (``geometry.edge_array``; formed from ``q`` if None)."""
    return _stretch_bend_twist(q, ed, edge_nodes, vertex_nodes, vertex_edges, l_bar, k_stretch, lam, reference_twist,
                               weld, kappa_bar, twist_bar, voronoi, A1, A2, grad, ab, kl, ku, perm, E, 2,
                               np.empty((0, 3)), np.empty(0))


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
    if F is None or M is None:
        return _stretch_bend_twist(q, ed, edge_nodes, vertex_nodes, vertex_edges, l_bar, k_stretch, lam,
                                   reference_twist, weld, kappa_bar, twist_bar, voronoi, A1, A2, grad, ab, 0, 0,
                                   perm, E, 1, np.empty((0, 3)), np.empty(0))
    return _stretch_bend_twist(q, ed, edge_nodes, vertex_nodes, vertex_edges, l_bar, k_stretch, lam, reference_twist,
                               weld, kappa_bar, twist_bar, voronoi, A1, A2, grad, ab, 0, 0, perm, E, 1, F, M)


@njit(cache=True, inline="always")
def _stretch_bend_twist(q, ed, edge_nodes, vertex_nodes, vertex_edges, l_bar, k_stretch, lam, reference_twist,
                        weld, kappa_bar, twist_bar, voronoi, A1, A2, grad, ab, kl, ku, perm, E, order, F, M):
    """The pass of ``stretch_bend_twist_hessian`` (order 2) and ``stretch_bend_twist_gradient`` (order 1; with a
    non-empty ``F`` also the edge forces and vertex moments of ``diagnostics._edge_forces``)."""
    Ee = edge_array(q, edge_nodes) if E is None else E
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
    for v in range(vertex_edges.shape[0]):
        for s in (1, 0):
            j = vertex_edges[v, s]
            if owner[j] < 0:
                owner[j] = v
                side[j] = s
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
        eb = _bend_local(ed, vertex_edges, weld, v, kappa_bar, a1 / voronoi[v], a2 / voronoi[v], order, g8, H8, work)
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
        else:
            e_twist += _twist_local(q, ed, vertex_edges, reference_twist, weld, v, twist_bar[v],
                                    twisting_at(A2, v) / voronoi[v], order, g8,
                                    H8, work, True)
        scatter_vertex_gradient(grad, vertex_nodes[v, 0], vertex_nodes[v, 1], vertex_nodes[v, 2],
                                vertex_edges[v, 0], vertex_edges[v, 1], g8)
        if order >= 2:
            expand_vertex_hessian(H8, H11)
        for s in range(2):
            j = vertex_edges[v, s]
            if owner[j] != v or side[j] != s:
                continue
            if want_f:
                e_stretch += e6s[s]
                for i in range(6):
                    g6[i] = g6s[s, i]
            else:
                e_stretch += _stretch_local(Ee, j, l_bar[j], k_stretch[j], lam[j], order, g6, H6)
            a = 4 * edge_nodes[j, 0]
            c = 4 * edge_nodes[j, 1]
            for i in range(3):
                grad[a + i] += g6[i]
                grad[c + i] += g6[3 + i]
            if order >= 2:
                m = _EDGE_IN_STENCIL[s]
                for r in range(6):
                    for t in range(6):
                        H11[m[r], m[t]] += H6[r, t]
        if order >= 2:
            vertex_dofs(vertex_nodes, vertex_edges, v, dofs)
            contiguous = band_positions(perm, dofs, pos)
            scatter_band_at(ab, kl, ku, pos, contiguous, H11)
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
