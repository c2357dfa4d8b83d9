"""Cost and accuracy of the stability analysis at large n: a straight cantilever (clamped at xi = 0, A1 = 1,
rho_A = 1, L = 1) under a small transverse tip load 1e-4 A1/L^2 (so that the solve does real Newton work; it
moves the eigenvalue by O(1e-8)); the lowest eigenvalue of the pencil (K, M) is compared with the Euler-Bernoulli
value (1.8751041)^4 A1/(rho_A L^4) = 12.362363.

    python tools/stability_scaling.py [--n 1000 10000 100000] [--edge-newton | --both] [--baseline] [--repeat 3]
                                      [--threads 1] [--json]

``--edge-newton`` solves with ``SolverOptions(edge_newton=True)`` (Newton steps in edge coordinates: the loaded
solve converges at n = 10^5, where node-coordinate steps are round-off); ``--both`` gives the rows of both solvers.
``--baseline`` times the analysis also with the previous block Lanczos (``stability.EDGE_LANCZOS = "baseline"``:
numpy products, a temporary per update) beside the current one (numba sweeps), the two alternating run by run in
the same process, and prints both CPU times and ratios side by side ("base cpu", "base ratio"). ``--threads`` sets
OPENBLAS_NUM_THREADS/OMP_NUM_THREADS before numpy loads (default 1: on a shared, loaded machine threaded BLAS
costs more than it saves; 0 leaves them alone).

Per n, CPU times (``time.process_time``, the least of ``--repeat`` runs each) side by side: ``der.solve`` without
the analysis ("solve cpu"), with it ("+stab cpu"), and the analysis's own CPU time in the latter ("stab cpu",
``result.stability_cpu_time``: it includes the whole assembly of the Hessian at the final state, which the solver
then does with its last force evaluation); "cpu ratio" is stab cpu / solve cpu. Then the lowest eigenvalue, its relative error, its relative
eigen-residual ||K v - lambda M v|| / (|lambda| ||M v||) in node coordinates with the residual's own round-off level
("its r-o", edge path only), the eigenvalue's round-off floor eps |v|^T |K| |v| / v^T M v in the coordinates the
analysis used (it grows like eps n^4 in node coordinates, like eps n^2 in edge coordinates), and the method
(der.solvers.stability: "edge shift-invert" for this clamped rod, with its eigen-solver and operator passes).

If the loaded solve fails (n = 10^5 without ``--edge-newton``: Newton's steps in node coordinates are round-off,
the condition number of the stiffness growing like n^4), the row says so and times the analysis alone
(``stability`` on a fresh system, assembling its Hessian) at an exact equilibrium instead, the unloaded cantilever
at rest (no solve time to compare with).
"""
import argparse
import json
import os
import sys

if __name__ == "__main__":
    _t = "1"
    for i, a in enumerate(sys.argv):
        if a == "--threads" and i + 1 < len(sys.argv):
            _t = sys.argv[i + 1]
    if _t != "0":
        os.environ["OPENBLAS_NUM_THREADS"] = os.environ["OMP_NUM_THREADS"] = _t

import time  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import der  # noqa: E402
import der.solvers.stability as _stability  # noqa: E402
from der.solvers.stability import lowest_modes, stability  # noqa: E402
from der.solvers.system import build_system, prepare_state  # noqa: E402

EXACT = 1.8751040687119611 ** 4
P = 1e-4   # a small transverse tip load (A1/L^2): a real solve; it moves the eigenvalue by O(P^2) only


def _least_cpu(fn, repeat):
    """(least CPU seconds over ``repeat`` calls, the last call's value)."""
    best, out = np.inf, None
    for _ in range(repeat):
        c0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - c0)
    return best, out


def _with_lanczos(variant, fn):
    """``fn()`` with the edge analysis's block Lanczos ``variant`` ("fused" or "baseline")."""
    old = _stability.EDGE_LANCZOS
    _stability.EDGE_LANCZOS = variant
    try:
        return fn()
    finally:
        _stability.EDGE_LANCZOS = old


def row(n, load=None, edge_newton=False, repeat=3, baseline=False):
    load = P if load is None else load
    variants = ["fused", "baseline"] if baseline else ["fused"]
    rod = der.rod_from_shape(der.shapes.straight(1.0, n, axis=(0, 0, 1), director=(1, 0, 0)), 1.0, 1.0)
    scene = der.Scene(rod, loads=[der.end_force([load, 0, 0])], constraints=[der.clamp("start")])
    options = der.SolverOptions(edge_newton=True) if edge_newton else der.SolverOptions()
    try:
        # CPU times side by side: the solve alone, then the solve with the analysis der.solve runs after it
        cpu_solve, r0 = _least_cpu(lambda: der.solve(scene, options=options, progress=False, stability=False),
                                   repeat)
        # (with --baseline the two Lanczos variants alternate run by run: the same machine state for both)
        runs = {v: [] for v in variants}
        for _ in range(repeat):
            for v in variants:
                runs[v].append(_with_lanczos(v, lambda: _least_cpu(
                    lambda: der.solve(scene, options=options, progress=False), 1)))
        cpu_both = min(c for c, _ in runs["fused"])
        res = runs["fused"][-1][1]
        # the analysis's own CPU time (result.stability_cpu_time: with the Hessian's assembly at the final state)
        cpu_stab = min(r.stability_cpu_time for _, r in runs["fused"])
        base = {}
        if baseline:
            rb = runs["baseline"][-1][1]
            base = {"cpu_stability_baseline_s": min(r.stability_cpu_time for _, r in runs["baseline"]),
                    "lowest_baseline": float(rb.min_eigenvalue)}
            base["cpu_ratio_baseline"] = base["cpu_stability_baseline_s"] / cpu_solve
    except der.ConvergenceError as exc:
        # the loaded solve failed (at n = 10^5 Newton's steps in node coordinates are round-off: the stiffness's
        # condition number grows like n^4). No analysis of an uncertified state: the analysis alone is timed at an
        # exact equilibrium instead, the unloaded cantilever at rest
        r = exc.result
        rest = der.Scene(rod, constraints=[der.clamp("start")])
        system = build_system(rest, der.SolverOptions())
        state = prepare_state(system, rod.rest_state())
        res = der.SolveResult(state=state, converged=True, status="", residual=float("nan"), iterations=0,
                              wall_time=0.0, message="the rest state")
        cpu_stab, _ = _least_cpu(lambda: stability(system, res), repeat)
        base = {}
        if baseline:
            rb = der.SolveResult(state=state, converged=True, status="", residual=float("nan"), iterations=0,
                                 wall_time=0.0, message="the rest state")
            base["cpu_stability_baseline_s"] = _with_lanczos("baseline", lambda: _least_cpu(
                lambda: stability(system, rb), repeat))[0]
            base["lowest_baseline"] = float(rb.min_eigenvalue)
        out = lowest_modes(build_system(rest, der.SolverOptions()), state, 6)
        lam = float(res.min_eigenvalue)
        return {"n": n, "edge_newton": edge_newton, "solve_s": r.wall_time, "iterations": r.iterations,
                "status": r.status, "message": r.message, "exact": EXACT, "analysed": "unloaded rest state",
                "stability_s": res.stability_time, "cpu_stability_s": cpu_stab, "lowest": lam,
                "rel_error": (lam - EXACT) / EXACT, "rel_residual": float(out["residuals"][0]),
                "residual_floor": float(out.get("residual_floors", [np.nan])[0]),
                "floor": float(out["floors"][0]), "method": out["method"],
                "eigen_solver": out.get("eigen_solver", ""), "note": res.stability_note, **base}
    out = lowest_modes(build_system(scene, der.SolverOptions()), res.state, 6)
    lam = float(res.min_eigenvalue)
    return {"n": n, "edge_newton": edge_newton, "load": load, "solve_s": r0.wall_time, "iterations": res.iterations,
            "status": res.status, "residual": res.residual, "stability_s": res.stability_time,
            "cpu_solve_s": cpu_solve, "cpu_solve_and_stability_s": cpu_both, "cpu_stability_s": cpu_stab,
            "cpu_ratio": cpu_stab / cpu_solve, "lowest": lam, "exact": EXACT, "analysed": "solved state",
            "rel_error": (lam - EXACT) / EXACT, "rel_residual": float(out["residuals"][0]),
            "residual_floor": float(out.get("residual_floors", [np.nan])[0]),
            "floor": float(out["floors"][0]), "method": out["method"], "eigen_solver": out.get("eigen_solver", ""),
            "note": res.stability_note, **base}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[1000, 10000, 100000])
    ap.add_argument("--edge-newton", action="store_true", help="Newton steps in edge coordinates")
    ap.add_argument("--both", action="store_true", help="the rows of both solvers (node, then edge Newton)")
    ap.add_argument("--baseline", action="store_true",
                    help="also time the previous block Lanczos (EDGE_LANCZOS = 'baseline'), side by side")
    ap.add_argument("--repeat", type=int, default=3, help="runs per timing (the least CPU time is kept)")
    ap.add_argument("--threads", type=int, default=1, help="BLAS threads (0: leave the environment alone)")
    ap.add_argument("--load", type=float, default=P, help=f"transverse tip load, A1/L^2 (default {P:g})")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    solvers = [False, True] if a.both else [a.edge_newton]
    for edge_newton in solvers:
        for variant in (["fused", "baseline"] if a.baseline else ["fused"]):
            _with_lanczos(variant, lambda: row(20, a.load, edge_newton, 1))    # compile
            _with_lanczos(variant, lambda: row(400, a.load, edge_newton, 1))   # compile the banded path
    rows = [row(n, a.load, edge_newton, a.repeat, a.baseline) for edge_newton in solvers for n in a.n]
    if a.json:
        print(json.dumps(rows, indent=1))
        return 0
    bh = f" {'base cpu':>8} {'base ratio':>10}" if a.baseline else ""
    print(f"{'solver':>6} {'n':>7} {'iters':>5} {'solve cpu':>9} {'+stab cpu':>9} {'stab cpu':>8} {'cpu ratio':>9}{bh} "
          f"{'lowest':>12} {'rel err':>10} {'residual':>9} {'its r-o':>8} {'floor':>9}  method")
    for r in rows:
        solver = "edge" if r["edge_newton"] else "node"
        b = ""
        if a.baseline:
            ratio = f"{r['cpu_ratio_baseline']:10.2f}" if "cpu_ratio_baseline" in r else f"{'-':>10}"
            b = f" {r['cpu_stability_baseline_s']:8.3f} {ratio}"
        if "cpu_ratio" not in r:
            print(f"{solver:>6} {r['n']:>7} {r['iterations']:>5} {'-':>9} {'-':>9} {r['cpu_stability_s']:8.3f} "
                  f"{'-':>9}{b} {r['lowest']:12.6f} {r['rel_error']:10.2e} {r['rel_residual']:9.1e} "
                  f"{r['residual_floor']:8.1e} {r['floor']:9.1e}  {r['method']} ({r['eigen_solver']}), "
                  f"{r['analysed']}")
            print(f"{'':>14} the loaded solve: {r['status']}: {r['message']}")
            continue
        print(f"{solver:>6} {r['n']:>7} {r['iterations']:>5} {r['cpu_solve_s']:9.3f} "
              f"{r['cpu_solve_and_stability_s']:9.3f} {r['cpu_stability_s']:8.3f} {r['cpu_ratio']:9.2f}{b} "
              f"{r['lowest']:12.6f} {r['rel_error']:10.2e} {r['rel_residual']:9.1e} {r['residual_floor']:8.1e} "
              f"{r['floor']:9.1e}  {r['method']} ({r['eigen_solver']})")
    if a.baseline:
        same = all(abs(r["lowest_baseline"] - r["lowest"]) <= 1e-9 * abs(r["lowest"]) for r in rows)
        print(f"lowest eigenvalue of the baseline within 1e-9 (relative) of the current one in every row: {same}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
