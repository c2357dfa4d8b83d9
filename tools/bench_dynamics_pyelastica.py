"""der against PyElastica on cosseratbench's experiments, through both adapters (same scenario, same elements):
metrics and pass/fail against the suite's tolerances, CPU and wall time, the time step each used, and each
explicit step's stability limit; for der's implicit step, the largest one that meets the pendulum's tolerance.

    python tools/bench_dynamics_pyelastica.py                       # everything below (PyElastica's twist: ~10 min)
    python tools/bench_dynamics_pyelastica.py --full pendulum --pyelastica-full none --stability pendulum

Needs cosseratbench 0.3 and PyElastica 1.0 (``pip install -e '.[bench]'``).

Parts
* full runs (``--full``, ``--pyelastica-full``): ``cosseratbench.experiment.run`` (its own warm-up run first,
  then the timed run; wall time is the suite's, CPU time ``time.process_time`` around the call, warm-up included).
  Tolerances (the suite's ``tests/test_solvers.py``): catenary settling residual < 1e-5 and sag error < 2e-3;
  cantilever at 20 elements tip error < 0.08 and < 0.6 x the 10-element error (both resolutions are run);
  pendulum period error < 3e-4 and |amplitude change| < 1e-4; twist critical-twist error < 0.03.
* explicit stability limits (``--stability``): the largest step with which a short run from the scenario's start
  (``--steps`` steps, default 2000) stays finite and within 0.1 L of where it started, by bisection (``--bisect``
  halvings of the bracket, default 6) from a stable step up. PyElastica: its adapter's ``time_step_scale`` (its
  step is 0.5 x scale x its own estimate, ``_stable_time_step``); der: velocity Verlet on the adapter's scene with
  der's refusal of steps above its Gershgorin bound lifted (the bound is reported beside the measured limit).
  Instability grows from round-off, so a step just above the limit can survive a short run: the limit is an
  upper estimate within the bracket printed.
* der's implicit step for the pendulum (``--newmark-scales``): the adapter's ``time_step_scale`` (dt = 0.01 s x
  scale, shortened to fit the frame interval); the largest dt whose period error and amplitude change meet the
  tolerance is reported.

Report the load (``uptime``) with the numbers: the machine may be shared.
"""
import argparse
import dataclasses
import json
import math
import os
import sys
import time

import numpy as np

TOLERANCES = {
    "catenary": "settling_residual < 1e-5 and sag_error < 2e-3",
    "cantilever": "tip error (20 el.) < 0.08 and < 0.6 x the 10-element error",
    "pendulum": "period_error < 3e-4 and |amplitude_change| < 1e-4",
    "twist": "critical_twist_error < 0.03",
}


def experiment(name):
    import importlib

    mod = importlib.import_module(f"cosseratbench.experiments.{name}")
    return getattr(mod, name)


def solver(name, scale=1.0):
    if name == "der":
        from der.bench import DerSolver

        return DerSolver(time_step_scale=scale)
    from cosseratbench.solvers.pyelastica import PyElasticaSolver

    return PyElasticaSolver(time_step_scale=scale)


def passes(name, m, coarse=None):
    """(pass?, the numbers checked) against the suite's tolerances."""
    if name == "catenary":
        return m["settling_residual"] < 1e-5 and m["sag_error"] < 2e-3
    if name == "cantilever":
        return m["tip_deflection_error"] < 0.08 and coarse is not None and \
            m["tip_deflection_error"] < 0.6 * coarse["tip_deflection_error"]
    if name == "pendulum":
        return m["period_error"] < 3e-4 and abs(m["amplitude_change"]) < 1e-4
    if name == "twist":
        return m["critical_twist_error"] < 0.03
    return None


def full_run(name, who, n_elements=None, scale=1.0):
    from cosseratbench.experiment import run

    exp = experiment(name)
    s = solver(who, scale)
    c0 = time.process_time()
    r = run(exp, s, n_elements=n_elements)
    cpu = time.process_time() - c0
    if r.failure or r.missing:
        return {"experiment": name, "solver": who, "failure": r.failure or f"missing {r.missing}", "cpu": cpu}
    settings = dict(r.settings or {})
    dt = settings.get("dt", settings.get("time_step"))
    return {"experiment": name, "solver": who, "n": n_elements or exp.n_elements, "metrics": dict(r.metrics),
            "wall": r.wall_time, "cpu": cpu, "dt": dt, "method": settings.get("method", settings.get("integrator")),
            "scale": scale}


def full_runs(names, who):
    out = []
    for name in names:
        if name == "cantilever":
            coarse = full_run(name, who, 10)
            fine = full_run(name, who, 20)
            fine["pass"] = passes(name, fine.get("metrics", {}), coarse.get("metrics"))
            fine["coarse"] = coarse.get("metrics")
            out += [coarse, fine]
        else:
            r = full_run(name, who)
            r["pass"] = passes(name, r["metrics"]) if "metrics" in r else False
            out.append(r)
        print(json.dumps(out[-1], default=float), flush=True)
    return out


class _Stop(Exception):
    pass


def _short_scenario(scenario, duration):
    return dataclasses.replace(scenario, duration=duration)


def _bounded(positions, start, length):
    return bool(np.all(np.isfinite(positions)) and np.abs(positions - start).max() < 0.1 * length)


def pyelastica_stable(name, steps, bisect):
    """Largest stable step of PyElastica's adapter on a short run; (limit estimate, bracket, its own estimate)."""
    from cosseratbench.solver import Diverged
    from cosseratbench.solvers.pyelastica import _stable_time_step

    exp = experiment(name)
    scenario = exp.scenario
    n = exp.n_elements
    estimate = min(_stable_time_step(r, n) for r in scenario.rods)
    length = max(r.length for r in scenario.rods)

    def stable(scale):
        dt = 0.5 * scale * estimate
        sc = _short_scenario(scenario, steps * dt)
        try:
            tr = solver("pyelastica", scale).run(sc, n_elements=n, n_frames=2)
        except (Diverged, FloatingPointError):
            return False
        return all(_bounded(p[-1], p[0], length) for p in tr.positions)

    return _bisect(stable, lambda s: 0.5 * s * estimate, bisect) + (estimate,)


def der_verlet_stable(name, steps, bisect):
    """Largest stable velocity-Verlet step of der on the adapter's scene (der's refusal above its Gershgorin bound
    lifted); (limit estimate, bracket, der's bound)."""
    import der
    import der.dynamics as dyn

    exp = experiment(name)
    scenario = exp.scenario
    n = exp.n_elements
    length = max(r.length for r in scenario.rods)
    original = der.simulate
    bound_of = dyn._VerletRun.stable_dt
    bounds = []

    def attempt(dt_try):
        def simulate(scene, t_end, **kw):
            kw.update(integrator="verlet", dt=dt_try, save_every=steps, progress=False)
            tr = original(scene, steps * dt_try, **kw)
            ok = tr.completed and _bounded(tr.positions[-1], tr.positions[0], length)
            if os.environ.get("BENCH_DEBUG"):
                print(dt_try, tr.status, tr.message, file=sys.stderr)
            raise _Stop(ok)

        def lifted(self):
            bounds.append(bound_of(self))
            return math.inf

        der.simulate, dyn._VerletRun.stable_dt = simulate, lifted
        try:
            solver("der").run(_short_scenario(scenario, 1.0), n_elements=n, n_frames=2)
        except _Stop as stop:
            return bool(stop.args[0])
        except (FloatingPointError, ValueError):
            return False
        finally:
            der.simulate, dyn._VerletRun.stable_dt = original, bound_of
        raise RuntimeError("the der adapter did not run der.simulate (a quasi-static experiment: der.solve)")

    attempt(1e-9)                               # der's Gershgorin bound, from the first call
    bound = min(bounds)
    return _bisect(lambda s: attempt(0.25 * s * bound), lambda s: 0.25 * s * bound, bisect) + (bound,)


def _bisect(stable, dt_of, halvings):
    """Bisection on a scale s (step dt_of(s)): from s = 1 (expected stable) double until unstable, then halve
    the bracket ``halvings`` times. Returns (largest stable dt, (stable dt, unstable dt))."""
    lo = 1.0
    while not stable(lo):
        lo *= 0.5
        if lo < 1e-3:
            return float("nan"), (float("nan"), float("nan"))
    hi = 2.0 * lo
    while stable(hi):
        lo, hi = hi, 2.0 * hi
        if hi > 1e4:
            return float("inf"), (dt_of(lo), float("inf"))
    for _ in range(halvings):
        mid = 0.5 * (lo + hi)
        if stable(mid):
            lo = mid
        else:
            hi = mid
    return dt_of(lo), (dt_of(lo), dt_of(hi))


def newmark_pendulum(scales):
    out = []
    for s in scales:
        r = full_run("pendulum", "der", scale=s)
        r["pass"] = passes("pendulum", r["metrics"]) if "metrics" in r else False
        out.append(r)
        print(json.dumps(r, default=float), flush=True)
    good = [r for r in out if r["pass"]]
    best = max(good, key=lambda r: r["dt"]) if good else None
    return out, best


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--full", nargs="*", default=["pendulum", "twist", "cantilever", "catenary"],
                    help="experiments der runs in full")
    ap.add_argument("--pyelastica-full", nargs="*", default=["pendulum", "twist", "cantilever", "catenary"],
                    help="experiments PyElastica runs in full ('none' for none)")
    ap.add_argument("--stability", nargs="*", default=["pendulum", "twist"],
                    help="experiments whose explicit stability limits are measured")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--bisect", type=int, default=6)
    ap.add_argument("--newmark-scales", nargs="*", type=float, default=[1.0, 1.25, 1.5, 2.0, 2.5])
    ap.add_argument("--json", help="write everything to this file")
    args = ap.parse_args(argv)
    print(f"# load: {os.getloadavg()}", flush=True)
    report = {"load_start": os.getloadavg()}
    report["der"] = full_runs(args.full, "der")
    pe = [e for e in args.pyelastica_full if e != "none"]
    report["pyelastica"] = full_runs(pe, "pyelastica")
    stab = {}
    for name in args.stability:
        c0 = time.process_time()
        pe_dt, pe_bracket, pe_est = pyelastica_stable(name, args.steps, args.bisect)
        c1 = time.process_time()
        de_dt, de_bracket, de_bound = der_verlet_stable(name, args.steps, args.bisect)
        stab[name] = {"pyelastica": {"limit": pe_dt, "bracket": pe_bracket, "adapter_estimate": pe_est,
                                     "adapter_dt": 0.5 * pe_est, "cpu": c1 - c0},
                      "der_verlet": {"limit": de_dt, "bracket": de_bracket, "gershgorin_bound": de_bound,
                                     "cpu": time.process_time() - c1}}
        print(f"# {name} stability: {json.dumps(stab[name], default=float)}", flush=True)
    report["stability"] = stab
    if args.newmark_scales:
        runs, best = newmark_pendulum(args.newmark_scales)
        report["newmark_pendulum"] = {"runs": runs, "largest_passing": best}
    report["load_end"] = os.getloadavg()
    print(f"# load: {report['load_end']}")
    _table(report)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(report, f, indent=1, default=float)


def _table(report):
    print("\n| experiment | solver | n | method | dt (s) | CPU (s) | wall (s) | metrics | tolerance | pass |")
    print("|---|---|---:|---|---:|---:|---:|---|---|---|")
    for who in ("der", "pyelastica"):
        for r in report[who]:
            if "metrics" not in r:
                print(f"| {r['experiment']} | {who} | | | | {r['cpu']:.1f} | | {r.get('failure')} | | fail |")
                continue
            m = ", ".join(f"{k} {v:.3g}" for k, v in r["metrics"].items())
            tol = TOLERANCES.get(r["experiment"], "") if "pass" in r else ""
            ok = {True: "pass", False: "FAIL", None: ""}[r.get("pass")]
            print(f"| {r['experiment']} | {who} | {r['n']} | {r['method']} | {r['dt']:.3g} | {r['cpu']:.1f} | "
                  f"{r['wall']:.1f} | {m} | {tol} | {ok} |")
    for name, s in report.get("stability", {}).items():
        p, d = s["pyelastica"], s["der_verlet"]
        print(f"\n{name}: explicit stability limit, PyElastica {p['limit']:.3g} s (bracket {p['bracket'][0]:.3g}-"
              f"{p['bracket'][1]:.3g}; its adapter runs at {p['adapter_dt']:.3g}), der velocity Verlet "
              f"{d['limit']:.3g} s (bracket {d['bracket'][0]:.3g}-{d['bracket'][1]:.3g}; Gershgorin bound "
              f"{d['gershgorin_bound']:.3g})")
    nm = report.get("newmark_pendulum")
    if nm:
        for r in nm["runs"]:
            m = r.get("metrics", {})
            nan = float("nan")
            print(f"pendulum, der newmark dt {r.get('dt', nan):.4g}: period {m.get('period_error', nan):.3e}"
                  f" amplitude {m.get('amplitude_change', nan):.2e} {'pass' if r.get('pass') else 'FAIL'}"
                  f" (CPU {r['cpu']:.1f} s)")
        if nm["largest_passing"]:
            print(f"largest passing implicit step: {nm['largest_passing']['dt']:.4g} s")


if __name__ == "__main__":
    sys.exit(main())
