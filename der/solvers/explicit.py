"""Explicit damped dynamics (the reference solver): FIRE (Bitzek et al. 2006) with stiffness-scaled masses.

Semi-implicit (symplectic) Euler with the FIRE velocity mixing and restarts, mass-weighted so that node
translations and cross-section rotations mix in consistent units. The total energy is kinetic + elastic - the
work done by the loads (accumulated by the trapezoidal rule); under conservative loads it is a Lyapunov
function of the damped dynamics and the solver never lets it increase. The time step never exceeds the stable
limit ``2 / omega_max``, with ``omega_max^2`` bounded by Gershgorin's theorem on ``M^-1/2 |K| M^-1/2``
(recomputed as the rod deforms); the bound is also evaluated for each energy term alone, to report which
mode -- stretch, bend or twist -- is the stiffest. By default the step is capped at ``safety / omega_max``, half
the limit, where a step from rest lowers the energy of every mode. A step that would raise the total energy is rejected and
restarted from rest (for circulatory loads, which can feed energy in, only a large rise is: an unstable step).

The masses are fictitious by default (``SolverOptions.fire_mass = "stiffness"``, dynamic relaxation's mass
scaling): each DOF's mass is its Gershgorin row sum of |K| (contact barrier included), recomputed with the stable
step every 10 kernel calls, so that every DOF has about the same stable step and a stiff mode (the stretch of a
rod with EA = 1e5 at h = 0.05) no longer sets the step of the soft bending modes: the plectoneme's continuation
steps before buckling took 10x fewer FIRE steps (README, "The explicit solver on every scenario"). The masses
change the path, not the equilibrium; when they are updated the velocity is rescaled by one common factor that keeps
the total kinetic energy, so the total energy stays a Lyapunov function and the velocity keeps its direction. "inertia" (the rod's lumped mass and rotational inertia) is used with an
explicit ``dt`` (physical time) and for inextensible rods (their stiff stretch is projected out already).

An inextensible rod moves on its constraint manifold |e_j| = l_j (``der.solvers.projection``): the force is
split into its tangent part and the tension (the multiplier, kept in ``state.lam``), positions are projected
back after each step (the fast projection of Goldenthal et al. 2007) and velocities onto the tangent space
(RATTLE). No axial penalty enters the dynamics, so the stable step is set by bending and twisting alone (plus
the geometric stiffness of the tension); the implicit solver's penalty is put back for the stability analysis.

The inner loop is one numba kernel. Python checks convergence after each call; a call runs at most
``check_every`` steps and about CHUNK_SECONDS of wall time (sized from the measured cost of a step), so the
time budget and Ctrl-C are honoured promptly. Every loop is bounded by a counter that always advances.
"""
import time

import numpy as np
from numba import njit
# numba's cache keys a kernel on its own file only: this file was edited with the compensated edges of
# issue 17 (geometry.edge_array's low parts, stencils.curvature_binormal_of / elongation) so that its
# kernels are compiled again with them.

from ..geometry import add_compensated_one, edge_array, transport_frames
from ..linalg import condense_vector
from ..scene import evaluate, make_plan
from .projection import (
    held_strain, inverse_mass, project_force, project_positions, project_velocity, tension_energy,
)
from .system import (
    FLOOR_FACTOR, FLOOR_MAX, INTERRUPTS, condense_forces, constrain_system, energy_terms, evaluate_system, final_result,
    is_interrupt, load_scales, residual_floor, max_strain, newton_error_estimate, residual_norm, residual_vector, state_edges, transport,
)

STATUS_RUNNING, STATUS_CONVERGED, STATUS_NONFINITE = 0, 1, 2
CAP_CUT = 0.9          # a step rejected near the cap dt_max lowers the cap by this factor (the kernels)
CAP_RECOVERY_STEPS = 2000   # steps without a rejection after which one such cut is undone (solve_explicit)
STALL_STEPS = 20_000   # no halving of the residual in this many steps (or a quarter of the run): stalled
NOISE_FACTOR = 3.0     # at the floor, a negative power below this many standard deviations of its noise is ignored


@njit(cache=True)
def _gershgorin(ab, kl, ku, perm, mass):
    """max_i sum_j |K_ij| / sqrt(m_i m_j): an upper bound of omega_max^2 (the largest of ``_gershgorin_rows``)."""
    return _gershgorin_rows(ab, kl, ku, perm, mass, np.zeros(ab.shape[1])).max()


@njit(cache=True)
def _gershgorin_rows(ab, kl, ku, perm, mass, rows):
    """rows[d] += sum_j |K_dj| / sqrt(m_d m_j) for every DOF d (DOF order; mass = 1 gives the plain row sums of |K|)."""
    n = ab.shape[1]
    off = kl + ku
    inv = np.empty(n, dtype=np.int64)
    for d in range(n):
        inv[perm[d]] = d
    for j in range(n):
        mj = mass[inv[j]]
        for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
            rows[inv[i]] += abs(ab[off + i - j, j]) / np.sqrt(mass[inv[i]] * mj)
    return rows


MASS_FLOOR = 1e-9     # a fictitious mass is at least this fraction of the largest (a DOF of almost no stiffness)


def stiffness_mass(system, state, contact=None):
    """(mass, omega2): dynamic relaxation's fictitious masses, m_d = sum_j |K_dj| (Gershgorin's row sum of the
    constrained stiffness at ``state``, the contact barrier's Hessian added if ``contact`` is given; at least
    MASS_FLOOR of the largest; 1 on held DOFs), and the Gershgorin bound of omega_max^2 of M^-1/2 |K| M^-1/2 with
    them (about 1: every DOF has about the same stable step). They change the path of the damped dynamics, not
    its equilibrium; the FIRE step is then in the units of these masses."""
    ab = np.zeros_like(system.ab)
    n = system.n_dof
    evaluate(system.plan, state.q, state.d1, state.reference_twist, state.lam, 2, np.zeros(n), np.zeros(n), ab,
             system.kl, system.ku, system.perm, state.q_lo)
    _zero_fixed(ab, system)
    ones = np.ones(n)
    rows = _gershgorin_rows(ab, system.kl, system.ku, system.perm, ones, np.zeros(n))
    if contact is not None:
        contact.barrier_rows(state, ones, rows)
    mass = np.maximum(rows, MASS_FLOOR * rows.max())
    mass[system.fixed] = 1.0
    bound = _gershgorin_rows(ab, system.kl, system.ku, system.perm, mass, np.zeros(n))
    if contact is not None:
        contact.barrier_rows(state, mass, bound)
    bound[system.fixed] = 0.0
    return mass, float(bound.max())


def stable_time_step(system, state):
    """(dt_stable, omega2_by_term): the stable explicit step 2/omega_max and the Gershgorin bound of
    omega_max^2 for each energy term of the scene alone (and for all of them together: key "all")."""
    from ..scene import Scene

    bounds = {}
    scene = system.scene
    for term in scene.energies + ("all",):
        if term == "all":
            plan = system.plan
        else:
            plan = make_plan(Scene(scene.rod, energies=(term,), loads=scene.loads, constraints=scene.constraints),
                             system.k_stretch)
        ab = np.zeros_like(system.ab)
        evaluate(plan, state.q, state.d1, state.reference_twist, state.lam, 2, np.zeros(system.n_dof),
                 np.zeros(system.n_dof), ab, system.kl, system.ku, system.perm, state.q_lo)
        _zero_fixed(ab, system)
        bounds[term] = float(_gershgorin(ab, system.kl, system.ku, system.perm, system.mass))
    return 2.0 / np.sqrt(bounds["all"]), bounds


def _zero_fixed(ab, system):
    constrain_system(system, ab, 0.0)     # T^T K T on the end supports' free variables, held DOFs removed


@njit(cache=True)
def _fire_run(plan, q, q_lo, d1, tangents, twist, lam, v, mass, fixed, inv_scale, tol, n_steps, dt, dt_max,
              alpha, n_pos, n_min, f_inc, f_dec, alpha0, f_alpha, kl, ku, perm, e_total, work_done, guard,
              project, w, closed, target, max_strain, noise, link_dep, link_const, tri_dep, tri_master, tri_coef):
    """Run up to n_steps FIRE steps in place. Returns (status, steps, residual, dt, alpha, n_pos, e_total,
    work_done, rejected, dt_max): a step rejected near the cap also lowers the cap by CAP_CUT (10 %), so that the
    integrator settles below the step at which its energy error shows (fewer restarts: FIRE keeps its momentum);
    ``solve_explicit`` undoes one such cut after CAP_RECOVERY_STEPS steps without a rejection.

    With ``project`` (an inextensible rod; ``plan`` then has no stretch term) the edge lengths are constraints:
    the force is split into its part along the constraint manifold (the rest is balanced by the tension, written
    to ``lam``), and after each step the positions are projected back onto the manifold (fast projection) and
    the velocity onto its tangent space (RATTLE). ``w`` is the inverse mass (zero on fixed DOFs); a step whose
    projection leaves a strain above ``max_strain`` is rejected like an energy-raising one; the projection
    iterates only while the strain exceeds ``target``, so that tiny steps are not moved by its round-off.
    ``noise``: the round-off of each force component once the solve is at the round-off floor (else zeros).

    Positions are compensated pairs ``q + q_lo`` (``RodState.q_lo``, as in the implicit solver): every step is
    added with ``geometry.add_compensated_one`` and every edge is formed from both parts (``evaluate``, the
    projections, the frame transport all take ``q_lo``), so that the forces carry the rounding of each edge's
    own length (eps |e|) instead of that of the coordinates (eps |x|): on a fine or lightly loaded rod the latter
    buried the forces of the slow modes and FIRE stalled far above tol (issue 11)."""
    n = q.shape[0]
    grad = np.zeros(n)
    fext = np.zeros(n)
    ab = np.zeros((1, 1)).T    # Fortran-ordered like the solvers' bands: the kernels compile once for both
    q_old = q.copy()
    lo_old = q_lo.copy()
    d1_old = d1.copy()
    t_old = tangents.copy()
    tw_old = twist.copy()
    f = np.zeros(n)
    energy = evaluate(plan, q, d1, twist, lam, np.int64(1), grad, fext, ab, kl, ku, perm, q_lo)
    if project:
        energy += tension_energy(q, plan.edge_nodes, plan.l_bar, lam, q_lo)
    residual = np.inf
    rejected = 0
    for step in range(n_steps):
        residual = 0.0
        for i in range(n):
            f[i] = fext[i] - grad[i]
        condense_vector(f, tri_dep, tri_master, tri_coef, fixed)   # end supports: forces on the free variables
        if project and not project_force(q, plan.edge_nodes, plan.l_bar, w, closed, f, lam, q_lo,
                                                 tri_dep, tri_master, tri_coef):
            return STATUS_NONFINITE, step, residual, dt, alpha, n_pos, e_total, work_done, rejected, dt_max
        for i in range(n):
            r = abs(f[i]) * inv_scale[i]
            if r > residual:
                residual = r
        if not np.isfinite(residual) or not np.isfinite(energy):
            return STATUS_NONFINITE, step, residual, dt, alpha, n_pos, e_total, work_done, rejected, dt_max
        if residual <= tol:
            return STATUS_CONVERGED, step, residual, dt, alpha, n_pos, e_total, work_done, rejected, dt_max
        # FIRE: power, mixing, adaptive step
        power = 0.0
        vnorm2 = 0.0
        fnorm2 = 0.0
        pnoise2 = 0.0
        for i in range(n):
            power += f[i] * v[i]
            vnorm2 += mass[i] * v[i] * v[i]
            fnorm2 += f[i] * f[i] / mass[i]
            pnoise2 += (noise[i] * v[i]) ** 2
        # at the round-off floor a negative power within the force's round-off noise is no overshoot: that noise
        # would restart FIRE every few steps and the slow modes would never gain momentum (noise = 0 before)
        if power > -NOISE_FACTOR * np.sqrt(pnoise2):
            if fnorm2 > 0.0:
                c = alpha * np.sqrt(vnorm2 / fnorm2)
                for i in range(n):
                    v[i] = (1.0 - alpha) * v[i] + c * f[i] / mass[i]
            n_pos += 1
            if n_pos > n_min:
                dt = min(dt * f_inc, dt_max)
                alpha *= f_alpha
        else:
            for i in range(n):
                v[i] = 0.0
            dt *= f_dec
            alpha = alpha0
            n_pos = 0
        # symplectic Euler (positions as compensated pairs)
        q_old[:] = q
        lo_old[:] = q_lo
        d1_old[:, :] = d1
        t_old[:, :] = tangents
        tw_old[:] = twist
        for i in range(n):
            if not fixed[i]:
                v[i] += dt * f[i] / mass[i]
                add_compensated_one(q, q_lo, i, dt * v[i])
        _follow_links(q, q_lo, link_dep, link_const, tri_dep, tri_master, tri_coef)
        ok = True
        if project:
            # positions back onto |e_j| = l_j (a step of dt v leaves a strain O(dt^2 v^2 / l^2)); the velocity made
            # tangent there (RATTLE: the normal part, the constraint impulse, is removed). End supports: all
            # three in the free variables (projection.py), the dependents following the masters
            ok = project_positions(q, plan.edge_nodes, plan.l_bar, w, closed, 20, target, q_lo, tri_dep,
                                   tri_master, tri_coef) <= max_strain
            if ok:
                ok = project_velocity(q, plan.edge_nodes, plan.l_bar, w, closed, v, q_lo, tri_dep, tri_master,
                                      tri_coef)
        ok = ok and transport_frames(q, plan.edge_nodes, plan.vertex_edges, t_old, d1_old, tw_old, tangents, d1,
                                     twist, edge_array(q, plan.edge_nodes, q_lo))
        fext_old_dot = 0.0
        for i in range(n):
            fext_old_dot += fext[i] * ((q[i] - q_old[i]) + (q_lo[i] - lo_old[i]))
        new_energy = np.inf
        if ok:
            new_energy = evaluate(plan, q, d1, twist, lam, np.int64(1), grad, fext, ab, kl, ku, perm, q_lo)
            if project:       # the Lagrangian E + lam . g (projection.tension_energy)
                new_energy += tension_energy(q, plan.edge_nodes, plan.l_bar, lam, q_lo)
        kinetic = 0.0
        fext_new_dot = 0.0
        for i in range(n):
            kinetic += 0.5 * mass[i] * v[i] * v[i]
            fext_new_dot += fext[i] * ((q[i] - q_old[i]) + (q_lo[i] - lo_old[i]))
        new_work = work_done + 0.5 * (fext_old_dot + fext_new_dot)
        new_total = kinetic + new_energy - new_work
        # energy guard: for conservative loads only the round-off of the energy is tolerated (guard ~ 64 eps), so
        # the recorded energy never increases; circulatory loads may feed energy in, and the guard then only
        # catches an unstable step (guard = 1e-6). With the projection the same total is a Lyapunov function: the
        # tension does no work along the manifold (it is not in the energy, the state stays on the manifold) and
        # the RATTLE velocity projection is M-orthogonal, so it only removes kinetic energy.
        slack = guard * (abs(new_energy) + abs(new_work) + abs(kinetic))
        if not ok or not (new_total <= e_total + slack):
            # reject: back to the old state, at rest, smaller step
            rejected += 1
            if dt > 0.5 * dt_max:     # failing near the cap: the cap is too high for this trajectory
                dt_max *= CAP_CUT
            q[:] = q_old
            q_lo[:] = lo_old
            d1[:, :] = d1_old
            tangents[:, :] = t_old
            twist[:] = tw_old
            for i in range(n):
                v[i] = 0.0
            dt *= f_dec
            alpha = alpha0
            n_pos = 0
            energy = evaluate(plan, q, d1, twist, lam, np.int64(1), grad, fext, ab, kl, ku, perm, q_lo)
            if project:
                energy += tension_energy(q, plan.edge_nodes, plan.l_bar, lam, q_lo)
            e_total = energy - work_done
            continue
        energy = new_energy
        work_done = new_work
        e_total = new_total
    return STATUS_RUNNING, n_steps, residual, dt, alpha, n_pos, e_total, work_done, rejected, dt_max


@njit(cache=True)
def _follow_links(q, q_lo, link_dep, link_const, tri_dep, tri_master, tri_coef):
    """End supports: each dependent coordinate is its constant plus its masters times their coefficients
    (``constraints.Links``), high and low parts apart (the constants are exact: their low parts are 0)."""
    for k in range(link_dep.shape[0]):
        q[link_dep[k]] = link_const[k]
        q_lo[link_dep[k]] = 0.0
    for k in range(tri_dep.shape[0]):
        q[tri_dep[k]] += tri_coef[k] * q[tri_master[k]]
        q_lo[tri_dep[k]] += tri_coef[k] * q_lo[tri_master[k]]


def solve_explicit(system, state, options, progress=None, recorder=None):
    """Relax ``state`` (a prepared working copy, modified in place) by FIRE damped dynamics.

    An inextensible rod is integrated on its constraint manifold (``der.solvers.projection``): no axial
    penalty enters the dynamics, so the stable step is set by bending and twisting (and the tension's geometric
    stiffness) alone; the tension is the multiplier of the force projection, left in ``state.lam``.
    Every loop is bounded: each pass of the outer loop runs at least one step or counts as an idle pass
    (at most IDLE_PASSES of them), and each pass lasts at most about CHUNK_SECONDS, so the time budget and Ctrl-C
    are honoured whatever ``check_every`` is.
    """
    rod = system.rod
    if state.q_lo is None:
        state.q_lo = np.zeros_like(state.q)     # compensated positions (prepare_state gives them already)
    project = rod.inextensible
    fixed = system.fixed
    w = inverse_mass(system)
    strain_tol = options.effective_strain_tol
    # a step must leave the constraints far inside the requested strain tolerance (the projection itself goes
    # to the round-off floor, ~1e-15)
    proj_strain = max(min(1e-3 * strain_tol, 1e-10), PROJECTION_TARGET)
    plan = system.plan
    t_start = time.perf_counter()
    if project:
        # the penalty is not used: the plan's stretch term keeps only the multiplier (for the residual, the load
        # scale and the tension's geometric stiffness in the stable step); the kernel runs without it
        system.plan.k_stretch[:] = 0.0
        state.penalty = system.plan.k_stretch.copy()
        plan = system.plan._replace(has_stretch=False)
        base = state.copy()
        lk = system.links
        if not project_positions(state.q, rod.edge_nodes, rod.l_bar, w, rod.closed, 100, PROJECTION_TARGET,
                                 state.q_lo, lk.tri_dep, lk.tri_master, lk.tri_coef) <= proj_strain or not transport(
                                     system, base, state.q, state):
            _restore_penalty(system, state)
            raise ValueError("the starting state cannot be projected onto the inextensible rod's edge lengths "
                             "(its edges are too far from their rest lengths, or fixed nodes hold an edge at "
                             "another length); start closer to the rest shape or give the rod EA")
        _initial_tension(system, state, w)
        held, held_eps = held_strain(rod, state, w, system.links)
        if held.size and held_eps.max() > strain_tol:
            # no step can change these lengths: the solve cannot end with strain <= strain_tol, say so now
            j = int(held[np.argmax(held_eps)])
            _restore_penalty(system, state)
            evaluate_system(system, state, 1)
            r0 = residual_norm(system, residual_vector(system), load_scales(system, state))
            return final_result(
                system, state, "stalled", residual=r0, iterations=0, wall_time=time.perf_counter() - t_start,
                message=f"edge {j} lies between fixed nodes at strain {held_eps.max():.2e} > strain_tol "
                f"{strain_tol:.1e}: the constraints hold the inextensible rod away from its rest length (start from a "
                "state whose clamped edges have their rest length)", solver="explicit", strain=float(held_eps.max()),
                history=[], dt=None, residual_floor=float("nan"))
    run, contact = _fire_run, None
    if system.terms:      # contact: barrier forces and CCD-proven steps (explicit_contact.py)
        from .explicit_contact import ContactRun

        contact = ContactRun(system)
        run = contact.run
    # the fictitious masses (SolverOptions.fire_mass): scaled to the stiffness unless the user's dt is physical
    # time; an inextensible rod keeps its inertia (its stiff stretch is already projected out, and the residual
    # of its projected force is measured in the inertia's metric)
    true_mass = system.mass
    scaled = options.fire_mass == "stiffness" and options.dt is None and not project
    if scaled:
        system.mass, omega2 = stiffness_mass(system, state, contact)
    dt_stable, bounds = stable_time_step(system, state)
    if scaled:
        dt_stable = 2.0 / np.sqrt(omega2)     # the bound with the contact barrier's share
    stiffest = max((k for k in bounds if k != "all"), key=lambda k: bounds[k], default="all")
    if options.dt is not None and options.dt > dt_stable:
        _restore_penalty(system, state)
        raise ValueError(f"explicit time step dt={options.dt:.3e} exceeds the stable limit {dt_stable:.3e} "
                         f"(2/omega_max, omega_max^2 <= {bounds['all']:.3e} from the {stiffest} mode); "
                         "use dt=None for the largest stable step")
    # the largest step that is refused is the linear stability limit 2/omega_max; the default is half of it
    # (times ``safety``): from rest, a symplectic Euler step then lowers the energy in every mode (dt omega < 1),
    # so a restart after a rejected step always makes progress
    dt_max = options.dt if options.dt is not None else options.safety * 0.5 * dt_stable
    dt_cap = dt_max       # the ceiling of dt_max: the user's dt, or the current stable-step bound times safety / 2
    clean = 0             # steps since the kernel last cut dt_max (a step rejected near it)
    dt = 0.1 * dt_max
    alpha, n_pos = options.fire_alpha, 0
    v = np.zeros(rod.n_dof)
    history, energies = [], []
    steps, rejected_total, passes, idle = 0, 0, 0, 0
    residual = np.inf
    strain = 0.0
    status, message = "max_iterations", f"no convergence within {options.max_steps} steps"
    last_good = state.copy()
    e_total, work_done = None, 0.0
    conservative = not (system.plan.has_theta or system.plan.has_dead_torques or system.plan.has_follower
                        or system.plan.has_follower_torques)
    guard = 64 * np.finfo(float).eps if conservative else 1e-6
    best, best_step = np.inf, 0
    best_err = np.inf     # the smallest Newton error estimate at the round-off floor so far
    looks = 0             # looks at the floor in a row since that estimate last halved
    noise = np.zeros(rod.n_dof)
    floor = np.nan
    step_cost = None      # measured seconds per step: sizes the chunks
    try:
        while True:
            passes += 1
            scales = load_scales(system, state)
            F_s, M_s = scales
            inv_scale = 1.0 / np.where(system.is_theta, M_s, F_s)
            if e_total is None:
                energy = float(evaluate(plan, state.q, state.d1, state.reference_twist, state.lam, 1, system.grad,
                                        system.fext, system.ab, system.kl, system.ku, system.perm, state.q_lo))
                if contact is not None:
                    energy += contact.energy(state)
                if project:
                    energy += tension_energy(state.q, rod.edge_nodes, rod.l_bar, state.lam, state.q_lo)
                e_total = energy + 0.5 * float(system.mass @ v ** 2) - work_done
            n = _chunk_steps(options, steps, step_cost, time.perf_counter() - t_start)
            t_chunk = time.perf_counter()
            code, done, residual, dt, alpha, n_pos, e_total, work_done, rejected, dt_max = run(
                plan, state.q, state.q_lo, state.d1, state.tangents, state.reference_twist, state.lam, v, system.mass,
                fixed, inv_scale, options.tol, n, dt, dt_max, alpha, n_pos, options.fire_n_min, options.fire_f_inc,
                options.fire_f_dec, options.fire_alpha, options.fire_f_alpha, system.kl, system.ku, system.perm,
                e_total, work_done, guard, project, w, rod.closed, PROJECTION_TARGET, proj_strain, noise,
                system.links.dep, system.links.const, system.links.tri_dep, system.links.tri_master,
                system.links.tri_coef)
            if done > 0:
                cost = (time.perf_counter() - t_chunk) / done
                step_cost = cost if step_cost is None else max(cost, 0.5 * step_cost)
            steps += done
            rejected_total += rejected
            # a rejected step near the cap cuts dt_max by CAP_CUT (the kernel); without a way back those cuts
            # compound over a long solve (greenhill's snap into a loop: 19 of them took dt_max from 2.0e-5 to
            # 3.7e-6 and the solve 5 times slower, its residual stalled at 1.2e-5 after 129k steps): after
            # CAP_RECOVERY_STEPS steps without a rejection one cut is undone, up to the stable ceiling
            clean = 0 if rejected else clean + done
            if clean >= CAP_RECOVERY_STEPS and dt_max < dt_cap:
                dt_max = min(dt_cap, dt_max / CAP_CUT)
                clean = 0
            if code == STATUS_NONFINITE:
                state.copy_from(last_good)
                status, message = "nonfinite", f"non-finite force at step {steps}; last finite state kept"
                break
            if project:
                _initial_tension(system, state, w)   # the multipliers at the state the kernel ended in
            last_good.copy_from(state)
            energies.append(e_total)
            strain = max_strain(system, state) if rod.inextensible else 0.0
            evaluate_system(system, state, 1)
            if contact is not None and any([t.after_step(state) for t in system.terms]):
                # the adaptive barrier stiffness changed (docs/contact.md section 6): a new energy landscape
                evaluate_system(system, state, 1)
                e_total, best, best_step = None, np.inf, steps
            residual = residual_norm(system, residual_vector(system), load_scales(system, state))
            history.append(residual)
            if recorder is not None and passes % options.record_every == 0:
                recorder.log_step(steps, state, residual, energy_terms(system, state))
            if progress is not None:
                progress.update(steps, residual, f"dt={dt:.2e}")
            if residual <= options.tol and strain <= strain_tol:
                status, message = "converged", f"residual {residual:.2e} <= tol {options.tol:.1e}"
                break
            if done == 0:
                # the kernel stopped before its first step although the outer check does not accept the state
                # (its residual was measured on the chunk's load scales): never loop on that
                idle += 1
                if idle >= IDLE_PASSES:
                    status, message = "stalled", (f"residual {residual:.2e} (tol {options.tol:.1e}) and strain "
                                                  f"{strain:.1e} (strain_tol {strain_tol:.1e}) no longer change")
                    break
                e_total = None
            if residual < 0.5 * best:
                best, best_step = residual, steps
            elif steps - best_step >= max(STALL_STEPS, steps // 4):
                # no progress for a while: stop if that is the round-off floor; otherwise FIRE may just be slow
                # (the step and time limits still apply)
                evaluate_system(system, state, 2)
                floor = residual_floor(system, state, load_scales(system, state))
                if residual <= FLOOR_FACTOR * floor and floor < FLOOR_MAX:
                    # At the round-off floor the slow modes are driven by forces buried in round-off, so unlike
                    # Newton the explicit solver cannot claim convergence from the residual: it certifies with the
                    # size of one Newton correction (not applied, computed with the penalty back in place of the
                    # projection), the error left in the slow modes, against its own displacement_tol.
                    # (floor_verdict's limit, max(tol, 1e-13) of the displacement, is the implicit solver's: a
                    # Newton iteration reaches it, damped dynamics whose slow forces are round-off do not, and
                    # with it no explicit solve ever got a verdict at the floor -- helix_torque at n = 200 ran
                    # 5 million steps at residual ~5e-8 and ended max_iterations.)
                    _restore_penalty(system, state)
                    err = newton_error_estimate(system, state)
                    if project:
                        system.plan.k_stretch[:] = 0.0
                    if err <= options.displacement_tol:
                        status = "converged_at_floor"
                        message = (f"converged at the round-off floor, above tol: residual {residual:.2e} is "
                                   f"{residual / options.tol:.3g} times tol {options.tol:.1e}, below the floor "
                                   f"{floor:.1e} of double precision, and a Newton correction would move the state "
                                   f"by {err:.1e} of its displacement (<= displacement_tol "
                                   f"{options.displacement_tol:.0e}); no progress in {steps - best_step} steps")
                        break
                    if err < 0.5 * best_err or looks < FLOOR_LOOKS:
                        # the max-norm residual is round-off noise now, but the slow modes still converge (the
                        # error estimate halved since the last look): go on (the step and time limits apply).
                        # (FIRE's restarts are not made blind to the noise here: without restarts its mixing
                        # alpha decays to 0, the dynamics loses its damping and the residual rose from 5e-8 to
                        # 1e-5 on helix_torque at n = 200.)
                        looks = 0 if err < 0.5 * best_err else looks + 1
                        best_err = min(best_err, err)
                    else:
                        status = "stalled"
                        message = (f"stopped at the round-off floor: residual {residual:.2e} is below the floor "
                                   f"{floor:.1e} but above tol {options.tol:.1e}, and a Newton correction would still "
                                   f"move the state by {err:.1e} of its displacement (> displacement_tol "
                                   f"{options.displacement_tol:.0e}): the slow modes are not converged (use the "
                                   "implicit solver, a larger tol or a larger load)")
                        break
                best, best_step = residual, steps   # above the floor FIRE may just be slow: go on
            if steps + idle >= options.max_steps or passes >= options.max_steps + IDLE_PASSES:
                break
            if time.perf_counter() - t_start > options.time_budget:
                status, message = "time_budget", f"time budget of {options.time_budget:g} s used up"
                break
            if passes % 10 == 0 and options.dt is None:
                # the stiffness changes as the rod deforms: keep the step below the stable limit
                if scaled:
                    # and the masses follow it (a coiling rod turns its stretch into other coordinates; a contact's
                    # barrier stiffens); the velocity is rescaled by one common factor that keeps the total kinetic
                    # energy, so the energy the guard watches is unchanged (a Lyapunov function across updates) and
                    # the direction FIRE mixes with the force is kept (a rescale per DOF turned it, and the snap into
                    # the plectoneme then ran into the guard 523 times instead of 29)
                    mass, omega2 = stiffness_mass(system, state, contact)
                    kinetic_new = float(np.dot(mass, v * v))
                    if kinetic_new > 0.0:
                        v *= np.sqrt(float(np.dot(system.mass, v * v)) / kinetic_new)
                    system.mass = mass
                    dt_stable = 2.0 / np.sqrt(omega2)
                else:
                    dt_stable, bounds = stable_time_step(system, state)
                dt_cap = options.safety * 0.5 * dt_stable
                dt_max = min(dt_max, dt_cap)
                dt = min(dt, dt_max)
    except INTERRUPTS as exc:
        if not is_interrupt(exc):
            system.mass = true_mass
            _restore_penalty(system, state)
            raise
        state.copy_from(last_good)
        status, message = "interrupted", "interrupted by the user; last state kept"
    wall = time.perf_counter() - t_start
    system.mass = true_mass
    _restore_penalty(system, state)
    how = "edge lengths held by projection; " if project else ""
    if contact is not None:
        how += (f"contact: {contact.rebuilds} pair-list builds, {contact.ccd_rejected} steps refused by CCD, "
                f"barrier stiffness {contact.term.kappa:.3g}; ")
    res = final_result(system, state, status, residual=float(residual), iterations=steps, wall_time=wall,
                       message=message + f" ({how}{rejected_total} steps rejected; stiffest mode: {stiffest}, dt_max "
                       f"{dt_max:.2e}{' in the stiffness-scaled masses' if scaled else ''})", solver="explicit", strain=strain, history=history, dt=dt,
                       residual_floor=float(floor))
    res.total_energy = energies
    res.dt_max = dt_max      # the step cap the run ended with (the stable-step bound times safety / 2)
    return res


# looks at the round-off floor (one per stall period, a quarter of the steps so far) without the Newton error
# estimate halving before the solve is declared stalled there: FIRE's slow modes converge at the floor, but slowly
# (helix_torque at n = 200: 4.2e-6 at the second look, which one look's patience declared stalled)
FLOOR_LOOKS = 3
PROJECTION_TARGET = 1e-13   # strain the projection aims at (below it, it leaves the positions alone)
IDLE_PASSES = 100       # outer passes in a row without a step before the solve is declared stalled
CHUNK_SECONDS = 0.25    # a kernel call lasts about this long at most: checks, time budget and Ctrl-C stay prompt
FIRST_CHUNK = 50        # steps of the first call, which measures the cost of a step


def _chunk_steps(options, steps, step_cost, elapsed):
    """Steps for the next kernel call: at most ``check_every``, the steps left, and what fits in CHUNK_SECONDS
    (and in the time budget left) at the measured cost of a step."""
    n = min(options.check_every, options.max_steps - steps)
    if step_cost is None:
        return max(1, min(n, FIRST_CHUNK))
    seconds = min(CHUNK_SECONDS, max(options.time_budget - elapsed, 0.0))
    return max(1, min(n, int(seconds / max(step_cost, 1e-12))))


def _initial_tension(system, state, w):
    """The tension that balances the force at ``state`` as well as the edge lengths can (the multiplier of the
    force projection) into state.lam: before the run, so that the first stable-step estimate includes its
    geometric stiffness, and after each kernel call, so that the residual checked is the projected one."""
    evaluate_system(system, state, 1)
    f = system.fext - system.grad
    # the plan still has the multiplier term: remove it from the force before projecting
    _add_lam_force(system, state, f)
    condense_forces(system, f)      # the force on the free variables (end supports' links)
    rod, lk = system.rod, system.links
    project_force(state.q, rod.edge_nodes, rod.l_bar, w, rod.closed, f, state.lam, state.q_lo, lk.tri_dep,
                  lk.tri_master, lk.tri_coef)


def _add_lam_force(system, state, f):
    """f += C^T lam: undo the multiplier's share of -dE/dq (the stretch term with k = 0 is lam_j g_j)."""
    rod = system.rod
    e = state_edges(system, state)
    t = e / np.linalg.norm(e, axis=1)[:, None]
    h = state.lam[:, None] * t
    F = np.zeros((rod.n_nodes, 3))
    np.add.at(F, rod.edge_nodes[:, 0], -h)
    np.add.at(F, rod.edge_nodes[:, 1], h)
    g = f.reshape(-1, 4)
    g[:, :3] += F


def _restore_penalty(system, state):
    """Put the augmented-Lagrangian penalty back into the plan after a projected solve: the stability analysis
    and the diagnostics see the same stiffness as after an implicit solve (the strain is ~1e-15, so the
    reported tension lam + k g is the multiplier)."""
    if system.rod.inextensible:
        system.plan.k_stretch[:] = system.k_initial
        state.penalty = system.k_initial.copy()
