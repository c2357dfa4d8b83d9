"""Reference solutions of the Kirchhoff rod equations for rods varying along their length (issue 13), from
scipy's ``solve_bvp`` or in closed form. The validation tests and ``scenarios/perversion.py`` compare der with
them; nothing here uses der's discretisation.

Equations (static, no distributed load): with r the centreline, (d1, d2, d3 = t) the material frame, u its
Darboux vector (d_i' = u x d_i), F the internal force and M the internal moment (exerted by the part beyond s
on the part before it),

    r' = d3,   F' = 0,   M' + d3 x F = 0,
    M . d2 = A1 (u . d2 - kappa1_0),   M . d1 = A1' (u . d1 + kappa2_0),   M . d3 = A2 (u . d3 - omega_0)

(der's material curvatures are kappa1 = u . d2, bending towards d1 = m1 about d2, and kappa2 = -u . d1,
bending towards m2 about m1.)

Example
-------
>>> import der.references as ref
>>> round(ref.tapered_tip_deflection(1.0, 1.0, 1.0, 1.0), 12)     # uniform A1 = 1: P L^3 / (3 A1)
0.333333333333
"""
import numpy as np


def tapered_tip_deflection(L, P, A_root, A_tip):
    """Tip deflection of a cantilever (clamped at s = 0) whose bending stiffness varies linearly from ``A_root``
    to ``A_tip``, under a small transverse tip force P (linear theory, unit-load method):

        delta = P int_0^L (L - s)^2 / A1(s) ds,   A1(s) = a + b s   (a = A_root, b = (A_tip - A_root) / L)
              = P / b^3 [c^2 ln(c / a) - 2 c (c - a) + (c^2 - a^2) / 2],   c = A_tip

    (P L^3 / (3 A1) when A_tip = A_root). Length units of P L^3 / A1.

    Example
    -------
    >>> import der.references as ref
    >>> round(float(ref.tapered_tip_deflection(1.0, 1.0, 2.0, 1.0)), 6)    # int (1 - s)^2 / (2 - s) = ln 2 - 1/2
    0.193147
    """
    a, c = float(A_root), float(A_tip)
    if abs(c - a) <= 1e-6 * a:
        # the series of the closed form about b = 0 (it loses digits there): P L^3 / 3 (1/a - b L / (4 a^2) ...)
        b = (c - a) / L
        return P * L ** 3 * (1.0 / (3 * a) - b * L / (12 * a * a) + (b * L) ** 2 / (30 * a ** 3))
    b = (c - a) / L
    return float(P / b ** 3 * (c * c * np.log(c / a) - 2 * c * (c - a) + 0.5 * (c * c - a * a)))


def anisotropic_cantilever_linear(L, P, A1, A1prime):
    """Tip deflection (d1, d2 components) of a straight cantilever along d3 under a small tip force P = (P1, P2)
    in the cross-section's principal axes (d1, d2): ``(P1 L^3 / (3 A1), P2 L^3 / (3 A1'))``.

    Example
    -------
    >>> import der.references as ref
    >>> ref.anisotropic_cantilever_linear(1.0, (3.0, 3.0), 1.0, 10.0)
    (1.0, 0.1)
    """
    return P[0] * L ** 3 / (3.0 * A1), P[1] * L ** 3 / (3.0 * A1prime)


def _frame_rhs(y, A1, A1p, A2, F):
    """d/ds of (r, d1, d2, d3, M) for a naturally straight rod under the constant internal force F."""
    d1, d2, d3, M = y[3:6], y[6:9], y[9:12], y[12:15]
    u1 = np.einsum("i...,i...->...", M, d1) / A1p
    u2 = np.einsum("i...,i...->...", M, d2) / A1
    u3 = np.einsum("i...,i...->...", M, d3) / A2
    u = u1 * d1 + u2 * d2 + u3 * d3
    F = np.asarray(F, float).reshape(3, *([1] * (y.ndim - 1)))
    return np.concatenate([d3, np.cross(u, d1, axis=0), np.cross(u, d2, axis=0), np.cross(u, d3, axis=0),
                           -np.cross(d3, np.broadcast_to(F, d3.shape), axis=0)])


def anisotropic_cantilever(L, F, A1, A1prime, A2, tol=1e-10, nodes=201):
    """Large-deflection cantilever: clamped at s = 0 with (d1, d2, d3) = (e1, e2, e3), naturally straight,
    dead tip force ``F`` (lab frame) at s = L; ``solve_bvp`` on (r, d1, d2, d3, M) (15 unknowns; the frame
    stays orthonormal, checked), continued in the load from zero.

    Returns ``sol`` (scipy's result; ``sol.sol(s)[:3]`` is r(s)). Raises RuntimeError if it does not converge.

    Example
    -------
    >>> import der.references as ref
    >>> sol = ref.anisotropic_cantilever(1.0, (1e-3, 0, 0), 1.0, 10.0, 1.0)
    >>> round(float(sol.sol(1.0)[0]) / (1e-3 / 3), 4)
    1.0
    """
    from scipy.integrate import solve_bvp

    F = np.asarray(F, float)
    s = np.linspace(0.0, L, nodes)
    y = np.zeros((15, s.size))
    y[2] = s
    y[3], y[7], y[11] = 1.0, 1.0, 1.0
    e = np.eye(3)

    def bc(ya, yb):
        return np.concatenate([ya[:3], ya[3:6] - e[0], ya[6:9] - e[1], ya[9:12] - e[2], yb[12:15]])

    sol = None
    for frac in np.linspace(0.0, 1.0, 11)[1:]:
        Fi = frac * F
        sol = solve_bvp(lambda x, yy: _frame_rhs(yy, A1, A1prime, A2, Fi), bc, s, y, tol=tol, max_nodes=100000)
        if not sol.success:
            raise RuntimeError(f"anisotropic_cantilever: solve_bvp failed at {frac:.1f} of the load: {sol.message}")
        s, y = sol.x, sol.y
    frame = sol.y[3:12].reshape(3, 3, -1)
    if np.abs(np.einsum("ik...,jk...->ij...", frame, frame) - np.eye(3)[:, :, None]).max() > 1e-7:
        raise RuntimeError("anisotropic_cantilever: the frame drifted from orthonormal")
    return sol


def perversion(L, kappa0, A1, P, tol=1e-10, nodes=201):
    """A planar "perversion": a rod of length L (naturally curved with material curvature kappa1 = +kappa0 on
    [0, L/2) and -kappa0 on (L/2, L], towards m1 = e1; kappa2 = omega0 = 0) clamped at s = 0 with its tangent
    along e3, its other end clamped parallel (tangent e3, no rotation) but free to slide along e3, pulled by a
    force P along e3 there.

    Planar Kirchhoff equations in the (e1, e3) plane, with theta the angle of the tangent from e3 towards e1:

        x' = sin theta,  z' = cos theta,  theta' = kappa0(s) + M / A1,  M' = P sin theta - Fx cos theta

    (M the moment about e2, Fx the unknown transverse reaction at the sliding end); boundary conditions
    x = z = theta = 0 at s = 0, theta = x = 0 at s = L. The step in kappa0 is handled by solving the two
    halves as one system of 8 equations on [0, L/2] joined continuously at the middle (``solve_bvp``).

    Returns ``(positions, Fx, M0)``: a function s -> (x(s), z(s)) for s in [0, L], the reaction Fx and the
    clamp moment M(0). Raises RuntimeError if solve_bvp fails.

    Example
    -------
    >>> import der.references as ref
    >>> pos, Fx, M0 = ref.perversion(2.0, 1.0, 1.0, 0.0)     # no pull: only the end moments hold it
    >>> round(abs(float(pos(2.0)[0])), 8)
    0.0
    """
    from scipy.integrate import solve_bvp

    h = 0.5 * L

    def rhs(s, y, p):
        Fx = p[0]
        out = np.empty_like(y)
        for k, sign in ((0, 1.0), (4, -1.0)):
            th, M = y[k + 2], y[k + 3]
            out[k] = np.sin(th)
            out[k + 1] = np.cos(th)
            out[k + 2] = sign * kappa0 + M / A1
            out[k + 3] = P * np.sin(th) - Fx * np.cos(th)
        return out

    def bc(ya, yb, p):
        return np.array([ya[0], ya[1], ya[2],                           # clamped at s = 0
                         yb[0] - ya[4], yb[1] - ya[5], yb[2] - ya[6], yb[3] - ya[7],   # continuity at L/2
                         yb[6], yb[4]])                                 # theta = x = 0 at s = L

    s = np.linspace(0.0, h, nodes)
    # start from the rod's natural shape (the first half curving towards e1, the second back)
    th1 = kappa0 * s * (1 - s / h)
    y = np.zeros((8, s.size))
    y[2] = th1
    y[6] = -kappa0 * s * (1 - s / h)
    y[1] = s
    y[5] = h + s
    sol = solve_bvp(rhs, bc, s, y, p=[0.0], tol=tol, max_nodes=200000)
    if not sol.success:
        raise RuntimeError(f"perversion: solve_bvp failed: {sol.message}")

    def positions(si):
        si = np.asarray(si, float)
        first = si <= h
        out = np.empty((2,) + si.shape)
        a = sol.sol(np.where(first, si, h))
        b = sol.sol(np.where(first, 0.0, si - h))
        out[0] = np.where(first, a[0], b[4])
        out[1] = np.where(first, a[1], b[5])
        return out

    return positions, float(sol.p[0]), float(sol.sol(0.0)[3])
