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


# ---- the formulas of one edge, one home each: called by ``_stretch_local`` and by the fused vertex pass
# (``energies.vertex._stretch_local_upper``), which then computes the same floating-point operations in the same
# order (``tools/kernel_fingerprint.py`` checks it bitwise).
# Editing one of them: numba's cache keys a kernel on its own file only, so also touch energies/vertex.py (its
# fused kernels inline these, and scene.evaluate calls them) or clear the caches, else they run stale.


@njit(cache=True, inline="always")
def _stretch_energy_of(g, k, lam):
    """E_j = lam g + k g^2 / 2 of an edge with elongation ``g``."""
    return lam * g + 0.5 * k * g * g


@njit(cache=True, inline="always")
def _stretch_tension(E, j, g, le, k, lam, g6):
    """``g6`` <- the gradient of edge j's stretching in (x_a, x_b), -T t and T t; returns ``(T, t)``: the tension
    T = lam + k g and the unit tangent t = e_j / |e_j| (``le`` = |e_j|)."""
    tension = lam + k * g
    t = (E[j, 0] / le, E[j, 1] / le, E[j, 2] / le)
    for i in range(3):
        g6[i] = -tension * t[i]
        g6[3 + i] = tension * t[i]
    return tension, t


@njit(cache=True, inline="always")
def _stretch_hessian_entry(k, c, t, i, jj):
    """Entry (i, jj) of the x_a x_a block of the stretching Hessian, (k - c) t t^T + c I with c = T / |e_j| (the
    x_b x_b block is the same, the x_a x_b blocks its negative)."""
    h = (k - c) * t[i] * t[jj]
    if i == jj:
        h += c
    return h


@njit(cache=True)
def _stretch_local(E, j, l_bar, k, lam, order, g6, H6):
    """Energy of edge j; gradient ``g6`` in (x_a, x_b) with order >= 1, Hessian ``H6`` with order >= 2. ``E``:
    the edge vectors (``geometry.edge_array``; with their low parts, 6 columns, the elongation is formed without
    cancellation, ``stencils.elongation``)."""
    g, le = elongation(E, j, l_bar)
    energy = _stretch_energy_of(g, k, lam)
    if order == 0:
        return energy
    tension, t = _stretch_tension(E, j, g, le, k, lam, g6)
    if order == 1:
        return energy
    c = tension / le
    for i in range(3):
        for jj in range(3):
            h = _stretch_hessian_entry(k, c, t, i, jj)
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


@njit(cache=True)
def chord_excess_forces(E, edge_nodes, delta, k, out):
    """The generalized forces ``out`` (n_dof) <- -J^T (k g2) of the elongation a straight-line step ``delta``
    adds beyond its linearisation, and the largest |g2|: for edge j with vector e_j (``E``, rounded high parts)
    and step d_j = delta_b - delta_a,

        g2_j = |e_j + d_j| - |e_j| - t_j . d_j = |d_perp|^2 / (|e_j + d_j| + |e_j| + t_j . d_j)

    (t_j = e_j / |e_j|, d_perp the part of d_j across the edge; the quotient has no cancellation): the chord
    error of a step that turns the edge, O(|d|^2 / |e|), which the linearised elongation t . d does not see. J is
    the elongation's Jacobian at ``E`` (dg_j/dx_b = t_j = -dg_j/dx_a). A step that reverses an edge (a
    non-positive denominator) contributes nothing. The second-order correction of the implicit solver solves
    K c = -J^T (k g2) (``SolverOptions.second_order_correction``). Entries of ``out`` that no edge touches (the
    angles) are 0."""
    for i in range(out.shape[0]):
        out[i] = 0.0
    worst = 0.0
    for j in range(edge_nodes.shape[0]):
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        e0, e1, e2 = E[j, 0], E[j, 1], E[j, 2]
        le = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        if not le > 0.0:
            continue
        t0, t1, t2 = e0 / le, e1 / le, e2 / le
        d0 = delta[b] - delta[a]
        d1 = delta[b + 1] - delta[a + 1]
        d2 = delta[b + 2] - delta[a + 2]
        td = t0 * d0 + t1 * d1 + t2 * d2
        p0, p1, p2 = d0 - td * t0, d1 - td * t1, d2 - td * t2
        f0, f1, f2 = e0 + d0, e1 + d1, e2 + d2
        den = np.sqrt(f0 * f0 + f1 * f1 + f2 * f2) + le + td
        if not den > 0.0:
            continue
        g2 = (p0 * p0 + p1 * p1 + p2 * p2) / den
        worst = max(worst, abs(g2))
        f = k[j] * g2
        out[a] += f * t0
        out[a + 1] += f * t1
        out[a + 2] += f * t2
        out[b] -= f * t0
        out[b + 1] -= f * t1
        out[b + 2] -= f * t2
    return worst
