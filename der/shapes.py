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
"""
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Shape:
    positions: np.ndarray
    closed: bool = False
    director: np.ndarray | None = None


def _check_n(n, minimum, what):
    if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < minimum:
        raise ValueError(f"{what}: n (number of edges) must be an integer >= {minimum}; got {n!r}")


def _open_arclengths(length, n):
    """Node arc lengths of an open rod: end-edge midpoints at 0 and ``length``."""
    h = length / (n - 1)
    return (np.arange(n + 1) - 0.5) * h


def _check_positive(**kw):
    for name, val in kw.items():
        if not (np.isfinite(val) and val > 0):
            raise ValueError(f"{name} must be finite and > 0; got {val!r}")


def straight(length, n, axis=(0.0, 0.0, 1.0), director=(1.0, 0.0, 0.0)):
    """Straight rod of ``length`` from the origin along ``axis`` with ``n`` edges; ``director`` sets m1."""
    _check_n(n, 2, "straight")
    _check_positive(length=length)
    axis = np.asarray(axis, float)
    if axis.shape != (3,) or not np.isfinite(axis).all() or np.linalg.norm(axis) == 0:
        raise ValueError(f"axis must be a non-zero finite 3-vector; got {axis}")
    axis = axis / np.linalg.norm(axis)
    s = _open_arclengths(length, n)
    return Shape(s[:, None] * axis[None, :], False, np.asarray(director, float))


def arc(radius, length, n):
    """Planar circular arc of ``radius`` and ``length`` (< 2 pi radius), curvature 1/radius, ``n`` edges.

    Starts at the origin (xi = 0) with tangent e1, turning towards e2."""
    _check_n(n, 2, "arc")
    _check_positive(radius=radius, length=length)
    if length >= 2 * np.pi * radius:
        raise ValueError(f"arc length {length} must be < 2 pi radius = {2 * np.pi * radius:.6g} (use ring())")
    phi = _open_arclengths(length, n) / radius
    x = np.stack([radius * np.sin(phi), radius * (1 - np.cos(phi)), np.zeros_like(phi)], axis=1)
    return Shape(x, False, None)


def ring(radius, n):
    """Closed planar circle of ``radius`` in the (e1, e2) plane with ``n`` edges (n nodes)."""
    _check_n(n, 3, "ring")
    _check_positive(radius=radius)
    phi = 2 * np.pi * np.arange(n) / n
    x = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.zeros_like(phi)], axis=1)
    return Shape(x, True, None)


def helix_geometry(kappa0, omega0):
    """Radius a0, pitch parameter b0 and angular rate S = 1/sqrt(a0^2 + b0^2) of the helix (paper Eq. 50)."""
    k2 = kappa0 ** 2 + omega0 ** 2
    a0 = kappa0 / k2
    b0 = omega0 / k2
    return a0, b0, np.sqrt(k2)


def helix_length(kappa0, omega0, turns):
    """Arc length of ``turns`` full turns (one turn: paper Eq. 51)."""
    return turns * 2 * np.pi / np.hypot(kappa0, omega0)


def helix(kappa0, omega0, turns, n, phase=0.0):
    """Helix of curvature ``kappa0`` > 0 and torsion ``omega0`` (paper Eq. 49), ``turns`` turns, ``n`` edges.

    R(s) = a0 cos(S s + phase) e1 + a0 sin(S s + phase) e2 + b0 S s e3, xi in [0, turns * 2 pi / S].
    """
    _check_n(n, 2, "helix")
    _check_positive(kappa0=kappa0, turns=turns)
    if not np.isfinite(omega0):
        raise ValueError(f"omega0 must be finite; got {omega0!r}")
    a0, b0, S = helix_geometry(kappa0, omega0)
    s = _open_arclengths(helix_length(kappa0, omega0, turns), n)
    x = np.stack([a0 * np.cos(S * s + phase), a0 * np.sin(S * s + phase), b0 * S * s], axis=1)
    return Shape(x, False, None)
