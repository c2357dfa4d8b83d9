"""The scenario contract: one command-line harness shared by every script in ``scenarios/``.

    python scenarios/<name>.py [scenario parameters] [--n N] [--solver implicit|explicit] [--tol TOL]
                               [--rrd PATH] [--json]

* ``--json``: the last line on stdout is one JSON object with at least ``scenario``, ``params`` (every input,
  defaults included), ``n``, ``solver``, ``converged``, ``status``, ``residual``, ``iterations``,
  ``runtime_s`` (solve wall time, JIT compilation excluded), ``compile_s``, ``error`` (headline relative
  error against the reference), ``reference`` (what that is), plus the scenario's own quantities.
* exit status 0 when converged, 2 for invalid input (one line on stderr, nothing else done), 3 when the
  solve did not converge (the JSON is still printed, with ``converged: false``).
* progress of long solves goes to stderr, never stdout.

A scenario script defines its parameters and a ``run(p, solver)`` function that builds scenes, calls
``solver.solve(scene, ...)`` (this module's wrapper around ``der.solve``: it applies --solver/--tol/--rrd and
adds up run times) and returns a dict with ``error``, ``reference`` and its quantities.
"""
import argparse
import json
import math
import os
import sys
import time

import numpy as np

from . import solvers as _solvers
from .warmup import warmup


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        print(f"{self.prog}: invalid input: {message}", file=sys.stderr)
        sys.exit(2)


class SolveRunner:
    """Calls der.solve with the command-line choices; accumulates wall time, iterations and results."""

    def __init__(self, args):
        self.args = args
        self.results = []
        self.recorder = None
        self.offset = 0

    def solve(self, scene, state=None, **options):
        from .recording import Recorder

        options.setdefault("tol", self.args.tol)
        if self.args.max_iterations is not None:
            options.setdefault("max_iterations", self.args.max_iterations)
            options.setdefault("max_steps", 1000 * self.args.max_iterations)
        record = None
        if self.args.rrd:
            if self.recorder is None:
                self.recorder = Recorder(self.args.rrd, scene.rod, scene=scene)
                self.recorder.log_rest()
            record = self.recorder
            self.recorder.offset = self.offset
        result = _solvers.solve(scene, state=state, solver=self.args.solver, record=record,
                                raise_on_failure=False, **options)
        self.offset += result.iterations + 1
        self.results.append(result)
        return result

    @property
    def runtime(self):
        return sum(r.wall_time for r in self.results)

    @property
    def iterations(self):
        return sum(r.iterations for r in self.results)

    def close(self):
        if self.recorder is not None:
            self.recorder.close()


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.bool_,)):
        return bool(value)
    if isinstance(value, complex):
        return [value.real, value.imag]
    return value


def scenario_main(name, description, parameters, run, n_default=100, n_min=2, argv=None, human=None, tol_default=1e-8):
    """Run a scenario script. ``parameters``: list of (name, default, type, help)."""
    parser = _Parser(prog=f"{name}.py", description=description)
    for pname, default, ptype, phelp in parameters:
        parser.add_argument(f"--{pname}", type=ptype, default=default, help=f"{phelp} (default: {default})")
    parser.add_argument("--n", type=int, default=n_default, help=f"number of edges (default: {n_default})")
    parser.add_argument("--solver", choices=_solvers.SOLVERS, default="implicit",
                        help="implicit (default) or explicit damped dynamics")
    parser.add_argument("--tol", type=float, default=tol_default,
                        help=f"residual tolerance, per node (default: {tol_default:g})")
    parser.add_argument("--max-iterations", type=int, default=None,
                        help="iteration limit of the implicit solver (explicit: x1000 steps); default: the solver's")
    parser.add_argument("--rrd", default=None, help="write a rerun recording (.rrd) to this path")
    parser.add_argument("--json", action="store_true", help="print one JSON object as the last line of stdout")
    args = parser.parse_args(argv)
    try:
        if args.n < n_min:
            raise ValueError(f"--n must be an integer >= {n_min} (number of edges); got {args.n}")
        if args.max_iterations is not None and args.max_iterations < 1:
            raise ValueError(f"--max-iterations must be >= 1; got {args.max_iterations}")
        if not (math.isfinite(args.tol) and args.tol > 0):
            raise ValueError(f"--tol must be a finite number > 0; got {args.tol}")
        for pname, _, ptype, _ in parameters:
            v = getattr(args, pname.replace("-", "_"))
            if ptype is float and v is not None and not math.isfinite(v):
                raise ValueError(f"--{pname} must be finite; got {v}")
        if args.rrd:
            parent = os.path.dirname(os.path.abspath(args.rrd))
            if not os.path.isdir(parent):
                raise ValueError(f"--rrd: directory {parent} does not exist")
        validate = getattr(run, "validate", None)
        if validate is not None:
            validate(args)
    except ValueError as exc:
        print(f"{name}.py: invalid input: {exc}", file=sys.stderr)
        return 2
    params = {p[0]: getattr(args, p[0].replace("-", "_")) for p in parameters}
    compile_s = warmup()
    runner = SolveRunner(args)
    t0 = time.perf_counter()
    try:
        out = run(args, runner)
    except ValueError as exc:
        print(f"{name}.py: invalid input: {exc}", file=sys.stderr)
        return 2
    finally:
        runner.close()
    wall = time.perf_counter() - t0
    main = runner.results[-1] if runner.results else None
    converged = bool(out.pop("converged", bool(runner.results) and all(r.converged for r in runner.results)))
    record = {
        "scenario": name,
        "params": params,
        "n": args.n,
        "solver": args.solver,
        "tol": args.tol,
        "converged": converged,
        "status": main.status if main else "no solve",
        "message": main.message if main else "",
        "residual": max((r.residual for r in runner.results), default=None),
        "iterations": runner.iterations,
        "runtime_s": runner.runtime,
        "wall_s": wall,
        "compile_s": compile_s,
        "min_eigenvalue": main.min_eigenvalue if main else None,
        "stable": main.stable if main else None,
        # every support's reaction (force, moment about the end cross-section), lab frame, of the last solve
        "reactions": [{k: v for k, v in r.items()} for r in main.reactions] if main else [],
    }
    record.update(out)
    if args.rrd:
        record["rrd"] = os.path.abspath(args.rrd)
    record = _jsonable(record)
    if args.json:
        print(json.dumps(record))
    else:
        (human or _human)(record)
    return 0 if converged else 3


def _human(r):
    status = "converged" if r["converged"] else f"NOT converged ({r['status']})"
    print(f"{r['scenario']}: {status}, residual {r['residual']:.2e}, {r['iterations']} iterations, "
          f"{r['runtime_s']:.3f} s (+{r['compile_s']:.2f} s compile)")
    if r.get("error") is not None:
        print(f"  error {r['error']:.3e} against {r.get('reference', '?')}")
    for k, v in r.items():
        if k in ("scenario", "params", "converged", "status", "residual", "iterations", "runtime_s", "compile_s",
                 "error", "reference", "wall_s", "profile", "sweep", "tol", "message"):
            continue
        if isinstance(v, (int, float, str, bool)) or v is None:
            print(f"  {k}: {v}")
    if r.get("stable") is False:
        print("  WARNING: the equilibrium is not stable (an eigenvalue of the stiffness is negative)")
