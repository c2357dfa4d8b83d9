"""The rod: topology, rest state (natural curvature and twist), stiffnesses, and its mutable state.

A ``Rod`` is built from a discrete shape (``der.shapes``) whose material frame is put on the discrete Frenet
frame (alpha = 0). Its natural material curvatures and natural twist are measured on that discrete shape
with the same kernels the energies use, so the rest state has zero force to round-off.

Units: lengths in any consistent unit L; A1, A2 in force * L^2; EA in force; energies in force * L.
"""
from dataclasses import dataclass, field, replace

import numpy as np

from .energies.bend import material_curvatures
from .geometry import (
    curvature_binormals, edge_frames, frenet_directors, parallel_transport, reference_twist_angle, tangents,
)


@dataclass(frozen=True, eq=False)
class Rod:
    """An elastic rod with natural curvature and twist (immutable definition).

    Attributes
    ----------
    closed : bool
        True for a ring (the last node joins the first).
    A1, A2 : float
        Bending and twisting stiffness (paper Eq. 17), force * length^2.
    EA : float or None
        Axial stiffness (force). ``None`` (default): inextensible, enforced exactly by the solvers.
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
    rest_q : (n_dof,) rest state vector; rest_d1 : (n_edges, 3) rest reference (= material) directors;
    rest_twist : (n_vertices,) rest reference twist.
    rho_A, rho_J : float
        Line density and rotational inertia per length used by the dynamics (they do not change equilibria).
    imposed_twist : float
        Ring only: the rotation (radians, right-handed about the tangent) with which its ends were welded
        (``with_imposed_twist``): at the wrap vertex 0 the first edge's material frame, continued from the
        last edge, is turned by it (``weld``), in the twisting and the bending energy alike.
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
        if np.abs(ke.mean(axis=1) - kb).max(initial=0.0) > 1e-12 * max(1.0, np.abs(kb).max(initial=0.0)):
            raise ValueError("Rod.kappa_bar disagrees with the mean of Rod.kappa_bar_edges (was kappa_bar replaced "
                             "alone?); set natural curvatures with Rod.with_natural(kappa_bar=...)")
        return np.ascontiguousarray(ke)

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
        return self.edge_nodes.shape[0]

    @property
    def n_nodes(self):
        return self.n_edges if self.closed else self.n_edges + 1

    @property
    def n_vertices(self):
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
        return self.EA is None

    def rest_state(self):
        """A fresh state equal to the rest shape."""
        t = tangents(self.rest_q, self.edge_nodes)
        return RodState(self.rest_q.copy(), self.rest_d1.copy(), t, self.rest_twist.copy(),
                        np.zeros(self.n_edges))

    def with_natural(self, kappa_bar=None, twist_bar=None):
        """A copy with other natural integrated curvatures and/or twists (n_vertices,), same shape: e.g.
        ``kappa_bar=0`` for a naturally straight rod bent into the shape.

        ``kappa_bar`` broadcastable to (n_vertices, 2) sets both edge sides of each vertex to it; an array of
        shape (n_vertices, 2, 2) sets the two sides apart (see ``kappa_bar_edges``). To rescale the natural
        curvature of a rest shape that twists between its edges, scale ``kappa_bar_edges`` (``kappa_bar`` holds
        only the mean of the two sides)."""
        nv = self.kappa_bar.shape[0]
        if kappa_bar is None:
            kb, ke = self.kappa_bar, self.kappa_bar_edges
        else:
            arr = np.asarray(kappa_bar, float)
            if arr.ndim == 3:
                if arr.shape != (nv, 2, 2):
                    raise ValueError(f"with_natural: a per-edge-side kappa_bar must have shape ({nv}, 2, 2); "
                                     f"got {arr.shape}")
                ke = arr.copy()
            else:
                try:
                    arr = np.broadcast_to(arr, (nv, 2))
                except ValueError:
                    raise ValueError(f"with_natural: kappa_bar must broadcast to ({nv}, 2) or have shape ({nv}, 2, 2); "
                                     f"got {arr.shape}") from None
                ke = np.repeat(arr[:, None, :], 2, axis=1)
            kb = ke.mean(axis=1)
        tb = self.twist_bar if twist_bar is None else np.broadcast_to(np.asarray(twist_bar, float),
                                                                     self.twist_bar.shape).copy()
        if not (np.all(np.isfinite(kb)) and np.all(np.isfinite(tb))):
            raise ValueError("natural curvatures and twists must be finite")
        return replace(self, kappa_bar=kb, kappa_bar_edges=ke, twist_bar=tb)

    def with_imposed_twist(self, twist):
        """A ring whose ends were welded after a rotation by ``twist`` radians about the tangent (extra
        linking number twist / 2 pi; any real value, e.g. to sweep through Michell's threshold).

        The weld sits at vertex 0 (between the last edge and the first): there the first edge's material
        frame, continued from the last edge, is turned by ``twist`` (``weld``). Once the edge angles relax, a
        naturally straight ring carries the uniform twist ``twist / L``. Calling it again replaces the weld.
        """
        if not self.closed:
            raise ValueError("with_imposed_twist: an imposed twist needs a closed ring (the rod is open); "
                             "twist an open rod with an end torque or a clamp rotation instead")
        twist = float(twist)
        if not np.isfinite(twist):
            raise ValueError(f"with_imposed_twist: twist must be finite; got {twist}")
        return replace(self, imposed_twist=twist)

    def displaced(self, state, dx=None, dtheta=None):
        """A copy of ``state`` with its nodes moved by ``dx`` (n_nodes, 3) and its edge angles turned by
        ``dtheta`` (n_edges,) [radians], reference frames parallel-transported along the straight path (so
        the reference twist stays continuous: windings and a ring's linking number are kept)."""
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

    def with_stiffness(self, A1=None, A2=None, EA=...):
        """A copy with other stiffnesses (same shape and rest state)."""
        new = replace(self, A1=self.A1 if A1 is None else float(A1), A2=self.A2 if A2 is None else float(A2),
                      EA=self.EA if EA is ... else EA)
        _check_stiffness(new.A1, new.A2, new.EA)
        return new


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
    """

    q: np.ndarray
    d1: np.ndarray
    tangents: np.ndarray
    reference_twist: np.ndarray
    lam: np.ndarray = field(default_factory=lambda: np.zeros(0))
    penalty: np.ndarray | None = None

    def copy(self):
        return RodState(self.q.copy(), self.d1.copy(), self.tangents.copy(), self.reference_twist.copy(),
                        self.lam.copy(), None if self.penalty is None else self.penalty.copy())

    @property
    def positions(self):
        """Node positions, shape (n_nodes, 3) (a view into q)."""
        return self.q.reshape(-1, 4)[:, :3]

    @property
    def theta(self):
        """Edge angles theta, shape (n_edges,) (a view into q)."""
        return self.q.reshape(-1, 4)[: self.d1.shape[0], 3]

    def copy_from(self, other):
        self.q[:] = other.q
        self.d1[:] = other.d1
        self.tangents[:] = other.tangents
        self.reference_twist[:] = other.reference_twist
        self.lam[:] = other.lam


# ---------------------------------------------------------------------------------------------
# construction
# ---------------------------------------------------------------------------------------------


def _check_stiffness(A1, A2, EA):
    for name, val in (("A1", A1), ("A2", A2)):
        if not (isinstance(val, (int, float, np.floating, np.integer)) and np.isfinite(val) and val > 0):
            raise ValueError(f"{name} must be a finite number > 0 (bending/twisting stiffness); got {val!r}")
    if EA is not None and not (np.isfinite(EA) and EA > 0):
        raise ValueError(f"EA must be None (inextensible) or a finite number > 0; got {EA!r}")


def topology(n_edges, closed):
    """Edge and vertex index arrays of an open rod or a ring with ``n_edges`` edges."""
    n_nodes = n_edges if closed else n_edges + 1
    j = np.arange(n_edges)
    edge_nodes = np.stack([j, (j + 1) % n_nodes], axis=1).astype(np.int64)
    if closed:
        v = np.arange(n_edges)
        vertex_nodes = np.stack([(v - 1) % n_nodes, v, (v + 1) % n_nodes], axis=1)
        vertex_edges = np.stack([(v - 1) % n_edges, v], axis=1)
    else:
        v = np.arange(1, n_edges)
        vertex_nodes = np.stack([v - 1, v, v + 1], axis=1)
        vertex_edges = np.stack([v - 1, v], axis=1)
    return edge_nodes, vertex_nodes.astype(np.int64), vertex_edges.astype(np.int64)


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
    kb = curvature_binormals(t, vertex_edges)
    # threshold on the integrated curvature |kb| ~ kappa * l: relative to the edge length scale
    nrm, defined = frenet_directors(t, kb, vertex_edges, n_edges, min_curvature)
    nrm = nrm.copy()
    if director is not None:
        director = np.asarray(director, dtype=float)
        for j in np.flatnonzero(~defined):
            d = director if director.ndim == 1 else director[j]
            p = d - (d @ t[j]) * t[j]
            if np.linalg.norm(p) < 1e-12:
                raise ValueError(f"director is parallel to edge {j}; give a director normal to the rod")
            nrm[j] = p / np.linalg.norm(p)
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
    return t, nrm, defined


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
    x = np.asarray(shape.positions, dtype=float)
    closed = bool(shape.closed)
    _check_stiffness(A1, A2, EA)
    if not (np.isfinite(rho_A) and rho_A > 0):
        raise ValueError(f"rho_A must be finite and > 0; got {rho_A!r}")
    if rho_J is not None and not (np.isfinite(rho_J) and rho_J > 0):
        raise ValueError(f"rho_J must be None or finite and > 0; got {rho_J!r}")
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"positions must have shape (n_nodes, 3); got {x.shape}")
    n_edges = x.shape[0] if closed else x.shape[0] - 1
    need = 3 if closed else 2
    if n_edges < need:
        kind = "a closed ring" if closed else "an open rod"
        raise ValueError(f"{kind} needs at least {need} edges; got {n_edges} (from {x.shape[0]} nodes)")
    if not np.all(np.isfinite(x)):
        bad = np.argwhere(~np.isfinite(x))[0, 0]
        raise ValueError(f"positions must be finite; node {bad} is {x[bad].tolist()}")
    edge_nodes, vertex_nodes, vertex_edges = topology(n_edges, closed)
    e = x[edge_nodes[:, 1]] - x[edge_nodes[:, 0]]
    le = np.linalg.norm(e, axis=1)
    scale = max(np.max(np.abs(x)), le.max())
    if np.any(le <= 1e-12 * scale):
        j = int(np.argmin(le))
        raise ValueError(f"coincident nodes: edge {j} (nodes {edge_nodes[j].tolist()}) has length {le[j]:.3g}; "
                         "every edge must have positive length"
                         + (" (do not repeat the first node at the end of a closed ring)" if closed else ""))
    t = e / le[:, None]
    cos_turn = np.einsum("ij,ij->i", t[vertex_edges[:, 0]], t[vertex_edges[:, 1]])
    if np.any(cos_turn <= -1 + 1e-8):
        v = int(np.argmin(cos_turn))
        raise ValueError(f"the rod folds back onto itself at node {vertex_nodes[v, 1]} (turning angle ~ 180 deg); "
                         "adjacent edges must turn by less than 180 degrees")
    director = getattr(shape, "director", None)
    if director is not None:
        director = np.asarray(director, dtype=float)
        if director.shape not in ((3,), (n_edges, 3)) or not np.all(np.isfinite(director)):
            raise ValueError(f"director must be a finite 3-vector or have shape ({n_edges}, 3); got {director.shape}")
    _, d1, _ = frenet_frame_of_shape(x, closed, director)

    q = np.zeros(4 * x.shape[0])
    q.reshape(-1, 4)[:, :3] = x
    rest_twist = np.array([reference_twist_angle(t[a], d1[a], t[b], d1[b]) for a, b in vertex_edges])
    ed = edge_frames(q, edge_nodes, d1)
    no_weld = np.zeros(vertex_nodes.shape[0])
    # natural curvatures in each edge's frame, with the energy's own kernel: the rest state is force-free
    kappa_bar_edges = np.array([material_curvatures(ed, vertex_edges, no_weld, v)
                                for v in range(vertex_nodes.shape[0])]).reshape(-1, 2, 2)
    kappa_bar = kappa_bar_edges.mean(axis=1)
    voronoi = 0.5 * (le[vertex_edges[:, 0]] + le[vertex_edges[:, 1]])
    return Rod(closed=closed, A1=float(A1), A2=float(A2), EA=None if EA is None else float(EA),
               edge_nodes=edge_nodes, vertex_nodes=vertex_nodes, vertex_edges=vertex_edges,
               l_bar=le, voronoi=voronoi, kappa_bar=kappa_bar, kappa_bar_edges=kappa_bar_edges,
               twist_bar=rest_twist.copy(),
               rest_q=q, rest_d1=d1, rest_twist=rest_twist, rho_A=float(rho_A),
               rho_J=None if rho_J is None else float(rho_J))
