"""The discrete energy converges to the paper's continuum energy (Eq. 17) at second order (issue 2)."""
import numpy as np
from scipy.integrate import quad, solve_ivp

import der
from der.energies.bend import bend_energy
from der.energies.twist import twist_energy
from der.geometry import edge_frames, reference_twist_angle, tangents

A1, A2 = 1.3, 0.8
KAPPA0, OMEGA0 = 1.0, 0.6
L = 5.0


def kappa(s):
    return KAPPA0 * (1.0 + 0.3 * np.sin(2 * np.pi * s / L))


def omega(s):
    return OMEGA0 + 0.4 * np.cos(2 * np.pi * s / L)


def alpha(s):
    return 0.2 + 0.5 * np.sin(3 * np.pi * s / L)


def alpha_prime(s):
    return 0.5 * 3 * np.pi / L * np.cos(3 * np.pi * s / L)


def continuum_energy():
    """Integral of Eq. 17 over [0, L] (independent of the discrete code)."""
    def U(s):
        k, a = kappa(s), alpha(s)
        return 0.5 * (A1 * (k * k - 2 * k * KAPPA0 * np.cos(a) + KAPPA0 ** 2)
                      + A2 * (alpha_prime(s) + omega(s) - OMEGA0) ** 2)
    return quad(U, 0, L, epsabs=1e-14, epsrel=1e-13, limit=400)[0]


def frenet_curve():
    """Integrate Frenet-Serret for kappa(s), omega(s): returns a dense solution of (R, t, n, b)."""
    def rhs(s, y):
        t, n, b = y[3:6], y[6:9], y[9:12]
        k, w = kappa(s), omega(s)
        return np.concatenate([t, k * n, -k * t + w * b, -w * n])
    y0 = np.concatenate([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]).astype(float)
    return solve_ivp(rhs, (-1.0, L + 1.0), y0, method="DOP853", rtol=1e-13, atol=1e-14, dense_output=True)


def discrete_energy(curve, n):
    rod = der.rod_from_shape(der.shapes.helix(KAPPA0, OMEGA0, L * np.hypot(KAPPA0, OMEGA0) / (2 * np.pi), n),
                             A1, A2)
    xi = rod.xi_nodes
    y = curve.sol(xi)
    state = rod.rest_state()
    state.positions[:] = y[0:3].T
    state.theta[:] = 0.0
    t = tangents(state.q, rod.edge_nodes)
    ym = curve.sol(rod.xi_edges)
    nrm, bin_ = ym[6:9].T, ym[9:12].T
    a = alpha(rod.xi_edges)[:, None]
    m1 = np.cos(a) * nrm + np.sin(a) * bin_
    m1 -= np.einsum("ij,ij->i", m1, t)[:, None] * t
    m1 /= np.linalg.norm(m1, axis=1)[:, None]
    ref = np.array([reference_twist_angle(t[e], m1[e], t[f], m1[f]) for e, f in rod.vertex_edges])
    ed = edge_frames(state.q, rod.edge_nodes, m1)
    kappa_bar = rod.natural_curvature_edges().reshape(-1, 4)
    return (bend_energy(ed, rod.vertex_edges, rod.weld, kappa_bar, rod.voronoi, A1)
            + twist_energy(state.q, rod.vertex_edges, ref, rod.weld, rod.twist_bar, rod.voronoi, A2))


def fitted_order(ns, errors):
    return -np.polyfit(np.log(ns), np.log(errors), 1)[0]


def test_discrete_energy_converges_to_eq17_at_second_order():
    curve = frenet_curve()
    exact = continuum_energy()
    ns = np.array([20, 40, 80, 160])
    errors = np.array([abs(discrete_energy(curve, n) - exact) / exact for n in ns])
    assert errors[-1] < 1e-3
    assert fitted_order(ns, errors) >= 1.8


def test_uniform_rotation_of_a_curved_ring_costs_A1_kappa0_squared_one_minus_cos_alpha():
    a0, alpha_rot = 1.7, 0.9
    exact = A1 / a0 ** 2 * (1 - np.cos(alpha_rot))   # per unit length (paper Eq. 17 with kappa = kappa0)
    ns = np.array([24, 48, 96, 192])
    errors = []
    for n in ns:
        rod = der.rod_from_shape(der.shapes.ring(a0, n), A1, A2)
        state = rod.rest_state()
        state.theta[:] += alpha_rot
        E = bend_energy(edge_frames(state.q, rod.edge_nodes, state.d1), rod.vertex_edges, rod.weld,
                        rod.natural_curvature_edges().reshape(-1, 4), rod.voronoi, A1)
        errors.append(abs(E / rod.length - exact) / exact)
    errors = np.array(errors)
    assert errors[-1] < 1e-3
    assert fitted_order(ns, errors) >= 1.8
