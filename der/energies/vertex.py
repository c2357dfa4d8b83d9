"""Bending and twisting of each vertex stencil assembled together (the Newton matrix of a rod with both).

The two energies share the vertex's 11 DOFs: adding their local Hessians before the stencil is expanded and
scattered halves the scattering into the band (issue 17). ``stretch_bend_twist_hessian`` also adds the
stretching of each edge into the stencil of one vertex on it (its 6 DOFs are among the 11), which saves the
edges' own scatter. The math is that of ``energies.bend`` and ``energies.twist``; ``bend_hessian`` followed by
``twist_hessian`` gives the same matrix to round-off (the local sums are added in another order).
"""
import numpy as np
from numba import njit

from ..geometry import edge_array
from ..stencils import expand_vertex_hessian, scatter_band, scatter_vertex_gradient, vertex_dofs
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
    Ee = edge_array(q, edge_nodes) if E is None else E
    n_edges = edge_nodes.shape[0]
    g8 = np.empty(8)
    H8 = np.empty((8, 8))
    H11 = np.empty((11, 11))
    g6 = np.empty(6)
    H6 = np.empty((6, 6))
    work = np.empty((5, 8))
    dofs = np.empty(11, dtype=np.int64)
    d6 = np.empty(6, dtype=np.int64)
    owner = np.full(n_edges, -1, dtype=np.int64)   # the vertex that carries edge j's stretching
    side = np.zeros(n_edges, dtype=np.int64)       # 0: it is that vertex's edge before, 1: after
    for v in range(vertex_edges.shape[0]):
        for s in (1, 0):
            j = vertex_edges[v, s]
            if owner[j] < 0:
                owner[j] = v
                side[j] = s
    e_stretch = e_bend = e_twist = 0.0
    for v in range(vertex_edges.shape[0]):
        a1, a2 = bending_at(A1, v)
        e_bend += _bend_local(ed, vertex_edges, weld, v, kappa_bar, a1 / voronoi[v], a2 / voronoi[v], 2, g8, H8, work)
        e_twist += _twist_local(q, ed, vertex_edges, reference_twist, weld, v, twist_bar[v],
                                twisting_at(A2, v) / voronoi[v], 2, g8,
                                H8, work, True)
        scatter_vertex_gradient(grad, vertex_nodes[v, 0], vertex_nodes[v, 1], vertex_nodes[v, 2],
                                vertex_edges[v, 0], vertex_edges[v, 1], g8)
        expand_vertex_hessian(H8, H11)
        for s in range(2):
            j = vertex_edges[v, s]
            if owner[j] != v or side[j] != s:
                continue
            e_stretch += _stretch_local(Ee, j, l_bar[j], k_stretch[j], lam[j], 2, g6, H6)
            a = 4 * edge_nodes[j, 0]
            c = 4 * edge_nodes[j, 1]
            for i in range(3):
                grad[a + i] += g6[i]
                grad[c + i] += g6[3 + i]
            m = _EDGE_IN_STENCIL[s]
            for r in range(6):
                for t in range(6):
                    H11[m[r], m[t]] += H6[r, t]
        vertex_dofs(vertex_nodes, vertex_edges, v, dofs)
        scatter_band(ab, kl, ku, perm, dofs, H11, 1.0)
    for j in range(n_edges):   # edges on no vertex (a single-edge rod)
        if owner[j] < 0:
            e_stretch += _stretch_local(Ee, j, l_bar[j], k_stretch[j], lam[j], 2, g6, H6)
            a = 4 * edge_nodes[j, 0]
            c = 4 * edge_nodes[j, 1]
            for i in range(3):
                d6[i] = a + i
                d6[3 + i] = c + i
                grad[a + i] += g6[i]
                grad[c + i] += g6[3 + i]
            scatter_band(ab, kl, ku, perm, d6, H6, 1.0)
    return e_stretch, e_bend, e_twist
