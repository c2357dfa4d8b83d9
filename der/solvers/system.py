"""What both solvers share: the scene flattened into work arrays, residual and load scale, frame transport,
the inextensibility multiplier update, and energy by term.

Residual (dimensionless): the largest out-of-balance generalized force on a free DOF -- a node force, or a
moment about the tangent on an edge angle -- relative to the load scale:

    residual = max_i |R_i| / S_i

with ``R = f_ext - dE/dq`` and ``S_i`` the force scale ``F_s`` for node DOFs, the moment scale ``M_s`` for theta
DOFs. ``F_s`` (``M_s``) is the largest applied force (moment) -- point loads, distributed loads times L -- or
internal force (moment) anywhere along the rod, which includes the reactions at the constraints, and at least
the other scale converted over the rod length L (M_s / L, F_s L).

The same imbalance per unit length (``residual_per_length``: each R_i divided by the length w_i its DOF stands
for, against S_i / L) is n times larger for a uniform rod; it is what a solution error scales with (a residual
acts like a spurious distributed load of that relative size). Newton's quadratic convergence usually takes both
far below the tolerance in its last step; both are reported.
"""
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..constraints import apply_targets, fixed_dofs
from ..diagnostics import _edge_forces
from ..energies.stretch import elongations
from ..geometry import edge_frames, transport_frames
from ..linalg import band_layout, band_matvec, dot, new_band
from ..loads import DistributedForce, EndForce, EndTorque, PointForce, TwistingMoment
from ..scene import COUNTER_NAMES, evaluate, make_plan


@dataclass(eq=False)
class System:
    scene: object
    rod: object
    plan: object
    fixed: np.ndarray
    free: np.ndarray
    kl: int
    ku: int
    perm: np.ndarray
    k_stretch: np.ndarray
    weights: np.ndarray        # w_i / L: rest length share of each DOF, as a fraction of L
    is_theta: np.ndarray
    mass: np.ndarray           # lumped mass (nodes) and rotational inertia (theta) per DOF
    applied_force: float
    applied_moment: float
    grad: np.ndarray
    fext: np.ndarray
    ab: np.ndarray

    @property
    def n_dof(self):
        return self.rod.n_dof

    @property
    def counters(self):
        return dict(zip(COUNTER_NAMES, self.plan.counters.tolist()))


def axial_penalty(rod, options):
    """Per-edge axial stiffness k_j: EA / l_j for an extensible rod, the augmented-Lagrangian penalty
    ``c A1 / l_j^3`` for an inextensible one."""
    if rod.inextensible:
        return options.inextensible_penalty * rod.A1 / rod.l_bar ** 3
    return rod.EA / rod.l_bar


def rotational_inertia(rod):
    """Rotational inertia per length: ``rod.rho_J`` or a default putting twist waves at the bending wave
    speed on the edge scale, ``rho_A h^2 A2 / (4 A1)``."""
    if rod.rho_J is not None:
        return rod.rho_J
    h = rod.l_bar.mean()
    return rod.rho_A * h * h * rod.A2 / (4.0 * rod.A1)


def safe_norm(v):
    """Euclidean norm of a vector without overflow or underflow (scaled by its largest entry, like np.hypot):
    |(1e200, 0, 0)| is 1e200, not inf."""
    v = np.asarray(v, dtype=float)
    m = float(np.abs(v).max()) if v.size else 0.0
    if m == 0.0 or not np.isfinite(m):
        return m
    return m * float(np.sqrt(((v / m) ** 2).sum()))


def row_norms(a):
    """Euclidean norm of each row of ``a`` (k, 3) without overflow or underflow."""
    m = float(np.abs(a).max()) if a.size else 0.0
    if m == 0.0 or not np.isfinite(m):
        return np.full(a.shape[0], m)
    return m * np.sqrt(((a / m) ** 2).sum(axis=1))


@njit(cache=True)
def max_row_norm(a):
    """max over rows of ``row_norms(a)`` in one pass and no temporaries (the same operations, so the same
    number: the load scale is recomputed at every Newton iteration)."""
    m = 0.0
    for i in range(a.shape[0]):
        for k in range(a.shape[1]):
            if np.isnan(a[i, k]):
                return np.nan   # (max() would skip it)
            m = max(m, abs(a[i, k]))
    if m == 0.0 or not np.isfinite(m):
        return m
    best = 0.0
    for i in range(a.shape[0]):
        s = 0.0
        for k in range(a.shape[1]):
            x = a[i, k] / m
            s += x * x
        best = max(best, np.sqrt(s))
    return m * best


def applied_scales(scene):
    """(F_app, M_app): the largest applied force (point loads, distributed loads times L) and moment (torques,
    twisting moments times L). A load whose scale, or the moment it implies over the rod length (F L), is not
    a finite double is refused with a ValueError naming it: a residual relative to an infinite scale is 0 and
    would certify anything."""
    L = scene.rod.length
    F_app = M_app = 0.0
    for load in scene.loads:
        f = m = 0.0
        if isinstance(load, (PointForce, EndForce)):
            f = safe_norm(load.force)
        elif isinstance(load, DistributedForce):
            f = safe_norm(load.density) * L
        elif isinstance(load, EndTorque):
            m = abs(float(load.torque)) if load.follower else safe_norm(load.torque)
        elif isinstance(load, TwistingMoment):
            m = abs(load.density) * L
        if not (np.isfinite(f) and np.isfinite(m) and np.isfinite(f * L) and np.isfinite(m / L)):
            raise ValueError(f"load {load!r}: its scale (|force| {f:.3e}, |moment| {m:.3e}, over the rod length "
                             f"L = {L:g}) is not a finite double; scale the problem (units) so that its loads "
                             "are representable")
        F_app, M_app = max(F_app, f), max(M_app, m)
    return F_app, M_app


def build_system(scene, options):
    rod = scene.rod
    k = axial_penalty(rod, options)
    plan = make_plan(scene, k)
    fixed = fixed_dofs(rod, scene.constraints)
    kl, ku, perm = band_layout(rod.n_nodes, rod.closed)
    n = rod.n_dof
    L = rod.length
    # residual weights: the length each DOF stands for (the outer nodes of an open rod stand for half an edge)
    node_len = np.zeros(rod.n_nodes)
    np.add.at(node_len, rod.edge_nodes[:, 0], 0.5 * rod.l_bar)
    np.add.at(node_len, rod.edge_nodes[:, 1], 0.5 * rod.l_bar)
    weights = np.repeat(node_len, 4) / L
    is_theta = np.zeros(n, dtype=bool)
    is_theta[3::4] = True
    weights[3::4] = 1.0
    weights[4 * np.arange(rod.n_edges) + 3] = rod.l_bar / L
    mass = np.repeat(rod.rho_A * node_len, 4)
    mass[3::4] = 1.0
    mass[4 * np.arange(rod.n_edges) + 3] = rotational_inertia(rod) * rod.l_bar
    F_app, M_app = applied_scales(scene)
    system = System(scene, rod, plan, fixed, ~fixed, kl, ku, perm, plan.k_stretch, weights, is_theta, mass, F_app,
                    M_app, np.zeros(n), np.zeros(n), new_band(n, kl, ku))
    system.k_initial = plan.k_stretch.copy()
    return system


def evaluate_system(system, state, order):
    """Energy; fills system.grad, system.fext (and system.ab with order 2)."""
    return evaluate(system.plan, state.q, state.d1, state.reference_twist, state.lam, order, system.grad,
                    system.fext, system.ab, system.kl, system.ku, system.perm)


def load_scales(system, state):
    """(F_s, M_s): force and moment scales of the residual (see module docstring)."""
    rod, plan = system.rod, system.plan
    F, M = _edge_forces(state.q, state.d1, state.reference_twist, state.lam, rod.edge_nodes, rod.vertex_nodes,
                        rod.vertex_edges, rod.l_bar, plan.k_stretch, plan.kappa_bar, rod.twist_bar, plan.weld,
                        rod.voronoi, rod.A1, rod.A2, plan.has_stretch, plan.has_bend, plan.has_twist)
    f_int = float(max_row_norm(F)) if F.size else 0.0
    m_int = float(M.max()) if M.size else 0.0
    L = rod.length
    F_raw = max(system.applied_force, f_int)
    M_raw = max(system.applied_moment, m_int)
    if F_raw == 0.0 and M_raw == 0.0:
        return rod.A1 / L ** 2, rod.A1 / L
    # a force scale implies a moment scale over the rod length and vice versa (e.g. a rod loaded only by
    # torques has no force of its own: round-off forces must not set the scale)
    return max(F_raw, M_raw / L), max(M_raw, F_raw * L)


def residual_vector(system):
    """R = f_ext - dE/dq on the free DOFs (zero on fixed ones), from the last evaluation."""
    R = system.fext - system.grad
    R[system.fixed] = 0.0
    return R


def residual_norm(system, R, scales, per_length=False):
    """max_i |R_i| / S_i (the convergence measure), or per unit length with ``per_length``."""
    F_s, M_s = scales
    s = np.where(system.is_theta, M_s, F_s)
    if per_length:
        s = s * system.weights
    return float(np.max(np.abs(R) / s)) if R.size else 0.0


def floor_forces(system, state):
    """eps |K| |q| per DOF (force units): a bound on the generalized force change from rounding every
    coordinate, zero on fixed DOFs. Needs ``system.ab`` evaluated at ``state``."""
    out = np.empty(system.n_dof)
    band_matvec(system.ab, system.kl, system.ku, system.perm, state.q, out, True)
    out[system.fixed] = 0.0
    return np.finfo(float).eps * out


def residual_floor(system, state, scales):
    """Round-off floor of the residual: eps |K| |q| (the force change from rounding every coordinate), in
    residual units. Positions are rounded relative to their size, so the floor grows with the distance from
    the origin, the stiffness and the fourth power of n (the bending stiffness of an edge scales as 1/h^3)."""
    return residual_norm(system, floor_forces(system, state), scales)


def newton_error_estimate(system, state):
    """Size of the Newton correction K^-1 R at ``state`` relative to the displacement from the rest shape
    (max norm over node positions and, times the rod length, edge angles): an estimate of the error left,
    dominated by the slowest modes. Rigid-body
    and other symmetry modes of an unconstrained rod are projected out (they carry no error)."""
    from ..linalg import add_diagonal, band_solve, constrain_band
    from .stability import symmetry_modes

    evaluate_system(system, state, 2)
    R = residual_vector(system)
    V = np.array(symmetry_modes(system, state)).T if symmetry_modes(system, state) else np.zeros((R.size, 0))
    if V.shape[1]:
        Q, _ = np.linalg.qr(V)
        R = R - Q @ (Q.T @ R)
    ab = system.ab.copy(order="F")
    diag = np.abs(ab[system.kl + system.ku, :][system.perm])
    diag[diag == 0] = 1.0
    add_diagonal(ab, system.kl, system.ku, system.perm, diag, 1e-14)   # regularises the symmetry modes
    constrain_band(ab, system.kl, system.ku, system.perm, system.fixed, 1.0)
    delta, info = band_solve(ab, system.kl, system.ku, system.perm, R)
    if info != 0 or not np.all(np.isfinite(delta)):
        return np.inf
    if V.shape[1]:
        delta = delta - Q @ (Q.T @ delta)
    # displacement and rotation (times the rod length) from the rest shape, against the same of the correction
    rod = system.rod
    L = rod.length
    d = delta.reshape(-1, 4)
    u = state.q.reshape(-1, 4) - rod.rest_q.reshape(-1, 4)
    ne = rod.n_edges
    scale = max(float(np.abs(u[:, :3]).max()), L * float(np.abs(u[:ne, 3]).max()), 1e-300)
    return max(float(np.abs(d[:, :3]).max()), L * float(np.abs(d[:ne, 3]).max())) / scale


# the floor is a worst-case bound (every coordinate's rounding adding up); converged solves end at 0.2-0.4x
# of it, and accepting 10x let a ring of 30,000 edges stop with a 1e-3 error
FLOOR_FACTOR = 1.0
# The largest floor a verdict may rest on. The floor is a bound on the force that rounding the coordinates can
# produce, relative to the force scale; at 1 it is as large as the largest force of the problem, and a residual
# below it can no longer tell an equilibrium from a state with no equilibrium at all (a free rod under a net
# force "converged" below a floor of 2.0 at residual 0.93). Below 1 a residual at the floor still certifies the
# balance to that fraction of the load: a straight inextensible cantilever under an axial force of 1e-6 A1/L^2
# at n = 400 is exact (no motion) yet its residual stops at 0.13 of the load, under a floor of 0.55, because the
# penalty stiffness c A1/h^3 times the rounding of coordinates of size L is that large against so small a load
# (the cancellation of absolute coordinates, issue 17). Such a verdict is "converged_at_floor", with a warning.
FLOOR_MAX = 1.0


def floor_verdict(system, state, scales, residual, tol, what):
    """Status, floor and message for a solve whose residual stopped falling: "converged_at_floor" if the
    residual is below FLOOR_FACTOR times the round-off floor and that floor is below FLOOR_MAX (a larger bound
    means the estimate certifies nothing), "stalled" otherwise. Needs ``system.ab`` evaluated at ``state``."""
    floor = residual_floor(system, state, scales)
    if residual <= FLOOR_FACTOR * floor and floor < FLOOR_MAX:
        return "converged_at_floor", floor, (
            f"converged at the round-off floor, above tol: residual {residual:.2e} is {residual / tol:.3g} times "
            f"tol {tol:.1e}, below the floor {floor:.1e} of double precision; {what}")
    if residual <= FLOOR_FACTOR * floor:
        return "stalled", floor, (
            f"residual stuck at {residual:.2e} (tol {tol:.1e}); the round-off floor bound {floor:.1e} is not "
            f"below {FLOOR_MAX:g} times the force scale, so it certifies nothing (a load too small for the "
            f"stiffness, or no equilibrium); {what}")
    return "stalled", floor, (f"residual stuck at {residual:.2e}, above the round-off floor {floor:.1e} and tol "
                              f"{tol:.1e}; {what}")


INTERRUPTS = (KeyboardInterrupt, SystemError)


def is_interrupt(exc):
    """True for Ctrl-C, also when it arrived inside a numba call: numba then raises a SystemError whose cause
    is the KeyboardInterrupt."""
    while exc is not None:
        if isinstance(exc, KeyboardInterrupt):
            return True
        exc = exc.__cause__ or exc.__context__
    return False


def final_result(system, state, status, **fields):
    """The SolveResult of a solve that ended in ``status`` at ``state``: the force-derived fields (load scale,
    residual per unit length, energy by term) are evaluated here, once, for both solvers."""
    from .options import CONVERGED_STATUSES, SolveResult

    evaluate_system(system, state, 1)
    scales = load_scales(system, state)
    if status in CONVERGED_STATUSES and not np.isfinite(scales).all():
        # a residual relative to an infinite scale is 0 whatever the forces: no verdict can rest on it
        status = "nonfinite"
        fields["message"] = f"the force scale became non-finite ({scales[0]:.3g}, {scales[1]:.3g}); no verdict"
    per_length = residual_norm(system, residual_vector(system), scales, per_length=True)
    return SolveResult(state=state, converged=status in CONVERGED_STATUSES, status=status, load_scale=float(scales[0]),
                       energy=energy_terms(system, state), residual_per_length=per_length, **fields)


def max_strain(system, state):
    rod = system.rod
    return float(np.max(np.abs(elongations(state.q, rod.edge_nodes, rod.l_bar) / rod.l_bar)))


def constraint_residual(system, state, scales):
    """The elongation left in an inextensible rod as a residual (same units as ``residual_norm``): the force
    k_j |g_j| a multiplier update would shift, relative to the force scale."""
    rod = system.rod
    g = elongations(state.q, rod.edge_nodes, rod.l_bar)
    return float(np.max(system.k_stretch * np.abs(g)) / scales[0])


PENALTY_GROWTH = 10.0
PENALTY_MAX = 1e5      # times the initial penalty


def multiplier_update(system, state, previous=None):
    """Augmented-Lagrangian step for an inextensible rod: lam <- lam + k g. Returns the elongations g it used.

    With ``previous`` (the elongations of the previous update; the implicit solver passes them only near
    equilibrium, where its inner solves are exact): if the elongation did not fall at least fourfold along itself
    since then, the penalty k is raised tenfold first (up to 1e5 times its start value). A rod whose shape is
    itself nearly inextensible -- a straight rod under tension, a tight helix -- resists the multiplier update,
    and the remedy of the method of multipliers is a larger penalty. An elongation that changed sign means the
    update overshot: then the penalty is left alone."""
    rod = system.rod
    g = elongations(state.q, rod.edge_nodes, rod.l_bar)
    k = system.plan.k_stretch
    if previous is not None:
        gg = dot(previous, previous)
        ratio = dot(g, previous) / gg if gg > 0 else 0.0
        if ratio > 0.25 and k.max() * PENALTY_GROWTH <= PENALTY_MAX * system.k_initial.max():
            k *= PENALTY_GROWTH           # in place: the plan and the state see it
    state.lam += k * g
    state.penalty = k.copy()
    return g


def transport(system, base, q_new, out):
    """Put ``q_new`` into ``out`` with frames transported from ``base``; False if an edge reversed/vanished."""
    rod = system.rod
    if out is not base:
        out.q[:] = q_new
        out.lam[:] = base.lam
    try:
        ok = transport_frames(out.q, rod.edge_nodes, rod.vertex_edges, base.tangents, base.d1, base.reference_twist,
                              out.tangents, out.d1, out.reference_twist)
    except ZeroDivisionError:
        # a director transported onto its own tangent (a step that turned an edge by ~pi, or a vanishing edge):
        # a failed step like a reversed edge, not an exception out of the solve
        return False
    return bool(ok)


def prepare_state(system, state):
    """A working copy of ``state`` with constraint targets applied and frames consistent with positions."""
    rod = system.rod
    work = state.copy()
    work.penalty = system.k_stretch.copy()
    if work.lam.size != rod.n_edges:
        work.lam = np.zeros(rod.n_edges)
    if not rod.inextensible:
        work.lam[:] = 0.0
    if not rod.closed:
        work.q[4 * rod.n_nodes - 1] = 0.0
    base = work.copy()
    directors = apply_targets(rod, work, system.scene.constraints)
    if not transport(system, base, work.q, work):
        raise ValueError("the prescribed constraint targets reverse an edge in one step; "
                         "move the clamp in smaller increments (continuation)")
    for j, m1 in directors:
        t = work.tangents[j]
        d1 = work.d1[j]
        d2 = np.cross(t, d1)
        target = np.arctan2(m1 @ d2, m1 @ d1)
        current = work.q[4 * j + 3]
        work.q[4 * j + 3] = current + (target - current + np.pi) % (2 * np.pi) - np.pi
    return work


def energy_terms(system, state):
    """Energy of each term the scene uses, plus the work of the constant generalized loads."""
    from ..energies.bend import bend_energy
    from ..energies.stretch import stretch_energy
    from ..energies.twist import twist_energy

    rod, plan = system.rod, system.plan
    out = {}
    if plan.has_stretch:
        out["stretch"] = float(stretch_energy(state.q, rod.edge_nodes, rod.l_bar, plan.k_stretch, state.lam))
    if plan.has_bend:
        ed = edge_frames(state.q, rod.edge_nodes, state.d1)
        out["bend"] = float(bend_energy(ed, rod.vertex_edges, plan.weld, plan.kappa_bar, rod.voronoi, rod.A1))
    if plan.has_twist:
        out["twist"] = float(twist_energy(state.q, rod.vertex_edges, state.reference_twist, plan.weld, rod.twist_bar,
                                          rod.voronoi, rod.A2))
    return out


def _fmt_vector(v):
    return "(" + ", ".join(f"{x:.6g}" for x in v) + ")"


def check_equilibrium_exists(system, state):
    """Refuse, before the solve, a scene that has no static equilibrium because a rigid motion its constraints
    leave free is pushed by a load that does work on it whatever the configuration: a net dead force along a
    free translation, or (with no forces and no follower loads) a net dead torque about a free rotation.
    Internal forces do no work on rigid motions, so nothing can balance such a load; the solve would only run
    into its iteration limit (or, inextensible, into a degenerate step). Raises ValueError."""
    rod, scene = system.rod, system.scene
    fixed = system.fixed.copy()
    if not rod.closed:
        fixed[4 * rod.n_nodes - 1] = False       # the dummy slot is not a constraint
    net_force = np.zeros(3)
    total = 0.0                                  # sum of |forces|: the scale of round-off in their sum
    net_torque = np.zeros(3)
    torque_total = 0.0
    conservative_torques_only = True
    for load in scene.loads:
        if isinstance(load, (PointForce, EndForce)):
            f = np.asarray(load.force, float)
        elif isinstance(load, DistributedForce):
            # the total the rod receives: the density times the length its nodes stand for (make_plan's lumping)
            f = np.asarray(load.density, float) * float(rod.node_weights().sum())
        else:
            if isinstance(load, EndTorque) and not load.follower:
                net_torque += np.asarray(load.torque, float)
                torque_total += safe_norm(load.torque)
            else:
                conservative_torques_only = False    # follower moments turn with the rod
            continue
        net_force += f
        total += safe_norm(f)
        if np.any(f != 0.0):
            conservative_torques_only = False        # forces have a moment that depends on the configuration
    what = "an unconstrained rod" if not fixed.any() else None
    free_axes = [a for a in range(3) if not fixed.reshape(-1, 4)[:, a].any()]
    bad = [a for a in free_axes if abs(net_force[a]) > 1e-12 * total]
    if bad:
        where = what or f"a rod whose constraints cannot react along {', '.join('xyz'[a] for a in bad)}"
        raise ValueError(f"net applied force {_fmt_vector(net_force)} on {where}: no static equilibrium exists "
                         "(add a clamp or pin that can react, or balance the loads)")
    if conservative_torques_only and torque_total > 0.0:
        bad = [a for a in range(3) if abs(net_torque[a]) > 1e-12 * torque_total
               and _rotation_is_free(system, state, fixed, a)]
        if bad:
            where = what or f"a rod whose constraints leave it free to rotate about {', '.join('xyz'[a] for a in bad)}"
            raise ValueError(f"net applied torque {_fmt_vector(net_torque)} on {where}, with no force to balance "
                             "it: no static equilibrium exists (add a clamp, or balance the torques)")


def _rotation_is_free(system, state, fixed, a):
    """Whether a rigid rotation about coordinate axis ``a`` -- about the one pinned node, or the centroid -- moves
    no fixed DOF (the centre used by ``stability.symmetry_modes``)."""
    rod = system.rod
    x = state.positions
    pinned = [k for k in range(rod.n_nodes) if fixed[4 * k:4 * k + 3].all()]
    centre = x[pinned[0]] if len(pinned) == 1 else x.mean(axis=0)
    w = np.zeros(3)
    w[a] = 1.0
    v = np.zeros(rod.n_dof)
    v.reshape(-1, 4)[:, :3] = np.cross(w, x - centre)
    v[4 * np.arange(rod.n_edges) + 3] = state.tangents @ w
    if not rod.closed:
        v[4 * rod.n_nodes - 1] = 0.0
    return bool(np.abs(v[fixed]).max(initial=0.0) < 1e-12 * np.abs(v).max())


# constraint tension against the larger of the bending scale A1/L^2 and the applied load scale above which an
# inextensible rod held at both ends is reported locked: at T = 100 A1/L^2 the boundary layers at the clamps are
# L/10 wide (sqrt(A1/T)); an Euler-buckled rod between clamps carries 4 pi^2 A1/L^2 ~ 40
LOCK_RATIO = 100.0


def locked_rod_note(system, state):
    """A note (or "") for an inextensible open rod whose two end nodes are held in place and whose constraint
    tension is more than LOCK_RATIO times both its bending scale A1/L^2 and its applied loads: the rod cannot
    bend without changing its chord, so its multipliers grow until they pull it straight with boundary layers at
    the ends -- the true inextensible limit, but not the beam theory a user may expect."""
    rod = system.rod
    if not rod.inextensible or rod.closed:
        return ""
    fixed = system.fixed
    if not (fixed[0:3].all() and fixed[4 * (rod.n_nodes - 1):4 * (rod.n_nodes - 1) + 3].all()):
        return ""
    g = elongations(state.q, rod.edge_nodes, rod.l_bar)
    tension = float(np.abs(state.lam + system.k_stretch * g).max())
    L = rod.length
    bending = float(np.max(rod.A1)) / L ** 2
    loads = system.applied_force + system.applied_moment / L
    if not tension > LOCK_RATIO * max(bending, loads):
        return ""
    return (f"the inextensible rod is locked between fixed ends; give it EA or a sliding clamp (its constraint "
            f"tension {tension:.3g} is {tension / bending:.3g} times the bending scale A1/L^2 = {bending:.3g}, "
            f"and its loads apply at most {loads:.3g})")
