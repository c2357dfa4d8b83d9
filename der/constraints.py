"""Constraints: clamps, hinges, rollers, pinned nodes, fixed angles.

Two kinds of constraint:

- plain DOF fixes (``pin`` on a node, ``fix_theta`` on an edge angle, the end angle of a ``clamp``): entries of
  the state vector held where they are (the boolean mask ``fixed_dofs``);
- end supports (``clamp``, ``hinge``, ``roller``) that act on the END CROSS-SECTION of an open rod, the midpoint
  of its end edge (``Rod.xi_nodes``): linear equations on the two nodes of the end edge -- the centre
  (x_outer + x_inner) / 2 held (or held on a line or plane), and for a clamp the end edge held along its
  direction t (it may stretch: the end edge's stretch is part of the rod). They are solved for some of the
  end-edge coordinates ("dependents") in terms of the others ("masters"), ``q_d = c_d + sum_m a_dm q_m``
  (``build_links``): a linear change of variables q = c + T y. Dependents are taken from the outer node first,
  so T couples only the two end nodes and ``T^T K T`` keeps the band of K (``linalg.condense_band``).

Optional targets move a support before a solve: a clamp's prescribed motion is a rigid motion of its end
cross-section, a rotation about the cross-section's centre plus a translation of that centre.
"""
from collections import namedtuple
from dataclasses import dataclass

import numpy as np
from numba import njit

from . import loads as _loads
from . import validate as _v


@dataclass(frozen=True)
class Clamp:
    """Clamp the end ``end`` ("start" or "end"): the end cross-section's centre and its material frame held.

    The centre of the end cross-section (the end edge's midpoint) is held, the end edge keeps its direction
    (it may stretch, like every other edge of an extensible rod) and the end edge's angle theta is held.
    ``rotation`` (3x3) and ``position`` (3,) optionally prescribe where the clamp goes: the end cross-section is
    turned rigidly by ``rotation`` about its centre and its centre moved to ``position``. ``slide`` is the
    direction along which the clamp may slide freely (no force along it): ``slide=(2,)`` (an axis, the old
    form) or ``direction`` (a unit 3-vector). Made by ``der.clamp``.
    """
    end: str
    rotation: object = None
    position: object = None
    slide: tuple = ()
    direction: object = None

    def free_directions(self):
        """Unit directions (k, 3) along which the centre may move (k = 0 or 1)."""
        if self.direction is not None:
            return np.asarray(self.direction, float).reshape(1, 3)
        out = np.zeros((len(self.slide), 3))
        for i, a in enumerate(self.slide):
            out[i, a] = 1.0
        return out


@dataclass(frozen=True)
class EndSupport:
    """A hinge or roller on the end cross-section ``end``: its centre held (hinge) or held on a line or in a
    plane (roller, ``free`` lists the orthonormal directions it may move along); every rotation free.
    ``position``: where the centre is held (default: where it is at the start of the solve). Made by
    ``der.hinge`` and ``der.roller``."""
    end: str
    kind: str
    position: object = None
    free: tuple = ()

    def free_directions(self):
        return np.asarray(self.free, float).reshape(-1, 3)


@dataclass(frozen=True)
class Pin:
    """Hold node ``node`` at its position (or move it to ``position``); its rotation stays free.

    Made by ``der.pin``."""
    node: int
    position: object = None


@dataclass(frozen=True)
class FixTheta:
    """Hold the angle theta of edge ``edge`` (the material frame relative to the transported reference).

    Made by ``der.fix_theta``."""
    edge: int


_EYE = np.eye(3)


def _rotation_matrix(R, name):
    R = _v.finite_array(R, name, (3, 3), "a proper 3x3 rotation matrix (orthogonal, determinant +1), "
                                               "e.g. numpy.eye(3)")
    # numpy.allclose(R R^T, I, atol=1e-9) and det R >= 0, cheaply (a clamp turned at every step of a simulation
    # makes one of these per step)
    (a, b, c), (d, e, f), (g, h, i) = R.tolist()
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if not (np.abs(R @ R.T - _EYE) <= 1e-9 + 1e-5 * _EYE).all() or det < 0:
        raise ValueError(f"{name} must be a proper 3x3 rotation matrix (R R^T = I to 1e-9, det R = +1); got "
                         f"{np.array2string(R, precision=4)} with det {np.linalg.det(R):.4g} and "
                         f"|R R^T - I| = {np.abs(R @ R.T - np.eye(3)).max():.2g}")
    return R


def clamp(end="start", rotation=None, position=None, slide=()):
    """Clamp an end of an open rod: its end cross-section's centre and material frame are held.

    Parameters
    ----------
    end : "start" or "end"
        Which end, xi = 0 or xi = L. The clamp holds the centre of the end cross-section (the end edge's
        midpoint, where the rod's end is), the direction of the end edge and its angle theta, i.e. the end
        material frame. The end edge may stretch (extensible rods): its inner half is part of the rod.
    rotation : (3, 3) array, optional
        A proper rotation matrix R (R R^T = I, det R = +1) that moves the clamp before the solve: the end
        cross-section is turned rigidly by R about its CENTRE, and the end material frame is turned with it
        (m1 -> R m1_rest). Turning an end by an angle phi about its rest tangent t0 is ``R = rotation about t0
        by phi`` (right-handed: phi > 0 over-twists at the "end"). Relative to the REST configuration.
    position : 3-vector, optional
        Where the centre of the end cross-section goes (global frame, length units); default: its rest
        position when ``rotation`` is given, else where it is at the start of the solve. (Before issue 13 this
        was the outer node's position and rotations turned about the outer node.)
    slide : int, tuple of one int, or 3-vector
        A direction along which the clamped end may slide freely (a sleeve: no force along it): a coordinate
        axis 0, 1, 2 (x, y, z) or (2,), or any direction as a 3-vector, e.g. ``slide=(1, 1, 0)``.

    Returns
    -------
    Clamp, to pass in ``der.Scene(rod, constraints=[...])``.

    Example
    -------
    A straight rod along z, clamped at xi = 0, its far end turned by 0.1 rad about z and free to slide along z:

    >>> import numpy as np, der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.5)
    >>> c, s = np.cos(0.1), np.sin(0.1)
    >>> R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    >>> scene = der.Scene(rod, constraints=[der.clamp("start"), der.clamp("end", rotation=R, slide=2)])
    """
    end = _loads.check_end(end, "der.clamp: end")
    if rotation is not None:
        rotation = _rotation_matrix(rotation, "der.clamp: rotation")
    if position is not None:
        position = _v.vector3(position, "der.clamp: position")
    if isinstance(slide, (str, bytes)) or slide is None:
        raise TypeError(f"der.clamp: slide must be an axis 0, 1 or 2 (x, y, z), a tuple of at most one, or a "
                        f"direction 3-vector; got {slide!r}")
    if np.ndim(slide) == 1 and len(slide) == 3:
        return Clamp(end, rotation, position, (), tuple(_unit(slide, "der.clamp: slide")))
    axes = tuple(_v.integer(a, "der.clamp: slide", "an axis 0, 1 or 2 (x, y, z), or a direction 3-vector")
                 for a in np.atleast_1d(np.asarray(slide, dtype=object)))
    return Clamp(end, rotation, position, axes)


def _unit(v, name):
    v = _v.vector3(v, name)
    n = float(np.linalg.norm(v))
    if n == 0.0:
        raise ValueError(f"{name} must be a non-zero direction 3-vector; got {v.tolist()}")
    return v / n


def hinge(end="start", position=None, slide=None):
    """A hinge at an end cross-section of an open rod: its centre held, the rod free to turn about it.

    Parameters
    ----------
    end : "start" or "end"
        Which end (xi = 0 or xi = L). The hinge acts on the centre of the end cross-section (the end edge's
        midpoint), not on a node: a simply supported span is exactly L.
    position : 3-vector, optional
        Where the centre is held (global frame); default: where it is at the start of the solve.
    slide : 3-vector, optional
        A direction along which the centre may move freely (a roller on a line); see also ``der.roller``.

    Every rotation is free, twist included: a rod hinged at both ends needs ``der.fix_theta(0)`` (a fork) to
    hold its rotation about its own axis.

    Returns
    -------
    EndSupport, to pass in ``der.Scene(rod, constraints=[...])``.

    Example
    -------
    A simply supported beam (hinge and roller) under a central load:

    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 40, axis=(1, 0, 0), director=(0, 0, 1)), 1.0, 1.0)
    >>> scene = der.Scene(rod, loads=[der.point_force(20, [0, 0, -1e-3])],
    ...                   constraints=[der.hinge("start"), der.roller("end", along=(1, 0, 0)), der.fix_theta(0)])
    """
    end = _loads.check_end(end, "der.hinge: end")
    if position is not None:
        position = tuple(_v.vector3(position, "der.hinge: position"))
    free = () if slide is None else (tuple(_unit(slide, "der.hinge: slide")),)
    return EndSupport(end, "hinge", position, free)


def roller(end="end", along=None, normal=None, position=None):
    """A roller at an end cross-section: its centre free along a line (``along``) or in a plane (``normal``).

    Parameters
    ----------
    end : "start" or "end"
    along : 3-vector, optional
        The centre moves freely on the line through its position along this direction (reaction normal to it).
    normal : 3-vector, optional
        The centre moves freely in the plane through its position normal to this direction (reaction along it).
        Give exactly one of ``along`` and ``normal``.
    position : 3-vector, optional
        A point of the line or plane (default: the centre's position at the start of the solve).

    Every rotation is free.

    Returns
    -------
    EndSupport, to pass in ``der.Scene(rod, constraints=[...])``.

    Example
    -------
    >>> import der
    >>> r = der.roller("end", normal=(0, 0, 1))    # the end rests on the plane z = const
    """
    end = _loads.check_end(end, "der.roller: end")
    if (along is None) == (normal is None):
        raise ValueError("der.roller: give exactly one of along= (a line) and normal= (a plane); got "
                         f"along={along!r}, normal={normal!r}")
    if position is not None:
        position = tuple(_v.vector3(position, "der.roller: position"))
    if along is not None:
        free = (tuple(_unit(along, "der.roller: along")),)
    else:
        nrm = _unit(normal, "der.roller: normal")
        u = np.cross(nrm, np.eye(3)[int(np.argmin(np.abs(nrm)))])
        u /= np.linalg.norm(u)
        free = (tuple(u), tuple(np.cross(nrm, u)))
    return EndSupport(end, "roller", position, free)


def pin(node, position=None):
    """Pin one node: its position is held (or moved to ``position``); the rod turns freely about it.

    Parameters
    ----------
    node : int
        Node index (negative counts from the end). Python or numpy integers, or a float with a whole value;
        2.5 is refused. An open rod's first and last nodes lie half an edge outside [0, L] (``Rod.xi_nodes``).
    position : 3-vector, optional
        Where the node goes before the solve (global frame); default: where it is. Two pins on one node with
        different positions are refused.

    Returns
    -------
    Pin, to pass in ``der.Scene(rod, constraints=[...])``.

    Example
    -------
    A ring pinned at two opposite nodes:

    >>> import der
    >>> ring = der.rod_from_shape(der.shapes.ring(1.0, 40), A1=1.0, A2=1.5)
    >>> scene = der.Scene(ring, constraints=[der.pin(0), der.pin(20)])
    """
    node = _v.integer(node, "der.pin: node", "an integer node index")
    if position is not None:
        position = _v.vector3(position, "der.pin: position")
    return Pin(node, position)


def fix_theta(edge):
    """Hold the material angle theta of one edge (its frame about its tangent, relative to the reference).

    Parameters
    ----------
    edge : int
        Edge index (negative counts from the end); whole-valued floats accepted, 2.5 refused. Used to remove
        the free rotation of a ring about its own centreline, for instance.

    Returns
    -------
    FixTheta, to pass in ``der.Scene(rod, constraints=[...])``.

    Example
    -------
    >>> import der
    >>> ring = der.rod_from_shape(der.shapes.ring(1.0, 40), A1=1.0, A2=1.5)
    >>> scene = der.Scene(ring, constraints=[der.pin(0), der.fix_theta(0)])
    """
    return FixTheta(_v.integer(edge, "der.fix_theta: edge", "an integer edge index"))


def end_index(rod, end):
    """(end node, neighbour node, end edge) for end "start" or "end"."""
    if rod.closed:
        raise ValueError("a closed ring has no ends; use pin/fix_theta constraints or loads on nodes")
    if end in ("start", 0):
        return 0, 1, 0
    if end in ("end", -1):
        return rod.n_nodes - 1, rod.n_nodes - 2, rod.n_edges - 1
    raise ValueError(f"end must be 'start' or 'end'; got {end!r}")


Links = namedtuple("Links", ["dep", "const", "tri_dep", "tri_master", "tri_coef"])
Links.__doc__ = """Dependent coordinates of the end supports: ``q[dep[i]] = const[i] + sum a q[m]`` over the triplets
(``tri_dep``, ``tri_master``, ``tri_coef``) with ``tri_dep == dep[i]``. Dependents are never masters."""

NO_LINKS = Links(np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))

END_SUPPORTS = (Clamp, EndSupport)


def _local_dofs(rod, end):
    """The six position DOFs of an end edge, outer node first: [x_outer (3), x_inner (3)]."""
    k_out, k_in, _ = end_index(rod, end)
    return np.array([4 * k_out + i for i in range(3)] + [4 * k_in + i for i in range(3)], dtype=np.int64)


def _complement(directions):
    """Orthonormal basis (3 - k, 3) of the directions normal to the (k, 3) ``directions``."""
    if directions.shape[0] == 0:
        return np.eye(3)
    _, sv, vt = np.linalg.svd(directions)
    rank = int(np.sum(sv > 1e-12 * sv.max()))
    return vt[rank:]


def _support_equations(c, x_out, x_in, rigid_edge=False):
    """Rows G (m, 6) and right-hand side g (m,) of the linear equations an end support puts on its end edge's
    local coordinates [x_outer, x_inner], at the (prepared) positions: the centre held where it is (in the
    directions normal to its free directions), and for a clamp the end edge held along its direction."""
    centre = 0.5 * (x_out + x_in)
    rows, rhs = [], []
    for nu in _complement(c.free_directions()):
        rows.append(np.concatenate([0.5 * nu, 0.5 * nu]))
        rhs.append(float(nu @ centre))
    if isinstance(c, Clamp):
        e = x_in - x_out
        t = e / np.linalg.norm(e)
        for b in _complement(t[None, :]):
            rows.append(np.concatenate([-b, b]))
            rhs.append(0.0)
        if rigid_edge:
            # an inextensible rod's clamped end edge cannot stretch either: the clamp holds it whole (as a
            # rigid body: fixed, or translating along its slide direction)
            rows.append(np.concatenate([-t, t]))
            rhs.append(float(t @ e))
    return np.array(rows).reshape(-1, 6), np.array(rhs)


def _eliminate(G, g, groups, tol=1e-10):
    """Reduced row echelon form of G z = g, pivoting group by group (complete pivoting inside a group, the
    outer node's group first): returns [(pivot column, constant, {column: coefficient})] with
    z_pivot = constant + sum coefficient * z_column over non-pivot columns only."""
    G = np.array(G, float)
    g = np.array(g, float)
    scale = np.abs(G).max(initial=0.0)
    used = np.zeros(G.shape[0], bool)
    pivots = []
    for group in groups:
        while True:
            best, where = tol * scale, None
            for r in np.flatnonzero(~used):
                for col in group:
                    if col not in [p for _, p in pivots] and abs(G[r, col]) > best:
                        best, where = abs(G[r, col]), (r, col)
            if where is None:
                break
            r, col = where
            g[r] /= G[r, col]
            G[r] /= G[r, col]
            for r2 in range(G.shape[0]):
                if r2 != r and G[r2, col] != 0.0:
                    g[r2] -= G[r2, col] * g[r]
                    G[r2] -= G[r2, col] * G[r]
            used[r] = True
            pivots.append((r, col))
        # what is left of this group in the unused rows is round-off: drop it (so that later pivots never
        # depend on an outer node's master, which would widen the band)
        for col in group:
            G[~used, col] = 0.0
    if np.abs(G[~used]).max(initial=0.0) > tol * max(scale, 1.0) or np.abs(g[~used]).max(initial=0.0) > 1e-9 * (
            1.0 + np.abs(g).max(initial=0.0)):
        raise ValueError("end support: its equations are inconsistent (two supports contradict each other)")
    pivot_cols = {p for _, p in pivots}
    out = []
    for r, col in pivots:
        coefs = {c2: -G[r, c2] for c2 in range(G.shape[1]) if c2 not in pivot_cols and G[r, c2] != 0.0}
        out.append((col, g[r], coefs))
    return out


def build_links(rod, constraints, state=None, pattern=None):
    """(fixed, links): the boolean mask of held state entries -- plain fixes and the dependents of end supports,
    the dummy theta of an open rod always -- and the ``Links`` of the end supports, at ``state`` (default: the
    rest state; the solvers pass the prepared starting state, whose targets are applied).

    With a list ``pattern`` (moving supports, ``refresh_links``), every admissible (dependent, master) pair of an
    end support is kept as a triplet, zero or not, and what ``refresh_links`` needs to recompute the links in
    place at other positions is appended to ``pattern`` (one ``LinkPattern`` per end support)."""
    fixed = np.zeros(rod.n_dof, dtype=np.bool_)
    if not rod.closed:
        fixed[4 * rod.n_nodes - 1] = True
    q = rod.rest_q if state is None else state.q
    x = q.reshape(-1, 4)[:, :3]
    by_end = {}
    for c in constraints:
        if isinstance(c, Clamp):
            _, _, j = end_index(rod, c.end)
            fixed[4 * j + 3] = True
            by_end.setdefault(c.end, []).append(c)
        elif isinstance(c, EndSupport):
            end_index(rod, c.end)
            by_end.setdefault(c.end, []).append(c)
        elif isinstance(c, Pin):
            k = _node_index(rod, c.node)
            fixed[4 * k:4 * k + 3] = True
        elif isinstance(c, FixTheta):
            j = c.edge
            if not -rod.n_edges <= j < rod.n_edges:
                raise ValueError(f"FixTheta edge {j} out of range for a rod with {rod.n_edges} edges")
            fixed[4 * (j % rod.n_edges) + 3] = True
        else:
            raise ValueError(f"unknown constraint {c!r}; use der.clamp, der.hinge, der.roller, der.pin or "
                             "der.fix_theta")
    if len(by_end) == 2 and rod.n_edges < 3:
        raise ValueError(f"supports at both ends need at least 3 edges (the two end edges must not share a node); "
                         f"the rod has {rod.n_edges}")
    dep, const, tri = [], [], []
    for end, supports in by_end.items():
        if len(supports) > 1:
            raise ValueError(f"two supports at the {end!r} end ({supports[0]!r} and {supports[1]!r}): use one (a "
                             "clamp, hinge or roller per end)")
        local = _local_dofs(rod, end)
        if fixed[local].any():
            raise ValueError(f"der.pin on a node of the {end!r} end edge together with a support at that end: the "
                             "support already holds the end cross-section; drop the pin")
        G, g = _support_equations(supports[0], x[local[0] // 4], x[local[3] // 4], rigid_edge=rod.inextensible)
        pivots = _eliminate(G, g, ([0, 1, 2], [3, 4, 5]))
        cols = [col for col, _, _ in pivots]
        masters = [k for k in range(6) if k not in cols]
        slots = -np.ones((len(cols), len(masters)), np.int64)
        first = len(dep)
        for i, (col, value, coefs) in enumerate(pivots):
            d = int(local[col])
            fixed[d] = True
            dep.append(d)
            const.append(value)
            if pattern is None:
                tri.extend((d, int(local[c2]), a) for c2, a in coefs.items())
                continue
            for k, m in enumerate(masters):     # every admissible pair (no inner dependent on an outer master)
                if col < 3 or m >= 3:
                    slots[i, k] = len(tri)
                    tri.append((d, int(local[m]), coefs.get(m, 0.0)))
        if pattern is not None:
            pattern.append(LinkPattern(supports[0], local, np.array(cols, np.int64), np.array(masters, np.int64),
                                       first, slots if len(cols) == G.shape[0] else None,
                                       np.ascontiguousarray(_complement(supports[0].free_directions()))))
    if not dep:
        return fixed, NO_LINKS
    tri = np.array(tri, dtype=object).reshape(-1, 3)
    return fixed, Links(np.array(dep, np.int64), np.array(const, float), tri[:, 0].astype(np.int64),
                        tri[:, 1].astype(np.int64), tri[:, 2].astype(float))


LinkPattern = namedtuple("LinkPattern", ["support", "local", "pivots", "masters", "first", "slots", "normals"])
LinkPattern.__doc__ = """How one end support's links are laid out (``build_links(..., pattern=[])``): its record,
its six local DOFs, the local columns solved for (``pivots``, in the order of ``Links.dep`` from index ``first``) and the others
(``masters``), ``slots[i, k]`` the index in the triplet arrays of (pivot i, master k) or -1 where the band forbids
a coupling (an inner-node dependent on an outer-node master; None if the support's equations were dependent:
no square system to re-solve), and ``normals`` the directions its centre is held along."""


@njit(cache=True)
def relink_end(x_out, x_in, normals, clamp, rigid, pivots, masters, X):
    """One end support's link values at the end edge (x_out, x_in), for the pivots (dependents) and masters of
    its ``LinkPattern``: its equations G z = g (z = [x_out, x_in]; the centre held along ``normals``, and for a
    ``clamp`` the end edge held along its direction t: b.(x_in - x_out) = 0 for two unit b normal to t, plus
    t.(x_in - x_out) = |e| if ``rigid``) solved for the pivots, X = G_P^-1 [G_M | g] (Gaussian elimination with
    partial pivoting; X has len(pivots) rows and len(masters) + 1 columns). The two b may be any orthonormal pair:
    the reduced row echelon form for given pivots depends only on the equations' row space. False if G_P is
    singular or the equation count differs from the pivot count."""
    m = pivots.shape[0]
    G = np.zeros((6, 6))
    g = np.zeros(6)
    r = 0
    for k in range(normals.shape[0]):
        s = 0.0
        for a in range(3):
            G[r, a] = 0.5 * normals[k, a]
            G[r, 3 + a] = 0.5 * normals[k, a]
            s += normals[k, a] * 0.5 * (x_out[a] + x_in[a])
        g[r] = s
        r += 1
    if clamp:
        e = x_in - x_out
        length = np.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
        t = e / length
        k = 0                                   # the axis t is least along: a = e_k
        for a in range(1, 3):
            if abs(t[a]) < abs(t[k]):
                k = a
        b1 = -t[k] * t
        b1[k] += 1.0
        b1 /= np.sqrt(b1[0] * b1[0] + b1[1] * b1[1] + b1[2] * b1[2])
        b2 = np.array([t[1] * b1[2] - t[2] * b1[1], t[2] * b1[0] - t[0] * b1[2], t[0] * b1[1] - t[1] * b1[0]])
        for b in (b1, b2):
            for a in range(3):
                G[r, a] = -b[a]
                G[r, 3 + a] = b[a]
            r += 1
        if rigid:
            for a in range(3):
                G[r, a] = -t[a]
                G[r, 3 + a] = t[a]
            g[r] = length
            r += 1
    if r != m:
        return False
    nm = masters.shape[0]
    A = np.zeros((m, m + nm + 1))
    for i in range(m):
        for j in range(m):
            A[i, j] = G[i, pivots[j]]
        for j in range(nm):
            A[i, m + j] = G[i, masters[j]]
        A[i, m + nm] = g[i]
    scale = 0.0
    for i in range(m):
        for j in range(m):
            scale = max(scale, abs(A[i, j]))
    for c in range(m):
        p = c
        for i in range(c + 1, m):
            if abs(A[i, c]) > abs(A[p, c]):
                p = i
        if not abs(A[p, c]) > 1e-12 * scale:
            return False
        if p != c:
            for j in range(A.shape[1]):
                A[c, j], A[p, j] = A[p, j], A[c, j]
        piv = A[c, c]
        for j in range(A.shape[1]):
            A[c, j] /= piv
        for i in range(m):
            if i != c and A[i, c] != 0.0:
                f = A[i, c]
                for j in range(A.shape[1]):
                    A[i, j] -= f * A[c, j]
    for i in range(m):
        for j in range(nm + 1):
            X[i, j] = A[i, m + j]
    return True


def refresh_links(rod, links, patterns, constraints, q):
    """Recompute the end supports' links in place (``links.const``, ``links.tri_coef``) at the positions ``q``
    for the support records ``constraints`` (the same kinds, ends and free directions as when ``patterns`` was
    built: only their targets moved), keeping the dependents and masters chosen then (``relink_end``). The
    reduced row echelon form of a support's equations for given pivot columns depends only on the equations' row
    space, so this is what ``build_links`` gives at ``q`` as long as it would choose the same pivots.

    Returns False, touching nothing, when that choice no longer fits -- the pivots ill-conditioned (a coefficient
    above 10: complete pivoting keeps them near 1) or a coupling the band forbids needed; the caller then builds
    the links afresh (``build_links``)."""
    x = q.reshape(-1, 4)[:, :3]
    ends = [c for c in constraints if isinstance(c, END_SUPPORTS)]
    if len(ends) != len(patterns):
        return False
    updates = []
    for pat, c in zip(patterns, ends):
        if pat.slots is None or pat.support.end != c.end:
            return False
        X = np.empty((pat.pivots.size, pat.masters.size + 1))
        if not relink_end(x[pat.local[0] // 4], x[pat.local[3] // 4], pat.normals, isinstance(c, Clamp),
                          rod.inextensible, pat.pivots, pat.masters, X):
            return False
        coef = -X[:, :-1]
        if not np.isfinite(X).all() or np.abs(coef).max(initial=0.0) > 10.0:
            return False
        if np.abs(coef[pat.slots < 0]).max(initial=0.0) > 1e-12:
            return False
        updates.append((pat, X[:, -1], coef))
    for pat, const, coef in updates:
        links.const[pat.first:pat.first + const.size] = const
        ok = pat.slots >= 0
        links.tri_coef[pat.slots[ok]] = coef[ok]
    return True


def fixed_dofs(rod, constraints, state=None):
    """Boolean mask of the held state entries (the dummy theta of an open rod is always held); the dependents of
    end supports count as held (see ``build_links``)."""
    return build_links(rod, constraints, state)[0]


def _node_index(rod, node):
    if not -rod.n_nodes <= node < rod.n_nodes:
        raise ValueError(f"node {node} out of range for a rod with {rod.n_nodes} nodes")
    return node % rod.n_nodes


def validate(rod, constraints):
    """Check constraint arguments before any work (ValueError naming the bad value)."""
    pinned = {}
    for c in constraints:
        if isinstance(c, Clamp):
            end_index(rod, c.end)
            if c.rotation is not None:
                _rotation_matrix(c.rotation, "der.clamp: rotation")
            if c.position is not None:
                _v.vector3(c.position, "der.clamp: position")
            if not set(c.slide) <= {0, 1, 2} or len(set(c.slide)) != len(c.slide) or len(c.slide) > 1:
                raise ValueError(f"clamp slide must name at most one coordinate axis (0, 1 or 2) or be a direction "
                                 f"3-vector; got {c.slide!r}")
        elif isinstance(c, EndSupport):
            end_index(rod, c.end)
            if c.position is not None:
                _v.vector3(c.position, f"der.{c.kind}: position")
            f = c.free_directions()
            if f.shape[0] > 2 or not np.all(np.isfinite(f)):
                raise ValueError(f"der.{c.kind}: at most two finite free directions; got {f.tolist()}")
        elif isinstance(c, Pin):
            k = _node_index(rod, c.node)
            if c.position is not None:
                p = _v.vector3(c.position, "der.pin: position")
                if k in pinned and not np.array_equal(pinned[k], p):
                    raise ValueError(f"der.Scene: constraints: two pins on node {k} with different positions "
                                     f"({pinned[k].tolist()} and {p.tolist()}): a node can be held at one place "
                                     "only; drop one of them")
                pinned[k] = p
    fixed_dofs(rod, constraints)


def end_centre(x, rod, end):
    """Centre of the end cross-section ``end`` (the end edge's midpoint) for node positions ``x``."""
    k_out, k_in, _ = end_index(rod, end)
    return 0.5 * (x[k_out] + x[k_in])


def apply_targets(rod, state, constraints):
    """Move constrained node positions of ``state`` to their targets (in place).

    A clamp with ``rotation`` or ``position`` puts its end edge at R times its rest edge vector (its current
    length kept), centred on ``position`` (default: the rest centre); a support free along some directions
    keeps where it has slid to along them (the centre is projected onto its line or plane). Hinges and rollers
    with a ``position`` translate their end edge so that its centre is there (projected likewise).

    Returns a list of ``(edge, m1_target)``: end material directors that rotated clamps prescribe. The caller
    transports the frames to the new positions and then sets theta of those edges (on the branch nearest the
    current theta, so that an end turned a little at a time keeps count of its full turns).
    """
    directors = []
    x = state.positions
    rest_x = rod.rest_q.reshape(-1, 4)[:, :3]
    for c in constraints:
        if isinstance(c, Pin) and c.position is not None:
            x[_node_index(rod, c.node)] = np.asarray(c.position, float)
        elif isinstance(c, Clamp) and (c.rotation is not None or c.position is not None):
            k_out, k_in, j = end_index(rod, c.end)
            R = np.eye(3) if c.rotation is None else np.asarray(c.rotation, float)
            p = end_centre(rest_x, rod, c.end) if c.position is None else np.asarray(c.position, float)
            p = _slid(p, end_centre(x, rod, c.end), c.free_directions())
            e_rest = R @ (rest_x[k_in] - rest_x[k_out])
            e = e_rest * (np.linalg.norm(x[k_in] - x[k_out]) / np.linalg.norm(e_rest))
            x[k_in] = p + 0.5 * e
            x[k_out] = p - 0.5 * e
            directors.append((j, R @ rod.rest_d1[j]))
        elif isinstance(c, EndSupport) and c.position is not None:
            k_out, k_in, _ = end_index(rod, c.end)
            now = end_centre(x, rod, c.end)
            shift = _slid(np.asarray(c.position, float), now, c.free_directions()) - now
            x[k_out] += shift
            x[k_in] += shift
    return directors


def _slid(p, current, free):
    """``p`` moved along the ``free`` (orthonormal) directions to where ``current`` is along them."""
    p = np.array(p, float)
    for u in free:
        p += u * float(u @ (current - p))
    return p


def enforce_links(q, links):
    """Set the dependents of the end supports from their masters (in place): q_d = c_d + sum a q_m."""
    if links.dep.size:
        q[links.dep] = links.const
        np.add.at(q, links.tri_dep, links.tri_coef * q[links.tri_master])


def support_dofs(rod, c):
    """Where a constraint's reaction is read: (the nodes whose position entries it acts on, the edge whose
    angle theta it holds or None)."""
    if isinstance(c, END_SUPPORTS):
        k_out, k_in, j = end_index(rod, c.end)
        return (k_out, k_in), (j if isinstance(c, Clamp) else None)
    if isinstance(c, Pin):
        return (_node_index(rod, c.node),), None
    return (), c.edge % rod.n_edges
