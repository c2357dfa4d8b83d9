"""Discrete rest shapes: straight rod, circular arc, closed ring, helix.

Each function returns a ``Shape``: node positions sampled on the exact curve at equal arc-length steps, and
for straight rods a ``director`` (where the Frenet frame is undefined). ``der.rod_from_shape`` puts the
material frame on the discrete Frenet frame of these nodes.

An open rod of length L with n edges has edge length h = L / (n - 1) and its nodes at arc lengths
``(k - 1/2) h``, k = 0..n: the midpoints of the end edges -- where the end material frames live -- are the
ends xi = 0 and xi = L of the rod (see ``Rod.xi_nodes``). A ring of length L has n nodes at ``k L / n``.

Conventions: the arc starts at the origin with tangent e1 and turns towards e2 (binormal e3); the ring is
centred at the origin in the (e1, e2) plane, traversed counter-clockwise about e3; the helix is paper Eq. 49
with axis e3, right-handed for omega0 > 0 and left-handed for omega0 < 0.

Example
-------
>>> import der
>>> shape = der.shapes.helix(kappa0=1.0, omega0=0.6, turns=2, n=100)
>>> shape.positions.shape                  # n + 1 nodes of an open rod
(101, 3)
"""
from dataclasses import dataclass

import numpy as np

from . import validate


@dataclass(frozen=True)
class Shape:
    """A discrete rest shape: what ``der.rod_from_shape`` builds a rod on.

    Attributes
    ----------
    positions : (n_nodes, 3) float array
        Node positions (length units). An open rod of n edges has n + 1 nodes, its end cross-sections at the
        midpoints of the end edges; a ring of n edges has n nodes (the first is not repeated).
    closed : bool
        True for a ring.
    director : (3,) or (n_edges, 3) array or None
        Where the shape is straight (no Frenet frame), the direction of the material vector m1 (projected
        normal to each edge); ignored where the shape is curved.

    Example
    -------
    >>> import numpy as np, der
    >>> x = np.stack([np.linspace(0, 1, 11), np.zeros(11), 0.1 * np.linspace(0, 1, 11) ** 2], axis=1)
    >>> rod = der.rod_from_shape(der.shapes.Shape(x), A1=1.0, A2=1.0)   # any polygon of your own
    """
    positions: np.ndarray
    closed: bool = False
    director: np.ndarray | None = None


def _check_n(n, minimum, what):
    n = validate.integer(n, f"der.shapes.{what}: n (number of edges)", f"an integer >= {minimum}")
    if n < minimum:
        raise ValueError(f"{what}: n (number of edges) must be an integer >= {minimum}; got {n!r}")
    return n


def _open_arclengths(length, n):
    """Node arc lengths of an open rod: end-edge midpoints at 0 and ``length``."""
    h = length / (n - 1)
    return (np.arange(n + 1) - 0.5) * h


def _check_positive(what, **kw):
    return [validate.positive_number(val, f"der.shapes.{what}: {name}", "a finite number > 0")
            for name, val in kw.items()]


def straight(length, n, axis=(0.0, 0.0, 1.0), director=(1.0, 0.0, 0.0)):
    """A straight rod of ``length`` from the origin along ``axis``, with ``n`` edges.

    Parameters
    ----------
    length : float
        Rest length L (> 0). The end cross-sections (end-edge midpoints) are at the origin and at L * axis;
        the outer nodes lie half an edge beyond them: nodes at arc lengths (k - 1/2) L / (n - 1), k = 0..n.
    n : int
        Number of edges, >= 2.
    axis : 3-vector
        Direction of the rod (normalised here), e.g. (0, 0, 1) for z. Not a name like "z".
    director : 3-vector or (n, 3) array
        Direction of the material vector m1 (projected normal to the axis); must not be parallel to it.

    Returns
    -------
    Shape

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(2.0, 40, axis=(1, 0, 0), director=(0, 0, 1)), 1.0, 1.5)
    >>> round(rod.length, 12)
    2.0
    """
    n = _check_n(n, 2, "straight")
    length, = _check_positive("straight", length=length)
    axis = validate.finite_array(axis, "der.shapes.straight: axis", (3,),
                                 "a non-zero finite 3-vector, e.g. (0, 0, 1) for z")
    if np.linalg.norm(axis) == 0:
        raise ValueError(f"der.shapes.straight: axis must be a non-zero finite 3-vector, e.g. (0, 0, 1) for z; "
                         f"got {axis.tolist()}")
    axis = axis / np.linalg.norm(axis)
    director = validate.finite_array(director, "der.shapes.straight: director", None,
                                     "a finite 3-vector (or one per edge, shape (n, 3)) not parallel to axis")
    if director.shape not in ((3,), (n, 3)):
        raise ValueError(f"der.shapes.straight: director must be a finite 3-vector or have shape ({n}, 3); "
                         f"got shape {director.shape}")
    s = _open_arclengths(length, n)
    return Shape(s[:, None] * axis[None, :], False, director)


def arc(radius, length, n):
    """A planar circular arc of ``radius`` and ``length`` (< 2 pi radius), curvature 1/radius, ``n`` edges.

    Parameters
    ----------
    radius : float
        Radius a0 > 0 (natural curvature kappa0 = 1/a0 once made a rod).
    length : float
        Rest length L, 0 < L < 2 pi radius (a closed circle is ``ring``).
    n : int
        Number of edges, >= 2.

    Returns
    -------
    Shape: starts at the origin (xi = 0) with tangent e1, turning towards e2 (binormal e3); the end
    cross-sections are at xi = 0 and xi = L, the outer nodes half an edge beyond.

    Example
    -------
    The arc of the paper's ring torsion (Section 6.2):

    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.arc(1.0, 3.0, 60), A1=1.0, A2=1.5)
    """
    n = _check_n(n, 2, "arc")
    radius, length = _check_positive("arc", radius=radius, length=length)
    if length >= 2 * np.pi * radius:
        raise ValueError(f"arc length {length} must be < 2 pi radius = {2 * np.pi * radius:.6g} (use ring())")
    phi = _open_arclengths(length, n) / radius
    x = np.stack([radius * np.sin(phi), radius * (1 - np.cos(phi)), np.zeros_like(phi)], axis=1)
    return Shape(x, False, None)


def ring(radius, n):
    """A closed planar circle of ``radius`` in the (e1, e2) plane, ``n`` edges (n nodes).

    Parameters
    ----------
    radius : float
        Radius a0 > 0; centred at the origin, traversed counter-clockwise about e3, node k at angle 2 pi k / n.
    n : int
        Number of edges (= nodes), >= 3.

    Returns
    -------
    Shape (closed).

    Example
    -------
    >>> import der
    >>> ring = der.rod_from_shape(der.shapes.ring(1.0, 100), A1=1.0, A2=1.5).with_imposed_twist(2.0)
    """
    n = _check_n(n, 3, "ring")
    radius, = _check_positive("ring", radius=radius)
    phi = 2 * np.pi * np.arange(n) / n
    x = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.zeros_like(phi)], axis=1)
    return Shape(x, True, None)


def helix_geometry(kappa0, omega0):
    """Radius a0, pitch parameter b0 and angular rate S of the helix of curvature kappa0, torsion omega0.

    Parameters
    ----------
    kappa0, omega0 : float
        Curvature (> 0) and torsion (1/length; omega0 > 0 right-handed).

    Returns
    -------
    (a0, b0, S) with a0 = kappa0 / (kappa0^2 + omega0^2), b0 = omega0 / (kappa0^2 + omega0^2),
    S = 1 / sqrt(a0^2 + b0^2) = sqrt(kappa0^2 + omega0^2) (paper Eq. 50).

    Example
    -------
    >>> import der
    >>> a0, b0, S = der.shapes.helix_geometry(1.0, 0.0)     # a circle of radius 1
    >>> (a0, b0, S)
    (1.0, 0.0, 1.0)
    """
    kappa0 = validate.finite_number(kappa0, "der.shapes.helix_geometry: kappa0")
    omega0 = validate.finite_number(omega0, "der.shapes.helix_geometry: omega0")
    k2 = kappa0 ** 2 + omega0 ** 2
    a0 = kappa0 / k2
    b0 = omega0 / k2
    return a0, b0, float(np.sqrt(k2))


def helix_length(kappa0, omega0, turns):
    """Arc length of ``turns`` full turns of the helix (kappa0, omega0): turns * 2 pi / sqrt(kappa0^2 + omega0^2).

    Parameters
    ----------
    kappa0, omega0 : float
        Curvature and torsion (1/length).
    turns : float
        Number of turns (need not be whole).

    Returns
    -------
    float, length units (one turn: paper Eq. 51).

    Example
    -------
    >>> import der
    >>> round(float(der.shapes.helix_length(1.0, 0.0, 1)), 6)    # one turn of the unit circle
    6.283185
    """
    return turns * 2 * np.pi / np.hypot(kappa0, omega0)


def helix(kappa0, omega0, turns, n, phase=0.0):
    """A helix of curvature ``kappa0`` and torsion ``omega0`` (paper Eq. 49), ``turns`` turns, ``n`` edges.

    R(s) = a0 cos(S s + phase) e1 + a0 sin(S s + phase) e2 + b0 S s e3 for xi in [0, turns * 2 pi / S]
    (``helix_geometry`` gives a0, b0, S). Its axis is e3; the end cross-sections are at xi = 0 and
    xi = L, the outer nodes half an edge beyond.

    Parameters
    ----------
    kappa0 : float
        Curvature, > 0 (1/length).
    omega0 : float
        Torsion (1/length), any sign: right-handed for omega0 > 0, left-handed for omega0 < 0, a planar
        circle for 0. A single number (for a non-uniform rod build your own ``Shape``).
    turns : float
        Number of turns, > 0 (need not be whole).
    n : int
        Number of edges, >= 2.
    phase : float
        Angle (radians) of the start about the axis.

    Returns
    -------
    Shape

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.helix(kappa0=1.0, omega0=0.6, turns=1, n=200), A1=1.0, A2=1.5)
    """
    n = _check_n(n, 2, "helix")
    kappa0, turns = _check_positive("helix", kappa0=kappa0, turns=turns)
    omega0 = validate.finite_number(omega0, "der.shapes.helix: omega0 (the torsion, one number)")
    phase = validate.finite_number(phase, "der.shapes.helix: phase")
    a0, b0, S = helix_geometry(kappa0, omega0)
    s = _open_arclengths(helix_length(kappa0, omega0, turns), n)
    x = np.stack([a0 * np.cos(S * s + phase), a0 * np.sin(S * s + phase), b0 * S * s], axis=1)
    if not np.isfinite(x).all():
        raise ValueError(f"der.shapes.helix: kappa0={kappa0!r}, omega0={omega0!r}, turns={turns!r} give non-finite "
                         "node positions (overflow); use moderate values")
    return Shape(x, False, None)
