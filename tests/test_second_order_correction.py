"""The implicit solver's second-order correction (``SolverOptions.second_order_correction``, issue 17): a Newton
step refused for the chord error of the edges it turns is corrected with the same factorisation and searched
along an arc. Its pieces: the chord error's forces (``stretch.chord_excess_forces``) and the solve that reuses
the last factors (``linalg.band_resolve``)."""
import numpy as np
import pytest

import der
from der import closed_forms as cf
from der import diagnostics as dg
from der.energies.stretch import chord_excess_forces
from der.linalg import BandLDLT, band_layout, band_resolve, band_solve, band_to_sparse, new_band


def ring_torsion(n, T, A1=1.0, A2=1.0 / 0.67, a0=1.0, L=3.0):
    rod = der.rod_from_shape(der.shapes.arc(a0, L, n), A1, A2)
    return der.Scene(rod, loads=[der.end_torque(T * cf.ring_end_basis(a0, L)[0])], constraints=[der.clamp("start")])


def test_second_order_correction_takes_ring_torsion_past_the_chord_error_plateau():
    # a 200-edge arc under an end torque of 0.02 A1/a0: the straight Newton steps turn the edges, the chord error
    # they add (|d_perp|^2 / 2h) is priced by the axial penalty c A1 / h^3 above the step's gain, and the line
    # search cuts them (13 iterations, several refused pseudo-time steps). Corrected, Newton converges in 4.
    scene = ring_torsion(200, 0.02)
    plain = der.solve(scene, stability=False, raise_on_failure=False, max_iterations=8)
    soc = der.solve(scene, stability=False, raise_on_failure=False, max_iterations=8, second_order_correction=True)
    assert not plain.converged                    # measured: max_iterations at 8 (13 iterations unlimited)
    assert soc.status == "converged" and soc.residual <= 1e-8 and soc.iterations <= 6
    assert soc.linear_solves.get("second_order", 0) >= 1
    # the same equilibrium as the plain solve given all the iterations it needs
    full = der.solve(scene, stability=False, tol=1e-10)
    rot = dg.end_motion(scene.rod, soc.state)[1]
    ref = dg.end_motion(scene.rod, full.state)[1]
    assert np.linalg.norm(rot - ref) <= 1e-6 * np.linalg.norm(ref)


def test_second_order_correction_is_off_by_default_and_changes_nothing_where_full_steps_pass():
    # default None: automatic, off for this coarse ring (c (L/h)^4 = 1.3e8, below implicit.EDGE_NEWTON_CONDITION)
    assert der.SolverOptions().second_order_correction is None
    scene = ring_torsion(60, 1e-3)          # full Newton steps: the correction is never asked for
    a = der.solve(scene, stability=False)
    b = der.solve(scene, stability=False, second_order_correction=True)
    assert a.iterations == b.iterations and a.residual == b.residual
    assert np.array_equal(a.state.q, b.state.q)
    assert b.linear_solves.get("second_order", 0) == 0


def test_chord_excess_forces_are_the_elongation_beyond_its_linearisation():
    rng = np.random.default_rng(3)
    n_nodes = 6
    q = rng.normal(size=4 * n_nodes)
    delta = 0.3 * rng.normal(size=4 * n_nodes)
    edge_nodes = np.array([[i, i + 1] for i in range(n_nodes - 1)], dtype=np.int64)
    k = rng.uniform(1.0, 2.0, n_nodes - 1)
    x = q.reshape(-1, 4)[:, :3]
    d = delta.reshape(-1, 4)[:, :3]
    E = x[1:] - x[:-1]
    out = np.empty_like(q)
    worst = chord_excess_forces(E, edge_nodes, delta, k, out)
    expected = np.zeros_like(q)
    g2s = []
    for j, (a, b) in enumerate(edge_nodes):
        e, dj = E[j], d[b] - d[a]
        t = e / np.linalg.norm(e)
        g2 = np.linalg.norm(e + dj) - np.linalg.norm(e) - t @ dj     # the plain formula (no cancellation here)
        g2s.append(g2)
        expected[4 * a:4 * a + 3] += k[j] * g2 * t
        expected[4 * b:4 * b + 3] -= k[j] * g2 * t
    assert np.allclose(out, expected, rtol=1e-12, atol=1e-13)
    assert worst == pytest.approx(max(abs(g) for g in g2s), rel=1e-12)
    # a pure stretch along the edges adds no chord error; a tiny turn is resolved without cancellation
    E1 = np.array([[1.0, 0.0, 0.0]])
    e1n = np.array([[0, 1]], dtype=np.int64)
    along = np.array([0, 0, 0, 0, 1e-3, 0, 0, 0], float)
    assert chord_excess_forces(E1, e1n, along, np.ones(1), np.empty(8)) == 0.0
    turn = np.array([0, 0, 0, 0, 0, 1e-9, 0, 0], float)
    g = chord_excess_forces(E1, e1n, turn, np.ones(1), np.empty(8))
    assert g == pytest.approx(0.5e-18, rel=1e-9)          # sqrt(1 + 1e-18) - 1 = 5e-19 (0 by the plain formula)


@pytest.mark.parametrize("closed", [False, True])
@pytest.mark.parametrize("skew", [0.0, 3.0])
def test_band_resolve_reuses_the_last_factors(closed, skew):
    # symmetric: the LDL^T path (its factors refined against the untouched band); skew: dgbsv's LU in the band
    rng = np.random.default_rng(7)
    nodes = 12
    kl, ku, perm = band_layout(nodes, closed)
    n = 4 * nodes
    ab = new_band(n, kl, ku)
    off = kl + ku
    for j in range(n):
        for i in range(max(0, j - kl), min(n - 1, j + kl) + 1):
            ab[off + i - j, j] = rng.normal() if i != j else 20.0
    for j in range(n):                     # symmetric part, plus the skew part asked for
        for i in range(j + 1, min(n - 1, j + kl) + 1):
            s = 0.5 * (ab[off + i - j, j] + ab[off + j - i, i])
            ab[off + i - j, j] = s + skew
            ab[off + j - i, i] = s - skew
    A = band_to_sparse(ab, kl, ku, perm).toarray()
    ldlt = BandLDLT(n, kl)
    r1, r2 = rng.normal(size=n), rng.normal(size=n)
    x1, info = band_solve(ab, kl, ku, perm, r1, ldlt=ldlt)
    assert info == 0
    assert ldlt.factors == ("ldlt" if skew == 0.0 else "dgbsv")
    x2 = band_resolve(ab, kl, ku, perm, r2, ldlt)
    assert np.allclose(A @ x1, r1, rtol=0, atol=1e-12)
    assert np.allclose(A @ x2, r2, rtol=0, atol=1e-12)
    ldlt.release()
    assert band_resolve(ab, kl, ku, perm, r2, ldlt) is None


# ---- with the Newton steps in edge coordinates (SolverOptions.edge_newton, der.solvers.edge_coordinates) ----

def _first_newton_steps(n, T=1e-3):
    """At the rest state of ring torsion: the residual, the Newton step solved in node coordinates and in edge
    coordinates, and K_e (the edge-coordinate stiffness read off the band) to judge them by."""
    from der.linalg import add_diagonal
    from der.solvers.edge_coordinates import EdgeNewton, edge_eligible
    from der.solvers.system import (
        build_system, constrain_system, evaluate_system, expand, prepare_state, residual_vector,
    )

    scene = ring_torsion(n, T)
    system = build_system(scene, der.SolverOptions())
    state = prepare_state(system, scene.rod.rest_state())
    evaluate_system(system, state, 2)
    R = residual_vector(system).copy()
    assert edge_eligible(system)
    edge = EdgeNewton(system, state)
    assert edge.prepare(system.ab, system.kl, system.ku)
    dz, info = edge.step(system.fext - system.grad, 1e30)
    assert info == 0
    dz_lo = edge.step_lo.copy()
    abz = edge.ez.band(system.ab, system.kl, system.ku)
    ab = system.ab.copy(order="F")
    diag = np.abs(ab[system.kl + system.ku, :][system.perm])
    diag[diag == 0] = 1.0
    add_diagonal(ab, system.kl, system.ku, system.perm, diag, 1e-30)
    constrain_system(system, ab, 1.0)
    dq, info = band_solve(ab, system.kl, system.ku, system.perm, R, ldlt=system.ldlt)
    assert info == 0
    expand(system, dq)
    return system, edge, abz, R, dq, (dz, dz_lo)


def _relative_residual(edge, abz, R, d, lo=None):
    """||T^T R - K_e T^-1 d|| / ||T^T R|| on the free edge coordinates: how well the step d (plus its low part
    ``lo``, a compensated step) solves K d = R, with K applied as T^-T K_e T^-1 (no cancellation of the
    node-coordinate entries c A1 / h^3)."""
    from der.linalg import band_matvec
    from der.solvers.edge_coordinates import EDGE_BAND

    ez = edge.ez
    kz = np.empty(d.size)
    z = ez.to_z(d) if lo is None else ez.to_z(d) + ez.to_z(lo)
    band_matvec(abz, EDGE_BAND, EDGE_BAND, ez.perm, z, kz, False)
    rz = ez.condense_full(ez.transpose_to_z(R))
    return float(np.linalg.norm(ez.condense_full(kz) - rz) / np.linalg.norm(rz))


def test_edge_newton_solve_the_same_newton_step_on_a_coarse_rod():
    system, edge, abz, R, dq, (dz, dz_lo) = _first_newton_steps(60)
    assert np.linalg.norm(dz - dq) <= 1e-8 * np.linalg.norm(dq)
    assert np.abs(dz_lo).max() <= 1e-15 * np.abs(dz).max()          # a low part: below the rounding of dz
    # the correction solve reuses the edge factors: the same as a node-coordinate solve of the same forces
    rhs = np.random.default_rng(2).normal(size=R.size)
    rhs[system.fixed] = 0.0
    c = edge.resolve(rhs.copy())
    assert c is not None and np.all(np.isfinite(c))
    assert _relative_residual(edge, abz, rhs, c) <= 1e-8


def test_edge_newton_keep_the_newton_step_accurate_where_node_coordinates_lose_it():
    # ring torsion, n = 3000: the node-coordinate Newton matrix (entries c A1 / h^3 against a smooth mode's
    # A1 h / L^4, condition ~ (L / h)^4) gives a step whose relative residual is 2e-3 (measured; 1.6 at 10^4);
    # the same system in edge coordinates 1.1e-8 (2.5e-7 at 10^4), the step applied as a compensated pair; its
    # high part alone 1.6e-5 (the cumulative sums rounded at eps |step|)
    _, edge, abz, R, dq, (dz, dz_lo) = _first_newton_steps(3000)
    node, in_edges = _relative_residual(edge, abz, R, dq), _relative_residual(edge, abz, R, dz, dz_lo)
    assert in_edges <= 1e-6
    assert node >= 1e-4          # the cause, measured: what the node-coordinate path loses here
    assert _relative_residual(edge, abz, R, dz) >= 10 * in_edges     # what the low part keeps


def test_edge_newton_reach_the_equilibrium_of_node_coordinates():
    scene = ring_torsion(200, 0.02)
    ref = der.solve(scene, stability=False, tol=1e-10)
    for soc in (False, True):
        res = der.solve(scene, stability=False, tol=1e-10, edge_newton=True, second_order_correction=soc)
        assert res.status == "converged" and res.linear_solves.get("edge", 0) > 0
        assert res.linear_solves["band"] == 0
        rot, rot_ref = dg.end_motion(scene.rod, res.state)[1], dg.end_motion(scene.rod, ref.state)[1]
        assert np.linalg.norm(rot - rot_ref) <= 1e-7 * np.linalg.norm(rot_ref)


def test_second_order_correction_with_edge_newton_solves_the_correction_with_the_edge_factors():
    # the plateau scene of the first test with Newton steps in edge coordinates: alone they are cut by the chord
    # error as the node steps are (max_iterations at 8); the correction, solved with the edge factors
    # (EdgeNewton.resolve: no node-coordinate factorisation at all), converges in 4 (measured)
    scene = ring_torsion(200, 0.02)
    edge = der.solve(scene, stability=False, raise_on_failure=False, max_iterations=8, edge_newton=True)
    both = der.solve(scene, stability=False, raise_on_failure=False, max_iterations=8, edge_newton=True,
                     second_order_correction=True)
    assert not edge.converged and edge.linear_solves.get("edge", 0) > 0
    assert both.status == "converged" and both.residual <= 1e-8 and both.iterations <= 6
    assert both.linear_solves.get("second_order", 0) >= 1 and both.linear_solves["band"] == 0
    full = der.solve(scene, stability=False, tol=1e-10)
    rot, ref = dg.end_motion(scene.rod, both.state)[1], dg.end_motion(scene.rod, full.state)[1]
    assert np.linalg.norm(rot - ref) <= 1e-6 * np.linalg.norm(ref)


def test_edge_newton_apply_only_to_open_rods_held_at_their_start():
    from der.solvers.edge_coordinates import edge_eligible
    from der.solvers.system import build_system

    arc = der.rod_from_shape(der.shapes.arc(1.0, 3.0, 40), 1.0, 1.5)
    ring = der.rod_from_shape(der.shapes.ring(1.0, 40), 1.0, 1.5)
    held_at_start = der.Scene(arc, loads=[der.end_torque([1e-3, 0.0, 0.0])], constraints=[der.clamp("start")])
    held_at_end = der.Scene(arc, loads=[der.end_torque([1e-3, 0.0, 0.0], end="start")], constraints=[der.clamp("end")])
    closed = der.Scene(ring, constraints=[der.pin(0), der.pin(20)])
    assert edge_eligible(build_system(held_at_start, der.SolverOptions()))
    for scene in (held_at_end, closed):
        assert not edge_eligible(build_system(scene, der.SolverOptions()))
    res = der.solve(held_at_end, stability=False, edge_newton=True)     # the option then changes nothing
    assert res.converged and res.linear_solves.get("edge", 0) == 0 and res.linear_solves["band"] > 0


def test_a_fine_inextensible_ring_takes_edge_steps_with_the_correction_by_default():
    # Stop 27 (docs/scaling.md): ring torsion at 3x10^4 and 10^5 stalled and restarted by default: the node-coordinate
    # Newton matrix's condition c (L/h)^4 (1e17 at 3x10^4) is beyond double precision, and its straight steps carry
    # the chord error c A1 / h^3 prices (Maratos). Scaled down: n = 400 with a penalty c = 1e7 puts c (L/h)^4 at
    # 2.6e17. Old default (node coordinates, no correction): converged after 114 iterations. Now the edge-coordinate
    # Newton with the second-order correction is on by default there: converged in 6.
    n, c = 400, 1e7
    scene = ring_torsion(n, 1e-3)
    res = der.solve(scene, stability=False, inextensible_penalty=c)
    assert res.status == "converged" and res.residual <= 1e-8
    assert res.iterations <= 10, res.iterations
    assert res.linear_solves.get("edge", 0) == res.iterations and res.linear_solves.get("band", 0) == 0
    assert "restart" not in res.message
    ref = cf.ring_end_rotation(1.0, 1.0 / 0.67, 1.0, 3.0, 1e-3)
    err = np.linalg.norm(dg.end_motion(scene.rod, res.state)[1] - ref) / np.linalg.norm(ref)
    assert err < 5e-5, err          # the discretisation's error at n = 400 (2.1e-5)
    # False keeps the node-coordinate path (the old default's 114 iterations)
    old = der.solve(scene, stability=False, inextensible_penalty=c, edge_newton=False, second_order_correction=False,
                    max_iterations=20, raise_on_failure=False)
    assert old.linear_solves.get("edge", 0) == 0 and not old.converged
