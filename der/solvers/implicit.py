"""Implicit damped dynamics: backward Euler on viscous (overdamped) dynamics, one Newton step per pseudo-time
step, with a pseudo-time step that grows as the iteration succeeds (pseudo-transient continuation) and a
line search. Near equilibrium dt -> infinity and it is Newton's method, converging quadratically.

Each step solves, on the banded force Jacobian K (energy Hessian + frame-transport term + load stiffness),

    (D / dt + K) delta = R,     R = f_ext - dE/dq,

with D = diag(|K|) (a dimensionless pseudo-time: the damping of every DOF scaled to its stiffness), then
backtracks along delta until the work-corrected energy ``E(q + a delta) - a f_ext(q) . delta`` decreases
(Armijo). It first tries Newton's method itself (``newton_first``: dt at its cap) and keeps it while its steps
lower the energy; where they do not (an indefinite stiffness, a snap), it falls back to dt = ``dt0`` and lets dt
grow by ``dt_growth`` after every full step and shrink after a backtrack, like a trust region: steps that would
climb in energy (towards a saddle, through a snap) are damped. An inextensible rod's tensions are augmented-Lagrangian
multipliers, updated when the inner residual is small against the force the remaining elongation stands for.

Convergence: residual <= tol (and |strain| <= strain_tol). Double precision sets a floor under the residual
(``residual_floor``: a bound on the force change from rounding every coordinate); a solve whose residual stops
falling below that floor has converged as far as the arithmetic allows: status "converged_at_floor" (unless the
bound is 1 or more, when it certifies nothing). "Stops falling" means: no halving of the residual, and no new
low of the energy minus the load work by more than the round-off forces can do along the step actually taken.
"""
import time

import numpy as np
from numba import njit

from ..geometry import add_compensated
from ..linalg import (
    BandLDLT, add_diagonal, band_resolve, band_solve, band_to_coo, condense_band, constrain_band, dot, dot_abs,
    expand_step, zero_band,
)
from .system import (
    FLOOR_FACTOR, INTERRUPTS, condense_forces, constrain_system, constraint_residual, energy_terms, evaluate_forces,
    evaluate_system, expand, final_result, floor_forces, floor_verdict, is_interrupt, load_scales, max_strain,
    multiplier_update, residual_floor, residual_norm, residual_vector, state_edges, transport,
)

STALL_ITERATIONS = 6
# contact: below this residual, after a full Newton step, the barrier Hessian is used unprojected
EXACT_CONTACT_BELOW = 1e-4
# contact: the Newton matrix reordered by reverse Cuthill-McKee and factorised as a band (der/contact/reorder.py)
# while its bandwidth kl + ku stays at most this (measured: LAPACK's banded LU beats splu up to about 2 x 60)
BANDED_CONTACT = True
BANDED_CONTACT_MAX_WIDTH = 120
FLOOR_STALL_ITERATIONS = 2      # enough once the residual is down at the round-off floor
# pseudo-time step reductions (x0.1 each) before a step is declared impossible: enough to go from Newton's
# method (dt up to 1e30) down to a step that only damps (dt ~ 1e-10); 12 near the round-off floor
MAX_SHRINKS = 40
# the band path factorises the Jacobian in place (False: copy it before each attempt, as the contact path does;
# kept for the test that both end bitwise the same)
IN_PLACE = True


def second_order_correction(system, state, delta, resolve):
    """The correction c of a Newton step ``delta`` for the chord error of its straight line: K c = -J^T (k g2),
    g2 the elongation the step adds to each edge beyond its linearisation (``stretch.chord_excess_forces``),
    solved by ``resolve`` (generalized forces in q -> step in q) with the factors of the matrix that gave
    ``delta`` (no new factorisation). Along q + a delta + a^2 c the edges keep their lengths to third order in a
    where the straight line stretches them at second order. None if there is nothing to correct or no factors
    to reuse."""
    from ..energies.stretch import chord_excess_forces

    if resolve is None:
        return None
    rhs = np.empty(system.n_dof)
    worst = chord_excess_forces(state_edges(system, state), system.rod.edge_nodes, delta, system.plan.k_stretch,
                                rhs)
    if not worst > 0.0:
        return None
    c = resolve(rhs)
    if c is None or not np.all(np.isfinite(c)):
        return None
    return c


def _band_resolve_q(system, rhs):
    """K^-1 rhs with the factors the last band solve of the node-coordinate Newton matrix left (``band_resolve``):
    ``rhs`` generalized forces in q, condensed to the free variables here; the step expanded to q."""
    condense_forces(system, rhs)
    c = band_resolve(system.ab, system.kl, system.ku, system.perm, rhs, getattr(system, "ldlt", None))
    return None if c is None else expand(system, c)


@njit(cache=True)
def _cumulative_edges(z, n_nodes, hi, lo):
    """(hi, lo) <- q = T z as compensated pairs: for each node slot c the positions x_0 + e_0 + ... + e_{c-1} summed
    with TwoSum (the running error carried and renormalised), so that hi + lo is the exact prefix sum to about eps^2;
    the theta slots are copied (lo 0)."""
    for i in range(z.shape[0]):
        hi[i] = z[i]
        lo[i] = 0.0
    for a in range(3):
        s = 0.0
        c = 0.0
        for k in range(n_nodes):
            x = z[4 * k + a]
            t = s + x
            bb = t - s
            c += (s - (t - bb)) + (x - bb)
            h = t + c
            c = c - (h - t)
            s = h
            hi[4 * k + a] = s
            lo[4 * k + a] = c


class EdgeNewton:
    """The Newton systems of an open rod held at its start solved in edge coordinates
    (``SolverOptions.edge_coordinates``): z holds x_0 and the edge vectors e_c = x_c - x_{c-1}, q = T z
    (``stability._EdgeCoordinates``, which reads K_e = T^T K T off the assembled node band without cancellation).
    In node coordinates the Newton matrix of a fine inextensible rod has entries c A1 / h^3 (the axial penalty)
    against a smooth bending mode's A1 h / L^4: a condition number ~ (L / h)^4, 10^20 at 10^5 edges, beyond
    double precision, where LAPACK's pivoted solve returned directions with a relative residual of 0.9 and once
    not a descent direction (docs/scaling.md); in edge coordinates the penalty acts on each edge alone and the
    condition number is ~ (L / h)^2. The pseudo-time damping is diag(|K_e|) in these coordinates."""

    def __init__(self, system, state):
        from .stability import EDGE_BAND, _EdgeCoordinates

        self.ez = _EdgeCoordinates(system, state)
        self.kb = EDGE_BAND
        self.ldlt = BandLDLT(system.n_dof, EDGE_BAND)
        self.abz = None
        self.checked = None      # whether K_e reproduces K (translation invariance), checked on the first band
        self.step_lo = None      # the low part of the last step (``to_q``)

    @staticmethod
    def eligible(system):
        from .stability import _edge_eligible

        return _edge_eligible(system) and system.links.tri_dep.size == 0

    def band(self, system):
        """K_e read off the assembled band ``system.ab`` into this solver's one band array (reused)."""
        from .stability import _edge_band_fill

        if self.abz is None:
            self.abz = np.zeros((3 * self.kb + 1, system.n_dof), order="F")
        else:
            zero_band(self.abz)
        _edge_band_fill(system.ab, system.kl, system.ku, self.ez.N, self.abz, self.kb)
        return self.abz

    def usable(self, system):
        """Whether K_e (from the band at the state, assembled and unfactorised) reproduces K: checked once."""
        from .stability import EDGE_CHECK_TOL

        if self.checked is None:
            abz = self.band(system)
            self.checked = bool(self.ez.check_band(system.ab, system.kl, system.ku, abz) <= EDGE_CHECK_TOL)
        return self.checked

    def solve(self, system, R, dt):
        """(delta in q, info): (K_e + D_e / dt) z = T^T R on the free z, D_e = diag(|K_e|), delta = T z."""
        ez, kb = self.ez, self.kb
        abz = self.band(system)
        diag = np.abs(abz[2 * kb, :])
        diag[diag == 0] = 1.0
        add_diagonal(abz, kb, kb, ez.perm, diag, 1.0 / dt)
        if ez.tri_dep.size:
            condense_band(abz, kb, kb, ez.perm, ez.tri_dep, ez.tri_master, ez.tri_coef)
        constrain_band(abz, kb, kb, ez.perm, ez.fixed, 1.0)
        z, info = band_solve(abz, kb, kb, ez.perm, ez.condense_full(ez.transpose_to_z(R)), ldlt=self.ldlt)
        return self.to_q(z), info

    def to_q(self, z):
        """The step in q of the edge-coordinate solution z (links applied): cumulative sums of the edges, as a
        compensated pair -- returned the high part, ``self.step_lo`` the low part (the edges of the step, its
        differences, then come back to their own rounding, not to eps |step|: issue 17, docs/scaling.md)."""
        ez = self.ez
        if ez.tri_dep.size:
            expand_step(z, ez.tri_dep, ez.tri_master, ez.tri_coef)
        hi = np.empty_like(z)
        self.step_lo = np.empty_like(z)
        _cumulative_edges(z, ez.N, hi, self.step_lo)
        return hi

    def resolve(self, rhs):
        """K^-1 rhs (generalized forces in q -> step in q) with the factors of the last ``solve``."""
        ez = self.ez
        z = band_resolve(self.abz, self.kb, self.kb, ez.perm, ez.condense_full(ez.transpose_to_z(rhs)), self.ldlt)
        return None if z is None else self.to_q(z)


def shrink(dt, options):
    """The next pseudo-time step after a failed one: a tenth, or, from Newton's method (dt at its cap), back to
    the cautious start ``dt0``."""
    return options.dt0 if dt >= options.dt_max else dt * 0.1


def solve_implicit(system, state, options, progress=None, recorder=None):
    """Relax ``state`` (a prepared working copy, modified in place) to equilibrium. Returns a SolveResult.

    With ``options.newton_first`` the first step is Newton's; if that path stalls above the round-off floor
    (Newton steps from far away can land where round-off hides every descent direction of the soft modes)
    the solve restarts once from the initial state with the cautious pseudo-time start, within what is left
    of the iteration and time budgets."""
    if not options.newton_first:
        return _relax(system, state, options, options.dt0, progress, recorder)
    start = state.copy()
    t_start = time.perf_counter()
    first = _relax(system, state, options, options.dt_max, progress, recorder, 0, t_start)
    if first.status != "stalled":
        return first
    state.copy_from(start)
    second = _relax(system, state, options, options.dt0, progress, recorder, first.iterations, t_start)
    second.history = first.history + second.history
    second.timings = {k: first.timings.get(k, 0.0) + v for k, v in second.timings.items()}
    second.message += (f" (after Newton's method from the start stalled at residual {first.residual:.2e} in "
                       f"{first.iterations} iterations and the solve restarted with dt0)")
    return second


def _relax(system, state, options, dt, progress=None, recorder=None, it=0, t_start=None):
    """The pseudo-transient continuation loop from the pseudo-time step ``dt``; iterations are counted from
    ``it`` and the time budget from ``t_start`` (so that a restart shares both with the first attempt)."""
    rod = system.rod
    kl, ku, perm = system.kl, system.ku, system.perm
    t_start = time.perf_counter() if t_start is None else t_start
    trial = state.copy()
    last_good = state.copy()
    strain_tol = options.effective_strain_tol
    history = []
    status, message = "max_iterations", f"no convergence within {options.max_iterations} iterations"
    residual = floor = np.inf
    strain = 0.0
    best, since_best = np.inf, 0
    last_update = None
    just_updated = False
    descent = total_descent = noise = 0.0
    potential = potential_best = 0.0     # E - work of the loads, from the start of this loop
    timings = {"assembly": 0.0, "factorisation": 0.0, "line_search": 0.0}   # seconds of wall_time by phase
    # band path: the Jacobian is factorised in place in system.ab (no copy of the band per iteration; a retried
    # step assembles it again, bitwise the same). With contact terms the band is copied as before: their
    # evaluation is not repeated, and their sparse path does not factorise the band (issue 17)
    ab_K = work = None
    n_dof = system.ab.shape[1]
    fext = np.empty(n_dof)          # the loads at ``state`` (the line search's evaluations overwrite system.fext)
    q_trial = np.empty(n_dof)
    step = np.empty(n_dof)
    # the second-order correction of a refused full step (SolverOptions.second_order_correction): band path only
    soc = (options.second_order_correction and not system.terms and system.parts is None
           and bool(system.plan.has_stretch))
    # the Newton systems in edge coordinates (SolverOptions.edge_coordinates): open rods held at their start
    edge = EdgeNewton(system, state) if options.edge_coordinates and EdgeNewton.eligible(system) else None
    # contact: exact (unprojected) barrier Hessian in Newton's end game: below a residual the terms set (a smooth
    # barrier, der/contact/sampled.py, sets infinity: exact from the start, the projected one only as a fallback)
    exact_below = max([getattr(t, "exact_hessian_below", EXACT_CONTACT_BELOW) for t in system.terms],
                      default=EXACT_CONTACT_BELOW)
    exact_contact = exact_below == np.inf
    # band path: the forces first (order 1: the same pass and sums as the assembly, bitwise the same residual and
    # energy), the band only when it is used -- a step, the floor's bound or verdict. A converged check and an
    # inextensible rod's multiplier update then assemble nothing (issue 17). With contact terms as before.
    lazy_band = IN_PLACE and not system.terms
    band_at_state = False
    # the load scale's edge forces and vertex moments, computed by that same order-1 pass (one rod, all terms)
    pass_forces = None
    if lazy_band and system.parts is None:
        pass_forces = (np.empty((rod.n_edges, 3)), np.empty(rod.n_vertices))

    def assemble():
        """The band at ``state`` (``system.ab``), unless it is already there and unfactorised."""
        nonlocal band_at_state
        if not band_at_state:
            t0 = time.perf_counter()
            evaluate_system(system, state, 2)
            timings["assembly"] += time.perf_counter() - t0
            band_at_state = True

    try:
        while True:
            for t in system.terms:
                t.project = not exact_contact
            t_phase = time.perf_counter()
            forces = None
            if lazy_band:
                energy, forces = evaluate_forces(system, state, pass_forces)
            else:
                energy = evaluate_system(system, state, 2)
            band_at_state = not lazy_band
            timings["assembly"] += time.perf_counter() - t_phase
            if system.terms and any([t.after_step(state) for t in system.terms]):
                # contact: the adaptive barrier stiffness changed (docs/contact.md section 6); a new landscape
                energy = evaluate_system(system, state, 2)
                best, since_best, potential_best = np.inf, 0, potential
            R = residual_vector(system)
            scales = load_scales(system, state, forces)
            residual = residual_norm(system, R, scales)
            strain = max_strain(system, state) if rod.inextensible else 0.0
            if not (np.isfinite(energy) and np.isfinite(residual) and np.isfinite(scales).all()):
                # (an infinite force scale would make every residual 0: never a verdict)
                state.copy_from(last_good)
                status, message = "nonfinite", (f"non-finite energy, force or force scale at iteration {it}; last "
                                                "finite state kept")
                break
            last_good.copy_from(state)
            history.append(residual)
            if recorder is not None and it % options.record_every == 0:
                recorder.log_step(it, state, residual, energy_terms(system, state))
            if progress is not None:
                progress.update(it, residual, f"dt={dt:.2e}")
            strain_ok = strain <= strain_tol
            if residual <= options.tol and strain_ok:
                status, message = "converged", f"residual {residual:.2e} <= tol {options.tol:.1e}"
                break
            # progress: the residual halves, or the energy (minus the load work) still falls to a new low
            # (leaving a saddle can raise the residual) by more than the round-off forces could account for along
            # the step (floor forces . |step|). Judged against the energy alone, descents of 1e-24 in an energy of
            # 1e-18 -- a state rounding back and forth between two neighbours -- counted as progress for ever.
            if residual < 0.5 * best or (
                    potential < potential_best - max(1e-9 * max(abs(energy), total_descent), noise)):
                best, since_best = min(best, residual), 0
                potential_best = min(potential_best, potential)
            else:
                since_best += 1
            if strain_ok and since_best >= FLOOR_STALL_ITERATIONS:
                assemble()      # the floor bound reads the band
            if strain_ok and (since_best >= STALL_ITERATIONS or (
                    since_best >= FLOOR_STALL_ITERATIONS
                    and residual <= FLOOR_FACTOR * residual_floor(system, state, scales))):
                status, floor, message = floor_verdict(system, state, scales, residual, options.tol,
                                                       f"no progress in {since_best} Newton steps")
                break
            if rod.inextensible and not strain_ok and not just_updated:
                if residual <= max(options.tol, 0.1 * constraint_residual(system, state, scales)):
                    # near equilibrium a strain that will not fall calls for a larger penalty (see
                    # multiplier_update); during a transient it only means the rod is still moving
                    last_update = multiplier_update(system, state,
                                                           last_update if residual < 1e-4 else None)
                    best, since_best = np.inf, 0
                    just_updated = True   # let Newton answer before the next update
                    continue
            just_updated = False
            if it >= options.max_iterations:
                break
            if time.perf_counter() - t_start > options.time_budget:
                status, message = "time_budget", f"time budget of {options.time_budget:g} s used up"
                break
            it += 1
            assemble()
            in_place = IN_PLACE and not system.terms
            if not in_place:
                if ab_K is None:
                    ab_K, work = np.empty_like(system.ab), np.empty_like(system.ab)
                ab_K[:] = system.ab
            diag = np.abs(system.ab[kl + ku, :][perm])
            coo = system.contact_coo            # off-band contact Hessian triplets (empty: banded path)
            if coo:
                cd = _coo_diagonal(coo, diag.size)
                # (a smooth term's exact Hessian may have negative diagonal entries: no anti-damping)
                diag += np.maximum(cd, 0.0) if exact_below == np.inf else cd
            diag[diag == 0] = 1.0
            fext[:] = system.fext
            round_off = floor_forces(system, state)
            accepted = False
            for _attempt in range(MAX_SHRINKS):
                if in_place and _attempt > 0:
                    # the LU factors of the last attempt overwrote the Jacobian: assemble it again
                    assemble()
                if _attempt == 12 and residual < 100.0 * residual_floor(system, state, scales):
                    break   # near the round-off floor a step that lowers the energy may not exist
                t_phase = time.perf_counter()
                if edge is not None and edge.usable(system):
                    # edge coordinates: K_e read off the assembled band, which stays unfactorised (a retried
                    # step needs no new assembly)
                    delta, info = edge.solve(system, R, dt)
                    step_lo = edge.step_lo
                    system.linear_solves["edge"] = system.linear_solves.get("edge", 0) + 1
                    resolve = edge.resolve
                else:
                    if in_place:
                        work = system.ab
                        band_at_state = False       # factorised in place just below
                    else:
                        work[:] = ab_K
                    add_diagonal(work, kl, ku, perm, diag, 1.0 / dt)
                    constrain_system(system, work, 1.0)     # T^T (K + D/dt) T: the end supports' free variables
                    if coo:
                        delta, info = _contact_solve(system, work, coo, R)
                    else:
                        delta, info = band_solve(work, kl, ku, perm, R, ldlt=getattr(system, "ldlt", None))
                        system.linear_solves["band"] += 1
                    expand(system, delta)
                    step_lo = None
                    resolve = (lambda rhs: _band_resolve_q(system, rhs)) if in_place and not coo else None
                timings["factorisation"] += time.perf_counter() - t_phase
                with np.errstate(over="ignore", invalid="ignore"):   # a huge step is refused just below
                    slope = dot(R, delta)
                if info != 0 or not np.all(np.isfinite(delta)) or slope <= 0:
                    if exact_contact:
                        break         # the exact contact Hessian is indefinite here: back to the projected one
                    dt = shrink(dt, options)
                    continue
                a = 1.0
                if system.terms:
                    # contact: start at the CCD-safe fraction, so that no strand passes through another (or
                    # through an obstacle) anywhere within the step
                    a = min([1.0] + [t.max_step(state, delta) for t in system.terms])
                    if not a > 0.0:
                        dt = shrink(dt, options)
                        continue
                a_start = a
                t_phase = time.perf_counter()
                arc = None          # the second-order correction c: the search then runs along q + a delta + a^2 c
                # the edge path's step is a compensated pair (delta + step_lo: the cumulative sums of the edges kept
                # to their own rounding); the node path's is delta alone
                compensated = getattr(state, "q_lo", None) is not None and getattr(trial, "q_lo", None) is not None
                ls = 0
                while ls < options.line_search_steps:
                    if arc is None and step_lo is None:
                        if compensated:
                            add_compensated(state.q, state.q_lo, a, delta, trial.q, trial.q_lo)
                            q_new = trial.q
                        else:       # a state without low parts (prepared elsewhere): plain coordinates
                            np.multiply(delta, a, out=q_trial)
                            q_trial += state.q
                            q_new = q_trial
                        work_done = a * dot(fext, delta)
                    else:
                        # q + a (delta + step_lo) + a^2 c, each part added in turn (a is 1 or a power of 2 from
                        # the halvings: a delta is exact, and the edges see the step to their own rounding)
                        if compensated:
                            add_compensated(state.q, state.q_lo, a, delta, trial.q, trial.q_lo)
                            if step_lo is not None:
                                add_compensated(trial.q, trial.q_lo, a, step_lo, trial.q, trial.q_lo)
                            if arc is not None:
                                add_compensated(trial.q, trial.q_lo, a * a, arc, trial.q, trial.q_lo)
                            q_new = trial.q
                        else:
                            np.multiply(delta, a, out=q_trial)
                            q_trial += state.q
                            if arc is not None:
                                q_trial += (a * a) * arc
                            q_new = q_trial
                        work_done = a * dot(fext, delta) + (a * a * dot(fext, arc) if arc is not None else 0.0)
                    if transport(system, state, q_new, trial):
                        e_trial = evaluate_system(system, trial, 0)
                        merit = e_trial - energy - work_done
                        slack = 1e-13 * (abs(energy) + abs(e_trial)) + 1e-300
                        if np.isfinite(e_trial) and merit <= -options.armijo * a * slope + slack:
                            accepted = True
                            break
                    if arc is None and ls == 0 and soc:
                        # the full step was refused: correct it for the chord error of the edges it turns and
                        # try the full step again along the arc (one solve with the same factors)
                        arc = second_order_correction(system, state, delta, resolve)
                        if arc is not None:
                            system.linear_solves["second_order"] = system.linear_solves.get("second_order", 0) + 1
                            continue
                    a *= 0.5
                    ls += 1
                timings["line_search"] += time.perf_counter() - t_phase
                if accepted or exact_contact:
                    break
                dt = shrink(dt, options)
            if not accepted and exact_contact:
                exact_contact = False
                it -= 1
                continue
            if not accepted:
                evaluate_system(system, state, 2)
                status, floor, message = floor_verdict(
                    system, state, scales, residual, options.tol,
                    "no pseudo-time step lowers the energy (round-off, or a singular linearised system)")
                if not strain_ok:
                    status = "stalled"
                break
            # the progress measure uses the step actually taken (q + a delta rounded), not a delta: at the floor a
            # step can round back and forth between two states and credit the load work a fext.delta each time
            np.subtract(trial.q, state.q, out=step)
            change = e_trial - energy - dot(fext, step)
            potential += change
            descent = max(-change, 0.0)
            noise = dot_abs(round_off, step)
            state.copy_from(trial)
            total_descent += descent
            if system.contact_coo and a == 1.0 and dt >= options.dt_max and residual < exact_below:
                exact_contact = True
            # trust the pseudo-time step more after a full step, less after a backtrack
            # (a step cut by the CCD bound alone, a == a_start < 1, is a full step of the linearised model)
            dt = min(options.dt_max, dt * options.dt_growth) if a == a_start else max(dt * a / a_start, 1e-12)
    except INTERRUPTS as exc:
        if not is_interrupt(exc):
            raise
        state.copy_from(last_good)
        status, message = "interrupted", "interrupted by the user; last state kept"
    except ArithmeticError as exc:
        # a numerical failure inside a kernel (division by zero, overflow) ends the solve like a NaN would
        state.copy_from(last_good)
        status, message = "nonfinite", (f"numerical failure at iteration {it} ({type(exc).__name__}: {exc}); last "
                                        "finite state kept")
    return final_result(system, state, status, residual=float(residual), iterations=it,
                        wall_time=time.perf_counter() - t_start, message=message, solver="implicit", strain=strain,
                        history=history, dt=dt, residual_floor=float(floor), timings=timings)


# ---- contact (issue 14): the sparse path, taken only while a contact term reports off-band triplets ----

def _coo_diagonal(coo, n):
    """Diagonal of the contact Hessian (PSD: non-negative), for the pseudo-time damping D = diag(|K|)."""
    out = np.zeros(n)
    for r, c, v in coo:
        on = r == c
        out += np.bincount(r[on], weights=v[on], minlength=n)
    return out


def _contact_solve(system, work, coo, R):
    """Solve (K + D/dt + H_contact) delta = R: the constrained band (fixed DOFs already identity rows and
    columns, the pseudo-time diagonal included) plus the contact triplets off the fixed DOFs. The DOF blocks are
    reordered by reverse Cuthill-McKee and the matrix factorised as a band by LAPACK (der/contact/reorder.py) while
    the reordered bandwidth is at most BANDED_CONTACT_MAX_WIDTH; otherwise as one CSC matrix by scipy's splu
    (SuperLU, COLAMD ordering). Returns (delta, info) like band_solve."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

    n = work.shape[1]
    fixed = system.fixed
    rows, cols, vals = [], [], []
    for r, c, v in coo:
        keep = ~(fixed[r] | fixed[c])
        rows.append(r[keep])
        cols.append(c[keep])
        vals.append(v[keep])
    rows, cols, vals = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    if BANDED_CONTACT:
        from ..contact.reorder import banded_solve, bandwidths, block_order

        # the contact pattern changes little from one Newton step to the next: keep the last ordering while the
        # pattern's bandwidth in it stays within 1.25x of what RCM gave when it was computed
        cached = getattr(system, "contact_order", None)
        newpos = None
        if cached is not None:
            newpos, width = cached
            kl2, ku2 = bandwidths(system.kl, system.ku, system.perm, rows, cols, newpos)
            if kl2 + ku2 > 1.25 * width:
                newpos = None
        if newpos is None:
            newpos, kl2, ku2 = block_order(work, system.kl, system.ku, system.perm, rows, cols)
            system.contact_order = (newpos, kl2 + ku2)
        if kl2 + ku2 <= BANDED_CONTACT_MAX_WIDTH:
            system.linear_solves["sparse"] += 1
            return banded_solve(work, system.kl, system.ku, system.perm, rows, cols, vals, R, newpos, kl2, ku2)
    rb, cb, vb = band_to_coo(work, system.kl, system.ku, system.perm)
    rows, cols, vals = np.concatenate([rb, rows]), np.concatenate([cb, cols]), np.concatenate([vb, vals])
    A = sp.csc_matrix((vals, (rows, cols)), shape=(n, n))
    system.linear_solves["sparse"] += 1
    try:
        lu = splu(A, permc_spec="COLAMD")
    except RuntimeError:          # exactly singular
        return np.zeros(n), 1
    return lu.solve(R), 0
