"""Solver options (every tolerance and limit in one place) and the result of a solve."""
import math
from dataclasses import dataclass, field, fields

import numpy as np


@dataclass(frozen=True)
class SolverOptions:
    """All tolerances and limits of the solvers.

    Convergence is declared when the residual -- the largest out-of-balance generalized force on a free DOF
    (node forces relative to the force scale, moments on theta relative to the moment scale) -- is below
    ``tol`` and, for an inextensible rod, the largest axial strain is below ``strain_tol``. The scales are the
    largest applied, reaction or internal force (moment) in the rod (``der.solvers.system``); the force scale
    is reported with every result as ``load_scale``.

    Attributes
    ----------
    tol : residual tolerance (dimensionless), default 1e-8.
    strain_tol : inextensibility tolerance on |strain| (None: equal to ``tol``).
    max_iterations : implicit solver: pseudo-time steps (each one Newton step with a line search).
    max_steps : explicit solver: time steps.
    time_budget : wall-clock seconds after which a solve stops with status "time_budget".
    dt0, dt_max, dt_growth : implicit pseudo-time step (dimensionless: the damping matrix is the diagonal of
        the stiffness), its cap, and the largest growth per step. dt -> infinity is Newton's method; the cap
        is high because D / dt must fall below the softest stiffness, about n^-4 of the diagonal of a long rod.
    newton_first : start with Newton's method (dt at its cap) and fall back to dt0 when its step does not lower
        the energy; False starts every solve at dt0.
    edge_newton : implicit solver, an open rod held at its start (a clamp, hinge or roller at the start, or a pin
        on node 0; no contact, no follower loads): Newton steps in edge coordinates x_i = x_0 + sum_{j<i} e_j
        (der.solvers.edge_coordinates), whose stiffness has condition number ~ n^2 instead of ~ n^4 -- a cantilever
        of 10^5 edges converges there where the node-coordinate steps are round-off. Other scenes take
        node-coordinate steps as usual (``result.linear_solves["edge"]`` counts the edge steps). Each step q = T z
        is applied as a compensated pair (the edges' prefix sums with TwoSum), so that the edges of the step keep
        their own rounding. With ``second_order_correction`` the correction is solved with the edge factors.
        Default None (automatic): on, with ``second_order_correction``, for an inextensible rod of that kind whose
        node-coordinate Newton matrix is beyond double precision, c (L/h)^4 > 1e14 (``inextensible_penalty`` c,
        the longest-to-shortest edge ratio L/h; der.solvers.implicit.EDGE_NEWTON_CONDITION): ring torsion from
        n ~ 1,800 edges at c = 10 (docs/scaling.md, "Stop 27"); off otherwise. False or True forces it.
    line_search_steps, armijo : backtracking halvings per pseudo-time step and the sufficient-decrease factor.
    second_order_correction : implicit solver, rods with a stretching term, no contact: when the line search
        refuses a full step, correct it for the elongation that the straight-line step adds to the edges it
        turns beyond its linearisation (the chord error |d_perp|^2 / 2h, priced by the axial stiffness: the
        Maratos effect that stalls Newton's method on a fine inextensible ring), solved with the same
        factorisation, and search along the arc q + a delta + a^2 c. Default None: on where ``edge_newton`` is
        turned on automatically (above), off otherwise (docs/scaling.md); False or True forces it. Scenes with
        self-contact (segment barrier) always correct a refused step this way, with the contact solve's factors and
        each arc proven free of passage (der/solvers/implicit.py CONTACT_SECOND_ORDER; docs/contact.md 9.5).
    dt : explicit time step (physical time for the rod's line density rho_A); None picks ``safety / omega_max``,
        half the stability limit 2 / omega_max. A dt above the stability limit is refused with a ValueError.
    safety : fraction of the stable explicit step used.
    fire_* : FIRE parameters of the explicit solver (Bitzek et al. 2006).
    fire_mass : the explicit solver's fictitious masses (they change the path, not the equilibrium): "stiffness"
        (default, dynamic relaxation's mass scaling) gives each DOF a mass equal to its row sum of the stiffness
        |K| (Gershgorin's, contact barrier included; recomputed as the rod deforms, the velocity rescaled by one
        factor that keeps the kinetic energy), so that every DOF has about the same stable step and a stiff mode (the stretch
        of a rod with large EA) no longer sets the step of the soft ones; "inertia" is the rod's lumped mass and
        rotational inertia (the old behaviour; always used with an explicit ``dt``, which is physical time, and
        for inextensible rods, whose stretch is projected out).
    check_every : explicit steps between residual checks, progress and recording.
    inextensible_penalty : penalty c of the augmented Lagrangian, k_j = c A1 / l_j^3 (inextensible rods).
    displacement_tol : explicit solver only: when its residual stalls at the round-off floor, the state counts as
        converged if one Newton correction (not applied) would move it by less than this fraction of its
        displacement -- the forces of its slowest modes are buried in round-off there, so the residual alone
        cannot certify them.
    stability : compute the lowest eigenvalues of the constrained stiffness at the equilibrium.
    n_eigenvalues : how many of the lowest eigenvalues to report.
    progress : print progress to stderr (None: only for solves longer than 2 s).
    record_every : log every k-th iteration (implicit) or check (explicit) to a recording.
    tight_bend : what a contact solve does with a start bent tighter than a contact radius (a radius of curvature
        below r at some vertex): "refuse" (default: a user's start, ValueError before any work) or "warn" (a
        ``TightBendWarning``; the start is the model's own equilibrium, as in a continuation's steps, which
        ``der.continuation`` uses). The contact diagnostics report the tightest bend either way
        (``result.contact["min_curvature_radius"]``).

    Example
    -------
    >>> import der
    >>> options = der.SolverOptions(tol=1e-10, max_iterations=100)
    >>> options
    SolverOptions(tol=1e-10, max_iterations=100)
    >>> # result = der.solve(scene, options=options)   # or der.solve(scene, tol=1e-10, max_iterations=100)
    """

    tol: float = 1e-8
    strain_tol: float | None = None
    max_iterations: int = 500
    max_steps: int = 5_000_000
    time_budget: float = math.inf
    dt0: float = 1.0
    newton_first: bool = True
    edge_newton: bool | None = None
    dt_max: float = 1e30
    dt_growth: float = 10.0
    line_search_steps: int = 10
    armijo: float = 1e-4
    second_order_correction: bool | None = None
    dt: float | None = None
    safety: float = 0.9
    fire_n_min: int = 5
    fire_f_inc: float = 1.1
    fire_f_dec: float = 0.5
    fire_alpha: float = 0.1
    fire_f_alpha: float = 0.99
    fire_mass: str = "stiffness"
    check_every: int = 200
    inextensible_penalty: float = 10.0
    displacement_tol: float = 1e-6
    stability: bool = True
    n_eigenvalues: int = 6
    progress: bool | None = None
    record_every: int = 1
    tight_bend: str = "refuse"

    def __post_init__(self):
        positive = ("tol", "max_iterations", "max_steps", "time_budget", "dt0", "dt_max", "dt_growth", "safety",
                    "check_every", "inextensible_penalty", "n_eigenvalues", "record_every", "fire_f_inc",
                    "displacement_tol")
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in positive and not (isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0
                                           and not math.isnan(v)):
                raise ValueError(f"SolverOptions.{f.name} must be a number > 0; got {v!r}")
        if self.strain_tol is not None and not self.strain_tol > 0:
            raise ValueError(f"SolverOptions.strain_tol must be None or > 0; got {self.strain_tol!r}")
        if self.dt is not None and not (isinstance(self.dt, (int, float)) and math.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"SolverOptions.dt must be None or a finite number > 0; got {self.dt!r}")
        if not 0 < self.safety <= 1:
            raise ValueError(f"SolverOptions.safety must be in (0, 1]; got {self.safety!r}")
        if self.tight_bend not in TIGHT_BEND:
            raise ValueError(f"SolverOptions.tight_bend must be one of {TIGHT_BEND}; got {self.tight_bend!r}")
        if self.fire_mass not in FIRE_MASSES:
            raise ValueError(f"SolverOptions.fire_mass must be one of {FIRE_MASSES}; got {self.fire_mass!r}")
        if not 0 < self.armijo < 0.5:
            raise ValueError(f"SolverOptions.armijo must be in (0, 0.5); got {self.armijo!r}")

    def __repr__(self):
        """Only the fields that differ from the defaults (a valid constructor call)."""
        changed = [f"{f.name}={getattr(self, f.name)!r}" for f in fields(self) if getattr(self, f.name) != f.default]
        return f"SolverOptions({', '.join(changed)})"

    @property
    def effective_strain_tol(self):
        return self.tol if self.strain_tol is None else self.strain_tol


FIRE_MASSES = ("stiffness", "inertia")

STATUSES = {
    "converged": "residual below tol",
    "converged_at_floor": "residual stopped at the round-off floor of double precision, above tol (converged is "
                          "True; the message gives residual / tol and a RoundoffFloorWarning is emitted)",
    "max_iterations": "iteration or step limit reached before tol",
    "time_budget": "wall-clock budget used up before tol",
    "stalled": "no step could reduce the residual (at the round-off floor, or a singular/indefinite system)",
    "nonfinite": "a NaN or inf appeared; the last finite state is kept",
    "interrupted": "stopped by KeyboardInterrupt; the last state is kept",
}


CONVERGED_STATUSES = ("converged", "converged_at_floor")


TIGHT_BEND = ("refuse", "warn")


class TightBendWarning(UserWarning):
    """A contact solve started from a state bent tighter than the contact radius (radius of curvature below r at
    some vertex; ``SolverOptions(tight_bend="warn")``, as in ``der.continuation``'s steps). Neighbours within an
    arc pi r + dhat are not contact partners, so the barrier does not forbid such a bend: the rod model (a thin
    rod, a centreline) allows it, a real rod of radius r would crush its inside there. The message names the
    vertex and its radius of curvature.

    Example
    -------
    >>> import warnings, der
    >>> options = der.SolverOptions(tight_bend="warn")      # what der.continuation's steps use
    >>> # with warnings.catch_warnings(record=True) as w: der.solve(scene, state=state, options=options)
    """


class RoundoffFloorWarning(UserWarning):
    """A solve stopped at the round-off floor of its residual, above the requested ``tol`` (status
    "converged_at_floor"): the arithmetic cannot certify the equilibrium more closely. The message gives the
    ratio residual / tol.

    Example
    -------
    Turn it into an error, or silence it, with the standard ``warnings`` filters:

    >>> import warnings, der
    >>> warnings.simplefilter("error", der.RoundoffFloorWarning)     # a floor verdict now raises
    >>> warnings.resetwarnings()
    """


class LockedRodWarning(UserWarning):
    """An inextensible rod held at both ends carries a constraint tension far above its bending scale A1/L^2
    that its loads do not explain: it is locked between its fixed ends (it cannot bend without changing its
    chord), so its answer is the inextensible limit, not beam theory. Give the rod a finite ``EA``
    (``der.rod_from_shape(..., EA=...)``) or let one end slide (``der.clamp("end", slide=axis)``).

    Example
    -------
    >>> import warnings, der
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always", der.LockedRodWarning)
    ...     # a solve of a rod clamped at both ends and turned at one of them would record it here
    ...     pass
    >>> caught
    []
    """


@dataclass
class SolveResult:
    """Outcome of a solve (like scipy.optimize.OptimizeResult).

    state : the final RodState (the last finite one on failure).
    converged, status, message : whether and why the solve stopped (``STATUSES``); converged is True for
        "converged" (residual <= tol) and "converged_at_floor" (stopped at the round-off floor above tol).
    residual : final residual (dimensionless, relative to ``load_scale``); strain : largest |axial strain|.
    residual_floor : round-off floor of the residual, when it was estimated (NaN otherwise).
    residual_per_length : the same imbalance per unit length (see ``der.solvers.system``), n times the residual
        for a uniform rod: the measure a solution error scales with.
    iterations : pseudo-time steps (implicit) or time steps (explicit); wall_time : seconds (after compilation).
    load_scale : the force scale of the residual.
    min_eigenvalue, stable, eigenvalues : stability at the equilibrium (None if not computed); eigenvalues are
        of the stiffness pencil (K, M), i.e. squared natural frequencies, with rigid-body and other symmetry
        modes removed. ``stable`` is False if one has a negative real part (divergence); ``flutter`` is True if
        complex eigenvalues appear among the lowest (circulatory loads: the undamped rod would flutter).
    stability_time : seconds spent in the stability analysis (not part of ``wall_time``; 0 if not run), with the
        assembly of the Hessian at the final state (which the implicit solver does in its last force evaluation
        when the analysis follows). ``stability_cpu_time``: the same in CPU seconds of this process
        (``time.process_time``; tools/stability_scaling.py compares it with the solve's).
    stability_method : the eigen-solver path that ran ("dense", "banded shift-invert" in node coordinates, "edge
        shift-invert" in edge coordinates: open rods held at their start; "" if not run). See der.solvers.stability.
    energy : energy by term at the final state.
    history : residual after each iteration/check.
    compile_time : seconds spent compiling (or loading from numba's cache) der's kernels before this solve,
        on the first solve of a process; never part of ``wall_time``. 0 afterwards.
    tol : the residual tolerance the solve was asked for.
    reactions : one dict per constraint: ``support``, ``end`` (or ``node``/``edge``), ``at``, ``force`` and
        ``moment`` (lab frame, what the support exerts on the rod, moment about ``at``: the end cross-section's
        centre for clamps, hinges and rollers); see ``der.solvers.system.support_reactions``.
    contact : with contact terms, ``der.diagnostics.contact_forces`` at the final state (pairs in contact,
        force per pair and per length, minimal distance, per term); None otherwise.
    linear_solves : how many Newton systems the implicit solver factorised on the banded path and on the
        sparse (contact) path.
    states, rods : for a scene of several rods (``der.Scene([scene_a, scene_b, ...])``): ``states[i]`` is rod i's
        final RodState (``state`` is then a ``MultiState`` holding them, ``state.rods``), ``rods[i]`` a dict with
        its ``energy`` by term, ``reactions`` and ``load_scale``; None for one rod. ``reactions`` then lists every
        rod's supports, each with its ``rod`` index.
    timings : seconds of ``wall_time`` by phase where the solver measures them (implicit: "assembly" -- forces,
        band Jacobian, residual and its scales --, "factorisation" -- banded LU and solve --, "line_search").

    ``print(result)`` shows a short summary (``repr``); the arrays are attributes (``result.state``,
    ``result.eigenvalues``, ``result.history``).

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.5)
    >>> scene = der.Scene(rod, loads=[der.end_torque(1e-3, follower=True)], constraints=[der.clamp("start")])
    >>> result = der.solve(scene)
    >>> result.converged, result.status
    (True, 'converged')
    >>> print(result)                                         # doctest: +SKIP
    SolveResult(converged, implicit solver)
      residual 3.25e-15 <= tol 1e-08 after 1 iteration; wall time 0.000333 s
      stable: True (min eigenvalue 11.13, flutter)
      message: residual 3.25e-15 <= tol 1.0e-08
    """

    state: object
    converged: bool
    status: str
    residual: float
    iterations: int
    wall_time: float
    message: str
    solver: str = ""
    strain: float = 0.0
    load_scale: float = float("nan")
    min_eigenvalue: float | None = None
    stable: bool | None = None
    eigenvalues: np.ndarray | None = None
    flutter: bool | None = None
    stability_note: str = ""
    energy: dict = field(default_factory=dict)
    history: list = field(default_factory=list)
    dt: float | None = None
    residual_floor: float = float("nan")
    residual_per_length: float = float("nan")
    stability_time: float = 0.0
    stability_cpu_time: float = 0.0
    stability_method: str = ""
    compile_time: float = 0.0
    reactions: list = field(default_factory=list)
    tol: float = float("nan")
    contact: dict | None = None         # contact diagnostics (issue 14; None for a scene without contact)
    linear_solves: dict = field(default_factory=dict)   # implicit: {"band": count, "sparse": count}
    timings: dict = field(default_factory=dict)
    states: list | None = None          # several rods: one RodState per rod
    rods: list | None = None            # several rods: per rod energy, reactions, load scale

    def __repr__(self):
        """One short paragraph: status, residual against tol, iterations, times, stability, message."""
        def num(v, fmt=".3g"):
            return "nan" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)

        head = self.status or ("converged" if self.converged else "not converged")
        if self.converged and head != "converged":
            head += ", converged"
        elif not self.converged:
            head += ", NOT converged"
        rel = "<=" if self.residual <= self.tol else ">" if self.tol == self.tol else "vs"
        lines = [f"SolveResult({head}" + (f", {self.solver} solver)" if self.solver else ")"),
                 f"  residual {num(self.residual, '.2e')} {rel} tol {num(self.tol, '.0e')} after {self.iterations} "
                 f"iteration{'' if self.iterations == 1 else 's'}; wall time {num(self.wall_time)} s"]
        stability_time = getattr(self, "stability_time", None)
        if stability_time:
            lines[-1] += f", stability {num(stability_time)} s"
        if self.compile_time:
            lines[-1] += f" (+{num(self.compile_time)} s compiling or loading the kernels, not in wall time)"
        if self.stable is not None:
            lines.append(f"  stable: {self.stable} (min eigenvalue {num(self.min_eigenvalue, '.4g')}"
                         + (", flutter)" if self.flutter else ")"))
        message = self.message if len(self.message) <= 200 else self.message[:197] + "..."
        lines.append(f"  message: {message}")
        return "\n".join(lines)


class ConvergenceError(RuntimeError):
    """Raised by ``der.solve`` when a solve does not converge; ``.result`` holds the SolveResult with the last state.

    Parameters
    ----------
    result : SolveResult
        The unconverged result (``status``, ``residual``, ``message``, and the last finite ``state``).

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.5)
    >>> scene = der.Scene(rod, loads=[der.end_force([1e-3, 0, 0])], constraints=[der.clamp("start")])
    >>> try:
    ...     der.solve(scene, max_iterations=1, newton_first=False)
    ... except der.ConvergenceError as exc:
    ...     last_state = exc.result.state                    # continue from here, or inspect exc.result
    """

    def __init__(self, result):
        self.result = result
        super().__init__(f"{result.solver} solve did not converge: {result.status} after {result.iterations} "
                         f"iterations, residual {result.residual:.3e} -- {result.message}")
