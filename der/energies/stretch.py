"""Stretching: the (near-)inextensibility of the centreline.

Per edge ``j`` with rest length ``l_j`` and elongation ``g_j = |e_j| - l_j``:

    E_j = lam_j g_j + 1/2 k_j g_j^2

* an extensible rod of axial stiffness EA has ``k_j = EA / l_j`` and ``lam_j = 0`` (``E = EA/2 l eps^2``);
* the inextensible rod of the paper (the default) uses the same term as an augmented Lagrangian: ``lam_j`` is
  the multiplier (the tension) updated by the solver, ``k_j`` a moderate penalty, so that ``g -> 0`` without
  the ill-conditioning and round-off floor of a huge EA.

The tension carried by edge j is ``lam_j + k_j g_j`` (units of force).
"""
import numpy as np
from numba import njit

from ..geometry import edge_array
from ..stencils import edge_dofs, elongation, scatter_band, scatter_gradient


@njit(cache=True)
def _stretch_local(E, j, l_bar, k, lam, order, g6, H6):
    """Energy of edge j; gradient ``g6`` in (x_a, x_b) with order >= 1, Hessian ``H6`` with order >= 2. ``E``:
    the edge vectors (``geometry.edge_array``; with their low parts, 6 columns, the elongation is formed without
    cancellation, ``stencils.elongation``)."""
    e0 = E[j, 0]
    e1 = E[j, 1]
    e2 = E[j, 2]
    g, le = elongation(E, j, l_bar)
    energy = lam * g + 0.5 * k * g * g
    if order == 0:
        return energy
    tension = lam + k * g
    t = (e0 / le, e1 / le, e2 / le)
    for i in range(3):
        g6[i] = -tension * t[i]
        g6[3 + i] = tension * t[i]
    if order == 1:
        return energy
    c = tension / le
    for i in range(3):
        for jj in range(3):
            h = (k - c) * t[i] * t[jj]
            if i == jj:
                h += c
            H6[i, jj] = h
            H6[3 + i, 3 + jj] = h
            H6[i, 3 + jj] = -h
            H6[3 + i, jj] = -h
    return energy


@njit(cache=True)
def stretch_energy(q, edge_nodes, l_bar, k, lam, E=None):
    """Total stretching energy (including the multiplier term)."""
    Ee = edge_array(q, edge_nodes) if E is None else E
    g6 = np.empty(6)
    H6 = np.empty((6, 6))
    total = 0.0
    for j in range(edge_nodes.shape[0]):
        total += _stretch_local(Ee, j, l_bar[j], k[j], lam[j], 0, g6, H6)
    return total


@njit(cache=True)
def stretch_gradient(q, edge_nodes, l_bar, k, lam, grad, E=None):
    """Add the stretching gradient to ``grad``; returns the energy."""
    Ee = edge_array(q, edge_nodes) if E is None else E
    g6 = np.empty(6)
    H6 = np.empty((6, 6))
    total = 0.0
    for j in range(edge_nodes.shape[0]):
        total += _stretch_local(Ee, j, l_bar[j], k[j], lam[j], 1, g6, H6)
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        for i in range(3):
            grad[a + i] += g6[i]
            grad[b + i] += g6[3 + i]
    return total


@njit(cache=True)
def stretch_hessian(q, edge_nodes, l_bar, k, lam, grad, ab, kl, ku, perm, E=None):
    """Add gradient to ``grad`` and Hessian to the band matrix ``ab``; returns the energy.

    (Edited with ``stencils.scatter_band``: numba's cache keys a kernel on its own file only, so a kernel whose
    helper in another file changed keeps the old helper compiled in until its own file changes.)"""
    Ee = edge_array(q, edge_nodes) if E is None else E
    g6 = np.empty(6)
    H6 = np.empty((6, 6))
    dofs = np.empty(6, dtype=np.int64)
    total = 0.0
    for j in range(edge_nodes.shape[0]):
        total += _stretch_local(Ee, j, l_bar[j], k[j], lam[j], 2, g6, H6)
        edge_dofs(edge_nodes, j, dofs)
        scatter_gradient(grad, dofs, g6, 1.0)
        scatter_band(ab, kl, ku, perm, dofs, H6, 1.0)
    return total


@njit(cache=True)
def elongations(q, edge_nodes, l_bar, E=None):
    """g_j = |e_j| - l_j for all edges (edges ``E`` from ``geometry.edge_array`` when given, else from q; with
    the low parts of the edges, as the energy kernels take them, without cancellation)."""
    Ee = edge_array(q, edge_nodes) if E is None else E
    n = edge_nodes.shape[0]
    out = np.empty(n)
    for j in range(n):
        out[j] = elongation(Ee, j, l_bar[j])[0]
    return out
