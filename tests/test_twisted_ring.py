"""Twisted rings (issue 7): the weld in the kernels, writhe, linking number, Michell's threshold."""
import argparse

import numpy as np
import pytest
from helpers import Evaluator, free_mask, moved, perturbed_state
from test_scenarios import load, run

import der
from der import closed_forms as cf
from der import diagnostics as dg


def welded_ring(n=9, twist=2.3, kappa0_scale=1.0):
    rod = der.rod_from_shape(der.shapes.ring(1.0, n), 1.3, 0.7, EA=40.0)
    return rod.with_natural(kappa_bar=rod.kappa_bar * kappa0_scale).with_imposed_twist(twist)


@pytest.mark.parametrize("term", ["bend", "twist"])
@pytest.mark.parametrize("kappa0_scale", [0.0, 1.0])
def test_welded_ring_gradient_and_hessian_match_differences(term, kappa0_scale):
    rng = np.random.default_rng(7)
    rod = welded_ring(kappa0_scale=kappa0_scale)
    state = perturbed_state(rod, rng, twist=0.5)
    ev = Evaluator(der.Scene(rod, energies=(term,)))
    _, g, _, K = ev(state, 2)
    free = np.flatnonzero(free_mask(rod))
    h = 1e-6
    fd = np.zeros_like(g)
    for i in free:
        qp, qm = state.q.copy(), state.q.copy()
        qp[i] += h
        qm[i] -= h
        fd[i] = (ev(moved(rod, state, qp), 0)[0] - ev(moved(rod, state, qm), 0)[0]) / (2 * h)
    assert np.abs(g - fd).max() < 1e-6 * np.abs(fd).max()
    # the force Jacobian: differences of the gradient with frames transported along the step
    for i in free[::3]:
        qp, qm = state.q.copy(), state.q.copy()
        qp[i] += h
        qm[i] -= h
        col = (ev(moved(rod, state, qp))[1] - ev(moved(rod, state, qm))[1]) / (2 * h)
        assert np.abs(K[:, i] - col).max() < 1e-5 * max(np.abs(K).max(), 1.0)


def test_a_full_turn_weld_is_a_winding_of_the_reference_twist():
    """Welding after a whole turn leaves the cross-sections where they were: the bending energy is that of
    the unwelded ring and the twisting energy that of one whose reference twist at the weld wound once more."""
    rod = welded_ring(n=12, twist=0.0)
    state = perturbed_state(rod, np.random.default_rng(3), twist=0.4)
    turned = rod.with_imposed_twist(2 * np.pi)
    for term in ("bend", "twist"):
        e0, g0, _, K0 = Evaluator(der.Scene(rod, energies=(term,)))(state, 2)
        wound = state.copy()
        if term == "twist":
            wound.reference_twist[0] += 2 * np.pi
        e1, g1, _, K1 = Evaluator(der.Scene(turned, energies=(term,)))(wound if term == "bend" else state, 2)
        e2 = Evaluator(der.Scene(rod, energies=(term,)))(wound, 0)[0]
        if term == "bend":
            assert abs(e1 - e0) < 1e-12 * e0 and np.abs(g1 - g0).max() < 1e-12 * np.abs(g0).max()
        else:
            assert abs(e1 - e2) < 1e-12 * e2 and e2 > 2 * e0
    # and a weld that is not a whole turn is seen by the bending of a naturally curved ring
    curved = welded_ring(n=12, twist=0.0)
    e = [Evaluator(der.Scene(curved.with_imposed_twist(w), energies=("bend",)))(state, 0)[0] for w in (0.0, 1.0)]
    assert abs(e[1] - e[0]) > 1e-3 * e[0]


def test_imposed_twist_needs_a_ring():
    rod = der.rod_from_shape(der.shapes.arc(1.0, 2.0, 10), 1.0, 1.0)
    with pytest.raises(ValueError, match="closed ring"):
        rod.with_imposed_twist(1.0)
    with pytest.raises(ValueError, match="writhe"):
        dg.writhe(rod, rod.rest_state())


def _torus_knot(N, p=2, q=3, R=2.0, r=0.7):
    t = 2 * np.pi * np.arange(N) / N
    x = np.stack([(R + r * np.cos(q * t)) * np.cos(p * t), (R + r * np.cos(q * t)) * np.sin(p * t),
                  r * np.sin(q * t)], axis=1)
    dx = np.stack([-q * r * np.sin(q * t) * np.cos(p * t) - (R + r * np.cos(q * t)) * p * np.sin(p * t),
                   -q * r * np.sin(q * t) * np.sin(p * t) + (R + r * np.cos(q * t)) * p * np.cos(p * t),
                   q * r * np.cos(q * t)], axis=1)
    return x, dx


def _gauss_quadrature(N):
    """Writhe of the smooth trefoil by the periodic trapezoidal rule on the Gauss integral (an independent
    method: smooth tangents, no polygon, no solid angles)."""
    x, dx = _torus_knot(N)
    d = x[:, None, :] - x[None, :, :]
    num = (np.cross(dx[:, None, :], dx[None, :, :]) * d).sum(-1)
    den = np.linalg.norm(d, axis=-1) ** 3
    np.fill_diagonal(den, np.inf)
    return (num / den).sum() * (2 * np.pi / N) ** 2 / (4 * np.pi)


def test_writhe_of_a_planar_ring_is_zero_and_of_a_trefoil_matches_quadrature():
    rod = der.rod_from_shape(der.shapes.ring(1.0, 40), 1.0, 1.0)
    assert dg.writhe(rod, rod.rest_state()) == 0.0
    reference = _gauss_quadrature(3000)
    assert abs(reference - _gauss_quadrature(1500)) < 1e-5   # the quadrature has converged
    errors = []
    for n in (200, 400):
        x, _ = _torus_knot(n)
        errors.append(abs(dg._writhe(x) - reference))
    assert errors[0] < 5e-3 and errors[1] < errors[0] / 3   # the polygon's writhe converges at second order
    # a mirror image has the opposite writhe; a rigid motion keeps it
    x, _ = _torus_knot(200)
    assert dg._writhe(x * [1, 1, -1]) == pytest.approx(-dg._writhe(x), abs=1e-12)
    c, s = np.cos(0.7), np.sin(0.7)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    assert dg._writhe(x @ rot.T + [0.3, -2.0, 1.0]) == pytest.approx(dg._writhe(x), abs=1e-12)


def test_linking_number_is_conserved_through_buckling(tmp_path):
    """A naturally curved ring welded with 3/4 turn starts planar and writhes: Lk = 3/4 at every iteration."""
    from der.recording import Recorder, read_scalars

    p = argparse.Namespace(A1=1.0, A2=1 / 0.67, a0=1.0, kappa0=None, n=60)
    mod = load("twisted_ring")
    base, _ = mod.make_rod(p)
    rod = base.with_imposed_twist(1.5 * np.pi)
    state = mod.start_state(rod, base.rest_state(), 0.0, 1.5 * np.pi, 0.0, 1.0)
    path = str(tmp_path / "ring.rrd")
    # every iteration (max_overhead=None: no frame skipped to bound the recording's cost)
    result = der.solve(der.Scene(rod), state=state, record=Recorder(path, rod, max_overhead=None))
    its, lk = read_scalars(path, "ring/linking_number")
    _, wr = read_scalars(path, "ring/writhe")
    assert its == list(range(result.iterations + 1))   # one row per iteration
    assert np.abs(lk - 0.75).max() < 1e-10
    assert abs(wr[0]) < 1e-12 and wr[-1] > 0.7            # it went from planar to strongly writhed
    assert result.stable


def test_strand_passage_of_a_naturally_straight_ring_is_reported():
    """Without self-contact the writhed ring passes through itself: Lk jumps by exactly 2, and it is said."""
    out = run("twisted_ring", 60, kappa0=0.0, twist=8.0, perturb=0.01)
    assert out["strand_passage_at"] == 8.0 and "no self-contact" in out["note"]
    assert abs(abs(out["linking_number"] - 8.0 / (2 * np.pi)) - 2.0) < 1e-10


def test_planar_twisted_ring_has_uniform_twist():
    out = run("twisted_ring", 40, kappa0=0.0, twist=5.0)
    assert out["error"] < 1e-12 and out["writhe"] == 0.0 and out["out_of_plane"] < 1e-12
    assert out["twist_strain_spread"] < 1e-10 and out["stable"]


@pytest.mark.parametrize("ratio", [0.5, 0.67, 1.0, 1.5])
def test_michell_threshold(ratio):
    out = run("twisted_ring", 200, kappa0=0.0, A1=1.0, A2=1.0 / ratio, sweep=6)
    michell = cf.michell_twist(1.0, 1.0 / ratio)
    assert out["threshold_located_by"].startswith("der.continuation") and out["threshold_kind"] == "bifurcation"
    assert abs(out["threshold_twist"] - michell) < 0.01 * michell
    # stable below, unstable above, on the planar branch
    before = [s for s in out["sweep"] if s["twist"] < michell]
    after = [s for s in out["sweep"] if s["twist"] > 1.01 * michell]
    assert before and after and all(s["stable"] for s in before) and not any(s["stable"] for s in after)


def test_naturally_curved_ring_writhes_into_a_doubly_covered_circle_at_one_turn():
    """kappa0 = 1/a0: no planar branch and no threshold up to Lk = 1, where the ring is a circle of radius
    a0/2 covered twice (Tw = 0, Wr = 1) with bending energy pi A1 / a0 (kappa = 2/a0 against kappa0 = 1/a0)."""
    out = run("twisted_ring", 120, twist=2 * np.pi, sweep=8)
    sweep = out["sweep"]
    assert all(s["stable"] for s in sweep) and out["threshold_twist"] is None
    assert all(s["out_of_plane"] > 0.02 for s in sweep[:-1])      # out of plane at once
    # at Lk = 1 exactly the two strands of the doubled circle coincide: Wr is +1 or, past the touching, -1
    # with Lk = -1 (a strand passage, which der, without self-contact, cannot prevent)
    last = sweep[-1]
    assert abs(abs(last["writhe"]) - 1.0) < 1e-3 and abs(last["twist_total"]) < 1e-3
    assert last["energy"] == pytest.approx(np.pi, rel=5e-3)
    assert all(abs(s["lk_error"]) < 1e-10 for s in sweep[:-1])


def test_twisted_ring_rejects_bad_input():
    mod = load("twisted_ring")
    for bad in ({"kappa0": -1.0}, {"perturb": 0.7}, {"sweep": -2}, {"locate": 3}):
        p = argparse.Namespace(**{**{q[0]: q[1] for q in mod.PARAMETERS}, "n": 20, **bad})
        with pytest.raises(ValueError):
            mod.run.validate(p)
