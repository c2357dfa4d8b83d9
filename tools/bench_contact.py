"""Contact kernels: der's numba kernels (der/contact) against ipctk (IPC Toolkit's Python bindings), side by side.

    python tools/bench_contact.py [--json] [--repeat 5] [--n 100 1000 10000] [--threads 1]

Configuration: one open rod folded into a plectoneme (der.contact.samples.plectoneme_polyline, edges ~1 long,
strands interwound at centreline distance d_min), radius r = 0.45 d_min and barrier range dhat = 0.15 d_min,
so the closest pairs sit at gap 0.1 d_min inside the barrier and 2r + dhat < shortest edge: the neighbour
exclusion is k = 1 (edges sharing a node), which is also ipctk's built-in rule, so both see the same pairs.
Step for the CCD: every node displaced by 0.5 d_min * N(0, 1) per coordinate (many pairs limit the step).

Timed, median of ``--repeat`` runs after a warm-up call (numba compilation excluded, reported apart):
  broad     candidate pairs within r + dhat/2 box inflation (der: spatial hash; ipctk: HashGrid)
  barrier   broad phase + distances + barrier energy, gradient and PSD-projected Hessian assembled into a
            CSC matrix (der: SQUARED mode, the convention of ipctk's BarrierPotential with dmin = 2r, so the
            numbers can be compared; eigen-clamping of every 12x12 block in both)
  ccd       largest safe step fraction (der: swept-box hash + conservative advancement, f = 0.1; ipctk:
            compute_collision_free_stepsize with HashGrid and AdditiveCCD (conservative_rescaling 0.9 ~ f = 0.1)
            and with its default TightInclusionCCD)
  per pair  the squared-distance Hessian of one pair: ipctk called from a Python loop against der's batched
            numba loop (the binding overhead on many small calls).
Checks in the same run: energies and gradients agree (relative), Hessians agree (max abs difference / max),
the CCD fractions of both are safe on the sampled trajectory (no candidate pair below 2r).
ipctk runs single-threaded by default (--threads), as der's kernels are, on a 2-core machine shared by others.
"""
import argparse
import json
import os
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from numba import njit  # noqa: E402

from der.contact import SQUARED, barrier_system, candidate_pairs, safe_step, topology  # noqa: E402
from der.contact.distance import segment_distance2, segment_distance2_derivatives  # noqa: E402
from der.contact.samples import min_distance, plectoneme_polyline  # noqa: E402


def median_time(fn, repeat):
    times = []
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


@njit(cache=True)
def batched_distance_hessians(X):
    """Squared-distance Hessians of the pairs X (m, 12); returns the sum of their traces (kept honest)."""
    g = np.empty(12)
    H = np.empty((12, 12))
    acc = 0.0
    for p in range(X.shape[0]):
        segment_distance2_derivatives(X[p], g, H)
        for i in range(12):
            acc += H[i, i]
    return acc


def setup(n):
    pos = plectoneme_polyline(n)
    probe = topology([(n, False, 1e-3, 0.5)], 0.5)
    d_min = min_distance(pos, probe.edges, candidate_pairs(pos, probe, 0.8))
    r, dhat = 0.45 * d_min, 0.15 * d_min
    h_min = float(np.linalg.norm(np.diff(pos, axis=0), axis=1).min())
    topo = topology([(n, False, r, h_min)], dhat)
    assert topo.rod_k[0] == 1, topo.rod_k
    rng = np.random.default_rng(0)
    dpos = 0.5 * d_min * rng.standard_normal(pos.shape)
    return pos, dpos, r, dhat, topo


def der_barrier(pos, topo, dhat, kappa):
    import scipy.sparse as sp
    n_dof = 3 * pos.shape[0]
    pairs = candidate_pairs(pos, topo, dhat)
    E, g, (rows, cols, vals), n_active, min_gap = barrier_system(pos, topo, pairs, dhat, kappa,
                                                                 3 * np.arange(pos.shape[0]), n_dof, mode=SQUARED,
                                                                 project=True)
    H = sp.csc_matrix((vals, (rows, cols)), shape=(n_dof, n_dof))
    return E, g, H, n_active


def sampled_min_gap(pos, dpos, topo, tau, r, n_samples=20):
    """Smallest gap (dist - 2r) over candidate pairs of the swept step, at n_samples times in [0, tau]."""
    pairs = candidate_pairs(pos, topo, 0.0, pos1=pos + tau * dpos)
    best = np.inf
    e = topo.edges
    for t in np.linspace(0.0, tau, n_samples):
        p = pos + t * dpos
        X = np.concatenate([p[e[pairs[:, 0]]].reshape(-1, 6), p[e[pairs[:, 1]]].reshape(-1, 6)], axis=1)
        for x in X:
            best = min(best, segment_distance2(x))
    return float(np.sqrt(best) - 2 * r)


def run(n, repeat, ipctk):
    pos, dpos, r, dhat, topo = setup(n)
    kappa = 1.0
    row = {"n": n, "radius": r, "dhat": dhat}
    t0 = time.perf_counter()
    der_barrier(pos, topo, dhat, kappa)
    safe_step(pos, dpos, topo, dhat)
    row["der_first_call_s"] = time.perf_counter() - t0
    row["der_broad_s"], pairs = median_time(lambda: candidate_pairs(pos, topo, dhat), repeat)
    row["candidates"] = int(len(pairs))
    row["der_barrier_s"], (E, g, H, n_active) = median_time(lambda: der_barrier(pos, topo, dhat, kappa), repeat)
    row["active_pairs"] = int(n_active)
    row["der_ccd_s"], (tau, _) = median_time(lambda: safe_step(pos, dpos, topo, dhat), repeat)
    row["der_tau"] = tau
    row["der_tau_min_gap"] = sampled_min_gap(pos, dpos, topo, tau, r)
    m = min(len(pairs), 2000)
    X = np.concatenate([pos[topo.edges[pairs[:m, 0]]].reshape(-1, 6), pos[topo.edges[pairs[:m, 1]]].reshape(-1, 6)], 1)
    batched_distance_hessians(X)
    row["der_per_pair_us"] = median_time(lambda: batched_distance_hessians(X), repeat)[0] / m * 1e6
    if ipctk is None:
        return row
    V = np.asfortranarray(pos)
    V1 = np.asfortranarray(pos + dpos)
    Ed = np.asfortranarray(topo.edges.astype(np.int32))
    F = np.zeros((0, 3), dtype=np.int32, order="F")
    mesh = ipctk.CollisionMesh(V, Ed)
    potential = ipctk.BarrierPotential(dhat, kappa)

    def i_broad():
        bp = ipctk.HashGrid()
        bp.build(V, Ed, F, r + 0.5 * dhat)
        return bp.detect_edge_edge_candidates()

    def i_barrier():
        col = ipctk.NormalCollisions()
        col.build(mesh, V, dhat, 2 * r, ipctk.HashGrid())
        Ei = potential(col, mesh, V)
        gi = potential.gradient(col, mesh, V)
        Hi = potential.hessian(col, mesh, V, ipctk.PSDProjectionMethod.CLAMP)
        return Ei, gi, Hi, len(col)

    def i_ccd(narrow):
        return ipctk.compute_collision_free_stepsize(mesh, V, V1, 2 * r, ipctk.HashGrid(), narrow)

    i_barrier()
    row["ipctk_broad_s"], cands = median_time(i_broad, repeat)
    row["ipctk_candidates"] = len(cands)
    row["ipctk_barrier_s"], (Ei, gi, Hi, n_col) = median_time(i_barrier, repeat)
    row["ipctk_active"] = int(n_col)
    row["energy_rel_diff"] = abs(E - Ei) / abs(Ei)
    row["grad_rel_diff"] = float(np.abs(g - gi.ravel()).max() / np.abs(gi).max())
    D = (H - Hi).tocoo()
    row["hess_rel_diff"] = float(np.abs(D.data).max() / np.abs(Hi.data).max()) if D.nnz else 0.0
    row["ipctk_accd_s"], tau_a = median_time(lambda: i_ccd(ipctk.AdditiveCCD()), repeat)
    row["ipctk_tight_s"], tau_t = median_time(lambda: i_ccd(ipctk.TightInclusionCCD()), max(1, repeat // 2))
    row["ipctk_accd_tau"], row["ipctk_tight_tau"] = tau_a, tau_t
    row["ipctk_accd_min_gap"] = sampled_min_gap(pos, dpos, topo, tau_a, r)
    row["ipctk_tight_min_gap"] = sampled_min_gap(pos, dpos, topo, tau_t, r)

    def i_per_pair():
        acc = 0.0
        for x in X:
            acc += np.trace(ipctk.edge_edge_distance_hessian(x[0:3], x[3:6], x[6:9], x[9:12]))
        return acc

    row["ipctk_per_pair_us"] = median_time(i_per_pair, repeat)[0] / m * 1e6
    for k in ("broad", "barrier"):
        row[f"ratio_{k}"] = row[f"ipctk_{k}_s"] / row[f"der_{k}_s"]
    row["ratio_ccd_accd"] = row["ipctk_accd_s"] / row["der_ccd_s"]
    row["ratio_ccd_tight"] = row["ipctk_tight_s"] / row["der_ccd_s"]
    row["ratio_per_pair"] = row["ipctk_per_pair_us"] / row["der_per_pair_us"]
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[100, 1000, 10000])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1, help="ipctk threads (default 1, like der's kernels)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    try:
        import ipctk
        ipctk.set_num_threads(args.threads)
        version = ipctk.__version__
    except ImportError as err:
        ipctk, version = None, f"not installed ({err})"
    rows = [run(n, args.repeat, ipctk) for n in args.n]
    meta = {"python": platform.python_version(), "machine": platform.machine(), "ipctk": version,
            "ipctk_threads": args.threads, "repeat": args.repeat}
    if args.json:
        print(json.dumps({"meta": meta, "rows": rows}, indent=1))
        return
    print(f"# contact kernels, der (numba) vs ipctk {version} ({args.threads} thread), median of {args.repeat}")
    hdr = (f"{'n':>6} {'cand':>6} {'active':>6} | {'broad der':>9} {'ipctk':>9} {'x':>5} | {'barrier der':>11} "
           f"{'ipctk':>9} {'x':>5} | {'ccd der':>9} {'accd':>9} {'x':>5} {'tight':>9} {'x':>5} | "
           f"{'pair der us':>11} {'ipctk us':>8} {'x':>5}")
    short = (f"{'n':>6} {'cand':>6} {'active':>6} | {'broad der':>9} | {'barrier der':>11} | {'ccd der':>9} | "
             f"{'pair der us':>11}")
    print(hdr if ipctk is not None else short)
    for w in rows:
        if ipctk is None:
            print(f"{w['n']:>6} {w['candidates']:>6} {w['active_pairs']:>6} | {w['der_broad_s']:9.2e} | "
                  f"{w['der_barrier_s']:11.2e} | {w['der_ccd_s']:9.2e} | {w['der_per_pair_us']:11.3f}")
            continue
        print(f"{w['n']:>6} {w['candidates']:>6} {w['active_pairs']:>6} | {w['der_broad_s']:9.2e} "
              f"{w['ipctk_broad_s']:9.2e} {w['ratio_broad']:5.1f} | {w['der_barrier_s']:11.2e} "
              f"{w['ipctk_barrier_s']:9.2e} {w['ratio_barrier']:5.1f} | {w['der_ccd_s']:9.2e} "
              f"{w['ipctk_accd_s']:9.2e} {w['ratio_ccd_accd']:5.1f} {w['ipctk_tight_s']:9.2e} "
              f"{w['ratio_ccd_tight']:5.1f} | {w['der_per_pair_us']:11.3f} {w['ipctk_per_pair_us']:8.2f} "
              f"{w['ratio_per_pair']:5.0f}")
    if ipctk is None:
        for w in rows:
            print(f"{w['n']:>6} tau {w['der_tau']:.4f} min gap/2r on [0, tau] "
                  f"{w['der_tau_min_gap'] / (2 * w['radius']):.4f} first call {w['der_first_call_s']:.2f} s")
        return
    print("# x = ipctk time / der time (> 1: der faster)")
    print(f"{'n':>6} {'E rel':>9} {'grad rel':>9} {'hess rel':>9} {'ipctk act':>9} | {'tau der':>8} {'accd':>8} "
          f"{'tight':>8} | min gap/2r on [0, tau]: {'der':>8} {'accd':>8} {'tight':>8} | first call s")
    for w in rows:
        if ipctk is None:
            print(f"{w['n']:>6} tau {w['der_tau']:.4f} min gap {w['der_tau_min_gap'] / (2 * w['radius']):.4f} "
                  f"first {w['der_first_call_s']:.2f}")
            continue
        two_r = 2 * w["radius"]
        print(f"{w['n']:>6} {w['energy_rel_diff']:9.1e} {w['grad_rel_diff']:9.1e} {w['hess_rel_diff']:9.1e} "
              f"{w['ipctk_active']:>9} | {w['der_tau']:8.4f} {w['ipctk_accd_tau']:8.4f} {w['ipctk_tight_tau']:8.4f} | "
              f"{'':>24}{w['der_tau_min_gap'] / two_r:8.4f} {w['ipctk_accd_min_gap'] / two_r:8.4f} "
              f"{w['ipctk_tight_min_gap'] / two_r:8.4f} | {w['der_first_call_s']:.2f}")


if __name__ == "__main__":
    main()
