"""Constraints: clamps, pinned nodes, fixed angles.

A constraint fixes some entries of the state vector. A clamp at an end fixes the two end nodes and the
angle theta of the end edge, i.e. the end position and the end material frame. Optional targets move the
constrained entries before a solve (prescribed displacements and rotations).
"""
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Clamp:
    """Clamp the end ``end`` ("start" or "end"): end position and end material frame held fixed.

    ``rotation`` (3x3) and ``position`` (3,) optionally prescribe where the clamp goes: the end edge is
    rotated rigidly by ``rotation`` (about the end node) and the end node moved to ``position``; the end
    material frame follows the rotation. ``slide`` lists coordinate axes (0, 1, 2 for x, y, z) along which the
    clamped end may slide freely (no force along them): e.g. ``slide=(2,)`` for an end clamped in a sleeve
    along z, which keeps its direction and frame but not its distance from the other end. Sliding must be
    along the end tangent (an axis the end edge lies on).
    """
    end: str
    rotation: object = None
    position: object = None
    slide: tuple = ()


@dataclass(frozen=True)
class Pin:
    """Hold node ``node`` at its position (or move it to ``position``); its rotation stays free."""
    node: int
    position: object = None


@dataclass(frozen=True)
class FixTheta:
    """Hold the angle theta of edge ``edge`` (the material frame relative to the transported reference)."""
    edge: int


def clamp(end="start", rotation=None, position=None, slide=()):
    return Clamp(end, rotation, position, tuple(int(a) for a in np.atleast_1d(slide)))


def pin(node, position=None):
    return Pin(int(node), position)


def fix_theta(edge):
    return FixTheta(int(edge))


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
            raise ValueError(f"unknown constraint {c!r}; use clamp(), pin() or fix_theta()")
    return fixed


def _node_index(rod, node):
    if not -rod.n_nodes <= node < rod.n_nodes:
        raise ValueError(f"node {node} out of range for a rod with {rod.n_nodes} nodes")
    return node % rod.n_nodes


def validate(rod, constraints):
    """Check constraint arguments before any work (ValueError naming the bad value)."""
    for c in constraints:
        if isinstance(c, Clamp):
            k0, k1, _ = end_index(rod, c.end)
            if not set(c.slide) <= {0, 1, 2} or len(set(c.slide)) != len(c.slide) or len(c.slide) > 1:
                raise ValueError(f"clamp slide must name at most one coordinate axis (0, 1 or 2); got {c.slide!r}")
            if c.slide:
                R = np.eye(3) if c.rotation is None else np.asarray(c.rotation, float)
                e = R @ (rod.rest_q.reshape(-1, 4)[k1, :3] - rod.rest_q.reshape(-1, 4)[k0, :3])
                off = np.delete(e, c.slide[0])
                if np.abs(off).max() > 1e-12 * np.linalg.norm(e):
                    raise ValueError(f"a clamp can slide only along its end tangent: the end edge {e / np.linalg.norm(e)}"
                                     f" is not along axis {c.slide[0]}")
            if c.rotation is not None:
                R = np.asarray(c.rotation, float)
                if R.shape != (3, 3) or not np.isfinite(R).all() or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) \
                        or np.linalg.det(R) < 0:
                    raise ValueError(f"clamp rotation must be a proper 3x3 rotation matrix; got {c.rotation!r}")
            if c.position is not None:
                p = np.asarray(c.position, float)
                if p.shape != (3,) or not np.isfinite(p).all():
                    raise ValueError(f"clamp position must be a finite 3-vector; got {c.position!r}")
        elif isinstance(c, Pin):
            _node_index(rod, c.node)
            if c.position is not None:
                p = np.asarray(c.position, float)
                if p.shape != (3,) or not np.isfinite(p).all():
                    raise ValueError(f"pin position must be a finite 3-vector; got {c.position!r}")
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
