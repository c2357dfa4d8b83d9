"""Rigid obstacles: a plane (a floor), a sphere and an infinite cylinder, each offset by the rod's radius r.

The barrier kappa b(gap; dhat) on the gap between the rod's surface and the obstacle (der/contact/obstacles.py:
exact for edges), its Hessian blocks per node (plane) or per edge (sphere, cylinder) added into the band (no
off-band coupling: the banded solve stays), and a CCD bound on every step.
"""
from dataclasses import dataclass

import numpy as np

from .. import validate
from . import register
from .contact import MIN_GAP_FRACTION, DHAT_FRACTION, BoundBarrier, RodContact, SelfContact, positive_radius

PLANE, SPHERE, CYLINDER = 0, 1, 2           # as der/contact/obstacles.py
_NAMES = {PLANE: "plane", SPHERE: "sphere", CYLINDER: "cylinder"}


@register
@dataclass(frozen=True, eq=False)
class Obstacle:
    """A rigid obstacle; build one with ``der.plane``, ``der.sphere`` or ``der.cylinder``."""

    kind: int
    params: np.ndarray          # (7,) as der/contact/obstacles.py
    radius: float | None = None
    dhat: float | None = None
    kappa: float | None = None
    constructor = "plane(point, normal), der.sphere(centre, R), der.cylinder(point, axis, R)"

    @property
    def name(self):
        return _NAMES[self.kind]

    def rod_radius(self, scene):
        """The offset: this obstacle's ``radius`` or the radius of the scene's self-contact term."""
        if self.radius is not None:
            return self.radius
        for t in scene.contacts:
            if isinstance(t, SelfContact):
                return t.radius
            if isinstance(t, RodContact) and not isinstance(t.radius, tuple):
                return t.radius
        raise ValueError(f"der.{self.name}: give the rod's radius (der.{self.name}(..., radius=r)) or add "
                         "der.self_contact(radius) or der.rod_contact(radius) to the scene's contacts")

    def check_scene(self, scene):
        self.rod_radius(scene)

    def bind(self, system):
        return BoundObstacle(self, system)


def _unit(v, name):
    v = validate.vector3(v, name)
    n = float(np.linalg.norm(v))
    if not n > 0:
        raise ValueError(f"{name} must be a non-zero vector; got {v!r}")
    return v / n


def _options(radius, dhat, kappa, name):
    if radius is not None:
        radius = positive_radius(radius, f"der.{name}: radius")
    if dhat is not None:
        dhat = positive_radius(dhat, f"der.{name}: dhat")
    if kappa is not None:
        kappa = validate.positive_number(kappa, f"der.{name}: kappa")
    return radius, dhat, kappa


def plane(point, normal, radius=None, dhat=None, kappa=None):
    """A rigid plane through ``point`` with ``normal`` (any length, normalised): the rod stays on the side the
    normal points to, its centreline at least its radius r from the plane.

    radius : the rod's radius r (default: that of the scene's ``der.self_contact``); dhat, kappa: the barrier's
    range (default 0.1 r) and stiffness (default adaptive), as for ``der.self_contact``.

    Example
    -------
    >>> import der
    >>> floor = der.plane([0, 0, 0], [0, 0, 1], radius=0.01)
    """
    p = validate.vector3(point, "der.plane: point")
    n = _unit(normal, "der.plane: normal")
    return Obstacle(PLANE, np.concatenate([p, n, [0.0]]), *_options(radius, dhat, kappa, "plane"))


def sphere(centre, R, radius=None, dhat=None, kappa=None):
    """A rigid ball of radius ``R`` around ``centre``: the rod's centreline stays at least R + r from the centre.

    Parameters
    ----------
    centre : 3-vector; R : float > 0 (length)
    radius, dhat, kappa : as for ``der.plane`` (the rod's radius r, default that of ``der.self_contact``).

    Example
    -------
    >>> import der
    >>> ball = der.sphere([0, 0, -1], 0.5, radius=0.01)
    """
    c = validate.vector3(centre, "der.sphere: centre")
    R = positive_radius(R, "der.sphere: R")
    return Obstacle(SPHERE, np.concatenate([c, [0.0, 0.0, 0.0], [R]]), *_options(radius, dhat, kappa, "sphere"))


def cylinder(point, axis, R, radius=None, dhat=None, kappa=None):
    """A rigid infinite cylinder of radius ``R`` about the line through ``point`` along ``axis``: the rod stays
    outside, its centreline at least R + r from the axis.

    Parameters
    ----------
    point : 3-vector on the axis; axis : 3-vector (any length, normalised); R : float > 0 (length)
    radius, dhat, kappa : as for ``der.plane`` (the rod's radius r, default that of ``der.self_contact``).

    Example
    -------
    >>> import der
    >>> post = der.cylinder([0, 0, 0], [0, 1, 0], 0.2, radius=0.01)
    """
    c = validate.vector3(point, "der.cylinder: point")
    a = _unit(axis, "der.cylinder: axis")
    R = positive_radius(R, "der.cylinder: R")
    return Obstacle(CYLINDER, np.concatenate([c, a, [R]]), *_options(radius, dhat, kappa, "cylinder"))


class BoundObstacle(BoundBarrier):
    couples_dofs = False           # node or edge blocks: inside the band

    def __init__(self, term, system):
        from ..contact import assembly

        self.A = assembly
        self.term = term
        rod = system.rod
        self.rod = rod
        self.system = system
        self.radius = term.rod_radius(system.scene)
        self.dhat = DHAT_FRACTION * self.radius if term.dhat is None else term.dhat
        self.edges = np.ascontiguousarray(rod.edge_nodes, dtype=np.int64)
        self.params = np.ascontiguousarray(term.params, dtype=float)
        self.n_nodes = rod.n_nodes
        self.node_dof = 4 * np.arange(rod.n_nodes, dtype=np.int64)
        self._init_stiffness(term.kappa, system)

    def check_start(self, state, tight_bend="refuse"):
        pos = self.positions(state)
        gaps = np.array([self.A.edge_obstacle_gap(pos, a, b, self.term.kind, self.params, self.radius)
                         for a, b in self.edges])
        e = int(np.argmin(gaps))
        if gaps[e] <= 0.0:
            raise ValueError(f"der.{self.term.name}: the starting state intersects the obstacle: edge {e} is "
                             f"{gaps[e] + self.radius:.6g} from it (centreline), not more than the rod's radius "
                             f"{self.radius:.6g}")

    def evaluate(self, state, order, grad, ab, coo):
        s = self.system
        if order == 0:
            grad, ab = s.grad, s.ab          # not written at order 0
        energy, n_active, min_gap, fmax = self.A.obstacle_system(
            self.positions(state), self.edges, self.radius, self.term.kind, self.params, self.dhat, self.kappa, order,
            self.node_dof, grad, ab, s.kl, s.ku, s.perm, self.project)
        self.n_active, self.min_gap, self.force_scale = int(n_active), float(min_gap), float(fmax)
        return float(energy)

    def max_step(self, state, delta):
        dpos = np.ascontiguousarray(delta.reshape(-1, 4)[:self.n_nodes, :3])
        tau, _ = self.A.obstacle_step(self.positions(state), dpos, self.edges, self.radius, self.term.kind,
                                      self.params, MIN_GAP_FRACTION, 1e-6, 10000)
        return float(tau)

    def diagnostics(self, state):
        """Nodes (plane) or edges (sphere, cylinder) in contact, their gaps and forces, the smallest gap."""
        pos = self.positions(state)
        n = self.rod.n_dof
        grad = np.zeros(n)
        dummy = np.zeros((1, 1), order="F")
        kind = self.term.kind
        if kind == PLANE:
            gaps = (pos - self.params[:3]) @ self.params[3:6] - self.radius
            idx = np.flatnonzero(gaps < self.dhat)
            forces = []
            for k in idx:
                g = np.zeros(n)
                self.A.obstacle_system(pos[k:k + 1], np.zeros((0, 2), dtype=np.int64), self.radius, kind, self.params,
                                       self.dhat, self.kappa, 1, np.zeros(1, dtype=np.int64), g, dummy, 0, 0,
                                       np.zeros(1, dtype=np.int64), True)
                forces.append(float(np.linalg.norm(g[:3])))
            w = np.zeros(self.n_nodes)          # the length each node stands for: half of each adjacent edge
            np.add.at(w, self.edges[:, 0], 0.5 * self.rod.l_bar)
            np.add.at(w, self.edges[:, 1], 0.5 * self.rod.l_bar)
            points = pos[idx] - self.radius * self.params[3:6]
            g_min = float(gaps.min())
        else:
            gaps = np.array([self.A.edge_obstacle_gap(pos, a, b, kind, self.params, self.radius) for a, b in self.edges])
            idx = np.flatnonzero(gaps < self.dhat)
            forces = []
            for e in idx:
                g = np.zeros(n)
                self.A.obstacle_system(pos, self.edges[e:e + 1], self.radius, kind, self.params, self.dhat, self.kappa,
                                       1, self.node_dof, g, dummy, 0, 0, np.zeros(1, dtype=np.int64), True)
                forces.append(float(np.linalg.norm(g.reshape(-1, 4)[:, :3].sum(axis=0))))
            w = self.rod.l_bar
            points = 0.5 * (pos[self.edges[idx, 0]] + pos[self.edges[idx, 1]])
            g_min = float(gaps.min())
        del grad
        forces = np.array(forces)
        return {
            "kind": self.term.name, "radius": self.radius, "dhat": self.dhat, "kappa": self.kappa,
            "n_contacts": int(idx.size), "elements": idx.tolist(), "gap": gaps[idx].tolist(), "force": forces.tolist(),
            "force_per_length": (forces / w[idx]).tolist() if idx.size else [], "total_force": float(forces.sum()),
            "points": points.tolist(), "min_distance": g_min + self.radius,
        }
