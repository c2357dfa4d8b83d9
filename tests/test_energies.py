"""Energy kernels against finite differences, invariants and rest states (issue 2)."""
import numpy as np
import pytest
from helpers import Evaluator, free_mask, moved, perturbed_state, shapes_for_tests

import der
from der.geometry import add_transport_jacobian
from der.linalg import band_layout, band_to_sparse, new_band

TERMS = ["stretch", "bend", "twist"]
SHAPES = shapes_for_tests()


def _rel(a, b):
    return np.abs(a - b).max() / max(np.abs(b).max(), 1e-300)


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("term", TERMS)
def test_gradient_matches_central_differences(shape, term):
    rng = np.random.default_rng(hash((shape, term)) % 2 ** 32)
    rod = der.rod_from_shape(SHAPES[shape], 1.3, 0.7, EA=40.0)
    state = perturbed_state(rod, rng)
    state.lam = 0.3 * rng.standard_normal(rod.n_edges)
    ev = Evaluator(der.Scene(rod, energies=(term,)))
    _, g, _, _ = ev(state)
    h = 1e-6
    fd = np.zeros_like(g)
    for i in np.flatnonzero(free_mask(rod)):
        qp, qm = state.q.copy(), state.q.copy()
        qp[i] += h
        qm[i] -= h
        fd[i] = (ev(moved(rod, state, qp), 0)[0] - ev(moved(rod, state, qm), 0)[0]) / (2 * h)
    assert _rel(g, fd) < 1e-6


def _transport_term(rod, state, g):
    kl, ku, perm = band_layout(rod.n_nodes, rod.closed)
    ab = new_band(rod.n_dof, kl, ku)
    add_transport_jacobian(state.q, rod.edge_nodes, g[3::4][: rod.n_edges].copy(), ab, kl, ku, perm)
    return band_to_sparse(ab, kl, ku, perm).toarray()


def _energies(term):
    """A scene's energies: one term, or "all" three (the assembly's fused vertex pass, ``energies.vertex``)."""
    return tuple(TERMS) if term == "all" else (term,)


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("term", TERMS + ["all"])
def test_hessian_matches_second_differences_of_energy(shape, term):
    """The symmetric energy Hessian: u^T H v against 5-point second differences of E along straight rays."""
    rng = np.random.default_rng(1 + hash((shape, term)) % 2 ** 32)
    rod = der.rod_from_shape(SHAPES[shape], 1.3, 0.7, EA=40.0)
    state = perturbed_state(rod, rng)
    state.lam = 0.3 * rng.standard_normal(rod.n_edges)
    ev = Evaluator(der.Scene(rod, energies=_energies(term)))
    _, g, _, K = ev(state, 2)
    H = K - _transport_term(rod, state, g)
    free = free_mask(rod)
    assert np.abs(H - H.T).max() <= 1e-12 * np.abs(H).max()

    def d2(w, h=1e-3):
        E = [ev(moved(rod, state, state.q + k * h * w), 0)[0] for k in (-2, -1, 0, 1, 2)]
        return (-E[0] + 16 * E[1] - 30 * E[2] + 16 * E[3] - E[4]) / (12 * h * h)

    for _ in range(4):
        u = rng.standard_normal(rod.n_dof) * free
        v = rng.standard_normal(rod.n_dof) * free
        fd = (d2(u + v) - d2(u - v)) / 4
        scale = max(abs(u @ H @ u), abs(v @ H @ v))
        assert abs(u @ H @ v - fd) < 1e-6 * scale


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("term", ["bend", "twist", "all"])
def test_force_jacobian_matches_differences_of_transported_gradient(shape, term):
    """K = d(gradient)/dq with frames parallel-transported along the step: Hessian + frame-transport term ("all":
    the three terms in one vertex pass, the transport term added inside it)."""
    rng = np.random.default_rng(2 + hash((shape, term)) % 2 ** 32)
    rod = der.rod_from_shape(SHAPES[shape], 1.3, 0.7)
    state = perturbed_state(rod, rng)
    ev = Evaluator(der.Scene(rod, energies=_energies(term)))
    _, g, _, K = ev(state, 2)
    free = np.flatnonzero(free_mask(rod))
    h = 1e-6
    J = np.zeros((rod.n_dof, rod.n_dof))
    for i in free:
        qp, qm = state.q.copy(), state.q.copy()
        qp[i] += h
        qm[i] -= h
        J[:, i] = (ev(moved(rod, state, qp))[1] - ev(moved(rod, state, qm))[1]) / (2 * h)
    Kf, Jf = K[np.ix_(free, free)], J[np.ix_(free, free)]
    assert _rel(Kf, Jf) < 1e-6
    # the transport term is what makes it non-symmetric away from theta-equilibrium
    assert np.abs(Kf - Kf.T).max() > 1e-3 * np.abs(Kf).max()


@pytest.mark.parametrize("follower", [False, True])
def test_torque_load_and_its_stiffness(follower):
    rng = np.random.default_rng(5)
    rod = der.rod_from_shape(SHAPES["helix"], 1.0, 1.0)
    state = perturbed_state(rod, rng)
    load = der.end_torque(0.7, follower=True) if follower else der.end_torque([0.3, -0.5, 0.8])
    ev = Evaluator(der.Scene(rod, energies=(), loads=[load]))
    _, _, f, K = ev(state, 2)
    # power of the torque for a small motion = tau . (rotation of the end material frame)
    j = rod.n_edges - 1
    t = state.tangents[j]
    assert f[4 * j + 3] == pytest.approx(0.7 if follower else np.dot([0.3, -0.5, 0.8], t), rel=1e-12)
    # load stiffness = -d f_ext / dq
    h = 1e-6
    J = np.zeros_like(K)
    for i in np.flatnonzero(free_mask(rod)):
        qp, qm = state.q.copy(), state.q.copy()
        qp[i] += h
        qm[i] -= h
        J[:, i] = -(ev(moved(rod, state, qp))[2] - ev(moved(rod, state, qm))[2]) / (2 * h)
    assert np.abs(J - K).max() <= 1e-6 * max(np.abs(K).max(), 1.0)


@pytest.mark.parametrize("shape", SHAPES)
def test_energy_invariant_under_rigid_motion(shape):
    rng = np.random.default_rng(7)
    rod = der.rod_from_shape(SHAPES[shape], 1.3, 0.7, EA=40.0)
    state = perturbed_state(rod, rng)
    ev = Evaluator(der.Scene(rod))
    E0 = ev(state, 0)[0]
    axis = rng.standard_normal(3)
    axis /= np.linalg.norm(axis)
    ang = 1.1
    Kx = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + np.sin(ang) * Kx + (1 - np.cos(ang)) * Kx @ Kx
    moved_state = state.copy()
    moved_state.positions[:] = state.positions @ R.T + np.array([3.0, -2.0, 5.0])
    moved_state.d1[:] = state.d1 @ R.T
    moved_state.tangents[:] = state.tangents @ R.T
    assert ev(moved_state, 0)[0] == pytest.approx(E0, rel=1e-12, abs=1e-14)


@pytest.mark.parametrize("shape", SHAPES)
def test_internal_forces_have_zero_net_force_and_torque(shape):
    rng = np.random.default_rng(8)
    rod = der.rod_from_shape(SHAPES[shape], 1.3, 0.7, EA=40.0)
    state = perturbed_state(rod, rng, amplitude=0.1)
    _, g, _, _ = Evaluator(der.Scene(rod))(state)
    gx = g.reshape(-1, 4)[:, :3]
    gt = g.reshape(-1, 4)[: rod.n_edges, 3]
    scale = np.abs(g).max() * rod.length
    assert np.abs(gx.sum(axis=0)).max() < 1e-12 * np.abs(g).max() * rod.n_nodes
    torque = np.cross(state.positions, gx).sum(axis=0) + (gt[:, None] * state.tangents).sum(axis=0)
    assert np.abs(torque).max() < 1e-12 * scale * rod.n_nodes


@pytest.mark.parametrize("turns", [1, 2, 5, 20])
@pytest.mark.parametrize("omega0", [0.6, -0.6, 3.0])
def test_rest_helices_have_zero_gradient(turns, omega0):
    rod = der.rod_from_shape(der.shapes.helix(1.0, omega0, turns, 12 * turns), 1.0, 1.5)
    _, g, _, _ = Evaluator(der.Scene(rod))(rod.rest_state())
    assert np.abs(g).max() < 1e-12


@pytest.mark.parametrize("shape", [der.shapes.arc(1.0, 4.0, 30), der.shapes.ring(2.0, 40),
                                   der.shapes.straight(1.0, 10)])
def test_rest_arc_ring_straight_have_zero_gradient(shape):
    rod = der.rod_from_shape(shape, 1.0, 1.5)
    E, g, _, _ = Evaluator(der.Scene(rod))(rod.rest_state())
    # bending and twisting are measured on the rest shape by the kernels themselves: exactly zero. The stretching
    # is formed exactly from the edges (issue 17), and the rest lengths are doubles, the rest edges' lengths
    # rounded: at most eps l of elongation per edge, an energy of order (c A1 / l^3) (eps l)^2 / 2 (1e-30 here)
    eps = np.finfo(float).eps
    assert 0.0 <= E <= float(np.sum(0.5 * 10.0 / rod.l_bar ** 3 * (eps * rod.l_bar) ** 2))
    assert np.abs(g).max() < 1e-12


def test_natural_curvature_and_twist_of_a_helix():
    """Interior vertices of a discrete helix: natural curvature (kappa0 D, 0) and twist omega0 D to O(h^2)."""
    for n in (40, 80):
        rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1.0, n), 1.0, 1.5)
        D = rod.voronoi[5:-5]
        assert np.allclose(rod.kappa_bar[5:-5, 0] / D, 1.0, atol=2 * (6.0 / n) ** 2)
        assert np.abs(rod.kappa_bar[5:-5, 1]).max() < 1e-12
        assert np.allclose(rod.twist_bar[5:-5] / D, 0.6, atol=2 * (6.0 / n) ** 2)


def _per_edge_cases():
    """Rods whose two edge sides differ: strong natural twist (1.7 rad per edge), and a helix given random,
    unequal natural curvatures on the two sides of each vertex."""
    from test_discretisation import twisted_straight

    rng = np.random.default_rng(11)
    helix = der.rod_from_shape(der.shapes.helix(1.0, 2.0, 1.0, 9), 1.3, 0.7, EA=40.0)
    return {
        "twisted_straight": twisted_straight(1.0, 8, 2.0, 1.3, 0.7),
        "helix_random_sides": helix.with_natural(kappa_bar=0.3 * rng.standard_normal((helix.n_vertices, 2, 2))),
    }


@pytest.mark.parametrize("case", ["twisted_straight", "helix_random_sides"])
def test_per_edge_bending_gradient_and_hessian_match_differences(case):
    rod = _per_edge_cases()[case]
    rng = np.random.default_rng(12)
    state = perturbed_state(rod, rng, amplitude=0.1)
    ev = Evaluator(der.Scene(rod, energies=("bend",)))
    E, g, _, K = ev(state, 2)
    assert E > 0
    free = free_mask(rod)
    h = 1e-6
    fd = np.zeros_like(g)
    for i in np.flatnonzero(free):
        qp, qm = state.q.copy(), state.q.copy()
        qp[i] += h
        qm[i] -= h
        fd[i] = (ev(moved(rod, state, qp), 0)[0] - ev(moved(rod, state, qm), 0)[0]) / (2 * h)
    assert _rel(g, fd) < 1e-6
    H = K - _transport_term(rod, state, g)
    assert np.abs(H - H.T).max() <= 1e-12 * np.abs(H).max()
    J = np.zeros_like(K)
    for i in np.flatnonzero(free):
        qp, qm = state.q.copy(), state.q.copy()
        qp[i] += h
        qm[i] -= h
        J[:, i] = (ev(moved(rod, state, qp))[1] - ev(moved(rod, state, qm))[1]) / (2 * h)
    fi = np.flatnonzero(free)
    assert _rel(K[np.ix_(fi, fi)], J[np.ix_(fi, fi)]) < 1e-6
