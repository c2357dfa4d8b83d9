"""Damped dynamics to static equilibrium: closed forms, an independent elastica solution, solver agreement,
energy decrease, stability and failure paths (issue 3)."""
import numpy as np
import pytest
from scipy.integrate import solve_bvp

import der
import der.solvers.implicit as implicit_module
from der.geometry import material_frames
from der.solvers.options import ConvergenceError


def fitted_order(ns, errors):
    return -np.polyfit(np.log(ns), np.log(errors), 1)[0]


def twisted_rod(n, T=0.4, L=1.3, A1=1.0, A2=1.7):
    rod = der.rod_from_shape(der.shapes.straight(L, n), A1, A2)
    return der.Scene(rod, loads=[der.end_torque([0.0, 0.0, T])], constraints=[der.clamp("start")]), T * L / A2


@pytest.mark.parametrize("solver", ["implicit", "explicit"])
@pytest.mark.parametrize("n", [2, 5, 17, 40])
def test_straight_rod_end_twist_is_TL_over_A2_for_any_n(solver, n):
    scene, exact = twisted_rod(n)
    res = der.solve(scene, solver=solver, tol=1e-11)
    twist = res.state.theta[-1] - res.state.theta[0]
    assert abs(twist - exact) <= 1e-9 * exact
    assert np.abs(res.state.positions[:, :2]).max() < 1e-12


def cantilever_tip(n, P, solver="implicit", L=1.0, A1=1.0):
    rod = der.rod_from_shape(der.shapes.straight(L, n), A1, 0.8)
    scene = der.Scene(rod, loads=[der.end_force([P, 0.0, 0.0])], constraints=[der.clamp("start")])
    res = der.solve(scene, solver=solver, tol=1e-10)
    x = res.state.positions
    return 0.5 * (x[-1] + x[-2]), res   # the rod's end: the midpoint of the end edge


def test_cantilever_small_load_error_is_second_order_in_h_and_in_P():
    P, L, A1 = 1e-4, 1.0, 1.0
    exact = P * L ** 3 / (3 * A1)
    ns = np.array([8, 16, 32, 64])
    errors = np.array([abs(cantilever_tip(n, P)[0][0] - exact) / exact for n in ns])
    assert fitted_order(ns, errors) >= 1.8
    # the load effect: at fixed n the error changes by c P^2 (the elastica's first nonlinear term)
    n = 32
    e = {p: cantilever_tip(n, p)[0][0] / (p * L ** 3 / (3 * A1)) - 1 for p in (1e-4, 0.02, 0.04)}
    ratio = (e[0.04] - e[1e-4]) / (e[0.02] - e[1e-4])
    assert ratio == pytest.approx(4.0, rel=0.03)


def elastica_tip(PL2_over_A1, L=1.0):
    """Planar elastica of a cantilever with a transverse tip force, by solve_bvp: A1 phi'' = -P cos(phi)."""
    p = PL2_over_A1 / L ** 2
    s = np.linspace(0, L, 201)

    def f(s, y):
        return np.vstack([y[1], -p * np.cos(y[0]), np.sin(y[0]), np.cos(y[0])])

    def bc(ya, yb):
        return np.array([ya[0], yb[1], ya[2], ya[3]])

    y0 = np.zeros((4, s.size))
    y0[3] = s
    sol = solve_bvp(f, bc, s, y0, tol=1e-10, max_nodes=100000)
    assert sol.success
    return sol.sol(L)[2], sol.sol(L)[3]


def test_large_deflection_cantilever_against_elastica():
    load = 3.0
    x_ref, z_ref = elastica_tip(load)
    ns = np.array([20, 40, 80])
    errors = []
    for n in ns:
        tip, res = cantilever_tip(n, load)
        assert res.stable
        errors.append(np.hypot(tip[0] - x_ref, tip[2] - z_ref))
    errors = np.array(errors)
    assert x_ref > 0.6          # a large deflection
    assert errors[-1] < 2e-4
    assert fitted_order(ns, errors) >= 1.8


def helix_scene(EA=None, n=30):
    rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1.0, n), 1.0, 1.5, EA=EA)
    loads = [der.end_force([0.0, 0.0, 0.05]), der.end_torque(0.03, follower=True)]
    return der.Scene(rod, loads=loads, constraints=[der.clamp("start")])


def test_explicit_and_implicit_reach_the_same_equilibrium():
    scene = helix_scene()
    a = der.solve(scene, solver="implicit", tol=1e-10)
    b = der.solve(scene, solver="explicit", tol=1e-9)
    size = np.ptp(a.state.positions, axis=0).max()
    disp = np.abs(a.state.positions - scene.rod.rest_state().positions).max()
    assert disp > 1e-2 * size
    assert np.abs(a.state.positions - b.state.positions).max() < 1e-6 * size
    # theta is measured from reference frames that depend on the path taken; the material frames do not
    m1a, _ = material_frames(a.state.q, a.state.tangents, a.state.d1)
    m1b, _ = material_frames(b.state.q, b.state.tangents, b.state.d1)
    assert np.abs(m1a - m1b).max() < 1e-6


def test_explicit_trajectory_total_energy_never_increases():
    # conservative (a dead force) and extensible (no multiplier updates): the energy is a Lyapunov function
    rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1.0, 30), 1.0, 1.5, EA=2e3)
    scene = der.Scene(rod, loads=[der.end_force([0.02, 0.0, 0.05])], constraints=[der.clamp("start")])
    res = der.solve(scene, solver="explicit", tol=1e-8, check_every=5)
    E = np.array(res.total_energy)
    assert len(E) > 20
    # non-increasing up to the round-off of evaluating the energy (a sum of n terms)
    assert np.all(np.diff(E) <= 1e-12 * np.abs(E).max())
    assert E[-1] < E[0]


def test_iteration_cap_raises_convergence_error_with_status_and_residual():
    scene = helix_scene()
    with pytest.raises(ConvergenceError) as info:
        der.solve(scene, max_iterations=2)
    res = info.value.result
    assert res.status == "max_iterations" and not res.converged
    assert np.isfinite(res.residual) and res.residual > 1e-8
    assert np.isfinite(res.state.q).all()
    assert "did not converge" in str(info.value)
    res = der.solve(scene, max_iterations=2, raise_on_failure=False)
    assert res.status == "max_iterations"


def test_explicit_step_above_the_stable_limit_is_refused():
    scene = helix_scene(EA=2e3)
    with pytest.raises(ValueError, match=r"exceeds the stable limit .* from the (stretch|bend|twist) mode"):
        der.solve(scene, solver="explicit", dt=1.0)


def test_nonfinite_force_is_caught_and_last_finite_state_kept(monkeypatch):
    scene = helix_scene()
    # the residual pass of the banded path (issue 17: the forces alone, the band only for a step)
    original = implicit_module.evaluate_forces
    calls = {"n": 0}

    n_dof = scene.rod.rest_q.size

    def poisoned(system, state, forces):
        out = original(system, state, forces)
        if system.grad.size != n_dof:      # another system (a warm-up's small rod)
            return out
        calls["n"] += 1
        if calls["n"] == 4:
            system.grad[4 * (system.grad.size // 8) + 1] = np.nan   # a free DOF (the middle node, y)
        return out

    monkeypatch.setattr(implicit_module, "evaluate_forces", poisoned)
    res = der.solve(scene, raise_on_failure=False)
    assert calls["n"] >= 4                     # the poisoned pass was reached
    assert res.status == "nonfinite" and not res.converged
    assert np.isfinite(res.state.q).all()
    assert "last finite state kept" in res.message


def test_euler_column_stability_from_eigenvalues():
    L, A1, n = 1.0, 1.0, 30
    P_cr = np.pi ** 2 * A1 / (4 * L ** 2)
    rod = der.rod_from_shape(der.shapes.straight(L, n), A1, 1.0)
    below = der.solve(der.Scene(rod, loads=[der.end_force([0, 0, -0.9 * P_cr])], constraints=[der.clamp("start")]))
    above = der.solve(der.Scene(rod, loads=[der.end_force([0, 0, -1.1 * P_cr])], constraints=[der.clamp("start")]))
    assert below.stable and below.min_eigenvalue > 0
    # a perfectly straight column stays straight: an equilibrium, found and reported unstable
    assert above.converged and not above.stable and above.min_eigenvalue < 0
    assert np.abs(above.state.positions[:, :2]).max() < 1e-12
    # with an imperfection (a small lateral load) the solver leaves the straight state for the buckled, stable one
    kicked = der.solve(der.Scene(rod, loads=[der.end_force([0.01 * P_cr, 0, -1.1 * P_cr])],
                                 constraints=[der.clamp("start")]))
    assert kicked.stable and kicked.min_eigenvalue > 0 and kicked.state.positions[-1, 0] > 0.3 * L


def test_greenhill_with_a_sliding_clamp():
    """Both ends clamped, the far end sliding along the axis and turned by phi: the straight rod loses stability
    at Greenhill's phi = 8.9868 A1/A2 (clamped ends); kicked past it, damped dynamics leave the straight state
    (the sliding end lets the rod shorten and writhe), while Newton's method from the start returns to the
    nearest equilibrium, the straight one, and reports it unstable."""
    L, A1, A2, n = 1.0, 1.0, 1.0, 40
    rod = der.rod_from_shape(der.shapes.straight(L, n, axis=(0, 0, 1)), A1, A2)

    def scene(phi):
        R = np.array([[np.cos(phi), -np.sin(phi), 0], [np.sin(phi), np.cos(phi), 0], [0, 0, 1.0]])
        return der.Scene(rod, constraints=[der.clamp("start"), der.clamp("end", rotation=R, slide=2)])

    state = rod.rest_state()
    lams = {}
    for phi in np.linspace(0.5, 1.2 * 8.9868, 20):
        res = der.solve(scene(phi), state=state)
        state = res.state
        lams[phi] = res.min_eigenvalue
    phis = np.array(sorted(lams))
    lam = np.array([lams[p] for p in phis])
    k = int(np.flatnonzero(lam <= 0)[0])
    cross = phis[k - 1] + (phis[k] - phis[k - 1]) * lam[k - 1] / (lam[k - 1] - lam[k])
    assert abs(cross - 8.9868) / 8.9868 < 1e-2
    bulge = np.zeros((rod.n_nodes, 3))
    bulge[2:-2, 0] = 1e-3 * np.sin(np.pi * rod.xi_nodes[2:-2] / L)
    kicked = rod.displaced(state, bulge)
    back = der.solve(scene(phis[-1]), state=kicked)
    assert back.converged and not back.stable and np.abs(back.state.positions[:, :2]).max() < 1e-6
    away = der.solve(scene(phis[-1]), state=kicked, newton_first=False)
    assert away.converged and away.stable and np.abs(away.state.positions[:, :2]).max() > 0.1 * L
    # the end slid towards the start: the rod shortened to make room for its writhe
    assert away.state.positions[-1, 2] < state.positions[-1, 2] - 0.1 * L


def test_scene_pays_only_for_what_it_needs():
    from der.solvers.system import build_system, evaluate_system

    rod = der.rod_from_shape(der.shapes.straight(1.0, 6), 1.0, 1.0)
    scene = der.Scene(rod, energies=("stretch", "bend"), loads=[der.end_force([0.1, 0, 0])],
                      constraints=[der.clamp("start")])
    system = build_system(scene, der.SolverOptions())
    for order in (0, 1, 2):
        evaluate_system(system, rod.rest_state(), order)
    c = system.counters
    assert c["stretch"] == 3 and c["bend"] == 3 and c["nodal_forces"] == 3
    assert c["twist"] == 0 and c["theta_moments"] == 0 and c["dead_torques"] == 0


def test_import_der_does_not_import_rerun_or_plotting():
    import subprocess
    import sys

    code = ("import sys, der; bad = [m for m in ('rerun', 'matplotlib', 'scipy.sparse') if m in sys.modules];"
            "print(','.join(bad))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
