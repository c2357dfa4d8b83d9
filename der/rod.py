"""The rod: topology, rest state (natural curvature and twist), stiffnesses, and its mutable state.

A ``Rod`` is built from a discrete shape (``der.shapes``) whose material frame is put on the discrete Frenet
frame (alpha = 0). Its natural material curvatures and natural twist are measured on that discrete shape
with the same kernels the energies use, so the rest state has zero force to round-off.

Units: lengths in any consistent unit L; A1, A2 in force * L^2; EA in force; energies in force * L.
"""
from dataclasses import dataclass, field, replace

import numpy as np

from . import validate
from .energies.bend import material_curvatures_all
from .geometry import (
    curvature_binormals, edge_frames, frenet_directors, parallel_transport, reference_twists, rod_topology,
    shape_edges, tangents,
)


@dataclass(frozen=True, eq=False)
class Rod:
    """An elastic rod with natural curvature and twist (immutable definition).

    Attributes
    ----------
    closed : bool
        True for a ring (the last node joins the first).
    A1, A2 : float or (n_vertices,) array
        Bending and twisting stiffness (paper Eq. 17), force * length^2: a float for a uniform rod, one value per
        vertex for a rod that varies along its length (``der.rod``). A1 is the stiffness of the material
        curvature kappa1 = kb . m2 (bending towards m1, about m2).
    A1prime : None, float or (n_vertices,) array
        The second bending stiffness A1' (kappa2 = -kb . m1: bending towards m2, about m1); None: isotropic,
        A1' = A1 (``bending_stiffness()`` gives both per vertex).
    EA : float, (n_edges,) array or None
        Axial stiffness (force), uniform or per edge. ``None`` (default): inextensible, enforced exactly by the
        solvers.
    edge_nodes : (n_edges, 2) int
        Node indices of each edge.
    vertex_nodes : (n_vertices, 3) int, vertex_edges : (n_vertices, 2) int
        The three nodes and the two edges (before, after) of each bending/twisting vertex.
    l_bar : (n_edges,) rest edge lengths; voronoi : (n_vertices,) rest Voronoi lengths.
    kappa_bar : (n_vertices, 2)
        Natural integrated material curvatures (kappa1, kappa2), the mean of the two edge sides of
        ``kappa_bar_edges``; (kappa0 * D, 0) on a Frenet-aligned rest shape.
    kappa_bar_edges : (n_vertices, 2, 2)
        What the bending energy uses: the natural curvatures of each vertex measured in the material frame of
        its edge before (``[:, 0]``) and after (``[:, 1]``) it, components (kappa1, kappa2) last (see
        ``energies.bend``). The two sides differ where the rest shape twists between the edges. ``None``
        (a Rod built directly) means both sides equal ``kappa_bar``. Set both with ``with_natural``.
    twist_bar : (n_vertices,)
        Natural integrated twist (radians); omega0 * D in the continuum.
    rest_q : (n_dof,) state vector of the start (the rest shape for ``rod_from_shape``; the start of ``der.rod``,
    which may differ from its rest); rest_d1 : (n_edges, 3) its reference (= material) directors;
    rest_twist : (n_vertices,) its reference twist. The natural strains (``kappa_bar``, ``twist_bar``) and
    ``l_bar`` alone define the rest state.
    rho_A, rho_J : float
        Line density and rotational inertia per length used by the dynamics (they do not change equilibria).
    imposed_twist : float
        Ring only: the rotation (radians, right-handed about the tangent) with which its ends were welded
        (``with_imposed_twist``): at the wrap vertex 0 the first edge's material frame, continued from the
        last edge, is turned by it (``weld``), in the twisting and the bending energy alike.

    Where the nodes lie: an open rod of rest length L with n edges has n + 1 nodes; its end cross-sections
    (where clamps, end forces and end torques act) are the midpoints of the end edges, at xi = 0 and xi = L,
    so the first and last nodes lie half an edge outside [0, L] (``xi_nodes``). A ring has n nodes.

    Build one with ``der.rod(rest=..., start=..., A1=..., A2=...)`` (rest and start apart, stiffness varying) or
    ``der.rod_from_shape`` (rest = start = a shape); the copies ``with_natural``, ``with_stiffness`` and
    ``with_imposed_twist`` change one property. A rod is immutable; its configuration is a ``RodState``.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1, 100), A1=1.0, A2=1.5)
    >>> rod
    Rod(open, n_edges=100, L=5.387, A1=1, A2=1.5, EA=None (inextensible), kappa0 ~ 1, omega0 ~ 0.6)
    >>> state = rod.rest_state()
    """

    closed: bool
    A1: float
    A2: float
    EA: float | None
    edge_nodes: np.ndarray
    vertex_nodes: np.ndarray
    vertex_edges: np.ndarray
    l_bar: np.ndarray
    voronoi: np.ndarray
    kappa_bar: np.ndarray
    twist_bar: np.ndarray
    rest_q: np.ndarray
    rest_d1: np.ndarray
    rest_twist: np.ndarray
    rho_A: float = 1.0
    rho_J: float | None = None
    imposed_twist: float = 0.0
    kappa_bar_edges: np.ndarray | None = None
    A1prime: float | np.ndarray | None = None

    # -- stiffness along the rod (floats for a uniform rod, arrays for one that varies: ``der.rod``) --------

    @property
    def isotropic(self):
        """True when the two bending stiffnesses are equal (``A1prime`` None): a circular-like cross-section."""
        return self.A1prime is None

    def bending_stiffness(self):
        """(n_vertices, 2) array of (A1, A1') per vertex, force * length^2: A1 for the material curvature
        kappa1 = kb . m2 (bending towards m1, about m2), A1' for kappa2 = -kb . m1 (bending towards m2, about m1)."""
        nv = self.n_vertices
        a1 = np.broadcast_to(np.asarray(self.A1, float), (nv,))
        a2 = a1 if self.A1prime is None else np.broadcast_to(np.asarray(self.A1prime, float), (nv,))
        return np.stack([a1, a2], axis=1)

    def twisting_stiffness(self):
        """(n_vertices,) array of the twisting stiffness A2 per vertex (force * length^2)."""
        return np.broadcast_to(np.asarray(self.A2, float), (self.n_vertices,)).copy()

    def axial_stiffness(self):
        """(n_edges,) array of EA per edge (force), or None for an inextensible rod."""
        if self.EA is None:
            return None
        return np.broadcast_to(np.asarray(self.EA, float), (self.n_edges,)).copy()

    @property
    def uniform(self):
        """True when A1, A2 are single numbers and A1' = A1 (every rod built by ``rod_from_shape``)."""
        return np.ndim(self.A1) == 0 and np.ndim(self.A2) == 0 and self.A1prime is None

    def kernel_bending(self):
        """What the bending kernels take (``energies.stiffness.bending_at``): the float ``A1`` of a uniform rod
        (every result bitwise that of a scalar stiffness), else the (n_vertices, 2) array of (A1, A1'). Two
        types only, so that the kernels are compiled twice at most (``der.warmup`` does both)."""
        if self.uniform:
            return self.A1
        return np.ascontiguousarray(self.bending_stiffness())

    def kernel_twisting(self):
        """What the twisting kernels take: the float ``A2`` of a uniform rod, else the (n_vertices,) array."""
        if self.uniform:
            return self.A2
        return np.ascontiguousarray(self.twisting_stiffness())

    @property
    def bending_scale(self):
        """The largest bending stiffness (force * length^2): what the solvers' scales use; ``A1`` of a uniform
        isotropic rod."""
        if np.ndim(self.A1) == 0 and self.A1prime is None:
            return self.A1
        return float(max(np.max(self.A1), np.max(self.A1 if self.A1prime is None else self.A1prime)))

    @property
    def twisting_scale(self):
        """The largest twisting stiffness (force * length^2); ``A2`` of a uniform rod."""
        return self.A2 if np.ndim(self.A2) == 0 else float(np.max(self.A2))

    def natural_curvature_edges(self):
        """The (n_vertices, 2, 2) natural curvatures per edge side the bending energy uses (``kappa_bar_edges``,
        or ``kappa_bar`` on both sides when it is None). Raises ValueError if ``kappa_bar`` was replaced
        without ``kappa_bar_edges`` (their means disagree)."""
        kb = np.asarray(self.kappa_bar, float)
        if self.kappa_bar_edges is None:
            return np.ascontiguousarray(np.repeat(kb[:, None, :], 2, axis=1))
        ke = np.asarray(self.kappa_bar_edges, float)
        if ke.shape != (kb.shape[0], 2, 2):
            raise ValueError(f"Rod.kappa_bar_edges must have shape ({kb.shape[0]}, 2, 2); got {ke.shape}")
        # (the mean over the two sides without ndarray.mean's strided reduction: 10 ms at 10^5 edges, every solve)
        if np.abs((ke[:, 0] + ke[:, 1]) / 2.0 - kb).max(initial=0.0) > 1e-12 * max(1.0, np.abs(kb).max(initial=0.0)):
            raise ValueError("Rod.kappa_bar disagrees with the mean of Rod.kappa_bar_edges (was kappa_bar replaced "
                             "alone?); set natural curvatures with Rod.with_natural(kappa_bar=...)")
        return np.ascontiguousarray(ke)

    def __repr__(self):
        kind = "ring" if self.closed else "open"

        def show(a):
            if np.ndim(a) == 0:
                return f"{a:.4g}"
            return f"{np.min(a):.4g}..{np.max(a):.4g}"
        ea = "None (inextensible)" if self.EA is None else show(self.EA)
        a1 = show(self.A1) + ("" if self.A1prime is None else f", A1'={show(self.A1prime)}")
        text = f"Rod({kind}, n_edges={self.n_edges}, L={self.length:.4g}, A1={a1}, A2={show(self.A2)}, EA={ea}"
        if self.voronoi.size:
            k0 = np.linalg.norm(self.kappa_bar, axis=1) / self.voronoi
            w0 = self.twist_bar / self.voronoi
            text += f", kappa0 ~ {np.median(k0):.3g}, omega0 ~ {np.median(w0):.3g}"
        if self.closed and self.imposed_twist:
            text += f", imposed_twist={self.imposed_twist:.6g}"
        return text + ")"

    @property
    def weld(self):
        """Per vertex: the turn of edge f's material frame as seen from edge e (radians); nonzero only at
        vertex 0 of a ring welded with ``imposed_twist``."""
        w = np.zeros(self.vertex_nodes.shape[0])
        if self.closed:
            w[0] = self.imposed_twist
        return w

    @property
    def n_edges(self):
        """Number of edges n."""
        return self.edge_nodes.shape[0]

    @property
    def n_nodes(self):
        """Number of nodes: n + 1 for an open rod, n for a ring."""
        return self.n_edges if self.closed else self.n_edges + 1

    @property
    def n_vertices(self):
        """Number of interior vertices (bending/twisting stencils): n - 1 for an open rod, n for a ring."""
        return self.vertex_nodes.shape[0]

    @property
    def n_dof(self):
        """Size of the state vector: 4 per node (x, y, z, theta of the edge leaving it).

        An open rod has no edge after its last node; that theta slot is a dummy, always held fixed.
        """
        return 4 * self.n_nodes

    @property
    def length(self):
        """Rest length L of the material rod (see ``xi_nodes``)."""
        if self.closed:
            return float(self.l_bar.sum())
        return float(self.l_bar.sum() - 0.5 * (self.l_bar[0] + self.l_bar[-1]))

    @property
    def xi_nodes(self):
        """Rest arc length xi of each node.

        An open rod's end cross-sections are the material frames of its end edges, so its arc length runs from
        the midpoint of the first edge (xi = 0) to the midpoint of the last (xi = L): the first and last nodes
        lie half an edge outside [0, L]. This puts a clamp, an end torque and an end force exactly at the
        rod's ends, and every vertex at the centre of its Voronoi cell, so that the discrete energy is a
        midpoint rule for the integral of Eq. 17 over [0, L] (second order, ends included).
        """
        xi = np.concatenate([[0.0], np.cumsum(self.l_bar)])[: self.n_nodes]
        return xi if self.closed else xi - 0.5 * self.l_bar[0]

    @property
    def xi_edges(self):
        """Rest arc length of each edge midpoint."""
        return np.cumsum(self.l_bar) - 0.5 * self.l_bar - (0.0 if self.closed else 0.5 * self.l_bar[0])

    def node_weights(self):
        """Length of [0, L] each node stands for (its Voronoi cell; zero for the two outer nodes of an open rod)."""
        w = np.zeros(self.n_nodes)
        np.add.at(w, self.edge_nodes[:, 0], 0.5 * self.l_bar)
        np.add.at(w, self.edge_nodes[:, 1], 0.5 * self.l_bar)
        if not self.closed:
            w[0] = w[-1] = 0.0
        return w

    def edge_weights(self):
        """Length of [0, L] each edge's material frame stands for (half the end edges of an open rod)."""
        w = self.l_bar.copy()
        if not self.closed:
            w[0] *= 0.5
            w[-1] *= 0.5
        return w

    @property
    def inextensible(self):
        """True when ``EA`` is None (the tension is a Lagrange multiplier)."""
        return self.EA is None

    def rest_state(self):
        """A fresh ``RodState`` equal to the rest shape (theta = 0, frames on the rest directors); for a rod built
        by ``der.rod`` with a separate start, the start (``start_state``; ``rest_q`` holds the start).

        Example
        -------
        >>> import der
        >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 10), 1.0, 1.0)
        >>> rod.rest_state().positions.shape
        (11, 3)
        """
        t = tangents(self.rest_q, self.edge_nodes)
        return RodState(self.rest_q.copy(), self.rest_d1.copy(), t, self.rest_twist.copy(),
                        np.zeros(self.n_edges))

    def start_state(self):
        """A fresh ``RodState`` at the rod's start (``der.rod(..., start=...)``; for ``rod_from_shape`` the rest
        shape). The same as ``rest_state()``, whose name predates rods whose start differs from their rest.

        Example
        -------
        >>> import der
        >>> r = der.rod(rest=der.shapes.arc(1.0, 2.0, 20), start="straight", A1=1.0, A2=1.0)
        >>> float(abs(r.start_state().positions[:, :2]).max())        # straight along e3
        0.0
        """
        return self.rest_state()

    def with_natural(self, kappa_bar=None, twist_bar=None):
        """A copy with other natural curvatures and/or twists, same rest shape.

        Parameters
        ----------
        kappa_bar : float, (n_vertices, 2) or (n_vertices, 2, 2) array, optional
            Natural INTEGRATED material curvatures (kappa1, kappa2) per vertex (dimensionless: curvature times
            the Voronoi length ``voronoi``); a scalar is used for every entry, e.g. 0 for a naturally straight
            rod bent into this shape. A (n_vertices, 2) array sets both edge sides of each vertex to it; an
            array of shape (n_vertices, 2, 2) sets the two sides apart (see ``kappa_bar_edges``). To rescale
            the natural curvature of a rest shape that twists between its edges, scale ``kappa_bar_edges``
            (``kappa_bar`` holds only the mean of the two sides). None keeps the rod's.
        twist_bar : float or (n_vertices,) array, optional
            Natural integrated twist per vertex (radians: omega0 times the Voronoi length). None keeps it.

        Example
        -------
        >>> import der
        >>> ring = der.rod_from_shape(der.shapes.ring(1.0, 50), 1.0, 1.5)
        >>> straight_ring = ring.with_natural(kappa_bar=0.0)          # Michell's naturally straight ring
        """
        nv = self.kappa_bar.shape[0]
        if kappa_bar is None:
            kb, ke = self.kappa_bar, self.kappa_bar_edges
        else:
            try:
                ndim = np.ndim(kappa_bar)
            except Exception:          # ragged input: finite_array below says what is wrong
                ndim = 0
            if ndim == 3:
                ke = self._natural(kappa_bar, "kappa_bar", (nv, 2, 2))
            else:
                ke = np.repeat(self._natural(kappa_bar, "kappa_bar", (nv, 2))[:, None, :], 2, axis=1)
            kb = ke.mean(axis=1)
        tb = self.twist_bar if twist_bar is None else self._natural(twist_bar, "twist_bar", self.twist_bar.shape)
        return replace(self, kappa_bar=kb, kappa_bar_edges=ke, twist_bar=tb)

    def _natural(self, value, name, shape):
        dims = ", ".join(str(d) for d in shape) + ("," if len(shape) == 1 else "")
        allowed = f"a finite number or an array of shape ({dims}) (one per vertex: this rod has {self.n_vertices})"
        arr = validate.finite_array(value, f"Rod.with_natural: {name}", None, allowed)
        if arr.ndim != 0 and arr.shape != shape:
            raise ValueError(f"Rod.with_natural: {name} must be {allowed}; got shape {arr.shape}")
        return np.broadcast_to(arr, shape).copy()

    def with_imposed_twist(self, twist):
        """A ring whose ends were welded after a rotation by ``twist`` radians about the tangent (extra
        linking number twist / 2 pi; any real value, e.g. to sweep through Michell's threshold).

        The weld sits at vertex 0 (between the last edge and the first): there the first edge's material
        frame, continued from the last edge, is turned by ``twist`` (``weld``). Once the edge angles relax, a
        naturally straight ring carries the uniform twist ``twist / L``. Calling it again replaces the weld.

        Example
        -------
        >>> import numpy as np, der
        >>> ring = der.rod_from_shape(der.shapes.ring(1.0, 50), 1.0, 1.5).with_imposed_twist(2 * np.pi)  # Lk = 1
        """
        if not self.closed:
            raise ValueError("with_imposed_twist: an imposed twist needs a closed ring (the rod is open); "
                             "twist an open rod with an end torque or a clamp rotation instead")
        twist = validate.finite_number(twist, "Rod.with_imposed_twist: twist (radians)")
        return replace(self, imposed_twist=twist)

    def displaced(self, state, dx=None, dtheta=None):
        """A copy of ``state`` with its nodes moved by ``dx`` and its edge angles turned by ``dtheta``.

        The reference frames are parallel-transported along the straight path, so the reference twist stays
        continuous (windings and a ring's linking number are kept). ``state`` is not modified.

        Parameters
        ----------
        state : RodState
            A state of this rod.
        dx : (n_nodes, 3) array, optional
            Node displacements (length units); a flat array of 3 n_nodes entries is accepted too.
        dtheta : float or (n_edges,) array, optional
            Turn of each edge's material frame about its tangent (radians, right-handed).

        Example
        -------
        A small out-of-plane kick of a ring, e.g. to start a buckling solve off the symmetric state:

        >>> import numpy as np, der
        >>> ring = der.rod_from_shape(der.shapes.ring(1.0, 40), 1.0, 1.5)
        >>> state = ring.rest_state()
        >>> dx = np.zeros((ring.n_nodes, 3))
        >>> dx[:, 2] = 1e-3 * np.sin(2 * np.linspace(0, 2 * np.pi, ring.n_nodes, endpoint=False))
        >>> kicked = ring.displaced(state, dx)
        """
        check_state(self, state, "Rod.displaced")
        if dx is not None:
            arr = validate.finite_array(dx, "Rod.displaced: dx", None,
                                        f"an array of shape ({self.n_nodes}, 3) (one displacement per node)")
            if arr.shape not in ((self.n_nodes, 3), (3 * self.n_nodes,)):
                raise ValueError(f"Rod.displaced: dx must be an array of shape ({self.n_nodes}, 3) (one displacement "
                                 f"per node); got shape {arr.shape}")
            dx = arr
        if dtheta is not None:
            arr = validate.finite_array(dtheta, "Rod.displaced: dtheta", None,
                                        f"a number or an array of shape ({self.n_edges},) (one angle per edge)")
            if arr.ndim != 0 and arr.shape != (self.n_edges,):
                raise ValueError(f"Rod.displaced: dtheta must be a number or an array of shape ({self.n_edges},) "
                                 f"(one angle per edge); got shape {arr.shape}")
            dtheta = arr
        from .geometry import transport_frames

        out = state.copy()
        if dx is not None:
            out.positions[:] += np.asarray(dx, float).reshape(self.n_nodes, 3)
        if dtheta is not None:
            out.theta[:] += np.asarray(dtheta, float)
        if not transport_frames(out.q, self.edge_nodes, self.vertex_edges, state.tangents, state.d1,
                                state.reference_twist, out.tangents, out.d1, out.reference_twist):
            raise ValueError("displaced: the displacement reverses or collapses an edge; use a smaller one")
        return out

    def with_stiffness(self, A1=None, A2=None, EA=..., A1prime=...):
        """A copy with other stiffnesses (same shape and rest state).

        Parameters
        ----------
        A1, A2 : float or (n_vertices,) array, optional
            Bending and twisting stiffness (force * length^2), > 0, uniform or one per vertex; None keeps the rod's.
        EA : float, (n_edges,) array or None, optional
            Axial stiffness (force), uniform or one per edge, or None for inextensible; omitted keeps the rod's.
        A1prime : float, (n_vertices,) array or None, optional
            Second bending stiffness A1' (bending towards m2, about m1; see ``bending_stiffness``); None makes the
            rod isotropic (A1' = A1); omitted keeps the rod's.

        Example
        -------
        >>> import der
        >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 10), 1.0, 1.0).with_stiffness(A2=2.0, EA=1e6)
        >>> ribbon = rod.with_stiffness(A1prime=10.0)      # ten times stiffer about m1
        """
        A1, A2, EA = _check_stiffness(self.A1 if A1 is None else A1, self.A2 if A2 is None else A2,
                                      self.EA if EA is ... else EA, "Rod.with_stiffness",
                                      self.n_vertices, self.n_edges)
        if A1prime is ...:
            A1prime = self.A1prime
        elif A1prime is not None:
            A1prime = _stiffness(A1prime, "Rod.with_stiffness: A1prime", self.n_vertices, "vertex",
                                 "bending stiffness about m1, force * length^2")
        return replace(self, A1=A1, A2=A2, EA=EA, A1prime=A1prime)


@dataclass(eq=False)
class RodState:
    """Mutable configuration of a rod.

    q : (n_dof,) node positions and edge angles theta, interleaved (see ``der.geometry``).
    d1 : (n_edges, 3) reference directors, parallel-transported in time.
    tangents : (n_edges, 3) unit tangents the reference directors belong to.
    reference_twist : (n_vertices,) reference twist, unwrapped (continuous in time).
    lam : (n_edges,) tension multipliers of an inextensible rod (force); zeros otherwise.
    penalty : (n_edges,) the axial penalty the solver used with ``lam`` (force/length), or None. The tension of
        edge j is ``lam_j + penalty_j g_j`` (g the elongation); ``der.diagnostics`` uses it.
    q_lo : (n_dof,) or None: the low parts of compensated coordinates, ``x = q + q_lo`` with |q_lo| <= ulp(q)/2
        (the solvers keep them, so that the state resolves a deformation far below the rounding of coordinates
        of size L; ``q`` alone is the state rounded to double precision). None means zero.

    Node positions and angles are views (``positions``, ``theta``); a state belongs to one rod (same sizes).
    Get one from ``Rod.rest_state()`` or ``der.solve(...).state``.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 10), 1.0, 1.0)
    >>> state = rod.rest_state()
    >>> state
    RodState(n_edges=10, n_nodes=11, |theta| <= 0, bounding box 0 x 0 x 1.111)
    >>> state.positions[-1]        # the outer node, half an edge beyond the end xi = L = 1
    array([0.        , 0.        , 1.05555556])
    """

    q: np.ndarray
    d1: np.ndarray
    tangents: np.ndarray
    reference_twist: np.ndarray
    lam: np.ndarray = field(default_factory=lambda: np.zeros(0))
    penalty: np.ndarray | None = None
    q_lo: np.ndarray | None = None

    def __repr__(self):
        n_edges = self.d1.shape[0]
        x = self.positions
        box = " x ".join(f"{v:.4g}" for v in (x.max(axis=0) - x.min(axis=0))) if x.size else "empty"
        th = float(np.abs(self.theta).max()) if n_edges else 0.0
        return (f"RodState(n_edges={n_edges}, n_nodes={x.shape[0]}, |theta| <= {th:.4g}, bounding box {box})")

    def copy(self):
        """An independent copy (all arrays copied)."""
        return RodState(self.q.copy(), self.d1.copy(), self.tangents.copy(), self.reference_twist.copy(),
                        self.lam.copy(), None if self.penalty is None else self.penalty.copy(),
                        None if self.q_lo is None else self.q_lo.copy())

    @property
    def positions(self):
        """Node positions, shape (n_nodes, 3) (a view into q)."""
        return self.q.reshape(-1, 4)[:, :3]

    @property
    def theta(self):
        """Edge angles theta, shape (n_edges,) (a view into q)."""
        return self.q.reshape(-1, 4)[: self.d1.shape[0], 3]

    def copy_from(self, other):
        """Overwrite this state's arrays in place with ``other``'s (same rod)."""
        self.q[:] = other.q
        self.d1[:] = other.d1
        self.tangents[:] = other.tangents
        self.reference_twist[:] = other.reference_twist
        self.lam[:] = other.lam
        if other.q_lo is None:
            if self.q_lo is not None:
                self.q_lo[:] = 0.0
        elif self.q_lo is None:
            self.q_lo = other.q_lo.copy()
        else:
            self.q_lo[:] = other.q_lo


# ---------------------------------------------------------------------------------------------
# construction
# ---------------------------------------------------------------------------------------------


def _stiffness(value, name, n, per, what):
    """A stiffness: a float > 0, or an array of n finite values > 0 (one per ``per``), or a TypeError/ValueError
    naming the argument."""
    allowed = f"a finite number > 0 ({what}) or an array of {n} such numbers (one per {per})"
    if np.ndim(value) == 0 and not isinstance(value, np.ndarray):
        return validate.positive_number(value, name, f"a finite number > 0 ({what})")
    arr = validate.finite_array(value, name, None, allowed)
    if arr.ndim == 0:
        return validate.positive_number(float(arr), name, allowed)
    if arr.shape != (n,):
        raise ValueError(f"{name} must be {allowed}; got shape {arr.shape}")
    if np.any(arr <= 0):
        i = int(np.argmax(arr <= 0))
        raise ValueError(f"{name} must be {allowed}; entry {i} is {arr[i]!r}")
    return arr.copy()


def _check_stiffness(A1, A2, EA, where="der.rod_from_shape", n_vertices=None, n_edges=None):
    """(A1, A2, EA) as floats or per-vertex / per-edge arrays (EA None for inextensible), or a
    TypeError/ValueError naming the argument. Arrays need ``n_vertices`` / ``n_edges``."""
    def one(value, name, n, per, what):
        if n is None:
            return validate.positive_number(value, f"{where}: {name}", f"a finite number > 0 ({what})")
        return _stiffness(value, f"{where}: {name}", n, per, what)
    A1 = one(A1, "A1", n_vertices, "vertex", "bending stiffness, force * length^2")
    A2 = one(A2, "A2", n_vertices, "vertex", "twisting stiffness, force * length^2")
    if EA is not None:
        if n_edges is None:
            EA = validate.positive_number(EA, f"{where}: EA", "None (inextensible) or a finite number > 0")
        else:
            EA = _stiffness(EA, f"{where}: EA", n_edges, "edge", "axial stiffness, force; None: inextensible")
    return A1, A2, EA


def check_state(rod, state, where):
    """Refuse, before any work, a state that is not a ``RodState`` of this rod (its array sizes differ)."""
    if not isinstance(state, RodState):
        raise TypeError(f"{where}: state must be a der.RodState (rod.rest_state() or a solve's result.state); got "
                        f"{type(state).__name__}")
    if state.q.shape != (rod.n_dof,) or state.d1.shape != (rod.n_edges, 3) \
            or state.reference_twist.shape != (rod.n_vertices,):
        raise ValueError(f"{where}: state does not belong to this rod: it has {state.d1.shape[0]} edges and "
                         f"{state.q.shape[0] // 4} nodes, the rod {rod.n_edges} edges and {rod.n_nodes} nodes")


def topology(n_edges, closed):
    """Edge and vertex index arrays ``(edge_nodes, vertex_nodes, vertex_edges)`` (int64) of an open rod or a ring with
    ``n_edges`` edges (``geometry.rod_topology``, one kernel pass)."""
    return rod_topology(int(n_edges), bool(closed))


def _perpendicular(t):
    """A unit vector normal to unit t (deterministic)."""
    a = np.zeros(3)
    a[np.argmin(np.abs(t))] = 1.0
    p = a - (a @ t) * t
    return p / np.linalg.norm(p)


def frenet_frame_of_shape(x, closed, director=None, min_curvature=1e-9):
    """Per-edge unit tangents and Frenet normals of a discrete curve.

    Where the curve is straight the normal is undefined; there it is taken from ``director`` (projected
    normal to the edge) if given, else parallel-transported from the nearest edge where it is defined.
    Returns ``(t, n, defined)``.
    """
    n_edges = x.shape[0] if closed else x.shape[0] - 1
    edge_nodes, _, vertex_edges = topology(n_edges, closed)
    q = np.zeros(4 * x.shape[0])
    q.reshape(-1, 4)[:, :3] = x
    t = tangents(q, edge_nodes)
    nrm, defined = _frenet_normals(t, vertex_edges, n_edges, director, min_curvature)
    return t, nrm, defined


def _frenet_normals(t, vertex_edges, n_edges, director=None, min_curvature=1e-9):
    """``frenet_frame_of_shape``'s normals and ``defined`` from the unit tangents ``t`` of the edges."""
    kb = curvature_binormals(t, vertex_edges)
    # threshold on the integrated curvature |kb| ~ kappa * l: relative to the edge length scale
    nrm, defined = frenet_directors(t, kb, vertex_edges, n_edges, min_curvature)
    nrm = nrm.copy()
    if director is not None:
        director = np.asarray(director, dtype=float)
        js = np.flatnonzero(~defined)
        d = np.broadcast_to(director, (n_edges, 3))[js]
        p = d - np.einsum("ij,ij->i", d, t[js])[:, None] * t[js]
        lp = np.sqrt(np.einsum("ij,ij->i", p, p))
        if js.size and np.any(lp < 1e-12):
            j = int(js[np.argmax(lp < 1e-12)])
            raise ValueError(f"director is parallel to edge {j}; give a director normal to the rod")
        nrm[js] = p / lp[:, None]
    elif not defined.all():
        if not defined.any():
            nrm[0] = _perpendicular(t[0])
            defined_now = np.zeros(n_edges, bool)
            defined_now[0] = True
        else:
            defined_now = defined.copy()
        # sweep forward then backward, transporting from the neighbour
        for j in range(1, n_edges):
            if not defined_now[j] and defined_now[j - 1]:
                nrm[j] = parallel_transport(nrm[j - 1], t[j - 1], t[j])
                defined_now[j] = True
        for j in range(n_edges - 2, -1, -1):
            if not defined_now[j] and defined_now[j + 1]:
                nrm[j] = parallel_transport(nrm[j + 1], t[j + 1], t[j])
                defined_now[j] = True
    return nrm, defined


def _shape_geometry(shape, where):
    """Validate a ``der.shapes.Shape`` and return ``(x, closed, edge_nodes, vertex_nodes, vertex_edges, le, t, d1)``:
    positions, topology, edge lengths, unit tangents and the material directors m1 (the discrete Frenet normal,
    or the shape's director where it is straight or where the shape asks for its director everywhere)."""
    if not hasattr(shape, "positions"):
        raise TypeError(f"{where}: shape must be a der.shapes.Shape (e.g. der.shapes.helix(...)); got "
                        f"{type(shape).__name__}")
    x = validate.finite_array(shape.positions, f"{where}: shape.positions", None,
                              "an array of real numbers of shape (n_nodes, 3)", finite=False)
    closed = bool(shape.closed)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"positions must have shape (n_nodes, 3); got {x.shape}")
    n_edges = x.shape[0] if closed else x.shape[0] - 1
    need = 3 if closed else 2
    if n_edges < need:
        kind = "a closed ring" if closed else "an open rod"
        raise ValueError(f"{kind} needs at least {need} edges; got {n_edges} (from {x.shape[0]} nodes)")
    # one kernel pass (issue 17): topology, edge lengths, unit tangents and the checks below, bitwise what the
    # NumPy expressions gave (tests/test_setup.py keeps them as the reference)
    edge_nodes, vertex_nodes, vertex_edges = rod_topology(n_edges, closed)
    x = np.ascontiguousarray(x, dtype=float)
    le, t, finite, scale, j, v, cos_min = shape_edges(x, edge_nodes, vertex_edges)
    if not finite:
        bad = np.argwhere(~np.isfinite(x))[0, 0]
        raise ValueError(f"positions must be finite; node {bad} is {x[bad].tolist()}")
    if le[j] <= 1e-12 * scale:
        raise ValueError(f"coincident nodes: edge {j} (nodes {edge_nodes[j].tolist()}) has length {le[j]:.3g}; "
                         "every edge must have positive length"
                         + (" (do not repeat the first node at the end of a closed ring)" if closed else ""))
    if cos_min <= -1 + 1e-8:
        raise ValueError(f"the rod folds back onto itself at node {vertex_nodes[v, 1]} (turning angle ~ 180 deg); "
                         "adjacent edges must turn by less than 180 degrees")
    director = getattr(shape, "director", None)
    if director is not None:
        director = np.asarray(director, dtype=float)
        if director.shape not in ((3,), (n_edges, 3)) or not np.all(np.isfinite(director)):
            raise ValueError(f"director must be a finite 3-vector or have shape ({n_edges}, 3); got {director.shape}")
    if getattr(shape, "frame", "frenet") == "director":
        # the shape's own director on every edge (e.g. a ribbon's width direction), projected normal to it
        if director is None:
            raise ValueError(f"{where}: a shape with frame='director' needs a director")
        d = np.broadcast_to(director, (n_edges, 3))
        p = d - np.einsum("ij,ij->i", d, t)[:, None] * t
        lp = np.linalg.norm(p, axis=1)
        if np.any(lp < 1e-12):
            raise ValueError(f"director is parallel to edge {int(np.argmin(lp))}; give a director normal to the rod")
        d1 = p / lp[:, None]
    else:
        d1, _ = _frenet_normals(t, vertex_edges, n_edges, director)
    return x, closed, edge_nodes, vertex_nodes, vertex_edges, le, t, d1


def _measure(x, edge_nodes, vertex_edges, t, d1):
    """State vector, reference twist and the natural curvatures per edge side of a shape with material directors
    ``d1``, measured with the bending energy's own kernel (so that this shape has exactly zero force)."""
    q = np.zeros(4 * x.shape[0])
    q.reshape(-1, 4)[:, :3] = x
    # one kernel pass per quantity (a Python loop over vertices cost 4 s at 10^5 edges)
    twist = reference_twists(t, np.ascontiguousarray(d1), vertex_edges)
    ed = edge_frames(q, edge_nodes, d1)
    no_weld = np.zeros(vertex_edges.shape[0])
    kappa_bar_edges = material_curvatures_all(ed, vertex_edges, no_weld).reshape(-1, 2, 2)
    return q, twist, kappa_bar_edges


def rod_from_shape(shape, A1, A2, EA=None, rho_A=1.0, rho_J=None):
    """Build a ``Rod`` whose rest state is ``shape`` with its material frame on the discrete Frenet frame.

    Parameters
    ----------
    shape : der.shapes.Shape
        Node positions (and, for straight parts, a director).
    A1, A2 : float
        Bending and twisting stiffness (force * length^2), > 0.
    EA : float or None
        Axial stiffness (force); None for an inextensible rod (the paper's model, the default).
    rho_A, rho_J : float
        Line density and rotational inertia per length for the dynamics (defaults: 1 and a value that
        puts the twist waves at the same speed as the bending waves at the edge scale).

    Raises ValueError, before any work, for too few edges, non-finite or coincident nodes, edges folding
    back onto each other, or non-positive stiffness.
    """
    if not hasattr(shape, "positions"):
        raise TypeError(f"der.rod_from_shape: shape must be a der.shapes.Shape (e.g. der.shapes.helix(...)); got "
                        f"{type(shape).__name__}")
    validate.finite_array(shape.positions, "der.rod_from_shape: shape.positions", None,
                          "an array of real numbers of shape (n_nodes, 3)", finite=False)
    A1, A2, EA = _check_stiffness(A1, A2, EA)
    rho_A, rho_J = _check_inertia(rho_A, rho_J, "der.rod_from_shape")
    x, closed, edge_nodes, vertex_nodes, vertex_edges, le, t, d1 = _shape_geometry(shape, "der.rod_from_shape")
    q, rest_twist, kappa_bar_edges = _measure(x, edge_nodes, vertex_edges, t, d1)
    # kappa_bar_edges.mean(axis=1), bitwise (its sum starts from +0.0: -0.0 + -0.0 gives +0.0), without its slow
    # strided reduction (10-15 ms at 10^5 edges)
    kappa_bar = (kappa_bar_edges[:, 0] + kappa_bar_edges[:, 1] + 0.0) / 2.0
    voronoi = 0.5 * (le[vertex_edges[:, 0]] + le[vertex_edges[:, 1]])
    return Rod(closed=closed, A1=float(A1), A2=float(A2), EA=None if EA is None else float(EA),
               edge_nodes=edge_nodes, vertex_nodes=vertex_nodes, vertex_edges=vertex_edges,
               l_bar=le, voronoi=voronoi, kappa_bar=kappa_bar, kappa_bar_edges=kappa_bar_edges,
               twist_bar=rest_twist.copy(),
               rest_q=q, rest_d1=d1, rest_twist=rest_twist, rho_A=rho_A, rho_J=rho_J)


def _check_inertia(rho_A, rho_J, where):
    rho_A = validate.positive_number(rho_A, f"{where}: rho_A", "a finite number > 0 (mass per length)")
    if rho_J is not None:
        rho_J = validate.positive_number(rho_J, f"{where}: rho_J",
                                         "None or a finite number > 0 (rotational inertia per length)")
    return float(rho_A), (None if rho_J is None else float(rho_J))


def _along(value, name, xi, per, what):
    """A stiffness given as a number, an array (one per vertex or edge) or a function of the rest arc length
    (evaluated at ``xi``); a float for a number, else a validated array."""
    if callable(value):
        from .shapes import _evaluate

        value = _evaluate(value, xi, name.split(": ")[-1], name.split(": ")[0])
    return _stiffness(value, name, xi.size, per, what)


def rod(rest, start=None, *, A1, A2, EA=None, A1prime=None, rho_A=1.0, rho_J=None):
    """Build a ``Rod`` from a rest description and a separate starting state (issue 13).

    The rest state (natural strains and rest lengths) and the start (where a solve begins) are independent: a
    rod can be straight now and curved at rest (a bimetal strip, intrinsically curved DNA, a flagellum that
    switches form), and its stiffnesses can vary along it.

    Parameters
    ----------
    rest : der.shapes.Shape or der.shapes.Strains
        A shape (``der.shapes.helix``, ``polyline``, ``spline``, ``varying_helix``, ...): its rest lengths are its
        edge lengths, its natural curvatures (both material components, per edge side) and twists are measured
        on it with the energies' own kernels (material frame on its Frenet frame, or on its director for
        ``polyline(..., director=...)``), so that this shape is exactly force-free. Or strains along the arc
        length (``der.shapes.strains``: kappa1, kappa2, omega0 per vertex, the rest edge lengths equal or given).
    start : None, "rest", "straight" or der.shapes.Shape
        The starting state (``Rod.start_state()``, what ``der.solve`` starts from). None: the rest shape when
        ``rest`` is a shape, else "straight". "straight": along e3 from the origin, with the rest edge lengths,
        m1 = e1 (an open rod only). A shape: those node positions (same number of edges as the rest; an
        inextensible rod's edges are pulled to their rest lengths by the solve), material frame on its
        Frenet frame or director, theta = 0.
    A1 : float, (n_vertices,) array or callable
        Bending stiffness for the material curvature kappa1 (bending towards m1, about m2), force * length^2,
        > 0: uniform, one per vertex, or a function of the rest arc length xi evaluated at the vertices.
    A2 : float, (n_vertices,) array or callable
        Twisting stiffness (force * length^2), > 0, likewise.
    EA : None, float, (n_edges,) array or callable
        Axial stiffness (force), uniform, per edge or a function of xi evaluated at the edge midpoints; None
        (default): inextensible.
    A1prime : None, float, (n_vertices,) array or callable
        Second bending stiffness A1' for kappa2 (bending towards m2, about m1); None (default): A1' = A1,
        isotropic (every result then bitwise that of an isotropic rod). ``der.sections`` computes A1, A1', A2,
        EA of circles, annuli, rectangles and ellipses.
    rho_A, rho_J : float
        Line density and rotational inertia per length for the dynamics (as for ``rod_from_shape``).

    Returns
    -------
    Rod (``Rod.start_state()`` is the start; ``rod_from_shape(shape, ...)`` is ``rod(rest=shape, ...)``).

    Raises TypeError/ValueError, before any work, naming the argument: a rest or start of the wrong type, a
    start with another number of edges, a "straight" start of a ring, a non-positive or non-finite stiffness, an
    array of the wrong length.

    Example
    -------
    A rod straight at start with a step in its natural curvature (a "perversion"), tapered in bending:

    >>> import der
    >>> rest = der.shapes.strains(length=2.0, n=40, kappa1=lambda s: 2.0 if s < 1.0 else -2.0)
    >>> r = der.rod(rest=rest, start="straight", A1=lambda s: 1.0 + 0.5 * s, A2=1.0)
    >>> r.bending_stiffness().shape, r.start_state().positions[-1].round(3).tolist()
    ((39, 2), [0.0, 0.0, 2.026])
    """
    from .shapes import Shape, Strains

    where = "der.rod"
    rho_A, rho_J = _check_inertia(rho_A, rho_J, where)
    if isinstance(rest, Strains):
        n_edges, closed = rest.n, rest.closed
        l_bar = np.array(rest.l_bar, dtype=float)
        edge_nodes, vertex_nodes, vertex_edges = topology(n_edges, closed)
        voronoi = 0.5 * (l_bar[vertex_edges[:, 0]] + l_bar[vertex_edges[:, 1]])
        k = rest.kappa * voronoi[:, None]            # integrated material curvature at the vertex's mid frame
        twist_bar = rest.omega * voronoi
        # edge e's frame sees it turned back by half the natural twist, edge f's forward (kappa^f = R(-m) kappa^e,
        # see energies.bend): a discrete state with exactly these strains exists, with zero force
        c, s = np.cos(0.5 * twist_bar), np.sin(0.5 * twist_bar)
        ke = np.stack([c * k[:, 0] - s * k[:, 1], s * k[:, 0] + c * k[:, 1]], axis=1)
        kf = np.stack([c * k[:, 0] + s * k[:, 1], -s * k[:, 0] + c * k[:, 1]], axis=1)
        kappa_bar_edges = np.ascontiguousarray(np.stack([ke, kf], axis=1))
        rest_shape = None
    elif isinstance(rest, Shape) or hasattr(rest, "positions"):
        x, closed, edge_nodes, vertex_nodes, vertex_edges, l_bar, t, d1 = _shape_geometry(rest, f"{where}: rest")
        n_edges = l_bar.size
        rq, twist_bar, kappa_bar_edges = _measure(x, edge_nodes, vertex_edges, t, d1)
        twist_bar = twist_bar.copy()
        voronoi = 0.5 * (l_bar[vertex_edges[:, 0]] + l_bar[vertex_edges[:, 1]])
        rest_shape = (rq, d1, twist_bar.copy())
    else:
        raise TypeError(f"{where}: rest must be a der.shapes.Shape (e.g. der.shapes.arc(...)) or der.shapes.Strains "
                        f"(der.shapes.strains(...)); got {type(rest).__name__}")

    if start is None:
        start = "rest" if rest_shape is not None else "straight"
    if isinstance(start, str):
        if start == "rest":
            if rest_shape is None:
                raise ValueError(f"{where}: start='rest' needs a rest shape; the rest is given by its strains "
                                 "(allowed: 'straight' or a der.shapes.Shape)")
            q, d1s, ref = rest_shape
            q = q.copy()
        elif start == "straight":
            if closed:
                raise ValueError(f"{where}: start='straight' is not possible for a ring; give a start shape "
                                 "(e.g. der.shapes.ring(...))")
            z = np.concatenate([[0.0], np.cumsum(l_bar)]) - 0.5 * l_bar[0]
            q = np.zeros(4 * (n_edges + 1))
            q.reshape(-1, 4)[:, 2] = z
            d1s = np.tile([1.0, 0.0, 0.0], (n_edges, 1))
            ref = np.zeros(vertex_edges.shape[0])
        else:
            raise ValueError(f"{where}: start must be None, 'rest', 'straight' or a der.shapes.Shape; got {start!r}")
    elif isinstance(start, Shape) or hasattr(start, "positions"):
        xs, closed_s, _, _, _, ls, ts, d1s = _shape_geometry(start, f"{where}: start")
        if closed_s != closed or ls.size != n_edges:
            raise ValueError(f"{where}: start must have the rest's {n_edges} edges and be "
                             f"{'closed' if closed else 'open'}; got {ls.size} edges, "
                             f"{'closed' if closed_s else 'open'}")
        q, ref, _ = _measure(xs, edge_nodes, vertex_edges, ts, d1s)
    else:
        raise TypeError(f"{where}: start must be None, 'rest', 'straight' or a der.shapes.Shape; got "
                        f"{type(start).__name__}")

    # stiffnesses at the vertices (bending, twisting) and at the edge midpoints (stretching)
    xi_nodes = np.concatenate([[0.0], np.cumsum(l_bar)])[: (n_edges if closed else n_edges + 1)]
    if not closed:
        xi_nodes = xi_nodes - 0.5 * l_bar[0]
    xi_v = xi_nodes[vertex_nodes[:, 1]]
    xi_e = np.cumsum(l_bar) - 0.5 * l_bar - (0.0 if closed else 0.5 * l_bar[0])
    A1 = _along(A1, f"{where}: A1", xi_v, "vertex", "bending stiffness, force * length^2")
    A2 = _along(A2, f"{where}: A2", xi_v, "vertex", "twisting stiffness, force * length^2")
    if A1prime is not None:
        A1prime = _along(A1prime, f"{where}: A1prime", xi_v, "vertex", "bending stiffness about m1, force * length^2")
    if EA is not None:
        EA = _along(EA, f"{where}: EA", xi_e, "edge", "axial stiffness, force; None: inextensible")
    return Rod(closed=closed, A1=A1, A2=A2, EA=EA, A1prime=A1prime,
               edge_nodes=edge_nodes, vertex_nodes=vertex_nodes, vertex_edges=vertex_edges,
               l_bar=l_bar, voronoi=voronoi, kappa_bar=kappa_bar_edges.mean(axis=1), kappa_bar_edges=kappa_bar_edges,
               twist_bar=twist_bar, rest_q=q, rest_d1=np.ascontiguousarray(d1s), rest_twist=ref,
               rho_A=rho_A, rho_J=rho_J)
