"""Property-based fuzzing of der's public API: random scenes, valid and invalid, and the one rule they obey.

Every outcome of building a scene and solving it must be one of

* ``invalid_input``: a ValueError or TypeError raised by der's own code (not numpy's or Python's generic
  conversion errors) with a message, before any solver work;
* ``converged``: status "converged", residual <= tol, finite state;
* ``converged_at_floor``: status "converged_at_floor" (residual above tol at the round-off floor, said so);
* ``not_converged``: a ConvergenceError carrying a finite residual and a finite last state;

and anything else -- another exception type, a generic conversion error, a run past the per-example time
limit, a non-finite state, a "converged" whose residual is above tol -- is the class ``other``, which must stay
empty. The same case generator drives the hypothesis test (``tests/test_fuzz.py``) and ``tools/fuzz.py``
through a small ``Draw`` interface (a numpy generator or hypothesis' ``data.draw``), so a failure found by one
can be replayed by the other from the printed case.
"""
import math
import os
import signal
import time
import traceback
import warnings
from contextlib import contextmanager

import numpy as np

import der

OUTCOMES = ("invalid_input", "converged", "converged_at_floor", "not_converged", "other")
DER_DIR = os.path.dirname(os.path.abspath(der.__file__))

# messages of Python's and numpy's own conversions: an error that says only this names no argument
GENERIC_MESSAGES = (
    "could not convert", "only 0-dimensional", "is not iterable", "argument must be a string or a",
    "object cannot be interpreted", "zero-size array", "setting an array element", "invalid literal",
    "unsupported operand", "must be real number", "can't convert complex", "ufunc", "not supported between",
    "object is not subscriptable", "index out of bounds", "operands could not be broadcast",
)

# values that a careless caller passes where a number or vector is expected
BAD_SCALARS = (0.0, -1.0, float("nan"), float("inf"), -float("inf"), 1e300, "1", None, 1 + 1j, [1.0, 2.0], True)
BAD_VECTORS = ([1.0, 2.0], [np.nan, 0.0, 0.0], [np.inf, 0.0, 0.0], "x", None, 3.0, np.zeros((3, 3)), [1j, 0, 0],
               [1e300, 1e300, 0.0])


class RngDraw:
    """The Draw interface on a numpy random generator (tools/fuzz.py)."""

    def __init__(self, rng):
        self.rng = rng

    def integer(self, lo, hi):
        return int(self.rng.integers(lo, hi + 1))

    def real(self, lo, hi):
        return float(self.rng.uniform(lo, hi))

    def choice(self, options):
        return options[int(self.rng.integers(len(options)))]

    def boolean(self, p=0.5):
        return bool(self.rng.random() < p)


class HypothesisDraw:
    """The Draw interface on hypothesis' ``data.draw`` (tests/test_fuzz.py): hypothesis can shrink the case."""

    def __init__(self, data):
        from hypothesis import strategies as st

        self.data, self.st = data, st

    def integer(self, lo, hi):
        return self.data.draw(self.st.integers(lo, hi))

    def real(self, lo, hi):
        return self.data.draw(self.st.floats(lo, hi, allow_nan=False, allow_infinity=False))

    def choice(self, options):
        return options[self.data.draw(self.st.integers(0, len(options) - 1))]

    def boolean(self, p=0.5):
        return self.data.draw(self.st.integers(0, 999)) < 1000 * p


def _log(draw, lo, hi):
    """10**u for u uniform in [lo, hi]."""
    return 10.0 ** draw.real(lo, hi)


def _maybe_bad(draw, good, bad_pool, p_bad):
    return draw.choice(bad_pool) if draw.boolean(p_bad) else good


def random_case(draw, p_bad=0.1, max_edges=24):
    """A random scene description (plain data: printable, replayable) for ``run_case``."""
    kind = draw.choice(("straight", "arc", "ring", "helix"))
    n = draw.integer(1 if draw.boolean(p_bad) else 3, max_edges)
    case = {"kind": kind, "n": n}
    if kind == "straight":
        case["length"] = _log(draw, -1, 1)
        case["axis"] = draw.choice(((0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.0)))
        case["director"] = draw.choice(((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)))
        if case["director"][0] == 1.0 and case["axis"][0] == 1.0 and case["axis"][1] == 0.0:
            case["director"] = (0.0, 0.0, 1.0)
    elif kind == "arc":
        case["radius"] = _log(draw, -1, 1)
        case["length"] = case["radius"] * draw.real(0.1, 6.0)
    elif kind == "ring":
        case["radius"] = _log(draw, -1, 1)
    else:
        case["kappa0"] = _log(draw, -1, 1)
        case["omega0"] = draw.real(-2.0, 2.0) * case["kappa0"]
        case["turns"] = draw.real(0.2, 3.0)
    case["A1"] = _maybe_bad(draw, _log(draw, -2, 2), BAD_SCALARS, p_bad)
    case["A2"] = _maybe_bad(draw, _log(draw, -2, 2), BAD_SCALARS, p_bad)
    case["EA"] = None if draw.boolean() else _maybe_bad(draw, _log(draw, 1, 6), BAD_SCALARS, p_bad)
    closed = kind == "ring"
    loads = []
    for _ in range(draw.integer(0, 3)):
        load = draw.choice(("point_force", "distributed_force", "twisting_moment") if closed else
                           ("point_force", "end_force", "distributed_force", "end_torque", "end_torque_follower",
                            "twisting_moment"))
        size = _log(draw, -6, 0)
        vec = tuple(size * draw.real(-1, 1) for _ in range(3))
        entry = {"load": load}
        if load in ("point_force", "end_force", "distributed_force", "end_torque"):
            entry["value"] = _maybe_bad(draw, vec, BAD_VECTORS, p_bad)
        else:
            entry["value"] = _maybe_bad(draw, size * draw.real(-1, 1), BAD_SCALARS, p_bad)
        if load == "point_force":
            entry["node"] = _maybe_bad(draw, draw.integer(-2, n), (2.5, n + 5, "0", None), p_bad)
        if load in ("end_force", "end_torque", "end_torque_follower"):
            entry["end"] = _maybe_bad(draw, draw.choice(("start", "end")), ("middle", 3, None), p_bad)
        loads.append(entry)
    case["loads"] = loads
    constraints = []
    for _ in range(draw.integer(0, 2)):
        c = draw.choice(("pin", "fix_theta") if closed else ("clamp", "clamp", "pin", "fix_theta"))
        entry = {"constraint": c}
        if c == "clamp":
            entry["end"] = draw.choice(("start", "end"))
        elif c == "pin":
            entry["node"] = _maybe_bad(draw, draw.integer(0, n), (2.5, -n - 7, None), p_bad)
        else:
            entry["edge"] = _maybe_bad(draw, draw.integer(0, max(n - 1, 0)), (1.5, n + 3), p_bad)
        constraints.append(entry)
    case["constraints"] = constraints
    case["perturb"] = draw.choice((0.0, 0.0, 1e-3, 0.05))
    case["seed"] = draw.integer(0, 2 ** 16)
    case["solver"] = _maybe_bad(draw, draw.choice(("implicit", "implicit", "explicit")), ("newton", None), p_bad)
    case["tol"] = _maybe_bad(draw, _log(draw, -12, -3), (0.0, -1e-8, float("nan")), p_bad)
    case["max_iterations"] = draw.integer(5, 300)
    case["max_steps"] = draw.integer(100, 50_000)
    return case


def build(case):
    """(scene, state, solve keyword arguments) from a case; der raises here for invalid arguments."""
    kind, n = case["kind"], case["n"]
    if kind == "straight":
        shape = der.shapes.straight(case["length"], n, axis=case["axis"], director=case["director"])
    elif kind == "arc":
        shape = der.shapes.arc(case["radius"], case["length"], n)
    elif kind == "ring":
        shape = der.shapes.ring(case["radius"], n)
    else:
        shape = der.shapes.helix(case["kappa0"], case["omega0"], case["turns"], n)
    rod = der.rod_from_shape(shape, case["A1"], case["A2"], EA=case["EA"])
    loads = []
    for entry in case["loads"]:
        load, value = entry["load"], entry["value"]
        if load == "point_force":
            loads.append(der.point_force(entry["node"], value))
        elif load == "end_force":
            loads.append(der.end_force(value, end=entry["end"]))
        elif load == "distributed_force":
            loads.append(der.distributed_force(value))
        elif load == "end_torque":
            loads.append(der.end_torque(value, end=entry["end"]))
        elif load == "end_torque_follower":
            loads.append(der.end_torque(value, end=entry["end"], follower=True))
        else:
            loads.append(der.twisting_moment(value))
    constraints = []
    for entry in case["constraints"]:
        c = entry["constraint"]
        if c == "clamp":
            constraints.append(der.clamp(entry["end"]))
        elif c == "pin":
            constraints.append(der.pin(entry["node"]))
        else:
            constraints.append(der.fix_theta(entry["edge"]))
    scene = der.Scene(rod, loads=loads, constraints=constraints)
    state = None
    if case["perturb"]:
        rng = np.random.default_rng(case["seed"])
        e = case["perturb"]
        state = rod.displaced(rod.rest_state(), e * rod.length * rng.standard_normal((rod.n_nodes, 3)),
                              e * rng.standard_normal(rod.n_edges))
    kwargs = dict(solver=case["solver"], tol=case["tol"], max_iterations=case["max_iterations"],
                  max_steps=case["max_steps"], progress=False)
    return scene, state, kwargs


class Hang(Exception):
    """The example ran past its time limit."""


@contextmanager
def time_limit(seconds):
    """Raise Hang in the main thread after ``seconds`` (a bound on a run that never returns)."""
    def handler(signum, frame):
        raise Hang(f"no outcome within {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, handler)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def _finite_state(state):
    return state is not None and all(np.isfinite(a).all() for a in (state.q, state.d1, state.reference_twist))


def _raised_by_der(exc):
    """True if the innermost frame of the traceback is der's own code (its own ``raise``)."""
    frames = traceback.extract_tb(exc.__traceback__)
    return bool(frames) and os.path.abspath(frames[-1].filename).startswith(DER_DIR)


def classify(case, budget=2.0, limit=10.0):
    """(outcome, detail, seconds): run one case and put it in one of OUTCOMES.

    ``budget`` is passed to the solver as its time budget; ``limit`` (wall-clock seconds) is the hang bound."""
    t0 = time.perf_counter()
    detail = ""
    try:
        with time_limit(limit), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene, state, kwargs = build(case)
            result = der.solve(scene, state=state, time_budget=budget, **kwargs)
    except (ValueError, TypeError) as exc:
        msg = str(exc)
        generic = any(g in msg for g in GENERIC_MESSAGES)
        if msg and not generic and _raised_by_der(exc) and not isinstance(exc, der.ConvergenceError):
            outcome, detail = "invalid_input", msg
        else:
            outcome, detail = "other", f"{type(exc).__name__}: {msg} (generic or not raised by der)"
    except der.ConvergenceError as exc:
        r = exc.result
        if math.isfinite(r.residual) and _finite_state(r.state) and r.status != "converged":
            outcome, detail = "not_converged", r.status
        else:
            outcome, detail = "other", f"ConvergenceError with residual {r.residual} / non-finite state"
    except Hang as exc:
        outcome, detail = "other", f"hang: {exc}"
    except Exception as exc:   # noqa: BLE001 -- every other exception is the defect this test looks for
        outcome, detail = "other", f"{type(exc).__name__}: {exc}"
    else:
        tol = case["tol"]
        if not _finite_state(result.state):
            outcome, detail = "other", "non-finite state in a returned result"
        elif result.status == "converged" and result.residual <= tol:
            outcome = "converged"
        elif result.status == "converged_at_floor" and result.converged:
            outcome = "converged_at_floor"
        else:
            outcome, detail = "other", (f"returned status {result.status!r}, converged={result.converged}, "
                                        f"residual {result.residual:.3e} vs tol {tol:.1e}")
    return outcome, detail, time.perf_counter() - t0
