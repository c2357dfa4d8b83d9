"""Diagnostics along the rod, in the paper's variables.

Where things live: curvature ``kappa``, geometric torsion ``omega``, material twist and the internal moment
``M`` at vertices; the twist angle ``alpha`` and the internal force ``F`` on edges. ``profile`` gathers them
at the interior vertices (edge values averaged onto vertices), with ``xi`` the rest arc length.

* ``kappa = |kb| / D`` (|kb| = 2 tan(phi/2), D the rest Voronoi length), the curvature the energy uses.
* ``alpha``: signed angle from the discrete Frenet normal n to m1, about t (right-handed). The discrete Frenet
  binormal of an edge is the average of the curvature binormals of its two vertices; alpha is NaN where
  that average is below ``min_curvature`` (the Frenet frame is undefined there; never a made-up 0).
* ``omega``: geometric torsion, the rotation of the discrete Frenet frame about t from edge to edge (the
  Frenet frame's own reference twist) divided by D. At interior vertices the material twist is then exactly
  ``(alpha_f - alpha_e) / D + omega``, the discrete form of ``alpha' + omega``. At the two vertices next to
  the ends of an open rod that difference would be one-sided; omega is extrapolated there (see ``torsion``).
* ``M``: the discrete constitutive law of the energy, ``A1 [(kappa1 - kappa1_bar) m2 - (kappa2 - kappa2_bar) m1]
  / D + A2 (m - m_bar) / D t`` with the bending part evaluated in each edge's own frame (as the bending energy
  does) and averaged over the two edges; components (M_n, M_b, M_t) in the vertex Frenet frame. This is paper
  Eq. 28 in the continuum limit.
* ``F``: the force transmitted across each edge by the part beyond it (paper's convention: at a free end F
  equals the applied end force), ``F_j = sum over energy terms of dE/de_j`` -- exact for the discrete rod,
  in equilibrium or not. In ``profile`` it is averaged onto vertices (at the two vertices next to the end
  edges of an open rod, which carry the end loads and clamps, the inner edge's value is used) and resolved
  on the vertex Frenet frame (F_t, F_n, F_b).

Every function takes the rod and a state of it (``rod.rest_state()``, ``result.state``); a state of another
rod is refused. Units: lengths as the rod's, angles in radians, moments in force * length, forces in force.

Example
-------
>>> import der
>>> rod = der.rod_from_shape(der.shapes.arc(1.0, 3.0, 60), A1=1.0, A2=1.5)
>>> scene = der.Scene(rod, loads=[der.end_torque(1e-3, follower=True)], constraints=[der.clamp("start")])
>>> state = der.solve(scene).state
>>> p = der.diagnostics.profile(rod, state)                  # xi, kappa, omega, alpha, Mn, Mb, Mt, Ft, Fn, Fb
>>> displacement, rotation = der.diagnostics.end_motion(rod, state)   # in the rest end frame (t0, n0, b0)
"""
import numpy as np
from numba import njit

from .energies.bend import _bend_local, material_curvatures
from .energies.stiffness import bending_at, twisting_at
from .energies.stretch import _stretch_local, elongations
from .energies.twist import _twist_local, material_twist
from .geometry import (
    curvature_binormals, edge_array, edge_frames, frenet_directors, material_frames, signed_angle, tangents,
)
from .rod import Rod, RodState, check_state


def _q(state):
    return state.q if isinstance(state, RodState) else np.asarray(state)


def curvature(rod: Rod, state: RodState):
    """Curvature kappa at each vertex (1/length): |kb| / D, |kb| = 2 tan(phi/2) and D the rest Voronoi
    length (the curvature the bending energy uses).

    Parameters
    ----------
    rod : der.Rod
    state : der.RodState
        A state of this rod (``rod.rest_state()``, ``result.state``).

    Returns
    -------
    (n_vertices,) array; vertex v sits at the rest arc length ``rod.xi_nodes[rod.vertex_nodes[v, 1]]``.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1, 100), A1=1.0, A2=1.5)
    >>> state = rod.rest_state()
    >>> round(float(der.diagnostics.curvature(rod, state)[10]), 3)   # kappa0 = 1
    1.0
    """
    t = tangents(state.q, rod.edge_nodes)
    kb = curvature_binormals(t, rod.vertex_edges)
    return np.linalg.norm(kb, axis=1) / rod.voronoi


def frenet_normals(rod, state, min_curvature=1e-8):
    """Discrete Frenet normal of each edge (NaN rows where the curvature vanishes) and the unit tangents.

    Parameters
    ----------
    rod : der.Rod
    state : der.RodState
        A state of this rod (``rod.rest_state()``, ``result.state``).
    min_curvature : float
        Below this curvature (1/length) the Frenet frame counts as undefined (NaN).

    Returns
    -------
    (n, t): two (n_edges, 3) arrays.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1, 100), A1=1.0, A2=1.5)
    >>> state = rod.rest_state()
    >>> n, t = der.diagnostics.frenet_normals(rod, state)
    """
    t = tangents(state.q, rod.edge_nodes)
    kb = curvature_binormals(t, rod.vertex_edges)
    # threshold on |kb| ~ kappa * l: scale the curvature threshold by the local edge length
    n, defined = frenet_directors(t, kb, rod.vertex_edges, rod.n_edges, min_curvature * rod.l_bar.mean())
    n = n.copy()
    n[~defined] = np.nan
    return n, t


def alpha(rod, state, min_curvature=1e-8):
    """The paper's twist angle alpha of each edge (radians): the signed angle from the discrete Frenet
    normal n to the material vector m1, right-handed about the tangent t; NaN where kappa ~ 0 (never a
    made-up 0).

    Parameters
    ----------
    rod : der.Rod
    state : der.RodState
        A state of this rod (``rod.rest_state()``, ``result.state``).
    min_curvature : float
        Below this curvature (1/length) the Frenet frame counts as undefined (NaN).

    Returns
    -------
    (n_edges,) array.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1, 100), A1=1.0, A2=1.5)
    >>> state = rod.rest_state()
    >>> bool(abs(der.diagnostics.alpha(rod, state)).max() < 1e-9)   # the rest frame is the Frenet frame
    True
    """
    n, t = frenet_normals(rod, state, min_curvature)
    m1, _ = material_frames(state.q, t, state.d1)
    out = np.full(rod.n_edges, np.nan)
    for j in range(rod.n_edges):
        if np.isfinite(n[j, 0]):
            out[j] = signed_angle(n[j], m1[j], t[j])
    return out


def torsion(rod, state, min_curvature=1e-8):
    """Geometric torsion omega at each vertex (1/length); NaN where the Frenet frame is undefined. Positive for
    a right-handed helix.

    Interior vertices: the rotation about t of the discrete Frenet frame from edge e to edge f over D, a
    central difference (second order). An end edge of an open rod has one vertex only, so its Frenet frame
    sits at that vertex rather than half an edge further out, and the same difference at the vertex next to
    an end would span half a step (about half the torsion, first order). There omega is instead extrapolated
    linearly in arc length from the two nearest interior vertices (second order; NaN if either is undefined
    or the rod has fewer than four vertices). The identity material twist = (alpha_f - alpha_e) / D + omega
    holds exactly at the interior vertices only.

    Parameters
    ----------
    rod : der.Rod
    state : der.RodState
        A state of this rod (``rod.rest_state()``, ``result.state``).
    min_curvature : float
        Below this curvature (1/length) the Frenet frame counts as undefined (NaN).

    Returns
    -------
    (n_vertices,) array.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1, 100), A1=1.0, A2=1.5)
    >>> state = rod.rest_state()
    >>> round(float(der.diagnostics.torsion(rod, state)[10]), 3)    # omega0 = 0.6
    0.6
    """
    from .geometry import reference_twist_angle

    n, t = frenet_normals(rod, state, min_curvature)
    out = np.full(rod.n_vertices, np.nan)
    for v, (a, b) in enumerate(rod.vertex_edges):
        if np.isfinite(n[a, 0]) and np.isfinite(n[b, 0]):
            out[v] = reference_twist_angle(t[a], n[a], t[b], n[b]) / rod.voronoi[v]
    if not rod.closed:
        nv = rod.n_vertices
        xi = rod.xi_nodes[rod.vertex_nodes[:, 1]]
        for end, (i1, i2) in ((0, (1, 2)), (nv - 1, (nv - 2, nv - 3))):
            if nv >= 4:
                out[end] = out[i1] + (out[i1] - out[i2]) * (xi[end] - xi[i1]) / (xi[i1] - xi[i2])
            else:
                out[end] = np.nan
    return out


def material_twist_density(rod, state):
    """Material twist per length at each vertex (radians/length): alpha' + omega in the continuum, the
    twist the energy's A2 term measures (positive: right-handed about t).

    Parameters
    ----------
    rod : der.Rod
    state : der.RodState
        A state of this rod (``rod.rest_state()``, ``result.state``).

    Returns
    -------
    (n_vertices,) array.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1, 100), A1=1.0, A2=1.5)
    >>> state = rod.rest_state()
    >>> tw = der.diagnostics.material_twist_density(rod, state)
    """
    weld = rod.weld
    return np.array([material_twist(state.q, rod.vertex_edges, state.reference_twist, weld, v)
                     for v in range(rod.n_vertices)]) / rod.voronoi


def total_twist(rod, state):
    """Total material twist Tw of the rod (radians): the sum of the integrated twists (a ring's weld
    rotation included: the twist of the material ribbon the weld closes).

    Parameters
    ----------
    rod : der.Rod
    state : der.RodState
        A state of this rod (``rod.rest_state()``, ``result.state``).

    Returns
    -------
    float, radians (divide by 2 pi for turns).

    Example
    -------
    >>> import numpy as np, der
    >>> ring = der.rod_from_shape(der.shapes.ring(1.0, 60), A1=1.0, A2=1.5).with_imposed_twist(2 * np.pi)
    >>> state = ring.rest_state()
    >>> round(der.diagnostics.total_twist(ring, state) / (2 * np.pi), 6)
    1.0
    """
    weld = rod.weld
    return float(sum(material_twist(state.q, rod.vertex_edges, state.reference_twist, weld, v)
                     for v in range(rod.n_vertices)))


@njit(cache=True)
def _solid_angle(a, b, c):
    """Signed solid angle of the triangle (a, b, c) seen from the origin (Van Oosterom & Strackee 1983):
    positive when a . (b x c) > 0."""
    la = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    lb = np.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2])
    lc = np.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
    triple = (a[0] * (b[1] * c[2] - b[2] * c[1]) + a[1] * (b[2] * c[0] - b[0] * c[2])
              + a[2] * (b[0] * c[1] - b[1] * c[0]))
    ab = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    ac = a[0] * c[0] + a[1] * c[1] + a[2] * c[2]
    bc = b[0] * c[0] + b[1] * c[1] + b[2] * c[2]
    return 2.0 * np.arctan2(triple, la * lb * lc + ab * lc + ac * lb + bc * la)


@njit(cache=True)
def _writhe(x):
    """Writhe of the closed polygon through the rows of x: the Gauss double integral, exact per pair of
    segments. For segments i (p1 -> p2) and j (p3 -> p4) the integrand over (s, t) is the area element of
    the map (s, t) -> (r_j(t) - r_i(s)) / |.|, whose image is the spherical quadrilateral (p3 - p1, p3 - p2,
    p4 - p2, p4 - p1) bounded by great arcs: its signed solid angle, two triangles, over 4 pi."""
    n = x.shape[0]
    total = 0.0
    r13 = np.empty(3)
    r14 = np.empty(3)
    r23 = np.empty(3)
    r24 = np.empty(3)
    for i in range(n):
        i1 = (i + 1) % n
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue   # adjacent through the wrap: coplanar, no contribution
            j1 = (j + 1) % n
            for k in range(3):
                r13[k] = x[j, k] - x[i, k]
                r14[k] = x[j1, k] - x[i, k]
                r23[k] = x[j, k] - x[i1, k]
                r24[k] = x[j1, k] - x[i1, k]
            total += _solid_angle(r13, r23, r24) + _solid_angle(r13, r24, r14)
    return 2.0 * total / (4.0 * np.pi)


def writhe(rod, state):
    """Writhe Wr of a ring's centreline (turns): the Gauss double integral over the closed polygon of its
    nodes, exact for the polygon (Klenin & Langowski 2000: one solid angle per pair of segments). O(n^2):
    about 0.1 s at n = 2,000 and 10x that per tripling of n beyond. ValueError for an open rod.

    Parameters
    ----------
    rod : der.Rod
    state : der.RodState
        A state of this rod (``rod.rest_state()``, ``result.state``).

    Returns
    -------
    float, turns.

    Example
    -------
    >>> import numpy as np, der
    >>> ring = der.rod_from_shape(der.shapes.ring(1.0, 60), A1=1.0, A2=1.5).with_imposed_twist(2 * np.pi)
    >>> state = ring.rest_state()
    >>> abs(der.diagnostics.writhe(ring, state)) < 1e-12         # a planar circle
    True
    """
    if not rod.closed:
        raise ValueError("writhe: the rod is open; writhe (and the linking number) is defined for a closed ring")
    return float(_writhe(np.ascontiguousarray(_q(state).reshape(-1, 4)[:, :3])))


def linking_number(rod, state):
    """(Lk, Tw, Wr) of a ring in turns, with Lk = Tw + Wr (Calugareanu-White): Tw the total material twist
    over 2 pi (the weld rotation included), Wr the writhe. For a ring closed with ``imposed_twist`` and no
    other twist at rest, Lk = imposed_twist / 2 pi, conserved by every smooth deformation.

    Parameters
    ----------
    rod : der.Rod
    state : der.RodState
        A state of this rod (``rod.rest_state()``, ``result.state``).

    Returns
    -------
    (Lk, Tw, Wr), floats, turns.

    Example
    -------
    >>> import numpy as np, der
    >>> ring = der.rod_from_shape(der.shapes.ring(1.0, 60), A1=1.0, A2=1.5).with_imposed_twist(2 * np.pi)
    >>> state = ring.rest_state()
    >>> [round(v, 6) + 0.0 for v in der.diagnostics.linking_number(ring, state)]
    [1.0, 1.0, 0.0]
    """
    tw = total_twist(rod, state) / (2.0 * np.pi)
    wr = writhe(rod, state)
    return tw + wr, tw, wr


def _vertex_frames(rod, state):
    t = tangents(state.q, rod.edge_nodes)
    m1, m2 = material_frames(state.q, t, state.d1)
    e, f = rod.vertex_edges[:, 0], rod.vertex_edges[:, 1]
    tv = t[e] + t[f]
    tv /= np.linalg.norm(tv, axis=1)[:, None]
    kb = curvature_binormals(t, rod.vertex_edges)
    return t, m1, m2, tv, kb


def internal_moments(rod, state):
    """Internal moment vectors at the vertices (force * length), global frame: the discrete constitutive
    law A1 (kappa - kappa_bar) + A2 (twist - twist_bar) t (paper Eq. 28 in the continuum limit); with anisotropic
    bending, A1 (kappa1 - kappa1_bar) m2 - A1' (kappa2 - kappa2_bar) m1 for the bending part.

    Parameters
    ----------
    rod : der.Rod
    state : der.RodState
        A state of this rod (``rod.rest_state()``, ``result.state``).

    Returns
    -------
    (n_vertices, 3) array.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1, 100), A1=1.0, A2=1.5)
    >>> state = rod.rest_state()
    >>> bool(abs(der.diagnostics.internal_moments(rod, state)).max() < 1e-12)   # rest: no moment
    True
    """
    t, m1, m2, tv, kb = _vertex_frames(rod, state)
    e, f = rod.vertex_edges[:, 0], rod.vertex_edges[:, 1]
    ed = edge_frames(state.q, rod.edge_nodes, state.d1)
    weld = rod.weld
    # the bending energy's own curvatures, per edge frame (energies.bend)
    k = np.array([material_curvatures(ed, rod.vertex_edges, weld, v)
                  for v in range(rod.n_vertices)]).reshape(-1, 2, 2)
    r = k - rod.natural_curvature_edges()
    m = np.array([material_twist(state.q, rod.vertex_edges, state.reference_twist, weld, v)
                  for v in range(rod.n_vertices)])
    c, s = np.cos(weld)[:, None], np.sin(weld)[:, None]
    m1f = c * m1[f] + s * m2[f]     # edge f's frame turned by the weld, as in the bending energy
    m2f = c * m2[f] - s * m1[f]
    # each edge side's moment A1 [(k1 - k1_bar) m2 - (k2 - k2_bar) m1] / D in its own frame, averaged (the two
    # sides share the cell); its small component along the vertex tangent is dropped: the bending moment is
    # transverse, the twisting moment is the one along t
    D = rod.voronoi[:, None]
    A2 = rod.A2 if np.ndim(rod.A2) == 0 else np.asarray(rod.A2)[:, None]
    if rod.isotropic:
        A1 = rod.A1 if np.ndim(rod.A1) == 0 else np.asarray(rod.A1)[:, None]
        Mb = 0.5 * ((r[:, 0, :1] * m2[e] - r[:, 0, 1:] * m1[e]) + (r[:, 1, :1] * m2f - r[:, 1, 1:] * m1f))
        Mb -= np.einsum("ij,ij->i", Mb, tv)[:, None] * tv
        return A1 * Mb / D + A2 * (m - rod.twist_bar)[:, None] / D * tv
    B = rod.bending_stiffness()       # (A1, A1') per vertex: kappa1 pairs with m2, kappa2 with m1
    b1, b2 = B[:, :1], B[:, 1:]
    Mb = 0.5 * ((b1 * r[:, 0, :1] * m2[e] - b2 * r[:, 0, 1:] * m1[e])
                + (b1 * r[:, 1, :1] * m2f - b2 * r[:, 1, 1:] * m1f))
    Mb -= np.einsum("ij,ij->i", Mb, tv)[:, None] * tv
    return Mb / D + A2 * (m - rod.twist_bar)[:, None] / D * tv


def vertex_frenet(rod, state, min_curvature=1e-8):
    """Frenet frame (t, n, b) at each vertex: t the averaged tangent, b along the curvature binormal kb,
    n = b x t (NaN rows where kappa ~ 0).

    Parameters
    ----------
    rod : der.Rod
    state : der.RodState
        A state of this rod (``rod.rest_state()``, ``result.state``).
    min_curvature : float
        Below this curvature (1/length) the Frenet frame counts as undefined (NaN).

    Returns
    -------
    (t, n, b): three (n_vertices, 3) arrays.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1, 100), A1=1.0, A2=1.5)
    >>> state = rod.rest_state()
    >>> t, n, b = der.diagnostics.vertex_frenet(rod, state)
    """
    t, _, _, tv, kb = _vertex_frames(rod, state)
    lk = np.linalg.norm(kb, axis=1)
    b = kb / np.where(lk > 0, lk, 1.0)[:, None]
    b[lk <= min_curvature * rod.voronoi] = np.nan
    n = np.cross(b, tv)
    return tv, n, b


@njit(cache=True)
def _edge_forces(q, d1, reference_twist, lam, edge_nodes, vertex_nodes, vertex_edges, l_bar, k_stretch,
                 kappa_bar, twist_bar, weld, voronoi, A1, A2, has_stretch, has_bend, has_twist, q_lo=None):
    """F_j = sum of dE/de_j over the energy terms (n_edges, 3), and the internal moment magnitude per vertex.
    ``q_lo``: the low parts of compensated positions (``RodState.q_lo``), as in ``scene.evaluate``; the solvers'
    order-1 evaluation of a rod with all three terms computes the same numbers in its own pass
    (``energies.vertex.stretch_bend_twist_gradient``)."""
    n = edge_nodes.shape[0]
    F = np.zeros((n, 3))
    M = np.zeros(vertex_nodes.shape[0])
    g6 = np.empty(6)
    H6 = np.empty((6, 6))
    g8 = np.empty(8)
    H8 = np.empty((8, 8))
    work = np.empty((5, 8))
    E = edge_array(q, edge_nodes, q_lo, True)
    ed = edge_frames(q, edge_nodes, d1, E)
    if has_stretch:
        for j in range(n):
            _stretch_local(E, j, l_bar[j], k_stretch[j], lam[j], 1, g6, H6)
            for i in range(3):
                F[j, i] += g6[3 + i]   # dE/de = dE/dx_b
    for v in range(vertex_nodes.shape[0]):
        a = vertex_edges[v, 0]
        b = vertex_edges[v, 1]
        m2 = 0.0
        if has_bend:
            a1, a2 = bending_at(A1, v)
            s = max(a1, a2) / voronoi[v]
            e = _bend_local(ed, vertex_edges, weld, v, kappa_bar, a1 / voronoi[v], a2 / voronoi[v], 1, g8, H8, work)
            for i in range(3):
                F[a, i] += g8[i]
                F[b, i] += g8[3 + i]
            # |bending moment|^2 <= (A1/D)^2 mean_j |kappa^j - kappa_bar^j|^2 = 2 E_v A1/D (equal when the
            # two edge sides agree)
            m2 += 2.0 * e * s
        if has_twist:
            s = twisting_at(A2, v) / voronoi[v]
            e = _twist_local(q, ed, vertex_edges, reference_twist, weld, v, twist_bar[v], s, 1, g8, H8, work)
            for i in range(3):
                F[a, i] += g8[i]
                F[b, i] += g8[3 + i]
            m2 += 2.0 * e * s
        M[v] = np.sqrt(m2)
    return F, M


def _extensible_stiffness(rod):
    """EA / l per edge, the end edges of an open rod at half weight (what the solvers use:
    ``der.solvers.system.axial_penalty``)."""
    k = np.broadcast_to(np.asarray(rod.EA, float), rod.l_bar.shape) / rod.l_bar
    if not rod.closed:
        k = k.copy()
        k[[0, -1]] *= 0.5
    return k


def reactions(scene, state):
    """The reaction of every constraint of ``scene`` at ``state``: what ``der.solve`` reports as
    ``result.reactions`` (one dict per constraint: ``support``, ``end``/``node``/``edge``, ``at``, ``force``,
    ``moment``; lab frame, what the support exerts on the rod, moment about ``at`` -- the end cross-section's
    centre for clamps, hinges and rollers). At an equilibrium the reactions and the loads balance, forces and
    moments; away from one they include the out-of-balance forces on the supported nodes.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 20, axis=(1, 0, 0), director=(0, 0, 1)), 1.0, 1.0)
    >>> scene = der.Scene(rod, loads=[der.end_force([0, -1e-3, 0])], constraints=[der.clamp("start")])
    >>> r = der.diagnostics.reactions(scene, der.solve(scene).state)[0]
    >>> [round(float(v), 9) + 0.0 for v in r["force"]], [round(float(v), 9) + 0.0 for v in r["moment"]]
    ([0.0, 0.001, 0.0], [0.0, 0.0, 0.001])
    """
    from .solvers.options import SolverOptions
    from .solvers.system import build_system, evaluate_system, support_reactions, update_links

    system = build_system(scene, SolverOptions())
    if state.penalty is not None:
        system.plan.k_stretch[:] = state.penalty
    update_links(system, state)
    evaluate_system(system, state, 1)
    return support_reactions(system, state)


def internal_forces(rod, state, k_stretch=None, energies=("stretch", "bend", "twist")):
    """Internal force across each edge (force units), global frame: F_j = sum of dE/de_j over the energy
    terms (paper's convention: at a free end F equals the applied end force). The tension of an
    inextensible rod is ``lam + penalty g`` with the multipliers and penalty the solver left in the state;
    of an extensible rod, EA times the strain.

    Parameters
    ----------
    rod : der.Rod
    state : der.RodState
        A state of this rod (``rod.rest_state()``, ``result.state``).
    k_stretch : (n_edges,) array, optional
        Axial penalty overriding the state's.
    energies : tuple of str
        Which energy terms to include.

    Returns
    -------
    (n_edges, 3) array.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1, 100), A1=1.0, A2=1.5)
    >>> state = rod.rest_state()
    >>> F = der.diagnostics.internal_forces(rod, state)
    """
    if k_stretch is None:
        if state.penalty is not None:
            k_stretch = state.penalty
        else:
            k_stretch = np.zeros(rod.n_edges) if rod.inextensible else _extensible_stiffness(rod)
    lam = state.lam if state.lam.size == rod.n_edges else np.zeros(rod.n_edges)
    kappa_bar = rod.natural_curvature_edges().reshape(-1, 4)
    return _edge_forces(state.q, state.d1, state.reference_twist, lam, rod.edge_nodes, rod.vertex_nodes,
                        rod.vertex_edges, rod.l_bar, np.asarray(k_stretch, float), kappa_bar, rod.twist_bar,
                        rod.weld, rod.voronoi, rod.kernel_bending(), rod.kernel_twisting(), "stretch" in energies,
                        "bend" in energies,
                        "twist" in energies)[0]


def strain(rod, state):
    """Axial strain of each edge, (|e| - l) / l (dimensionless; positive stretched).

    Parameters
    ----------
    rod : der.Rod
    state : der.RodState
        A state of this rod (``rod.rest_state()``, ``result.state``).

    Returns
    -------
    (n_edges,) array.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1, 100), A1=1.0, A2=1.5)
    >>> state = rod.rest_state()
    >>> bool(abs(der.diagnostics.strain(rod, state)).max() < 1e-12)
    True
    """
    return elongations(state.q, rod.edge_nodes, rod.l_bar) / rod.l_bar


def profile(rod, state, k_stretch=None, min_curvature=1e-8):
    """The paper's variables at the interior vertices, as a dict of equal-length arrays.

    Keys: xi (rest arc length), kappa (curvature), omega (geometric torsion), alpha (twist angle, edge values
    averaged), twist (material twist per length), Mn, Mb, Mt (internal moment in the vertex Frenet frame
    (n, b, t)), Ft, Fn, Fb (internal force, averaged from the adjacent edges, same frame). Lengths in rod units,
    moments in force * length, forces in force units.

    Parameters
    ----------
    rod : der.Rod
    state : der.RodState
        A state of this rod (``rod.rest_state()``, ``result.state``).
    k_stretch : (n_edges,) array, optional
        Axial penalty overriding the state's (internal_forces).
    min_curvature : float
        Below this curvature (1/length) the Frenet frame counts as undefined (NaN).

    Returns
    -------
    dict of (n_vertices,) arrays. A state of another rod (other sizes) is refused with a ValueError.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1, 100), A1=1.0, A2=1.5)
    >>> state = rod.rest_state()
    >>> p = der.diagnostics.profile(rod, state)
    >>> sorted(p)
    ['Fb', 'Fn', 'Ft', 'Mb', 'Mn', 'Mt', 'alpha', 'kappa', 'omega', 'twist', 'xi']
    """
    check_state(rod, state, "der.diagnostics.profile")
    xi = rod.xi_nodes[rod.vertex_nodes[:, 1]]
    tv, nv, bv = vertex_frenet(rod, state, min_curvature)
    M = internal_moments(rod, state)
    F = internal_forces(rod, state, k_stretch)
    e, f = rod.vertex_edges[:, 0], rod.vertex_edges[:, 1]
    Fv = 0.5 * (F[e] + F[f])
    if not rod.closed:
        # the end edges carry the end loads and the clamps (their cut forces are split): use the inner edge
        Fv[0] = F[f[0]]
        Fv[-1] = F[e[-1]]
    al = alpha(rod, state, min_curvature)
    av = 0.5 * (al[e] + _unwrap_near(al[f], al[e]))
    return {
        "xi": xi,
        "kappa": curvature(rod, state),
        "omega": torsion(rod, state, min_curvature),
        "alpha": av,
        "twist": material_twist_density(rod, state),
        "Mn": np.einsum("ij,ij->i", M, nv), "Mb": np.einsum("ij,ij->i", M, bv), "Mt": np.einsum("ij,ij->i", M, tv),
        "Ft": np.einsum("ij,ij->i", Fv, tv), "Fn": np.einsum("ij,ij->i", Fv, nv), "Fb": np.einsum("ij,ij->i", Fv, bv),
    }


def _unwrap_near(a, ref):
    return ref + (a - ref + np.pi) % (2 * np.pi) - np.pi


def rotation_vector(R):
    """Rotation vector (axis * angle, radians) of a rotation matrix R (the log map), angle in [0, pi].

    Parameters
    ----------
    R : (3, 3) array
        A rotation matrix.

    Returns
    -------
    (3,) array, right-handed about its own direction.

    Example
    -------
    >>> import numpy as np, der
    >>> c, s = np.cos(0.3), np.sin(0.3)
    >>> der.diagnostics.rotation_vector([[c, -s, 0], [s, c, 0], [0, 0, 1]]).round(12) + 0.0
    array([0. , 0. , 0.3])
    """
    R = np.asarray(R, float)
    c = np.clip(0.5 * (np.trace(R) - 1.0), -1.0, 1.0)
    angle = np.arccos(c)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    s = np.sin(angle)
    if angle < 1e-6:
        return 0.5 * w * (1.0 + angle ** 2 / 6.0)
    if np.pi - angle < 1e-6:
        # near pi: axis from the symmetric part
        B = 0.5 * (R + np.eye(3))
        axis = B[np.argmax(np.diag(B))]
        return angle * axis / np.linalg.norm(axis)
    return angle / (2.0 * s) * w


def end_frame(rod, state, end="end"):
    """Position and material frame of an end cross-section: the midpoint of the end edge (xi = 0 or L)
    and the rows t, m1, m2 (global frame; t along increasing arc length).

    Parameters
    ----------
    rod : der.Rod
    state : der.RodState
        A state of this rod (``rod.rest_state()``, ``result.state``).
    end : "start" or "end"

    Returns
    -------
    (midpoint (3,), frame (3, 3) with rows t, m1, m2).

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1, 100), A1=1.0, A2=1.5)
    >>> state = rod.rest_state()
    >>> x, frame = der.diagnostics.end_frame(rod, state, "end")
    """
    j = 0 if end == "start" else rod.n_edges - 1
    x = state.positions
    a, b = rod.edge_nodes[j]
    t = x[b] - x[a]
    t = t / np.linalg.norm(t)
    d2 = np.cross(t, state.d1[j])
    c, s = np.cos(state.theta[j]), np.sin(state.theta[j])
    m1 = c * state.d1[j] + s * d2
    m2 = np.cross(t, m1)
    return 0.5 * (x[a] + x[b]), np.stack([t, m1, m2])


def end_motion(rod, state, end="end"):
    """Displacement and rotation of an end cross-section relative to the rest state, in the REST END FRAME.

    Both vectors are given as components along (t0, m1_0, m2_0), the rest end frame of that end
    (``end_frame`` of the rest state) -- for a Frenet-aligned rest shape (``rod_from_shape``), (t0, n0, b0):
    the tangent, normal and binormal of the rest shape at that end. The displacement is that of the end-edge
    midpoint (length units); the rotation is the rotation vector (axis * angle, radians, right-handed, angle in
    [0, pi]) taking the rest end material frame to the current one. So ``rot[0]`` is the turn of the end about
    its rest tangent.

    Parameters
    ----------
    rod : der.Rod
    state : der.RodState
        A state of this rod (``rod.rest_state()``, ``result.state``).
    end : "start" or "end"

    Returns
    -------
    (displacement (3,), rotation (3,)) in the rest end frame.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.5)
    >>> scene = der.Scene(rod, loads=[der.end_torque(1.5e-3, follower=True)], constraints=[der.clamp("start")])
    >>> disp, rot = der.diagnostics.end_motion(rod, der.solve(scene).state)
    >>> round(float(rot[0]), 9)                                  # T L / A2
    0.001
    """
    check_state(rod, state, "der.diagnostics.end_motion")
    p0, F0 = end_frame(rod, rod.rest_state(), end)
    p, F = end_frame(rod, state, end)
    Q = F.T @ F0                       # maps rest frame vectors to current ones: Q F0[i] = F[i]
    return F0 @ (p - p0), F0 @ rotation_vector(Q)


def contact_forces(scene, state):
    """Contact diagnostics of a scene's contact terms (issue 14) at ``state``.

    Parameters
    ----------
    scene : der.Scene with ``contacts`` (or the solver's internal system, which keeps the barrier stiffness the
        solve adapted: ``result.contact`` is this at the final state).
    state : der.RodState (for a scene of several rods: ``result.state``, or one RodState per rod)

    Returns
    -------
    dict with ``n_contacts`` (pairs or obstacle elements whose gap is below dhat), ``min_distance`` (the
    smallest centreline distance between non-neighbour edges, or to an obstacle, over all terms; length),
    ``total_force`` and ``terms``: one dict per term with ``pairs`` (edge index pairs) or ``elements``,
    ``gap`` (surface gaps, length), ``force`` (|-kappa b'(gap)|, force units), ``force_per_length`` (force over
    the pair's mean rest edge length, or the element's length share), ``points`` (contact points),
    ``min_distance``, ``kappa``, ``dhat``, ``radius``. With a Scene the barrier stiffness is the term's
    ``kappa`` or its adaptive start value (the forces of an equilibrium do not depend on it to within the gap's
    change, but their split between neighbouring pairs may).

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 10), A1=1.0, A2=1.5)
    >>> scene = der.Scene(rod, contacts=[der.plane([0, 0, -1], [0, 0, 1], radius=0.05)])
    >>> der.diagnostics.contact_forces(scene, rod.rest_state())["n_contacts"]
    0
    """
    system = scene
    if not hasattr(scene, "terms"):
        from .solvers.options import SolverOptions
        from .solvers.system import build_system, prepare_state

        if not scene.contacts:
            return {"n_contacts": 0, "min_distance": float("inf"), "total_force": 0.0, "terms": []}
        if scene.scenes is not None:          # several rods: state is a MultiState or one RodState per rod
            from .solvers.multi import MultiState, build_multi_system, prepare_multi_state

            states = list(state.rods) if isinstance(state, MultiState) else list(state)
            if len(states) != len(scene.scenes):
                raise ValueError(f"der.diagnostics.contact_forces: give one state per rod ({len(scene.scenes)}); "
                                 f"got {len(states)}")
            for i, (r, s) in enumerate(zip(scene.rods, states)):
                check_state(r, s, f"der.diagnostics.contact_forces: state of rod {i}")
            system = build_multi_system(scene, SolverOptions())
            state = prepare_multi_state(system, MultiState(states))
        else:
            check_state(scene.rod, state, "der.diagnostics.contact_forces")
            system = build_system(scene, SolverOptions())
            state = prepare_state(system, state)
        for t in system.terms:
            t.start_stiffness(state, system)
    terms = [t.diagnostics(state) for t in system.terms]
    return {
        "n_contacts": int(sum(t["n_contacts"] for t in terms)),
        "min_distance": float(min((t["min_distance"] for t in terms), default=float("inf"))),
        "total_force": float(sum(t["total_force"] for t in terms)),
        "terms": terms,
    }
