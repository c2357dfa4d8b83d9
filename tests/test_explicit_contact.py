"""Contact in the explicit solver (issue 14): FIRE with barrier forces and CCD-proven steps reaches the implicit
solver's self-contact equilibrium (a naturally straight ring twisted to twice Michell's threshold writhes into
self-contact), Lk = twist / 2 pi and the strands stay more than 2r apart after every kernel call, and what it
cannot do is refused with a clear message."""
import numpy as np
import pytest

import der
from der import closed_forms as cf
from der import diagnostics as dg

A1, A2 = 1.0, 1.0 / 0.67
R = 0.05


def _twisted_ring(n=40, factor=2.0):
    base = der.rod_from_shape(der.shapes.ring(1.0, n), A1, A2)
    base = base.with_natural(kappa_bar=base.kappa_bar * 0.0)        # naturally straight, closed into a ring
    twist = factor * cf.michell_twist(A1, A2)
    rod = base.with_imposed_twist(twist)
    x0 = rod.rest_q.reshape(-1, 4)[:, :3]
    phi = np.arctan2(x0[:, 1], x0[:, 0])
    dx = np.zeros_like(x0)
    dx[:, 2] = 0.05 * (np.cos(2 * phi) + np.sin(3 * phi))
    start = rod.displaced(rod.rest_state(), dx, twist * np.arange(n) / n)
    return rod, twist, start


def test_explicit_reaches_the_implicit_self_contact_equilibrium_and_conserves_lk(monkeypatch):
    import der.solvers.explicit_contact as ec

    rod, twist, start = _twisted_ring()
    scene = der.Scene(rod, contacts=[der.self_contact(R)])
    implicit = der.solve(scene, state=start, stability=False, tol=1e-8)
    ec.warmup()     # the warm-up's own explicit solve (a 24-edge ring) must not reach the watcher below
    seen = []
    run = ec.ContactRun.run

    def watching(self, plan, q, q_lo, d1, *args):
        out = run(self, plan, q, q_lo, d1, *args)
        x = q + q_lo        # the compensated positions, as one array
        state = der.RodState(x, d1.copy(), np.zeros_like(d1), args[1].copy())
        state.tangents[:] = der.geometry.tangents(x, rod.edge_nodes)
        seen.append((dg.linking_number(rod, state)[0], self.term.diagnostics(state)["min_distance"]))
        return out

    monkeypatch.setattr(ec.ContactRun, "run", watching)
    explicit = der.solve(scene, state=start, solver="explicit", stability=False, tol=1e-6)
    assert implicit.converged and explicit.converged
    assert len(seen) >= 3
    lk = twist / (2 * np.pi)
    for lk_i, d_i in seen:
        assert lk_i == pytest.approx(lk, abs=1e-6)        # no strand passage at any kernel call
        assert d_i > 2 * R
    # the same equilibrium (the ring's shape may slide along itself: compare what does not depend on that)
    lk_e, tw_e, wr_e = dg.linking_number(rod, explicit.state)
    lk_i, tw_i, wr_i = dg.linking_number(rod, implicit.state)
    assert lk_e == pytest.approx(lk, abs=1e-6) and lk_i == pytest.approx(lk, abs=1e-6)
    assert wr_i > 1.5                                      # it writhed into self-contact
    assert wr_e == pytest.approx(wr_i, abs=1e-4)
    for term in ("bend", "twist", "contact"):
        assert explicit.energy[term] == pytest.approx(implicit.energy[term], rel=1e-4)
    ci, ce = implicit.contact, explicit.contact
    assert ci["n_contacts"] > 0 and ce["n_contacts"] == ci["n_contacts"]
    assert ce["min_distance"] == pytest.approx(ci["min_distance"], abs=1e-6)
    assert ce["total_force"] == pytest.approx(ci["total_force"], rel=1e-3)
    assert "refused by CCD" in explicit.message


def test_explicit_refuses_obstacles_and_several_rods():
    rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=A1, A2=A2)
    floor = der.Scene(rod, constraints=[der.clamp("end")], contacts=[der.plane([0, 0, -1], [0, 0, 1], radius=0.01)])
    with pytest.raises(ValueError, match="implicit"):
        der.solve(floor, solver="explicit")
    two = der.Scene([rod, rod], contacts=[der.rod_contact(0.01)])
    with pytest.raises(ValueError, match="implicit"):
        der.solve(two, solver="explicit")


def test_gradient_only_barrier_and_the_step_bound_agree_with_pair_barrier_and_ccd():
    """The explicit contact kernel's per-step shortcuts: ``pair_barrier_gradient`` is ``pair_barrier`` without the
    Hessian (bitwise the same energy, gap and gradient), ``barrier_gradient`` (which skips pairs farther than dhat
    by their bounding spheres) sums to the same force and returns a lower bound of every pair's gap, and whenever
    ``step_bound_safe`` accepts a step without CCD, CCD proves it too (tau = 1)."""
    from der.contact.barrier import GAP, pair_barrier
    from der.contact.ccd import pairs_ccd
    from der.contact.distance import segment_distance2
    from der.solvers.explicit_contact import (MIN_GAP_FRACTION, barrier_gradient, pair_barrier_gradient,
                                              step_bound_safe)

    rng = np.random.default_rng(3)
    r, dhat, kappa = 0.05, 0.02, 7.0
    g_ref, H, g = np.empty(12), np.empty((12, 12)), np.empty(12)
    active = 0
    for _ in range(3000):
        x = rng.normal(size=12) * 0.15
        e_ref, z_ref = pair_barrier(x, 2 * r, dhat, kappa, GAP, False, g_ref, H)
        g[:] = 0.0
        e, z = pair_barrier_gradient(x, 2 * r, dhat, kappa, g)
        assert z == z_ref and (e == e_ref or (np.isinf(e) and np.isinf(e_ref)))
        if 0.0 < e_ref < np.inf:
            active += 1
            assert np.array_equal(g, g_ref)
    assert active > 50
    # a random polyline: all non-neighbour pairs, the summed barrier and the gap bound
    n_nodes = 30
    pos = np.cumsum(rng.normal(size=(n_nodes, 3)) * 0.06, axis=0)
    q = np.zeros(4 * n_nodes)
    q.reshape(-1, 4)[:, :3] = pos
    edges = np.column_stack([np.arange(n_nodes - 1), np.arange(1, n_nodes)])
    pairs = np.array([(a, b) for a in range(n_nodes - 1) for b in range(a + 2, n_nodes - 1)])
    radius = np.full(n_nodes - 1, 0.01)
    gaps = []
    for a, b in pairs:
        xab = np.concatenate([pos[edges[a, 0]], pos[edges[a, 1]], pos[edges[b, 0]], pos[edges[b, 1]]])
        gaps.append(np.sqrt(segment_distance2(xab)) - 0.02)
    keep = np.array(gaps) > 0
    pairs = pairs[keep]
    grad = np.zeros_like(q)
    energy, min_gap = barrier_gradient(q, edges, pairs, radius, 0.05, kappa, grad)
    ref = np.zeros_like(q)
    e_ref = 0.0
    for a, b in pairs:
        nodes = [edges[a, 0], edges[a, 1], edges[b, 0], edges[b, 1]]
        xab = np.concatenate([pos[k] for k in nodes])
        e, _ = pair_barrier(xab, 0.02, 0.05, kappa, GAP, False, g_ref, H)
        if e > 0:
            e_ref += e
            for k, nd in enumerate(nodes):
                ref[4 * nd:4 * nd + 3] += g_ref[3 * k:3 * k + 3]
    assert energy == pytest.approx(e_ref, rel=1e-13) and e_ref > 0
    assert np.allclose(grad, ref, rtol=1e-13, atol=1e-13 * np.abs(ref).max())
    assert min_gap <= min(np.array(gaps)[keep]) + 1e-15
    proven = 0
    lo = np.zeros_like(q)
    for scale in np.geomspace(1e-4, 1.0, 40):
        dpos = rng.normal(size=(n_nodes, 3)) * scale * min_gap
        q_new = q.copy()
        q_new.reshape(-1, 4)[:, :3] += dpos
        if step_bound_safe(q_new, lo, q, lo, n_nodes, min_gap, MIN_GAP_FRACTION):
            proven += 1
            tau, _, _ = pairs_ccd(pos, dpos, edges, pairs, radius, MIN_GAP_FRACTION, 1e-6, 10000)
            assert tau == 1.0
    assert proven >= 5
