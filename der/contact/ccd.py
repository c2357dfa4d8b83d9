"""Continuous collision detection for linearly moving segments: a conservative, non-tunnelling step bound.

Trajectories are linear over the step: p(tau) = p0 + tau dp, tau in [0, 1] (the line-search direction of a
Newton step, or one explicit step). For two edges, every point a(s, tau) of edge a moves with velocity
(1 - s) da0 + s da1, so after subtracting any common translation c (which changes no distance) the speed of
a point of a relative to a point of b is at most L = max_k |da_k - c| + max_k |db_k - c|. The distance between
the segments is a minimum of point-pair distances, each L-Lipschitz in tau, hence
    dist(tau + delta) >= dist(tau) - L delta.
Conservative advancement (the additive-CCD idea of Li et al. 2021, "Codimensional Incremental Potential
Contact", here with the unsquared distance): with gap g(tau) = dist(tau) - off and target g_t = f g(0),
step delta = (g(tau) - g_t) / L, which by the bound keeps g >= g_t on [tau, tau + delta]; repeat from the
new, exactly evaluated, gap. The returned tau_safe is therefore a proven lower bound of the first time the gap
falls to f g(0): no pair gets below that, so no pair touches (g = 0) and no strand passes through another
within [0, tau_safe], however fast or large the step (no sampling, no tunnelling). f (``min_gap_fraction``,
default 0.1) is ipctk's 1 - conservative_rescaling.

Termination: the loop stops when the remaining margin g(tau) - g_t is below ``tol`` (1e-6) of its initial
value (tau is then the time of impact with the target, from below), or tau reaches tmax (1 by default), or
after ``max_iter`` (default 10000) iterations, returning the tau reached (still safe, only more
conservative). Pairs that slide fast past each other at constant gap need about L / ((1 - f) g) iterations
per unit step.

Layout as in barrier.py; dpos (n_nodes, 3) is the displacement of the full step.
"""
import numpy as np
from numba import njit

from .barrier import kept_pairs
from .distance import segment_distance2


@njit(cache=True)
def _relative_speed_bound(dx):
    """L = max_k |da_k - c| + max_k |db_k - c| for the 4 endpoint displacements dx (12,), minimised over
    c in {0, mean of the four}."""
    best = np.inf
    for variant in range(2):
        c = np.zeros(3)
        if variant == 1:
            for k in range(4):
                for i in range(3):
                    c[i] += 0.25 * dx[3 * k + i]
        la = 0.0
        lb = 0.0
        for k in range(4):
            s = 0.0
            for i in range(3):
                s += (dx[3 * k + i] - c[i]) ** 2
            s = np.sqrt(s)
            if k < 2:
                la = max(la, s)
            else:
                lb = max(lb, s)
        best = min(best, la + lb)
    return best


@njit(cache=True)
def segment_ccd(x0, dx, off, min_gap_fraction, tol, max_iter, tmax=1.0):
    """Safe step fraction tau in [0, 1] for segments x0 = [a0, a1, b0, b1] (12,) moving by dx (12,), offset
    off = r_a + r_b: the gap dist - off stays >= min_gap_fraction * (its value at tau = 0) on [0, tau].
    The search ends at ``tmax`` (<= 1): a caller that already has a smaller bound from another pair passes it,
    and pairs that cannot lower it stop early.

    Returns (tau, iterations). tau = 0 with iterations = -1 if the start already violates the gap (g0 <= 0)."""
    L = _relative_speed_bound(dx)
    g0 = np.sqrt(segment_distance2(x0)) - off
    if g0 <= 0.0:
        return 0.0, -1
    if L == 0.0:
        return tmax, 0
    target = min_gap_fraction * g0
    margin0 = g0 - target
    tau = 0.0
    g = g0
    x = np.empty(12)
    for it in range(max_iter):
        margin = g - target
        if margin <= tol * margin0:
            return tau, it
        delta = margin / L
        if tau + delta >= tmax:
            # the bound holds on the whole rest of [0, tmax]
            return tmax, it + 1
        tau += delta
        for m in range(12):
            x[m] = x0[m] + tau * dx[m]
        g = np.sqrt(segment_distance2(x)) - off
    return tau, max_iter


@njit(cache=True)
def pairs_ccd(pos0, dpos, edges, pairs, edge_radius, min_gap_fraction, tol, max_iter):
    """Smallest segment_ccd tau over the candidate pairs (n_pairs, 2), each pair searched only up to the
    smallest bound found so far. Returns (tau, index of the limiting pair or -1, total iterations);
    tau = 0 and that pair's index if a pair starts inadmissible."""
    x0 = np.empty(12)
    dx = np.empty(12)
    tau_min = 1.0
    worst = -1
    total = 0
    for p in range(pairs.shape[0]):
        ea, eb = pairs[p, 0], pairs[p, 1]
        nodes = (edges[ea, 0], edges[ea, 1], edges[eb, 0], edges[eb, 1])
        for k in range(4):
            for i in range(3):
                x0[3 * k + i] = pos0[nodes[k], i]
                dx[3 * k + i] = dpos[nodes[k], i]
        tau, it = segment_ccd(x0, dx, edge_radius[ea] + edge_radius[eb], min_gap_fraction, tol, max_iter,
                              tau_min)
        if it < 0:
            return 0.0, p, total
        total += it
        if tau < tau_min:
            tau_min = tau
            worst = p
    return tau_min, worst, total


@njit(cache=True)
def step_reach(dpos, slack, out):
    """Each node's reach over a step pos0 -> pos0 + dpos: its displacement |dpos_i| (any fraction of the step
    moves it less), widened by 1e-9 relative and ``slack`` (a length, above the coordinates' rounding) so that a
    trial rounded onto the step stays within it."""
    for i in range(dpos.shape[0]):
        s = 0.0
        for k in range(3):
            s += dpos[i, k] * dpos[i, k]
        out[i] = np.sqrt(s) * (1.0 + 1e-9) + slack


@njit(cache=True)
def within_reach(pos, pos0, reach):
    """True if every node i of pos lies within reach[i] of pos0 (Euclidean)."""
    for i in range(pos.shape[0]):
        s = 0.0
        for k in range(3):
            s += (pos[i, k] - pos0[i, k]) ** 2
        if s > reach[i] * reach[i]:
            return False
    return True


@njit(cache=True)
def reach_pairs(pos0, reach, edges, pairs, edge_radius, dhat):
    """The rows of pairs (n_pairs, 2) whose gap can fall below dhat while every node i stays within reach[i] of
    pos0 -- the pair list of a whole step, whose every trial (any fraction of it) moves node i by at most its
    reach. The bound is this module's: a point of a segment is a convex combination of its endpoints, so it moves
    by at most its endpoints' largest displacement, and the distance of two segments by at most the sum of their
    two largest displacements: gap >= gap(pos0) - max(reach_a0, reach_a1) - max(reach_b0, reach_b1). A pair left
    out keeps gap >= dhat on every such state; ``pairs`` must hold every pair that can come within dhat there
    (a broad phase with the boxes inflated by the reach)."""
    keep = np.zeros(pairs.shape[0], dtype=np.bool_)
    x = np.empty(12)
    n = 0
    for p in range(pairs.shape[0]):
        ea, eb = pairs[p, 0], pairs[p, 1]
        a0, a1, b0, b1 = edges[ea, 0], edges[ea, 1], edges[eb, 0], edges[eb, 1]
        nodes = (a0, a1, b0, b1)
        for k in range(4):
            for i in range(3):
                x[3 * k + i] = pos0[nodes[k], i]
        move = max(reach[a0], reach[a1]) + max(reach[b0], reach[b1])
        if np.sqrt(segment_distance2(x)) - edge_radius[ea] - edge_radius[eb] - move < dhat:
            keep[p] = True
            n += 1
    return kept_pairs(pairs, keep, n)
