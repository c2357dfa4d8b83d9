"""The sampled (smooth) contact barrier, der/contact/sampled.py: derivatives against finite differences, the
offset lemma (sample distances above off_s keep the centrelines more than off apart) on random pieces, the exact
point CCD against dense sampling of the trajectories, and the bad input of der.self_contact(samples=...)."""
import numpy as np
import pytest

from der.contact import sampled as S
from der.contact.distance import segment_distance2


def two_strands(rng, n=4, gap=0.7, tilt=0.02):
    """Two nearly parallel open strands of n nodes (n - 1 edges each), 0.7 apart, slightly perturbed."""
    a = np.stack([np.linspace(0, 1, n), np.zeros(n), np.zeros(n)], 1)
    b = np.stack([np.linspace(0.1, 1.1, n), tilt * np.linspace(0, 1, n), gap + np.zeros(n)], 1)
    pos = np.vstack([a, b]) + 0.01 * rng.standard_normal((2 * n, 3))
    e = n - 1
    edges = np.array([[i, i + 1] for i in range(e)] + [[n + i, n + i + 1] for i in range(e)], dtype=np.int64)
    pairs = np.array([[i, j] for i in range(e) for j in range(e, 2 * e)], dtype=np.int64)
    owns = np.zeros(2 * e, dtype=np.int64)
    owns[e - 1] = owns[2 * e - 1] = 1
    return pos, edges, pairs, owns


def evaluate(pos, edges, pairs, owns, order, project, m=3, r=0.3, dhat=0.2, kappa=2.0):
    ne = edges.shape[0]
    er, el = np.full(ne, r), np.full(ne, 1.0 / 3.0)      # rest lengths: constants
    nd = pos.size
    g = np.zeros(nd)
    k = 144 * pairs.shape[0]
    rows, cols, vals = np.empty(k, np.int64), np.empty(k, np.int64), np.empty(k)
    out = S.sampled_system(pos, edges, pairs, er, el, owns, m, dhat, kappa, order, project,
                           3 * np.arange(pos.shape[0], dtype=np.int64), g, rows, cols, vals)
    H = np.zeros((nd, nd))
    np.add.at(H, (rows[:out[2]], cols[:out[2]]), vals[:out[2]])
    return out, g, H


def test_sampled_barrier_derivatives_match_finite_differences():
    rng = np.random.default_rng(1)
    pos, edges, pairs, owns = two_strands(rng)
    out, g, H = evaluate(pos, edges, pairs, owns, 2, False)
    assert out[4] > 10                    # many sample pairs active
    x0, eps = pos.ravel(), 1e-6
    e0 = lambda x: evaluate(x.reshape(-1, 3), edges, pairs, owns, 0, False)[0][0]   # noqa: E731
    g1 = lambda x: evaluate(x.reshape(-1, 3), edges, pairs, owns, 1, False)[1]      # noqa: E731
    I = np.eye(x0.size)
    g_fd = np.array([(e0(x0 + eps * d) - e0(x0 - eps * d)) / (2 * eps) for d in I])
    H_fd = np.array([(g1(x0 + eps * d) - g1(x0 - eps * d)) / (2 * eps) for d in I])
    assert np.abs(g - g_fd).max() <= 1e-7 * np.abs(g).max()
    assert np.abs(H - H_fd).max() <= 1e-7 * np.abs(H).max()
    assert np.abs(H - H.T).max() <= 1e-12 * np.abs(H).max()
    # the exact Hessian has the negative transverse stiffness of compressed contacts; the projected one is PSD
    _, _, Hp = evaluate(pos, edges, pairs, owns, 2, True)
    assert np.linalg.eigvalsh(H).min() < -1e-3 * np.abs(H).max()
    assert np.linalg.eigvalsh(Hp).min() >= -1e-12 * np.abs(Hp).max()


def test_offset_lemma_on_random_pieces():
    """Pieces [p, p'] (length la) and [q, q'] (lb) whose end-to-end distances are all >= d are at least
    sqrt(d^2 - (la^2 + lb^2) / 4) apart; the bound is attained by two pieces crossing at right angles."""
    rng = np.random.default_rng(2)
    worst = np.inf
    for _ in range(20000):
        x = rng.normal(size=12) * rng.choice([0.1, 1.0, 3.0])
        p, p1, q, q1 = x[0:3], x[3:6], x[6:9], x[9:12]
        d = min(np.linalg.norm(a - b) for a in (p, p1) for b in (q, q1))
        la, lb = np.linalg.norm(p1 - p), np.linalg.norm(q1 - q)
        bound2 = d * d - 0.25 * (la * la + lb * lb)
        worst = min(worst, segment_distance2(x) - bound2)
    assert worst >= -1e-12
    x = np.array([-1.0, 0, 0, 1, 0, 0, 0, -1, 0.5, 0, 1, 0.5])        # crossing at right angles, 0.5 apart
    d2 = 1.0 + 1.0 + 0.25
    assert segment_distance2(x) == pytest.approx(d2 - 0.25 * (4.0 + 4.0), rel=1e-14)
    assert S.sample_offset(0.5, 2.0, 2.0, 1) == pytest.approx(np.sqrt(d2), rel=1e-14)


def test_sample_ccd_keeps_a_tenth_of_every_sample_gap():
    rng = np.random.default_rng(3)
    pos, edges, pairs, owns = two_strands(rng)
    ne = edges.shape[0]
    er, el = np.full(ne, 0.3), np.full(ne, 1.0 / 3.0)
    m = 3
    taus = []
    for trial in range(30):
        dpos = rng.normal(size=pos.shape) * (0.2 if trial % 2 else 2.0)
        tau, k = S.sampled_ccd(pos, dpos, edges, pairs, er, el, owns, m, 0.1)
        assert 0.0 < tau <= 1.0
        taus.append(tau)
        for ea, eb in pairs:
            off_s = S.sample_offset(er[ea] + er[eb], el[ea], el[eb], m)
            for ia in range(m + owns[ea]):
                for ib in range(m + owns[eb]):
                    al, be = ia / m, ib / m
                    w0 = (1 - al) * pos[edges[ea, 0]] + al * pos[edges[ea, 1]] - (1 - be) * pos[edges[eb, 0]] \
                        - be * pos[edges[eb, 1]]
                    dw = (1 - al) * dpos[edges[ea, 0]] + al * dpos[edges[ea, 1]] - (1 - be) * dpos[edges[eb, 0]] \
                        - be * dpos[edges[eb, 1]]
                    g0 = np.linalg.norm(w0) - off_s
                    t = np.linspace(0.0, tau, 2001)
                    g = np.linalg.norm(w0[None] + t[:, None] * dw[None], axis=1) - off_s
                    assert g.min() >= 0.1 * g0 * (1 - 1e-9)
    assert min(taus) < 0.5          # some steps were cut


def test_self_contact_samples_bad_input():
    import der

    for bad in (0, -1, 65, 2.5, True, "3"):
        with pytest.raises(ValueError, match="samples"):
            der.self_contact(0.05, samples=bad)
    assert der.self_contact(0.05, samples=2).samples == 2
    rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.5)
    scene = der.Scene(rod, constraints=[der.clamp("start")], contacts=[der.self_contact(0.01, samples=2)])
    with pytest.raises(ValueError, match="explicit"):
        der.solve(scene, solver="explicit")


def test_sampled_self_contact_supercoiled_ring_keeps_lk_and_the_distance():
    """The naturally straight ring twisted to twice Michell's threshold (as tests/test_explicit_contact.py), solved
    with the sampled barrier: it writhes into self-contact without passage (Lk = twist / 2 pi), its centrelines
    stay more than 2r apart, and its writhe and energies are those of the segment barrier's equilibrium to within
    the models' difference (the sampled offset exceeds 2r by at most (l_a^2 + l_b^2) / (8 r) ~ 0.004 here)."""
    import der
    from der import diagnostics as dg

    from test_explicit_contact import R, _twisted_ring

    rod, twist, start = _twisted_ring()
    seg = der.solve(der.Scene(rod, contacts=[der.self_contact(R)]), state=start, stability=False, tol=1e-8)
    smp = der.solve(der.Scene(rod, contacts=[der.self_contact(R, samples=4)]), state=start, stability=False,
                    tol=1e-8)
    assert seg.converged and smp.converged
    lk, _, wr = dg.linking_number(rod, smp.state)
    assert lk == pytest.approx(twist / (2 * np.pi), abs=1e-6)
    assert smp.contact["n_contacts"] > 0 and smp.contact["min_distance"] > 2 * R
    assert wr == pytest.approx(dg.linking_number(rod, seg.state)[2], abs=0.05)
    assert smp.energy["bend"] == pytest.approx(seg.energy["bend"], rel=0.05)
