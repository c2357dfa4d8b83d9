"""Stiffness of one vertex or edge from a uniform value or a per-vertex / per-edge array, inside the kernels.

A rod's stiffnesses reach the energy kernels as given: a float (a uniform rod, every result bitwise as before)
or an array (a rod varying along its length, ``der.rod``). These helpers pick the value at one stencil, so
that the kernels read the same for both:

* ``bending_at(A1, v)``: the two bending stiffnesses ``(A1, A1')`` of vertex v, for the curvature components
  kappa1 = kb . m2 (bending towards m1, about m2) and kappa2 = -kb . m1 (bending towards m2, about m1). ``A1``
  is a float (isotropic, uniform), an (n_vertices,) array (isotropic, varying) or an (n_vertices, 2) array
  (columns A1, A1').
* ``twisting_at(A2, v)``: the twisting stiffness of vertex v (a float or an (n_vertices,) array).

Units: force * length^2 (they are divided by the Voronoi length by the callers).
"""
from numba import types
from numba.extending import overload


def bending_at(A1, v):
    """``(A1, A1')`` of vertex ``v`` (pure-Python version; the kernels use the numba overload below)."""
    import numpy as np

    a = np.asarray(A1, float)
    if a.ndim == 0:
        return float(a), float(a)
    if a.ndim == 1:
        return float(a[v]), float(a[v])
    return float(a[v, 0]), float(a[v, 1])


def twisting_at(A2, v):
    """The twisting stiffness of vertex ``v`` (pure-Python version of the numba overload)."""
    import numpy as np

    a = np.asarray(A2, float)
    return float(a) if a.ndim == 0 else float(a[v])


@overload(bending_at, inline="always")
def _bending_at(A1, v):
    if isinstance(A1, (types.Float, types.Integer)):
        return lambda A1, v: (float(A1), float(A1))
    if isinstance(A1, types.Array) and A1.ndim == 1:
        return lambda A1, v: (A1[v], A1[v])
    if isinstance(A1, types.Array) and A1.ndim == 2:
        return lambda A1, v: (A1[v, 0], A1[v, 1])
    return None


@overload(twisting_at, inline="always")
def _twisting_at(A2, v):
    if isinstance(A2, (types.Float, types.Integer)):
        return lambda A2, v: float(A2)
    if isinstance(A2, types.Array) and A2.ndim == 1:
        return lambda A2, v: A2[v]
    return None
