"""A smooth contact barrier for rods: the barrier on the distances between points sampled along the centrelines.

Why. The segment-segment distance (distance.py) is a minimum over the closest-point regions (edge-edge,
point-edge, point-point): it is C1 where the closest points change region, and its Hessian jumps there. Two
strands in a line contact (a plectoneme, a supercoiled ring) keep pairs at such switches all the time, so
Newton's method with the exact barrier Hessian meets a Hessian that changes discontinuously from one iterate to
the next, and with the PSD-projected one (IPC) it loses the transverse geometric stiffness -f / d of every
contact. Either way it converges linearly (docs/contact.md section 9).

What. Each edge carries ``m`` sample points at the parameters alpha = k / m, k = 0 .. m - 1 (the last edge of an
open rod also its end node, alpha = 1), so that every node is a sample and consecutive samples are the ends of
straight pieces of length l = h / m of the centreline. The barrier acts on the distance between two samples,

    E = kappa sum_{sample pairs} b(|p - q| - off_s),   off_s = sqrt(off^2 + (l_a^2 + l_b^2) / 4),

with off = r_a + r_b. A sample p = (1 - alpha) x_a0 + alpha x_a1 is linear in the nodes, and |p - q| is smooth
wherever p != q, so E is C2 (C-infinity inside the active set; C2 where a pair enters or leaves it, as the IPC
barrier). Its exact Hessian is cheap: with w = p - q, n = w / |w|, c = (1 - alpha, alpha, beta - 1, -beta),

    d2E/dx2 = (c c^T) x kappa [b'' n n^T + (b' / |w|) (I - n n^T)]      (x: Kronecker product),

whose second part (b' < 0) is the transverse geometric stiffness of a compressed contact, and its PSD projection
just drops that part.

Why off_s. Two straight pieces [p, p'] and [q, q'] of lengths l_a, l_b whose four end-to-end distances are at
least d have a distance of at least sqrt(d^2 - (l_a^2 + l_b^2) / 4): their squared distance f(s, t) is a convex
quadratic on the unit square, f minus its bilinear interpolation of the corners is
-(|U|^2 s (1 - s) + |V|^2 t (1 - t)) >= -(l_a^2 + l_b^2) / 4, and the interpolation is >= d^2. So sample
distances above off_s keep the centrelines more than off apart; the corrugation this sampling leaves on a line
contact is below off_s - off ~ (l_a^2 + l_b^2) / (8 off). The edge lengths are the rest lengths (the offsets are
constants); the strict guarantee (no passage, centreline distance > off) is kept by the segment CCD of every step
in any case (ccd.py), and the barrier's own finiteness by the sample CCD below.

Layout as in barrier.py; ``edge_len`` (n_edges,) the rest lengths, ``owns_end`` (n_edges,) 1 for the last edge
of an open rod (it carries its end node as a sample), else 0.
"""
import numpy as np
from numba import njit

from .barrier import barrier, barrier_first_derivative, barrier_second_derivative, kept_pairs


@njit(cache=True)
def sample_offset(off, la, lb, m):
    """off_s = sqrt(off^2 + ((la / m)^2 + (lb / m)^2) / 4): the sample distance that keeps the centrelines more
    than off apart (module docstring)."""
    return np.sqrt(off * off + 0.25 * ((la / m) ** 2 + (lb / m) ** 2))


@njit(cache=True)
def max_offset_excess(edge_radius, edge_len, m):
    """The largest off_s - off over all pairs of edges (an upper bound, from the longest edges): the broad phase
    lists the edge pairs within dhat plus this, which holds every sample pair within dhat of its own offset."""
    lmax = edge_len.max()
    rmin = edge_radius.min()
    off = 2.0 * rmin
    return sample_offset(off, lmax, lmax, m) - off


@njit(cache=True)
def _point(pos, a0, a1, alpha, out):
    for i in range(3):
        out[i] = (1.0 - alpha) * pos[a0, i] + alpha * pos[a1, i]


@njit(cache=True)
def sampled_system(pos, edges, pairs, edge_radius, edge_len, owns_end, m, dhat, kappa, order, project, node_dof,
                   grad_out, rows, cols, vals):
    """Barrier on the sample distances of the edge pairs ``pairs`` (n_pairs, 2).

    order 0: energy only; 1: the gradient added into grad_out (n_dof,); 2: also the Hessian, one 12 x 12 block per
    edge pair with an active sample pair, written as COO triplets into rows, cols, vals (length >= 144 n_pairs;
    the transverse part dropped if ``project``). Returns (energy, active edge pairs, triplets written, smallest
    sample gap |p - q| - off_s, active sample pairs); energy is +inf if a sample pair has a gap <= 0."""
    p = np.empty(3)
    q = np.empty(3)
    w = np.empty(3)
    H = np.empty((12, 12))
    c = np.empty(4)
    energy = 0.0
    n_edge_pairs = 0
    n_samples = 0
    nt = 0
    min_gap = np.inf
    for k in range(pairs.shape[0]):
        ea, eb = pairs[k, 0], pairs[k, 1]
        a0, a1, b0, b1 = edges[ea, 0], edges[ea, 1], edges[eb, 0], edges[eb, 1]
        off_s = sample_offset(edge_radius[ea] + edge_radius[eb], edge_len[ea], edge_len[eb], m)
        na = m + owns_end[ea]
        nb = m + owns_end[eb]
        active = False
        if order >= 2:
            H.fill(0.0)
        for ia in range(na):
            alpha = ia / m
            _point(pos, a0, a1, alpha, p)
            for ib in range(nb):
                beta = ib / m
                _point(pos, b0, b1, beta, q)
                d2 = 0.0
                for i in range(3):
                    w[i] = p[i] - q[i]
                    d2 += w[i] * w[i]
                d = np.sqrt(d2)
                z = d - off_s
                if z < min_gap:
                    min_gap = z
                if z >= dhat:
                    continue
                if z <= 0.0:
                    return np.inf, n_edge_pairs, nt, min_gap, n_samples
                energy += kappa * barrier(z, dhat)
                active = True
                n_samples += 1
                if order == 0:
                    continue
                b1d = kappa * barrier_first_derivative(z, dhat)
                c[0], c[1], c[2], c[3] = 1.0 - alpha, alpha, beta - 1.0, -beta
                nodes = (a0, a1, b0, b1)
                for j in range(4):
                    if c[j] != 0.0:
                        for i in range(3):
                            grad_out[node_dof[nodes[j]] + i] += c[j] * b1d * w[i] / d
                if order < 2:
                    continue
                cn = kappa * barrier_second_derivative(z, dhat)
                ct = 0.0 if project else b1d / d
                for i in range(3):
                    for l in range(3):
                        hw = (cn - ct) * w[i] * w[l] / d2
                        if i == l:
                            hw += ct
                        if hw == 0.0:
                            continue
                        for j in range(4):
                            if c[j] == 0.0:
                                continue
                            for jj in range(4):
                                H[3 * j + i, 3 * jj + l] += c[j] * c[jj] * hw
        if not active:
            continue
        n_edge_pairs += 1
        if order >= 2:
            nodes = (a0, a1, b0, b1)
            for j in range(4):
                for i in range(3):
                    for jj in range(4):
                        for l in range(3):
                            rows[nt] = node_dof[nodes[j]] + i
                            cols[nt] = node_dof[nodes[jj]] + l
                            vals[nt] = H[3 * j + i, 3 * jj + l]
                            nt += 1
    return energy, n_edge_pairs, nt, min_gap, n_samples


@njit(cache=True)
def sampled_active_pairs(pos, edges, pairs, edge_radius, edge_len, owns_end, m, dhat):
    """The rows of ``pairs`` with a sample pair within dhat of its offset (sizes the triplet buffers)."""
    keep = np.zeros(pairs.shape[0], dtype=np.bool_)
    p = np.empty(3)
    q = np.empty(3)
    n = 0
    for k in range(pairs.shape[0]):
        ea, eb = pairs[k, 0], pairs[k, 1]
        a0, a1, b0, b1 = edges[ea, 0], edges[ea, 1], edges[eb, 0], edges[eb, 1]
        off_s = sample_offset(edge_radius[ea] + edge_radius[eb], edge_len[ea], edge_len[eb], m)
        reach = (off_s + dhat) ** 2
        for ia in range(m + owns_end[ea]):
            _point(pos, a0, a1, ia / m, p)
            for ib in range(m + owns_end[eb]):
                _point(pos, b0, b1, ib / m, q)
                d2 = (p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2 + (p[2] - q[2]) ** 2
                if d2 < reach:
                    keep[k] = True
                    break
            if keep[k]:
                break
        if keep[k]:
            n += 1
    return kept_pairs(pairs, keep, n)


@njit(cache=True)
def point_ccd(w0, dw, radius):
    """Exact first time tau in [0, 1] at which |w0 + tau dw| falls to ``radius`` (< |w0|); 1 if it never does."""
    A = dw[0] * dw[0] + dw[1] * dw[1] + dw[2] * dw[2]
    B = w0[0] * dw[0] + w0[1] * dw[1] + w0[2] * dw[2]
    C = w0[0] * w0[0] + w0[1] * w0[1] + w0[2] * w0[2] - radius * radius
    if B >= 0.0 or A == 0.0:
        return 1.0                  # |w|^2 is convex in tau with a non-negative slope at 0: it never falls
    disc = B * B - A * C
    if disc < 0.0:
        return 1.0
    tau = C / (-B + np.sqrt(disc))  # the smaller root, without cancellation
    return min(tau, 1.0)


@njit(cache=True)
def sampled_ccd(pos0, dpos, edges, pairs, edge_radius, edge_len, owns_end, m, min_gap_fraction):
    """Largest tau in [0, 1] such that every sample pair of the edge pairs keeps a gap |p - q| - off_s of at least
    min_gap_fraction times its start value on [0, tau] (exact for points moving linearly; the root is taken 1e-9
    short of itself, relative). Returns (tau, index of the limiting edge pair or -1); tau = 0 if a sample pair
    starts with a gap <= 0."""
    p = np.empty(3)
    q = np.empty(3)
    w = np.empty(3)
    dw = np.empty(3)
    tau_min, worst = 1.0, -1
    for k in range(pairs.shape[0]):
        ea, eb = pairs[k, 0], pairs[k, 1]
        a0, a1, b0, b1 = edges[ea, 0], edges[ea, 1], edges[eb, 0], edges[eb, 1]
        off_s = sample_offset(edge_radius[ea] + edge_radius[eb], edge_len[ea], edge_len[eb], m)
        for ia in range(m + owns_end[ea]):
            alpha = ia / m
            for ib in range(m + owns_end[eb]):
                beta = ib / m
                d2 = 0.0
                v2 = 0.0
                for i in range(3):
                    w[i] = (1.0 - alpha) * pos0[a0, i] + alpha * pos0[a1, i] - (1.0 - beta) * pos0[b0, i] \
                        - beta * pos0[b1, i]
                    dw[i] = (1.0 - alpha) * dpos[a0, i] + alpha * dpos[a1, i] - (1.0 - beta) * dpos[b0, i] \
                        - beta * dpos[b1, i]
                    d2 += w[i] * w[i]
                    v2 += dw[i] * dw[i]
                g0 = np.sqrt(d2) - off_s
                if g0 <= 0.0:
                    return 0.0, k
                if (1.0 - min_gap_fraction) * g0 >= np.sqrt(v2) * tau_min:
                    continue            # it cannot lose that much gap within [0, tau_min]
                t = point_ccd(w, dw, off_s + min_gap_fraction * g0) * (1.0 - 1e-9)
                if t < tau_min:
                    tau_min, worst = t, k
    return tau_min, worst


@njit(cache=True)
def sampled_pair_forces(pos, edges, pairs, edge_radius, edge_len, owns_end, m, dhat, kappa, force):
    """For each edge pair: the sum of its sample pairs' contact force magnitudes -kappa b'(gap) (force units)."""
    p = np.empty(3)
    q = np.empty(3)
    for k in range(pairs.shape[0]):
        ea, eb = pairs[k, 0], pairs[k, 1]
        a0, a1, b0, b1 = edges[ea, 0], edges[ea, 1], edges[eb, 0], edges[eb, 1]
        off_s = sample_offset(edge_radius[ea] + edge_radius[eb], edge_len[ea], edge_len[eb], m)
        f = 0.0
        for ia in range(m + owns_end[ea]):
            _point(pos, a0, a1, ia / m, p)
            for ib in range(m + owns_end[eb]):
                _point(pos, b0, b1, ib / m, q)
                z = np.sqrt((p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2 + (p[2] - q[2]) ** 2) - off_s
                if z <= 0.0:
                    f = np.inf
                elif z < dhat:
                    f -= kappa * barrier_first_derivative(z, dhat)
        force[k] = f
