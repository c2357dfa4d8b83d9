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
from dataclasses import replace

import numpy as np

from ..geometry import add_compensated
from ..linalg import add_diagonal, band_diagonal_abs, band_resolve, band_solve, band_to_coo, dot, dot_difference
from .system import (
    FLOOR_FACTOR, INTERRUPTS, condense_forces, constrain_system, constraint_residual, energy_terms, evaluate_forces,
    evaluate_system, expand, final_result, floor_forces, floor_verdict, is_interrupt, load_scales, max_strain,
    multiplier_update, potential_round_off, residual_floor, residual_norm, residual_vector, state_edges, transport,
)

STALL_ITERATIONS = 6
# contact: below this residual, after a full Newton step, the barrier Hessian is used unprojected (the projected one
# as the fallback where the exact step fails: an indefinite matrix, no descent). Infinity: exact from the start,
# as the smooth barrier always had. Measured on the plectoneme (docs/contact.md section 9.5): the projection hides
# the sliding mode's small or negative curvature, and Newton with it converges linearly (a factor ~0.97-0.998 per
# step at residuals 1e-3 .. 1e-4: 200-1,600 iterations per quarter turn); at 1e-4 (= the default tol) the exact
# Hessian was never reached
EXACT_CONTACT_BELOW = np.inf
# contact: the Newton matrix reordered by reverse Cuthill-McKee and factorised as a band (der/contact/reorder.py)
# while its bandwidth kl + ku stays at most this (measured: LAPACK's banded LU beats splu up to about 2 x 60)
BANDED_CONTACT = True
BANDED_CONTACT_MAX_WIDTH = 120
# contact: the reordered band factorised by LAPACK's banded Cholesky (a quarter of dgbsv's flops; refined against
# the whole matrix, dgbsv where that is refused: der/contact/reorder.py); False: dgbsv always, as before
CONTACT_CHOLESKY = True
# contact: True solves the Newton matrix with the elastic band's symmetric part (K + K^T) / 2, dropping its skew part,
# the frame-transport term dE/dtheta_j / (2 |e_j|^2) [t_j]_x (geometry.add_transport_jacobian), so that the banded
# Cholesky is not refused on it. Measured and not kept (docs/contact.md section 9.6): that term is ~1e-8 of max|A|
# but not small against the plectoneme's soft modes (the smallest eigenvalue 2.9e-5, of max|A| 8e6), and without it
# the snap took 722-824 Newton iterations instead of 410-453 and the 6-turn slope moved 3-5 %
CONTACT_SYMMETRIC = False
FLOOR_STALL_ITERATIONS = 2      # enough once the residual is down at the round-off floor
# pseudo-time step reductions (x0.1 each) before a step is declared impossible: enough to go from Newton's
# method (dt up to 1e30) down to a step that only damps (dt ~ 1e-10); 12 near the round-off floor
MAX_SHRINKS = 40
# the band path factorises the Jacobian in place (False: copy it before each attempt, as the contact path does;
# kept for the test that both end bitwise the same)
IN_PLACE = True
# contact: a refused Newton step is corrected for its chord error (second_order_correction below, solved with the
# contact solve's factors) and searched along the arc q + a delta + a^2 c, each trial's arc proven free of passage
# by the terms' ``arc_step_safe`` (the straight step otherwise), whatever SolverOptions.second_order_correction
# says (that option is the no-contact path's, off by default). Measured on the plectoneme: docs/contact.md 9.5
CONTACT_SECOND_ORDER = True
# contact: that arc is tried at every fraction of the line search where it is proven free of passage (its deviation
# from the chord falls as a^2), the straight step where not; False: the straight step from the first fraction whose
# arc is not proven safe on (round 4's search). With CONTACT_ARC_FROM_CONTACT_START only in a solve that starts in
# contact: the snap of a straight rod into a plectoneme keeps round 4's search -- with the arc it landed the
# plectoneme lower on the rod, whose later steps then ran into the clamp (docs/contact.md section 9.6)
CONTACT_ARC_EVERY_FRACTION = True
CONTACT_ARC_FROM_CONTACT_START = True
# SolverOptions(edge_newton=None), the default: edge-coordinate Newton steps with the second-order correction for an
# inextensible rod the edge path applies to (edge_coordinates.edge_eligible) once the node-coordinate Newton matrix's
# condition c (L/h)^4 (penalty c A1/h^3 against a smooth bending mode's A1 h/L^4) exceeds this. Measured on ring
# torsion (docs/scaling.md, "Stop 27"): node-coordinate steps lose 2e-3 of their accuracy at c (L/h)^4 = 8e14
# (n = 3,000) and all of it at 1e17 (3x10^4), where the default path stalled and restarted; with both options it
# reaches the round-off floor in 6 iterations at 3x10^4 and 10^5
EDGE_NEWTON_CONDITION = 1e14
# a measurement hook (tools/ring_trace.py): None, or a callable TRACE(kind, **values) called once per iteration
# ("iteration": residual, strain, energy, dt), per accepted step ("step": fraction a, line-search halvings, arc
# used) and per multiplier update ("multipliers"). Off in every solve unless a tool sets it.
TRACE = None


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


def _edge_resolve_q(system, edge, rhs):
    """K^-1 rhs with the factors the last edge-coordinate Newton step left (``EdgeNewton.resolve``): ``rhs``
    generalized forces in q (full), the step in q with the node links applied as for the step itself."""
    c = edge.resolve(rhs)
    if c is None:
        return None
    c[system.fixed] = 0.0
    return expand(system, c)


def effective_options(system, options):
    """``options`` with ``edge_newton`` and ``second_order_correction`` decided where they are None (automatic):
    both on for an inextensible rod the edge path applies to whose node-coordinate Newton matrix has condition
    c (L/h)^4 above EDGE_NEWTON_CONDITION, off otherwise. Options set to True or False are kept."""
    if options.edge_newton is not None and options.second_order_correction is not None:
        return options
    auto = False
    rod = system.rod
    if system.parts is None and not system.terms and rod.inextensible and rod.n_edges > 0:
        from .edge_coordinates import edge_eligible

        l = np.asarray(rod.l_bar)
        condition = options.inextensible_penalty * (float(l.sum()) / float(l.min())) ** 4
        auto = condition > EDGE_NEWTON_CONDITION and edge_eligible(system)
    edge = auto if options.edge_newton is None else options.edge_newton
    soc = (auto and edge) if options.second_order_correction is None else options.second_order_correction
    return replace(options, edge_newton=edge, second_order_correction=soc)


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
    options = effective_options(system, options)
    # the start is kept only for the edge-coordinate fallback below (a state is 136 MB at 10^6 edges, issue 17)
    start = state.copy() if getattr(options, "edge_newton", False) else None
    t_start = time.perf_counter()
    result = _solve(system, state, options, progress, recorder, 0, t_start)
    if start is not None and result.status == "stalled" and result.linear_solves_edge:
        # edge coordinates stalled (their pseudo-time damping diag |K_e| differs from the node coordinates'; a
        # stiff inextensibility penalty far from equilibrium can leave them without progress): the node-coordinate
        # solve from the start, within what is left of the budgets
        state.copy_from(start)
        again = _solve(system, state, options, progress, recorder, result.iterations, t_start, edge=False)
        again.history = result.history + again.history
        again.timings = {k: result.timings.get(k, 0.0) + v for k, v in again.timings.items()}
        again.message += (f" (after the edge-coordinate Newton steps stalled at residual {result.residual:.2e} in "
                          f"{result.iterations} iterations and the solve restarted in node coordinates)")
        return again
    return result


def _solve(system, state, options, progress, recorder, it, t_start, edge=True):
    """Newton's method first (``options.newton_first``), then once more from the start with dt0 if it stalls."""
    if not options.newton_first:
        return _relax(system, state, options, options.dt0, progress, recorder, it, t_start, edge)
    start = state.copy()
    first = _relax(system, state, options, options.dt_max, progress, recorder, it, t_start, edge)
    if first.status != "stalled":
        return first
    state.copy_from(start)
    second = _relax(system, state, options, options.dt0, progress, recorder, first.iterations, t_start, edge)
    second.history = first.history + second.history
    second.timings = {k: first.timings.get(k, 0.0) + v for k, v in second.timings.items()}
    second.linear_solves_edge += first.linear_solves_edge
    second.message += (f" (after Newton's method from the start stalled at residual {first.residual:.2e} in "
                       f"{first.iterations - it} iterations and the solve restarted with dt0)")
    return second


def _relax(system, state, options, dt, progress=None, recorder=None, it=0, t_start=None, edge_ok=True):
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
    best_scales = None          # the force and moment scales ``best`` was measured against
    potential_noise = None      # the rounding of the potential at its lowest (``potential_best``)
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
    q_trial = np.empty(n_dof)       # (only a state without low parts touches it)
    # work arrays reused by every iteration (issue 17: at 10^6 edges fresh n-sized arrays were page-faulted on
    # each use): the residual, the damping diagonal, the round-off forces (their rounding scale formed in place)
    R_work, diag_work, round_off_work = (np.empty(n_dof) for _ in range(3))
    # the second-order correction of a refused full step: without contact SolverOptions.second_order_correction
    # decides (band path); with contact terms CONTACT_SECOND_ORDER, on the contact solve's factors, when every term
    # can prove the curved path free of passage (der/terms/contact.py arc_step_safe)
    if system.terms:
        soc = CONTACT_SECOND_ORDER and all([getattr(t, "arc_ok", False) for t in system.terms])
    else:
        soc = options.second_order_correction
    soc = bool(soc) and system.parts is None and bool(system.plan.has_stretch)
    # contact: exact (unprojected) barrier Hessian in Newton's end game: below a residual the terms set (a smooth
    # barrier, der/contact/sampled.py, sets infinity: exact from the start, the projected one only as a fallback)
    exact_below = max([getattr(t, "exact_hessian_below", EXACT_CONTACT_BELOW) for t in system.terms],
                      default=EXACT_CONTACT_BELOW)
    exact_contact = exact_below == np.inf
    # the arc at every fraction (CONTACT_ARC_EVERY_FRACTION) in a solve that starts in contact; decided at its first
    # iteration (None until then)
    arc_every = None
    # band path: the forces first (order 1: the same pass and sums as the assembly, bitwise the same residual and
    # energy), the band only when it is used -- a step, the floor's bound or verdict. A converged check and an
    # inextensible rod's multiplier update then assemble nothing (issue 17). With contact terms as before.
    lazy_band = IN_PLACE and not system.terms
    # SolverOptions(edge_newton=True): Newton steps in edge coordinates for an open rod held at its start
    # (der.solvers.edge_coordinates); ``f_node`` keeps the node forces f_ext - dE/dq at ``state`` for them
    edge = None
    edge_steps = 0
    if edge_ok and getattr(options, "edge_newton", False) and not system.terms:
        from .edge_coordinates import EdgeNewton, edge_eligible

        if edge_eligible(system):
            edge = EdgeNewton(system, state)
            f_node = np.empty(n_dof)
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
                best, since_best, potential_best, potential_noise = np.inf, 0, potential, None
            if edge is not None:
                np.subtract(system.fext, system.grad, out=f_node)
            R = residual_vector(system, R_work)
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
            if TRACE is not None:
                TRACE("iteration", it=it, residual=residual, strain=strain, energy=energy, potential=potential,
                      dt=dt, constraint=constraint_residual(system, state, scales) if rod.inextensible else 0.0,
                      since_best=since_best)
            if recorder is not None and it % options.record_every == 0:
                recorder.log_step(it, state, residual, energy_terms(system, state))
            if progress is not None:
                progress.update(it, residual, f"dt={dt:.2e}")
            strain_ok = strain <= strain_tol
            if residual <= options.tol and strain_ok:
                status, message = "converged", f"residual {residual:.2e} <= tol {options.tol:.1e}"
                break
            # progress: the residual halves, or the energy (minus the load work) still falls to a new low
            # (leaving a saddle can raise the residual) by more than its own rounding can. Judged against the
            # energy alone, descents of 1e-24 in an energy of 1e-18 -- a state rounding back and forth between two
            # neighbours -- counted as progress for ever.
            # The residual halves against one measuring stick: the best one's scales (the force scale follows the
            # state; far from equilibrium the largest internal force is the out-of-balance one itself, and every
            # residual measured against its own state's scale was 1.0 while the forces fell 15-fold).
            # The potential's rounding: from the edge forces and moments at both ends (``potential_round_off``),
            # not the round-off forces times the step, a bound that sums eps |K| w |step| over every DOF with the
            # axial penalty's stiffness in |K|: 4e-5 against true descents of 1e-10 on a 10^5-edge cantilever,
            # whose Newton steps then "stalled" (docs/scaling.md). Several rods and contact terms (their energies
            # do not come with edge forces) keep that bound.
            on_stick = residual if best_scales is None else residual_norm(system, R, best_scales)
            rounding = potential_round_off(system, state, forces)
            if potential_noise is None:                 # the start of this loop is its first low
                potential_noise = rounding or 0.0
            if on_stick < 0.5 * best or potential < potential_best - max(
                    1e-9 * max(abs(energy), total_descent), noise if rounding is None else rounding + potential_noise):
                if on_stick < best:
                    best, best_scales = residual, scales
                since_best = 0
                if potential < potential_best:
                    potential_best, potential_noise = potential, rounding or 0.0
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
                    lam_before = state.lam.copy() if TRACE is not None else None
                    last_update = multiplier_update(system, state,
                                                           last_update if residual < 1e-4 else None)
                    if TRACE is not None:
                        TRACE("multipliers", it=it, dlam=float(np.abs(state.lam - lam_before).max()),
                              lam=float(np.abs(state.lam).max()), k=float(system.plan.k_stretch.max()),
                              g=float(np.abs(last_update).max()))
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
            diag = band_diagonal_abs(system.ab, kl, ku, perm, diag_work)
            coo = system.contact_coo            # off-band contact Hessian triplets (empty: banded path)
            if arc_every is None:
                arc_every = CONTACT_ARC_EVERY_FRACTION and (
                    not CONTACT_ARC_FROM_CONTACT_START or any([c[0].size > 0 for c in coo]))
            if coo:
                cd = _coo_diagonal(coo, diag.size)
                # (a smooth term's exact Hessian may have negative diagonal entries: no anti-damping)
                diag += np.maximum(cd, 0.0) if exact_below == np.inf else cd
            diag[diag == 0] = 1.0
            fext[:] = system.fext
            # the round-off forces, for the progress test's noise where the potential's own rounding is not known
            round_off = floor_forces(system, state, round_off_work) if rounding is None else None
            # edge coordinates: K_e read off the band at ``state`` once (the band is not factorised in place: every
            # attempt below reuses it)
            use_edge = edge is not None and edge.prepare(system.ab, kl, ku)
            accepted = False
            for _attempt in range(MAX_SHRINKS):
                if in_place and _attempt > 0:
                    # the LU factors of the last attempt overwrote the Jacobian: assemble it again
                    assemble()
                if _attempt == 12 and residual < 100.0 * residual_floor(system, state, scales):
                    break   # near the round-off floor a step that lowers the energy may not exist
                t_phase = time.perf_counter()
                if use_edge:
                    delta, info = edge.step(f_node, dt)
                    system.linear_solves["edge"] = system.linear_solves.get("edge", 0) + 1
                    edge_steps += 1
                    step_lo = resolve = None
                    if info == 0:
                        # the node links exactly (T dz satisfies them to round-off): held DOFs zero, dependents
                        # from their masters -- on both parts of the compensated step (delta, step_lo)
                        delta[system.fixed] = 0.0
                        expand(system, delta)
                        step_lo = edge.step_lo
                        step_lo[system.fixed] = 0.0
                        expand(system, step_lo)
                        resolve = lambda rhs: _edge_resolve_q(system, edge, rhs)    # noqa: E731
                else:
                    if in_place:
                        work = system.ab
                        band_at_state = False       # factorised in place just below
                    else:
                        work[:] = ab_K
                    add_diagonal(work, kl, ku, perm, diag, 1.0 / dt)
                    constrain_system(system, work, 1.0)     # T^T (K + D/dt) T: the end supports' free variables
                    if coo:
                        factors = {}       # the solve's factors, for the second-order correction
                        delta, info = _contact_solve(system, work, coo, R, factors)
                    else:
                        delta, info = band_solve(work, kl, ku, perm, R, ldlt=getattr(system, "ldlt", None))
                        system.linear_solves["band"] += 1
                    expand(system, delta)
                    step_lo = None
                    resolve = (lambda rhs: _band_resolve_q(system, rhs)) if in_place and not coo else None
                    if coo:
                        resolve = lambda rhs, f=factors: _contact_resolve_q(system, f, rhs)    # noqa: E731
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
                arc_tried = False
                correction = None       # the second-order correction, once computed
                unsafe_at = None        # the fraction at which its arc was last found not provably free of passage
                while ls < options.line_search_steps:
                    if correction is not None and arc is None and a != unsafe_at and arc_every:
                        # a shorter arc may be proven free of passage where a longer one was not (its deviation
                        # from the chord shrinks as a^2): each fraction tries the arc first, the straight step where
                        # the proof fails
                        arc = correction
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
                    if arc is not None and system.terms and not all(
                            [t.arc_step_safe(state, delta, arc, a) for t in system.terms]):
                        # this fraction's arc is not proven free of passage: the straight step from here on
                        # (a <= the CCD-safe fraction a_start); at ls = 0 the straight step at this a was refused
                        # already, so halve rather than evaluate it again
                        arc = None
                        unsafe_at = a
                        if ls == 0:
                            a *= 0.5
                            ls += 1
                        continue
                    if transport(system, state, q_new, trial):
                        e_trial = evaluate_system(system, trial, 0)
                        merit = e_trial - energy - work_done
                        slack = 1e-13 * (abs(energy) + abs(e_trial)) + 1e-300
                        if np.isfinite(e_trial) and merit <= -options.armijo * a * slope + slack:
                            accepted = True
                            break
                    if arc is None and ls == 0 and soc and not arc_tried:
                        # the full step was refused: correct it for the chord error of the edges it turns and
                        # try the full step again along the arc (one solve with the same factors)
                        arc = correction = second_order_correction(system, state, delta, resolve)
                        arc_tried = True
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
            # (dot products with the step trial.q - state.q formed on the fly: no n-sized step array, issue 17)
            change = e_trial - energy - dot_difference(fext, trial.q, state.q)
            potential += change
            descent = max(-change, 0.0)
            noise = 0.0 if round_off is None else dot_difference(round_off, trial.q, state.q, True)
            if TRACE is not None:
                TRACE("step", it=it, a=a, ls=ls, arc=arc is not None, attempts=_attempt, change=change, dt=dt)
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
    result = final_result(system, state, status, residual=float(residual), iterations=it,
                          wall_time=time.perf_counter() - t_start, message=message, solver="implicit", strain=strain,
                          history=history, dt=dt, residual_floor=float(floor), timings=timings,
                          hessian=options.stability)
    result.linear_solves_edge = edge_steps      # (this attempt's edge-coordinate steps: solve_implicit's fallback)
    return result


# ---- contact (issue 14): the sparse path, taken only while a contact term reports off-band triplets ----

def _coo_diagonal(coo, n):
    """Diagonal of the contact Hessian (PSD: non-negative), for the pseudo-time damping D = diag(|K|)."""
    out = np.zeros(n)
    for r, c, v in coo:
        on = r == c
        out += np.bincount(r[on], weights=v[on], minlength=n)
    return out


def _contact_resolve_q(system, factors, rhs):
    """K^-1 rhs with the factors the last contact solve left in ``factors`` (``_contact_solve``): ``rhs``
    generalized forces in q, condensed to the free variables; the step expanded to q. None without factors."""
    condense_forces(system, rhs)
    if factors.get("kind") == "splu":
        c = factors["factors"].solve(rhs)
    else:
        from ..contact.reorder import banded_resolve

        c = banded_resolve(factors, rhs)
    return None if c is None else expand(system, c)


def _contact_solve(system, work, coo, R, factors=None):
    """Solve (K + D/dt + H_contact) delta = R: the constrained band (fixed DOFs already identity rows and
    columns, the pseudo-time diagonal included) plus the contact triplets off the fixed DOFs. The DOF blocks are
    reordered by reverse Cuthill-McKee and the matrix factorised as a band by LAPACK (der/contact/reorder.py) while
    the reordered bandwidth is at most BANDED_CONTACT_MAX_WIDTH; otherwise as one CSC matrix by scipy's splu
    (SuperLU, COLAMD ordering). Returns (delta, info) like band_solve; with ``factors`` (a dict) the factorisation
    is left there for ``_contact_resolve_q``."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

    n = work.shape[1]
    if CONTACT_SYMMETRIC and system.kl == system.ku:
        from ..contact.reorder import symmetric_part

        symmetric_part(work, system.kl, system.ku)
    fixed = system.fixed
    rows, cols, vals = [], [], []
    for r, c, v in coo:
        keep = ~(fixed[r] | fixed[c])
        rows.append(r[keep])
        cols.append(c[keep])
        vals.append(v[keep])
    rows, cols, vals = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    if BANDED_CONTACT:
        from ..contact.reorder import BandCholesky, banded_solve, bandwidths, block_order

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
            chol = None
            if CONTACT_CHOLESKY:
                chol = getattr(system, "contact_cholesky", None)
                if chol is None:
                    chol = system.contact_cholesky = BandCholesky()
            return banded_solve(work, system.kl, system.ku, system.perm, rows, cols, vals, R, newpos, kl2, ku2, chol,
                                factors)
    rb, cb, vb = band_to_coo(work, system.kl, system.ku, system.perm)
    rows, cols, vals = np.concatenate([rb, rows]), np.concatenate([cb, cols]), np.concatenate([vb, vals])
    A = sp.csc_matrix((vals, (rows, cols)), shape=(n, n))
    system.linear_solves["sparse"] += 1
    try:
        lu = splu(A, permc_spec="COLAMD")
    except RuntimeError:          # exactly singular
        return np.zeros(n), 1
    if factors is not None:
        factors.update(kind="splu", factors=lu)
    return lu.solve(R), 0
