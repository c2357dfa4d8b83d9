"""Broad phase: candidate edge pairs whose inflated axis-aligned boxes overlap, by a uniform spatial hash.

Each edge gets an AABB (of its two nodes, or of its four nodes at the start and end of a step for CCD),
inflated by ``inflate`` on every side. The grid's cell size is the largest box extent, so a box spans at most
2 cells per axis (<= 8 cells). Entries (cell key, edge) are sorted (m log m); every pair sharing a cell is
tested for box overlap and reported only from the cell that holds the low corner of the two boxes'
intersection, so each pair appears once without a hash set. Expected cost O(n log n + pairs) for rods of
roughly uniform edge length; one very long edge enlarges the cells for all (not a case rods meet).

Neighbour exclusion (the thickness rule). Two edges i, j = i + m of one rod with edge length h have their
nearest nodes (m - 1) h apart along the rod; straight, their gap is (m - 1) h - 2r. Edges that close along
the rod are not contacts: they would sit inside the barrier on a straight rod at rest. So pairs with
index distance m <= k are skipped, k = max(1, ceil((2r + dhat) / h_min)), m measured around the ring
(min(|i - j|, n - |i - j|)) for a closed rod. m = 1 (a shared node, distance 0) is always excluded. A rod bent
to curvature radius R has chord 2R sin(s / 2R) < s between points s apart, so rods bent much tighter than
their thickness (R ~ r) need a larger k (arc pi r rather than 2r); ``exclusion_k`` takes the arc to exclude.

Layout: lo, hi (n_edges, 3); rod_of_edge, local_edge (n_edges,) int64; per rod: rod_n_edges, rod_closed
(0/1), rod_k (n_rods,) int64. Pairs are returned as (n_pairs, 2) int64 with pairs[:, 0] < pairs[:, 1].
"""
import math

import numpy as np
from numba import njit


def exclusion_k(h_min, radius, dhat, arc=None):
    """Largest excluded index distance k for a rod of shortest edge h_min, radius r and barrier range dhat.

    ``arc`` (default 2r + dhat) is the length along the rod within which edges are not contact partners."""
    if not (h_min > 0 and math.isfinite(h_min)):
        raise ValueError(f"exclusion_k: h_min must be a positive finite edge length, got {h_min!r}")
    if not (radius > 0 and math.isfinite(radius)):
        raise ValueError(f"exclusion_k: radius must be positive and finite, got {radius!r}")
    if not (dhat > 0 and math.isfinite(dhat)):
        raise ValueError(f"exclusion_k: dhat must be positive and finite, got {dhat!r}")
    if arc is None:
        arc = 2.0 * radius + dhat
    return max(1, int(math.ceil(arc / h_min - 1e-12)))


@njit(cache=True)
def edge_boxes(pos, edges, inflate, out_lo, out_hi):
    """AABBs of the edges at positions pos (n_nodes, 3), inflated by ``inflate`` (per edge, (n_edges,))."""
    for e in range(edges.shape[0]):
        a, b = edges[e, 0], edges[e, 1]
        for i in range(3):
            out_lo[e, i] = min(pos[a, i], pos[b, i]) - inflate[e]
            out_hi[e, i] = max(pos[a, i], pos[b, i]) + inflate[e]


@njit(cache=True)
def swept_edge_boxes(pos0, pos1, edges, inflate, out_lo, out_hi):
    """AABBs of the edges over a linear step from pos0 to pos1 (they contain every point of the edge at every
    time of the step), inflated by ``inflate`` (n_edges,)."""
    for e in range(edges.shape[0]):
        a, b = edges[e, 0], edges[e, 1]
        for i in range(3):
            out_lo[e, i] = min(min(pos0[a, i], pos0[b, i]), min(pos1[a, i], pos1[b, i])) - inflate[e]
            out_hi[e, i] = max(max(pos0[a, i], pos0[b, i]), max(pos1[a, i], pos1[b, i])) + inflate[e]


@njit(cache=True)
def excluded(i, j, rod_of_edge, local_edge, rod_n_edges, rod_closed, rod_k):
    """True if edges i and j are neighbours along one rod (index distance <= that rod's k)."""
    r = rod_of_edge[i]
    if rod_of_edge[j] != r:
        return False
    m = abs(local_edge[i] - local_edge[j])
    if rod_closed[r]:
        m = min(m, rod_n_edges[r] - m)
    return m <= rod_k[r]


@njit(cache=True)
def _overlap(lo, hi, i, j):
    for a in range(3):
        if lo[i, a] > hi[j, a] or lo[j, a] > hi[i, a]:
            return False
    return True


@njit(cache=True)
def _argsort_heap(keys):
    """Indices that sort the int64 keys (heapsort, O(m log m)); a hand loop because numba's np.argsort and
    2D slice copies cost seconds of compilation each."""
    m = keys.shape[0]
    idx = np.arange(m)
    for start in range(m // 2 - 1, -1, -1):
        _sift(keys, idx, start, m)
    for end in range(m - 1, 0, -1):
        idx[0], idx[end] = idx[end], idx[0]
        _sift(keys, idx, 0, end)
    return idx


@njit(cache=True)
def _sift(keys, idx, root, end):
    while True:
        child = 2 * root + 1
        if child >= end:
            return
        if child + 1 < end and keys[idx[child + 1]] > keys[idx[child]]:
            child += 1
        if keys[idx[child]] <= keys[idx[root]]:
            return
        idx[root], idx[child] = idx[child], idx[root]
        root = child


@njit(cache=True)
def _trimmed(out, n):
    res = np.empty((n, 2), dtype=np.int64)
    for i in range(n):
        res[i, 0] = out[i, 0]
        res[i, 1] = out[i, 1]
    return res


@njit(cache=True)
def hash_grid_pairs(lo, hi, rod_of_edge, local_edge, rod_n_edges, rod_closed, rod_k):
    """All non-excluded edge pairs whose boxes overlap (see module docstring). Returns (n_pairs, 2) int64."""
    n = lo.shape[0]
    if n < 2:
        return np.empty((0, 2), dtype=np.int64)
    cell = 0.0
    gmin = np.full(3, np.inf)
    gmax = np.full(3, -np.inf)
    for e in range(n):
        for a in range(3):
            gmin[a] = min(gmin[a], lo[e, a])
            gmax[a] = max(gmax[a], hi[e, a])
            cell = max(cell, hi[e, a] - lo[e, a])
    if not cell > 0.0:
        cell = 1.0
    dims = np.empty(3, dtype=np.int64)
    for a in range(3):
        dims[a] = int((gmax[a] - gmin[a]) / cell) + 2
    c0 = np.empty((n, 3), dtype=np.int64)
    c1 = np.empty((n, 3), dtype=np.int64)
    count = 0
    for e in range(n):
        m = 1
        for a in range(3):
            c0[e, a] = int((lo[e, a] - gmin[a]) / cell)
            c1[e, a] = int((hi[e, a] - gmin[a]) / cell)
            m *= c1[e, a] - c0[e, a] + 1
        count += m
    keys = np.empty(count, dtype=np.int64)
    owner = np.empty(count, dtype=np.int64)
    q = 0
    for e in range(n):
        for cx in range(c0[e, 0], c1[e, 0] + 1):
            for cy in range(c0[e, 1], c1[e, 1] + 1):
                for cz in range(c0[e, 2], c1[e, 2] + 1):
                    keys[q] = (cx * dims[1] + cy) * dims[2] + cz
                    owner[q] = e
                    q += 1
    order = _argsort_heap(keys)
    out = np.empty((max(16, 4 * n), 2), dtype=np.int64)
    npairs = 0
    start = 0
    while start < count:
        key = keys[order[start]]
        stop = start + 1
        while stop < count and keys[order[stop]] == key:
            stop += 1
        cz = key % dims[2]
        cy = (key // dims[2]) % dims[1]
        cx = key // (dims[2] * dims[1])
        for u in range(start, stop):
            i = owner[order[u]]
            for w in range(u + 1, stop):
                j = owner[order[w]]
                if not _overlap(lo, hi, i, j):
                    continue
                # report from the cell of the intersection's low corner only
                if (max(c0[i, 0], c0[j, 0]) != cx or max(c0[i, 1], c0[j, 1]) != cy
                        or max(c0[i, 2], c0[j, 2]) != cz):
                    continue
                if excluded(i, j, rod_of_edge, local_edge, rod_n_edges, rod_closed, rod_k):
                    continue
                if npairs == out.shape[0]:
                    grown = np.empty((2 * out.shape[0], 2), dtype=np.int64)
                    for q2 in range(npairs):
                        grown[q2, 0] = out[q2, 0]
                        grown[q2, 1] = out[q2, 1]
                    out = grown
                out[npairs, 0] = min(i, j)
                out[npairs, 1] = max(i, j)
                npairs += 1
        start = stop
    return _trimmed(out, npairs)


@njit(cache=True)
def brute_force_pairs(lo, hi, rod_of_edge, local_edge, rod_n_edges, rod_closed, rod_k):
    """Reference O(n^2) version of hash_grid_pairs (tests only)."""
    n = lo.shape[0]
    out = np.empty((n * (n - 1) // 2 + 1, 2), dtype=np.int64)
    npairs = 0
    for i in range(n):
        for j in range(i + 1, n):
            if _overlap(lo, hi, i, j) and not excluded(i, j, rod_of_edge, local_edge, rod_n_edges,
                                                        rod_closed, rod_k):
                out[npairs, 0] = i
                out[npairs, 1] = j
                npairs += 1
    return _trimmed(out, npairs)


@njit(cache=True)
def sort_pairs(pairs, n_edges):
    """The rows of pairs (m, 2), edges in [0, n_edges), in lexicographic order: a counting sort by the second
    column, then a stable one by the first (O(m + n_edges))."""
    m = pairs.shape[0]
    tmp = np.empty((m, 2), dtype=np.int64)
    out = np.empty((m, 2), dtype=np.int64)
    for col, src, dst in ((1, pairs, tmp), (0, tmp, out)):
        start = np.zeros(n_edges + 1, dtype=np.int64)
        for p in range(m):
            start[src[p, col] + 1] += 1
        for e in range(n_edges):
            start[e + 1] += start[e]
        for p in range(m):
            k = start[src[p, col]]
            dst[k, 0] = src[p, 0]
            dst[k, 1] = src[p, 1]
            start[src[p, col]] = k + 1
    return out

