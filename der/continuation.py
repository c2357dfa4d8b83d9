"""Continuation: follow an equilibrium as a parameter of the scene changes, around folds, with its stability.

``der.continuation(scene_of, p0, ...)`` follows the equilibria of ``scene_of(p)`` (a function of one float
returning a ``der.Scene``: a load, a support motion, an imposed twist, a natural strain, a stiffness ...) from
``p0``. Pseudo-arclength continuation (Keller): the unknowns are the state q and the parameter p together, and
each new point x = (q, p) solves

    R(q, p) = 0                          (the free DOFs' force balance, R = f_ext - dE/dq)
    <t, x - x_pred> = 0                  (on the hyperplane through the predictor x_pred = x_k + ds t, normal to t)

by Newton's method on the bordered system. With K = d(grad - f_ext)/dq (the solver's banded force Jacobian)
and R_p = dR/dp (a central difference of the residual in p), each Newton step factorises K once and solves
K a = R, K b = R_p; then dp = -(N + <t_q, a>) / (<t_q, b> + w_p t_p), dq = a + dp b (block elimination of
the bordered matrix). The tangent t at a converged point is (b, 1) t_p, normalised, oriented by the previous
tangent; its p component dp/ds changes sign at a fold, so folds are passed (and told from bifurcations).

<u, v> weighs node coordinates by 1/L^2 and angles by 1 (averaged over the DOFs) and the parameter by
1/p_scale^2: an arclength step ``ds`` is dimensionless. Rigid motions an unconstrained rod is free to make
(those the stiffness annihilates) are projected out of every step; they are not part of the branch.

Stability at every point comes from ``der.check_stability`` (its ``min_eigenvalue``: the real part of the
lowest eigenvalue of the constrained stiffness pencil). Between two points where dp/ds changes sign there is a
fold; where the stability changes without a fold, a bifurcation (or a Hopf-type crossing, when the crossing
eigenvalue is complex). Both are located by a secant (Illinois) search on the arclength of the step: the root
of dp/ds for a fold, of the lowest eigenvalue for a bifurcation. ``Branch.switch`` starts the bifurcated
branch along the critical eigenvector.

Contact: while contact pairs are active the stiffness couples distant DOFs; each Newton step then factorises
the constrained band plus the contact Hessian's triplets as one sparse matrix (SuperLU, as the implicit solver
does), and K a = R, K b = R_p are solved with it (``Branch.sparse_factorisations`` counts them). On a rod whose
end supports link DOFs (a sliding clamp, a pin: q_dep = c + T y) the triplets are condensed as the band is,
T^T H T (``condensed_triplets``). The barrier keeps the strands apart as long as no Newton step jumps across it;
a step that would (a non-finite energy) fails and is halved; the natural method's steps are der.solve's, whose
line search is limited by CCD.

Held DOFs (clamps, prescribed rotations) are put where scene_of(p)'s targets put them at every iterate, never
extrapolated along a linear step: a clamp keeps its end edge's length, which a linear turn would stretch.

``method="natural"`` is the simpler natural-parameter continuation: p steps, each point a ``der.solve`` warm
started from a secant predictor (``predictor="last"``: from the last point, its held DOFs moved to the new
targets; ``predictor="tangent"``: along the path's tangent dq/dp at the last point, K dq/dp = dR/dp solved with
the converged state's force Jacobian, the exact contact Hessian included at the barrier stiffness that solve
ended with; measured on the plectoneme it pays with the smooth barrier ``der.self_contact(r, samples=m)`` and
steps of 1/8 turn, not with the segment barrier: docs/contact.md section 9.3).
It stops at a fold. ``dp`` makes its steps a fixed parameter step (halved on a failed solve, grown back
after a converged one, never above dp): a grid in p, with each point what ``der.solve`` finds from its warm start,
snaps included (the tangent-continuity test, which halves adaptive steps whose secant turns by more than ~26
degrees, does not apply). ``perturb(p, state)`` may add an imperfection to each step's start (e.g. while a rod is
straight, so that it buckles past its threshold rather than staying on the unstable straight branch). Its steps
after the first start from the model's own equilibria: a start bent tighter than a contact radius is solved on
with a ``TightBendWarning`` (``SolverOptions.tight_bend = "warn"``); only the user's start is refused for it. A
predicted start that violates a contact distance (a secant extrapolated into a contact) falls back to the last
point's state.
"""
import csv
import dataclasses
import io
import json
import math
import sys
import time

import numpy as np

from .scene import Scene

METHODS = ("arclength", "natural")
PREDICTORS = ("secant", "last", "tangent")
KINDS = ("fold", "bifurcation", "hopf", "target")
GAUGE_REGULARISATION = 1e-12   # times diag|K|, only when the rod has free rigid motions (they are projected out)
GAUGE_TOL = 1e-6               # |K v| <= GAUGE_TOL |K| |v|: a rigid motion the stiffness annihilates
DENSE_EIGENVECTOR_MAX_DOFS = 2400
GAUGE_ANGLE_WEIGHT = 1e-8        # rigid motions are fitted on the node coordinates (Problem.gauge_coordinates)
RP_REUSE_RATE = 0.1            # the corrector keeps dR/dp while each Newton step cuts the residual 10x or more
PREDICTOR_HALVINGS = 4         # natural method, predictor "tangent": halvings of a start that violates a contact
# unstable_mode: the dense eigen-solver only up to this many DOFs (a non-symmetric QZ costs ~0.7 s at 240 free DOFs,
# greenhill n = 60; the banded shift-invert of der.solvers.stability ~10 ms)
DENSE_MODES_MAX_DOFS = 60
UNSTABLE_KICKS = 3             # leave_unstable: kicks along the lowest mode and solves again, at most, per point
TANGENT_COS = 0.9              # a step whose tangent turns by more than acos(0.9) = 26 degrees is halved


class Branch:
    """A followed branch of equilibria.

    Attributes
    ----------
    parameter : the parameter's name (a column of the table).
    points : list of dicts, one per equilibrium on the branch: the parameter, ``s`` (arclength, dimensionless),
        ``dp_ds``, the user's summaries, ``residual``, ``newton_iterations`` (Newton steps and multiplier
        updates of the corrector), ``min_eigenvalue``, ``stable``, ``flutter`` and ``stability_time`` (seconds
        of the eigenvalue computation at that point).
    states : the RodState of each point (empty if ``keep_states=False``).
    special : list of dicts: the located special points, each with ``kind`` ("fold", "bifurcation", "hopf", or "target": where a summary reached ``target``),
        the parameter, ``index`` (it lies between points index - 1 and index), ``s``, ``min_eigenvalue``,
        the summaries, ``located_to`` (the width of the final bracket, in the parameter) and ``state``.
    status : "completed" (reached a bound or the stop condition), "max_steps", "time_budget", "step_too_small"
        (the corrector failed down to ``ds_min``: a turning point the natural method cannot pass, or no
        equilibrium nearby), "interrupted"; message : why, in words.
    wall_time : seconds. sparse_factorisations : how many bordered Newton steps factorised the sparse K of an
    active contact (band + contact Hessian, SuperLU) instead of the band.

    ``table()`` gives the columns, ``to_csv``/``to_json`` write them, ``plot`` a PNG bifurcation diagram,
    ``record`` a rerun recording of the path, ``switch`` the branch that bifurcates at a special point.
    """

    def __init__(self, parameter, settings):
        self.parameter = parameter
        self.points, self.states, self.special = [], [], []
        self.status, self.message, self.wall_time = "", "", 0.0
        self.sparse_factorisations = 0
        self._settings = settings

    def __repr__(self):
        sp = ", ".join(f"{s['kind']} at {self.parameter} = {s[self.parameter]:.8g}" for s in self.special)
        return (f"Branch({len(self.points)} points, {self.parameter} from "
                f"{self.points[0][self.parameter]:.6g} to {self.points[-1][self.parameter]:.6g}, {self.status}"
                f"{'; ' + sp if sp else ''})") if self.points else f"Branch(empty, {self.status})"

    @property
    def columns(self):
        cols = []
        for p in self.points:
            for k in p:
                if k not in cols:
                    cols.append(k)
        return cols

    def table(self):
        """The points as columns: {name: list}."""
        return {c: [p.get(c) for p in self.points] for c in self.columns}

    def to_dict(self):
        """Everything but the states, JSON-ready."""
        return {"parameter": self.parameter, "status": self.status, "message": self.message,
                "wall_time": self.wall_time, "points": [_jsonable(p) for p in self.points],
                "special": [_jsonable({k: v for k, v in s.items() if k not in ("state", "tangent")})
                            for s in self.special]}

    def to_json(self, path=None):
        """The branch as JSON text (written to ``path`` if given)."""
        text = json.dumps(self.to_dict(), allow_nan=False)
        if path is not None:
            with open(path, "w") as f:
                f.write(text + "\n")
        return text

    def to_csv(self, path=None):
        """The table of points as CSV text (written to ``path`` if given); special points are not rows."""
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        cols = self.columns
        writer.writerow(cols)
        for p in self.points:
            writer.writerow(["" if p.get(c) is None else p.get(c) for c in cols])
        if path is not None:
            with open(path, "w") as f:
                f.write(buf.getvalue())
        return buf.getvalue()

    def to_dataframe(self):
        """The table as a pandas DataFrame (pandas must be installed)."""
        import pandas as pd

        return pd.DataFrame(self.table())

    def plot(self, path, y, others=(), **kwargs):
        """A PNG bifurcation diagram of summary ``y`` against the parameter (``der.plotting.bifurcation_diagram``;
        needs matplotlib, the ``plot`` extra). ``others``: further branches drawn on the same axes."""
        from .plotting import bifurcation_diagram

        return bifurcation_diagram([self, *others], path, y, **kwargs)

    def record(self, path):
        """A rerun recording (.rrd) of the path: one time step per point (needs the states)."""
        if not self.states:
            raise ValueError("Branch.record: the branch kept no states (continuation(..., keep_states=True))")
        from .recording import Recorder
        from .solvers import SolverOptions
        from .solvers.system import build_system, energy_terms

        scene_of = self._settings["scene_of"]
        with Recorder(path, self.states[0] and scene_of(self.points[0][self.parameter]).rod) as rec:
            rec.log_rest()
            for i, (point, state) in enumerate(zip(self.points, self.states)):
                scene = scene_of(point[self.parameter])
                system = build_system(scene, SolverOptions())
                rec.log_step(i, state, point["residual"] or 0.0, energy_terms(system, state))
                rec.rec.log(f"continuation/{self.parameter}", rec.rr.Scalars(float(point[self.parameter])))
        return path

    def switch(self, which=0, side=1, ds=None, **overrides):
        """Follow the branch that bifurcates at special point ``which`` (an index into ``special``, or the dict),
        starting along the critical eigenvector (``side`` +1 or -1 picks its sign). The eigenvector is computed
        here with a dense eigen-solver on the constrained stiffness (small rods: at most
        DENSE_EIGENVECTOR_MAX_DOFS free DOFs). Other arguments as for ``continuation`` (default: this branch's).
        Returns a new Branch whose first point is the bifurcation point."""
        sp = self.special[which] if isinstance(which, int) else which
        if sp.get("kind") not in ("bifurcation",):
            raise ValueError(f"Branch.switch: special point {which!r} is a {sp.get('kind')!r}; branch switching "
                             "needs a 'bifurcation'")
        if side not in (1, -1):
            raise ValueError(f"Branch.switch: side must be +1 or -1; got {side!r}")
        settings = dict(self._settings)
        settings["stop"] = None          # the old branch's stop condition is about the old branch
        settings["target"] = None
        settings.update(overrides)
        settings["ds"] = settings["ds"] if ds is None else ds
        problem = _Problem(settings)
        p = sp[self.parameter]
        state = problem.prepared(p, sp["state"])
        phi = critical_eigenvector(problem.scene(p), state)
        tq = sp["tangent"][:-1]
        w = problem.weights
        # orthogonal (in <.,.>) to the old branch's tangent: the hyperplane then misses the old branch near x*
        nt = float(np.sum(w * tq * tq))
        if nt > 0:
            phi = phi - float(np.sum(w * phi * tq)) / nt * tq
        t = np.append(phi, 0.0)
        t *= side / problem.norm(t)
        return _follow(problem, state, p, t, settings, first=dict(sp), parameter=self.parameter, along=True)


def continuation(scene_of, p0, p_end=None, *, state=None, parameter="p", bounds=None, direction=None, ds=0.05,
                 ds_min=1e-6, ds_max=0.25, p_scale=None, max_steps=200, time_budget=math.inf, method="arclength",
                 summaries=None, stop=None, target=None, stability=True, locate=True, locate_tol=1e-7,
                 n_eigenvalues=6, tol=1e-8, max_newton=12, keep_states=True, progress=None, options=None, dp=None,
                 predictor="secant", perturb=None, solve=None, leave_unstable=None):
    """Follow an equilibrium of ``scene_of(p)`` as p changes, from ``p0``.

    Parameters
    ----------
    scene_of : callable float -> der.Scene; every scene's rod has the same number of edges (the parameter may
        set loads, constraint targets, natural strains, stiffnesses).
    p0 : the start; the first point is ``der.solve(scene_of(p0), state=state)``.
    p_end : optional end of the parameter range (the branch stops on it, or when p leaves ``bounds``).
    state : starting state for the first solve (default: the rod's rest state).
    parameter : the parameter's name in the table (e.g. "mt").
    bounds : (low, high): the branch ends where p would leave them (default: p0 and p_end, or unbounded).
    direction : +1 or -1, the initial sign of dp/ds (default: towards p_end, else +1).
    ds, ds_min, ds_max : arclength step (dimensionless, see the module docstring), adapted: halved on a failed
        corrector, x1.5 after a corrector of at most 3 Newton iterations (natural method: after every converged
        solve).
    p_scale : the parameter's unit in the arclength (default |p_end - p0|, else max(|p0|, 1)).
    max_steps, time_budget : bounds on the number of points and the seconds.
    method : "arclength" (default; passes folds) or "natural" (p steps, each a der.solve; stops at a fold).
    summaries : {name: f(scene, state) -> float}: scalar columns of the table.
    stop : optional f(point dict) -> bool; True ends the branch after that point.
    target : optional (name, value): the branch ends where summary ``name`` reaches ``value`` (a force under
        displacement control: force control), located by the same secant as the special points to
        |summary - value| <= locate_tol max(|value|, 1) and reported as a special point of kind "target".
    stability, locate, locate_tol : the lowest eigenvalues at every point; special points located by secant
        to ``locate_tol`` relative width in p (folds: |dp/ds| below it).
    n_eigenvalues, tol, max_newton : eigenvalues per point, residual tolerance (as ``der.solve``), Newton
        iterations per corrector.
    keep_states : keep every point's RodState (needed for ``record`` and ``switch``).
    progress : True: a line per point on stderr; None: after 2 s.
    options : der.SolverOptions for the first solve and the natural method (whose steps after the first use it
        with ``tight_bend="warn"``).
    dp : natural method only: a fixed parameter step (> 0; its sign follows ``direction``), halved on a failed
        solve (down to ds_min p_scale) and grown back after a converged one; None: arclength steps ``ds``.
    predictor : natural method only: "secant" (default), "last" (each solve starts from the last point) or
        "tangent" (from the last point along the tangent of the path, K dq/dp = dR/dp at that point, the
        contact terms' exact Hessian in K: one factorisation per step; a start that would violate a contact
        distance is pulled back towards the last point, halving the step up to PREDICTOR_HALVINGS times, then
        the last point).
    perturb : natural method only: f(p, state) -> RodState or None, applied to each step's predicted start
        (None: unchanged), e.g. an imperfection while the rod is straight.
    leave_unstable : natural method only: None, or a kick size k > 0 (a fraction of the rod's length): a point
        that converged to an unstable equilibrium (der.check_stability's lowest eigenvalue below zero, the
        scene's symmetries removed) is moved along its lowest mode by k L (largest node displacement; the sign
        that makes its largest node component positive) and solved again, up to UNSTABLE_KICKS times
        (``leave_unstable``): past a threshold the grid follows the branch the unstable mode leads to instead of
        the unstable one (e.g. the straight rod turned past its buckling). Costs one stability analysis per point.
    solve : a function with der.solve's arguments (scene, state=, options=, tol=, stability=) returning its
        SolveResult without raising when a solve does not converge, used for the first point and the natural
        method's steps (e.g. a scenario's runner that records them); default der.solve.

    Returns
    -------
    Branch

    Raises
    ------
    TypeError / ValueError before any work for bad arguments; der.ConvergenceError if the first point does not
    converge.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.ring(1.0, 24), A1=1.0, A2=1.5)
    >>> branch = der.continuation(lambda mt: der.Scene(rod, loads=[der.twisting_moment(mt)]), 0.0, 0.5,
    ...                           parameter="mt")                                   # doctest: +SKIP
    """
    from . import validate
    from .solvers import SolverOptions

    if not callable(scene_of):
        raise TypeError(f"der.continuation: scene_of must be a function of the parameter returning a der.Scene; "
                        f"got {type(scene_of).__name__}")
    p0 = validate.finite_number(p0, "der.continuation: p0")
    if p_end is not None:
        p_end = validate.finite_number(p_end, "der.continuation: p_end")
        if p_end == p0:
            raise ValueError(f"der.continuation: p_end must differ from p0 = {p0}")
    if method not in METHODS:
        raise ValueError(f"der.continuation: method must be one of {METHODS}; got {method!r}")
    for name, value in (("ds", ds), ("ds_min", ds_min), ("ds_max", ds_max), ("locate_tol", locate_tol),
                        ("tol", tol)):
        validate.positive_number(value, f"der.continuation: {name}")
    if not ds_min <= ds <= ds_max:
        raise ValueError(f"der.continuation: need ds_min <= ds <= ds_max; got {ds_min}, {ds}, {ds_max}")
    max_steps = validate.integer(max_steps, "der.continuation: max_steps", "an integer >= 1")
    max_newton = validate.integer(max_newton, "der.continuation: max_newton", "an integer >= 1")
    if max_steps < 1 or max_newton < 1:
        raise ValueError(f"der.continuation: max_steps and max_newton must be >= 1; got {max_steps}, {max_newton}")
    if predictor not in PREDICTORS:
        raise ValueError(f"der.continuation: predictor must be one of {PREDICTORS}; got {predictor!r}")
    if perturb is not None and not callable(perturb):
        raise TypeError(f"der.continuation: perturb must be a function (p, state) -> RodState or None; got {perturb!r}")
    if dp is not None:
        dp = validate.positive_number(dp, "der.continuation: dp")
    if leave_unstable is not None:
        leave_unstable = validate.positive_number(leave_unstable, "der.continuation: leave_unstable")
    if method != "natural" and (dp is not None or perturb is not None or predictor != "secant"
                                or leave_unstable is not None):
        raise ValueError("der.continuation: dp, perturb, predictor and leave_unstable are options of "
                         "method='natural' (the arclength method steps by ds along its tangent)")
    if solve is not None and not callable(solve):
        raise TypeError(f"der.continuation: solve must be a function like der.solve or None; got {solve!r}")
    if not (isinstance(time_budget, (int, float)) and time_budget > 0):
        raise ValueError(f"der.continuation: time_budget must be a number of seconds > 0; got {time_budget!r}")
    if direction is None:
        direction = 1 if p_end is None or p_end > p0 else -1
    if direction not in (1, -1):
        raise ValueError(f"der.continuation: direction must be +1 or -1; got {direction!r}")
    if bounds is None:
        bounds = (-math.inf, math.inf) if p_end is None else (min(p0, p_end), max(p0, p_end))
    lo, hi = (float(b) for b in bounds)
    if not lo <= p0 <= hi or not lo < hi:
        raise ValueError(f"der.continuation: bounds {bounds} must contain p0 = {p0} (low < high)")
    if p_scale is None:
        p_scale = abs(p_end - p0) if p_end is not None else max(abs(p0), 1.0)
    p_scale = validate.positive_number(p_scale, "der.continuation: p_scale")
    summaries = dict(summaries or {})
    for name, f in summaries.items():
        if not callable(f) or name in ("s", parameter):
            raise ValueError(f"der.continuation: summaries[{name!r}] must be a function (scene, state) -> float "
                             f"with a name other than 's' and {parameter!r}")
    if target is not None:
        if not (isinstance(target, (tuple, list)) and len(target) == 2 and target[0] in summaries):
            raise ValueError(f"der.continuation: target must be (name, value) with name one of the summaries "
                             f"{sorted(summaries)}; got {target!r}")
        target = (target[0], validate.finite_number(target[1], "der.continuation: target value"))
    if stop is not None and not callable(stop):
        raise TypeError(f"der.continuation: stop must be a function of a point (dict) or None; got {stop!r}")
    options = options or SolverOptions()
    if not isinstance(options, SolverOptions):
        raise TypeError(f"der.continuation: options must be a der.SolverOptions; got {type(options).__name__}")
    settings = dict(scene_of=scene_of, parameter=parameter, bounds=(lo, hi), ds=float(ds), ds_min=float(ds_min),
                    ds_max=float(ds_max), p_scale=p_scale, max_steps=max_steps, time_budget=float(time_budget),
                    method=method, summaries=summaries, stop=stop, target=target, stability=bool(stability), locate=bool(locate),
                    locate_tol=float(locate_tol), n_eigenvalues=n_eigenvalues, tol=float(tol),
                    max_newton=max_newton, keep_states=bool(keep_states), progress=progress, options=options,
                    dp=None if dp is None else float(dp), predictor=predictor, perturb=perturb,
                    solve=solve or _der_solve, leave_unstable=leave_unstable)
    problem = _Problem(settings)
    scene = problem.scene(p0)
    if state is not None:
        from .rod import check_state

        check_state(scene.rod, state, "der.continuation: state")
    from .solvers import ConvergenceError

    first = settings["solve"](scene, state=state, options=options, tol=tol, stability=False)
    if not first.converged:
        raise ConvergenceError(first)
    t0 = np.zeros(problem.n + 1)
    t0[-1] = direction
    return _follow(problem, problem.prepared(p0, first.state), p0, t0, settings, parameter=parameter,
                   first_residual=first.residual, first_iterations=first.iterations)


class _Problem:
    """The scenes along the parameter, their systems, residuals and the bordered Newton solves."""

    def __init__(self, settings):
        from .solvers import SolverOptions

        self.scene_of = settings["scene_of"]
        self.options = settings.get("options") or SolverOptions()
        self.tol = settings["tol"]
        self.p_scale = settings["p_scale"]
        self._systems = {}
        self.n = None
        self.weights = None
        self.sparse_factorisations = 0
        self.rp_evaluations = 0
        self.kappas = None      # the contact terms' barrier stiffness of the last natural step's solve
        # natural method, predictor "tangent": the tangent on the exact (unprojected) barrier Hessian -- the
        # derivative of the equilibrium path; the PSD projection is the solver's globalisation, not the path's
        self.exact_contact = settings.get("method") == "natural" and settings.get("predictor") == "tangent"

    def scene(self, p):
        scene = self.scene_of(float(p))
        if not isinstance(scene, Scene):
            raise TypeError(f"der.continuation: scene_of({p!r}) must return a der.Scene; got {type(scene).__name__}")
        if scene.scenes is not None:
            raise ValueError(f"der.continuation: scene_of({p!r}) is a scene of several rods; the continuation follows "
                             "one rod (continue each rod alone, or step der.solve along the parameter)")
        if self.n is None:
            rod = scene.rod
            self.n = rod.n_dof
            w = np.where(np.arange(rod.n_dof) % 4 == 3, 1.0, 1.0 / rod.length ** 2)
            if not rod.closed:
                w[4 * rod.n_nodes - 1] = 0.0      # the unused angle slot of the last node
            self.weights = w / np.count_nonzero(w)
            self.w_p = 1.0 / self.p_scale ** 2
        elif scene.rod.n_dof != self.n:
            raise ValueError(f"der.continuation: scene_of({p!r}) has a rod with {scene.rod.n_dof // 4} nodes; the "
                             f"first had {self.n // 4} (the parameter may not change the discretisation)")
        return scene

    def system(self, p):
        from .solvers.system import build_system

        p = float(p)
        sys_ = self._systems.get(p)
        if sys_ is None:
            if len(self._systems) > 8:
                self._systems.pop(next(iter(self._systems)))
            sys_ = build_system(self.scene(p), self.options)
            self._systems[p] = sys_
        if self.kappas is not None:
            for term, kappa in zip(sys_.terms, self.kappas):
                if kappa is not None and getattr(term, "adaptive", False):
                    term.kappa = kappa
        return sys_

    def stiffness_from(self, result):
        """Keep the adaptive barrier stiffness a natural step's solve ended with (``result.contact``): the tangent
        at its point is taken on the energy that point is an equilibrium of."""
        contact = getattr(result, "contact", None)
        if contact and contact.get("terms"):
            self.kappas = [t.get("kappa") for t in contact["terms"]]

    def prepared(self, p, state):
        """A copy of ``state`` with scene_of(p)'s constraint targets applied (frames transported)."""
        from .solvers.system import prepare_state

        sys_ = self.system(p)
        carry_penalty(sys_, state)
        return prepare_state(sys_, state)

    def admissible(self, p, state):
        """False if ``state`` violates a contact distance of scene_of(p) (the contact terms' start check; a
        tight bend alone does not count); True without contact terms."""
        sys_ = self.system(p)
        if not sys_.terms:
            return True
        import warnings

        from .solvers.system import prepare_state

        work = prepare_state(sys_, state)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                for term in sys_.terms:
                    term.check_start(work, "warn")
        except ValueError:
            return False
        return True

    def inner(self, u, v):
        return float(np.sum(self.weights * u[:-1] * v[:-1]) + self.w_p * u[-1] * v[-1])

    def norm(self, u):
        return math.sqrt(self.inner(u, u))

    def residual(self, p, state):
        """(R, residual norm, strain ok, the elongation as a residual) at ``state`` for scene_of(p) (evaluates
        the system)."""
        from .solvers.system import (
            constraint_residual, evaluate_system, load_scales, max_strain, residual_norm, residual_vector,
        )

        sys_ = self.system(p)
        carry_penalty(sys_, state)
        evaluate_system(sys_, state, 1)
        R = residual_vector(sys_)
        scales = load_scales(sys_, state)
        res = residual_norm(sys_, R, scales)
        if not sys_.rod.inextensible:
            return R, res, True, 0.0
        strain_ok = max_strain(sys_, state) <= self.options.effective_strain_tol
        return R, res, strain_ok, constraint_residual(sys_, state, scales)

    def dR_dp(self, p, state):
        """(dR/dp at fixed free DOFs, dq_fixed/dp): central differences; the constraint targets move with p."""
        from .solvers.system import evaluate_system, prepare_state, residual_vector

        h = 1e-6 * max(abs(p), self.p_scale)
        out = []
        for pp in (p + h, p - h):
            sys_ = self.system(pp)
            st = prepare_state(sys_, state)
            st.lam[:] = state.lam
            evaluate_system(sys_, st, 1)
            out.append((residual_vector(sys_), st.q.copy()))
        return (out[0][0] - out[1][0]) / (2 * h), (out[0][1] - out[1][1]) / (2 * h)

    def factor(self, p, state):
        """Factorise the constrained force Jacobian at ``state``; returns (lu, piv, system, gauge basis)."""
        from scipy.linalg.lapack import dgbtrf

        from .linalg import add_diagonal
        from .solvers.system import constrain_system, evaluate_system

        sys_ = self.system(p)
        if self.exact_contact:
            for term in sys_.terms:
                term.project = False
        evaluate_system(sys_, state, 2)
        coo = getattr(sys_, "contact_coo", None)
        V = gauge_modes(sys_, state)
        ab = sys_.ab.copy(order="F")
        if V.shape[1]:
            diag = np.abs(ab[sys_.kl + sys_.ku, :][sys_.perm])
            diag[diag == 0] = 1.0
            add_diagonal(ab, sys_.kl, sys_.ku, sys_.perm, diag, GAUGE_REGULARISATION)
        constrain_system(sys_, ab, 1.0)        # T^T K T on the end supports' free variables, held DOFs identity
        if coo:
            return self._sparse_factor(sys_, ab, coo, V)
        lu, piv, info = dgbtrf(ab, sys_.kl, sys_.ku, overwrite_ab=1)
        return (lu, piv, sys_, V) if info == 0 else None

    def _sparse_factor(self, sys_, ab, coo, V):
        """Active contact couples distant DOFs: the constrained band plus the contact Hessian's triplets (off the
        held DOFs) as one sparse matrix, factorised by SuperLU (as the implicit solver does while pairs are
        active). Returns ("sparse", lu, system, gauge basis) or None if it is singular."""
        import scipy.sparse as sp
        from scipy.sparse.linalg import splu

        from .linalg import band_to_coo

        n = ab.shape[1]
        rb, cb, vb = band_to_coo(ab, sys_.kl, sys_.ku, sys_.perm)
        rows, cols, vals = [rb], [cb], [vb]
        for r, c, v in coo:
            r, c, v = condensed_triplets(sys_, r, c, v)
            keep = ~(sys_.fixed[r] | sys_.fixed[c])
            rows.append(r[keep])
            cols.append(c[keep])
            vals.append(v[keep])
        A = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
        try:
            lu = splu(A, permc_spec="COLAMD")
        except RuntimeError:           # exactly singular
            return None
        self.sparse_factorisations += 1
        return ("sparse", lu, sys_, V)

    def solve(self, fac, rhs):
        """K^-1 rhs (rhs (n,) or (n, k)), rigid motions projected out."""
        from scipy.linalg.lapack import dgbtrs

        lu, piv, sys_, V = fac
        if isinstance(lu, str):                    # the sparse factorisation (active contact)
            x = piv.solve(np.ascontiguousarray(rhs))
        else:
            b = np.empty_like(rhs)
            b[sys_.perm] = rhs
            x, info = dgbtrs(lu, sys_.kl, sys_.ku, b.reshape(len(b), -1), piv)
            x = x.reshape(b.shape)[sys_.perm]
        if x.ndim == 1:
            _expand(sys_, x)
        else:
            for k in range(x.shape[1]):
                col = np.ascontiguousarray(x[:, k])
                _expand(sys_, col)
                x[:, k] = col
        if V.shape[1]:
            x = x - V @ self.gauge_coordinates(V, x)
        return x

    def gauge_coordinates(self, V, x):
        """The rigid-motion coordinates c of ``x`` (n,) or (n, k), with V c its rigid part: fitted on the node
        coordinates (angles weighted GAUGE_ANGLE_WEIGHT times less), so that a step that only turns cross-sections
        -- a twist ramp, which an orthogonal projection would split into a tilt of the whole rod and a remainder --
        keeps its nodes where they are. A rod whose cross-sections may all turn together (no natural curvature)
        has that turn fitted on the angles."""
        w = np.where(self.weights == 0, 0.0, np.where(np.arange(self.n) % 4 == 3, GAUGE_ANGLE_WEIGHT, 1.0))
        VW = V.T * w
        return np.linalg.solve(VW @ V, VW @ x)

    def tangent(self, p, state, t_prev):
        """The unit tangent at a converged point, oriented along ``t_prev``; None if K is singular."""
        fac = self.factor(p, state)
        if fac is None:
            return None
        Rp, dqf = self.dR_dp(p, state)
        b = self.solve(fac, Rp)
        held, dep = held_dofs(fac[2])
        b[held] = dqf[held]
        b[dep] += dqf[dep]
        # (K b = R_p: t = (b, 1) tp with <t_prev, t> = 1 fixing length and orientation)
        t = np.append(b, 1.0)
        tp = 1.0 / self.inner(t_prev, t) if self.inner(t_prev, t) != 0 else 1.0
        t *= tp
        return t / self.norm(t)

    def correct(self, state, p, t, x_pred, max_newton, fixed_p=False):
        """Bordered Newton from ``state`` at ``p`` onto {R = 0, <t, x - x_pred> = 0} (or R = 0 at fixed p).

        Returns (state, p, residual, iterations) or None on failure."""
        from .solvers.system import multiplier_update, transport

        trial = state.copy()
        res_prev = math.inf
        updates = newton = 0
        last_g, just_updated = None, False
        # dR/dp (two scenes and systems at p +- h: the costly part of a step when scene_of builds constraints) is
        # computed at the corrector's first iterate and kept while Newton converges fast (the residual falls by
        # RP_REUSE_RATE or more per step); the bordered step stays exact to first order, and the tangent at the
        # converged point is always computed afresh (Problem.tangent)
        Rp_kept = None
        # Newton's method on the bordered system. An inextensible rod's multipliers are updated as der.solve does
        # (augmented Lagrangian: near equilibrium, when the stretch is above its tolerance; the penalty grows
        # where the update does not shrink it), and Newton goes on from there with its own count and its own
        # convergence test (an update raises the residual)
        for it in range(max_newton + 61):
            R, res, strain_ok, constraint_res = self.residual(p, state)
            if not np.isfinite(res):
                return None
            if res <= self.tol and strain_ok:
                return state, p, res, it
            if not strain_ok and not just_updated and res <= max(self.tol, 0.1 * constraint_res):
                if updates >= 30:
                    return None
                last_g = multiplier_update(self.system(p), state, last_g if res < 1e-4 else None)
                updates += 1
                newton, res_prev, just_updated = 0, math.inf, True
                Rp_kept = None
                continue
            just_updated = False
            if newton == max_newton or (newton >= 3 and res > 0.5 * res_prev) or res > 1e3 * max(res_prev, 1e-3):
                return None
            newton += 1
            if res > RP_REUSE_RATE * res_prev:
                Rp_kept = None
            res_prev = res
            fac = self.factor(p, state)
            if fac is None:
                return None
            sys_ = fac[2]
            if fixed_p:
                dq, dp = self.solve(fac, R), 0.0
            else:
                if Rp_kept is None:
                    Rp_kept = self.dR_dp(p, state)
                    self.rp_evaluations += 1
                Rp, dqf = Rp_kept
                ab = self.solve(fac, np.stack([R, Rp], axis=1))
                a, b = ab[:, 0], ab[:, 1]
                held, dep = held_dofs(sys_)
                a[held] = 0.0
                b[held] = dqf[held]
                b[dep] += dqf[dep]
                x = np.append(state.q, p)
                N = self.inner(t, x - x_pred)
                denom = float(np.sum(self.weights * t[:-1] * b)) + self.w_p * t[-1]
                if denom == 0 or not np.isfinite(denom):
                    return None
                dp = -(N + float(np.sum(self.weights * t[:-1] * a))) / denom
                dq = a + dp * b
            if not np.all(np.isfinite(dq)):
                return None
            if not fixed_p:
                # held DOFs go where scene_of(p_new)'s targets put them (prepared, below), not along the linear
                # step: a clamp keeps its end edge's length, and a linear turn of it would stretch it for good
                dq[held] = 0.0
            p_new = p + dp
            trial.penalty = None if state.penalty is None else state.penalty.copy()
            if not transport(sys_, state, state.q + dq, trial):
                return None
            state = self.prepared(p_new, trial)
            state.lam[:] = trial.lam
            p = p_new
        return None


def condensed_triplets(system, rows, cols, vals):
    """Triplets (rows, cols, vals) of a matrix H on the DOFs as those of T^T H T on the end supports' free
    variables (q_dep = c + sum_k coef_k q_master_k; the band's ``condense_band``): an entry on a dependent row
    (column) is moved to each of its masters' rows (columns), times the coefficient. Unchanged without links."""
    lk = getattr(system, "links", None)
    if lk is None or not lk.tri_dep.size:
        return rows, cols, vals
    n = system.fixed.shape[0]
    # for each DOF: the slice of its (master, coef) entries, or itself with coefficient 1
    order = np.argsort(lk.tri_dep, kind="stable")
    dep_sorted, master, coef = lk.tri_dep[order], lk.tri_master[order], lk.tri_coef[order]
    start = np.searchsorted(dep_sorted, np.arange(n), side="left")
    count = np.searchsorted(dep_sorted, np.arange(n), side="right") - start

    def expand(idx, other, v):
        c = count[idx]
        plain = c == 0
        out_i, out_o, out_v = [idx[plain]], [other[plain]], [v[plain]]
        dep = np.flatnonzero(~plain)
        for k in range(int(c.max(initial=0))):
            sel = dep[c[dep] > k]
            j = start[idx[sel]] + k
            out_i.append(master[j])
            out_o.append(other[sel])
            out_v.append(coef[j] * v[sel])
        return np.concatenate(out_i), np.concatenate(out_o), np.concatenate(out_v)

    r, c, v = expand(np.asarray(rows), np.asarray(cols), np.asarray(vals))
    c, r, v = expand(c, r, v)
    return r, c, v


def held_dofs(system):
    """(held, dependent): boolean masks of the DOFs the constraints hold outright, and of those an end support
    moves with its free variables (q_dep = c(p) + T y; system.fixed has both). A step's dependent entries are
    T times its free ones (Problem.solve expands them) plus, along the parameter, dc/dp."""
    dep = np.zeros(system.rod.n_dof, dtype=bool)
    lk = getattr(system, "links", None)
    if lk is not None and lk.tri_dep.size:
        dep[lk.tri_dep] = True
    return system.fixed & ~dep, dep


def carry_penalty(system, state):
    """Set ``system``'s stretch penalty to the one ``state`` was last updated with (state.penalty; the start
    value if none): the continuation builds one system per parameter value, and a penalty grown by the multiplier
    updates (der.solvers.system.multiplier_update) must not fall back to its start value at the next p."""
    if system.rod.inextensible:
        # the energy must use the penalty the multipliers were updated with, or the update over- or undershoots
        system.plan.k_stretch[:] = system.k_initial if state.penalty is None else state.penalty


def _expand(system, x):
    """x <- T x: a step in the end supports' free variables as a step of q (in place; nothing without them)."""
    try:
        from .solvers.system import expand
    except ImportError:        # a der without end supports
        return x
    return expand(system, x)


def gauge_modes(system, state):
    """Orthonormal basis (n_dof, m) of the rigid motions (translations, rotations about the centroid, and the
    uniform turn of all cross-sections of a rod with no natural curvature) that the constraints leave free and
    the stiffness ``system.ab`` (evaluated at ``state``) annihilates; (n_dof, 0) if none."""
    from .linalg import band_matvec

    rod = system.rod
    fixed = system.fixed.copy()
    if not rod.closed:
        fixed[4 * rod.n_nodes - 1] = False
    x = state.positions
    centre = x.mean(axis=0)
    cands = []
    for a in range(3):
        v = np.zeros(rod.n_dof)
        v.reshape(-1, 4)[:, a] = 1.0
        cands.append(v)
        w = np.zeros(3)
        w[a] = 1.0
        v = np.zeros(rod.n_dof)
        v.reshape(-1, 4)[:, :3] = np.cross(w, x - centre)
        v[4 * np.arange(rod.n_edges) + 3] = state.tangents @ w
        cands.append(v)
    if np.abs(rod.kappa_bar).max() == 0.0:
        v = np.zeros(rod.n_dof)
        v[4 * np.arange(rod.n_edges) + 3] = 1.0
        cands.append(v)
    keep = []
    Kv, Kabs = np.empty(rod.n_dof), np.empty(rod.n_dof)
    for v in cands:
        if not rod.closed:
            v[4 * rod.n_nodes - 1] = 0.0
        if np.abs(v[fixed]).max(initial=0.0) > 1e-12 * np.abs(v).max():
            continue
        band_matvec(system.ab, system.kl, system.ku, system.perm, v, Kv, False)
        band_matvec(system.ab, system.kl, system.ku, system.perm, v, Kabs, True)
        Kv[fixed] = 0.0
        if np.abs(Kv).max() <= GAUGE_TOL * max(np.abs(Kabs).max(), 1e-300):
            keep.append(v)
    if not keep:
        return np.zeros((rod.n_dof, 0))
    Q, Rr = np.linalg.qr(np.array(keep).T)
    good = np.abs(np.diag(Rr)) > 1e-10 * np.abs(np.diag(Rr)).max()
    return Q[:, good]


def critical_eigenvector(scene, state):
    """The eigenvector of the constrained stiffness K (free DOFs, rigid motions removed) whose eigenvalue is
    nearest zero, as a full DOF vector (real part, unit max-norm). Dense: for small rods only (at most
    DENSE_EIGENVECTOR_MAX_DOFS free DOFs). Computed here, not by der.solvers.stability, which gives eigenvalues
    only."""
    import scipy.linalg as la

    from .linalg import band_to_sparse
    from .solvers import SolverOptions
    from .solvers.system import build_system, evaluate_system, prepare_state

    system = build_system(scene, SolverOptions())
    st = prepare_state(system, state)
    evaluate_system(system, st, 2)
    V = gauge_modes(system, st)
    free = system.free.copy()
    if not system.rod.closed:
        free[4 * system.rod.n_nodes - 1] = False
    idx = np.flatnonzero(free)
    if idx.size > DENSE_EIGENVECTOR_MAX_DOFS:
        raise ValueError(f"critical_eigenvector: {idx.size} free DOFs is more than the dense limit "
                         f"{DENSE_EIGENVECTOR_MAX_DOFS}; use a smaller rod for branch switching")
    K = band_to_sparse(system.ab, system.kl, system.ku, system.perm).toarray()[np.ix_(idx, idx)]
    Z = la.null_space(V[idx].T) if V.shape[1] else np.eye(idx.size)
    ev, vec = la.eig(Z.T @ K @ Z)
    k = int(np.argmin(np.abs(ev)))
    y = Z @ vec[:, k]
    y = y.real if np.abs(y.real).max() >= np.abs(y.imag).max() else y.imag
    out = np.zeros(system.rod.n_dof)
    out[idx] = y / np.abs(y).max()
    return out


def unstable_mode(scene, state, n_eigenvalues=2):
    """The lowest mode of ``state`` as an equilibrium of ``scene`` if it is unstable, else None.

    The stability analysis of ``der.check_stability`` (der.solvers.stability.lowest_modes: the constrained
    stiffness pencil, fixed DOFs and the scene's symmetries removed); unstable: the lowest eigenvalue's real part
    is below minus its round-off floor. Returns (eigenvalue, mode): the mode a full DOF vector (the end supports'
    dependent DOFs moved with their free ones, zero on held DOFs), scaled to a largest node displacement of 1 and
    signed so that its node component of largest magnitude is positive (one of its two signs, picked the same
    way every time)."""
    from .solvers import SolverOptions
    from .solvers.stability import lowest_modes
    from .solvers.system import build_system, prepare_state

    system = build_system(scene, SolverOptions())
    st = prepare_state(system, state)
    out = lowest_modes(system, st, n_eigenvalues, dense_max=DENSE_MODES_MAX_DOFS)
    ev = np.asarray(out["eigenvalues"])
    if ev.size == 0 or not float(ev.real[0]) < -float(out["floors"][0]):
        return None
    v = np.asarray(out["vectors"][:, 0])
    if np.iscomplexobj(v):
        v = v.real if np.abs(v.real).max() >= np.abs(v.imag).max() else v.imag
    v = _expand(system, np.array(v, dtype=float))
    nodes = v.reshape(-1, 4)[:, :3]
    k = int(np.argmax(np.abs(nodes)))
    big = float(nodes.flat[k])
    if big == 0.0:
        return None           # no node moves in it (a mode of the angles alone): not a kick sideways
    return float(ev.real[0]), v / big


def leave_unstable(scene, result, kick, solve=None, tries=UNSTABLE_KICKS, **options):
    """Leave an unstable equilibrium: while ``result.state`` is unstable (``unstable_mode``), move it along its
    lowest mode by ``kick`` times the rod's length (the largest node displacement) and solve ``scene`` again
    from there, at most ``tries`` times. A root finder converges to saddles too (e.g. a straight rod turned past
    its buckling threshold); this puts the solve on the branch the unstable mode leads to.

    Each solve from a kick starts damped (``newton_first=False`` unless ``options`` say otherwise): Newton's
    method from near a saddle returns to it (measured on the plectoneme at n = 100, 2.25 turns, kicks of 1e-3 L:
    after three kicks solved Newton-first the rod was still nearly straight and unstable; damped, one kick and it
    buckles: docs/continuation.md).

    ``solve``: a function like der.solve (default der.solve, without raising), called as
    ``solve(scene, state=..., stability=False, **options)``. Returns (result, kicks): the last converged result
    (``result`` itself if it is stable, or if no solve from a kick converged) and how many kicks were made."""
    solve = solve or _der_solve
    options.setdefault("newton_first", False)
    rod = scene.rod
    kicks = 0
    for _ in range(tries):
        found = unstable_mode(scene, result.state)
        if found is None:
            break
        _, mode = found
        blocks = kick * rod.length * mode.reshape(-1, 4)        # (x, y, z, theta) per node
        start = rod.displaced(result.state, blocks[:, :3], blocks[:rod.n_edges, 3])
        kicks += 1
        again = solve(scene, state=start, stability=False, **options)
        if not again.converged:
            break
        result = again
    return result, kicks


def _point(problem, settings, state, p, s, dp_ds, residual, iterations):
    """The table row of a converged point (and its stability)."""
    from .solvers import check_stability

    parameter = settings["parameter"]
    scene = problem.system(p).scene       # the scene the corrector used (cached with its system): no new scene_of
    row = {parameter: float(p), "s": float(s), "dp_ds": float(dp_ds)}
    for name, f in settings["summaries"].items():
        row[name] = float(f(scene, state))
    row["residual"] = float(residual)
    row["newton_iterations"] = int(iterations)
    if settings["stability"]:
        t0 = time.perf_counter()
        st = check_stability(scene, state, settings["n_eigenvalues"])
        row["stability_time"] = time.perf_counter() - t0
        row["min_eigenvalue"] = float(st.min_eigenvalue)
        row["stable"] = bool(st.stable)
        row["flutter"] = bool(st.flutter)
        ev = np.asarray(st.eigenvalues)
        # how many of the lowest eigenvalues are negative: a step with a fold in it must change this by one
        row["_n_unstable"] = int(np.sum(ev.real < -1e-9 * max(1.0, float(np.abs(ev).max(initial=0.0)))))
        row["_crossing_complex"] = bool(ev.size and abs(ev[0].imag) > 1e-8 * max(abs(ev[0]), 1e-300)) \
            if np.iscomplexobj(ev) else False
    return row


def _follow(problem, state, p, t_prev, settings, parameter, first=None, first_residual=0.0, first_iterations=0,
            along=False):
    """The continuation loop from a converged (state, p) with the previous tangent ``t_prev`` (``along``: the
    first step goes along t_prev itself, as from a bifurcation point onto the other branch)."""
    t_start = time.perf_counter()
    branch = Branch(parameter, settings)
    lo, hi = settings["bounds"]
    ds = settings["ds"]
    natural = settings["method"] == "natural"
    dp_max = settings.get("dp") if natural else None
    dp = dp_max
    progress = settings["progress"]

    def say(msg):
        if progress or (progress is None and time.perf_counter() - t_start > 2.0):
            print(f"[der] continuation: {msg} ({time.perf_counter() - t_start:.1f} s)", file=sys.stderr, flush=True)

    def add(state, p, s, t, residual, iterations):
        row = _point(problem, settings, state, p, s, t[-1], residual, iterations)
        branch.points.append(row)
        branch.states.append(state.copy())
        tangents.append(t)
        return row

    tangents = []
    if natural and settings["predictor"] == "tangent" and not along:
        t = problem.tangent(p, state, t_prev)
        if t is None:
            t = t_prev.copy()
    elif natural or along:
        t = t_prev.copy()
    else:
        t = problem.tangent(p, state, t_prev)
        if t is None:
            t = t_prev.copy()       # a start exactly at a singular point (a bifurcation): go along t_prev
    row = add(state, p, 0.0, t, first_residual if first is None else 0.0, first_iterations)
    s_total = 0.0
    status, message = "max_steps", f"{settings['max_steps']} steps done"
    try:
        while len(branch.points) <= settings["max_steps"]:
            if time.perf_counter() - t_start > settings["time_budget"]:
                status, message = "time_budget", f"time budget of {settings['time_budget']:g} s used up"
                break
            if settings["stop"] is not None and len(branch.points) > 1 and settings["stop"](row):
                status, message = "completed", "the stop condition holds"
                break
            if len(branch.points) > 1 and not (lo < p < hi):
                status, message = "completed", f"{parameter} reached the bound {p:.8g}"
                break
            # predictor; a step that would leave the bounds lands on the bound at fixed p
            x = np.append(state.q, p)
            if dp is not None:         # a fixed parameter step along the secant
                x_pred = x + (dp / abs(t[-1])) * t
                # (a bound reached up to rounding counts as reached: no sliver of a last step)
                landing = x_pred[-1] > hi - 1e-9 * dp_max if t[-1] > 0 else x_pred[-1] < lo + 1e-9 * dp_max
                bound = hi if t[-1] > 0 else lo
            else:
                x_pred = x + ds * t
                # (and one that would stop short of a bound by less than a tenth of its own length in p lands on
                # it now: not one more corrector and tangent for a sliver of a step)
                to_bound = min(abs(hi - x_pred[-1]), abs(x_pred[-1] - lo))
                landing = not (lo <= x_pred[-1] <= hi) or (t[-1] != 0 and to_bound < 0.1 * abs(ds * t[-1]))
                bound = hi if abs(hi - x_pred[-1]) <= abs(x_pred[-1] - lo) else lo
            if landing and t[-1] != 0:
                x_pred = x + (bound - p) / t[-1] * t
                x_pred[-1] = bound
            t_step = time.perf_counter()
            out = _step(problem, settings, state, p, t, x_pred, natural, landing, branch)
            if out is None and dp is not None:
                dp *= 0.5
                if dp < settings["ds_min"] * problem.p_scale:
                    status, message = "step_too_small", (
                        f"no equilibrium found from {parameter} = {p:.8g} with the smallest step "
                        f"{settings['ds_min'] * problem.p_scale:.3g} (natural continuation stops at a fold)")
                    break
                continue
            if out is None:
                ds *= 0.5
                if ds < settings["ds_min"]:
                    status, message = "step_too_small", (
                        f"no equilibrium found from {parameter} = {p:.8g} with the smallest step ds_min = "
                        f"{settings['ds_min']:g}" + (" (natural continuation stops at a fold)" if natural else ""))
                    break
                continue
            new_state, new_p, residual, iterations = out
            if natural and dp is None and not landing and abs(new_p - p) < 0.1 * settings["ds_min"] * problem.p_scale:
                # the secant has turned across p (a fold): its steps converge but no longer advance p
                status, message = "step_too_small", (
                    f"{parameter} advanced only {abs(new_p - p):.3g} from {p:.8g}, less than a tenth of the smallest "
                    f"step {settings['ds_min'] * problem.p_scale:.3g} (natural continuation stops at a fold)")
                break
            t_new = _tangent_of(problem, new_state, new_p, state, p, t, natural, settings["predictor"])
            if dp is not None and t_new is None:
                t_new = t.copy()
            if dp is None and t_new is None or (dp is None and not landing and ds > 2 * settings["ds_min"] and (
                    problem.inner(t, t_new) < TANGENT_COS or _crowded(settings, row, new_state, t, t_new,
                                                                      problem, new_p))):
                # the tangent turned by more than ~25 degrees (the step may have jumped branches), or a fold and
                # another change of stability fell into one step: halve it
                ds *= 0.5
                if ds < settings["ds_min"]:
                    status, message = "step_too_small", f"the tangent is not continuous at {parameter} = {p:.8g}"
                    break
                continue
            s_total += problem.norm(np.append(new_state.q, new_p) - x)
            prev_row, prev_state, prev_p, prev_t = row, state, p, t
            row = add(new_state, new_p, s_total, t_new, residual, iterations)
            row["step_time"] = time.perf_counter() - t_step
            state, p, t = new_state, new_p, t_new
            say(f"point {len(branch.points) - 1}: {parameter} = {p:.8g}, dp/ds = {t[-1]:+.3g}, ds = {ds:.3g}"
                + (f", min eigenvalue {row['min_eigenvalue']:.3g}" if settings["stability"] else ""))
            if settings["locate"] and not natural and not (along and len(branch.points) == 2):
                # (a switched branch starts at the special point itself: its first step is not a crossing)
                _detect(problem, settings, branch, prev_row, row, prev_state, prev_p, prev_t, ds)
            target = settings.get("target")
            if target is not None and (prev_row[target[0]] - target[1]) * (row[target[0]] - target[1]) <= 0:
                _detect(problem, settings, branch, prev_row, row, prev_state, prev_p, prev_t, ds, target=target)
                status, message = "completed", f"{target[0]} reached {target[1]:.8g}"
                break
            if landing:
                status, message = "completed", f"{parameter} reached the bound {p:.8g}"
                break
            if dp is not None:
                dp = min(dp_max, 2.0 * dp)
            elif iterations <= 3 or natural:
                # (a natural step is a der.solve, whose pseudo-time iterations count in the hundreds on a contact
                # state: its convergence is the test; with "<= 3" a halved step never grew back)
                ds = min(settings["ds_max"], ds * 1.5)
    except KeyboardInterrupt:
        status, message = "interrupted", "interrupted by the user; the points so far are kept"
    for r in branch.points:
        r.pop("_crossing_complex", None)
        r.pop("_n_unstable", None)
    if not settings["keep_states"]:
        branch.states = []
    branch.status, branch.message = status, message
    branch.wall_time = time.perf_counter() - t_start
    branch.sparse_factorisations = problem.sparse_factorisations
    return branch


def _crowded(settings, row, new_state, t, t_new, problem, new_p):
    """True if the step to (new_state, new_p) holds a fold (dp/ds changes sign) and the number of negative
    eigenvalues changed by other than one: a bifurcation near the fold, to be separated by a smaller step."""
    if not settings["stability"] or t[-1] * t_new[-1] >= 0:
        return False
    new_row = _point(problem, settings, new_state, new_p, 0.0, t_new[-1], 0.0, 0)
    return abs(new_row["_n_unstable"] - row["_n_unstable"]) != 1


def _step(problem, settings, state, p, t, x_pred, natural, landing, branch):
    """One corrector from the prediction ``x_pred``; (state, p, residual, iterations) or None."""
    from .solvers.system import transport

    p_new = float(x_pred[-1])
    if natural:
        pred = state.copy()
        if settings["predictor"] != "last" and not transport(
                problem.system(p), state, _free_part(problem, p, state, x_pred[:-1]), pred):
            return None
        if settings["predictor"] == "tangent":
            # a tangent that runs into a contact: shorten the predicted displacement (the parameter step stays)
            dx = x_pred[:-1] - state.q
            for _ in range(PREDICTOR_HALVINGS):
                if problem.admissible(p_new, pred):
                    break
                dx *= 0.5
                if not transport(problem.system(p), state, _free_part(problem, p, state, state.q + dx), pred):
                    return None
        if not problem.admissible(p_new, pred):
            pred = state.copy()        # a secant extrapolated into a contact: start from the last point
        if settings["perturb"] is not None:
            perturbed = settings["perturb"](p_new, pred.copy())
            if perturbed is not None and problem.admissible(p_new, perturbed):
                pred = perturbed
        options = dataclasses.replace(settings["options"], tight_bend="warn")
        scene = problem.scene(p_new)
        result = settings["solve"](scene, state=pred, options=options, tol=settings["tol"], stability=False)
        if not result.converged:
            return None
        if settings.get("leave_unstable"):
            # an unstable equilibrium (a root finder finds saddles too): kicked along its lowest mode and solved
            # again, so that the grid follows the branch that mode leads to
            first = result
            # (the same scene: a solve hook sees one scene per point, solved again from each kick)
            result, kicks = leave_unstable(scene, result, settings["leave_unstable"], solve=settings["solve"],
                                           options=options, tol=settings["tol"])
            if kicks:
                result.iterations += first.iterations     # (every solve of the point counts)
        if settings["predictor"] == "tangent":
            problem.stiffness_from(result)
        return problem.prepared(p_new, result.state), p_new, result.residual, result.iterations
    pred = state.copy()
    if not transport(problem.system(p), state, _free_part(problem, p, state, x_pred[:-1]), pred):
        return None
    pred = problem.prepared(p_new, pred)
    pred.lam[:] = state.lam
    return problem.correct(pred, p_new, t, x_pred, settings["max_newton"], fixed_p=landing)


def _der_solve(scene, **kwargs):
    from .solvers import solve
    from .solvers.system import raise_if_interrupted

    return raise_if_interrupted(solve(scene, raise_on_failure=False, **kwargs))   # Ctrl-C ends the continuation


def _tangent_of(problem, new_state, new_p, state, p, t, natural, predictor="secant"):
    if not natural or predictor == "tangent":
        t_new = problem.tangent(new_p, new_state, t)
        if t_new is not None or not natural:
            return t_new
    # natural parameter: the secant
    d = np.append(new_state.q - state.q, new_p - p)
    n = problem.norm(d)
    return d / n if n > 0 else None


def _detect(problem, settings, branch, a, b, state_a, p_a, t_a, ds, target=None):
    """Locate a fold (dp/ds changes sign) or a change of stability between consecutive points a and b (or, with
    ``target`` = (summary name, value), where that summary reaches the value)."""
    parameter = settings["parameter"]
    if target is not None:
        fold, kind, key, offset = False, "target", target[0], target[1]
    else:
        fold = a["dp_ds"] * b["dp_ds"] < 0
        stab = settings["stability"] and a["stable"] != b["stable"]
        if not (fold or stab):
            return
        kind = "fold" if fold else ("hopf" if (b["_crossing_complex"] or a["_crossing_complex"]) else "bifurcation")
        key, offset = ("dp_ds" if fold else "min_eigenvalue"), 0.0
    x_a = np.append(state_a.q, p_a)
    s_b = problem.norm(np.append(branch.states[-1].q, b[parameter]) - x_a)   # chord length of the step
    # Illinois (regula falsi) on the step length sigma in (0, s_b), from point a along its tangent
    s0, g0, q0 = 0.0, a[key] - offset, a[parameter]
    s1, g1, q1 = s_b, b[key] - offset, b[parameter]
    best = None
    width = abs(q1 - q0)
    scale = max(abs(b[parameter]), problem.p_scale)
    for _ in range(40):
        sigma = (s0 * g1 - s1 * g0) / (g1 - g0) if g1 != g0 else 0.5 * (s0 + s1)
        if not (min(s0, s1) < sigma < max(s0, s1)):
            sigma = 0.5 * (s0 + s1)
        out = problem.correct(_predicted(problem, state_a, p_a, t_a, sigma), p_a + sigma * t_a[-1], t_a,
                              x_a + sigma * t_a, settings["max_newton"])
        if out is None:
            break
        st, pp, res, its = out
        tt = problem.tangent(pp, st, t_a)
        if tt is None:
            break
        row = _point(problem, settings, st, pp, a["s"] + sigma, tt[-1], res, its)
        g = row[key] - offset
        if best is None or abs(g) < abs(best[0][key] - offset):
            best = (row, st, tt)
        if g * g1 < 0:
            s0, g0, q0 = s1, g1, q1
        else:
            g0 *= 0.5
        s1, g1, q1 = sigma, g, pp
        width = abs(q1 - q0)
        if g == 0 or (fold and abs(g) <= settings["locate_tol"]) or \
                (target is not None and abs(g) <= settings["locate_tol"] * max(abs(offset), 1.0)) or \
                (target is None and not fold and width <= settings["locate_tol"] * scale):
            break
    if best is None:
        row, st, tt = b, branch.states[-1], None
        note = "not refined (the corrector failed); the point after the change is reported"
    else:
        row, st, tt = best
        note = ""
    sp = {"kind": kind, parameter: row[parameter], "index": len(branch.points) - 1, "s": row["s"]}
    for k, v in row.items():
        if k not in sp and not k.startswith("_") and k not in ("newton_iterations",):
            sp[k] = v
    sp["located_to"] = (abs(row[key] - offset) if target is not None else width if fold is False
                        else abs(row["dp_ds"]))
    sp["located_by"] = (f"secant on {key} - {offset:.8g} (located_to: |{key} - {offset:.8g}| there)"
                        if target is not None else "secant on dp/ds (located_to: |dp/ds| there)" if fold else
                        "secant on the lowest eigenvalue (located_to: bracket width in the parameter)")
    if note:
        sp["note"] = note
    sp["state"] = st.copy()
    sp["tangent"] = tt if tt is not None else np.append(np.zeros(problem.n), 1.0)
    branch.special.append(sp)


def _predicted(problem, state, p, t, sigma):
    from .solvers.system import transport

    pred = state.copy()
    transport(problem.system(p), state, _free_part(problem, p, state, state.q + sigma * t[:-1]), pred)
    pred = problem.prepared(p + sigma * t[-1], pred)
    pred.lam[:] = state.lam
    return pred


def _free_part(problem, p, state, q):
    """``q`` with the held DOFs put back to ``state``'s (scene_of's targets move them when the predicted state is
    prepared: see Problem.correct)."""
    held, _ = held_dofs(problem.system(p))
    q = q.copy()
    q[held] = state.q[held]
    return q


def _jsonable(value):
    """JSON-ready copy of ``value`` (the scenario contract's conversion, der.cli)."""
    from .cli import _jsonable as jsonable

    return jsonable(value)


__all__ = ["continuation", "Branch", "critical_eigenvector", "unstable_mode", "leave_unstable", "gauge_modes",
           "condensed_triplets", "METHODS", "KINDS", "PREDICTORS"]
