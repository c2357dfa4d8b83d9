"""Error against run time for the paper's scenarios: both solvers, a sweep in n, and where the error floor
comes from.

    python tools/error_vs_runtime.py [--scenario ring_torsion] [--repeat 3] [--budget 300] [--json]
                                     [--csv PATH] [--png PATH] [--rrd PATH]

For each scenario (ring_torsion, helix_torque, helix_winding, loop_twist; or the one named) and each solver it
sweeps n (implicit 25 ... 1600, explicit 25 ... 400 within a time budget per solve), records the headline error
against the scenario's reference and the solve wall time (median of ``--repeat`` runs; compilation is done
once beforehand and reported apart), fits the convergence order in n, and reports the run time needed to reach
errors of 1e-3, 1e-4 and 1e-6. The linear scenarios (ring_torsion, helix_torque) are solved at +load and -load
and compared by their odd part, which removes the O(load^2) error of the linearised closed form; that error, the
error of a finite axial stiffness and that of the solver tolerance are then measured apart (``sources``). The
last line with --json is one JSON object; --csv writes the sweep, --png a log-log plot of error against run time
(matplotlib), --rrd the same as rerun time series.
"""
import argparse
import csv
import importlib.util
import json
import os
import platform
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))

import der  # noqa: E402
from der.cli import SolveRunner  # noqa: E402

SCENARIO_DIR = os.path.join(HERE, "..", "scenarios")
SCENARIOS = {
    # name: (extra parameters of the sweep, the note on its reference)
    "ring_torsion": ({"symmetric": 1, "T": 1e-2}, "corrected closed form, end rotation; odd part of +T/-T solves"),
    "helix_torque": ({"symmetric": 1, "P": 1e-4, "T": 2e-4},
                     "corrected closed form, worst profile; odd part of +load/-load solves"),
    "helix_winding": ({}, "corrected Eq. 81 and axial torque (exact for uniform helices)"),
    "loop_twist": ({}, "paper Eq. 40 (correct)"),
}
N_IMPLICIT = [25, 50, 100, 200, 400, 800, 1600]
N_EXPLICIT = [25, 50, 100, 200, 400]
TARGETS = (1e-3, 1e-4, 1e-6)


def load(name):
    spec = importlib.util.spec_from_file_location(name, os.path.join(SCENARIO_DIR, f"{name}.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


class BudgetRunner(SolveRunner):
    """The scenario harness' solver wrapper, with a time budget and extra options for every solve."""

    def __init__(self, args, **options):
        super().__init__(args)
        self.options = options

    def solve(self, scene, state=None, **options):
        return super().solve(scene, state=state, **{**self.options, **options})


def run_once(mod, n, solver, tol=1e-8, budget=300.0, **params):
    defaults = {p[0]: p[1] for p in mod.PARAMETERS}
    defaults.update(params)
    p = argparse.Namespace(n=n, solver=solver, tol=tol, rrd=None, max_iterations=None, json=True, **defaults)
    mod.run.validate(p)
    runner = BudgetRunner(p, time_budget=budget, stability=False)
    out = mod.run(p, runner)
    out["params"] = vars(p)
    return {"error": out.get("error"), "runtime_s": runner.runtime, "iterations": runner.iterations,
            "converged": all(r.converged for r in runner.results),
            "status": ",".join(sorted({r.status for r in runner.results})), "out": out}


def measure(mod, n, solver, repeat, budget, **params):
    runs = [run_once(mod, n, solver, budget=budget, **params)]
    if runs[0]["converged"]:
        runs += [run_once(mod, n, solver, budget=budget, **params) for _ in range(repeat - 1)]
    r = dict(runs[0])
    r["runtime_s"] = float(np.median([x["runtime_s"] for x in runs]))
    r["runs"] = len(runs)
    r.pop("out")
    return r


def asymptotic(rows):
    """The converged runs up to the last one whose error still falls with n: past it a floor (round-off of a
    lightly loaded fine rod, or the linearisation of the closed form) dominates, which is no convergence order."""
    ok = [r for r in rows if r["converged"] and r["error"]]
    for k in range(1, len(ok)):
        if ok[k]["error"] >= ok[k - 1]["error"]:
            return ok[:k], ok[k:]
    return ok, []


def fitted_order(rows):
    """(order, first n, last n) of error ~ n^-order over the asymptotic runs, or (None, None, None)."""
    ok, _ = asymptotic(rows)
    if len(ok) < 3:
        return None, None, None
    ns = np.array([r["n"] for r in ok], float)
    errs = np.array([r["error"] for r in ok])
    return float(-np.polyfit(np.log(ns), np.log(errs), 1)[0]), ok[0]["n"], ok[-1]["n"]


def time_to_reach(rows, target):
    """Run time to reach ``target`` (log-log interpolation between the bracketing runs), or a reason."""
    ok = [r for r in rows if r["converged"] and r["error"]]
    for a, b in zip(ok, ok[1:]):
        if a["error"] > target >= b["error"]:
            t = np.exp(np.interp(np.log(target), [np.log(b["error"]), np.log(a["error"])],
                                 [np.log(b["runtime_s"]), np.log(a["runtime_s"])]))
            return float(t), None
    if ok and ok[0]["error"] <= target:
        return float(ok[0]["runtime_s"]), None
    unfinished = [r for r in rows if not r["converged"]]
    if unfinished:
        return None, f"not reached: n = {unfinished[0]['n']} did not finish ({unfinished[0]['status']})"
    if not ok:
        return None, "no runs"
    best = min(ok, key=lambda r: r["error"])
    if best is not ok[-1]:
        return None, (f"not reached: floor {best['error']:.1e} at n = {best['n']}, error rising to "
                      f"{ok[-1]['error']:.1e} at n = {ok[-1]['n']} (see error sources)")
    return None, f"not reached: error {ok[-1]['error']:.1e} at the largest n = {ok[-1]['n']}"


def primary(name, out):
    """The quantity each scenario's error is measured on, as one vector."""
    if name == "ring_torsion":
        return np.array(out["end_rotation"])
    if name == "helix_torque":
        return np.concatenate([np.asarray(out["profile"][k]) for k in ("Mn", "Mb", "Mt", "dalpha", "dkappa",
                                                                        "domega")])
    if name == "helix_winding":
        return np.array([out["P0"], out["T0"]])
    return np.array([out["alpha"]])


def error_sources(mod, name, n=400):
    """At fixed n, the error of each approximation measured apart: discretisation (the headline error), the
    linearisation of the closed form (linear scenarios), a finite axial stiffness, the solver tolerance."""
    extra = dict(SCENARIOS[name][0])
    base_out = run_once(mod, n, "implicit", tol=1e-10, **extra)["out"]
    ref = primary(name, base_out)

    def rel(other, scale=1.0):
        return float(np.abs(primary(name, other) * scale - ref).max() / np.abs(ref).max())

    out = {"n": n, "discretisation (headline error)": base_out["error"]}
    if "symmetric" in extra:
        load = "T" if name == "ring_torsion" else "P"
        value = extra.get(load, {p[0]: p[1] for p in mod.PARAMETERS}[load])
        raw = run_once(mod, n, "implicit", tol=1e-10, **{**extra, "symmetric": 0})["out"]
        out["linearisation, O(load^2) even part (raw minus odd part)"] = rel(raw)
        if name == "ring_torsion":
            small = run_once(mod, n, "implicit", tol=1e-10, **{**extra, load: value / 10})["out"]
            out["linearisation left in the odd part, O(load^3) (T vs T/10)"] = rel(small, 10.0)
    length = {"ring_torsion": 3.0, "helix_torque": 2 * np.pi / np.hypot(1.0, 0.6),
              "helix_winding": 2 * np.pi / np.hypot(1.0, 0.6), "loop_twist": 2 * np.pi}[name]
    A1 = {p[0]: p[1] for p in mod.PARAMETERS}.get("A1", {p[0]: p[1] for p in mod.PARAMETERS}.get("A", 1.0))
    for S in (1e4, 1e6, 1e8, 1e10):
        ea = run_once(mod, n, "implicit", tol=1e-10, **extra, EA=S * A1 / length ** 2)["out"]
        out[f"finite stretch stiffness, EA L^2/A1 = {S:.0e}"] = rel(ea)
    for tol in (1e-2, 1e-4, 1e-6):
        out[f"solver tolerance {tol:.0e}"] = rel(run_once(mod, n, "implicit", tol=tol, **extra)["out"])
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", choices=sorted(SCENARIOS), default=None)
    ap.add_argument("--solvers", nargs="+", default=["implicit", "explicit"], choices=["implicit", "explicit"])
    ap.add_argument("--n-implicit", type=int, nargs="+", default=N_IMPLICIT)
    ap.add_argument("--n-explicit", type=int, nargs="+", default=N_EXPLICIT)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--budget", type=float, default=300.0, help="time budget per solve, seconds")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--csv", default=None)
    ap.add_argument("--png", default=None)
    ap.add_argument("--rrd", default=None)
    ap.add_argument("--from-csv", default=None, metavar="CSV",
                    help="only re-plot --png from a CSV this tool wrote (no solve), e.g. docs/figures/error_vs_runtime.csv")
    args = ap.parse_args(argv)
    if args.png:
        from der.plotting import require_matplotlib
        try:
            require_matplotlib("--png")
        except ValueError as exc:
            print(f"error_vs_runtime.py: invalid input: {exc}", file=sys.stderr)
            sys.exit(2)
    if args.from_csv:
        if not args.png:
            print("error_vs_runtime.py: invalid input: --from-csv needs --png (it only re-plots)", file=sys.stderr)
            sys.exit(2)
        _plot(read_csv(args.from_csv), args.png)
        return
    names = [args.scenario] if args.scenario else list(SCENARIOS)
    compile_s = der.warmup()
    results, summary, sources = [], [], {}
    for name in names:
        mod = load(name)
        extra, note = SCENARIOS[name]
        for solver in args.solvers:
            rows = []
            stop = None
            for n in (args.n_implicit if solver == "implicit" else args.n_explicit):
                if stop:
                    rows.append({"scenario": name, "solver": solver, "n": n, "converged": False, "error": None,
                                 "runtime_s": None, "iterations": None, "status": f"skipped ({stop})", "runs": 0})
                    continue
                t0 = time.perf_counter()
                r = measure(mod, n, solver, args.repeat, args.budget, **extra)
                r.update({"scenario": name, "solver": solver, "n": n})
                rows.append(r)
                err = "-" if r["error"] is None else f"{r['error']:.3e}"
                print(f"{name:<14} {solver:<9} n={n:<5} error={err} time={r['runtime_s']:.3f}s "
                      f"status={r['status']} ({time.perf_counter() - t0:.1f} s)", file=sys.stderr)
                if not r["converged"]:
                    stop = f"n = {n} did not finish: {r['status']}"
            results += rows
            order, n_first, n_last = fitted_order(rows)
            row = {"scenario": name, "solver": solver, "order": order, "order_n_range": [n_first, n_last],
                   "reference": note}
            for target in TARGETS:
                t, why = time_to_reach(rows, target)
                row[f"time_to_{target:.0e}"] = t if t is not None else why
            summary.append(row)
        src = error_sources(mod, name)
        if src:
            sources[name] = src
    print(f"\nmachine: {platform.machine()}, {os.cpu_count()} cores; compilation (or cache load) {compile_s:.2f} s")
    print(f"{'scenario':<14} {'solver':<9} {'n':>5} {'error':>10} {'run time s':>11} {'iterations':>11}  status")
    for r in results:
        err = f"{r['error']:.3e}" if r["error"] is not None else "-"
        rt = f"{r['runtime_s']:.4f}" if r["runtime_s"] is not None else "-"
        print(f"{r['scenario']:<14} {r['solver']:<9} {r['n']:>5} {err:>10} {rt:>11} {str(r['iterations']):>11}  "
              f"{r['status']}")
    print(f"\n{'scenario':<14} {'solver':<9} {'order':>6}  {'fitted over':<16} time to 1e-3 / 1e-4 / 1e-6")
    for s in summary:
        times = [s[f"time_to_{t:.0e}"] for t in TARGETS]
        shown = [f"{t:.3g} s" if isinstance(t, float) else t for t in times]
        order = f"{s['order']:.2f}" if s["order"] is not None else "-"
        span = "n = {} ... {}".format(*s["order_n_range"]) if s["order"] is not None else ""
        print(f"{s['scenario']:<14} {s['solver']:<9} {order:>6}  {span:<16} " + " / ".join(shown))
    for name, src in sources.items():
        print(f"\nerror sources, {name} (relative change of its measured quantity, implicit, n = {src['n']}):")
        for k, v in src.items():
            if k != "n":
                print(f"  {k:<50} {v:.2e}")
    if args.csv:
        with open(args.csv, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=["scenario", "solver", "n", "error", "runtime_s", "iterations",
                                               "converged", "status", "runs"])
            w.writeheader()
            for r in results:
                w.writerow({k: r.get(k) for k in w.fieldnames})
    if args.png:
        _plot(results, args.png)
    if args.rrd:
        _record(results, args.rrd)
    if args.json:
        print(json.dumps({"compile_s": compile_s, "machine": platform.machine(), "rows": results,
                          "summary": summary, "sources": sources}))


def read_csv(path):
    """The rows of a CSV written by ``--csv`` (types restored), for ``--from-csv``."""
    rows = []
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            num = lambda v, f=float: f(v) if v not in ("", "None") else None  # noqa: E731
            rows.append({"scenario": r["scenario"], "solver": r["solver"], "n": int(r["n"]), "error": num(r["error"]),
                         "runtime_s": num(r["runtime_s"]), "iterations": num(r["iterations"], int),
                         "converged": r["converged"] == "True", "status": r["status"], "runs": num(r["runs"], int)})
    return rows


def _plot(results, path):
    from der.plotting import pyplot

    plt = pyplot("error_vs_runtime.py")
    if plt is None:
        return
    fig, ax = plt.subplots(figsize=(10, 5.5))
    keys = sorted({(r["scenario"], r["solver"]) for r in results})
    names = sorted({k[0] for k in keys})
    for i, (name, solver) in enumerate(keys):
        rows = [r for r in results if (r["scenario"], r["solver"]) == (name, solver) and r["converged"]
                and r["error"] and r["runtime_s"]]
        if not rows:
            continue
        color = f"C{names.index(name)}"
        ax.loglog([r["runtime_s"] for r in rows], [r["error"] for r in rows],
                  "o-" if solver == "implicit" else "s--", color=color, label=f"{name}, {solver}", ms=4)
        # n only at the last point of each curve (every point labelled piled up where the implicit curves cross,
        # near 1e-3 s and 1e-3); the first n, the same for every curve, is said in the title
        last = rows[-1]
        above = names.index(name) % 2 == 0   # alternate, so that neighbouring curves' labels do not overlap
        ax.annotate(f"n={last['n']}", (last["runtime_s"], last["error"]), fontsize=7, color=color,
                    va="bottom" if above else "top", ha="left", xytext=(4, 4 if above else -4),
                    textcoords="offset points")
    ax.set(xlabel="solve wall time [s] (median of 3, compilation excluded)", ylabel="relative error",
           title=f"error against run time: n = {min(r['n'] for r in results)} edges at the left end of each curve, "
                 "doubling along it")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def _record(results, path):
    import rerun as rr

    rec = rr.RecordingStream("der-error-vs-runtime")
    rec.save(path)
    for r in results:
        if not r["converged"]:
            continue
        rec.set_time("n", sequence=int(r["n"]))
        rec.log(f"error/{r['scenario']}/{r['solver']}", rr.Scalars(float(np.log10(r["error"]))))
        rec.log(f"runtime/{r['scenario']}/{r['solver']}", rr.Scalars(float(np.log10(r["runtime_s"]))))
    rec.flush()
    rec.disconnect()


if __name__ == "__main__":
    main()
