"""band_solve's symmetric path (issue 17): LDL^T without pivoting of the band's symmetric lower triangle, refined
against the band and accepted only on a small componentwise backward error, else LAPACK's dgbsv -- checked
against dense solves, eigenvalue counts and the cases that must fall back."""
import numpy as np
import pytest

from der import linalg
from der.linalg import BAND_SOLVES, BandLDLT, band_ldlt_compact, band_solve, new_band


def dense_to_band(A, kl, ku):
    n = A.shape[0]
    ab = new_band(n, kl, ku)
    off = kl + ku
    for j in range(n):
        for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
            ab[off + i - j, j] = A[i, j]
    return ab


def random_band(n, b, rng, shift):
    A = np.zeros((n, n))
    for s in range(1, b + 1):
        v = rng.standard_normal(n - s)
        A += np.diag(v, -s) + np.diag(v, s)
    return A + np.diag(shift + rng.standard_normal(n))


def counts():
    return dict(BAND_SOLVES)


def delta(before):
    return {k: BAND_SOLVES[k] - before[k] for k in BAND_SOLVES}


@pytest.mark.parametrize("b", [10, 19])
def test_symmetric_band_is_solved_by_ldlt_and_matches_dense(b):
    rng = np.random.default_rng(1)
    n = 120
    A = random_band(n, b, rng, 3.0 * b)            # diagonally dominant: positive definite
    perm = rng.permutation(n)                     # DOF -> band position
    Ad = A[np.ix_(perm, perm)]                    # A in DOF order: Ad[d, e] = A[perm[d], perm[e]]
    rhs = rng.standard_normal((n, 3))
    work = BandLDLT(n, b)
    c0 = counts()
    x, info = band_solve(dense_to_band(A, b, b), b, b, perm, rhs, ldlt=work)
    assert info == 0 and delta(c0) == {"ldlt": 1, "dgbsv": 0, "ldlt_refused": 0}
    assert work.accepted and work.backward_error <= linalg.LDLT_BACKWARD_ERROR
    assert np.allclose(x, np.linalg.solve(Ad, rhs), rtol=1e-12, atol=1e-12)
    assert work.negatives == 0


def test_inertia_counts_negative_eigenvalues_of_an_indefinite_band():
    rng = np.random.default_rng(2)
    n, b = 80, 10
    A = random_band(n, b, rng, 0.0)
    A += np.diag(np.linspace(-40.0, 40.0, n))     # indefinite, pivots far from zero
    L, D = np.empty((n, b)), np.empty(n)
    neg = band_ldlt_compact(dense_to_band(A, b, b), b, b, L, D)
    lower = np.zeros((n, n))
    for j in range(n):
        for s in range(1, b + 1):
            if j + s < n:
                lower[j + s, j] = L[j, s - 1]
    Lf = lower + np.eye(n)
    assert np.allclose(Lf @ np.diag(D) @ Lf.T, A, atol=1e-9 * np.abs(A).max())
    assert neg == int((np.linalg.eigvalsh(A) < 0).sum())


def test_small_skew_part_is_refined_to_the_nonsymmetric_solution():
    rng = np.random.default_rng(3)
    n, b = 100, 10
    A = random_band(n, b, rng, 3.0 * b)
    W = np.zeros((n, n))
    for s in range(1, 4):
        v = 1e-3 * rng.standard_normal(n - s)
        W += np.diag(v, s) - np.diag(v, -s)
    A = A + W                                      # a small skew part, like the frame-transport term
    rhs = rng.standard_normal(n)
    work = BandLDLT(n, b)
    c0 = counts()
    x, info = band_solve(dense_to_band(A, b, b), b, b, np.arange(n), rhs, ldlt=work)
    assert delta(c0)["ldlt"] == 1
    x_ref = np.linalg.solve(A, rhs)
    assert np.abs(x - x_ref).max() <= 1e-11 * np.abs(x_ref).max()


def test_zero_pivot_and_large_skew_fall_back_to_dgbsv():
    rng = np.random.default_rng(4)
    n, b = 60, 10
    # a symmetric matrix with a zero leading pivot (non-singular): LDL^T without pivoting cannot start
    A = random_band(n, b, rng, 3.0 * b)
    A[0, 0] = 0.0
    rhs = rng.standard_normal(n)
    work = BandLDLT(n, b)
    c0 = counts()
    x, info = band_solve(dense_to_band(A, b, b), b, b, np.arange(n), rhs, ldlt=work)
    assert delta(c0) == {"ldlt": 0, "dgbsv": 1, "ldlt_refused": 1} and not work.accepted
    assert np.allclose(A @ x, rhs, atol=1e-10)
    # a skew part as large as the symmetric one: refinement does not contract, the solve goes to dgbsv
    B = random_band(n, b, rng, 1.0)
    for s in range(1, b + 1):
        v = 3.0 * rng.standard_normal(n - s)
        B += np.diag(v, s) - np.diag(v, -s)
    work = BandLDLT(n, b)
    c0 = counts()
    x, info = band_solve(dense_to_band(B, b, b), b, b, np.arange(n), rhs, ldlt=work)
    assert delta(c0)["dgbsv"] == 1 and delta(c0)["ldlt"] == 0
    assert np.allclose(B @ x, rhs, atol=1e-9 * np.abs(B).max() * np.abs(x).max())
    # the next solves with the same work arrays go straight to dgbsv (refinement did not contract: a skew part,
    # which stays from one Newton matrix to the next), then LDL^T is tried again
    assert work.skip == linalg.LDLT_RETRY_AFTER
    C = dense_to_band(random_band(n, b, rng, 3.0 * b), b, b)
    c0 = counts()
    for _ in range(linalg.LDLT_RETRY_AFTER + 1):
        band_solve(C.copy(order="F"), b, b, np.arange(n), rhs, ldlt=work)
    assert delta(c0) == {"ldlt": 1, "dgbsv": linalg.LDLT_RETRY_AFTER, "ldlt_refused": 0}


def test_an_indefinite_matrix_refused_does_not_hold_back_the_next_solve(monkeypatch):
    """Newton's start matrix may be indefinite and refused (the wound helix at 10^5 edges: 311 negative pivots,
    refinement stops at 1e-13), its next ones positive definite near a stable equilibrium: the solve after the
    first refusal of an indefinite matrix refined to within LDLT_RETRY_BELOW tries LDL^T again (before:
    LDLT_RETRY_AFTER solves went to dgbsv). (At n = 60 refinement reaches 1e-16: the threshold is set below that
    for the refusal.)"""
    rng = np.random.default_rng(5)
    n, b = 60, 10
    B = random_band(n, b, rng, 0.0)
    B[0, 0] = 1e-8                                 # indefinite, a small first pivot: growth
    rhs = rng.standard_normal(n)
    work = BandLDLT(n, b)
    c0 = counts()
    monkeypatch.setattr(linalg, "LDLT_BACKWARD_ERROR", 1e-30)
    band_solve(dense_to_band(B, b, b), b, b, np.arange(n), rhs, ldlt=work)
    monkeypatch.setattr(linalg, "LDLT_BACKWARD_ERROR", 1e-15)
    assert delta(c0) == {"ldlt": 0, "dgbsv": 1, "ldlt_refused": 1} and work.negatives > 0
    assert work.skip == 0
    A = random_band(n, b, rng, 3.0 * b)            # positive definite
    c0 = counts()
    x, info = band_solve(dense_to_band(A, b, b), b, b, np.arange(n), rhs, ldlt=work)
    assert info == 0 and delta(c0) == {"ldlt": 1, "dgbsv": 0, "ldlt_refused": 0} and work.accepted
    assert np.allclose(A @ x, rhs, atol=1e-12 * np.abs(A).max() * np.abs(x).max())
    assert work.refusals == 0


def test_the_factor_lives_in_the_spare_rows_of_the_band():
    """band_solve's LDL^T keeps L in the kl spare rows of the general-band storage (dgbsv's fill-in rows): no
    second n x kl array (320 MB at 10^6 edges). The band's matrix rows are untouched, so a second right-hand side
    is solved with the same factors (band_resolve), and a refused matrix still goes to dgbsv correctly."""
    from der.linalg import band_resolve

    rng = np.random.default_rng(6)
    n, b = 90, 10
    A = random_band(n, b, rng, 3.0 * b)
    ab = dense_to_band(A, b, b)
    matrix_rows = ab[b:, :].copy()
    work = BandLDLT(n, b)
    r1, r2 = rng.standard_normal(n), rng.standard_normal(n)
    x1, info = band_solve(ab, b, b, np.arange(n), r1, ldlt=work)
    assert info == 0 and work.accepted
    assert np.shares_memory(work.L, ab) and np.array_equal(ab[b:, :], matrix_rows)
    assert np.array_equal(work.L, ab[:b, :].T)
    x2 = band_resolve(ab, b, b, np.arange(n), r2, work)
    assert np.allclose(A @ x1, r1, atol=1e-12) and np.allclose(A @ x2, r2, atol=1e-12)
    # the same solution as a separate factor gives, bitwise
    linalg.LDLT_IN_BAND = False
    try:
        y1, _ = band_solve(dense_to_band(A, b, b), b, b, np.arange(n), r1, ldlt=BandLDLT(n, b))
    finally:
        linalg.LDLT_IN_BAND = True
    assert np.array_equal(x1, y1)


def test_newton_solve_of_a_rod_uses_ldlt_and_keeps_its_inertia():
    """A clamped helix (symmetric Newton matrix up to the frame-transport term): the implicit solver's band
    solves are accepted LDL^T ones, and system.ldlt holds the last factorisation."""
    import der
    from der.solvers.system import build_system, evaluate_system, newton_steps, prepare_state, residual_vector

    rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1.0, 60), 0.67, 1.0)
    scene = der.Scene(rod, constraints=[der.clamp("start"), der.clamp("end")])
    system = build_system(scene, der.SolverOptions())
    state = prepare_state(system, rod.rest_state())
    evaluate_system(system, state, 2)
    c0 = counts()
    step = newton_steps(system, state, residual_vector(system))
    assert step is not None
    assert BAND_SOLVES["ldlt"] - c0["ldlt"] == 1
    assert system.ldlt.accepted and system.ldlt.negatives == 0     # the rest state is stable
