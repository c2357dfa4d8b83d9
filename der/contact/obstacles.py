"""Rigid obstacles: a plane (floor), a sphere and an infinite cylinder, against the rod's edges, offset by r.

Each obstacle is (kind, params (7,)): PLANE params = (point p (3), unit normal n (3), 0): the rod lives on
the side n points to; SPHERE params = (centre c (3), 0, 0, 0, radius R); CYLINDER params = (point c on the
axis (3), unit axis direction a (3), radius R). The rod stays outside the sphere and the cylinder.

Distances are exact for edges, not only nodes:
- plane: the signed distance (x - p) . n is linear, so an edge's nearest point is one of its nodes: the
  barrier is put on the nodes (gap z = (x - p) . n - r), exact for the edges;
- sphere: the edge's distance to the centre is a point-segment distance, i.e. the segment distance to the
  degenerate segment [c, c]; gap z = dist - R - r;
- cylinder: with P = I - a a^T the projection across the axis, the distance of a point to the axis is |P(x - c)|,
  so the edge's distance to the axis is the point-segment distance of the projected segment to P c (in the
  plane across the axis); gap z = dist - R - r. Derivatives by the chain rule (x -> P x, P symmetric).
The barrier is the one of barrier.py in GAP mode. CCD: planes exactly (the gap is linear in tau), spheres and
cylinders by the conservative advancement of ccd.py against a static (projected) point.
"""
import numpy as np
from numba import njit

from .barrier import barrier, barrier_first_derivative, barrier_second_derivative
from .ccd import segment_ccd
from .distance import segment_distance2, segment_distance2_derivatives

PLANE, SPHERE, CYLINDER = 0, 1, 2


@njit(cache=True)
def _edge_vs_point_x(pos, a, b, c, proj, axis, x):
    """x (12,) = [P a, P b, P c, P c] (P = identity if not proj)."""
    for k, src in enumerate((pos[a], pos[b], c, c)):
        for i in range(3):
            x[3 * k + i] = src[i]
        if proj:
            d = x[3 * k] * axis[0] + x[3 * k + 1] * axis[1] + x[3 * k + 2] * axis[2]
            for i in range(3):
                x[3 * k + i] -= d * axis[i]


@njit(cache=True)
def edge_obstacle_gap(pos, a, b, kind, params, radius):
    """Gap between edge (a, b) (node indices into pos (n_nodes, 3)) of radius r and the obstacle (length)."""
    if kind == PLANE:
        g = np.inf
        for node in (a, b):
            s = 0.0
            for i in range(3):
                s += (pos[node, i] - params[i]) * params[3 + i]
            g = min(g, s - radius)
        return g
    x = np.empty(12)
    _edge_vs_point_x(pos, a, b, params[0:3], kind == CYLINDER, params[3:6], x)
    return np.sqrt(segment_distance2(x)) - params[6] - radius


@njit(cache=True)
def edge_obstacle_barrier(pos, a, b, kind, params, radius, dhat, kappa, grad6, hess6):
    """Barrier energy of edge (a, b) against a sphere or cylinder; writes d/d[x_a, x_b] (6,) and the 6x6
    Hessian (not projected). Returns (energy, gap). For planes use node_plane_barrier."""
    x = np.empty(12)
    dD = np.empty(12)
    HD = np.empty((12, 12))
    proj = kind == CYLINDER
    axis = params[3:6]
    _edge_vs_point_x(pos, a, b, params[0:3], proj, axis, x)
    D, region = segment_distance2_derivatives(x, dD, HD)
    dist = np.sqrt(D)
    z = dist - params[6] - radius
    grad6.fill(0.0)
    hess6.fill(0.0)
    if z >= dhat:
        return 0.0, z
    if z <= 0.0:
        return np.inf, z
    z1, z2 = 0.5 / dist, -0.25 / (dist * D)
    b1 = barrier_first_derivative(z, dhat)
    b2 = barrier_second_derivative(z, dhat)
    c1 = kappa * b1 * z1
    c2 = kappa * (b2 * z1 * z1 + b1 * z2)
    for m in range(6):
        grad6[m] = c1 * dD[m]
        for n in range(6):
            hess6[m, n] = c2 * dD[m] * dD[n] + c1 * HD[m, n]
    if proj:
        # chain rule through x -> P x on each node: g <- P g, H <- P H P (blockwise)
        T = np.zeros((6, 6))
        for blk in range(2):
            for i in range(3):
                for j in range(3):
                    T[3 * blk + i, 3 * blk + j] = (1.0 if i == j else 0.0) - axis[i] * axis[j]
        g = np.zeros(6)
        TH = np.zeros((6, 6))
        for i in range(6):
            for l in range(6):
                g[i] += T[i, l] * grad6[l]
                for j in range(6):
                    TH[i, j] += T[i, l] * hess6[l, j]
        for i in range(6):
            grad6[i] = g[i]
            for j in range(6):
                acc = 0.0
                for l in range(6):
                    acc += TH[i, l] * T[l, j]
                hess6[i, j] = acc
    return kappa * barrier(z, dhat), z


@njit(cache=True)
def node_plane_barrier(x, params, radius, dhat, kappa, grad3, hess3):
    """Barrier of a node x (3,) against a plane; writes gradient (3,) and Hessian (3, 3). Returns
    (energy, gap)."""
    z = -radius
    for i in range(3):
        z += (x[i] - params[i]) * params[3 + i]
    grad3.fill(0.0)
    hess3.fill(0.0)
    if z >= dhat:
        return 0.0, z
    if z <= 0.0:
        return np.inf, z
    b1 = kappa * barrier_first_derivative(z, dhat)
    b2 = kappa * barrier_second_derivative(z, dhat)
    for i in range(3):
        grad3[i] = b1 * params[3 + i]
        for j in range(3):
            hess3[i, j] = b2 * params[3 + i] * params[3 + j]
    return kappa * barrier(z, dhat), z


@njit(cache=True)
def edge_obstacle_ccd(pos0, dpos, a, b, kind, params, radius, min_gap_fraction, tol, max_iter):
    """Safe step fraction tau in [0, 1]: the edge's gap to the obstacle stays >= min_gap_fraction times its
    start value on [0, tau]. Returns (tau, iterations); (0, -1) if the start already violates the gap."""
    if kind == PLANE:
        tau = 1.0
        for node in (a, b):
            g0 = -radius
            rate = 0.0
            for i in range(3):
                g0 += (pos0[node, i] - params[i]) * params[3 + i]
                rate += dpos[node, i] * params[3 + i]
            if g0 <= 0.0:
                return 0.0, -1
            if rate < 0.0:
                tau = min(tau, (1.0 - min_gap_fraction) * g0 / -rate)   # exact: the gap is linear in tau
        return tau, 0
    x0 = np.empty(12)
    _edge_vs_point_x(pos0, a, b, params[0:3], kind == CYLINDER, params[3:6], x0)
    dx = np.zeros(12)
    zero = np.zeros(3)
    disp = np.zeros((2, 3))
    disp[0] = dpos[a]
    disp[1] = dpos[b]
    for k in range(2):
        d = 0.0
        if kind == CYLINDER:
            for i in range(3):
                d += disp[k, i] * params[3 + i]
        for i in range(3):
            dx[3 * k + i] = disp[k, i] - d * params[3 + i]
    return segment_ccd(x0, dx, params[6] + radius, min_gap_fraction, tol, max_iter)
