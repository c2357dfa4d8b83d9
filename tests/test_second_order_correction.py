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
    assert der.SolverOptions().second_order_correction is False
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
