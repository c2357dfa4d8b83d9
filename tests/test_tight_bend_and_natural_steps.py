"""A start bent tighter than the contact radius: refused for a user's start, solved on (with a TightBendWarning)
for a continuation's steps, whose starts are the model's own equilibria; the continuation's condensation of the
contact Hessian on sliding supports; natural continuation on a fixed grid with an imperfection hook; the
tightest bend reported by the contact diagnostics and the PyElastica side-by-side tool (against closed forms)."""
import os
import sys
import warnings

import numpy as np
import pytest

import der
from der.continuation import condensed_triplets
from der.solvers import SolverOptions
from der.solvers.system import build_system, prepare_state

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
R = 0.05


def _kinked():
    """A rod of 20 edges along z, its upper half turned by 90 degrees about the kink (a right angle at one
    vertex: radius of curvature h / 2 = 0.0263 < r = 0.05 there), clamped at its start."""
    rod = der.rod_from_shape(der.shapes.straight(1.0, 20), 1.0, 1.5)
    x = rod.rest_state().positions
    k = 10
    dx = np.zeros_like(x)
    dx[k + 1:, 0] = x[k + 1:, 2] - x[k, 2]
    dx[k + 1:, 2] = x[k, 2] - x[k + 1:, 2]
    state = rod.displaced(rod.rest_state(), dx)
    scene = der.Scene(rod, constraints=[der.clamp("start")], contacts=[der.self_contact(R)])
    return rod, state, scene


def test_a_user_start_bent_tighter_than_r_is_refused():
    rod, state, scene = _kinked()
    radius, v = der.terms.contact.min_curvature_radius(rod, state)
    h = rod.l_bar[0]
    assert radius == pytest.approx(h / 2, rel=1e-9)          # kappa = 2 tan(45 deg) / h
    with pytest.raises(ValueError, match=r"radius of curvature 0\.0263.* at vertex 9, not larger than the radius 0\.05"):
        der.solve(scene, state=state)
    with pytest.raises(ValueError, match="tight_bend must be one of"):
        SolverOptions(tight_bend="ignore")


def test_a_continuation_step_bent_tighter_than_r_is_solved_on_with_a_warning():
    rod, state, scene = _kinked()
    with pytest.warns(der.TightBendWarning, match=r"radius of curvature 0\.0263.* at vertex 9"):
        result = der.solve(scene, state=state, options=SolverOptions(tight_bend="warn"), stability=False)
    assert result.converged
    # a clamped rod without loads relaxes to straight: no bend left, and the diagnostics say so
    assert result.contact["terms"][0]["min_curvature_radius"] > 1e3


def test_condensed_contact_triplets_are_T_transpose_H_T():
    """der.continuation condenses the contact Hessian's triplets on a sliding clamp's dependent DOFs (it refused
    active contact with sliding clamps or pins before): against the dense T^T H T."""
    rod = der.rod_from_shape(der.shapes.straight(1.0, 12), 1.0, 1.5)
    for end in (der.clamp("end", slide=2), der.hinge("end")):
        scene = der.Scene(rod, constraints=[der.clamp("start"), end])
        system = build_system(scene, SolverOptions())
        prepare_state(system, rod.rest_state())
        lk = system.links
        n = rod.n_dof
        T = np.eye(n)
        T[lk.tri_dep, lk.tri_dep] = 0.0
        np.add.at(T, (lk.tri_dep, lk.tri_master), lk.tri_coef)
        H = np.random.default_rng(1).normal(size=(n, n))
        H = H + H.T
        r, c = np.nonzero(H)
        rr, cc, vv = condensed_triplets(system, r, c, H[r, c])
        Hc = np.zeros((n, n))
        np.add.at(Hc, (rr, cc), vv)
        free = ~system.fixed
        ref = (T.T @ H @ T)[np.ix_(free, free)]
        assert np.abs(Hc[np.ix_(free, free)] - ref).max() <= 1e-12 * np.abs(ref).max()


def test_natural_continuation_on_a_fixed_grid_with_an_imperfection():
    """method='natural', dp: the points lie on the grid p0 + k dp and end on p_end; perturb is called once per
    step with the step's parameter; with a unique equilibrium the last-point and secant predictors agree."""
    rod = der.rod_from_shape(der.shapes.straight(1.0, 16), 1.0, 1.5)

    def scene_of(f):
        return der.Scene(rod, loads=[der.end_force([f, 0.0, 0.0])], constraints=[der.clamp("start")])

    called = []

    def perturb(p, state):
        called.append(p)
        return None

    tip = {"tip": lambda scene, st: float(st.positions[-1, 0])}
    a = der.continuation(scene_of, 0.0, 1.0, method="natural", dp=0.25, predictor="last", perturb=perturb,
                         stability=False, summaries=tip, tol=1e-10)
    b = der.continuation(scene_of, 0.0, 1.0, method="natural", dp=0.25, stability=False, summaries=tip, tol=1e-10)
    assert a.status == "completed" and [pt["p"] for pt in a.points] == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert called == [0.25, 0.5, 0.75, 1.0]
    assert np.allclose([pt["tip"] for pt in a.points], [pt["tip"] for pt in b.points], rtol=0, atol=1e-8)
    # small loads: the tip deflection F L^3 / 3 A1 (L the distance of the end cross-section from the clamp)
    assert a.points[1]["tip"] == pytest.approx(0.25 / 3, rel=0.05)
    with pytest.raises(ValueError, match="options of method='natural'"):
        der.continuation(scene_of, 0.0, 1.0, dp=0.25)


def test_side_by_side_tightest_bend_of_a_polygon_arc():
    """The tool's tightest bend (the same code for both codes): on a regular polygon inscribed in a circle of
    radius a, kappa = 2 tan(phi / 2) / h with h = 2 a sin(phi / 2), i.e. a radius a cos(phi / 2)."""
    sys.path.insert(0, os.path.join(ROOT, "tools"))
    import bench_plectoneme_pyelastica as b

    a, n = 0.2, 40
    phi = np.pi / n
    s = np.arange(n + 1) * phi
    x = np.stack([np.zeros_like(s), a * np.sin(s), a * (1 - np.cos(s))], axis=1)     # a half circle in y-z
    t = np.diff(x, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    d1 = np.tile([1.0, 0.0, 0.0], (n, 1))
    frames = np.stack([d1, np.cross(t, d1), t], axis=1)
    q = b.end_quantities(x, frames)
    assert q["min_curvature_radius"] == pytest.approx(a * np.cos(phi / 2), rel=1e-12)
    assert q["twist"] == pytest.approx(0.0, abs=1e-12)
