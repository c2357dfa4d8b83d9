"""A scene: a rod plus the energy terms, loads and constraints it names; nothing else is evaluated.

``Scene`` is plain data. ``make_plan`` turns it into flat arrays (a numba-friendly named tuple) and
``evaluate`` is the one kernel both solvers call: it runs exactly the terms the plan lists, and counts how
often each one ran (``plan.counters``), so that "a scene pays only for what it needs" can be checked.
"""
from collections import namedtuple
from dataclasses import dataclass

import numpy as np
from numba import njit

from . import constraints as _constraints
from .energies.bend import bend_energy, bend_gradient, bend_hessian
from .energies.stretch import stretch_energy, stretch_gradient, stretch_hessian
from .energies.twist import twist_energy, twist_gradient, twist_hessian
from .energies.vertex import bend_twist_hessian, stretch_bend_twist_gradient, stretch_bend_twist_hessian
from .geometry import add_transport_jacobian, edge_array_into, edge_frames
from .linalg import zero_band
from .loads import (
    LoadSums, add_dead_torques, add_follower_forces, add_follower_torques, add_nodal_forces, add_theta_moments,
    check_load,
)
from .rod import Rod

ENERGY_TERMS = ("stretch", "bend", "twist")
# slots of plan.counters
COUNTER_NAMES = ("stretch", "bend", "twist", "transport_jacobian", "nodal_forces", "theta_moments", "dead_torques",
                 "follower_forces", "follower_torques")


@dataclass(frozen=True, eq=False)
class Scene:
    """A rod with the energy terms, loads and constraints it uses.

    Parameters
    ----------
    rod : der.Rod, or a sequence of der.Scene (several rods)
        One rod; or, for a scene of several rods, one single-rod ``der.Scene`` per rod, each with its own energies,
        loads and constraints (a bare ``der.Rod`` in the list stands for ``der.Scene(rod)``). The outer scene then
        takes only ``contacts``: ``der.rod_contact(r)`` (between the rods and within each), obstacles. Its DOFs
        are the rods' concatenated (rod after rod); without a coupling term each rod solves on its own band.
    energies : tuple of str
        Any of "stretch", "bend", "twist" (default: all three).
    loads : sequence
        ``der.point_force``, ``der.end_force``, ``der.distributed_force``, ``der.end_torque``,
        ``der.twisting_moment``, ``der.point_torque``, ``der.follower_force`` records.
    constraints : sequence
        ``der.clamp``, ``der.hinge``, ``der.roller``, ``der.pin``, ``der.fix_theta`` records.
    contacts : sequence
        Contact terms (issue 14): ``der.self_contact(radius)``, ``der.plane(point, normal)``,
        ``der.sphere(centre, R)``, ``der.cylinder(point, axis, R)`` (registered in ``der.terms``; their energy is
        added to the rod's). A scene without them loads no contact code and solves exactly as before.

    Everything is checked here, before any work: an unknown load or constraint, a node out of range, an end
    load on a ring, conflicting pins raise a ValueError (or TypeError) naming the argument. Loads act in the
    global frame unless they are follower loads (``end_torque(..., follower=True)``, ``twisting_moment``).

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.helix(kappa0=1.0, omega0=0.6, turns=1, n=50), A1=1.0, A2=1.5)
    >>> scene = der.Scene(rod, loads=[der.end_force([0, 0, 1e-3])], constraints=[der.clamp("start")])
    >>> result = der.solve(scene)
    >>> result.converged
    True

    Several rods (``result.states[i]`` is rod i's state, ``result.rods[i]`` its energy and reactions):

    >>> x_b = der.shapes.straight(1.0, 20).positions + [0.5, 0.0, 0.0]      # a second rod beside the first
    >>> rod_b = der.rod_from_shape(der.shapes.Shape(x_b, director=[1, 0, 0]), A1=1.0, A2=1.5)
    >>> two = der.Scene([scene, der.Scene(rod_b, constraints=[der.clamp("start")])],
    ...                 contacts=[der.rod_contact(0.01)])
    >>> len(der.solve(two).states)
    2
    """

    rod: Rod
    energies: tuple = ENERGY_TERMS
    loads: tuple = ()
    constraints: tuple = ()
    contacts: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "scenes", None)
        if isinstance(self.rod, (list, tuple)):
            self._init_several()
            return
        if not isinstance(self.rod, Rod):
            raise ValueError(f"rod must be a der.Rod (see der.rod_from_shape); got {type(self.rod).__name__}")
        object.__setattr__(self, "energies", tuple(self.energies))
        object.__setattr__(self, "loads", tuple(self.loads))
        object.__setattr__(self, "constraints", tuple(self.constraints))
        for name in self.energies:
            if name not in ENERGY_TERMS:
                raise ValueError(f"unknown energy term {name!r}; allowed: {', '.join(ENERGY_TERMS)}")
        if len(set(self.energies)) != len(self.energies):
            raise ValueError(f"energy terms listed twice: {self.energies}")
        for load in self.loads:
            _check_load(self.rod, load)
        _constraints.validate(self.rod, self.constraints)
        object.__setattr__(self, "contacts", tuple(self.contacts))
        if self.contacts:
            from .terms import check_term

            for term in self.contacts:
                check_term(term, self)

    def _init_several(self):
        """A scene of several rods: the sub-scenes in ``scenes``, ``rod`` None; checked before any work."""
        parts = []
        for i, part in enumerate(self.rod):
            if isinstance(part, Rod):
                part = Scene(part)
            if not isinstance(part, Scene) or part.scenes is not None:
                raise ValueError(f"der.Scene: rod {i} of the list must be a der.Rod or a single-rod der.Scene; got "
                                 f"{type(part).__name__ if not isinstance(part, Scene) else 'a scene of several rods'}")
            if part.contacts:
                raise ValueError(f"der.Scene: the scene of rod {i} has contacts; give a scene of several rods its "
                                 "contact terms on the outer scene (der.Scene([...], contacts=[der.rod_contact(r)]))")
            parts.append(part)
        if not parts:
            raise ValueError("der.Scene: the list of rods is empty")
        if tuple(self.energies) != ENERGY_TERMS or self.loads or self.constraints:
            raise ValueError("der.Scene: a scene of several rods takes energies, loads and constraints per rod (in "
                             "each rod's der.Scene), only contacts on the outer scene")
        object.__setattr__(self, "scenes", tuple(parts))
        object.__setattr__(self, "rod", None)
        object.__setattr__(self, "energies", ())
        object.__setattr__(self, "loads", ())
        object.__setattr__(self, "constraints", ())
        object.__setattr__(self, "contacts", tuple(self.contacts))
        if self.contacts:
            from .terms import check_term

            for term in self.contacts:
                check_term(term, self)

    @property
    def rods(self):
        """The scene's rods: ``(rod,)`` for one rod, one per sub-scene for several."""
        return (self.rod,) if self.scenes is None else tuple(s.rod for s in self.scenes)

    @property
    def fixed(self):
        """Boolean mask of the state entries held by constraints."""
        return _constraints.fixed_dofs(self.rod, self.constraints)


def _check_load(rod, load):
    """Check a load record against the rod, before any work (the constructors check the values themselves;
    this catches records built by hand and what needs the rod: node ranges, ends of a ring). An object that is
    no load record: a ValueError naming the constructors (``loads.check_load``)."""
    check_load(rod, load)


Plan = namedtuple("Plan", [
    "has_stretch", "has_bend", "has_twist",
    "edge_nodes", "vertex_nodes", "vertex_edges",
    "l_bar", "voronoi", "kappa_bar", "twist_bar", "weld", "A1", "A2", "k_stretch",
    "has_nodal", "nodal_forces", "has_theta", "theta_moments",
    "has_dead_torques", "torque_edges", "torque_vectors",
    "counters",
    "has_follower", "follower_density", "follower_first", "follower_second",
    "has_follower_torques", "follower_torque_edges", "follower_torque_vectors",
    # work arrays of ``evaluate``, allocated once per plan and reused by every evaluation: the edges with their
    # low parts (n_edges, 6; a view of columns 10-15 of the next), the per-edge frames (n_edges, 16) and
    # dE/dtheta (n_edges,). Fresh arrays per call were page-faulted on every evaluation at 10^6 edges (176 MB each
    # time, issue 17)
    "work_E", "work_ed", "work_dE",
])


def make_plan(scene, k_stretch):
    """Flatten a scene for the kernels. ``k_stretch`` (per edge) is the axial penalty the solver uses."""
    rod = scene.rod
    sums = LoadSums(rod)
    for load in scene.loads:      # each record adds its share, in the scene's order (the sums' round-off)
        load.add_to(sums, rod)
    # follower forces: half of each edge's rest length to each of its nodes, none to the outer nodes of an open
    # rod (the outer halves of the end edges lie outside [0, L]): the lumping of Rod.node_weights
    w_first = 0.5 * rod.l_bar.copy()
    w_second = 0.5 * rod.l_bar.copy()
    if not rod.closed:
        w_first[0] = 0.0
        w_second[-1] = 0.0
    # the edges with their low parts are columns 10-15 of the edge frames (edge_frames copies them there): one
    # work array for both, 48 bytes per edge less at the peak of a solve
    work_ed = np.empty((rod.n_edges, 16))
    return Plan(
        "stretch" in scene.energies, "bend" in scene.energies, "twist" in scene.energies,
        rod.edge_nodes, rod.vertex_nodes, rod.vertex_edges,
        rod.l_bar, rod.voronoi, rod.natural_curvature_edges().reshape(-1, 4), rod.twist_bar, rod.weld,
        rod.kernel_bending(), rod.kernel_twisting(),   # floats for a uniform isotropic rod (energies.stiffness)
        np.array(k_stretch, dtype=float),        # a copy: the solver may raise the penalty in place
        sums.has_nodal, sums.nodal, sums.has_theta, sums.theta,
        len(sums.dead_edges) > 0, np.array(sums.dead_edges, dtype=np.int64),
        np.array(sums.dead_torques, dtype=float).reshape(-1, 3),
        np.zeros(len(COUNTER_NAMES), dtype=np.int64),
        sums.has_follower, sums.follower_density, w_first, w_second,
        len(sums.follower_torque_edges) > 0, np.array(sums.follower_torque_edges, dtype=np.int64),
        np.array(sums.follower_torques, dtype=float).reshape(-1, 3),
        work_ed[:, 10:16], work_ed, np.empty(rod.n_edges),
    )


def edge_forces_in_pass(plan, order):
    """True when ``evaluate`` at ``order`` fills its ``F``, ``M`` arguments (order 1, all three terms)."""
    return order == 1 and plan.has_stretch and plan.has_bend and plan.has_twist


@njit(cache=True)
def evaluate(plan, q, d1, reference_twist, lam, order, grad, fext, ab, kl, ku, perm, q_lo=None, F=None, M=None):
    """Energy of the scene at ``q``; ``grad`` <- dE/dq, ``fext`` <- generalized external force.

    With ``order >= 2`` also ``ab`` <- the force Jacobian ``K = d(grad - fext)/dq`` in band storage: the energy
    Hessian, the frame-transport term and the load stiffness. ``grad``, ``fext`` and ``ab`` are overwritten.
    ``q_lo``: the low parts of compensated positions (``RodState.q_lo``) or None; the edges every term uses are
    formed once, here (``geometry.edge_array``), with the relative accuracy of the edges themselves.
    ``F``, ``M``: with order 1 and all three terms, filled with ``diagnostics._edge_forces`` of the state (the
    solver's load scale) in the same pass; untouched otherwise (check ``edge_forces_in_pass``).
    """
    E = edge_array_into(q, plan.edge_nodes, q_lo, True, plan.work_E)   # with their low parts (curvature, elongation)
    grad[:] = 0.0
    fext[:] = 0.0
    energy = 0.0
    # all three terms: one pass over the vertex stencils, each edge's stretching inside one of them; at order 1 the
    # same pass without the band, so that the forces are bitwise the same with and without the Jacobian (a solver
    # evaluates its residual first and assembles the band only for a step, issue 17). At order 2 that pass zeroes
    # each column of the band just before its first entry and adds the frame-transport term
    full = order >= 1 and plan.has_stretch and plan.has_bend and plan.has_twist
    if order >= 2 and not full:
        zero_band(ab)
    if plan.has_stretch and not full:
        plan.counters[0] += 1
        if order >= 2:
            energy += stretch_hessian(q, plan.edge_nodes, plan.l_bar, plan.k_stretch, lam, grad, ab, kl, ku, perm,
                                      E)
        elif order == 1:
            energy += stretch_gradient(q, plan.edge_nodes, plan.l_bar, plan.k_stretch, lam, grad, E)
        else:
            energy += stretch_energy(q, plan.edge_nodes, plan.l_bar, plan.k_stretch, lam, E)
    if plan.has_bend or (plan.has_twist and order >= 1):
        ed = edge_frames(q, plan.edge_nodes, d1, E, plan.work_ed)   # one pass over edges, bending and twisting
    else:
        ed = np.empty((0, 16))
    if full:
        plan.counters[0] += 1
        plan.counters[1] += 1
        plan.counters[2] += 1
        if order >= 2:
            e_stretch, e_bend, e_twist = stretch_bend_twist_hessian(
                q, ed, plan.edge_nodes, plan.vertex_nodes, plan.vertex_edges, plan.l_bar, plan.k_stretch, lam,
                reference_twist, plan.weld, plan.kappa_bar, plan.twist_bar, plan.voronoi, plan.A1, plan.A2, grad, ab,
                kl, ku, perm, E)
        else:
            e_stretch, e_bend, e_twist = stretch_bend_twist_gradient(
                q, ed, plan.edge_nodes, plan.vertex_nodes, plan.vertex_edges, plan.l_bar, plan.k_stretch, lam,
                reference_twist, plan.weld, plan.kappa_bar, plan.twist_bar, plan.voronoi, plan.A1, plan.A2, grad, E,
                F, M)
        energy += e_stretch
        energy += e_bend
        energy += e_twist
    fused = order >= 2 and plan.has_bend and plan.has_twist and not full
    if fused:
        # one pass over the vertex stencils for both terms: half the scattering into the band (issue 17)
        plan.counters[1] += 1
        plan.counters[2] += 1
        e_bend, e_twist = bend_twist_hessian(q, ed, plan.vertex_nodes, plan.vertex_edges, reference_twist, plan.weld,
                                             plan.kappa_bar, plan.twist_bar, plan.voronoi, plan.A1, plan.A2, grad,
                                             ab, kl, ku, perm)
        energy += e_bend
        energy += e_twist
    if plan.has_bend and not fused and not full:
        plan.counters[1] += 1
        if order >= 2:
            energy += bend_hessian(ed, plan.vertex_nodes, plan.vertex_edges, plan.weld, plan.kappa_bar,
                                   plan.voronoi, plan.A1, grad, ab, kl, ku, perm)
        elif order == 1:
            energy += bend_gradient(ed, plan.vertex_nodes, plan.vertex_edges, plan.weld, plan.kappa_bar,
                                    plan.voronoi, plan.A1, grad)
        else:
            energy += bend_energy(ed, plan.vertex_edges, plan.weld, plan.kappa_bar, plan.voronoi, plan.A1)
    if plan.has_twist and not fused and not full:
        plan.counters[2] += 1
        if order >= 2:
            energy += twist_hessian(q, ed, plan.vertex_nodes, plan.vertex_edges, reference_twist, plan.weld,
                                    plan.twist_bar, plan.voronoi, plan.A2, grad, ab, kl, ku, perm)
        elif order == 1:
            energy += twist_gradient(q, ed, plan.vertex_nodes, plan.vertex_edges, reference_twist, plan.weld,
                                     plan.twist_bar, plan.voronoi, plan.A2, grad)
        else:
            energy += twist_energy(q, plan.vertex_edges, reference_twist, plan.weld, plan.twist_bar, plan.voronoi,
                                   plan.A2)
    if order >= 2 and (plan.has_bend or plan.has_twist):
        plan.counters[3] += 1
    if order >= 2 and (plan.has_bend or plan.has_twist) and not full:   # (``full``: added in its pass)
        n_edges = plan.edge_nodes.shape[0]
        dE_dtheta = plan.work_dE
        for j in range(n_edges):
            dE_dtheta[j] = grad[4 * j + 3]
        add_transport_jacobian(q, plan.edge_nodes, dE_dtheta, ab, kl, ku, perm, E)
    if plan.has_nodal:
        plan.counters[4] += 1
        add_nodal_forces(plan.nodal_forces, fext)
    if plan.has_theta:
        plan.counters[5] += 1
        add_theta_moments(plan.theta_moments, fext)
    if plan.has_dead_torques:
        plan.counters[6] += 1
        add_dead_torques(q, plan.edge_nodes, plan.torque_edges, plan.torque_vectors, order, fext, ab, kl, ku, perm,
                         E)
    if plan.has_follower:
        plan.counters[7] += 1
        add_follower_forces(edge_frames(q, plan.edge_nodes, d1, E), plan.edge_nodes, q, plan.follower_density,
                            plan.follower_first, plan.follower_second, order, fext, ab, kl, ku, perm)
    if plan.has_follower_torques:
        plan.counters[8] += 1
        add_follower_torques(edge_frames(q, plan.edge_nodes, d1, E), plan.edge_nodes, plan.follower_torque_edges,
                             plan.follower_torque_vectors, order, fext, ab, kl, ku, perm)
    return energy
