"""Squared distance between two 3D segments, with its gradient and Hessian in the 12 endpoint coordinates.

Segments a = [a0, a1], b = [b0, b1]; points a(s) = (1 - s) a0 + s a1, b(t) = (1 - t) b0 + t b1, s, t in [0, 1].
The squared distance D = min_{s,t} |r|^2 with r = a(s) - b(t) is a convex quadratic in (s, t) on the unit square,
so its minimiser is either the unconstrained (line-line) stationary point, when that lies inside the square,
or lies on one of the four sides, each side being a point-segment distance (a0 or a1 against b, b0 or b1
against a), which in turn is point-line or point-point. This is IPC's case analysis (edge-edge, point-edge,
point-point regions) reached by exhaustion instead of by region tests, which keeps it robust:

- parallel or nearly parallel segments (|u x v|^2 <= 1e-12 |u|^2 |v|^2) skip the line-line candidate: the
  minimum of a degenerate (rank-1) quadratic on the square is also attained on its boundary;
- a degenerate segment (zero length) is a point: its point-segment candidates reduce to point-point.

Derivatives by the closest-point parametrisation: with y the free closest-point parameters (none, s, t or
both), dD/dx = 2 J^T r (envelope theorem, dD/dy = 0 at the minimiser) and
d2D/dx2 = H_xx - H_xy H_yy^{-1} H_yx (implicit function theorem: dy/dx = -H_yy^{-1} H_yx), exact inside each
region. D is C1 across region boundaries, its Hessian jumps there (as in IPC).

Layout: x is a flat (12,) float64 array [a0, a1, b0, b1]; gradients (12,), Hessians (12, 12).
Units: D in length^2.
"""
import numpy as np
from numba import njit

PARALLEL_EPS = 1e-12   # |u x v|^2 <= PARALLEL_EPS |u|^2 |v|^2: treated as parallel (no interior candidate)

# region codes returned by closest_parameters (which parameters are free)
POINT_POINT, S_FREE, T_FREE, EDGE_EDGE = 0, 1, 2, 3


@njit(cache=True)
def _point_segment(px, py, pz, ax, ay, az, bx, by, bz):
    """Squared distance from p to segment [a, b] and the clamped parameter t (0 <= t <= 1); free flag."""
    ux, uy, uz = bx - ax, by - ay, bz - az
    uu = ux * ux + uy * uy + uz * uz
    t = 0.0
    free = False
    if uu > 0.0:
        t = ((px - ax) * ux + (py - ay) * uy + (pz - az) * uz) / uu
        if t <= 0.0:
            t = 0.0
        elif t >= 1.0:
            t = 1.0
        else:
            free = True
    rx, ry, rz = ax + t * ux - px, ay + t * uy - py, az + t * uz - pz
    return rx * rx + ry * ry + rz * rz, t, free


@njit(cache=True)
def closest_parameters(x):
    """Closest-point parameters of segments a = x[0:6], b = x[6:12].

    Returns (D, s, t, region): the squared distance, the parameters in [0, 1] and which of them are free
    (POINT_POINT, S_FREE, T_FREE, EDGE_EDGE).
    """
    ux, uy, uz = x[3] - x[0], x[4] - x[1], x[5] - x[2]
    vx, vy, vz = x[9] - x[6], x[10] - x[7], x[11] - x[8]
    wx, wy, wz = x[0] - x[6], x[1] - x[7], x[2] - x[8]
    a = ux * ux + uy * uy + uz * uz
    b = ux * vx + uy * vy + uz * vz
    c = vx * vx + vy * vy + vz * vz
    d = ux * wx + uy * wy + uz * wz
    e = vx * wx + vy * wy + vz * wz
    cx, cy, cz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    den = cx * cx + cy * cy + cz * cz          # = a c - b^2, without its cancellation
    if a > 0.0 and c > 0.0 and den > PARALLEL_EPS * a * c:
        s = (b * e - c * d) / den
        t = (a * e - b * d) / den
        if 0.0 < s < 1.0 and 0.0 < t < 1.0:
            rx, ry, rz = wx + s * ux - t * vx, wy + s * uy - t * vy, wz + s * uz - t * vz
            return rx * rx + ry * ry + rz * rz, s, t, EDGE_EDGE
    # boundary of the square: the four point-segment distances
    best, bs, bt, breg = np.inf, 0.0, 0.0, POINT_POINT
    D, tt, free = _point_segment(x[0], x[1], x[2], x[6], x[7], x[8], x[9], x[10], x[11])   # a0 vs b (s = 0)
    if D < best:
        best, bs, bt, breg = D, 0.0, tt, (T_FREE if free else POINT_POINT)
    D, tt, free = _point_segment(x[3], x[4], x[5], x[6], x[7], x[8], x[9], x[10], x[11])   # a1 vs b (s = 1)
    if D < best:
        best, bs, bt, breg = D, 1.0, tt, (T_FREE if free else POINT_POINT)
    D, ss, free = _point_segment(x[6], x[7], x[8], x[0], x[1], x[2], x[3], x[4], x[5])     # b0 vs a (t = 0)
    if D < best:
        best, bs, bt, breg = D, ss, 0.0, (S_FREE if free else POINT_POINT)
    D, ss, free = _point_segment(x[9], x[10], x[11], x[0], x[1], x[2], x[3], x[4], x[5])   # b1 vs a (t = 1)
    if D < best:
        best, bs, bt, breg = D, ss, 1.0, (S_FREE if free else POINT_POINT)
    return best, bs, bt, breg


@njit(cache=True)
def segment_distance2(x):
    """Squared distance between the segments x[0:6] and x[6:12] (length^2)."""
    return closest_parameters(x)[0]


@njit(cache=True)
def segment_distance2_derivatives(x, grad, hess):
    """Squared segment distance D; writes dD/dx into grad (12,) and d2D/dx2 into hess (12, 12).

    Returns (D, region)."""
    D, s, t, region = closest_parameters(x)
    ca = np.empty(4)
    ca[0], ca[1], ca[2], ca[3] = 1.0 - s, s, t - 1.0, -t          # r = sum_k ca[k] p_k
    r = np.zeros(3)
    for k in range(4):
        for i in range(3):
            r[i] += ca[k] * x[3 * k + i]
    u = np.empty(3)
    v = np.empty(3)
    for i in range(3):
        u[i] = x[3 + i] - x[i]
        v[i] = x[9 + i] - x[6 + i]
    for k in range(4):
        for i in range(3):
            grad[3 * k + i] = 2.0 * ca[k] * r[i]
    hess.fill(0.0)
    for k in range(4):
        for l in range(4):
            c2 = 2.0 * ca[k] * ca[l]
            for i in range(3):
                hess[3 * k + i, 3 * l + i] = c2
    if region == POINT_POINT:
        return D, region
    # mixed second derivatives d2|r|^2 / dx dy for y = s (dr/ds = u) and y = t (dr/dt = -v)
    hs = np.empty(12)
    ht = np.empty(12)
    ds = (-1.0, 1.0, 0.0, 0.0)
    dt = (0.0, 0.0, -1.0, 1.0)
    for k in range(4):
        for i in range(3):
            hs[3 * k + i] = 2.0 * (ca[k] * u[i] + ds[k] * r[i])
            ht[3 * k + i] = -2.0 * (ca[k] * v[i] + dt[k] * r[i])
    uu = u[0] * u[0] + u[1] * u[1] + u[2] * u[2]
    vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
    uv = u[0] * v[0] + u[1] * v[1] + u[2] * v[2]
    if region == S_FREE:
        f = 1.0 / (2.0 * uu)
        for m in range(12):
            for n in range(12):
                hess[m, n] -= f * hs[m] * hs[n]
    elif region == T_FREE:
        f = 1.0 / (2.0 * vv)
        for m in range(12):
            for n in range(12):
                hess[m, n] -= f * ht[m] * ht[n]
    else:
        # H_yy = [[2 uu, -2 uv], [-2 uv, 2 vv]]; its inverse = [[2 vv, 2 uv], [2 uv, 2 uu]] / det
        det = 4.0 * (uu * vv - uv * uv)
        iss, ist, itt = 2.0 * vv / det, 2.0 * uv / det, 2.0 * uu / det
        for m in range(12):
            for n in range(12):
                hess[m, n] -= (iss * hs[m] * hs[n] + ist * (hs[m] * ht[n] + ht[m] * hs[n])
                               + itt * ht[m] * ht[n])
    return D, region
