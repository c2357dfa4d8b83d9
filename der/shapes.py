"""Discrete rest shapes: straight rod, circular arc, closed ring, helix, and (issue 13) a user polyline, a spline
through points, a helix of varying curvature and torsion, and natural strains along the arc length (``strains``).

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
        normal to each edge); ignored where the shape is curved, unless ``frame`` is "director".
    frame : "frenet" or "director"
        Where the rest material frame lies: on the discrete Frenet frame (m1 = the Frenet normal, alpha = 0; the
        default), or on ``director`` (m1 = the director projected normal to each edge, e.g. the width direction
        of a ribbon; ``polyline(..., director=...)``).

    Example
    -------
    >>> import numpy as np, der
    >>> x = np.stack([np.linspace(0, 1, 11), np.zeros(11), 0.1 * np.linspace(0, 1, 11) ** 2], axis=1)
    >>> rod = der.rod_from_shape(der.shapes.Shape(x), A1=1.0, A2=1.0)   # any polygon of your own
    """
    positions: np.ndarray
    closed: bool = False
    director: np.ndarray | None = None
    frame: str = "frenet"


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


# ---------------------------------------------------------------------------------------------
# issue 13: shapes of your own, and rest states given by their strains
# ---------------------------------------------------------------------------------------------


def polyline(points, director=None, closed=False):
    """A rest shape whose nodes are the given ``points`` (a user polyline), optionally with a director per edge.

    Parameters
    ----------
    points : (n_nodes, 3) array
        Node positions (length units). An open rod's end cross-sections are the midpoints of its first and last
        edges (see ``Rod.xi_nodes``); a ring's first node is not repeated at the end.
    director : 3-vector or (n_edges, 3) array, optional
        The material vector m1 of each edge (projected normal to it): the rest material frame is then this
        director everywhere (``frame="director"``), not the Frenet frame, e.g. the width direction of a ribbon
        or a strip. None: the discrete Frenet frame (alpha = 0), as for the other shapes.
    closed : bool
        True for a ring.

    Returns
    -------
    Shape

    Example
    -------
    >>> import numpy as np, der
    >>> s = np.linspace(0.0, 1.0, 21)
    >>> shape = der.shapes.polyline(np.stack([s, 0.1 * s ** 2, 0 * s], axis=1), director=(0, 0, 1))
    >>> rod = der.rod(rest=shape, A1=1.0, A2=1.0)
    """
    x = validate.finite_array(points, "der.shapes.polyline: points", (-1, 3),
                              "a finite array of shape (n_nodes, 3) (the node positions)")
    closed = bool(closed)
    n_edges = x.shape[0] if closed else x.shape[0] - 1
    if n_edges < (3 if closed else 2):
        raise ValueError(f"der.shapes.polyline: points must hold at least {4 if not closed else 3} nodes "
                         f"({'a ring' if closed else 'an open rod'} needs {3 if closed else 2} edges); got "
                         f"{x.shape[0]}")
    if director is None:
        return Shape(x, closed, None)
    d = validate.finite_array(director, "der.shapes.polyline: director", None,
                              f"a finite 3-vector or an array of shape ({n_edges}, 3) (one per edge)")
    if d.shape not in ((3,), (n_edges, 3)):
        raise ValueError(f"der.shapes.polyline: director must be a finite 3-vector or an array of shape ({n_edges}, "
                         f"3) (one per edge); got shape {d.shape}")
    return Shape(x, closed, d, "director")


def _resample_open(curve, total, n):
    """Nodes of an open rod of ``n`` edges on a curve parametrised by arc length s in [0, total] (``curve``
    vectorised; it is evaluated half an edge beyond both ends, where the end-edge nodes lie)."""
    return curve(_open_arclengths(total, n))


def spline(points, n, closed=False):
    """A smooth rest shape through ``points``: a cubic spline (scipy ``CubicSpline``, not-a-knot; periodic for
    a ring), resampled at equal arc-length steps with ``n`` edges.

    The spline is parametrised by the cumulative chord length; its arc length s(u) is integrated accurately
    (Gauss-Legendre on every interval) and inverted, so that the nodes are equally spaced in arc length. An
    open rod's end cross-sections (end-edge midpoints) are the first and last points, its outer nodes half an
    edge beyond them on the spline's extrapolation.

    Parameters
    ----------
    points : (m, 3) array
        Points to pass through, in order (m >= 3; a ring: m >= 4, the first point not repeated).
    n : int
        Number of edges (>= 2 open, >= 3 closed).
    closed : bool
        True for a ring (a periodic spline).

    Returns
    -------
    Shape (material frame on its discrete Frenet frame)

    Example
    -------
    >>> import numpy as np, der
    >>> pts = [[0, 0, 0], [1, 0.5, 0], [2, 0, 0.3], [3, -0.2, 0.5]]
    >>> shape = der.shapes.spline(pts, 40)
    >>> rod = der.rod(rest=shape, start="straight", A1=1.0, A2=1.0)   # curved at rest, straight at start
    """
    from scipy.interpolate import CubicSpline

    P = validate.finite_array(points, "der.shapes.spline: points", (-1, 3),
                              "a finite array of shape (m, 3) (points to pass through)")
    closed = bool(closed)
    n = _check_n(n, 3 if closed else 2, "spline")
    if P.shape[0] < (4 if closed else 3):
        raise ValueError(f"der.shapes.spline: points must hold at least {4 if closed else 3} points; got {P.shape[0]}")
    if closed:
        P = np.vstack([P, P[:1]])
    chord = np.linalg.norm(np.diff(P, axis=0), axis=1)
    if np.any(chord <= 1e-12 * max(1.0, np.abs(P).max())):
        i = int(np.argmin(chord))
        raise ValueError(f"der.shapes.spline: points {i} and {i + 1} coincide; consecutive points must differ")
    u = np.concatenate([[0.0], np.cumsum(chord)])
    cs = CubicSpline(u, P, bc_type="periodic" if closed else "not-a-knot")
    dcs = cs.derivative()
    # arc length at the knots (16-point Gauss-Legendre per interval: exact to round-off for these smooth pieces)
    gx, gw = np.polynomial.legendre.leggauss(16)
    sub = 8
    uu = np.linspace(u[0], u[-1], sub * (len(u) - 1) + 1)
    a, b = uu[:-1], uu[1:]
    nodes = 0.5 * (b - a)[:, None] * gx[None, :] + 0.5 * (a + b)[:, None]
    speed = np.linalg.norm(dcs(nodes.ravel()), axis=1).reshape(nodes.shape)
    s_knots = np.concatenate([[0.0], np.cumsum(0.5 * (b - a) * (speed @ gw))])
    total = s_knots[-1]
    if closed:
        s_target = total * np.arange(n) / n
    else:
        h = total / (n - 1)
        s_target = (np.arange(n + 1) - 0.5) * h
    # invert s(u) by Newton's method from the piecewise-linear guess (extrapolating linearly beyond the ends)
    ut = np.interp(s_target, s_knots, uu)
    lo, hi = s_target < 0, s_target > total
    ut[lo] = u[0] + s_target[lo] / np.linalg.norm(dcs(u[0]))
    ut[hi] = u[-1] + (s_target[hi] - total) / np.linalg.norm(dcs(u[-1]))
    inside = ~(lo | hi)
    for _ in range(30):
        k = np.clip(np.searchsorted(uu, ut[inside]) - 1, 0, len(uu) - 2)
        a0 = uu[k]
        seg = 0.5 * (ut[inside] - a0)[:, None] * gx[None, :] + 0.5 * (ut[inside] + a0)[:, None]
        sp = np.linalg.norm(dcs(seg.ravel()), axis=1).reshape(seg.shape)
        s_now = s_knots[k] + 0.5 * (ut[inside] - a0) * (sp @ gw)
        step = (s_now - s_target[inside]) / np.linalg.norm(dcs(ut[inside]), axis=1)
        ut[inside] -= step
        if np.abs(step).max(initial=0.0) < 1e-15 * total:
            break
    x = cs(ut)
    if closed:
        return Shape(x, True, None)
    # beyond the ends: the spline's own cubic extrapolation, at arc length measured along it to good accuracy
    for idx, sign in ((np.flatnonzero(lo), -1.0), (np.flatnonzero(hi), 1.0)):
        for i in idx:
            u0 = u[0] if sign < 0 else u[-1]
            want = abs(s_target[i] - (0.0 if sign < 0 else total))
            uc = ut[i]
            for _ in range(30):
                g = 0.5 * (uc - u0) * gx + 0.5 * (uc + u0)
                got = abs(0.5 * (uc - u0) * (np.linalg.norm(dcs(g), axis=1) @ gw))
                d = (got - want) / np.linalg.norm(dcs(uc))
                uc -= sign * d
                if abs(d) < 1e-15 * total:
                    break
            x[i] = cs(uc)
    return Shape(x, False, None)


def _profile(value, name, where):
    """A function of arc length from a number or a callable (validated where it is evaluated)."""
    if callable(value):
        return value
    v = validate.finite_number(value, f"der.shapes.{where}: {name}")
    return lambda s: np.full(np.shape(s), v)


def _evaluate(fun, xi, name, where):
    """``fun`` at the arc lengths ``xi`` as a finite float array of xi's shape (called point by point if it is
    not vectorised), or a ValueError naming the argument."""
    where = where if where.startswith("der.") else f"der.shapes.{where}"
    xi = np.asarray(xi, float)
    try:
        out = np.asarray(fun(xi), dtype=float)
        if out.shape != xi.shape:
            out = np.broadcast_to(out, xi.shape).astype(float)
    except Exception:
        try:
            out = np.array([float(fun(float(v))) for v in xi.ravel()]).reshape(xi.shape)
        except Exception as exc:
            raise TypeError(f"{where}: {name} must be a number or a function of the arc length xi "
                            f"returning a real number; calling it failed: {exc}") from None
    if not np.all(np.isfinite(out)):
        i = int(np.argmax(~np.isfinite(out.ravel())))
        raise ValueError(f"{where}: {name} must be finite along the rod; at xi = "
                         f"{xi.ravel()[i]:.6g} it is {out.ravel()[i]}")
    return out


def varying_helix(kappa, omega, length, n):
    """A rest shape of curvature ``kappa(s)`` and torsion ``omega(s)`` varying along the arc length s (a helix
    when both are constant), from the Frenet-Serret equations

        r' = t,   t' = kappa n,   n' = -kappa t + omega b,   b' = -omega n

    integrated with scipy's ``solve_ivp`` (DOP853, rtol 1e-12) from r(0) = 0, t(0) = e3, n(0) = e1, b(0) = e2,
    forwards to L + h/2 and backwards to -h/2 (the outer nodes of an open rod lie half an edge outside [0, L]:
    ``kappa`` and ``omega`` are evaluated there too).

    Parameters
    ----------
    kappa : float or callable
        Curvature (1/length), a number or a function of the arc length s (vectorised or not); >= 0. The rest
        material frame is the discrete Frenet frame of the result (``der.rod`` measures its natural strains).
    omega : float or callable
        Torsion (1/length; > 0 right-handed), a number or a function of s.
    length : float
        Arc length L > 0.
    n : int
        Number of edges, >= 2.

    Returns
    -------
    Shape

    Example
    -------
    >>> import der
    >>> shape = der.shapes.varying_helix(lambda s: 1.0 + 0.5 * s, 0.6, length=4.0, n=80)  # curvature 1 -> 3
    >>> rod = der.rod(rest=shape, A1=1.0, A2=1.5)
    """
    from scipy.integrate import solve_ivp

    n = _check_n(n, 2, "varying_helix")
    length, = _check_positive("varying_helix", length=length)
    kf = _profile(kappa, "kappa", "varying_helix")
    wf = _profile(omega, "omega", "varying_helix")
    s = _open_arclengths(length, n)
    k_nodes = _evaluate(kf, s, "kappa", "varying_helix")
    _evaluate(wf, s, "omega", "varying_helix")
    if np.any(k_nodes < 0):
        i = int(np.argmax(k_nodes < 0))
        raise ValueError(f"der.shapes.varying_helix: kappa must be >= 0 (a curvature); at s = {s[i]:.6g} it is "
                         f"{k_nodes[i]:.6g}")

    def rhs(si, y):
        k = float(_evaluate(kf, si, "kappa", "varying_helix"))
        w = float(_evaluate(wf, si, "omega", "varying_helix"))
        t, nn, b = y[3:6], y[6:9], y[9:12]
        return np.concatenate([t, k * nn, -k * t + w * b, -w * nn])

    y0 = np.concatenate([np.zeros(3), [0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    x = np.empty((n + 1, 3))
    fwd = s >= 0
    for mask, end in ((fwd, s[-1]), (~fwd, s[0])):
        ts = s[mask] if end > 0 else s[mask][::-1]
        sol = solve_ivp(rhs, (0.0, end), y0, method="DOP853", t_eval=ts, rtol=1e-12, atol=1e-12 * length)
        if not sol.success:
            raise ValueError(f"der.shapes.varying_helix: integrating the Frenet equations failed: {sol.message}")
        pts = sol.y[:3].T
        x[mask] = pts if end > 0 else pts[::-1]
    return Shape(x, False, None)


@dataclass(frozen=True)
class Strains:
    """A rest state given by its strains along the arc length (``strains``): what ``der.rod`` builds a rod on
    when no rest shape is given.

    Attributes
    ----------
    length : float
        Rest length L.
    n : int
        Number of edges.
    closed : bool
        True for a ring.
    l_bar : (n,) array
        Rest edge lengths (equal by default: h = L / (n - 1) open, L / n closed).
    xi : (n_vertices,) array
        Rest arc length of each vertex (equal edges, open: h/2, 3h/2, ..., L - h/2; ring: 0, h, ...).
    kappa : (n_vertices, 2) array
        Natural material curvatures (kappa1, kappa2) at the vertices (1/length).
    omega : (n_vertices,) array
        Natural twist rate omega0 at the vertices (1/length; > 0 right-handed).

    Example
    -------
    >>> import der
    >>> rest = der.shapes.strains(length=2.0, n=40, kappa1=lambda s: 1.0 if s < 1.0 else -1.0)
    >>> rest.kappa.shape
    (39, 2)
    """
    length: float
    n: int
    closed: bool
    l_bar: np.ndarray
    xi: np.ndarray
    kappa: np.ndarray
    omega: np.ndarray


def strains(length, n, kappa1=0.0, kappa2=0.0, omega=0.0, closed=False, lengths=None):
    """A rest state given by its natural strains along the arc length: material curvatures kappa1, kappa2 and
    twist omega0, set independently of any shape.

    The material curvatures are components of the rest curvature vector in the material frame: kappa1 = kb . m2
    (curving towards m1) and kappa2 = -kb . m1 (curving towards m2); a rest shape built on its Frenet frame has
    (kappa0, 0). ``der.rod`` turns them into the discrete natural strains of each vertex (integrated: times the
    Voronoi length h, the two edge sides rotated by half the natural twist each way) so that a discrete state of
    exactly these strains exists and is force-free.

    Parameters
    ----------
    length : float
        Rest length L > 0.
    n : int
        Number of edges, >= 2 (>= 3 for a ring).
    kappa1, kappa2, omega : float, callable or array
        Each a number, a function of the rest arc length xi in [0, L] (vectorised or not), or an array with one
        value per vertex (n - 1 open, n closed). 1/length.
    closed : bool
        True for a ring.
    lengths : (n,) array, optional
        Rest edge lengths, > 0 (default: all equal). They must add up to ``length``: for an open rod the sum
        minus half of each end edge (whose midpoints are the ends), for a ring the sum.

    Returns
    -------
    Strains

    Example
    -------
    A "perversion": two halves of opposite natural curvature, relaxed from a straight start.

    >>> import der
    >>> rest = der.shapes.strains(2.0, 40, kappa1=lambda s: 1.0 if s < 1.0 else -1.0)
    >>> rod = der.rod(rest=rest, start="straight", A1=1.0, A2=1.0)
    """
    n = _check_n(n, 3 if closed else 2, "strains")
    length, = _check_positive("strains", length=length)
    closed = bool(closed)
    if lengths is None:
        l_bar = np.full(n, length / (n if closed else n - 1))
    else:
        l_bar = validate.finite_array(lengths, "der.shapes.strains: lengths", (n,),
                                      f"a finite array of shape ({n},) of edge lengths > 0")
        if np.any(l_bar <= 0):
            raise ValueError(f"der.shapes.strains: lengths must be > 0; edge {int(np.argmax(l_bar <= 0))} has "
                             f"{l_bar[l_bar <= 0][0]!r}")
        total = l_bar.sum() if closed else l_bar.sum() - 0.5 * (l_bar[0] + l_bar[-1])
        if abs(total - length) > 1e-12 * length:
            raise ValueError(f"der.shapes.strains: lengths must add up to length = {length!r}"
                             f"{'' if closed else ' (less half of each end edge)'}; they add up to {total!r}")
    nodes = np.concatenate([[0.0], np.cumsum(l_bar)])
    xi = nodes[:n] if closed else nodes[1:n] - 0.5 * l_bar[0]
    nv = xi.size
    out = []
    for name, value in (("kappa1", kappa1), ("kappa2", kappa2), ("omega", omega)):
        if callable(value):
            out.append(_evaluate(value, xi, name, "strains"))
        elif np.ndim(value) == 0 and not isinstance(value, np.ndarray):
            out.append(np.full(nv, validate.finite_number(value, f"der.shapes.strains: {name}")))
        else:
            arr = validate.finite_array(value, f"der.shapes.strains: {name}", None,
                                        f"a number, a function of xi, or an array of shape ({nv},) (one per vertex)")
            if arr.shape != (nv,):
                raise ValueError(f"der.shapes.strains: {name} must be a number, a function of xi, or an array of "
                                 f"shape ({nv},) (one per vertex: {n} edges); got shape {arr.shape}")
            out.append(arr)
    return Strains(float(length), n, closed, l_bar, xi, np.stack(out[:2], axis=1), out[2])
