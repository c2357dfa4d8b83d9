"""Closed forms for the paper's examples: the paper's formulas (``paper_*``) and the correct ones.

Derivations: ``docs/derivations.md``. Conventions as everywhere in der: right-handed Frenet frame (t, n, b),
alpha is the angle from n to m1 about t, M and F are the moment and force exerted by the part beyond xi on the
part before it (at a free end: the applied load), a positive moment about t over-twists, and the helix is
right-handed for omega0 > 0. Only numpy.

Sections: loop twist (Sec. 6.1), torsion of a disconnected ring (6.2), helix under tension and torque
(6.3.1), elongation and winding of a helix (6.3.2).
"""
import numpy as np

# ---------------------------------------------------------------------------------------------------------
# 6.1 Twist of a closed loop: planar ring of radius a0 under a follower twisting moment m_t per unit length
# ---------------------------------------------------------------------------------------------------------


def loop_alpha(mt, A1, a0):
    """Paper Eq. 40 (correct): the uniform twist angle of the planar loop, sin(alpha) = m_t a0^2 / A1 [rad].

    NaN beyond the fold |m_t| > A1 / a0^2, where no planar equilibrium exists."""
    s = np.asarray(mt, float) * a0 ** 2 / A1
    with np.errstate(invalid="ignore"):
        return np.where(np.abs(s) <= 1.0, np.arcsin(np.clip(s, -1, 1)), np.nan)


def loop_fold(A1, a0):
    """The fold of the planar branch, m_t = A1 / a0^2 (alpha = pi/2)."""
    return A1 / a0 ** 2


def michell_twist(A1, A2):
    """Michell's threshold (1889; Zajac 1962): a naturally straight rod closed into a planar ring with total
    twist Tw (radians, uniform) stays a stable planar ring while Tw < 2 pi sqrt(3) A1 / A2."""
    return 2.0 * np.pi * np.sqrt(3.0) * A1 / A2


def loop_threshold(A1, A2, a0):
    """(m_t, mode) where the planar loop stops being stable (linear stability with the follower load).

    Fourier mode k >= 2 of the out-of-plane perturbation diverges when cos(alpha) = (A - k^2) / (A - 1), A = A1/A2;
    mode 2 comes first and only for A > 4, at m_t a0^2 / A1 = sqrt(3 (2A - 5)) / (A - 1). For A <= 4 the planar
    ring is stable up to the fold (mode 0, the uniform twist). No flutter. (docs/derivations.md, 6.1)
    """
    A = A1 / A2
    if A <= 4.0:
        return loop_fold(A1, a0), 0
    return np.sqrt(3.0 * (2.0 * A - 5.0)) / (A - 1.0) * A1 / a0 ** 2, 2


# ---------------------------------------------------------------------------------------------------------
# 6.2 Torsion of a disconnected ring: arc of radius a0, length L, clamped at 0, torque T about t at L
# Linear in T (dead and follower torques agree at this order). q = k (L - xi), p = k L, k = 1/a0.
# Vector components in the rest end basis (t0(L), n0(L), b0).
# ---------------------------------------------------------------------------------------------------------


def ring_alpha(xi, A1, A2, a0, L, T):
    """alpha(xi) = T sin(k (L - xi)) / (A1 k): M_n = A1 k alpha carries the transported end torque."""
    k = 1.0 / a0
    return T * np.sin(k * (L - np.asarray(xi, float))) / (A1 * k)


def ring_omega(xi, A1, A2, a0, L, T):
    """Geometric torsion omega(xi) = T (1/A1 + 1/A2) cos(k (L - xi))."""
    k = 1.0 / a0
    return T * (1.0 / A1 + 1.0 / A2) * np.cos(k * (L - np.asarray(xi, float)))


def ring_twist(xi, A1, A2, a0, L, T):
    """Material twist alpha' + omega = M_t / A2 = T cos(k (L - xi)) / A2."""
    k = 1.0 / a0
    return T * np.cos(k * (L - np.asarray(xi, float))) / A2


def ring_kappa(xi, A1, A2, a0, L, T):
    """kappa = kappa0 to first order in T (M_b = 0)."""
    return np.full_like(np.asarray(xi, float), 1.0 / a0)


def ring_moments(xi, A1, A2, a0, L, T):
    """(M_n, M_b, M_t) = (T sin q, 0, T cos q): the constant moment vector T t0(L) on the Frenet frame at xi."""
    q = (L - np.asarray(xi, float)) / a0
    return T * np.sin(q), np.zeros_like(q), T * np.cos(q)


def ring_end_rotation(A1, A2, a0, L, T):
    """Rotation vector of the end material frame [rad], components (t, n, b) in the rest end basis."""
    k, p = 1.0 / a0, L / a0
    return np.array([T * (0.5 * L * (1 / A1 + 1 / A2) + (1 / A2 - 1 / A1) * np.sin(2 * p) / (4 * k)),
                     T * (1 / A1 - 1 / A2) * np.sin(p) ** 2 / (2 * k),
                     0.0])


def ring_end_displacement(A1, A2, a0, L, T):
    """Displacement of the end [length], components (t, n, b) in the rest end basis: out of plane only."""
    k, p = 1.0 / a0, L / a0
    return np.array([0.0, 0.0, T * (4 * A1 * np.sin(p) - A1 * np.sin(2 * p) + A2 * np.sin(2 * p) - 2 * (A1 + A2) * p)
                     / (4 * A1 * A2 * k ** 2)])


def ring_end_basis(a0, L):
    """(t0(L), n0(L), b0) of the arc R0 = a0 (sin(xi/a0), 1 - cos(xi/a0), 0) (der.shapes.arc)."""
    p = L / a0
    return np.array([[np.cos(p), np.sin(p), 0.0], [-np.sin(p), np.cos(p), 0.0], [0.0, 0.0, 1.0]])


def paper_ring_alpha(xi, A1, A2, a0, L, T):
    """Paper Eq. 47: alpha = T sin(kappa0 xi) / (A2 kappa0) (wrong boundary conditions, see the derivations)."""
    k = 1.0 / a0
    return T * np.sin(k * np.asarray(xi, float)) / (A2 * k)


def paper_ring_omega(xi, A1, A2, a0, L, T):
    """Paper Eq. 47: omega = T (A1 + A2) (1 - cos(kappa0 xi)) / A2^2."""
    k = 1.0 / a0
    return T * (A1 + A2) * (1 - np.cos(k * np.asarray(xi, float))) / A2 ** 2


# ---------------------------------------------------------------------------------------------------------
# 6.3.1 Helix under tension and torque: one turn, clamped at 0; at l a dead axial force with F_t = P and a
# follower torque T. Linear in P and T, which are independent (the paper's Eq. 71 is an artefact).
# ---------------------------------------------------------------------------------------------------------


def helix_end_force(kappa0, omega0, P):
    """The dead axial end force with tangential component P: (P sqrt(kappa0^2 + omega0^2) / omega0) e3.

    Its Frenet components are F_t = P, F_n = 0, F_b = P kappa0 / omega0 (the binormal part the paper drops)."""
    return np.array([0.0, 0.0, P * np.hypot(kappa0, omega0) / omega0])


def helix_profiles(xi, A1, A2, kappa0, omega0, P, T):
    """Correct linear profiles (dict of arrays): Mn, Mb, Mt, Ft, Fn, Fb, dalpha, dkappa, domega, dtwist.

    With lam = sqrt(kappa0^2 + omega0^2), phi = lam xi and D = P/omega0 - T (statics: M(xi) = T t(l) +
    (R(l) - R(xi)) x F_end on the rest helix):
        Mn = (kappa0/lam) D sin(phi),  Mb = -(kappa0 omega0/lam^2) D (1 - cos phi),
        Mt = T + (kappa0^2/lam^2) D (1 - cos phi),  F = (P, 0, P kappa0/omega0) in (t, n, b),
        dalpha = Mn/(A1 kappa0),  dkappa = Mb/A1,  dtwist = Mt/A2,  domega = Mt/A2 - D cos(phi)/A1.
    """
    xi = np.asarray(xi, float)
    lam = np.hypot(kappa0, omega0)
    ph = lam * xi
    D = P / omega0 - T
    Mn = kappa0 / lam * D * np.sin(ph)
    Mb = -kappa0 * omega0 / lam ** 2 * D * (1 - np.cos(ph))
    Mt = T + kappa0 ** 2 / lam ** 2 * D * (1 - np.cos(ph))
    one = np.ones_like(ph)
    return {"Mn": Mn, "Mb": Mb, "Mt": Mt, "Ft": P * one, "Fn": 0.0 * one, "Fb": P * kappa0 / omega0 * one,
            "dalpha": Mn / (A1 * kappa0), "dkappa": Mb / A1, "domega": Mt / A2 - D * np.cos(ph) / A1,
            "dtwist": Mt / A2}


def paper_helix_P(A1, A2, omega0, T):
    """Paper Eq. 71: the only P its solution allows, P = T omega0 (1 + A1/A2)."""
    return T * omega0 * (1 + A1 / A2)


def paper_helix_profiles(xi, A1, A2, kappa0, omega0, P, T):
    """Paper Eqs. 66-70 with its ansatz omega = omega0 (Eq. 53); P is fixed by Eq. 71 and not used."""
    xi = np.asarray(xi, float)
    lam = np.hypot(kappa0, omega0)
    ph = lam * xi
    A = A1 / A2
    c1 = A1 * T * kappa0 / (A2 * lam)
    Mn = c1 * np.sin(ph)
    Mt = T * np.cos(ph)
    dkappa = -T * kappa0 * omega0 / (A2 * lam ** 2) * (1 - np.cos(ph))
    Mb = A1 * dkappa
    Ft = T * omega0 * ((1 + A * (1 + omega0 ** 2 / lam ** 2)) * np.cos(ph) - A * omega0 ** 2 / lam ** 2)
    return {"Mn": Mn, "Mb": Mb, "Mt": Mt, "Ft": Ft, "Fn": 0.0 * ph, "Fb": c1 * lam * np.cos(ph) + kappa0 * Mt
            - omega0 * Mb, "dalpha": T * np.sin(ph) / (A2 * lam), "dkappa": dkappa, "domega": 0.0 * ph,
            "dtwist": T * np.cos(ph) / A2}


# ---------------------------------------------------------------------------------------------------------
# 6.3.2 Elongation and winding of a helix: uniform helix to uniform helix (alpha = 0 is forced).
# lam = omega0/kappa0, A = A1/A2, eta = axial elongation, phi = overtwist, c = 1 + phi,
# r = sqrt(1 + lam^2 (1 - eta^2)); P0 = P / (A2 omega0^2), T0 = T / (A2 omega0).
# ---------------------------------------------------------------------------------------------------------


def winding_eta_max(lam):
    """Elongation at which the helix becomes straight, sqrt(1 + 1/lam^2)."""
    return np.sqrt(1.0 + 1.0 / np.asarray(lam, float) ** 2)


def winding_geometry(eta, phi, lam, kappa0=1.0):
    """Deformed helix: dict with kappa, omega (1/length), S = |Darboux vector| (rotation rate about the axis),
    S1 = t . e3 (sine of the pitch angle) and the radius a."""
    eta, phi, lam = (np.asarray(v, float) for v in (eta, phi, lam))
    c = 1.0 + phi
    r = np.sqrt(1.0 + lam ** 2 * (1.0 - eta ** 2))
    kappa = kappa0 * c * r
    omega = kappa0 * lam * c * eta
    S = kappa0 * c * np.sqrt(1.0 + lam ** 2)
    return {"kappa": kappa, "omega": omega, "S": S, "S1": eta * lam / np.sqrt(1.0 + lam ** 2), "a": kappa / S ** 2}


def winding_P0(eta, phi, lam, A):
    """Corrected Eq. 81 (F_t = P S1, not P / S1):
    P0 = c sqrt(1 + lam^2) / lam [c eta - 1 - A eta (c - 1/r)] (P > 0 is tension)."""
    eta, phi, lam, A = (np.asarray(v, float) for v in (eta, phi, lam, A))
    c = 1.0 + phi
    r = np.sqrt(1.0 + lam ** 2 * (1.0 - eta ** 2))
    return c * np.sqrt(1.0 + lam ** 2) / lam * (c * eta - 1.0 - A * eta * (c - 1.0 / r))


def paper_winding_P0(eta, phi, lam, A):
    """Paper Eq. 81 as printed: lam c eta^2 / sqrt(1 + lam^2) [same bracket] = S1^2 times the correct P0."""
    eta, phi, lam, A = (np.asarray(v, float) for v in (eta, phi, lam, A))
    c = 1.0 + phi
    r = np.sqrt(1.0 + lam ** 2 * (1.0 - eta ** 2))
    return lam * c * eta ** 2 / np.sqrt(1.0 + lam ** 2) * (c * eta - 1.0 - A * eta * (c - 1.0 / r))


def winding_T0(eta, phi, lam, A):
    """Axial torque T0 = T/(A2 omega0), T = M . e3 = (omega M_t + kappa M_b)/S:
    [lam^2 eta (c eta - 1) + A r (c r - 1)] / (lam sqrt(1 + lam^2)); positive winds the helix further."""
    eta, phi, lam, A = (np.asarray(v, float) for v in (eta, phi, lam, A))
    c = 1.0 + phi
    r = np.sqrt(1.0 + lam ** 2 * (1.0 - eta ** 2))
    return (lam ** 2 * eta * (c * eta - 1.0) + A * r * (c * r - 1.0)) / (lam * np.sqrt(1.0 + lam ** 2))


def winding_eta(P0, phi, lam, A, corrected=True):
    """eta at a given force P0 and overtwist phi: the largest root on [0, eta_max), the tension branch that
    holds the rest state and runs to the straight rod. NaN if there is none."""
    f = winding_P0 if corrected else paper_winding_P0
    em = float(winding_eta_max(lam))
    grid = np.append(np.linspace(0.0, em, 4001)[:-1], em * (1 - 1e-12))
    g = f(grid, phi, lam, A) - P0
    idx = np.nonzero((g[:-1] <= 0.0) & (g[1:] > 0.0))[0]
    if idx.size == 0:
        return float("nan")
    lo, hi = grid[idx[-1]], grid[idx[-1] + 1]
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if (f(mid, phi, lam, A) - P0) <= 0.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
