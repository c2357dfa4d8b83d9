"""Discretisation (issue 11, items 13-14): natural twist must not soften bending; torsion at the ends."""
from dataclasses import replace

import numpy as np
import pytest
from helpers import Evaluator, moved
from test_solvers import elastica_tip, fitted_order

import der
from der import diagnostics as dg


def twisted_straight(L, n, turns, A1=1.0, A2=0.8):
    """A straight rod along z with ``n`` edges whose material frame turns ``turns`` times over [0, L]: natural
    twist omega0 = 2 pi turns / L, natural curvature zero."""
    x = der.shapes.straight(L, n, axis=(0, 0, 1)).positions
    xi_edges = np.arange(n) * L / (n - 1)          # edge midpoints run from 0 to L
    om = 2 * np.pi * turns / L
    d = np.stack([np.cos(om * xi_edges), np.sin(om * xi_edges), 0 * xi_edges], 1)
    return der.rod_from_shape(der.shapes.Shape(x, False, d), A1, A2)


def cantilever_tip(rod, force, torque=0.0, tol=1e-12):
    loads = [der.end_force(force)] + ([der.end_torque(torque, follower=True)] if torque else [])
    res = der.solve(der.Scene(rod, loads=loads, constraints=[der.clamp("start")]), tol=tol)
    assert res.converged
    x = res.state.positions
    return 0.5 * (x[-1] + x[-2]), res


def test_natural_twist_is_measured_and_the_rest_state_is_force_free():
    rod = twisted_straight(1.0, 12, 3)
    assert np.allclose(rod.twist_bar, 6 * np.pi / 11)          # omega0 h, about 1.7 rad per edge
    assert np.abs(rod.kappa_bar_edges).max() == 0.0
    _, g, _, _ = Evaluator(der.Scene(rod))(rod.rest_state())
    assert np.abs(g).max() < 1e-12
    # a coarse helix twisting 1.2 rad per edge: the two edge sides see different natural curvatures, each
    # measured with the energy's kernel, so the rest state stays force-free
    rod = der.rod_from_shape(der.shapes.helix(1.0, 3.0, 2.0, 12), 1.0, 1.5)
    side_e, side_f = rod.kappa_bar_edges[:, 0], rod.kappa_bar_edges[:, 1]
    assert np.abs(side_e - side_f).max() > 0.1 * np.abs(side_e).max()
    assert np.allclose(rod.kappa_bar, 0.5 * (side_e + side_f), rtol=0, atol=1e-15)
    _, g, _, _ = Evaluator(der.Scene(rod))(rod.rest_state())
    assert np.abs(g).max() < 1e-12


@pytest.mark.parametrize("turns", [0.5, 3.0])
def test_bending_energy_of_a_bent_twisted_rod_does_not_depend_on_its_natural_twist(turns):
    """A naturally straight rod bent into an arc of curvature k: E_bend = A1/2 k^2 L to O(h^2), identically for
    a naturally twisted rod (the old frame average gave A1 cos^2(omega0 h / 2) instead)."""
    L, n, k = 1.0, 16, 0.3
    energies = []
    for tw in (0.0, turns):
        rod = twisted_straight(L, n, tw)
        base = rod.rest_state()
        xi = rod.xi_nodes
        q = base.q.copy()
        X = q.reshape(-1, 4)
        X[:, 0], X[:, 2] = (1 - np.cos(k * xi)) / k, np.sin(k * xi) / k     # an arc in the x-z plane
        state = moved(rod, base, q)
        energies.append(Evaluator(der.Scene(rod, energies=("bend",)))(state, 0)[0])
    assert energies[1] == pytest.approx(energies[0], rel=1e-13)
    assert energies[0] == pytest.approx(0.5 * k ** 2 * L, rel=(1.0 / n) ** 2)


def test_twisted_cantilever_bends_exactly_like_an_untwisted_one():
    """omega0 L = 6 pi (three turns of natural twist): under a tip load the tip deflects as for an untwisted rod
    to round-off at equal n, so both converge at second order with the same error constant to P L^3 / (3 A1).
    Before the per-edge bending the twisted rod was softer by 1/cos^2(omega0 h / 2) - 1 (0.098 at n = 32)."""
    L, A1, P = 1.0, 1.0, 1e-4
    exact = P * L ** 3 / (3 * A1)
    ns = np.array([8, 16, 32])
    errors = {0.0: [], 3.0: []}
    for n in ns:
        tips = {}
        for turns in errors:
            tips[turns], _ = cantilever_tip(twisted_straight(L, n, turns, A1), [P, 0.0, 0.0])
            errors[turns].append(tips[turns][0] / exact - 1)
        assert abs(tips[3.0][0] / tips[0.0][0] - 1) < 1e-10
        assert np.abs(tips[3.0] - tips[0.0]).max() < 1e-12 * L
    e0, e3 = np.abs(errors[0.0]), np.abs(errors[3.0])
    assert fitted_order(ns, e3) >= 1.9
    assert np.allclose(e3 * ns ** 2, e0 * ns ** 2, rtol=1e-6)


def test_twisted_cantilever_large_deflection_against_the_elastica():
    load = 3.0
    x_ref, z_ref = elastica_tip(load)
    ns = np.array([20, 40])
    errors = {}
    for turns in (0.0, 3.0):
        errors[turns] = np.array([np.hypot(*(cantilever_tip(twisted_straight(1.0, n, turns), [load, 0, 0],
                                                            tol=1e-10)[0][[0, 2]] - [x_ref, z_ref]))
                                  for n in ns])
    assert np.allclose(errors[3.0], errors[0.0], rtol=1e-6)
    assert fitted_order(ns, errors[3.0]) >= 1.8


def test_twisted_cantilever_in_3d_with_an_end_torque_matches_the_untwisted_one():
    """A spatial deformation (a skew tip force and a follower end torque: bending, twist and their coupling
    through the reference twist): the centreline and the twist beyond the natural one are the same."""
    n, turns = 16, 3.0
    out = {}
    for tw in (0.0, turns):
        rod = twisted_straight(1.0, n, tw)
        tip, res = cantilever_tip(rod, [0.8, 0.5, 0.0], torque=0.6, tol=1e-11)
        prof = dg.profile(rod, res.state)
        out[tw] = (res.state.positions.copy(), dg.material_twist_density(rod, res.state) - rod.twist_bar / rod.voronoi,
                   np.hypot(prof["Mn"], prof["Mb"]))
    (x0, m0, M0), (x3, m3, M3) = out[0.0], out[turns]
    assert np.abs(x0 - x0[0]).max() > 0.3                       # a large deflection
    assert np.abs(x3 - x0).max() < 1e-9
    assert np.abs(m3 - m0).max() < 1e-8 * np.abs(m0).max()
    assert np.abs(M3 - M0).max() < 1e-8 * np.abs(M0).max()


def test_bending_moment_of_a_twisted_cantilever_is_the_beam_moment():
    """The diagnostic moment uses the energy's per-edge curvatures: |M_bend| = P (L - xi) to O(h^2) for a small
    tip load, naturally twisted or not (with the frame average it was cos(omega0 h / 2) of that)."""
    L, P = 1.0, 1e-4
    for n in (16, 32):
        rod = twisted_straight(L, n, 3.0)
        _, res = cantilever_tip(rod, [P, 0.0, 0.0])
        prof = dg.profile(rod, res.state)
        beam = P * (L - prof["xi"])
        assert np.abs(np.hypot(prof["Mn"], prof["Mb"]) - beam).max() < 2.0 * P * (1.0 / n) ** 2


def test_with_natural_and_the_per_edge_natural_curvatures():
    rod = der.rod_from_shape(der.shapes.helix(1.0, 1.5, 1.0, 9), 1.0, 1.0)
    nv = rod.n_vertices
    # (n_vertices, 2) and scalars: both edge sides
    a = rod.with_natural(kappa_bar=rod.kappa_bar * 2.0)
    assert np.array_equal(a.kappa_bar_edges[:, 0], a.kappa_bar_edges[:, 1])
    assert np.allclose(a.kappa_bar, 2.0 * rod.kappa_bar, rtol=1e-15)
    z = rod.with_natural(kappa_bar=0)
    assert np.abs(z.kappa_bar_edges).max() == 0.0 and z.kappa_bar.shape == (nv, 2)
    # (n_vertices, 2, 2): the sides apart
    b = rod.with_natural(kappa_bar=rod.kappa_bar_edges * 0.5)
    assert np.allclose(b.kappa_bar_edges, 0.5 * rod.kappa_bar_edges, rtol=1e-15)
    assert np.allclose(b.kappa_bar, 0.5 * rod.kappa_bar, rtol=1e-15)
    t = rod.with_natural(twist_bar=0.0)
    assert t.kappa_bar_edges is rod.kappa_bar_edges
    with pytest.raises(ValueError, match=r"\(8, 2, 2\)"):
        rod.with_natural(kappa_bar=np.zeros((nv + 1, 2, 2)))
    with pytest.raises(ValueError, match=r"shape \(8, 2\).*got shape \(9, 2\)"):
        rod.with_natural(kappa_bar=np.zeros((nv + 1, 2)))
    # replacing kappa_bar alone leaves the per-edge values stale: refused, not silently ignored
    stale = replace(rod, kappa_bar=rod.kappa_bar * 2.0)
    with pytest.raises(ValueError, match="with_natural"):
        der.solve(der.Scene(stale))
    # a Rod without per-edge values (built directly): kappa_bar on both sides
    plain = replace(rod, kappa_bar_edges=None)
    assert np.array_equal(plain.natural_curvature_edges(), np.stack([rod.kappa_bar] * 2, axis=1))


def _variable_pitch_helix(n):
    """r(u) = (cos u, sin u, 0.3 u + 0.25 u^2), u in [0, 3]: curvature and torsion vary along it."""
    u = np.linspace(0.0, 3.0, n + 1)
    x = np.stack([np.cos(u), np.sin(u), 0.3 * u + 0.25 * u ** 2], -1)
    d1 = np.stack([-np.sin(u), np.cos(u), 0.3 + 0.5 * u], -1)
    d2 = np.stack([-np.cos(u), -np.sin(u), 0.5 + 0 * u], -1)
    d3 = np.stack([np.sin(u), -np.cos(u), 0 * u], -1)
    c = np.cross(d1, d2)
    tau = np.einsum("ij,ij->i", c, d3) / np.einsum("ij,ij->i", c, c)
    return der.shapes.Shape(x, False, None), tau


def test_torsion_is_second_order_at_every_vertex_ends_included():
    """The vertex next to an end used a one-sided difference (first order there); now every vertex converges
    at second order to the exact torsion, on a variable-pitch helix and on a uniform one."""
    ns = np.array([20, 40, 80])
    end_err, all_err = [], []
    for n in ns:
        shape, tau = _variable_pitch_helix(n)
        rod = der.rod_from_shape(shape, 1.0, 1.0)
        err = np.abs(dg.torsion(rod, rod.rest_state()) - tau[rod.vertex_nodes[:, 1]])
        end_err.append(max(err[0], err[-1]))
        all_err.append(err.max())
    assert fitted_order(ns, end_err) >= 1.9
    assert fitted_order(ns, all_err) >= 1.9
    for n in (20, 40):
        rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1.0, n), 1.0, 1.0)
        err = np.abs(dg.torsion(rod, rod.rest_state()) - 0.6)
        assert err.max() <= 1.02 * err[1:-1].max()
    # too few vertices to extrapolate: the end values are undefined, never made up
    rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 0.3, 4), 1.0, 1.0)
    om = dg.torsion(rod, rod.rest_state())
    assert np.isnan(om[0]) and np.isnan(om[-1]) and np.isfinite(om[1:-1]).all()


def test_greenhill_stability_does_not_depend_on_natural_twist():
    """Both ends clamped, the far end sliding along the axis and turned by phi (Greenhill; threshold 8.9868
    A1/A2): the lowest eigenvalue of the straight state is the same with three turns of natural twist. With the
    frame average the twisted rod lost stability about 10% early at this n (8.00 instead of 8.91)."""
    n = 40
    lams = {}
    for turns in (0.0, 3.0):
        rod = twisted_straight(1.0, n, turns, A1=1.0, A2=1.0)
        state = rod.rest_state()
        for phi in (3.0, 6.0, 8.5):
            R = np.array([[np.cos(phi), -np.sin(phi), 0], [np.sin(phi), np.cos(phi), 0], [0, 0, 1.0]])
            scene = der.Scene(rod, constraints=[der.clamp("start"), der.clamp("end", rotation=R, slide=2)])
            res = der.solve(scene, state=state, tol=1e-11)
            assert res.converged
            state = res.state
        lams[turns] = res.min_eigenvalue
    assert lams[0.0] > 0
    assert lams[3.0] == pytest.approx(lams[0.0], rel=1e-6)
