"""The scenario contract: one command-line harness shared by every script in ``scenarios/``.

    python scenarios/<name>.py [scenario parameters] [--n N] [--solver implicit|explicit] [--tol TOL]
                               [--max-iterations K] [--time-budget S] [--rrd PATH] [--json]

* ``--json``: the last line on stdout is one JSON object with at least ``scenario``, ``params`` (every input,
  defaults included, as the values used), ``n``, ``solver``, ``converged``, ``status``, ``residual``,
  ``iterations``, ``runtime_s`` (solve wall time, JIT compilation excluded), ``compile_s``, ``error`` (headline
  relative error against the reference), ``reference`` (what that is), plus the scenario's own quantities.
* exit status (``EXIT_*`` below):

  - 0: every solve converged (status "converged", or "converged_at_floor": the residual stopped at the round-off
    floor above tol; the JSON records which) and the scenario's own check holds;
  - 2: invalid input, refused before any work, with ONE line on stderr naming the argument, what it got and what
    is allowed. Every parameter is checked here, in one place, against the range its scenario declares
    (``Range``: what is physically meaningful, e.g. loads up to a multiple of the critical one), ``--n`` against
    ``MAX_EDGES``, and the ``--rrd`` path is opened for writing before the solve;
  - 3: the run did not succeed, with the reason on ONE line on stderr: a solve did not converge (the JSON is
    still printed, with ``converged: false``), the result contradicts the scenario's own check (e.g. a ring that
    passed through itself), or a numerical or memory failure (overflow, an eigen-solver that failed, out of
    memory).
* progress of long solves goes to stderr, never stdout.

A scenario script defines its parameters and a ``run(p, solver)`` function that builds scenes, calls
``solver.solve(scene, ...)`` (this module's wrapper around ``der.solve``: it applies --solver/--tol/--rrd/
--time-budget and adds up run times) and returns a dict with ``error``, ``reference`` and its quantities; a
``"check_failed": reason`` entry makes the run exit 3 with that reason. ``run.validate(p)`` checks what the
ranges cannot (combinations); ``run.resolve(p)`` fills defaults that depend on other parameters, so that
``params`` records the values used.

A parameter is ``(name, default, type, help)`` or ``(name, default, type, help, Range(...))``; type ``bool``
makes a real flag (``--name`` / ``--no-name``); the old ``--name 0|1`` form still works, with a deprecation note.
"""
import argparse
import json
import math
import os
import sys
import time
import warnings
from dataclasses import dataclass

import numpy as np

from . import solvers as _solvers
from .solvers.system import raise_if_interrupted
from .warmup import warmup

EXIT_OK, EXIT_INVALID, EXIT_FAILED = 0, 2, 3

# The largest rod the scenarios accept: a solve needs about 4 kB per edge (NumPy peak 372 MB at n = 100,000,
# README "At scale": banded factorisation, work arrays) and the stability analysis more, so 10^6 edges already
# take gigabytes; beyond it a run would only fail for memory after a long setup (--n 100000000 was numpy's
# _ArrayMemoryError traceback). A MemoryError during a run is still caught (exit 3).
MAX_EDGES = 1_000_000


@dataclass(frozen=True)
class Range:
    """The physically meaningful values of a scenario parameter. ``lo``/``hi`` are numbers or functions of the
    parsed arguments (e.g. ``hi=lambda p: 2 * p.A1 / p.a0 ** 2``: a multiple of a critical load); ``open_lo`` /
    ``open_hi`` exclude the bound; ``nonzero`` refuses 0; ``why`` is said in the message."""
    lo: object = -math.inf
    hi: object = math.inf
    open_lo: bool = False
    open_hi: bool = False
    nonzero: bool = False
    why: str = ""

    def check(self, name, value, p):
        if value is None:
            return
        lo = self.lo(p) if callable(self.lo) else self.lo
        hi = self.hi(p) if callable(self.hi) else self.hi
        bad = (value < lo or value > hi or (self.open_lo and value == lo) or (self.open_hi and value == hi)
               or (self.nonzero and value == 0))
        if bad:
            left = "(" if self.open_lo else "["
            right = ")" if self.open_hi else "]"
            allowed = f"in {left}{lo:.6g}, {hi:.6g}{right}" + (", non-zero" if self.nonzero else "")
            raise ValueError(f"--{name} must be {allowed}{'; ' + self.why if self.why else ''}; got {value:g}")


# Stiffnesses and lengths: der is scale-free, and these bounds keep energies and forces far from overflow
POSITIVE = Range(1e-6, 1e6, why="choose units in which it is of order 1")


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        print(f"{self.prog}: invalid input: {message}", file=sys.stderr)
        sys.exit(EXIT_INVALID)


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
        if getattr(self.args, "max_iterations", None) is not None:
            options.setdefault("max_iterations", self.args.max_iterations)
            options.setdefault("max_steps", 1000 * self.args.max_iterations)
        budget = getattr(self.args, "time_budget", None)
        if budget is not None:
            options.setdefault("time_budget", budget)
        for flag in ("second_order_correction", "edge_newton"):      # implicit solver options (issue 17)
            if getattr(self.args, flag, False):
                options.setdefault(flag, True)
        record = None
        if getattr(self.args, "rrd", None):
            if self.recorder is None:
                self.recorder = Recorder(self.args.rrd, scene.rod, scene=scene)
                self.recorder.log_rest()
            record = self.recorder
            self.recorder.offset = self.offset
            if scene.rod.n_edges == self.recorder.rod.n_edges:
                # a continuation changes the rod (e.g. its welded twist) but not its discretisation: Lk and the
                # twist colours are those of the rod being solved
                self.recorder.rod = scene.rod
        result = _solvers.solve(scene, state=state, solver=self.args.solver, record=record,
                                raise_on_failure=False, **options)
        self.offset += result.iterations + 1
        self.results.append(result)
        return raise_if_interrupted(result)      # Ctrl-C ends the scenario, not just this solve

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


def check_parameters(parameters, p):
    """Every declared parameter of a scenario against its type and ``Range`` (ValueError naming it)."""
    for spec in parameters:
        pname, ptype = spec[0], spec[2]
        v = getattr(p, pname.replace("-", "_"))
        if ptype is float and v is not None and not math.isfinite(v):
            raise ValueError(f"--{pname} must be finite; got {v}")
    for spec in parameters:
        if len(spec) > 4 and spec[4] is not None:
            spec[4].check(spec[0], getattr(p, spec[0].replace("-", "_")), p)


def check_contact_resolution(p):
    """ValueError unless a contact scenario's rod resolves its radius: ``p.radius`` well below ``p.L`` (r < L/20),
    edges no longer than 2r (``p.L / p.n``), and ``p.perturb`` in [0, 0.1) (plectoneme, greenhill)."""
    if p.radius >= 0.05 * p.L:
        raise ValueError(f"--radius must be well below L (r < L/20); got r = {p.radius}, L = {p.L}")
    if p.L / p.n > 2 * p.radius:
        raise ValueError(f"--n {p.n} is too coarse for the contact: edge length {p.L / p.n:.3g} > 2r = "
                         f"{2 * p.radius:.3g} (use --n >= {int(np.ceil(p.L / (2 * p.radius)))})")
    if not 0 <= p.perturb < 0.1:
        raise ValueError(f"--perturb must lie in [0, 0.1); got {p.perturb}")


def validator(parameters, extra=None):
    """A scenario's ``run.validate``: the declared ranges, then ``extra(p)`` for what they cannot say."""
    def validate(p):
        check_parameters(parameters, p)
        if extra is not None:
            extra(p)
    return validate


def check_writable(path, what="--rrd"):
    """Refuse (ValueError) an output path that cannot be written, before any work: a directory, a missing
    folder, or a place where a file cannot be created (tried for real: permission bits say nothing to root)."""
    path = os.path.abspath(path)
    if os.path.isdir(path):
        raise ValueError(f"{what}: {path} is a directory; give a file path (e.g. {os.path.join(path, 'run.rrd')})")
    parent = os.path.dirname(path)
    if not os.path.isdir(parent):
        raise ValueError(f"{what}: directory {parent} does not exist")
    existed = os.path.exists(path)
    try:
        with open(path, "ab"):
            pass
    except OSError as exc:
        raise ValueError(f"{what}: cannot write {path} ({exc.strerror or exc})") from None
    if not existed:
        os.remove(path)


def deprecated_argv(argv, parameters, aliases, notes):
    """Rewrite the deprecated forms (``--flag 0|1`` for a flag, an alias such as ``--A``) into the current ones;
    a note for each is appended to ``notes`` (printed once the input is known valid: exit 2 prints one line)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    flags = {f"--{p[0]}" for p in parameters if p[2] is bool}
    out, i = [], 0
    while i < len(argv):
        a = argv[i]
        key, eq, val = a.partition("=")
        if key in aliases:
            notes.append(f"note: {key} is deprecated, use {aliases[key]}")
            key = aliases[key]
            a = key + eq + val
        if key in flags and (eq or (i + 1 < len(argv) and not argv[i + 1].startswith("--"))):
            if not eq:
                val = argv[i + 1]
                i += 1
            if val not in ("0", "1"):
                raise ValueError(f"{key} is a flag ({key} turns it on, --no-{key[2:]} off); got {key} {val}")
            notes.append(f"note: '{key} {val}' is deprecated, use {key if val == '1' else '--no-' + key[2:]}")
            out.append(key if val == "1" else "--no-" + key[2:])
            i += 1
            continue
        out.append(a)
        i += 1
    return out


def _one_line(text):
    return " ".join(str(text).split())


def scenario_main(name, description, parameters, run, n_default=100, n_min=2, argv=None, human=None, tol_default=1e-8,
                  aliases=None):
    """Run a scenario script. ``parameters``: list of (name, default, type, help[, Range]); ``aliases``:
    deprecated option -> current option (e.g. {"--A": "--A1"})."""
    parser = _Parser(prog=f"{name}.py", description=description)
    for spec in parameters:
        pname, default, ptype, phelp = spec[:4]
        if ptype is bool:
            parser.add_argument(f"--{pname}", action=argparse.BooleanOptionalAction, default=bool(default),
                                help=f"{phelp} (default: {'on' if default else 'off'})")
            continue
        shown = "" if default is None else f" (default: {default:g})" if isinstance(default, float) else \
            f" (default: {default})"
        parser.add_argument(f"--{pname}", type=ptype, default=default, help=phelp + shown)
    parser.add_argument("--n", type=int, default=n_default,
                        help=f"number of edges, {n_min} to {MAX_EDGES:,} (default: {n_default})")
    parser.add_argument("--solver", choices=_solvers.SOLVERS, default="implicit",
                        help="implicit (default) or explicit damped dynamics (slow on long or stiff rods)")
    parser.add_argument("--tol", type=float, default=tol_default,
                        help=f"residual tolerance, per node (default: {tol_default:g})")
    parser.add_argument("--max-iterations", type=int, default=None,
                        help="iteration limit of the implicit solver (explicit: x1000 steps); default: the solver's")
    parser.add_argument("--time-budget", type=float, default=None,
                        help="wall-clock seconds per solve (SolverOptions.time_budget); a solve that uses it up "
                             "ends with status time_budget (exit 3)")
    parser.add_argument("--second-order-correction", action="store_true",
                        help="implicit solver: correct a refused Newton step for its chord error and search along "
                             "an arc (SolverOptions.second_order_correction)")
    parser.add_argument("--edge-newton", action="store_true",
                        help="implicit solver: Newton steps of an open rod held at its start in edge coordinates "
                             "(SolverOptions.edge_newton)")
    parser.add_argument("--rrd", default=None, help="write a rerun recording (.rrd) to this file")
    parser.add_argument("--json", action="store_true", help="print one JSON object as the last line of stdout")
    notes = []
    try:
        argv = deprecated_argv(argv, parameters, aliases or {}, notes)
    except ValueError as exc:
        print(f"{name}.py: invalid input: {_one_line(exc)}", file=sys.stderr)
        return EXIT_INVALID
    args = parser.parse_args(argv)
    try:
        if not n_min <= args.n <= MAX_EDGES:
            raise ValueError(f"--n must be an integer from {n_min} to {MAX_EDGES:,} (number of edges); got {args.n}")
        if args.max_iterations is not None and args.max_iterations < 1:
            raise ValueError(f"--max-iterations must be >= 1; got {args.max_iterations}")
        if not (math.isfinite(args.tol) and args.tol > 0):
            raise ValueError(f"--tol must be a finite number > 0; got {args.tol}")
        if args.time_budget is not None and not (args.time_budget > 0):
            raise ValueError(f"--time-budget must be > 0 seconds; got {args.time_budget}")
        check_parameters(parameters, args)
        validate = getattr(run, "validate", None)
        if validate is not None:
            validate(args)
        if args.rrd:
            check_writable(args.rrd)
    except ValueError as exc:
        print(f"{name}.py: invalid input: {_one_line(exc)}", file=sys.stderr)
        return EXIT_INVALID
    for note in notes:
        print(f"{name}.py: {note}", file=sys.stderr)
    resolve = getattr(run, "resolve", None)
    if resolve is not None:
        resolve(args)
    params = {p[0]: getattr(args, p[0].replace("-", "_")) for p in parameters}
    interrupted, t_compile = False, time.perf_counter()
    try:
        compile_s = warmup()
    except KeyboardInterrupt:          # Ctrl-C while the kernels compile: no solve has run
        compile_s, interrupted = time.perf_counter() - t_compile, True
    runner = SolveRunner(args)
    t0 = time.perf_counter()
    failure = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        try:
            out = {} if interrupted else run(args, runner)
        except KeyboardInterrupt:
            # a solve that was interrupted kept its state and closed its recording (SolveRunner passes the
            # Ctrl-C on, so that no further solve starts); a Ctrl-C between solves lands here directly
            out, interrupted = {}, True
        except ValueError as exc:
            print(f"{name}.py: invalid input: {_one_line(exc)}", file=sys.stderr)
            return EXIT_INVALID
        except MemoryError as exc:
            failure = f"out of memory at n = {args.n} ({type(exc).__name__}{': ' + str(exc) if str(exc) else ''})"
        except (ArithmeticError, RuntimeError, np.linalg.LinAlgError) as exc:
            # overflow, an eigen-solver (ARPACK) or factorisation that failed, a bisection that lost its branch
            failure = f"numerical failure: {type(exc).__name__}: {exc}"
        finally:
            runner.close()
    numeric = [w for w in caught if issubclass(w.category, RuntimeWarning)]
    for w in caught:
        if w not in numeric:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    if failure is not None:
        print(f"{name}.py: failed: {_one_line(failure)}", file=sys.stderr)
        return EXIT_FAILED
    wall = time.perf_counter() - t0
    main = runner.results[-1] if runner.results else None
    converged = bool(out.pop("converged", bool(runner.results) and all(r.converged for r in runner.results)))
    converged = converged and not interrupted
    check_failed = out.pop("check_failed", None)
    if numeric:
        kinds = sorted({_one_line(w.message) for w in numeric})
        note = f"{len(numeric)} numerical warning(s): {'; '.join(kinds)[:300]}"
        err = out.get("error")
        if err is not None and not np.isfinite(err):
            check_failed = check_failed or f"the headline error is not finite ({note})"
        else:
            out.setdefault("numerical_warnings", note)
    statuses = sorted({r.status for r in runner.results})
    record = {
        "scenario": name,
        "params": params,
        "n": args.n,
        "solver": args.solver,
        "tol": args.tol,
        "converged": converged,
        "status": "interrupted" if interrupted else (main.status if main else "no solve"),
        "statuses": statuses,
        "message": main.message if main else "",
        "residual": max((r.residual for r in runner.results), default=None),
        "iterations": runner.iterations,
        "runtime_s": runner.runtime,
        "wall_s": wall,
        "compile_s": compile_s,
        "min_eigenvalue": main.min_eigenvalue if main else None,
        "stable": main.stable if main else None,
        "check_passed": check_failed is None,
        # every support's reaction (force, moment about the end cross-section), lab frame, of the last solve
        "reactions": [{k: v for k, v in r.items()} for r in main.reactions] if main else [],
    }
    if check_failed is not None:
        record["check_failed"] = check_failed
    record.update(out)
    if args.rrd:
        # (None: interrupted before the first solve opened it)
        record["rrd"] = os.path.abspath(args.rrd) if runner.recorder is not None else None
    record = _jsonable(record)
    if args.json:
        print(json.dumps(record))
    else:
        (human or _human)(record)
    if not converged:
        bad = next((r for r in runner.results if not r.converged), main)
        reason = f"not converged: {bad.status}: {bad.message}" if bad else "not converged: no solve ran"
        if interrupted and (bad is None or bad.status != "interrupted"):
            reason = ("interrupted by the user " + ("before the first solve (while der's kernels compiled); no "
                                                    "recording written" if main is None else
                                                    f"between solves; {len(runner.results)} solve(s) ran"))
        if args.solver == "explicit" and bad is not None and bad.status in ("max_iterations", "time_budget"):
            reason += "; the explicit solver is slow on long or stiff rods: try --solver implicit"
        print(f"{name}.py: {_one_line(reason)}", file=sys.stderr)
        return EXIT_FAILED
    if check_failed is not None:
        print(f"{name}.py: check failed: {_one_line(check_failed)}", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def _human(r):
    if r["converged"]:
        status = "converged" + (" (at the round-off floor)" if "converged_at_floor" in r.get("statuses", []) else "")
    else:
        status = f"NOT converged ({r['status']})"
    res = f"{r['residual']:.2e}" if r["residual"] is not None else "-"
    print(f"{r['scenario']}: {status}, residual {res}, {r['iterations']} iterations, "
          f"{r['runtime_s']:.3f} s (+{r['compile_s']:.2f} s compile)")
    if r.get("error") is not None:
        print(f"  error {r['error']:.3e} against {r.get('reference', '?')}")
    if r.get("check_failed"):
        print(f"  CHECK FAILED: {r['check_failed']}")
    for k, v in r.items():
        if k in ("scenario", "params", "converged", "status", "statuses", "residual", "iterations", "runtime_s",
                 "compile_s", "error", "reference", "wall_s", "profile", "sweep", "tol", "message", "check_passed",
                 "check_failed"):
            continue
        if isinstance(v, (int, float, str, bool)) or v is None:
            print(f"  {k}: {v}")
    if r.get("stable") is False:
        print("  WARNING: the equilibrium is not stable (an eigenvalue of the stiffness is negative)")
