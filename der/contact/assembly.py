"""Kernels the Scene's contact terms (der/terms) call inside a solve: energy-only sums for the line search,
obstacle barriers assembled into the band, the obstacle CCD over all edges, and the diagnostics (pair forces,
closest points, the minimal distance over all non-neighbour pairs).

Layout as in barrier.py: positions (n_nodes, 3); edges (n_edges, 2); pairs (n_pairs, 2) edge indices;
node_dof (n_nodes,) the index of each node's x in the DOF vector. Band storage as in der/linalg.py:
``ab[kl + ku + perm[i] - perm[j], perm[j]] = A[i, j]``.
"""
import numpy as np
from numba import njit

from .barrier import barrier, barrier_first_derivative
from .broadphase import excluded
from .distance import closest_parameters, segment_distance2
from .obstacles import PLANE, edge_obstacle_barrier, edge_obstacle_ccd, edge_obstacle_gap, node_plane_barrier


@njit(cache=True)
def _pair_x(pos, edges, ea, eb, x):
    nodes = (edges[ea, 0], edges[ea, 1], edges[eb, 0], edges[eb, 1])
    for k in range(4):
        for i in range(3):
            x[3 * k + i] = pos[nodes[k], i]


@njit(cache=True)
def pairs_energy(pos, edges, pairs, edge_radius, dhat, kappa):
    """Barrier energy kappa sum b(gap) of the pairs (GAP variable); +inf if a pair overlaps (gap <= 0)."""
    x = np.empty(12)
    e = 0.0
    for p in range(pairs.shape[0]):
        ea, eb = pairs[p, 0], pairs[p, 1]
        _pair_x(pos, edges, ea, eb, x)
        z = np.sqrt(segment_distance2(x)) - edge_radius[ea] - edge_radius[eb]
        if z <= 0.0:
            return np.inf
        if z < dhat:
            e += barrier(z, dhat)
    return kappa * e


@njit(cache=True)
def pair_forces(pos, edges, pairs, edge_radius, dhat, kappa, gap, force, point_a, point_b):
    """For each pair: its gap (length), the magnitude of the contact force -kappa b'(gap) >= 0 (0 beyond dhat)
    and the closest points on the two centrelines (the force acts along point_a - point_b on edge a)."""
    x = np.empty(12)
    for p in range(pairs.shape[0]):
        ea, eb = pairs[p, 0], pairs[p, 1]
        _pair_x(pos, edges, ea, eb, x)
        D, s, t, _ = closest_parameters(x)
        for i in range(3):
            point_a[p, i] = (1.0 - s) * x[i] + s * x[3 + i]
            point_b[p, i] = (1.0 - t) * x[6 + i] + t * x[9 + i]
        z = np.sqrt(D) - edge_radius[ea] - edge_radius[eb]
        gap[p] = z
        force[p] = -kappa * barrier_first_derivative(z, dhat) if 0.0 < z < dhat else (np.inf if z <= 0 else 0.0)


@njit(cache=True)
def min_pair_gap(pos, edges, rod_of_edge, local_edge, rod_n_edges, rod_closed, rod_k, edge_radius):
    """Smallest gap dist - (r_a + r_b) over every pair of non-neighbour edges (brute force, O(n^2): for
    diagnostics and start checks only). Returns (gap, edge a, edge b); (inf, -1, -1) if there is no pair."""
    x = np.empty(12)
    best, ba, bb = np.inf, -1, -1
    m = edges.shape[0]
    for i in range(m):
        for j in range(i + 1, m):
            if excluded(i, j, rod_of_edge, local_edge, rod_n_edges, rod_closed, rod_k):
                continue
            _pair_x(pos, edges, i, j, x)
            g = np.sqrt(segment_distance2(x)) - edge_radius[i] - edge_radius[j]
            if g < best:
                best, ba, bb = g, i, j
    return best, ba, bb


@njit(cache=True)
def _add_band(ab, kl, ku, perm, i, j, v):
    ab[kl + ku + perm[i] - perm[j], perm[j]] += v


@njit(cache=True)
def obstacle_system(pos, edges, radius, kind, params, dhat, kappa, order, node_dof, grad, ab, kl, ku, perm, project):
    """Barrier of one obstacle against every node (plane) or edge (sphere, cylinder) of radius ``radius``.

    order 0: energy only; 1: also adds dE/dq into grad; 2: also adds the PSD-projected Hessian into the band
    ``ab`` (blocks of one node or of the two nodes of an edge: inside the band; not projected if not
    ``project``). Returns (energy, n_active,
    min_gap, largest nodal contact force); energy is +inf if something overlaps the obstacle."""
    energy = 0.0
    n_active = 0
    min_gap = np.inf
    if kind == PLANE:
        n_nodes = pos.shape[0]
        g3 = np.empty(3)
        h3 = np.empty((3, 3))
        fmax = 0.0
        for k in range(n_nodes):
            e, z = node_plane_barrier(pos[k], params, radius, dhat, kappa, g3, h3)
            min_gap = min(min_gap, z)
            if z >= dhat:
                continue
            if z <= 0.0:
                return np.inf, n_active, min_gap, np.inf
            energy += e
            n_active += 1
            fmax = max(fmax, np.sqrt(g3[0] ** 2 + g3[1] ** 2 + g3[2] ** 2))
            if order >= 1:
                for i in range(3):
                    grad[node_dof[k] + i] += g3[i]
            if order >= 2:
                for i in range(3):
                    for j in range(3):
                        _add_band(ab, kl, ku, perm, node_dof[k] + i, node_dof[k] + j, h3[i, j])   # b'' n n^T >= 0
        return energy, n_active, min_gap, fmax
    g6 = np.empty(6)
    h6 = np.empty((6, 6))
    fnode = np.zeros(pos.shape[0])
    for ed in range(edges.shape[0]):
        a, b = edges[ed, 0], edges[ed, 1]
        z = edge_obstacle_gap(pos, a, b, kind, params, radius)
        min_gap = min(min_gap, z)
        if z >= dhat:
            continue
        if z <= 0.0:
            return np.inf, n_active, min_gap, np.inf
        e, z = edge_obstacle_barrier(pos, a, b, kind, params, radius, dhat, kappa, g6, h6)
        energy += e
        n_active += 1
        fnode[a] += np.sqrt(g6[0] ** 2 + g6[1] ** 2 + g6[2] ** 2)
        fnode[b] += np.sqrt(g6[3] ** 2 + g6[4] ** 2 + g6[5] ** 2)
        if order >= 1:
            for i in range(3):
                grad[node_dof[a] + i] += g6[i]
                grad[node_dof[b] + i] += g6[3 + i]
        if order >= 2:
            H = h6
            if project:
                w, V = np.linalg.eigh(0.5 * (h6 + h6.T))      # eigen-clamp the 6x6 block to PSD (as IPC)
                for m in range(6):
                    w[m] = max(w[m], 0.0)
                H = (V * w) @ V.T
            for m in range(6):
                dm = node_dof[a] + m if m < 3 else node_dof[b] + m - 3
                for n in range(6):
                    dn = node_dof[a] + n if n < 3 else node_dof[b] + n - 3
                    _add_band(ab, kl, ku, perm, dm, dn, H[m, n])
    return energy, n_active, min_gap, fnode.max() if fnode.size else 0.0


@njit(cache=True)
def obstacle_step(pos0, dpos, edges, radius, kind, params, min_gap_fraction, tol, max_iter):
    """Largest safe fraction tau of the step for every edge against the obstacle (edge_obstacle_ccd), each edge
    searched only while its start gap is within reach of the step. Returns (tau, limiting edge or -1)."""
    tau, worst = 1.0, -1
    for ed in range(edges.shape[0]):
        a, b = edges[ed, 0], edges[ed, 1]
        g0 = edge_obstacle_gap(pos0, a, b, kind, params, radius)
        reach = 0.0
        for i in range(3):
            reach = max(reach, abs(dpos[a, i]), abs(dpos[b, i]))
        if g0 > 2.0 * np.sqrt(3.0) * reach * tau:
            continue        # it cannot move (1 - f) g0 closer within [0, tau]
        t, it = edge_obstacle_ccd(pos0, dpos, a, b, kind, params, radius, min_gap_fraction, tol, max_iter)
        if it < 0:
            return 0.0, ed
        if t < tau:
            tau, worst = t, ed
    return tau, worst
