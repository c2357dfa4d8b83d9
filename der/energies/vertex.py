"""Bending and twisting of each vertex stencil assembled together (the Newton matrix of a rod with both).

The two energies share the vertex's 11 DOFs: adding their local Hessians before the stencil is expanded and
scattered halves the traffic into the band, which dominates the assembly once the band outgrows the cache
(issue 17). The math is that of ``energies.bend`` and ``energies.twist``; ``bend_hessian`` followed by
``twist_hessian`` gives the same matrix to round-off (the local sums are added in another order).
"""
import numpy as np
from numba import njit

from ..stencils import expand_vertex_hessian, scatter_band, scatter_vertex_gradient, vertex_dofs
from .bend import _bend_local
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
        b = A1 / voronoi[v]
        e_bend += _bend_local(ed, vertex_edges, weld, v, kappa_bar, b, b, 2, g8, H8, work)
        e_twist += _twist_local(q, ed, vertex_edges, reference_twist, weld, v, twist_bar[v], A2 / voronoi[v], 2, g8,
                                H8, work, True)   # added onto the bending of the same vertex
        scatter_vertex_gradient(grad, vertex_nodes[v, 0], vertex_nodes[v, 1], vertex_nodes[v, 2],
                                vertex_edges[v, 0], vertex_edges[v, 1], g8)
        expand_vertex_hessian(H8, H11)
        vertex_dofs(vertex_nodes, vertex_edges, v, dofs)
        scatter_band(ab, kl, ku, perm, dofs, H11, 1.0)
    return e_bend, e_twist
