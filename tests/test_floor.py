"""The round-off floor at its root (issue 17): compensated coordinates, edges formed in one place, and a floor
bound that the measured rounding noise stays under."""
import warnings
from fractions import Fraction

import numpy as np
import pytest

import der
from der import closed_forms as cf
from der.geometry import add_compensated, edge_array, edge_frames
from der.solvers import SolverOptions
from der.solvers.system import (
    build_system, evaluate_system, load_scales, prepare_state, residual_floor, residual_norm, residual_vector,
)


def test_add_compensated_keeps_what_the_sum_rounds_away():
    rng = np.random.default_rng(1)
    q = rng.uniform(-3.0, 3.0, 200)
    lo = np.zeros_like(q)
    exact = [Fraction(x) for x in q]
    for _ in range(20):   # many small steps: plain sums lose their low bits at every one
        d = 1e-9 * rng.standard_normal(q.size)
        add_compensated(q, lo, 0.37, d, q, lo)
        exact = [e + Fraction(0.37 * di) for e, di in zip(exact, d)]
    for x, l, e in zip(q, lo, exact):
        assert abs(l) <= 0.5 * abs(np.spacing(x))
        # the pair is exact to the rounding of its low part (~eps^2 |x|), a plain sum only to eps |x| per step
        assert abs(Fraction(x) + Fraction(l) - e) <= Fraction(1e-28)


def test_edge_array_forms_edges_from_both_parts():
    rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1, 30), 1.0, 1.5)
    q = rod.rest_q + 1e6                   # far from the origin: each coordinate rounded at 1e-10
    lo = np.zeros_like(q)
    lo.reshape(-1, 4)[:, :3] = np.random.default_rng(2).uniform(-1e-10, 1e-10, (rod.n_nodes, 3))
    E = edge_array(q, rod.edge_nodes, lo)
    x = [[Fraction(q[4 * k + c]) + Fraction(lo[4 * k + c]) for c in range(3)] for k in range(rod.n_nodes)]
    for j, (a, b) in enumerate(rod.edge_nodes):
        for c in range(3):
            exact = x[b][c] - x[a][c]
            assert abs(Fraction(E[j, c]) - exact) <= abs(exact) * Fraction(2.3e-16) + Fraction(1e-300)
    # without low parts: the plain differences (with their TwoSum low parts), bitwise what edge_frames forms itself
    assert np.array_equal(edge_frames(q, rod.edge_nodes, rod.rest_d1),
                          edge_frames(q, rod.edge_nodes, rod.rest_d1, edge_array(q, rod.edge_nodes, None, True)))
    # with ``lo`` the same rounded edges and, beside them, what they rounded away: the pair is exact to the
    # rounding of the low parts' difference (eps ulp(x), 2e-26 here), a million times below the edge's own
    E6 = edge_array(q, rod.edge_nodes, lo, True)
    assert np.array_equal(E6[:, :3], E)
    for j, (a, b) in enumerate(rod.edge_nodes):
        for c in range(3):
            exact = x[b][c] - x[a][c]
            assert abs(Fraction(E6[j, c]) + Fraction(E6[j, 3 + c]) - exact) <= Fraction(2.3e-16 * 2e-10)


def _ring_torsion(n, T):
    A1, A2, a0, L = 1.0, 1.0 / 0.67, 1.0, 3.0
    rod = der.rod_from_shape(der.shapes.arc(a0, L, n), A1, A2)
    scene = der.Scene(rod, loads=[der.end_torque(T * cf.ring_end_basis(a0, L)[0])], constraints=[der.clamp("start")])
    return rod, scene, cf.ring_end_rotation(A1, A2, a0, L, T)


def test_forces_are_smooth_below_the_rounding_of_the_edges():
    # issue 17, the ring's floor: the curvature binormal was formed from unit tangents (eps absolute against its
    # size h kappa) and the elongation as |e| - l (eps |e|): both jumped by a rounding step whenever an edge did,
    # and the bending (A1 / h^3) and axial penalty (c A1 / h^3) stiffnesses turned the jumps into a force noise
    # growing like n. From the low parts of the edges both are smooth: moving the nodes by their edges' rounding
    # changes the forces by K dx, the linear response, and little else.
    from der.linalg import band_matvec
    from der.solvers.system import transport

    rod, scene, _ = _ring_torsion(120, 1e-3)
    res = der.solve(scene, stability=False)
    system = build_system(scene, SolverOptions())
    s = prepare_state(system, res.state)
    evaluate_system(system, s, 2)
    f0 = system.grad - system.fext
    le = np.linalg.norm(edge_array(s.q, rod.edge_nodes, s.q_lo), axis=1)
    pos = np.zeros(rod.n_dof, dtype=bool)
    pos.reshape(-1, 4)[:, :3] = True
    pos &= ~system.fixed
    rng = np.random.default_rng(5)
    worst = 0.0
    for _ in range(3):
        dx = 0.5 * np.finfo(float).eps * le.min() * rng.choice([-1.0, 1.0], size=rod.n_dof) * pos
        Kdx = np.empty(rod.n_dof)
        band_matvec(system.ab, system.kl, system.ku, system.perm, dx, Kdx)
        trial = s.copy()
        trial.q_lo = s.q_lo + dx
        assert transport(system, s, trial.q, trial)
        evaluate_system(system, trial, 1)
        df = system.grad - system.fext - f0
        worst = max(worst, float(np.abs(df - Kdx)[pos].max() / np.abs(Kdx[pos]).max()))
        evaluate_system(system, s, 2)
    # measured: 0.57 before (jumps of eps |e| c A1 / h^3, as large as the response itself), 0.006 now (what is left
    # is the reference twist's rounding from unit tangents, A2 eps kappa / h: flat in n against the torque's
    # force scale T / h); the departure falls like 1 / |dx| (rounding) and not like |dx| (a wrong K)
    assert worst < 0.05, worst


def test_ring_torsion_under_a_small_torque_reaches_tol():
    # the floor mechanism at n = 10^5 scaled down: the force noise of the old curvature and elongation, relative to
    # the load, grew like eps A1 n / (T L); a small torque at n = 200 puts it where n = 10^5 had it (old code:
    # converged_at_floor at about 1e-6 for T = 2e-6 against the clamp's inflated force scale). The residual is
    # judged against the load's own scale T / L (the clamp's reaction couple T / h no longer sets it): T = 1e-4
    # reaches tol; T = 2e-6 stops at 9.7 times tol, "converged_at_floor" with a Newton correction at round-off.
    # Both end rotations are the closed form's to the discretisation error (O(h^2): 8e-5 at n = 200).
    from der import diagnostics as dg

    for T, status in [(1e-4, "converged"), (2e-6, "converged_at_floor")]:
        rod, scene, ref = _ring_torsion(200, T)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = der.solve(scene, stability=False, tol=1e-8)
        assert res.status == status and res.residual <= (1e-8 if status == "converged" else 1e-7), res.message
        assert res.load_scale == pytest.approx(T / 3.0, rel=1e-3)     # the internal moment, T to O(h^2)
        err = np.linalg.norm(dg.end_motion(rod, res.state)[1] - ref) / np.linalg.norm(ref)
        assert err < 5e-4, err


def test_readme_example_converges_below_tol():
    # issue 17: the README's example ended "converged_at_floor" at 1.6e-7 (tol 1e-8): the floor of absolute
    # coordinates. With compensated coordinates it reaches tol.
    rod = der.rod_from_shape(der.shapes.helix(kappa0=1.0, omega0=0.6, turns=1, n=200), A1=1.0, A2=1.5)
    scene = der.Scene(rod, loads=[der.end_force([0, 0, 1e-3]), der.end_torque(2e-3, follower=True)],
                      constraints=[der.clamp("start")])
    res = der.solve(scene, stability=False)
    assert res.status == "converged" and res.residual <= 1e-8, res.message


def test_a_rod_far_from_the_origin_solves_like_one_at_it():
    # the floor of absolute coordinates grew with the distance from the origin; compensated coordinates make the
    # solve translation invariant (to the rounding of the rest edges at ulp(1e6) = 1e-10)
    out = []
    for offset in (0.0, 1e6):
        s = der.shapes.straight(1.0, 100, axis=(1, 0, 0), director=(0, 1, 0))
        rod = der.rod_from_shape(der.shapes.Shape(s.positions + offset, s.closed, s.director), 1.0, 1.0)
        scene = der.Scene(rod, loads=[der.end_force([0, 0, 1e-4])], constraints=[der.clamp("start")])
        res = der.solve(scene, stability=False, raise_on_failure=False)
        out.append(res)
        assert res.status == "converged" and res.residual <= 1e-8, (offset, res.status, res.message)
    tip = [r.state.positions[-1, 2] - 1e6 * k for k, r in enumerate(out)]
    assert tip[1] == pytest.approx(tip[0], rel=1e-5)


@pytest.mark.parametrize("n", [100, 400])
def test_measured_rounding_noise_stays_under_the_floor_bound(n):
    # the bound eps |K| w must bound what rounding each edge at its own length does to the residual
    A1, A2, a0, L, T = 1.0, 1.0 / 0.67, 1.0, 3.0, 1e-3
    rod = der.rod_from_shape(der.shapes.arc(a0, L, n), A1, A2)
    scene = der.Scene(rod, loads=[der.end_torque(T * cf.ring_end_basis(a0, L)[0])],
                      constraints=[der.clamp("start")])
    res = der.solve(scene, stability=False, tol=1e-12, raise_on_failure=False)
    system = build_system(scene, SolverOptions())
    state = prepare_state(system, res.state)
    evaluate_system(system, state, 2)
    scales = load_scales(system, state)
    bound = residual_floor(system, state, scales)
    R0 = residual_vector(system).copy()
    le = np.linalg.norm(np.diff(state.positions, axis=0), axis=1)
    node = np.maximum(np.r_[le, 0.0], np.r_[0.0, le])
    rng = np.random.default_rng(3)
    worst = 0.0
    for _ in range(5):
        trial = state.copy()
        step = 0.5 * np.finfo(float).eps * np.repeat(node, 4) * rng.choice([-1.0, 1.0], rod.n_dof)
        step[3::4] = 0.0
        step[system.fixed] = 0.0
        trial.q_lo = state.q_lo + step
        evaluate_system(system, trial, 1)
        worst = max(worst, residual_norm(system, residual_vector(system) - R0, scales))
    assert 0.0 < worst <= bound
    # grows like n^2 (not n^3 as with absolute coordinates); against the torque's own force scale T / L (before,
    # the clamp's reaction couple T / h set it, n / 3 times larger, and the bound was below 1e-8 (n / 100)^2)
    assert bound < 3e-7 * (n / 100) ** 2
