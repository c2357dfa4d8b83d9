"""Contact groundwork (issue 14): segment distances, the IPC barrier, CCD, a broad phase and obstacles.

Numba kernels on flat arrays (``distance``, ``barrier``, ``ccd``, ``broadphase``, ``obstacles``) and a thin
Python layer (this module) that a contact term of the Scene can call. Nothing here is imported by
``import der``: a scene without contact loads none of it. Design and integration: docs/contact.md.

Conventions: positions (n_nodes, 3) float64; edges (n_edges, 2) int64 node indices over all rods;
edge_radius (n_edges,) the rod radius r of each edge (two edges touch at centreline distance r_a + r_b);
dhat the barrier's activation gap (length); kappa the barrier stiffness (energy / length^2 in GAP mode).
"""
from typing import NamedTuple

import numpy as np

from .barrier import GAP, SQUARED, active_pairs, assemble_pairs, pair_barrier  # noqa: F401
from .broadphase import edge_boxes, exclusion_k, hash_grid_pairs, swept_edge_boxes  # noqa: F401
from .ccd import pairs_ccd, reach_pairs, segment_ccd, step_reach, within_reach  # noqa: F401
from .distance import segment_distance2, segment_distance2_derivatives  # noqa: F401

__all__ = ["ContactTopology", "topology", "candidate_pairs", "barrier_system", "safe_step", "exclusion_k",
           "GAP", "SQUARED"]


class ContactTopology(NamedTuple):
    """Flat description of the rods' edges for the broad phase's neighbour exclusion."""
    edges: np.ndarray          # (n_edges, 2) int64 global node indices
    rod_of_edge: np.ndarray    # (n_edges,) int64
    local_edge: np.ndarray     # (n_edges,) int64 index of the edge along its rod
    rod_n_edges: np.ndarray    # (n_rods,) int64
    rod_closed: np.ndarray     # (n_rods,) int64 (0/1)
    rod_k: np.ndarray          # (n_rods,) int64 excluded index distance (broadphase.exclusion_k)
    edge_radius: np.ndarray    # (n_edges,) float64


def topology(rods, dhat):
    """ContactTopology of several rods given as (n_edges, closed, radius, h_min) tuples, nodes numbered rod
    after rod (an open rod of n edges has n + 1 nodes, a ring n); k from exclusion_k(h_min, radius, dhat)."""
    edges, rod_of, local, radius = [], [], [], []
    n_e, closed, ks = [], [], []
    node0 = 0
    for r, (n, is_closed, rad, h_min) in enumerate(rods):
        if int(n) != n or n < 1:
            raise ValueError(f"topology: rod {r} needs a positive integer number of edges, got {n!r}")
        k = exclusion_k(h_min, rad, dhat)
        n_nodes = n if is_closed else n + 1
        i = np.arange(n)
        edges.append(np.stack([node0 + i, node0 + (i + 1) % n_nodes], axis=1))
        rod_of.append(np.full(n, r))
        local.append(i)
        radius.append(np.full(n, float(rad)))
        n_e.append(n)
        closed.append(int(bool(is_closed)))
        ks.append(k)
        node0 += n_nodes
    as_i = lambda a: np.ascontiguousarray(np.concatenate(a), dtype=np.int64)  # noqa: E731
    return ContactTopology(as_i(edges).reshape(-1, 2), as_i(rod_of), as_i(local),
                           np.array(n_e, dtype=np.int64), np.array(closed, dtype=np.int64),
                           np.array(ks, dtype=np.int64), np.concatenate(radius))


def _positive(name, value, caller):
    if not (isinstance(value, (int, float, np.floating, np.integer)) and np.isfinite(value) and value > 0):
        raise ValueError(f"{caller}: {name} must be a positive finite number, got {value!r}")


def _positions(name, pos, topo, caller):
    pos = np.asarray(pos)
    n_nodes = int(topo.edges.max()) + 1 if topo.edges.size else 0
    if pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] < n_nodes:
        raise ValueError(f"{caller}: {name} must be an (n_nodes >= {n_nodes}, 3) array, got shape {pos.shape}")
    if pos.dtype != np.float64:
        raise TypeError(f"{caller}: {name} must be float64, got {pos.dtype}")
    if not np.all(np.isfinite(pos)):
        raise ValueError(f"{caller}: {name} has non-finite entries")
    return np.ascontiguousarray(pos)


def candidate_pairs(pos, topo, dhat, pos1=None, reach=None):
    """Edge pairs that may be within the barrier range (gap < dhat) at pos, or, with pos1, at any time of the
    linear step pos -> pos1 (boxes swept over the step), or, with ``reach`` (n_nodes,), at any positions within
    reach[i] of pos for every node i (each edge's box inflated by its nodes' larger reach). Neighbours along a rod
    are excluded."""
    if not (np.isfinite(dhat) and dhat >= 0):
        raise ValueError(f"candidate_pairs: dhat must be finite and >= 0, got {dhat!r}")
    pos = _positions("pos", pos, topo, "candidate_pairs")
    if pos1 is not None:
        pos1 = _positions("pos1", pos1, topo, "candidate_pairs")
    inflate = topo.edge_radius + 0.5 * dhat
    if reach is not None:
        inflate = inflate + np.maximum(reach[topo.edges[:, 0]], reach[topo.edges[:, 1]])
    m = topo.edges.shape[0]
    lo, hi = np.empty((m, 3)), np.empty((m, 3))
    if pos1 is None:
        edge_boxes(pos, topo.edges, inflate, lo, hi)
    else:
        swept_edge_boxes(pos, pos1, topo.edges, inflate, lo, hi)
    return hash_grid_pairs(lo, hi, topo.rod_of_edge, topo.local_edge, topo.rod_n_edges, topo.rod_closed,
                           topo.rod_k)


def barrier_system(pos, topo, pairs, dhat, kappa, node_dof, n_dof, mode=GAP, project=True):
    """Barrier energy, gradient (n_dof,) and Hessian COO triplets (rows, cols, vals) of the pairs.

    Returns (energy, grad, (rows, cols, vals), n_active, min_gap); min_gap is over the active pairs (inf if
    none is within dhat). Raises ValueError if a pair's gap is <= 0
    (an inadmissible state, naming the two edges)."""
    _positive("dhat", dhat, "barrier_system")
    _positive("kappa", kappa, "barrier_system")
    if mode not in (GAP, SQUARED):
        raise ValueError(f"barrier_system: mode must be GAP (0) or SQUARED (1), got {mode!r}")
    pos = _positions("pos", pos, topo, "barrier_system")
    node_dof = np.asarray(node_dof, dtype=np.int64)
    if node_dof.shape != (pos.shape[0],) or node_dof.min() < 0 or node_dof.max() + 3 > n_dof:
        raise ValueError(f"barrier_system: node_dof must hold one index per node (shape ({pos.shape[0]},)) with "
                         f"x, y, z inside n_dof = {n_dof}")
    pairs = active_pairs(pos, topo.edges, pairs, topo.edge_radius, dhat)
    n_p = pairs.shape[0]
    grad = np.zeros(n_dof)
    rows = np.empty(144 * n_p, dtype=np.int64)
    cols = np.empty(144 * n_p, dtype=np.int64)
    vals = np.empty(144 * n_p)
    energy, n_active, nt, min_gap = assemble_pairs(pos, topo.edges, pairs, topo.edge_radius, dhat, kappa,
                                                   mode, project, node_dof, grad, rows, cols, vals)
    if not np.isfinite(energy):
        gaps = [np.sqrt(segment_distance2(np.concatenate([pos[topo.edges[a]].ravel(), pos[topo.edges[b]].ravel()])))
                - topo.edge_radius[a] - topo.edge_radius[b] for a, b in pairs]
        p = int(np.argmin(gaps))
        raise ValueError(f"barrier_system: edges {pairs[p, 0]} and {pairs[p, 1]} overlap: centreline gap "
                         f"{gaps[p]:.6g} <= 0 beyond their radii (inadmissible state)")
    return energy, grad, (rows[:nt], cols[:nt], vals[:nt]), n_active, min_gap


def safe_step(pos0, dpos, topo, dhat, min_gap_fraction=0.1, tol=1e-6, max_iter=10000):
    """Largest proven-safe fraction tau in [0, 1] of the step pos0 -> pos0 + dpos: every candidate pair keeps a
    gap >= min_gap_fraction of its start gap, every other pair a gap > dhat, on [0, tau] (ccd.py).

    Returns (tau, limiting pair (2,) or None)."""
    if not (0.0 < min_gap_fraction < 1.0):
        raise ValueError(f"safe_step: min_gap_fraction must lie in (0, 1), got {min_gap_fraction!r}")
    pos0 = _positions("pos0", pos0, topo, "safe_step")
    dpos = _positions("dpos", dpos, topo, "safe_step")
    if dpos.shape != pos0.shape:
        raise ValueError(f"safe_step: dpos has shape {dpos.shape}, pos0 {pos0.shape}")
    pairs = candidate_pairs(pos0, topo, dhat, pos1=pos0 + dpos)
    tau, worst, _ = pairs_ccd(pos0, dpos, topo.edges, pairs, topo.edge_radius, min_gap_fraction, tol, max_iter)
    if tau == 0.0 and worst >= 0:
        raise ValueError(f"safe_step: edges {pairs[worst, 0]} and {pairs[worst, 1]} already overlap at the "
                         "start of the step")
    return tau, (pairs[worst] if worst >= 0 else None)
