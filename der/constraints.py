"""Constraints: clamps, pinned nodes, fixed angles.

A constraint fixes some entries of the state vector. A clamp at an end fixes the two end nodes and the
angle theta of the end edge, i.e. the end position and the end material frame. Optional targets move the
constrained entries before a solve (prescribed displacements and rotations).
"""
from dataclasses import dataclass

import numpy as np

from . import loads as _loads
from . import validate as _v


@dataclass(frozen=True)
class Clamp:
    """Clamp the end ``end`` ("start" or "end"): end position and end material frame held fixed.

    ``rotation`` (3x3) and ``position`` (3,) optionally prescribe where the clamp goes: the end edge is
    rotated rigidly by ``rotation`` (about the end node) and the end node moved to ``position``; the end
    material frame follows the rotation. ``slide`` lists coordinate axes (0, 1, 2 for x, y, z) along which the
    clamped end may slide freely (no force along them): e.g. ``slide=(2,)`` for an end clamped in a sleeve
    along z, which keeps its direction and frame but not its distance from the other end. Sliding must be
    along the end tangent (an axis the end edge lies on). Made by ``der.clamp``.
    """
    end: str
    rotation: object = None
    position: object = None
    slide: tuple = ()


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


def _rotation_matrix(R, name):
    R = _v.finite_array(R, name, (3, 3), "a proper 3x3 rotation matrix (orthogonal, determinant +1), "
                                               "e.g. numpy.eye(3)")
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
        raise ValueError(f"{name} must be a proper 3x3 rotation matrix (R R^T = I to 1e-9, det R = +1); got "
                         f"{np.array2string(R, precision=4)} with det {np.linalg.det(R):.4g} and "
                         f"|R R^T - I| = {np.abs(R @ R.T - np.eye(3)).max():.2g}")
    return R


def clamp(end="start", rotation=None, position=None, slide=()):
    """Clamp an end of an open rod: its end cross-section's position and material frame are held.

    Parameters
    ----------
    end : "start" or "end"
        Which end, xi = 0 or xi = L. The clamp holds both nodes of the end edge and its angle theta, i.e. the
        end cross-section (the end edge's midpoint, where the rod's end is) and the end material frame.
    rotation : (3, 3) array, optional
        A proper rotation matrix R (R R^T = I, det R = +1) that moves the clamp before the solve: the end edge
        is turned rigidly by R about its END NODE (the outer node of the end edge, half an edge beyond the end
        cross-section), and the end material frame is turned with it (m1 -> R m1_rest). Turning an end by an
        angle phi about its rest tangent t0 is ``R = rotation about t0 by phi`` (right-handed: phi > 0
        over-twists at the "end"). Relative to the REST configuration, not to the current one.
    position : 3-vector, optional
        Where the end node (the outer node) goes (global frame, length units); default: its rest position.
    slide : int or tuple of int
        At most one coordinate axis (0, 1, 2 = x, y, z) along which the clamped end may slide freely (a
        sleeve: no force along that axis). The end edge must lie along that axis.

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
        raise TypeError(f"der.clamp: slide must be an axis 0, 1 or 2 (x, y, z) or a tuple of at most one; "
                        f"got {slide!r}")
    axes = tuple(_v.integer(a, "der.clamp: slide", "an axis 0, 1 or 2 (x, y, z)")
                 for a in np.atleast_1d(np.asarray(slide, dtype=object)))
    return Clamp(end, rotation, position, axes)


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


def fixed_dofs(rod, constraints):
    """Boolean mask of the fixed state-vector entries (the dummy theta of an open rod is always fixed)."""
    fixed = np.zeros(rod.n_dof, dtype=np.bool_)
    if not rod.closed:
        fixed[4 * rod.n_nodes - 1] = True
    for c in constraints:
        if isinstance(c, Clamp):
            k0, k1, j = end_index(rod, c.end)
            for k in (k0, k1):
                fixed[4 * k:4 * k + 3] = True
                for a in c.slide:
                    fixed[4 * k + a] = False
            fixed[4 * j + 3] = True
        elif isinstance(c, Pin):
            k = _node_index(rod, c.node)
            fixed[4 * k:4 * k + 3] = True
        elif isinstance(c, FixTheta):
            j = c.edge
            if not -rod.n_edges <= j < rod.n_edges:
                raise ValueError(f"FixTheta edge {j} out of range for a rod with {rod.n_edges} edges")
            fixed[4 * (j % rod.n_edges) + 3] = True
        else:
            raise ValueError(f"unknown constraint {c!r}; use der.clamp, der.pin or der.fix_theta")
    return fixed


def _node_index(rod, node):
    if not -rod.n_nodes <= node < rod.n_nodes:
        raise ValueError(f"node {node} out of range for a rod with {rod.n_nodes} nodes")
    return node % rod.n_nodes


def validate(rod, constraints):
    """Check constraint arguments before any work (ValueError naming the bad value)."""
    pinned = {}
    for c in constraints:
        if isinstance(c, Clamp):
            k0, k1, _ = end_index(rod, c.end)
            R = np.eye(3) if c.rotation is None else _rotation_matrix(c.rotation, "der.clamp: rotation")
            if c.position is not None:
                _v.vector3(c.position, "der.clamp: position")
            if not set(c.slide) <= {0, 1, 2} or len(set(c.slide)) != len(c.slide) or len(c.slide) > 1:
                raise ValueError(f"clamp slide must name at most one coordinate axis (0, 1 or 2); got {c.slide!r}")
            if c.slide:
                e = R @ (rod.rest_q.reshape(-1, 4)[k1, :3] - rod.rest_q.reshape(-1, 4)[k0, :3])
                off = np.delete(e, c.slide[0])
                if np.abs(off).max() > 1e-12 * np.linalg.norm(e):
                    raise ValueError(f"a clamp can slide only along its end tangent: the end edge {e / np.linalg.norm(e)}"
                                     f" is not along axis {c.slide[0]}")
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


def apply_targets(rod, state, constraints):
    """Move constrained node positions of ``state`` to their targets (in place).

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
            k0, k1, j = end_index(rod, c.end)
            R = np.eye(3) if c.rotation is None else np.asarray(c.rotation, float)
            p = rest_x[k0] if c.position is None else np.asarray(c.position, float)
            if c.slide:   # a sliding clamp keeps where it has slid to
                p = p.copy()
                p[list(c.slide)] = x[k0, list(c.slide)]
            x[k1] = p + R @ (rest_x[k1] - rest_x[k0])
            x[k0] = p
            directors.append((j, R @ rod.rest_d1[j]))
    return directors
