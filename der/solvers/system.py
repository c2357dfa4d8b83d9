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
import time
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..constraints import NO_LINKS, apply_targets, build_links, enforce_links, refresh_links
from ..diagnostics import _edge_forces
from ..energies.stretch import elongations
from ..geometry import edge_array, edge_array_into, edge_frames, transport_frames
from ..linalg import BandLDLT, band_layout, band_matvec, condense_band, condense_vector, constrain_band, dot, expand_step, new_band
from ..scene import COUNTER_NAMES, edge_forces_in_pass, evaluate, make_plan


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
    links: object = NO_LINKS   # the end supports' dependents (constraints.Links): q = c + T y
    mass_full: np.ndarray = None   # lumped mass before condensation (``mass`` is T^T M T, lumped)
    parts = None                   # a scene of several rods: a MultiSystem (multi.py) has its rods' systems here
    link_builds: int = 0           # times the end supports' links were built (build_system, update_links, ...)
    link_patterns = None           # moving supports (dynamics): their links' layout (constraints.LinkPattern)

    @property
    def n_dof(self):
        return self.rod.n_dof

    @property
    def counters(self):
        return dict(zip(COUNTER_NAMES, self.plan.counters.tolist()))


def axial_penalty(rod, options):
    """Per-edge axial stiffness k_j: EA / l_j for an extensible rod, the augmented-Lagrangian penalty
    ``c A1 / l_j^3`` for an inextensible one.

    The end edges of an open extensible rod count half: only their inner half lies in [0, L] (their midpoints
    are the end cross-sections), so the stretch energy is the midpoint rule for the integral of EA/2 eps^2 over
    [0, L], like bending and twisting. With it a uniform bar pulled by an end force P (half on each node of the
    end edge) has the strain P/EA in every edge, end edges included, and its ends' centres move apart by exactly
    P L / EA (issue 13: with full-weight end edges the end edges carried P/2 and the bar stretched 1% short at
    n = 50)."""
    if rod.inextensible:
        return options.inextensible_penalty * rod.bending_scale / rod.l_bar ** 3
    k = np.broadcast_to(np.asarray(rod.EA, float), rod.l_bar.shape) / rod.l_bar
    if not rod.closed:
        k = k.copy()
        k[0] *= 0.5
        k[-1] *= 0.5
    return k


def rotational_inertia(rod):
    """Rotational inertia per length: ``rod.rho_J`` or a default putting twist waves at the bending wave
    speed on the edge scale, ``rho_A h^2 A2 / (4 A1)``."""
    if rod.rho_J is not None:
        return rod.rho_J
    h = rod.l_bar.mean()
    return rod.rho_A * h * h * rod.twisting_scale / (4.0 * rod.bending_scale)


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
        f, m = load.scale(L)
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
    fixed, links = build_links(rod, scene.constraints)
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
                    M_app, np.zeros(n), np.zeros(n), new_band(n, kl, ku), links, mass.copy())
    system.mass = condensed_mass(system)
    system.link_builds = 1
    system.k_initial = plan.k_stretch.copy()
    # contact terms (der/terms), bound for this solve; () for a scene without contact (nothing is imported)
    system.terms = tuple(term.bind(system) for term in scene.contacts)
    system.contact_coo = []
    system.linear_solves = {"band": 0, "sparse": 0}
    # the symmetric band factorisation's work arrays, reused by every band_solve of this system; after a solve
    # they hold the LDL^T factors and the inertia of the last matrix factorised (``linalg.BandLDLT``)
    system.ldlt = BandLDLT(n, kl) if kl == ku else None
    return system


def condensed_mass(system):
    """The lumped mass in the free variables y of q = c + T y: diag(T^T M T), i.e. M_m + sum_d a_dm^2 M_d (a
    master of a hinge carries its dependent's mass too); 1 on held DOFs."""
    m = system.mass_full.copy()
    lk = system.links
    np.add.at(m, lk.tri_master, lk.tri_coef ** 2 * system.mass_full[lk.tri_dep])
    return m


def update_links(system, state):
    """Recompute the end supports' links (and the held mask and condensed mass) at the prepared ``state``
    (whose targets are applied): a clamp holds its end edge along its current direction."""
    fixed, links = build_links(system.rod, system.scene.constraints, state)
    system.link_builds += 1
    system.fixed = fixed
    system.free = ~fixed
    system.links = links
    system.mass = condensed_mass(system)


def condense_system_band(system, ab):
    """ab <- T^T ab T for the end supports' change of variables (rows and columns of held DOFs untouched):
    the full-space Jacobian mapped to the free variables, in the same band storage. For the stability analysis
    and the solvers; with no end supports it does nothing (the plain ``fixed`` mask is all there is)."""
    lk = system.links
    if lk.tri_dep.size:
        condense_band(ab, system.kl, system.ku, system.perm, lk.tri_dep, lk.tri_master, lk.tri_coef)
    return ab


def constrain_system(system, ab, diag):
    """ab <- T^T ab T with the rows and columns of held DOFs replaced by ``diag`` times identity."""
    condense_system_band(system, ab)
    constrain_band(ab, system.kl, system.ku, system.perm, system.fixed, diag)
    return ab


def condense_forces(system, r):
    """r <- T^T r on the free variables, zero on held DOFs (in place): a generalized force on the free space."""
    lk = system.links
    condense_vector(r, lk.tri_dep, lk.tri_master, lk.tri_coef, system.fixed)
    return r


def expand(system, delta):
    """delta <- T delta (in place): a step in the free variables (zero on held DOFs) as a step of q."""
    lk = system.links
    if lk.tri_dep.size:
        expand_step(delta, lk.tri_dep, lk.tri_master, lk.tri_coef)
    return delta


def evaluate_system(system, state, order, forces=None):
    """Energy; fills system.grad, system.fext (and system.ab with order 2). With contact terms their energy,
    gradient and band-local Hessian blocks are added, and their off-band Hessian triplets are left in
    ``system.contact_coo`` (a list of (rows, cols, vals); empty while no pair is active).

    ``forces``: a pair of arrays (n_edges, 3), (n_vertices,) for one rod; where the same pass computes them
    (``scene.edge_forces_in_pass``) they are filled with the edge forces and vertex moments of the load scale and
    returned as the second value, ``(energy, forces)``, else ``(energy, None)`` (``load_scales(..., forces)``)."""
    if system.parts is not None:          # several rods (multi.py)
        from . import multi

        energy = multi.evaluate_system(system, state, order)
        return energy if forces is None else (energy, None)
    if forces is not None and edge_forces_in_pass(system.plan, order):
        energy = evaluate(system.plan, state.q, state.d1, state.reference_twist, state.lam, order, system.grad,
                          system.fext, system.ab, system.kl, system.ku, system.perm, state.q_lo, forces[0],
                          forces[1])
        return energy + add_terms(system, state, order), forces
    energy = evaluate(system.plan, state.q, state.d1, state.reference_twist, state.lam, order, system.grad,
                      system.fext, system.ab, system.kl, system.ku, system.perm, state.q_lo)
    energy += add_terms(system, state, order)
    return energy if forces is None else (energy, None)


def evaluate_forces(system, state, forces):
    """``evaluate_system`` at order 1 with the load scale's edge forces and vertex moments in the same pass where
    it computes them: ``(energy, forces or None)`` (the implicit solver's residual pass, issue 17; ``forces`` is
    None for several rods, whose load scales come from multi.py)."""
    out = evaluate_system(system, state, 1, forces)
    return out if forces is not None else (out, None)


def add_terms(system, state, order):
    """The scene's contact terms at ``state``: their energy (returned), gradient into ``system.grad`` and, with
    order 2, band-local Hessian blocks into ``system.ab`` and off-band triplets into a fresh ``system.contact_coo``
    (one rod or several: the terms see the whole scene)."""
    energy = 0.0
    if system.terms:
        if order >= 2:
            system.contact_coo = []
        for term in system.terms:
            energy += term.evaluate(state, order, system.grad, system.ab, system.contact_coo)
    return energy


def contact_force_scale(system):
    """The largest contact force on a node at the last evaluation (0 without contact terms)."""
    return max((t.force_scale for t in system.terms), default=0.0)


def _edges_within_supports(system):
    """The edges whose two nodes are both held by the supports (every position coordinate fixed or a dependent of
    the end supports' links), as indices; cached for the system's current ``fixed`` and ``links``."""
    cached = getattr(system, "_held_edges", None)
    if cached is not None and cached[0] is system.fixed and cached[1] is system.links:
        return cached[2]
    rod = system.rod
    held_dof = system.fixed.copy()
    held_dof[system.links.dep] = True
    node = held_dof.reshape(-1, 4)[:, :3].all(axis=1)
    edges = np.flatnonzero(node[rod.edge_nodes[:, 0]] & node[rod.edge_nodes[:, 1]])
    system._held_edges = (system.fixed, system.links, edges)   # the objects themselves: no reused id()
    return edges


def load_scales(system, state, forces=None):
    """(F_s, M_s): force and moment scales of the residual (see module docstring). ``forces``: the edge forces
    and vertex moments at ``state`` when an evaluation already computed them (``evaluate_system``), else None."""
    if system.parts is not None:          # several rods (multi.py)
        from . import multi

        return multi.load_scales(system, state)
    rod, plan = system.rod, system.plan
    if forces is not None:
        F, M = forces
    else:
        F, M = _edge_forces(state.q, state.d1, state.reference_twist, state.lam, rod.edge_nodes, rod.vertex_nodes,
                            rod.vertex_edges, rod.l_bar, plan.k_stretch, plan.kappa_bar, rod.twist_bar, plan.weld,
                            rod.voronoi, plan.A1, plan.A2, plan.has_stretch, plan.has_bend, plan.has_twist,
                            state.q_lo)
    # an edge between two held nodes (a clamp's end edge) carries the support's reaction couple as a pair of forces
    # +-M/h: a moment, counted in m_int, not a force scale. Counted as one, it made F_s grow like n M / L, and a
    # clamped cantilever under a small tip load "converged" 13 % off at n = 20,000
    # (tests/test_verdicts.py::test_a_clamps_reaction_couple_does_not_set_the_force_scale). Those few rows are
    # zeroed for the maximum and put back (F may be a solver's work array; no copy of it at 10^6 edges).
    held = _edges_within_supports(system)
    kept = F[held].copy()
    F[held] = 0.0
    f_int = float(max_row_norm(F)) if F.size else 0.0
    F[held] = kept
    m_int = float(M.max()) if M.size else 0.0
    L = rod.length
    # internal forces no larger than their own round-off (rounding every edge by eps |e| -- compensated
    # coordinates, geometry.edge_array -- moves a node force by ~ eps |e| (A / h^3 + k) and a moment by
    # ~ eps |e| A / h^2) define no scale: an unloaded rod at rest would otherwise be judged against its round-off,
    # with a residual of order 1 for ever. (With |x| in place of |e| the internal forces of a rod far from the
    # origin counted as round-off, and its residual was judged against the applied load alone.)
    X = float(rod.l_bar.max())
    if state.q_lo is None:       # plain absolute coordinates (the explicit solver): rounded at |x|
        X = max(float(np.abs(state.q.reshape(-1, 4)[:, :3]).max()), rod.length)
    h = float(rod.l_bar.min())
    A = max(rod.bending_scale, rod.twisting_scale)
    eps100 = 100.0 * np.finfo(float).eps
    if f_int <= eps100 * X * (A / h ** 3 + float(plan.k_stretch.max(initial=0.0))):
        f_int = 0.0
    if m_int <= eps100 * X * A / h ** 2:
        m_int = 0.0
    F_raw = max(system.applied_force, f_int, contact_force_scale(system))   # contact forces are loads too
    M_raw = max(system.applied_moment, m_int)
    if F_raw == 0.0 and M_raw == 0.0:
        return rod.bending_scale / L ** 2, rod.bending_scale / L
    # a force scale implies a moment scale over the rod length and vice versa (e.g. a rod loaded only by
    # torques has no force of its own: round-off forces must not set the scale)
    return max(F_raw, M_raw / L), max(M_raw, F_raw * L)


def residual_vector(system, out=None):
    """R = T^T (f_ext - dE/dq) on the free DOFs (zero on held ones), from the last evaluation; written into
    ``out`` when given (a solver's work array, issue 17), else a new array."""
    if out is None:
        return condense_forces(system, system.fext - system.grad)
    return condense_forces(system, np.subtract(system.fext, system.grad, out=out))


def residual_norm(system, R, scales, per_length=False):
    """max_i |R_i| / S_i (the convergence measure), or per unit length with ``per_length``."""
    F_s, M_s = scales
    if not per_length and np.ndim(F_s) == 0 and np.ndim(M_s) == 0:
        # one rod's scales: one pass, no temporaries, bitwise max(|R| / where(is_theta, M_s, F_s))
        return float(_scaled_max(R, system.is_theta, float(F_s), float(M_s))) if R.size else 0.0
    s = np.where(system.is_theta, M_s, F_s)      # (several rods: scales per DOF)
    if per_length:
        s = s * system.weights
    return float(np.max(np.abs(R) / s)) if R.size else 0.0


@njit(cache=True)
def _scaled_max(R, is_theta, F_s, M_s):
    """max_i |R_i| / (M_s if is_theta[i] else F_s), NaN propagating as in np.max (``residual_norm``)."""
    m = abs(R[0]) / (M_s if is_theta[0] else F_s)
    for i in range(1, R.shape[0]):
        v = abs(R[i]) / (M_s if is_theta[i] else F_s)
        if v > m or v != v:
            m = v
            if v != v:
                return v
    return m


# rounding steps an edge passes through before it becomes a force (the edge itself, its length, the unit tangent,
# the curvature binormal's cross product and quotient, the material frame): the floor bound counts each edge's
# rounding this many times. Since the curvature binormal and the elongation are formed from the edges' low parts
# (stencils.curvature_binormal_of, stencils.elongation) the bound is pessimistic: ring torsion's measured noise is
# 1e-11 against bounds of 1e-7 to 1e-5 (tools/scaling.py, docs/scaling.md); it only matters once a solve stalls.
FLOOR_ROUNDINGS = 4.0


def rounding_scale(system, state, out=None):
    """Per DOF, the size of the rounding the force evaluation sees (length units for node DOFs, radians for
    angles): a node's positions enter only through the edges beside it (``geometry.edge_array``), each formed from
    compensated coordinates and so rounded at its own length -- the longest edge at the node --, an angle at its
    own size (at least 1 rad: the trigonometry of the frames rounds at eps absolute). A state without low parts
    (``q_lo`` None: the explicit solver's plain coordinates) is rounded at |x| per coordinate."""
    rod = system.rod
    if state.q_lo is None:
        # plain absolute coordinates (the explicit solver): each rounded at its own size
        w = np.maximum(np.abs(state.q), float(rod.l_bar.max()))
        w[3::4] = np.maximum(np.abs(state.q[3::4]), 1.0)
        return FLOOR_ROUNDINGS * w
    # one kernel pass into ``out`` (or a new array), the edges in the plan's work array: bitwise the NumPy
    # expressions it replaced (|e| summed (x^2 + y^2) + z^2, the node maximum, np.maximum's NaN rule), without
    # their seven n-sized temporaries (issue 17; tests/test_scale.py keeps them as the reference)
    E = edge_array_into(state.q, rod.edge_nodes, state.q_lo, False, system.plan.work_E)
    w = np.empty(rod.n_dof) if out is None else out
    _rounding_scale_into(E, rod.edge_nodes, rod.vertex_edges, state.q, state.reference_twist, rod.n_nodes,
                         FLOOR_ROUNDINGS, w)
    return w


@njit(cache=True)
def _rounding_scale_into(E, edge_nodes, vertex_edges, q, reference_twist, n_nodes, factor, w):
    """``rounding_scale`` of a state with low parts, into ``w``: per node the longest edge on it (columns 0-2 of
    ``E``), per angle max(|theta|, 1) and, where a vertex's reference twist enters, max(that, |twist|); times
    ``factor``."""
    node = np.zeros(n_nodes)
    for j in range(edge_nodes.shape[0]):
        v = np.sqrt((E[j, 0] * E[j, 0] + E[j, 1] * E[j, 1]) + E[j, 2] * E[j, 2])
        for s in range(2):
            k = edge_nodes[j, s]
            if v > node[k] or v != v:
                node[k] = v
    for k in range(n_nodes):
        for i in range(4):
            w[4 * k + i] = node[k]
    for k in range(n_nodes):
        a = abs(q[4 * k + 3])
        w[4 * k + 3] = a if (a > 1.0 or a != a) else 1.0          # np.maximum(|theta|, 1.0)
    for v in range(vertex_edges.shape[0]):
        i = 4 * vertex_edges[v, 1] + 3
        t = abs(reference_twist[v])
        if t > w[i] or t != t:                                      # np.maximum(w, |twist|)
            w[i] = t
    for i in range(w.shape[0]):
        w[i] = factor * w[i]


@njit(cache=True)
def _node_edge_max(le, edge_nodes, n_nodes):
    """Per node, the largest of ``le`` over the edges on it (0 on a node without edges; NaN propagates, as
    with ``np.maximum.at``)."""
    node = np.zeros(n_nodes)
    for j in range(edge_nodes.shape[0]):
        v = le[j]
        for s in range(2):
            k = edge_nodes[j, s]
            if v > node[k] or v != v:
                node[k] = v
    return node


def floor_forces(system, state, out=None):
    """eps |K| w per DOF (force units, zero on held DOFs): a bound on the generalized force change from the
    rounding of the state as the kernels see it, ``w = rounding_scale`` (each edge rounded at its own length, each
    angle at its size). Needs ``system.ab`` evaluated at ``state``. ``out``: an n_dof work array for the result (a
    solver's, reused; w is formed in it first), else a new one.

    (Before compensated coordinates, w was |q|: every coordinate rounded at its distance from the origin, a
    floor growing like eps n^3 A1 / (L^2 P) on a rod of fixed length, issue 17.)"""
    if out is None:
        out = np.empty(system.n_dof)
        w = rounding_scale(system, state)
    else:     # w formed in ``out`` itself: band_matvec reads its x (permuted into its own array) before it writes
        w = rounding_scale(system, state, out)
    band_matvec(system.ab, system.kl, system.ku, system.perm, w, out, True)
    lk = system.links
    condense_vector(out, lk.tri_dep, lk.tri_master, np.abs(lk.tri_coef), system.fixed)
    return np.multiply(np.finfo(float).eps, out, out=out)


def residual_floor(system, state, scales):
    """Round-off floor of the residual: eps |K| w (the force change from rounding the state as the kernels see
    it, ``floor_forces``), in residual units. With compensated coordinates it does not depend on where the rod
    is, and grows like eps n^2 A1 / (L^2 P) (a node force A1 / h^2 times the rounding of a unit tangent)."""
    return residual_norm(system, floor_forces(system, state), scales)


def potential_round_off(system, state, forces):
    """A bound on the rounding error of the potential E - f_ext . q as the implicit solver evaluates it at ``state``
    (energy units), from the edge forces and vertex moments of the same evaluation (``forces``: the second value of
    ``evaluate_forces``); None without them (several rods, contact terms: their energies come without edge forces)
    or without compensated coordinates. Each edge is formed from compensated coordinates to its own rounding
    eps |e_j| and each angle to eps max(|theta|, 1) (``rounding_scale``): the energy moves by at most
    |dE/de_j| eps |e_j| per edge and the vertex moment times eps max(|theta|, 1) per vertex, each rounding counted
    FLOOR_ROUNDINGS times; the load work f_ext . q, formed on the high parts of q, by eps |f_ext| |q|. A fall of
    the potential by more than this at both of its ends is the potential's own, whatever forces chose the step."""
    if forces is None or state.q_lo is None:
        return None
    F, M = forces
    rod = system.rod
    return float(np.finfo(float).eps * _potential_rounding(F, M, state.q, system.fext, rod.edge_nodes,
                                                           rod.vertex_edges, FLOOR_ROUNDINGS))


@njit(cache=True)
def _potential_rounding(F, M, q, fext, edge_nodes, vertex_edges, roundings):
    """roundings (sum_j |F_j| |e_j| + sum_v M_v max(1, |theta_a|, |theta_b|)) + sum_i |f_ext,i| |q_i|
    (``potential_round_off``)."""
    s = 0.0
    for j in range(edge_nodes.shape[0]):
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        e2 = 0.0
        f2 = 0.0
        for i in range(3):
            d = q[b + i] - q[a + i]
            e2 += d * d
            f2 += F[j, i] * F[j, i]
        s += np.sqrt(f2 * e2)
    for v in range(M.shape[0]):
        ta = abs(q[4 * vertex_edges[v, 0] + 3])
        tb = abs(q[4 * vertex_edges[v, 1] + 3])
        s += M[v] * max(1.0, ta, tb)
    w = 0.0
    for i in range(q.shape[0]):
        w += abs(fext[i]) * abs(q[i])
    return roundings * s + w


def newton_steps(system, state, rhs):
    """Newton corrections K^-1 r for the columns of ``rhs`` (n_dof, k) at ``state`` (one factorisation; needs
    ``system.ab`` evaluated at ``state``), on the free variables of the constraints and expanded to q. Symmetry
    modes of the scene (rigid motions of a free rod, ...) are projected out of the right-hand sides and the
    corrections (they carry no error) and regularised by 1e-14 |K_ii|. Returns None if the factorisation fails."""
    from ..linalg import add_diagonal, band_solve
    from .stability import symmetry_modes

    rhs = np.array(rhs, dtype=float).reshape(system.n_dof, -1)
    # several rods: no symmetry analysis yet (check_stability refuses them); the 1e-14 shift below regularises
    modes = symmetry_modes(system, state) if system.parts is None else []
    Q = np.linalg.qr(np.array(modes).T)[0] if modes else None
    if Q is not None:
        rhs = rhs - Q @ (Q.T @ rhs)
    ab = system.ab.copy(order="F")
    diag = np.abs(ab[system.kl + system.ku, :][system.perm])
    diag[diag == 0] = 1.0
    add_diagonal(ab, system.kl, system.ku, system.perm, diag, 1e-14)   # regularises the symmetry modes
    constrain_system(system, ab, 1.0)
    coo = getattr(system, "contact_coo", None)
    if coo:
        # contact couples DOFs off the band: the implicit solver's sparse path (band + contact triplets)
        from .implicit import _contact_solve
        cols = [_contact_solve(system, ab.copy(order="F"), coo, np.ascontiguousarray(rhs[:, c]))
                for c in range(rhs.shape[1])]
        if any(info != 0 for _, info in cols):
            return None
        delta = np.column_stack([x for x, _ in cols])
    else:
        ldlt = getattr(system, "ldlt", None)
        delta, info = band_solve(ab, system.kl, system.ku, system.perm, rhs, ldlt=ldlt)
        if ldlt is not None:
            ldlt.release()      # its L may be a view of this copy's spare rows: do not keep the whole copy alive
        if info != 0:
            return None
    if not np.all(np.isfinite(delta)):
        return None
    for c in range(delta.shape[1]):
        col = np.ascontiguousarray(delta[:, c])
        expand(system, col)
        delta[:, c] = col
    if Q is not None:
        delta = delta - Q @ (Q.T @ delta)
    return delta


def step_size(system, delta):
    """max over node positions and (times the rod length) edge angles of |delta|: a step's size in length units."""
    rod = system.rod
    d = delta.reshape(-1, 4)
    return max(float(np.abs(d[:, :3]).max()), rod.length * float(np.abs(d[:rod.n_edges, 3]).max()))


def newton_error_estimate(system, state):
    """Size of the Newton correction K^-1 R at ``state`` relative to the displacement from the rest shape
    (max norm over node positions and, times the rod length, edge angles): an estimate of the error left,
    dominated by the slowest modes. Rigid-body and other symmetry modes of an unconstrained rod are projected
    out (they carry no error)."""
    evaluate_system(system, state, 2)
    delta = newton_steps(system, state, residual_vector(system))
    if delta is None:
        return np.inf
    rod = system.rod
    L = rod.length
    u = state.q.reshape(-1, 4) - rod.rest_q.reshape(-1, 4)
    ne = rod.n_edges
    scale = max(float(np.abs(u[:, :3]).max()), L * float(np.abs(u[:ne, 3]).max()), 1e-300)
    return step_size(system, delta[:, 0]) / scale


# A verdict at the floor also needs the Newton correction K^-1 R -- the error the linearised problem still sees --
# to be within tol of the displacement from the rest shape (or of the shortest edge, for a rod that hardly moves):
# the state is then as accurate as a solve converged to tol. A residual under the floor bound alone certified a
# ring of 10^4 edges whose Newton correction was 2.5 % of its displacement (error 27 % against the closed form,
# issue 11). FLOOR_STEP_MIN: the smallest relative correction asked for whatever tol (edges are rounded at
# eps |e|, and a correction of a few hundred eps of the displacement is all the arithmetic resolves).
FLOOR_STEP_MIN = 1e-13


def newton_correction(system, state):
    """(correction, scale): the size of the Newton correction K^-1 R at ``state`` and the displacement it is
    judged against, max(displacement from the rest shape, shortest rest edge), both by ``step_size`` (length
    units). Needs ``system.ab`` and the residual evaluated at ``state``; (inf, scale) if the factorisation
    fails."""
    rod = system.rod
    u = state.q - rod.rest_q
    scale = max(step_size(system, u), float(rod.l_bar.min()))
    delta = _edge_newton_correction(system, state)
    if delta is None:
        delta = newton_steps(system, state, residual_vector(system))
        if delta is None:
            return np.inf, scale
        delta = delta[:, 0]
    return step_size(system, delta), scale


def _edge_newton_correction(system, state):
    """K^-1 R in edge coordinates (``edge_coordinates.EdgeNewton``) for the scenes they apply to, else None. In node
    coordinates the correction of a fine inextensible rod is itself round-off (condition ~ (L/h)^4): at 3x10^4 edges
    a ring torsion state with error 1.1e-5 (against its discretisation's 6.2e-6) had a node-coordinate correction
    small enough to certify it "converged_at_floor" (issue 11; tests/test_verdicts.py)."""
    from .edge_coordinates import EdgeNewton, edge_eligible

    if not edge_eligible(system) or has_symmetry_modes(system, state):
        return None
    edge = EdgeNewton(system, state)
    if not edge.prepare(system.ab, system.kl, system.ku):
        return None
    delta, info = edge.step(system.fext - system.grad, np.inf)
    if info != 0 or not np.all(np.isfinite(delta)):
        return None
    delta = delta + edge.step_lo
    delta[system.fixed] = 0.0
    expand(system, delta)
    return delta


def has_symmetry_modes(system, state):
    """Whether the scene has symmetry modes (``stability.symmetry_modes``), which the edge path does not remove."""
    from .stability import symmetry_modes

    return len(symmetry_modes(system, state)) > 0


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
    residual is below FLOOR_FACTOR times the round-off floor, that floor is below FLOOR_MAX (a larger bound
    means the estimate certifies nothing), and the Newton correction K^-1 R is within max(tol, FLOOR_STEP_MIN) of
    the displacement (``newton_correction``); "stalled" otherwise.
    Needs ``system.ab`` evaluated at ``state``."""
    floor = residual_floor(system, state, scales)
    if residual <= FLOOR_FACTOR * floor and floor < FLOOR_MAX:
        step, scale = newton_correction(system, state)
        limit = max(tol, FLOOR_STEP_MIN)
        if step <= limit * scale:
            return "converged_at_floor", floor, (
                f"converged at the round-off floor, above tol: residual {residual:.2e} is {residual / tol:.3g} "
                f"times tol {tol:.1e}, below the floor {floor:.1e} of double precision, and the Newton correction "
                f"is {step / scale:.1e} of the displacement (at most {limit:.0e}); {what}")
        return "stalled", floor, (
            f"residual stuck at {residual:.2e} (tol {tol:.1e}) below the round-off floor bound {floor:.1e}, but the "
            f"Newton correction is {step / scale:.1e} of the displacement (more than {limit:.0e}): the state is not "
            f"at its round-off floor; {what}")
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


def raise_if_interrupted(result):
    """Pass a Ctrl-C on from a solve that der itself started; returns ``result`` otherwise.

    ``der.solve`` answers Ctrl-C with a result whose status is "interrupted" (the last state kept, the recording
    closed); a caller inside der (the compilation warm-up, a continuation step, a scenario script's next solve)
    must stop there too rather than take it for a step that merely failed and go on (the warm-up did: a Ctrl-C
    during a first, compiling run was lost and the solve after it ran to the end)."""
    if result.status == "interrupted":
        raise KeyboardInterrupt
    return result


def final_result(system, state, status, **fields):
    """The SolveResult of a solve that ended in ``status`` at ``state``: the force-derived fields (load scale,
    residual per unit length, energy by term) are evaluated here, once, for both solvers."""
    hessian = fields.pop("hessian", False)
    if system.parts is not None:          # several rods (multi.py)
        from . import multi

        return multi.final_result(system, state, status, **fields)
    from .options import CONVERGED_STATUSES, SolveResult

    # hessian=True (a stability analysis follows a converged solve): the force evaluation also assembles the band,
    # the Hessian at the final state, which the analysis then takes instead of assembling it again (the forces of
    # an order-2 pass are bitwise those of an order-1 pass: scene.evaluate)
    hessian = hessian and status in CONVERGED_STATUSES and not system.terms
    system.hessian_at = None
    if hessian:
        t0, c0 = time.perf_counter(), time.process_time()
        evaluate_system(system, state, 2)
        system.hessian_at = (state, state.q.copy(), state.lam.copy(), time.perf_counter() - t0,
                             time.process_time() - c0)
    else:
        evaluate_system(system, state, 1)
    scales = load_scales(system, state)
    if status in CONVERGED_STATUSES and not np.isfinite(scales).all():
        # a residual relative to an infinite scale is 0 whatever the forces: no verdict can rest on it
        status = "nonfinite"
        fields["message"] = f"the force scale became non-finite ({scales[0]:.3g}, {scales[1]:.3g}); no verdict"
    per_length = residual_norm(system, residual_vector(system), scales, per_length=True)
    fields.setdefault("reactions", support_reactions(system, state))
    return SolveResult(state=state, converged=status in CONVERGED_STATUSES, status=status, load_scale=float(scales[0]),
                       energy=energy_terms(system, state), residual_per_length=per_length, **fields)


def take_hessian(system, state):
    """(wall, CPU) seconds its assembly took if ``system.ab`` holds the Hessian at ``state``, assembled by
    ``final_result`` and untouched since (same state object, same coordinates and multipliers), else None. Either
    way the band is no longer marked as that Hessian (the caller condenses or factorises it)."""
    tok = getattr(system, "hessian_at", None)
    system.hessian_at = None
    if tok is None or tok[0] is not state or not np.array_equal(tok[1], state.q) or not np.array_equal(
            tok[2], state.lam):
        return None
    return tok[3], tok[4]


def support_reactions(system, state):
    """The reaction of every constraint at ``state``, from the last order >= 1 evaluation (``system.grad`` and
    ``system.fext`` at ``state``): a list of dicts, one per constraint in the scene's order, with

    ``support`` ("clamp", "hinge", "roller", "pin", "fix_theta"), ``end`` ("start"/"end") or ``node`` or
    ``edge``, ``at`` (the point the moment is taken about: the end cross-section's centre, the pinned node, the
    edge midpoint), ``force`` and ``moment`` (3-vectors, lab frame: what the support exerts ON the rod).

    A support's reaction is the generalized force its constraint adds so that the rod is in equilibrium,
    ``grad E - f_ext`` on the entries it acts on (the two nodes of the end edge and, for a clamp, the end angle
    theta, whose generalized force is the moment about the end tangent). Its moment about ``at`` is
    ``sum (x_k - at) x f_k + f_theta t``. Because the elastic energy does not change under rigid motions, the
    reactions and the loads balance exactly (to the residual), forces and moments; and since ``at`` is the
    end cross-section itself the moment needs no transport (second order like the solution). Two constraints
    on the same node both report the force on it."""
    from ..constraints import Clamp, EndSupport, FixTheta, Pin, end_centre, support_dofs

    rod = system.rod
    f = system.grad - system.fext
    x = state.positions
    out = []
    for c in system.scene.constraints:
        nodes, edge = support_dofs(rod, c)
        if isinstance(c, (Clamp, EndSupport)):
            at = end_centre(x, rod, c.end)
            entry = {"support": "clamp" if isinstance(c, Clamp) else c.kind, "end": c.end}
        elif isinstance(c, Pin):
            at = x[nodes[0]].copy()
            entry = {"support": "pin", "node": int(nodes[0])}
        elif isinstance(c, FixTheta):
            a, b = rod.edge_nodes[edge]
            at = 0.5 * (x[a] + x[b])
            entry = {"support": "fix_theta", "edge": int(edge)}
        else:
            continue
        force = np.zeros(3)
        moment = np.zeros(3)
        for k in nodes:
            fk = f[4 * k:4 * k + 3]
            force += fk
            moment += np.cross(x[k] - at, fk)
        if edge is not None:
            moment += f[4 * edge + 3] * state.tangents[edge]
        entry.update(at=at, force=force, moment=moment)
        out.append(entry)
    return out


def state_edges(system, state, lo=False):
    """The edge vectors of ``state`` (n_edges, 3), from its compensated positions (``geometry.edge_array``); with
    ``lo`` (n_edges, 6), the edges' exact low parts in columns 3-5."""
    return edge_array(state.q, system.rod.edge_nodes, state.q_lo, lo)


def state_elongations(system, state):
    """g_j = |e_j| - l_j of ``state``'s edges (compensated positions)."""
    rod = system.rod
    # the edges in the plan's work array (not a fresh (n_edges, 6) array per call, issue 17)
    E = edge_array_into(state.q, rod.edge_nodes, state.q_lo, True, system.plan.work_E)
    return elongations(state.q, rod.edge_nodes, rod.l_bar, E)


def max_strain(system, state):
    if system.parts is not None:          # several rods (multi.py)
        from . import multi

        return multi.max_strain(system, state)
    rod = system.rod
    return float(np.max(np.abs(state_elongations(system, state) / rod.l_bar)))


def constraint_residual(system, state, scales):
    """The elongation left in an inextensible rod as a residual (same units as ``residual_norm``): the force
    k_j |g_j| a multiplier update would shift, relative to the force scale."""
    if system.parts is not None:          # several rods (multi.py)
        from . import multi

        return multi.constraint_residual(system, state, scales)
    g = state_elongations(system, state)
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
    if system.parts is not None:          # several rods (multi.py)
        from . import multi

        return multi.multiplier_update(system, state, previous)
    g = state_elongations(system, state)
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
    """Put ``q_new`` into ``out`` with frames transported from ``base``; False if an edge reversed/vanished.
    ``q_new`` may be ``out.q`` itself, already set with its low parts ``out.q_lo`` (a compensated step,
    ``geometry.add_compensated``); any other ``q_new`` comes without low parts (``out.q_lo`` is zeroed)."""
    if system.parts is not None:          # several rods (multi.py)
        from . import multi

        return multi.transport(system, base, q_new, out)
    rod = system.rod
    if q_new is not out.q:
        out.q[:] = q_new
        if out.q_lo is not None:
            out.q_lo[:] = 0.0
    if out is not base:
        out.lam[:] = base.lam
    try:
        # the edges in the plan's work array (columns 0-2; transport_frames reads no more)
        E = edge_array_into(out.q, rod.edge_nodes, out.q_lo, False, system.plan.work_E)
        ok = transport_frames(out.q, rod.edge_nodes, rod.vertex_edges, base.tangents, base.d1, base.reference_twist,
                              out.tangents, out.d1, out.reference_twist, E)
    except ZeroDivisionError:
        # a director transported onto its own tangent (a step that turned an edge by ~pi, or a vanishing edge):
        # a failed step like a reversed edge, not an exception out of the solve
        return False
    return bool(ok)


def prepare_state(system, state):
    """A working copy of ``state`` with constraint targets applied and frames consistent with positions."""
    rod = system.rod
    work = state.copy()
    if work.q_lo is None or work.q_lo.shape != work.q.shape:
        work.q_lo = np.zeros_like(work.q)       # compensated positions from here on (geometry.edge_array)
    work.penalty = system.k_stretch.copy()
    if work.lam.size != rod.n_edges:
        work.lam = np.zeros(rod.n_edges)
    if not rod.inextensible:
        work.lam[:] = 0.0
    if not rod.closed:
        work.q[4 * rod.n_nodes - 1] = 0.0
    base = work.copy()
    directors = apply_targets(rod, work, system.scene.constraints)
    work.q_lo[system.fixed] = 0.0               # held coordinates are their targets, exactly
    if not transport(system, base, work.q, work):
        raise ValueError("the prescribed constraint targets reverse an edge in one step; "
                         "move the clamp in smaller increments (continuation)")
    set_clamp_angles(work, directors)
    update_links(system, work)
    work.q_lo[system.fixed] = 0.0
    if system.links.dep.size:
        enforce_links(work.q, system.links)
        work.q_lo[system.links.dep] = 0.0
        base = work.copy()
        transport(system, base, work.q, work)
    return work


def set_clamp_angles(state, directors):
    """Set theta of each clamped end edge so that its material director is the prescribed one: ``directors`` is
    a list of (edge, m1 target) (``constraints.apply_targets``), the frames of ``state`` already transported to
    its positions; the branch nearest the current theta is taken (an end turned a little at a time keeps count of
    its full turns)."""
    for j, m1 in directors:
        (t0, t1, t2), (a0, a1, a2), (m0, m1_, m2) = state.tangents[j].tolist(), state.d1[j].tolist(), m1.tolist()
        # d2 = t x d1
        target = np.arctan2(m0 * (t1 * a2 - t2 * a1) + m1_ * (t2 * a0 - t0 * a2) + m2 * (t0 * a1 - t1 * a0),
                            m0 * a0 + m1_ * a1 + m2 * a2)
        current = state.q[4 * j + 3]
        state.q[4 * j + 3] = current + (target - current + np.pi) % (2 * np.pi) - np.pi


def start_moving_supports(system, state):
    """Lay the end supports' links out for ``move_supports`` at the prepared ``state`` (once, at the start of a
    simulation whose supports move): every admissible coupling gets a slot, so that later steps recompute the
    links' numbers in place."""
    patterns = []
    fixed, links = build_links(system.rod, system.scene.constraints, state, pattern=patterns)
    system.fixed, system.free, system.links, system.link_patterns = fixed, ~fixed, links, patterns
    system.mass = condensed_mass(system)
    system.link_builds += 1


def move_supports(system, base, q, out, constraints):
    """Moving supports (dynamics): put the positions ``q`` into ``out`` with the targets of the support records
    ``constraints`` applied, the end supports' links recomputed there in place (``constraints.refresh_links``;
    built afresh only if their layout no longer fits, counted in ``system.link_builds``), the dependents set
    from them, the frames transported from ``base`` and the clamped end angles set. No scene or system is
    rebuilt: ``constraints`` has the kinds, ends and free directions of the system's own records, only their
    rotations and positions move. False if the frame transport failed (an edge reversed)."""
    rod = system.rod
    out.q[:] = q
    if out.q_lo is not None:
        out.q_lo[:] = 0.0
    directors = apply_targets(rod, out, constraints)
    patterns = getattr(system, "link_patterns", None)
    if patterns is None or not refresh_links(rod, system.links, patterns, constraints, out.q):
        patterns = []
        fixed, links = build_links(rod, constraints, out, pattern=patterns)
        system.fixed, system.free, system.links, system.link_patterns = fixed, ~fixed, links, patterns
        system.link_builds += 1
    system.mass = condensed_mass(system)
    enforce_links(out.q, system.links)
    if not transport(system, base, out.q, out):
        return False
    set_clamp_angles(out, directors)
    return True


def energy_terms(system, state):
    """Energy of each term the scene uses, plus the work of the constant generalized loads."""
    if system.parts is not None:          # several rods (multi.py)
        from . import multi

        return multi.energy_terms(system, state)
    from ..energies.bend import bend_energy
    from ..energies.stretch import stretch_energy
    from ..energies.twist import twist_energy

    rod, plan = system.rod, system.plan
    out = {}
    if plan.has_stretch:
        out["stretch"] = float(stretch_energy(state.q, rod.edge_nodes, rod.l_bar, plan.k_stretch, state.lam,
                                              state_edges(system, state, lo=True)))
    if plan.has_bend:
        ed = edge_frames(state.q, rod.edge_nodes, state.d1, state_edges(system, state, lo=True))
        out["bend"] = float(bend_energy(ed, rod.vertex_edges, plan.weld, plan.kappa_bar, rod.voronoi, plan.A1))
    if plan.has_twist:
        out["twist"] = float(twist_energy(state.q, rod.vertex_edges, state.reference_twist, plan.weld, rod.twist_bar,
                                          rod.voronoi, plan.A2))
    if system.terms:
        out["contact"] = float(sum(t.evaluate(state, 0, None, None, None) for t in system.terms))
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
        f, tau, follower = load.net(rod)
        if f is not None:
            net_force += f
            total += safe_norm(f)
            if np.any(f != 0.0):
                conservative_torques_only = False    # forces have a moment that depends on the configuration
        if tau is not None:
            net_torque += tau
            torque_total += safe_norm(tau)
        if follower:
            conservative_torques_only = False        # follower moments turn with the rod
    what = "an unconstrained rod" if not fixed.any() else None
    bad = [u for u in free_translations(system) if abs(u @ net_force) > 1e-12 * total]
    if bad:
        names = ["xyz"[int(np.argmax(np.abs(u)))] if np.abs(u).max() > 1 - 1e-12 else _fmt_vector(u) for u in bad]
        where = what or f"a rod whose constraints cannot react along {', '.join(names)}"
        raise ValueError(f"net applied force {_fmt_vector(net_force)} on {where}: no static equilibrium exists "
                         "(add a clamp or pin that can react, or balance the loads)")
    if conservative_torques_only and torque_total > 0.0:
        bad = [a for a in range(3) if abs(net_torque[a]) > 1e-12 * torque_total
               and _rotation_is_free(system, state, fixed, a)]
        if bad:
            where = what or f"a rod whose constraints leave it free to rotate about {', '.join('xyz'[a] for a in bad)}"
            raise ValueError(f"net applied torque {_fmt_vector(net_torque)} on {where}, with no force to balance "
                             "it: no static equilibrium exists (add a clamp, or balance the torques)")


def _violation(system, v):
    """How far the motion ``v`` (n_dof) breaks the constraints: its entries on plainly held DOFs and, on the end
    supports' dependents, v_d - sum a v_m (a motion the supports allow has q = c + T y, so v = T y)."""
    lk = system.links
    held = system.fixed.copy()
    if not system.rod.closed:
        held[4 * system.rod.n_nodes - 1] = False     # the dummy slot is not a constraint
    held[lk.dep] = False
    linked = v[lk.dep].astype(float)
    pos = {int(d): i for i, d in enumerate(lk.dep)}
    for d, m, a in zip(lk.tri_dep, lk.tri_master, lk.tri_coef):
        linked[pos[int(d)]] -= a * v[m]
    return np.concatenate([v[held], linked])


def free_translations(system):
    """Orthonormal rows (k, 3): the rigid translations the constraints leave free (for a roller along a line
    not on a coordinate axis, that line's direction)."""
    rod = system.rod
    C = []
    for a in range(3):
        v = np.zeros(rod.n_dof)
        v.reshape(-1, 4)[:, a] = 1.0
        if not rod.closed:
            v[4 * rod.n_nodes - 1] = 0.0
        C.append(_violation(system, v))
    C = np.array(C).T
    if C.size == 0:
        return np.eye(3)
    _, sv, vt = np.linalg.svd(C)
    rank = int(np.sum(sv > 1e-12 * max(sv.max(initial=0.0), 1.0)))
    U = vt[rank:]
    U[np.abs(U) < 1e-12] = 0.0
    return U * np.where(U[np.arange(len(U)), np.argmax(np.abs(U), axis=1)] < 0, -1.0, 1.0)[:, None]


def _rotation_is_free(system, state, fixed, a):
    """Whether a rigid rotation about coordinate axis ``a`` -- about the one pinned node or the one end support's
    centre, or the centroid -- moves no held DOF and keeps the end supports' links (the centre used by
    ``stability.symmetry_modes``)."""
    from ..constraints import END_SUPPORTS, end_centre

    rod = system.rod
    x = state.positions
    supports = [c for c in system.scene.constraints if isinstance(c, END_SUPPORTS)]
    held = fixed.copy()
    held[system.links.dep] = False
    pinned = np.flatnonzero(held.reshape(-1, 4)[:, :3].all(axis=1))   # (no Python loop over nodes: issue 17)
    if len(supports) == 1 and pinned.size == 0:
        centre = end_centre(x, rod, supports[0].end)
    else:
        centre = x[pinned[0]] if len(pinned) == 1 else x.mean(axis=0)
    w = np.zeros(3)
    w[a] = 1.0
    v = np.zeros(rod.n_dof)
    v.reshape(-1, 4)[:, :3] = np.cross(w, x - centre)
    v[4 * np.arange(rod.n_edges) + 3] = state.tangents @ w
    if not rod.closed:
        v[4 * rod.n_nodes - 1] = 0.0
    return bool(np.abs(_violation(system, v)).max(initial=0.0) < 1e-12 * np.abs(v).max())


# constraint tension against the larger of the bending scale A1/L^2 and the applied load scale above which an
# inextensible rod held at both ends is reported locked: at T = 100 A1/L^2 the boundary layers at the clamps are
# L/10 wide (sqrt(A1/T)); an Euler-buckled rod between clamps carries 4 pi^2 A1/L^2 ~ 40
LOCK_RATIO = 100.0


def locked_rod_note(system, state):
    """A note (or "") for an inextensible open rod whose two end nodes are held in place and whose constraint
    tension is more than LOCK_RATIO times both its bending scale A1 max(1/L^2, kappa0^2) and its applied loads: the rod cannot
    bend without changing its chord, so its multipliers grow until they pull it straight with boundary layers at
    the ends -- the true inextensible limit, but not the beam theory a user may expect."""
    rod = system.rod
    if not rod.inextensible or rod.closed:
        return ""
    fixed = system.fixed
    if not (fixed[0:3].all() and fixed[4 * (rod.n_nodes - 1):4 * (rod.n_nodes - 1) + 3].all()):
        return ""
    g = state_elongations(system, state)
    tension = float(np.abs(state.lam + system.k_stretch * g).max())
    L = rod.length
    # the bending scale: A1 times the larger of 1/L^2 and the natural curvature squared (a naturally curved rod,
    # a helix stretched between clamps, carries a tension of order A1 kappa0^2 without being locked)
    kappa0 = float(np.abs(rod.kappa_bar).max(initial=0.0)) * rod.n_edges / L   # kappa_bar is integrated
    bending = float(np.max(rod.A1)) * max(1.0 / L ** 2, kappa0 ** 2)
    loads = system.applied_force + system.applied_moment / L
    if not tension > LOCK_RATIO * max(bending, loads):
        return ""
    return (f"the inextensible rod is locked between fixed ends; give it EA or a sliding clamp (its constraint "
            f"tension {tension:.3g} is {tension / bending:.3g} times the bending scale A1 max(1/L^2, kappa0^2) = {bending:.3g}, "
            f"and its loads apply at most {loads:.3g})")


def numerical_failure(system, state, start, exc, solver):
    """The SolveResult of a solve that a numerical error ended (a division by zero or a failed factorisation
    inside a kernel, e.g. dependent constraints: an inextensible rod held straight between two fixed nodes has
    an indeterminate tension): status "nonfinite", the state the solver was at if it is finite (else the start),
    never an exception from inside the solve."""
    if solver == "explicit" and system.rod.inextensible:
        system.plan.k_stretch[:] = system.k_initial    # the projected explicit solve zeroes the penalty
        state.penalty = system.k_initial.copy()
    finite = all(np.isfinite(a).all() for a in (state.q, state.d1, state.reference_twist, state.lam))
    kept = state if finite else start
    try:
        evaluate_system(system, kept, 1)
    except ArithmeticError:            # finite, but degenerate (an edge collapsed): back to the start
        kept, finite = start, False
        evaluate_system(system, kept, 1)
    residual = residual_norm(system, residual_vector(system), load_scales(system, kept))
    return final_result(system, kept, "nonfinite", residual=float(residual), iterations=0, wall_time=0.0,
                        message=f"numerical failure in the {solver} solver ({type(exc).__name__}: {exc}); "
                        f"{'the last' if finite else 'the starting'} finite state is kept (dependent constraints, "
                        "e.g. an inextensible rod held straight between fixed nodes, make its tension "
                        "indeterminate: give it EA)", solver=solver)
