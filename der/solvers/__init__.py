"""Solvers: damped dynamics to static equilibrium (implicit by default, explicit as the reference)."""
import dataclasses
import os
import sys
import time
import warnings

import numpy as np

from .options import (
    STATUSES, ConvergenceError, LockedRodWarning, RoundoffFloorWarning, SolveResult, SolverOptions, TightBendWarning,
)
from .system import build_system, numerical_failure, check_equilibrium_exists, locked_rod_note, prepare_state

SOLVERS = ("implicit", "explicit")


class Progress:
    """Progress lines on stderr for solves that run longer than ``after`` seconds (never on stdout)."""

    def __init__(self, label, enabled=None, after=2.0, every=1.0):
        self.label, self.enabled, self.after, self.every = label, enabled, after, every
        self.t0 = time.perf_counter()
        self.last = self.t0

    def update(self, iteration, residual, extra=""):
        if self.enabled is False:
            return
        now = time.perf_counter()
        if (self.enabled or now - self.t0 > self.after) and now - self.last >= self.every:
            self.last = now
            print(f"[der] {self.label}: iteration {iteration}, residual {residual:.3e} {extra} "
                  f"({now - self.t0:.1f} s)", file=sys.stderr, flush=True)


def solve(scene, state=None, solver="implicit", options=None, record=None, raise_on_failure=True, **overrides):
    """Relax a scene to static equilibrium by damped dynamics.

    Parameters
    ----------
    scene : der.Scene
    state : der.RodState, optional
        Starting configuration (default: the rod's rest state). It is not modified.
    solver : "implicit" (default: backward Euler + Newton with pseudo-transient continuation) or "explicit"
        (FIRE damped dynamics with a stable time step).
    options : SolverOptions, optional; ``**overrides`` replace single fields (e.g. ``tol=1e-10``).
    record : path of a rerun recording (.rrd) to write, or a ``der.recording.Recorder``; None for none.
    raise_on_failure : raise ConvergenceError (carrying the result and last state) if not converged.

    Returns
    -------
    SolveResult, with the stability of the equilibrium (``min_eigenvalue``, ``stable``) when converged;
    ``print(result)`` shows a short summary. ``wall_time`` is the solve alone: the first solve of a process
    first compiles der's kernels (or loads them from numba's cache), reported apart as ``compile_time``; on a
    cold cache it prints "compiling der's kernels (first run only, a few minutes)" to stderr before it does.

    Raises
    ------
    ValueError / TypeError before any work for bad arguments (a state of another rod, an unwritable
    ``record`` path, ...), for a load whose scale is not a finite double, and for a scene with no static
    equilibrium (a net dead force along a translation, or a net dead torque about a rotation, that its
    constraints leave free); ConvergenceError (with ``.result``) when not converged and ``raise_on_failure``.

    Warns
    -----
    ``RoundoffFloorWarning`` for status "converged_at_floor" (converged, but at the round-off floor above
    ``tol``) and ``LockedRodWarning`` for an inextensible rod locked between fixed ends (constraint tension far
    above A1/L^2 that its loads do not explain).

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.5)
    >>> scene = der.Scene(rod, loads=[der.end_torque(1.5e-3, follower=True)], constraints=[der.clamp("start")])
    >>> result = der.solve(scene, tol=1e-10)
    >>> result.converged, round(float(der.diagnostics.end_motion(rod, result.state)[1][0]), 9)   # T L / A2
    (True, 0.001)
    """
    from ..scene import Scene

    if not isinstance(scene, Scene):
        raise TypeError(f"der.solve: scene must be a der.Scene (der.Scene(rod, loads=[...], constraints=[...])); "
                        f"got {type(scene).__name__}")
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}; got {solver!r}")
    if options is None:
        options = SolverOptions(**overrides)
    elif overrides:
        options = dataclasses.replace(options, **overrides)
    if scene.scenes is not None:
        return _solve_several(scene, state, solver, options, record, raise_on_failure)
    rod = scene.rod
    if state is None:
        state = rod.rest_state()
    elif state.q.shape != (rod.n_dof,) or state.d1.shape != (rod.n_edges, 3):
        raise ValueError(f"state does not belong to this rod: q has shape {state.q.shape}, expected ({rod.n_dof},)")
    elif not (np.isfinite(state.q).all() and np.isfinite(state.d1).all() and np.isfinite(state.reference_twist).all()):
        bad = int(np.flatnonzero(~np.isfinite(state.q))[0]) if not np.isfinite(state.q).all() else -1
        raise ValueError(f"the starting state must be finite (entry {bad} of q is {state.q[bad] if bad >= 0 else '?'})")
    if record is not None and isinstance(record, (str, os.PathLike)):
        check_record_path(record, "der.solve: record")
    if scene.contacts and solver != "implicit" and not (
            len(scene.contacts) == 1 and getattr(scene.contacts[0], "explicit_ok", False)):
        raise ValueError("der.solve: the explicit solver handles one self-contact term (der.self_contact, or "
                         "der.rod_contact on one rod); obstacles and several contact terms need the implicit solver "
                         "(solver='implicit')")
    compile_time = _compile_first()
    if scene.contacts:
        from ..terms import warmup as _contact_warmup

        compile_time += _contact_warmup()
        if solver == "explicit":
            from .explicit_contact import warmup as _explicit_contact_warmup

            compile_time += _explicit_contact_warmup()
    system = build_system(scene, options)     # refuses loads whose scale is not a finite double
    work = prepare_state(system, state)
    if not system.terms:                      # (a contact can react to a net load)
        check_equilibrium_exists(system, work)    # refuses a net load on a rigid motion nothing can react to
    for term in system.terms:                 # contact: an inadmissible start is refused before any work
        term.check_start(work, options.tight_bend)
    for term in system.terms:
        term.start_stiffness(work, system)
    recorder = None
    if record is not None:
        from ..recording import Recorder

        recorder = record if isinstance(record, Recorder) else Recorder(record, rod, scene=scene)
        recorder.log_rest()
    progress = Progress(solver, options.progress)
    try:
        if solver == "implicit":
            from .implicit import solve_implicit

            result = solve_implicit(system, work, options, progress, recorder)
        else:
            from .explicit import solve_explicit

            start = work.copy()
            try:
                result = solve_explicit(system, work, options, progress, recorder)
            except (ArithmeticError, np.linalg.LinAlgError) as exc:
                result = numerical_failure(system, work, start, exc, "explicit")
        if result.status != "interrupted":
            note = locked_rod_note(system, result.state)
            if note:
                result.message += f"; {note}"
                warnings.warn(note, LockedRodWarning, stacklevel=2)
        if result.status == "converged_at_floor":
            warnings.warn(f"{solver} solve: {result.message}", RoundoffFloorWarning, stacklevel=2)
        if result.converged and options.stability:
            from .stability import stability

            stability(system, result, options.n_eigenvalues)
        _annotate(system, result, options, compile_time)
        if recorder is not None:
            recorder.log_final(result)
    finally:
        if recorder is not None and recorder is not record:
            recorder.close()
    if not result.converged and raise_on_failure:
        raise ConvergenceError(result)
    return result


def _annotate(system, result, options, compile_time):
    """What every solve's result carries beside the solver's verdict: compile time, tol, linear solves, contact."""
    result.compile_time = compile_time
    result.tol = options.tol
    result.linear_solves = dict(system.linear_solves)
    if system.terms:
        from ..diagnostics import contact_forces

        result.contact = contact_forces(system, result.state)


def _solve_several(scene, state, solver, options, record, raise_on_failure):
    """``solve`` for a scene of several rods (der/solvers/multi.py); ``state`` None or one RodState per rod."""
    from ..rod import check_state
    from .multi import MultiState, build_multi_system, prepare_multi_state

    rods = scene.rods
    if state is None:
        states = [r.rest_state() for r in rods]
    else:
        states = list(state.rods) if isinstance(state, MultiState) else state
        if not isinstance(states, (list, tuple)) or len(states) != len(rods):
            raise ValueError(f"der.solve: state must be None, a MultiState or a list of {len(rods)} RodStates (one "
                             f"per rod of the scene); got {type(state).__name__}")
        for i, (r, s) in enumerate(zip(rods, states)):
            check_state(r, s, f"der.solve: state of rod {i}")
            if not (np.isfinite(s.q).all() and np.isfinite(s.d1).all() and np.isfinite(s.reference_twist).all()):
                raise ValueError(f"der.solve: the starting state of rod {i} must be finite")
    if record is not None and isinstance(record, (str, os.PathLike)):
        check_record_path(record, "der.solve: record")
    if solver != "implicit":
        raise ValueError("der.solve: a scene of several rods needs the implicit solver (solver='implicit'); the "
                         "explicit solver takes one rod")
    compile_time = _compile_first()
    if scene.contacts:
        from ..terms import warmup as _contact_warmup

        compile_time += _contact_warmup()
    system = build_multi_system(scene, options)
    work = prepare_multi_state(system, MultiState(states))
    if not system.terms:
        for i, (p, s) in enumerate(system.views(work)):
            try:
                check_equilibrium_exists(p, s)
            except ValueError as exc:
                raise ValueError(f"rod {i}: {exc}") from None
    for term in system.terms:
        term.check_start(work, options.tight_bend)
    for term in system.terms:
        term.start_stiffness(work, system)
    recorder = None
    if record is not None:
        from ..recording import MultiRecorder, Recorder

        recorder = record if isinstance(record, Recorder) else MultiRecorder(record, rods, scene=scene)
        recorder.log_rest()
    progress = Progress(solver, options.progress)
    try:
        from .implicit import solve_implicit

        result = solve_implicit(system, work, options, progress, recorder)
        if result.status == "converged_at_floor":
            warnings.warn(f"{solver} solve: {result.message}", RoundoffFloorWarning, stacklevel=3)
        if result.converged and options.stability:
            _stability_several(system, result, options.n_eigenvalues)
        _annotate(system, result, options, compile_time)
        if recorder is not None:
            recorder.log_final(result)
    finally:
        if recorder is not None and recorder is not record:
            recorder.close()
    if not result.converged and raise_on_failure:
        raise ConvergenceError(result)
    return result


def _stability_several(system, result, n_eigenvalues):
    """Stability of a scene of several rods: without a coupling term each rod's own (``result.rods[i]``
    gets ``stable`` and ``min_eigenvalue``; the scene is stable if every rod is); with contact terms it is not
    computed (the barrier couples the rods) and says so."""
    from .stability import stability

    if system.terms:
        result.stability_note = "not computed for a scene of several rods with contact terms"
        return
    stable, lowest = True, np.inf
    for i, (p, s) in enumerate(system.views(result.state)):
        one = SolveResult(state=s, converged=True, status="", residual=float("nan"), iterations=0, wall_time=0.0,
                          message="")
        stability(p, one, n_eigenvalues)
        result.rods[i].update(stable=one.stable, min_eigenvalue=one.min_eigenvalue)
        stable = stable and bool(one.stable)
        lowest = min(lowest, one.min_eigenvalue)
    result.stable, result.min_eigenvalue = stable, lowest
    result.stability_note = "each rod's own stability (no coupling term)"


def _compile_first():
    """On the first solve of a process, compile (or load from numba's cache) every kernel before any clock
    starts, announcing a compilation on stderr; returns the seconds it took (0 afterwards)."""
    from ..warmup import is_done, warmup

    return 0.0 if is_done() else warmup()


def check_record_path(path, name):
    """Refuse, before any work, a recording path that cannot be written (ValueError naming ``name``)."""
    path = os.fspath(path)
    if not path:
        raise ValueError(f"{name} must be the path of a .rrd file to write; got an empty string")
    if os.path.isdir(path):
        raise ValueError(f"{name}: {path!r} is a directory; give the path of a .rrd file to write")
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(parent):
        raise ValueError(f"{name}: cannot write {path!r}: the folder {parent} does not exist (create it first)")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"{name}: cannot write {path!r}: the folder {parent} is not writable")
    if os.path.exists(path) and not os.access(path, os.W_OK):
        raise ValueError(f"{name}: cannot write {path!r}: the file exists and is not writable")


def check_stability(scene, state, n_eigenvalues=6):
    """Stability of ``state`` as an equilibrium of ``scene`` (it need not be one exactly).

    Parameters
    ----------
    scene : der.Scene
    state : der.RodState
        A state of the scene's rod, e.g. a solve's ``result.state``.
    n_eigenvalues : int
        How many of the lowest eigenvalues of the constrained stiffness to compute.

    Returns
    -------
    A SolveResult-like record with ``min_eigenvalue``, ``eigenvalues`` (squared natural frequencies, rigid-body
    and symmetry modes removed), ``stable`` (no eigenvalue with a negative real part), ``flutter`` and
    ``stability_note``.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.5)
    >>> scene = der.Scene(rod, constraints=[der.clamp("start")])
    >>> der.check_stability(scene, rod.rest_state()).stable
    True
    """
    from ..rod import check_state
    from .stability import stability

    if scene.scenes is not None:
        raise ValueError("der.check_stability: a scene of several rods; check each rod's scene with its state "
                         "(der.solve reports each rod's stability in result.rods when no contact couples them)")
    check_state(scene.rod, state, "der.check_stability")
    system = build_system(scene, SolverOptions())
    work = prepare_state(system, state)
    result = SolveResult(state=work, converged=True, status="", residual=float("nan"), iterations=0,
                         wall_time=0.0, message="stability of a given state")
    return stability(system, result, n_eigenvalues)


__all__ = ["solve", "check_stability", "SolverOptions", "SolveResult", "ConvergenceError", "STATUSES", "SOLVERS",
           "RoundoffFloorWarning", "LockedRodWarning", "TightBendWarning"]
