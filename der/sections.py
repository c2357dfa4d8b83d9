"""Stiffnesses of a rod from its material and cross-section: A1, A1', A2 and EA.

For Young's modulus E and shear modulus G (or Poisson's ratio nu, G = E / (2 (1 + nu))) and a cross-section
with area A, second moments of area I1 (about m2: what bending towards m1, the material curvature kappa1,
strains) and I2 (about m1, for kappa2) and torsion constant J:

    A1 = E I1,   A1' = E I2,   A2 = G J,   EA = E A

Cross-sections (the first dimension along m1, the second along m2):

* circle of radius r:             A = pi r^2,  I1 = I2 = pi r^4 / 4,  J = pi r^4 / 2
* annulus, radii r_in < r_out:    A = pi (r_out^2 - r_in^2),  I1 = I2 = pi (r_out^4 - r_in^4) / 4,  J = 2 I1
* ellipse, semi-axes a (m1), b (m2): A = pi a b,  I1 = pi a^3 b / 4,  I2 = pi a b^3 / 4,
                                  J = pi a^3 b^3 / (a^2 + b^2)   (Saint-Venant, exact)
* rectangle, sides a (m1), b (m2): A = a b,  I1 = b a^3 / 12,  I2 = a b^3 / 12, and with c >= d the longer and
  the shorter side the Saint-Venant series (Timoshenko & Goodier, Theory of Elasticity, Sec. 109)

      J = c d^3 [1/3 - (64 / pi^5) (d / c) sum_{k = 1, 3, 5, ...} tanh(k pi c / (2 d)) / k^5]

  summed until the terms fall below 1e-16 of the total (J = 0.1406 a^4 for a square, c d^3 / 3 for a thin strip).

Every function takes numbers or arrays (a section varying along the rod: one value per vertex, e.g. a taper)
and returns a ``Section``; ``der.rod(rest, **section.stiffness())`` builds a rod with it.

Units: lengths L, moduli force / L^2; A1, A1', A2 in force * L^2, EA in force.

Example
-------
>>> import der
>>> s = der.sections.rectangle(0.02, 0.002, E=200e9, nu=0.3)      # a steel strip 20 mm x 2 mm
>>> round(s.A1prime / s.A1, 6)                                   # 100 times softer across its width
0.01
"""
from dataclasses import dataclass

import numpy as np

from . import validate


@dataclass(frozen=True)
class Section:
    """The stiffnesses of a cross-section (floats, or arrays for a section varying along the rod).

    Attributes
    ----------
    A1 : float or array
        Bending stiffness E I1 for the material curvature kappa1 (bending towards m1, about m2), force * L^2.
    A1prime : float or array
        Bending stiffness E I2 for kappa2 (bending towards m2, about m1), force * L^2.
    A2 : float or array
        Twisting stiffness G J, force * L^2.
    EA : float or array
        Axial stiffness, force.

    Example
    -------
    >>> import der
    >>> s = der.sections.circle(0.5, E=1.0, G=1.0)
    >>> round(s.A1, 6), round(s.A2, 6)
    (0.049087, 0.098175)
    """
    A1: float | np.ndarray
    A1prime: float | np.ndarray
    A2: float | np.ndarray
    EA: float | np.ndarray

    def stiffness(self, extensible=True):
        """Keyword arguments for ``der.rod``: A1, A1prime (None where A1' = A1, an isotropic rod), A2 and EA
        (None with ``extensible=False``: an inextensible rod).

        Example
        -------
        >>> import der
        >>> r = der.rod(rest=der.shapes.straight(1.0, 20), **der.sections.ellipse(0.1, 0.05, E=1e3, nu=0.5).stiffness())
        """
        iso = np.array_equal(np.asarray(self.A1), np.asarray(self.A1prime))
        return {"A1": self.A1, "A1prime": None if iso else self.A1prime, "A2": self.A2,
                "EA": self.EA if extensible else None}


def _moduli(E, G, nu, where):
    E = _positive(E, f"der.sections.{where}: E", "Young's modulus")
    if (G is None) == (nu is None):
        raise ValueError(f"der.sections.{where}: give exactly one of G (shear modulus) and nu (Poisson's ratio); got "
                         f"G={G!r}, nu={nu!r}")
    if G is not None:
        return E, _positive(G, f"der.sections.{where}: G", "shear modulus")
    nu = validate.finite_number(nu, f"der.sections.{where}: nu")
    if not -1.0 < nu <= 0.5:
        raise ValueError(f"der.sections.{where}: nu (Poisson's ratio) must be in (-1, 0.5]; got {nu!r}")
    return E, E / (2.0 * (1.0 + nu))


def _positive(value, name, what):
    if np.ndim(value) == 0 and not isinstance(value, np.ndarray):
        return validate.positive_number(value, name, f"a finite number > 0 ({what})")
    arr = validate.finite_array(value, name, (-1,), f"a finite number > 0 ({what}) or a 1-d array of them")
    if np.any(arr <= 0):
        raise ValueError(f"{name} must be > 0 ({what}); entry {int(np.argmax(arr <= 0))} is {arr[arr <= 0][0]!r}")
    return arr


def circle(radius, E, G=None, nu=None):
    """A solid circular section of ``radius`` (isotropic: A1' = A1; the paper's rod).

    Parameters
    ----------
    radius : float or array
        Radius r > 0 (length); an array gives one value per vertex (a taper).
    E : float
        Young's modulus (force / length^2), > 0.
    G, nu : float
        Shear modulus (> 0) or Poisson's ratio (in (-1, 0.5]); exactly one.

    Returns
    -------
    Section: A1 = A1' = E pi r^4 / 4, A2 = G pi r^4 / 2, EA = E pi r^2.

    Example
    -------
    >>> import der
    >>> s = der.sections.circle(1.0, E=4.0 / 3.14159265358979, nu=0.5)
    >>> round(s.A1, 6), round(s.A1 / s.A2, 6)        # A1 / A2 = 1 + nu for a circle
    (1.0, 1.5)
    """
    E, G = _moduli(E, G, nu, "circle")
    r = _positive(radius, "der.sections.circle: radius", "length")
    i = np.pi * r ** 4 / 4.0
    return Section(E * i, E * i, G * 2.0 * i, E * np.pi * r ** 2)


def annulus(r_out, r_in, E, G=None, nu=None):
    """A hollow circular section (a tube) of outer radius ``r_out`` and inner radius ``r_in`` < ``r_out``.

    Parameters
    ----------
    r_out, r_in : float or array
        Outer and inner radius (length), 0 < r_in < r_out.
    E : float
        Young's modulus (force / length^2).
    G, nu : float
        Shear modulus or Poisson's ratio; exactly one.

    Returns
    -------
    Section: A1 = A1' = E pi (r_out^4 - r_in^4) / 4, A2 = 2 G I, EA = E pi (r_out^2 - r_in^2).

    Example
    -------
    >>> import der
    >>> s = der.sections.annulus(1.0, 0.9, E=1.0, G=0.4)
    """
    E, G = _moduli(E, G, nu, "annulus")
    ro = _positive(r_out, "der.sections.annulus: r_out", "length")
    ri = _positive(r_in, "der.sections.annulus: r_in", "length")
    if np.any(np.asarray(ri) >= np.asarray(ro)):
        raise ValueError(f"der.sections.annulus: r_in must be < r_out; got r_in={r_in!r}, r_out={r_out!r}")
    i = np.pi * (ro ** 4 - ri ** 4) / 4.0
    return Section(E * i, E * i, G * 2.0 * i, E * np.pi * (ro ** 2 - ri ** 2))


def ellipse(a, b, E, G=None, nu=None):
    """An elliptical section with semi-axis ``a`` along m1 and ``b`` along m2.

    Parameters
    ----------
    a, b : float or array
        Semi-axes (length), > 0.
    E : float
        Young's modulus (force / length^2).
    G, nu : float
        Shear modulus or Poisson's ratio; exactly one.

    Returns
    -------
    Section: A1 = E pi a^3 b / 4 (bending towards m1), A1' = E pi a b^3 / 4, A2 = G pi a^3 b^3 / (a^2 + b^2),
    EA = E pi a b.

    Example
    -------
    >>> import der
    >>> s = der.sections.ellipse(2.0, 1.0, E=1.0, G=1.0)
    >>> round(s.A1 / s.A1prime, 6)
    4.0
    """
    E, G = _moduli(E, G, nu, "ellipse")
    a = _positive(a, "der.sections.ellipse: a", "semi-axis along m1, length")
    b = _positive(b, "der.sections.ellipse: b", "semi-axis along m2, length")
    return Section(E * np.pi * a ** 3 * b / 4.0, E * np.pi * a * b ** 3 / 4.0,
                   G * np.pi * a ** 3 * b ** 3 / (a ** 2 + b ** 2), E * np.pi * a * b)


def rectangle_torsion_constant(c, d):
    """Saint-Venant torsion constant of a c x d rectangle (any order of the sides; length^4):

        J = c d^3 [1/3 - (64 / pi^5) (d / c) sum_{k odd} tanh(k pi c / (2 d)) / k^5],   c >= d

    Example
    -------
    >>> import der
    >>> round(float(der.sections.rectangle_torsion_constant(1.0, 1.0)), 5)     # a square: 0.1406 a^4
    0.14058
    """
    c, d = np.maximum(c, d), np.minimum(c, d)
    total = np.zeros(np.shape(c))
    for k in range(1, 400, 2):
        term = np.tanh(k * np.pi * c / (2.0 * d)) / k ** 5
        total = total + term
        if np.all(term < 1e-16 * total):
            break
    out = c * d ** 3 * (1.0 / 3.0 - 64.0 / np.pi ** 5 * (d / c) * total)
    return float(out) if np.ndim(out) == 0 else out


def rectangle(a, b, E, G=None, nu=None):
    """A rectangular section with side ``a`` along m1 and ``b`` along m2 (a ribbon or strip when a >> b).

    Parameters
    ----------
    a, b : float or array
        Sides (length), > 0.
    E : float
        Young's modulus (force / length^2).
    G, nu : float
        Shear modulus or Poisson's ratio; exactly one.

    Returns
    -------
    Section: A1 = E b a^3 / 12 (bending towards m1, across the side a), A1' = E a b^3 / 12, A2 = G J with J from
    ``rectangle_torsion_constant``, EA = E a b.

    Example
    -------
    >>> import der
    >>> s = der.sections.rectangle(1.0, 0.1, E=12.0, G=1.0)
    >>> round(s.A1, 6), round(s.A1prime, 6)
    (0.1, 0.001)
    """
    E, G = _moduli(E, G, nu, "rectangle")
    a = _positive(a, "der.sections.rectangle: a", "side along m1, length")
    b = _positive(b, "der.sections.rectangle: b", "side along m2, length")
    return Section(E * b * a ** 3 / 12.0, E * a * b ** 3 / 12.0, G * rectangle_torsion_constant(a, b), E * a * b)
