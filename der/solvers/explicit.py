"""Explicit damped dynamics (the reference solver): FIRE (Bitzek et al. 2006) on the rod's true inertia.

Semi-implicit (symplectic) Euler with the FIRE velocity mixing and restarts, mass-weighted so that node
translations and cross-section rotations mix in consistent units. The total energy is kinetic + elastic - the
work done by the loads (accumulated by the trapezoidal rule); under conservative loads it is a Lyapunov
function of the damped dynamics and the solver never lets it increase. The time step never exceeds the stable
limit ``2 / omega_max``, with ``omega_max^2`` bounded by Gershgorin's theorem on ``M^-1/2 |K| M^-1/2``
(recomputed as the rod deforms); the bound is also evaluated for each energy term alone, to report which
mode -- stretch, bend or twist -- is the stiffest. By default the step is capped at ``safety / omega_max``, half
the limit, where a step from rest lowers the energy of every mode. A step that would raise the total energy is rejected and
restarted from rest (for circulatory loads, which can feed energy in, only a large rise is: an unstable step).
The whole inner loop is one numba kernel; Python only checks convergence every ``check_every`` steps.
"""
import time

import numpy as np
from numba import njit

from ..geometry import transport_frames
from ..linalg import condense_vector
from ..scene import evaluate, make_plan
from .system import (
    INTERRUPTS, constrain_system, constraint_residual, energy_terms, evaluate_system, final_result, floor_verdict,
    is_interrupt, load_scales, max_strain, multiplier_update, newton_error_estimate, residual_norm, residual_vector,
)

STATUS_RUNNING, STATUS_CONVERGED, STATUS_NONFINITE = 0, 1, 2
STALL_STEPS = 20_000   # no halving of the residual in this many steps (or a quarter of the run): stalled


@njit(cache=True)
def _gershgorin(ab, kl, ku, perm, mass):
    """max_i sum_j |K_ij| / sqrt(m_i m_j): an upper bound of omega_max^2."""
    n = ab.shape[1]
    off = kl + ku
    inv = np.empty(n, dtype=np.int64)
    for d in range(n):
        inv[perm[d]] = d
    rows = np.zeros(n)
    for j in range(n):
        mj = mass[inv[j]]
        for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
            rows[i] += abs(ab[off + i - j, j]) / np.sqrt(mass[inv[i]] * mj)
    return rows.max()


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
                 np.zeros(system.n_dof), ab, system.kl, system.ku, system.perm)
        _zero_fixed(ab, system)
        bounds[term] = float(_gershgorin(ab, system.kl, system.ku, system.perm, system.mass))
    return 2.0 / np.sqrt(bounds["all"]), bounds


def _zero_fixed(ab, system):
    constrain_system(system, ab, 0.0)     # T^T K T on the end supports' free variables, held DOFs removed


@njit(cache=True)
def _fire_run(plan, q, d1, tangents, twist, lam, v, mass, fixed, inv_scale, tol, n_steps, dt, dt_max,
              alpha, n_pos, n_min, f_inc, f_dec, alpha0, f_alpha, kl, ku, perm, e_total, work_done, guard,
              link_dep, link_const, tri_dep, tri_master, tri_coef):
    """Run up to n_steps FIRE steps in place. Returns (status, steps, residual, dt, alpha, n_pos, e_total,
    work_done, rejected, dt_max): a step rejected near the cap also lowers the cap by 10 %, so that the integrator
    settles below the step at which its energy error shows (fewer restarts: FIRE keeps its momentum)."""
    n = q.shape[0]
    grad = np.zeros(n)
    fext = np.zeros(n)
    ab = np.zeros((1, 1))
    q_old = q.copy()
    d1_old = d1.copy()
    t_old = tangents.copy()
    tw_old = twist.copy()
    f = np.zeros(n)
    energy = evaluate(plan, q, d1, twist, lam, 1, grad, fext, ab, kl, ku, perm)
    residual = np.inf
    rejected = 0
    for step in range(n_steps):
        residual = 0.0
        for i in range(n):
            f[i] = fext[i] - grad[i]
        condense_vector(f, tri_dep, tri_master, tri_coef, fixed)   # end supports: forces on the free variables
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
        for i in range(n):
            power += f[i] * v[i]
            vnorm2 += mass[i] * v[i] * v[i]
            fnorm2 += f[i] * f[i] / mass[i]
        if power > 0.0:
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
        # symplectic Euler
        q_old[:] = q
        d1_old[:, :] = d1
        t_old[:, :] = tangents
        tw_old[:] = twist
        for i in range(n):
            if not fixed[i]:
                v[i] += dt * f[i] / mass[i]
                q[i] += dt * v[i]
        for k in range(link_dep.shape[0]):      # end supports: dependents follow their masters
            q[link_dep[k]] = link_const[k]
        for k in range(tri_dep.shape[0]):
            q[tri_dep[k]] += tri_coef[k] * q[tri_master[k]]
        ok = transport_frames(q, plan.edge_nodes, plan.vertex_edges, t_old, d1_old, tw_old, tangents, d1, twist)
        fext_old_dot = 0.0
        for i in range(n):
            fext_old_dot += fext[i] * (q[i] - q_old[i])
        new_energy = np.inf
        if ok:
            new_energy = evaluate(plan, q, d1, twist, lam, 1, grad, fext, ab, kl, ku, perm)
        kinetic = 0.0
        fext_new_dot = 0.0
        for i in range(n):
            kinetic += 0.5 * mass[i] * v[i] * v[i]
            fext_new_dot += fext[i] * (q[i] - q_old[i])
        new_work = work_done + 0.5 * (fext_old_dot + fext_new_dot)
        new_total = kinetic + new_energy - new_work
        # energy guard: for conservative loads only the round-off of the energy is tolerated (guard ~ 64 eps), so
        # the recorded energy never increases; circulatory loads may feed energy in, and the guard then only
        # catches an unstable step (guard = 1e-6)
        slack = guard * (abs(new_energy) + abs(new_work) + abs(kinetic))
        if not ok or not (new_total <= e_total + slack):
            # reject: back to the old state, at rest, smaller step
            rejected += 1
            if dt > 0.5 * dt_max:     # failing near the cap: the cap is too high for this trajectory
                dt_max *= 0.9
            q[:] = q_old
            d1[:, :] = d1_old
            tangents[:, :] = t_old
            twist[:] = tw_old
            for i in range(n):
                v[i] = 0.0
            dt *= f_dec
            alpha = alpha0
            n_pos = 0
            energy = evaluate(plan, q, d1, twist, lam, 1, grad, fext, ab, kl, ku, perm)
            e_total = energy - work_done
            continue
        energy = new_energy
        work_done = new_work
        e_total = new_total
    return STATUS_RUNNING, n_steps, residual, dt, alpha, n_pos, e_total, work_done, rejected, dt_max


def solve_explicit(system, state, options, progress=None, recorder=None):
    """Relax ``state`` (a prepared working copy, modified in place) by FIRE damped dynamics."""
    rod = system.rod
    dt_stable, bounds = stable_time_step(system, state)
    stiffest = max((k for k in bounds if k != "all"), key=lambda k: bounds[k], default="all")
    if options.dt is not None and options.dt > dt_stable:
        raise ValueError(f"explicit time step dt={options.dt:.3e} exceeds the stable limit {dt_stable:.3e} "
                         f"(2/omega_max, omega_max^2 <= {bounds['all']:.3e} from the {stiffest} mode); "
                         "use dt=None for the largest stable step")
    # the largest step that is refused is the linear stability limit 2/omega_max; the default is half of it
    # (times ``safety``): from rest, a symplectic Euler step then lowers the energy in every mode (dt omega < 1),
    # so a restart after a rejected step always makes progress
    dt_max = options.dt if options.dt is not None else options.safety * 0.5 * dt_stable
    dt = 0.1 * dt_max
    alpha, n_pos = options.fire_alpha, 0
    t_start = time.perf_counter()
    v = np.zeros(rod.n_dof)
    fixed = system.fixed
    strain_tol = options.effective_strain_tol
    history, energies = [], []
    steps, rejected_total = 0, 0
    residual = np.inf
    strain = 0.0
    status, message = "max_iterations", f"no convergence within {options.max_steps} steps"
    last_good = state.copy()
    evaluate_system(system, state, 1)
    e_total, work_done = None, 0.0
    conservative = not (system.plan.has_theta or system.plan.has_dead_torques or system.plan.has_follower
                        or system.plan.has_follower_torques)
    guard = 64 * np.finfo(float).eps if conservative else 1e-6
    check = 0
    best, since_best = np.inf, 0
    floor = np.nan
    try:
        while True:
            scales = load_scales(system, state)
            F_s, M_s = scales
            inv_scale = 1.0 / np.where(system.is_theta, M_s, F_s)
            if e_total is None:
                e_total = evaluate_system(system, state, 1) + 0.5 * float(system.mass @ v ** 2) - work_done
            n = min(options.check_every, options.max_steps - steps)
            code, done, residual, dt, alpha, n_pos, e_total, work_done, rejected, dt_max = _fire_run(
                system.plan, state.q, state.d1, state.tangents, state.reference_twist, state.lam, v, system.mass,
                fixed, inv_scale, options.tol, n, dt, dt_max, alpha, n_pos, options.fire_n_min, options.fire_f_inc,
                options.fire_f_dec, options.fire_alpha, options.fire_f_alpha, system.kl, system.ku, system.perm,
                e_total, work_done, guard, system.links.dep, system.links.const, system.links.tri_dep,
                system.links.tri_master, system.links.tri_coef)
            steps += done
            rejected_total += rejected
            check += 1
            if code == STATUS_NONFINITE:
                state.copy_from(last_good)
                status, message = "nonfinite", f"non-finite force at step {steps}; last finite state kept"
                break
            last_good.copy_from(state)
            energies.append(e_total)
            strain = max_strain(system, state) if rod.inextensible else 0.0
            evaluate_system(system, state, 1)
            residual = residual_norm(system, residual_vector(system), load_scales(system, state))
            history.append(residual)
            if recorder is not None and check % options.record_every == 0:
                recorder.log_step(steps, state, residual, energy_terms(system, state))
            if progress is not None:
                progress.update(steps, residual, f"dt={dt:.2e}")
            if residual <= options.tol and strain <= strain_tol:
                status, message = "converged", f"residual {residual:.2e} <= tol {options.tol:.1e}"
                break
            if residual < 0.5 * best:
                best, since_best = residual, 0
            else:
                since_best += 1
            if since_best * options.check_every >= max(STALL_STEPS, steps // 4) and strain <= strain_tol:
                # no progress for a while: stop if that is the round-off floor; otherwise FIRE may just be slow
                # (the step and time limits still apply)
                evaluate_system(system, state, 2)
                verdict, floor, msg = floor_verdict(system, state, load_scales(system, state), residual,
                                                    options.tol, f"no progress in {since_best * options.check_every}"
                                                    " steps")
                if verdict == "converged_at_floor":
                    # At the round-off floor the slow modes are driven by forces buried in round-off, so unlike
                    # Newton the explicit solver cannot claim convergence from the residual: certify with the
                    # size of one Newton correction (not applied), the error left in the slow modes.
                    err = newton_error_estimate(system, state)
                    if err <= options.displacement_tol:
                        status = "converged_at_floor"
                        message = (msg + f"; a Newton correction would move it by {err:.1e} of the displacement"
                                   f" (<= displacement_tol {options.displacement_tol:.0e})")
                    else:
                        status = "stalled"
                        message = (f"stopped at the round-off floor: residual {residual:.2e} is below the floor "
                                   f"{floor:.1e} but above tol {options.tol:.1e}, and a Newton correction would still "
                                   f"move the state by {err:.1e} of its displacement: the slow modes are not "
                                   "converged (use the implicit solver, a larger tol or a larger load)")
                    break
                best, since_best = residual, 0   # above the floor FIRE may just be slow: go on
            if rod.inextensible and strain > strain_tol:
                if residual <= max(options.tol, 0.1 * constraint_residual(system, state, scales)):
                    multiplier_update(system, state)   # fixed penalty: FIRE's inner solves are inexact
                    e_total = None     # the energy function changed: new baseline
                    best, since_best = np.inf, 0
            if steps >= options.max_steps:
                break
            if time.perf_counter() - t_start > options.time_budget:
                status, message = "time_budget", f"time budget of {options.time_budget:g} s used up"
                break
            if check % 10 == 0 and options.dt is None:
                # the stiffness changes as the rod deforms: keep the step below the stable limit
                dt_stable, bounds = stable_time_step(system, state)
                dt_max = min(dt_max, options.safety * 0.5 * dt_stable)
                dt = min(dt, dt_max)
    except INTERRUPTS as exc:
        if not is_interrupt(exc):
            raise
        state.copy_from(last_good)
        status, message = "interrupted", "interrupted by the user; last state kept"
    res = final_result(system, state, status, residual=float(residual), iterations=steps,
                       wall_time=time.perf_counter() - t_start,
                       message=message + f" ({rejected_total} steps rejected; stiffest mode: {stiffest}, dt_max "
                       f"{dt_max:.2e})", solver="explicit", strain=strain, history=history, dt=dt,
                       residual_floor=float(floor))
    res.total_energy = energies
    return res
