"""Solvers: damped dynamics to static equilibrium (implicit by default, explicit as the reference)."""
import dataclasses
import sys
import time
import warnings

import numpy as np

from .options import (
    STATUSES, ConvergenceError, LockedRodWarning, RoundoffFloorWarning, SolveResult, SolverOptions,
)
from .system import build_system, check_equilibrium_exists, locked_rod_note, prepare_state

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
    SolveResult, with the stability of the equilibrium (``min_eigenvalue``, ``stable``) when converged.

    Raises ValueError before any work for a load whose scale is not a finite double, and for a scene with no
    static equilibrium (a net dead force along a translation, or a net dead torque about a rotation, that its
    constraints leave free). Warns ``RoundoffFloorWarning`` for status "converged_at_floor" (converged, but at
    the round-off floor above ``tol``) and ``LockedRodWarning`` for an inextensible rod locked between fixed
    ends (constraint tension far above A1/L^2 that its loads do not explain).
    """
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}; got {solver!r}")
    if options is None:
        options = SolverOptions(**overrides)
    elif overrides:
        options = dataclasses.replace(options, **overrides)
    rod = scene.rod
    if state is None:
        state = rod.rest_state()
    elif state.q.shape != (rod.n_dof,) or state.d1.shape != (rod.n_edges, 3):
        raise ValueError(f"state does not belong to this rod: q has shape {state.q.shape}, expected ({rod.n_dof},)")
    elif not (np.isfinite(state.q).all() and np.isfinite(state.d1).all() and np.isfinite(state.reference_twist).all()):
        bad = int(np.flatnonzero(~np.isfinite(state.q))[0]) if not np.isfinite(state.q).all() else -1
        raise ValueError(f"the starting state must be finite (entry {bad} of q is {state.q[bad] if bad >= 0 else '?'})")
    system = build_system(scene, options)     # refuses loads whose scale is not a finite double
    work = prepare_state(system, state)
    check_equilibrium_exists(system, work)    # refuses a net load on a rigid motion nothing can react to
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

            result = solve_explicit(system, work, options, progress, recorder)
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
        if recorder is not None:
            recorder.log_final(result)
    finally:
        if recorder is not None and recorder is not record:
            recorder.close()
    if not result.converged and raise_on_failure:
        raise ConvergenceError(result)
    return result


def check_stability(scene, state, n_eigenvalues=6):
    """Stability of ``state`` as an equilibrium of ``scene`` (it need not be one exactly): a SolveResult-like
    record with ``min_eigenvalue``, ``eigenvalues``, ``stable``, ``flutter`` and ``stability_note``."""
    from .stability import stability

    system = build_system(scene, SolverOptions())
    work = prepare_state(system, state)
    result = SolveResult(state=work, converged=True, status="", residual=float("nan"), iterations=0,
                         wall_time=0.0, message="stability of a given state")
    return stability(system, result, n_eigenvalues)


__all__ = ["solve", "check_stability", "SolverOptions", "SolveResult", "ConvergenceError", "STATUSES", "SOLVERS",
           "RoundoffFloorWarning", "LockedRodWarning"]
