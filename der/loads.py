"""External loads: what they are (small data records) and their generalized forces (numba kernels).

Every load becomes a generalized force ``f_ext`` on the state vector (node forces on x, moments about the
tangent on theta) and, where it depends on the configuration, a load stiffness ``-d f_ext / d q``.

A torque ``tau`` on the material frame of edge ``j`` acts through its two parts: ``tau . t_j`` on theta_j, and
the normal part as a couple of node forces ``+-(tau x t_j) / |e_j|`` on the edge's end nodes (so that
``e_j x f = tau - (tau . t_j) t_j``).

Sign conventions: a positive moment about t over-twists the rod (right-handed about t, the direction of
increasing arc length). Densities are per unit *rest* length.

Each load record (a frozen dataclass, registered with ``@register``) answers the ``Load`` protocol itself: its
check against the rod, its share of the plan's arrays (``add_to`` a ``LoadSums``), its scale, its net dead force
and torque, its dead direction, whether it turns with the sections, whether it keeps a ring's sliding symmetry.
The Scene, ``make_plan``, the solvers and the stability analysis only ask these (no chain of isinstance tests):
a new load type is one class here.
"""
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
from numba import njit

from . import validate
from .stencils import edge_dofs, scatter_band


# ---------------------------------------------------------------------------------------------
# the load protocol: every load record answers these questions itself
# ---------------------------------------------------------------------------------------------

LOAD_TYPES = []   # the registered load records, in the order the Scene's error names their constructors


def register(cls):
    """Class decorator: make ``cls`` a load the Scene accepts (its ``constructor`` is named in the Scene's error
    for an unknown load). A new load type is one class here, with this line."""
    if not (isinstance(cls, type) and issubclass(cls, Load) and isinstance(getattr(cls, "constructor", None), str)):
        raise TypeError(f"der.loads.register: {cls!r} must be a subclass of der.loads.Load with a `constructor` "
                        "name (the der function that makes it)")
    LOAD_TYPES.append(cls)
    return cls


def unknown_load_message(load):
    """The Scene's error for ``load`` that is no registered load record: it names the constructors."""
    names = [f"der.{cls.constructor}" for cls in LOAD_TYPES]
    return (f"der.Scene: loads: unknown load {load!r}; use {', '.join(names[:-1])} or {names[-1]}")


def check_load(rod, load):
    """Check ``load`` against ``rod`` before any work: a ValueError naming the constructors for an object that is
    no load record, else the record's own ``check(rod)``."""
    if not isinstance(load, tuple(LOAD_TYPES)):
        raise ValueError(unknown_load_message(load))
    load.check(rod)


class LoadSums:
    """The loads of a scene summed into the arrays of a plan (``scene.make_plan``): each record's ``add_to`` adds
    its share, in the order of ``scene.loads``.

    - ``nodal`` (n_nodes, 3): dead forces per node (force units, global frame), lumped; ``has_nodal``.
    - ``theta`` (n_edges,): moments about each edge's current tangent (force * length; positive over-twists);
      ``has_theta``.
    - ``dead_edges``, ``dead_torques``: dead torque vectors (force * length, global frame) on edges' frames.
    - ``follower_density`` (3,): the follower force per unit rest length along (m1, m2, t); ``has_follower``.
    - ``follower_torque_edges``, ``follower_torques``: follower torques (T1, T2, Tt) along an edge's current
      material frame (m1, m2, t).
    """

    def __init__(self, rod):
        self.nodal = np.zeros((rod.n_nodes, 3))
        self.theta = np.zeros(rod.n_edges)
        self.has_nodal = self.has_theta = False
        self.dead_edges, self.dead_torques = [], []
        self.follower_density = np.zeros(3)
        self.has_follower = False
        self.follower_torque_edges, self.follower_torques = [], []


def _end_edge(rod, end):
    """The index of the end edge at ``end`` ("start" or "end"); a ValueError for a ring or another end."""
    from .constraints import end_index     # (der.constraints imports this module)

    return end_index(rod, end)[2]


def _norm(v):
    """|v| without overflow (``solvers.system.safe_norm``)."""
    from .solvers.system import safe_norm

    return safe_norm(v)


class Load(ABC):
    """What every load record answers (the Scene's check, ``make_plan``, the solvers' load scale and equilibrium
    check, the stability analysis ask nothing else). Subclasses are frozen dataclasses, registered with
    ``@register``; a class that leaves one of these out cannot be instantiated."""

    constructor = None   # the der.<constructor> that makes the record

    @abstractmethod
    def check(self, rod):
        """ValueError (or TypeError) if the record does not fit ``rod`` or holds values its constructor refuses
        (records built by hand): node or edge out of range, an end of a ring, a non-finite value."""

    @abstractmethod
    def add_to(self, sums, rod):
        """Add the load's generalized force to ``sums`` (a ``LoadSums`` of ``rod``): its nodal forces, theta
        moments, dead torques, follower force density or follower torques."""

    @abstractmethod
    def scale(self, L):
        """(force, moment): the size of the applied force (force units; a density times the rod length ``L``)
        and of the applied moment (force * length; a moment density times ``L``), for the residual's load scale
        (``solvers.system.applied_scales``). Non-negative; inf or nan if the record's values overflow."""

    @abstractmethod
    def net(self, rod):
        """(force, torque, follower): the net dead force on ``rod`` (a 3-vector in the global frame, the total its
        nodes receive; None if the load has none), its dead torque (a 3-vector, force * length; None if none),
        and whether it is a follower load (its moment on the rod turns with the configuration). Used to refuse a
        scene without static equilibrium (``solvers.system.check_equilibrium_exists``)."""

    @abstractmethod
    def dead_vector(self):
        """The fixed global vector of a dead load (force, force per length or torque; not normalised), which
        breaks the rigid rotations about any other axis; None for a follower load."""

    @abstractmethod
    def turns_with_sections(self):
        """True if the load depends on the sections' angles (it has a component along a material director m1 or
        m2): then a uniform turn of every section (theta + c) is no symmetry of the scene."""

    @abstractmethod
    def keeps_ring_sliding(self):
        """True if a uniform free ring sliding along its centreline (``stability.sliding_mode``) stays a symmetry
        under this load: the load is uniform per unit rest length and does no work in that sliding."""


class _DeadForce(Load):
    """A dead force ``force`` (3-vector, force units, global frame) concentrated at one place."""

    def scale(self, L):
        return _norm(self.force), 0.0

    def net(self, rod):
        return np.asarray(self.force, float), None, False

    def dead_vector(self):
        return np.asarray(self.force, float)

    def turns_with_sections(self):
        return False

    def keeps_ring_sliding(self):
        return False


class _Torque(Load):
    """A torque on one edge's material frame: dead (``follower=False``: ``torque`` a 3-vector, force * length,
    global frame) or follower (``follower=True``: about the edge's current frame)."""

    def scale(self, L):
        return 0.0, (abs(float(self.torque)) if np.ndim(self.torque) == 0 else _norm(self.torque))

    def net(self, rod):
        if self.follower:
            return None, None, True          # follower moments turn with the rod
        return None, np.asarray(self.torque, float), False

    def dead_vector(self):
        return None if self.follower else np.asarray(self.torque, float)

    def turns_with_sections(self):
        return False

    def keeps_ring_sliding(self):
        return False

    def _add_on_edge(self, sums, j):
        """Edge ``j`` carries the torque: a moment about its tangent (scalar follower), a dead torque vector, or
        a follower torque along its material frame (m1, m2, t)."""
        if self.follower and np.ndim(self.torque) == 1:
            sums.follower_torque_edges.append(j)
            sums.follower_torques.append(self.torque)
        elif self.follower:
            sums.theta[j] += self.torque
            sums.has_theta = True
        else:
            sums.dead_edges.append(j)
            sums.dead_torques.append(self.torque)


@register
@dataclass(frozen=True)
class PointForce(_DeadForce):
    """A dead force ``force`` (3-vector, force units) on node ``node`` (negative indices count from the end).

    Made by ``der.point_force``."""
    node: int
    force: tuple

    constructor = "point_force"

    def check(self, rod):
        node = validate.integer(self.node, "der.point_force: node", "an integer node index")
        if not -rod.n_nodes <= node < rod.n_nodes:
            raise ValueError(f"point force on node {node}: out of range for {rod.n_nodes} nodes "
                             f"(allowed: {-rod.n_nodes} ... {rod.n_nodes - 1})")
        validate.vector3(self.force, "der.point_force: force")

    def add_to(self, sums, rod):
        sums.nodal[self.node % rod.n_nodes] += self.force
        sums.has_nodal = True


@register
@dataclass(frozen=True)
class EndForce(_DeadForce):
    """A dead force ``force`` (3-vector) on the end cross-section ``end`` ("start" or "end").

    It acts at the end edge's midpoint -- the rod's end, xi = 0 or L -- as half the force on each of its nodes.
    Made by ``der.end_force``.
    """
    end: str
    force: tuple

    constructor = "end_force"

    def check(self, rod):
        _end_edge(rod, self.end)
        validate.vector3(self.force, "der.end_force: force")

    def add_to(self, sums, rod):
        j = _end_edge(rod, self.end)
        for k in rod.edge_nodes[j]:
            sums.nodal[k] += 0.5 * np.asarray(self.force)
        sums.has_nodal = True


@register
@dataclass(frozen=True)
class DistributedForce(Load):
    """A dead force per unit rest length ``density`` (3-vector), lumped to nodes by Voronoi length.

    Made by ``der.distributed_force``."""
    density: tuple

    constructor = "distributed_force"

    def check(self, rod):
        validate.vector3(self.density, "der.distributed_force: density")

    def add_to(self, sums, rod):
        sums.nodal += rod.node_weights()[:, None] * np.asarray(self.density)[None, :]
        sums.has_nodal = True

    def scale(self, L):
        return _norm(self.density) * L, 0.0

    def net(self, rod):
        # the total the rod receives: the density times the length its nodes stand for (the lumping of add_to)
        return np.asarray(self.density, float) * float(rod.node_weights().sum()), None, False

    def dead_vector(self):
        return np.asarray(self.density, float)

    def turns_with_sections(self):
        return False

    def keeps_ring_sliding(self):
        return True


@register
@dataclass(frozen=True)
class EndTorque(_Torque):
    """A torque on the end cross-section at ``end`` ("start" or "end").

    ``follower=False``: a dead torque, ``torque`` a fixed 3-vector (force * length).
    ``follower=True``: ``torque`` a scalar T about the current end tangent (positive over-twists).
    Made by ``der.end_torque``.
    """
    end: str
    torque: object
    follower: bool = False

    constructor = "end_torque"

    def check(self, rod):
        _end_edge(rod, self.end)
        if self.follower:
            validate.finite_number(self.torque, "der.end_torque: torque (follower=True: a scalar)")
        else:
            validate.vector3(self.torque, "der.end_torque: torque: dead end torque")

    def add_to(self, sums, rod):
        self._add_on_edge(sums, _end_edge(rod, self.end))


@register
@dataclass(frozen=True)
class TwistingMoment(Load):
    """A distributed moment ``density`` (force * length / length) about the current tangent (a follower load).

    Made by ``der.twisting_moment``."""
    density: float

    constructor = "twisting_moment"

    def check(self, rod):
        validate.finite_number(self.density, "der.twisting_moment: density")

    def add_to(self, sums, rod):
        sums.theta += self.density * rod.edge_weights()
        sums.has_theta = True

    def scale(self, L):
        return 0.0, abs(self.density) * L

    def net(self, rod):
        return None, None, True

    def dead_vector(self):
        return None

    def turns_with_sections(self):
        return False

    def keeps_ring_sliding(self):
        return True


@register
@dataclass(frozen=True)
class PointTorque(_Torque):
    """A torque on the material frame of edge ``edge`` (any edge, interior ones included).

    ``follower=False``: a dead torque, ``torque`` a fixed 3-vector (force * length).
    ``follower=True``: ``torque`` a scalar T about the edge's current tangent (positive over-twists), or a
    3-vector of components along the edge's current material frame (m1, m2, t). Made by ``der.point_torque``."""
    edge: int
    torque: object
    follower: bool = False

    constructor = "point_torque"

    def check(self, rod):
        edge = validate.integer(self.edge, "der.point_torque: edge", "an integer edge index")
        if not -rod.n_edges <= edge < rod.n_edges:
            raise ValueError(f"point torque on edge {edge}: out of range for {rod.n_edges} edges "
                             f"(allowed: {-rod.n_edges} ... {rod.n_edges - 1})")
        if self.follower and np.ndim(self.torque) == 0:
            validate.finite_number(self.torque, "der.point_torque: torque (follower=True: a scalar)")
        else:
            validate.vector3(self.torque, "der.point_torque: torque")

    def add_to(self, sums, rod):
        self._add_on_edge(sums, self.edge % rod.n_edges)

    def turns_with_sections(self):
        return bool(self.follower and np.ndim(self.torque) == 1
                    and (self.torque[0] != 0.0 or self.torque[1] != 0.0))


@register
@dataclass(frozen=True)
class FollowerForce(Load):
    """A force per unit rest length that turns with the cross-section: ``density`` = (f1, f2, ft), its
    components along the material directors m1, m2 and the tangent t of each edge. Made by
    ``der.follower_force``."""
    density: tuple

    constructor = "follower_force"

    def check(self, rod):
        validate.vector3(self.density, "der.follower_force: density")

    def add_to(self, sums, rod):
        sums.follower_density += np.asarray(self.density, float)
        sums.has_follower = True

    def scale(self, L):
        return _norm(self.density) * L, 0.0

    def net(self, rod):
        return None, None, True

    def dead_vector(self):
        return None

    def turns_with_sections(self):
        return bool(self.density[0] != 0.0 or self.density[1] != 0.0)

    def keeps_ring_sliding(self):
        return False


ENDS = ("start", "end")


def check_end(end, name):
    """``end`` must be "start" or "end" (0 and -1 are accepted as aliases)."""
    if isinstance(end, str) and end in ENDS:
        return end
    if isinstance(end, (int, np.integer)) and not isinstance(end, (bool, np.bool_)) and int(end) in (0, -1):
        return ENDS[0] if int(end) == 0 else ENDS[1]
    raise ValueError(f"{name} must be 'start' or 'end'; got {end!r}")


def point_force(node, force):
    """A dead force on one node.

    Parameters
    ----------
    node : int
        Node index, 0 ... n_nodes - 1; negative indices count from the end (-1 is the last node). Python or
        numpy integers, or a float with a whole value (3.0); 2.5 is refused, never rounded. Note that an open
        rod's first and last nodes lie half an edge outside the rod's ends (``Rod.xi_nodes``): to load an end
        cross-section use ``der.end_force``.
    force : 3-vector
        The force (force units), in the global frame; it keeps its direction as the rod moves (dead load).

    Returns
    -------
    PointForce, to pass in ``der.Scene(rod, loads=[...])``.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 10), A1=1.0, A2=1.0)
    >>> load = der.point_force(5, [1e-3, 0, 0])      # node 5: the middle of the rod
    >>> scene = der.Scene(rod, loads=[load], constraints=[der.clamp("start")])
    """
    return PointForce(validate.integer(node, "der.point_force: node", "an integer node index"),
                      tuple(validate.vector3(force, "der.point_force: force")))


def end_force(force, end="end"):
    """A dead force on an end cross-section of an open rod.

    Parameters
    ----------
    force : 3-vector
        The force (force units), global frame, fixed in direction (dead load).
    end : "start" or "end"
        Which end: xi = 0 or xi = L. The end cross-section is the midpoint of the end edge (the outer node lies
        half an edge beyond it); the force is applied there, as half the force on each node of the end edge.

    Returns
    -------
    EndForce, to pass in ``der.Scene(rod, loads=[...])``.

    Example
    -------
    A cantilever clamped at xi = 0 pulled sideways at xi = L:

    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.0)
    >>> scene = der.Scene(rod, loads=[der.end_force([1e-3, 0, 0])], constraints=[der.clamp("start")])
    """
    return EndForce(check_end(end, "der.end_force: end"), tuple(validate.vector3(force, "der.end_force: force")))


def distributed_force(density):
    """A uniform dead force per unit REST length along the whole rod (e.g. gravity: rho g per length).

    Parameters
    ----------
    density : 3-vector
        Force per unit rest length (force / length), the same vector everywhere, global frame, fixed in
        direction. The rod of rest length L carries the total force ``density * L``, lumped onto the nodes by
        the length each stands for (``Rod.node_weights``: an open rod's two outer nodes carry none). A
        non-uniform load: use one ``der.point_force`` per node.

    Returns
    -------
    DistributedForce, to pass in ``der.Scene(rod, loads=[...])``.

    Example
    -------
    A cantilever sagging under its weight (weight per length 1e-3, along -z):

    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 20, axis=[1, 0, 0], director=[0, 0, 1]), 1.0, 1.0)
    >>> scene = der.Scene(rod, loads=[der.distributed_force([0, 0, -1e-3])], constraints=[der.clamp("start")])
    """
    return DistributedForce(tuple(validate.finite_array(
        density, "der.distributed_force: density", (3,),
        "a single finite 3-vector (force per unit rest length, uniform along the rod; for a non-uniform "
        "load use one der.point_force per node)")))


def end_torque(torque, end="end", follower=False):
    """A torque on an end cross-section of an open rod: dead (a fixed vector) or follower (about the tangent).

    Parameters
    ----------
    torque : 3-vector (dead) or float (follower)
        ``follower=False`` (default): a dead torque, a 3-vector in the global frame (force * length) that keeps
        its direction as the end turns; its component along the end tangent twists, the rest bends.
        ``follower=True``: a scalar T (force * length), the moment T t about the CURRENT end tangent t (the
        direction of increasing arc length at that end). Positive T is right-handed about t: at the "end" it
        over-twists a rod whose other end is held (turns the end cross-section by +T L / A2 on a straight rod).
    end : "start" or "end"
        Which end (xi = 0 or xi = L); it acts on the material frame of the end edge.
    follower : bool
        Dead (False) or follower (True).

    Returns
    -------
    EndTorque, to pass in ``der.Scene(rod, loads=[...])``.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.5)   # along +z
    >>> dead = der.end_torque([0, 0, 1e-3])                  # a fixed vector: about z, twists this rod
    >>> follower = der.end_torque(1e-3, follower=True)       # about the current end tangent
    >>> scene = der.Scene(rod, loads=[follower], constraints=[der.clamp("start")])
    """
    if not isinstance(follower, (bool, np.bool_)):
        raise TypeError(f"der.end_torque: follower must be True or False; got {follower!r}")
    end = check_end(end, "der.end_torque: end")
    if follower:
        if np.ndim(torque) != 0 and not isinstance(torque, str):
            raise ValueError(f"der.end_torque: a follower torque (follower=True) is a scalar T, the moment about the "
                             f"current end tangent; got torque={torque!r} (for a fixed torque vector pass "
                             "follower=False)")
        return EndTorque(end, validate.finite_number(torque, "der.end_torque: torque (follower=True: the moment "
                                                             "about the current end tangent)"), True)
    if np.ndim(torque) == 0 and not isinstance(torque, (str, type(None))):
        raise ValueError(f"der.end_torque: a dead torque (follower=False) is a 3-vector [Tx, Ty, Tz] in the global "
                         f"frame; got the scalar torque={torque!r} (for a moment T about the current end tangent "
                         "pass follower=True)")
    return EndTorque(end, tuple(validate.vector3(torque, "der.end_torque: torque: dead end torque")),
                     False)


def twisting_moment(density):
    """A uniform distributed twisting moment m_t per unit rest length about the current tangent (follower).

    Parameters
    ----------
    density : float
        Moment per unit rest length (force * length / length), a scalar, about the local tangent t as it
        moves (positive over-twists: right-handed about the direction of increasing arc length). This is the
        paper's m_t (Section 6.1, the loop under a twisting moment).

    Returns
    -------
    TwistingMoment, to pass in ``der.Scene(rod, loads=[...])``.

    Example
    -------
    >>> import der
    >>> ring = der.rod_from_shape(der.shapes.ring(1.0, 50), A1=1.0, A2=1.5)
    >>> scene = der.Scene(ring, loads=[der.twisting_moment(0.5)])
    """
    if np.ndim(density) != 0 and not isinstance(density, str):
        raise ValueError(f"der.twisting_moment: density must be a single number (the moment per unit rest length "
                         f"about the tangent, uniform along the rod); got {density!r}")
    return TwistingMoment(validate.finite_number(density, "der.twisting_moment: density"))


def point_torque(edge, torque, follower=False):
    """A torque on the cross-section of one edge (interior edges included): dead or follower.

    Parameters
    ----------
    edge : int
        Edge index, 0 ... n_edges - 1 (negative counts from the end). Edge j's cross-section is at its midpoint,
        arc length ``Rod.xi_edges()[j]``; the end edges' are the end cross-sections (``der.end_torque``).
    torque : 3-vector (dead), float or 3-vector (follower)
        ``follower=False``: a fixed vector in the global frame (force * length); its component along the edge
        tangent twists, the rest bends. ``follower=True``: a scalar T, the moment T t about the edge's CURRENT
        tangent t (right-handed about the direction of increasing arc length); or a 3-vector (T1, T2, Tt), the
        moment T1 m1 + T2 m2 + Tt t in the edge's current material frame (it turns with the cross-section; its
        load stiffness is in the Newton matrix).
    follower : bool

    Returns
    -------
    PointTorque, to pass in ``der.Scene(rod, loads=[...])``.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.5)
    >>> scene = der.Scene(rod, loads=[der.point_torque(10, [1e-3, 0, 0])], constraints=[der.clamp("start")])
    """
    if not isinstance(follower, (bool, np.bool_)):
        raise TypeError(f"der.point_torque: follower must be True or False; got {follower!r}")
    edge = validate.integer(edge, "der.point_torque: edge", "an integer edge index")
    if follower:
        if np.ndim(torque) == 1:
            return PointTorque(edge, tuple(validate.vector3(
                torque, "der.point_torque: torque (follower=True: components along m1, m2, t)")), True)
        if np.ndim(torque) != 0 and not isinstance(torque, str):
            raise ValueError(f"der.point_torque: a follower torque (follower=True) is a scalar T (about the current "
                             f"edge tangent) or a 3-vector in the material frame (m1, m2, t); got torque={torque!r}")
        return PointTorque(edge, validate.finite_number(torque, "der.point_torque: torque (follower=True)"), True)
    if np.ndim(torque) == 0 and not isinstance(torque, (str, type(None))):
        raise ValueError(f"der.point_torque: a dead torque (follower=False) is a 3-vector [Tx, Ty, Tz] in the global "
                         f"frame; got the scalar torque={torque!r} (about the current tangent: follower=True)")
    return PointTorque(edge, tuple(validate.vector3(torque, "der.point_torque: torque")), False)


def follower_force(density):
    """A uniform force per unit REST length that turns with the cross-section (pressure-like, a follower load).

    Parameters
    ----------
    density : 2- or 3-vector
        (f1, f2) or (f1, f2, ft): the force per unit rest length along the current material directors m1, m2
        of each edge (and along its tangent t), force / length. A pressure on a rod bent in the (t, m1) plane
        is ``(-p, 0)`` (along -m1 wherever the rod is). On edge j it acts as ``f1 m1 + f2 m2 + ft t`` times the
        length of [0, L] the edge stands for (the end edges: their inner half), half on each of its nodes (on
        the inner node only for the end edges' outer halves, which lie outside the rod), like
        ``der.distributed_force``.

    Its load stiffness (it depends on positions through t and on theta through m1, m2) is in the Newton
    matrix; it is not symmetric: a follower force does work that depends on the path (circulatory).

    Returns
    -------
    FollowerForce, to pass in ``der.Scene(rod, loads=[...])``.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 20, axis=(1, 0, 0), director=(0, 0, 1)), 1.0, 1.0)
    >>> scene = der.Scene(rod, loads=[der.follower_force((-1e-3, 0))], constraints=[der.clamp("start")])
    """
    d = np.asarray(density, dtype=float) if not isinstance(density, str) else None
    if d is None or d.ndim != 1 or d.size not in (2, 3) or not np.all(np.isfinite(d)):
        raise ValueError(f"der.follower_force: density must be (f1, f2) or (f1, f2, ft), finite numbers (force per "
                         f"unit rest length along m1, m2 and t); got {density!r}")
    return FollowerForce(tuple(float(v) for v in np.resize(np.append(d, [0.0] * (3 - d.size)), 3)))


# ---------------------------------------------------------------------------------------------
# kernels
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def add_nodal_forces(nodal, fext):
    """fext[4k:4k+3] += nodal[k] (dead point and distributed forces, already lumped per node)."""
    for k in range(nodal.shape[0]):
        for i in range(3):
            fext[4 * k + i] += nodal[k, i]


@njit(cache=True)
def add_theta_moments(per_edge, fext):
    """fext[4j+3] += per_edge[j] (follower moments about the tangent, already integrated per edge)."""
    for j in range(per_edge.shape[0]):
        fext[4 * j + 3] += per_edge[j]


@njit(cache=True)
def add_dead_torques(q, edge_nodes, edges, torques, order, fext, ab, kl, ku, perm, E=None):
    """Dead torque vectors ``torques[i]`` on the material frames of ``edges[i]``; with order >= 2 also their
    load stiffness ``-d fext / d q`` into the band matrix. ``E``: edge vectors (``geometry.edge_array``; formed
    from ``q`` if None)."""
    dofs = np.empty(6, dtype=np.int64)
    K = np.zeros((7, 7))
    for i in range(edges.shape[0]):
        j = edges[i]
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        e = np.empty(3)
        for k in range(3):
            e[k] = q[b + k] - q[a + k] if E is None else E[j, k]
        le = np.sqrt(e[0] ** 2 + e[1] ** 2 + e[2] ** 2)
        t = e / le
        tau = torques[i]
        tt = tau[0] * t[0] + tau[1] * t[1] + tau[2] * t[2]
        fb = np.empty(3)   # force on the end node b of the couple
        fb[0] = (tau[1] * t[2] - tau[2] * t[1]) / le
        fb[1] = (tau[2] * t[0] - tau[0] * t[2]) / le
        fb[2] = (tau[0] * t[1] - tau[1] * t[0]) / le
        fext[4 * j + 3] += tt
        for k in range(3):
            fext[b + k] += fb[k]
            fext[a + k] -= fb[k]
        if order < 2:
            continue
        # d(tau.t)/de = (tau - (tau.t) t) / |e|
        # d fb / de = ([tau]_x (I - t t^T) - (tau x t) t^T) / |e|^2
        P = np.empty((3, 3))
        for r in range(3):
            for s in range(3):
                P[r, s] = (1.0 if r == s else 0.0) - t[r] * t[s]
        tx = np.zeros((3, 3))
        tx[0, 1] = -tau[2]
        tx[0, 2] = tau[1]
        tx[1, 0] = tau[2]
        tx[1, 2] = -tau[0]
        tx[2, 0] = -tau[1]
        tx[2, 1] = tau[0]
        dfb = tx @ P
        for r in range(3):
            for s in range(3):
                dfb[r, s] = (dfb[r, s] - fb[r] * le * t[s]) / (le * le)
        dtt = (tau - tt * t) / le
        # local DOFs: [x_a (3), x_b (3), theta_j]; e = x_b - x_a; stiffness = -d fext / d q
        for r in range(7):
            for s in range(7):
                K[r, s] = 0.0
        for r in range(3):
            for s in range(3):
                K[3 + r, 3 + s] = -dfb[r, s]
                K[3 + r, s] = dfb[r, s]
                K[r, 3 + s] = dfb[r, s]
                K[r, s] = -dfb[r, s]
            K[6, 3 + r] = -dtt[r]
            K[6, r] = dtt[r]
        edge_dofs(edge_nodes, j, dofs)
        full = np.empty(7, dtype=np.int64)
        for r in range(6):
            full[r] = dofs[r]
        full[6] = 4 * j + 3
        scatter_band(ab, kl, ku, perm, full, K, 1.0)


@njit(cache=True)
def add_follower_forces(ed, edge_nodes, q, density, w_first, w_second, order, fext, ab, kl, ku, perm):
    """Follower force per length ``density`` = (f1, f2, ft) along (m1, m2, t) of every edge: edge j gives
    ``w_first[j] f_j`` to its first node and ``w_second[j] f_j`` to its second, f_j = f1 m1 + f2 m2 + ft t.
    With order >= 2 also the load stiffness -d fext/dq into the band: with the reference frame transported
    with the edge, dm_i/de = -t m_i^T / |e| and dt/de = (I - t t^T) / |e|; dm1/dtheta = m2, dm2/dtheta = -m1.
    ``ed`` is an ``edge_frames`` array (t, |e|, m1, m2 per edge)."""
    f1, f2, ft = density[0], density[1], density[2]
    dofs = np.empty(6, dtype=np.int64)
    full = np.empty(7, dtype=np.int64)
    K = np.zeros((7, 7))
    for j in range(edge_nodes.shape[0]):
        wa = w_first[j]
        wb = w_second[j]
        if wa == 0.0 and wb == 0.0:
            continue
        t = ed[j, 0:3]
        le = ed[j, 3]
        m1 = ed[j, 4:7]
        m2 = ed[j, 7:10]
        f = f1 * m1 + f2 * m2 + ft * t
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        for k in range(3):
            fext[a + k] += wa * f[k]
            fext[b + k] += wb * f[k]
        if order < 2:
            continue
        fm = f1 * m1 + f2 * m2
        D = np.empty((3, 3))      # d f / d e
        for r in range(3):
            for c in range(3):
                D[r, c] = (-t[r] * fm[c] + ft * ((1.0 if r == c else 0.0) - t[r] * t[c])) / le
        g = f1 * m2 - f2 * m1     # d f / d theta
        for r in range(7):
            for c in range(7):
                K[r, c] = 0.0
        # local DOFs [x_a, x_b, theta]; e = x_b - x_a; K = -d fext / d q
        for r in range(3):
            for c in range(3):
                K[r, c] = wa * D[r, c]
                K[r, 3 + c] = -wa * D[r, c]
                K[3 + r, c] = wb * D[r, c]
                K[3 + r, 3 + c] = -wb * D[r, c]
            K[r, 6] = -wa * g[r]
            K[3 + r, 6] = -wb * g[r]
        edge_dofs(edge_nodes, j, dofs)
        for r in range(6):
            full[r] = dofs[r]
        full[6] = 4 * j + 3
        scatter_band(ab, kl, ku, perm, full, K, 1.0)


@njit(cache=True)
def add_follower_torques(ed, edge_nodes, edges, torques, order, fext, ab, kl, ku, perm):
    """Follower torques ``torques[i]`` = (T1, T2, Tt), components along the current material frame (m1, m2, t)
    of edge ``edges[i]``: Tt on theta and the couple +-u / |e| on the edge's nodes, u = T x t = T2 m1 - T1 m2.
    With order >= 2 also the load stiffness -d fext/dq: d(u/|e|)/de = -(t u^T + u t^T) / |e|^2 (the material
    directors move with the edge as dm_i/de = -t m_i^T / |e|), d(u/|e|)/dtheta = (T1 m1 + T2 m2) / |e|.
    ``ed`` is an ``edge_frames`` array."""
    dofs = np.empty(6, dtype=np.int64)
    full = np.empty(7, dtype=np.int64)
    K = np.zeros((7, 7))
    for i in range(edges.shape[0]):
        j = edges[i]
        T1, T2, Tt = torques[i, 0], torques[i, 1], torques[i, 2]
        t = ed[j, 0:3]
        le = ed[j, 3]
        m1 = ed[j, 4:7]
        m2 = ed[j, 7:10]
        u = T2 * m1 - T1 * m2
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        fext[4 * j + 3] += Tt
        for k in range(3):
            fext[b + k] += u[k] / le
            fext[a + k] -= u[k] / le
        if order < 2:
            continue
        g = (T1 * m1 + T2 * m2) / le
        for r in range(7):
            for c in range(7):
                K[r, c] = 0.0
        for r in range(3):
            for c in range(3):
                D = -(t[r] * u[c] + u[r] * t[c]) / (le * le)
                K[3 + r, 3 + c] = -D
                K[3 + r, c] = D
                K[r, 3 + c] = D
                K[r, c] = -D
            K[3 + r, 6] = -g[r]
            K[r, 6] = g[r]
        edge_dofs(edge_nodes, j, dofs)
        for r in range(6):
            full[r] = dofs[r]
        full[6] = 4 * j + 3
        scatter_band(ab, kl, ku, perm, full, K, 1.0)
