"""Time and memory of one contact Newton iteration of the implicit solver against n, with the fitted exponent.

    python tools/bench_contact_newton.py [--n 200 400 1000 3000 10000] [--iterations 6] [--repeat 3] [--json]
                                         [--state FILE] [--splu] [--samples m] [--no-memory] [--old-list]
                                         [--no-cholesky] [--no-arc-list]

Configuration: the plectoneme of scenarios/plectoneme.py (L = 20, A1 = 1, A2 = 1/0.67, EA = 1e5, r = 0.05,
F = 1, clamped bottom, top turned and sliding) at 5 turns, a converged state at n = 400 (``--state``, a pickle
(scene, state) written by scenarios/plectoneme.py's continuation; without it the continuation is run here first),
resampled along its arc length to n edges by a cubic spline through its nodes (continuous curvature, so that a
fine resampling does not bend tighter than r at the coarse polygon's corners, as linear interpolation did at
n = 10,000) and widened across the axis by the least of 2, 5, 10, 20, 40 % that keeps its strands more than 2r
apart. ``--samples m``: the contact term with m sample points per edge (der.self_contact(r, samples=m)). Each n: der.solve from that start with max_iterations = --iterations, with self-contact
(the sparse path: RCM + banded LU, or splu) and, for the same start and the same iterations, without it (the
banded path); time per iteration = (CPU time, ``time.process_time``, of a solve of 2 + --iterations iterations
minus that of 2) / --iterations, the median of --repeat; memory = tracemalloc's peak of the solve (numpy's
allocations; ``--no-memory``: not traced, tracemalloc slows every allocation). ``--old-list``: the contact line
search on the Verlet list, as before the one pair list per Newton step (der/terms/contact.py STEP_LIST = False),
for a side-by-side run; ``--no-cholesky``: the reordered band factorised by dgbsv only, as before the banded
Cholesky (der/solvers/implicit.py CONTACT_CHOLESKY = False); ``--no-arc-list``: the arc trials of the
second-order-corrected line search on the Verlet list or a new broad phase, as before their step list
and a long step's trials on the Verlet list rebuilt at each, not on the CCD's swept list (der/terms/contact.py
ARC_STEP_LIST = LONG_STEP_LIST = False; bitwise the same iterations). The exponent is the least-squares slope of log(time) against log(n).
"""
import argparse
import json
import os
import pickle
import sys
import time
import tracemalloc

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))

import der  # noqa: E402

L, A1, A2, EA, R, F = 20.0, 1.0, 1.0 / 0.67, 1e5, 0.05, 1.0


def base_state(path):
    if path and os.path.exists(path):
        with open(path, "rb") as f:
            return pickle.load(f)[1].positions
    sys.path.insert(0, os.path.join(HERE, "..", "scenarios"))
    import plectoneme as P

    p = argparse.Namespace(A1=A1, A2=A2, L=L, EA=EA, radius=R, force=F, turns=5.0, sweep=20, perturb=1e-3, png=None,
                           samples=None, predictor="last",
                           n=400)
    keep = {}

    class Solver:
        args = argparse.Namespace(tol=1e-4)

        def solve(self, scene, **kw):
            kw.setdefault("tol", 1e-4)
            r = der.solve(scene, raise_on_failure=False, **kw)
            keep["x"] = r.state.positions
            return r

    P.run(p, Solver())
    return keep["x"]


WIDEN = (1.02, 1.05, 1.1, 1.2, 1.4)


def resample(x, n, widen):
    from scipy.interpolate import CubicSpline

    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(x, axis=0), axis=1))])
    t = np.linspace(0.0, s[-1], n + 1)
    y = CubicSpline(s, x, axis=0)(t)
    y[:, :2] *= widen
    return y


SAMPLES = None     # --samples
MEMORY = True      # --no-memory: False


def one(n, x400, iterations, contact):
    """(seconds per Newton iteration, peak bytes, result): the time of a solve of 2 + iterations minus that of a
    solve of 2 iterations, over iterations (the setup and the final diagnostics of a solve cancel)."""
    t_short, _, _ = _solve(n, x400, 2, contact)
    t_long, peak, r = _solve(n, x400, 2 + iterations, contact)
    return (t_long - t_short) / max(r.iterations - 2, 1), peak, r


def _solve(n, x400, iterations, contact):
    from scenarios.plectoneme import rotation_z

    rod = der.rod_from_shape(der.shapes.straight(L, n), A1, A2, EA=EA)
    scene = der.Scene(rod, loads=[der.end_force([0.0, 0.0, F])],
                      constraints=[der.clamp("start"), der.clamp("end", rotation=rotation_z(2 * np.pi * 5.0), slide=2)],
                      contacts=[der.self_contact(R, samples=SAMPLES)] if contact else [])
    from der.contact.samples import min_distance
    from der.contact import topology, candidate_pairs, exclusion_k

    for widen in WIDEN:
        # the least widening (of WIDEN) that keeps non-neighbour edges more than 2r apart
        x = resample(x400, n, widen)
        h = L / n
        topo = topology([(n, False, R, h)], 0.1 * R)
        topo = topo._replace(rod_k=np.array([exclusion_k(h, R, 0.1 * R, arc=np.pi * R + 0.1 * R)]))
        pairs = candidate_pairs(x, topo, 0.0)
        if not pairs.size or min_distance(x, topo.edges, pairs) > 2 * R * (1 + 1e-6):
            break
    start = rod.displaced(rod.rest_state(), x - rod.rest_state().positions)
    if MEMORY:
        tracemalloc.start()
    c0 = time.process_time()
    r = der.solve(scene, state=start, stability=False, max_iterations=iterations, raise_on_failure=False, tol=1e-14)
    cpu = time.process_time() - c0
    peak = 0
    if MEMORY:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    r.widen = widen
    return cpu, peak, r


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[200, 400, 1000, 3000, 10000])
    ap.add_argument("--iterations", type=int, default=6)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--state", default=None)
    ap.add_argument("--splu", action="store_true", help="the contact path with splu (COLAMD) only, as before RCM")
    ap.add_argument("--samples", type=int, default=None, help="sample points per edge of the contact barrier")
    ap.add_argument("--no-memory", action="store_true", help="do not trace the peak memory (tracemalloc)")
    ap.add_argument("--old-list", action="store_true",
                    help="line-search trials on the Verlet list, not one pair list per Newton step (the A/B)")
    ap.add_argument("--no-cholesky", action="store_true",
                    help="the reordered contact band by dgbsv only, not the banded Cholesky (the A/B)")
    ap.add_argument("--no-arc-list", action="store_true",
                    help="arc trials on the Verlet list, not the step's list widened to the arc (the A/B)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    global SAMPLES, MEMORY
    SAMPLES = args.samples
    MEMORY = not args.no_memory
    if args.old_list:
        import der.terms.contact as contact_term

        contact_term.STEP_LIST = False
    if args.no_arc_list:
        import der.terms.contact as contact_term

        contact_term.ARC_STEP_LIST = contact_term.LONG_STEP_LIST = False
    import der.solvers.implicit as implicit

    if args.splu:
        implicit.BANDED_CONTACT = False
    if args.no_cholesky:
        implicit.CONTACT_CHOLESKY = False
    from der.terms import warmup

    warmup()
    x400 = base_state(args.state)
    one(400, x400, 1, True)                    # compile / load everything once
    rows = []
    for n in args.n:
        tc, tb, mem, fc, fb = [], [], [], [], []
        try:
            one(n, x400, 1, True)
        except ValueError as exc:           # e.g. a resampled corner bent tighter than r at large n
            rows.append({"n": n, "refused": str(exc)})
            continue
        for _ in range(args.repeat):
            t, m, r = one(n, x400, args.iterations, True)
            tc.append(t)
            mem.append(m)
            t2, _, rb = one(n, x400, args.iterations, False)
            tb.append(t2)
            fc.append(r.timings["factorisation"] / max(sum(r.linear_solves.values()), 1))
            fb.append(rb.timings["factorisation"] / max(sum(rb.linear_solves.values()), 1))
        c = r.contact or {}
        rows.append({"n": n, "contact_s_per_iteration": float(np.median(tc)), "band_s_per_iteration": float(np.median(tb)),
                     "ratio": float(np.median(tc) / np.median(tb)),
                     "contact_s_per_linear_solve": float(np.median(fc)), "band_s_per_linear_solve": float(np.median(fb)),
                     "linear_solve_ratio": float(np.median(fc) / np.median(fb)), "peak_bytes": int(np.median(mem)),
                     "contacts": c.get("n_contacts"), "widened": r.widen, "linear_solves": dict(r.linear_solves),
                     "iterations": r.iterations})
    refused = [r for r in rows if "refused" in r]
    rows = [r for r in rows if "refused" not in r]
    ns = np.array([r["n"] for r in rows], float)
    fit = lambda k: float(np.polyfit(np.log(ns), np.log([r[k] for r in rows]), 1)[0]) if len(rows) > 1 else None  # noqa
    out = {"tool": "bench_contact_newton", "cpu_time": True, "splu": args.splu, "old_list": args.old_list, "cholesky": not args.no_cholesky,
           "arc_list": not args.no_arc_list,
           "samples": args.samples, "rows": rows, "refused": refused, "exponent_time": fit("contact_s_per_iteration"),
           "exponent_time_band": fit("band_s_per_iteration"),
           "exponent_linear_solve": fit("contact_s_per_linear_solve"), "exponent_memory": fit("peak_bytes") if MEMORY else None}
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        print("| n | contacts | contact Newton iteration | no-contact iteration | ratio | contact linear solve | "
              "band solve | ratio | peak memory |")
        print("|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r['n']:,} | {r['contacts']} | {r['contact_s_per_iteration'] * 1e3:.2f} ms | "
                  f"{r['band_s_per_iteration'] * 1e3:.2f} ms | {r['ratio']:.1f} | {r['contact_s_per_linear_solve'] * 1e3:.2f} ms | "
                  f"{r['band_s_per_linear_solve'] * 1e3:.2f} ms | {r['linear_solve_ratio']:.1f} | {r['peak_bytes'] / 1e6:.1f} MB |")
        for r in refused:
            print(f"n = {r['n']:,}: refused: {r['refused']}")
        if out["exponent_time"] is not None:
            print(f"fitted exponents: time n^{out['exponent_time']:.2f} (no contact n^{out['exponent_time_band']:.2f})"
                  + (f", memory n^{out['exponent_memory']:.2f}" if MEMORY else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
