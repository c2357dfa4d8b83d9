"""Issue 14 performance pieces: the reordered banded contact solve, the Verlet list of the self-contact broad
phase, and the independent ring calculation's gradient (tools/ring_contact_check.py). Small n, no timings."""
import os
import sys

import numpy as np
import pytest

import der
from der.contact.reorder import banded_solve, bandwidths, block_order
from der.contact.samples import plectoneme_polyline
from der.linalg import band_layout, band_to_coo, new_band

ROOT = os.path.join(os.path.dirname(__file__), "..")


def _band_plus_contact(n_nodes, closed, seed):
    """A random band (der's layout) with a dominant diagonal plus 12x12 blocks coupling the nodes of
    plectoneme-like edge pairs (i with n - i)."""
    rng = np.random.default_rng(seed)
    kl, ku, perm = band_layout(n_nodes, closed)
    n = 4 * n_nodes
    ab = new_band(n, kl, ku)
    off = kl + ku
    for j in range(n):
        for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
            ab[off + i - j, j] = rng.standard_normal()
        ab[off, j] += 40.0
    rows, cols, vals = [], [], []
    m = n_nodes - 1
    for a in range(2, m // 2 - 3, 2):
        b = m - 1 - a
        d = np.array([4 * k + c for k in (a, a + 1, b, b + 1) for c in range(3)])
        M = rng.standard_normal((12, 5))
        H = M @ M.T
        rows.append(np.repeat(d, 12))
        cols.append(np.tile(d, 12))
        vals.append(H.ravel())
    return ab, kl, ku, perm, np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)


@pytest.mark.parametrize("closed", [False, True])
def test_reordered_banded_solve_equals_a_dense_solve(closed):
    import scipy.sparse as sp

    ab, kl, ku, perm, rows, cols, vals = _band_plus_contact(60, closed, 3)
    n = ab.shape[1]
    rb, cb, vb = band_to_coo(ab, kl, ku, perm)
    A = sp.csr_matrix((np.concatenate([vb, vals]), (np.concatenate([rb, rows]), np.concatenate([cb, cols]))),
                      shape=(n, n)).toarray()
    rhs = np.random.default_rng(4).standard_normal(n)
    newpos, kl2, ku2 = block_order(ab, kl, ku, perm, rows, cols)
    assert sorted(newpos) == list(range(n))
    x, info = banded_solve(ab, kl, ku, perm, rows, cols, vals, rhs, newpos, kl2, ku2)
    assert info == 0
    assert np.allclose(x, np.linalg.solve(A, rhs), rtol=1e-10, atol=1e-12)
    # a bandwidth computed for another ordering is what that ordering needs (the solver's reuse test)
    assert bandwidths(kl, ku, perm, rows, cols, newpos) == (kl2, ku2)
    # the ladder of a plectoneme is far narrower in RCM order than in the DOF order
    ident = np.arange(n, dtype=np.int64)
    assert sum(bandwidths(kl, ku, perm, rows, cols, ident)) > 2 * (kl2 + ku2)


def _symmetric(ab, kl, ku, perm, shift):
    """The band made symmetric (its lower triangle mirrored) plus shift on the diagonal."""
    n = ab.shape[1]
    off = kl + ku
    inv = np.argsort(perm)
    for j in range(n):
        for i in range(j + 1, min(n - 1, j + kl) + 1):
            ab[off + j - i, i] = ab[off + i - j, j]      # A[inv i, inv j] -> A[inv j, inv i]
        ab[off, j] += shift
    return ab


@pytest.mark.parametrize("shift, cholesky", [(60.0, True), (-60.0, False)])
def test_reordered_banded_cholesky_solve_equals_a_dense_solve(shift, cholesky):
    """The symmetric path of the reordered contact band (LAPACK's banded Cholesky, refined against the whole
    matrix): a symmetric positive definite band plus PSD pair blocks is solved by it to the dense solution; an
    indefinite one is refused and solved by dgbsv, just as correctly, and the next solves go to dgbsv directly."""
    import scipy.sparse as sp

    from der.contact.reorder import CHOLESKY_RETRY_AFTER, BandCholesky

    ab, kl, ku, perm, rows, cols, vals = _band_plus_contact(60, False, 5)
    ab = _symmetric(ab, kl, ku, perm, shift)
    n = ab.shape[1]
    rb, cb, vb = band_to_coo(ab, kl, ku, perm)
    A = sp.csr_matrix((np.concatenate([vb, vals]), (np.concatenate([rb, rows]), np.concatenate([cb, cols]))),
                      shape=(n, n)).toarray()
    assert np.allclose(A, A.T)
    assert (np.linalg.eigvalsh(A).min() > 0) == cholesky
    rhs = np.random.default_rng(6).standard_normal(n)
    newpos, kl2, ku2 = block_order(ab, kl, ku, perm, rows, cols)
    chol = BandCholesky()
    x, info = banded_solve(ab, kl, ku, perm, rows, cols, vals, rhs, newpos, kl2, ku2, chol)
    assert info == 0
    assert np.allclose(x, np.linalg.solve(A, rhs), rtol=1e-10, atol=1e-12)
    assert chol.counts == ({"cholesky": 1, "dgbsv": 0, "cholesky_refused": 0} if cholesky else
                           {"cholesky": 0, "dgbsv": 1, "cholesky_refused": 1})
    banded_solve(ab, kl, ku, perm, rows, cols, vals, rhs, newpos, kl2, ku2, chol)
    assert chol.skip == (0 if cholesky else CHOLESKY_RETRY_AFTER - 1)


def test_contact_solve_paths_agree_on_a_supercoiled_ring():
    """The twisted ring of scenarios/twisted_ring.py in self-contact (a closed rod: der's interleaved band
    layout) solved with the banded (RCM) contact path and with splu: the same equilibrium (energy, writhe, contacts;
    a free ring's iterates differ along its rigid-body modes, which the pseudo-time term barely fixes)."""
    from der import diagnostics as dg

    import argparse

    import der.solvers.implicit as implicit

    sys.path.insert(0, os.path.join(ROOT, "scenarios"))
    from twisted_ring import make_rod, start_state

    base, _ = make_rod(argparse.Namespace(a0=1.0, n=48, A1=1.0, A2=1.0 / 0.67, kappa0=0.0))
    state, welded = base.rest_state(), 0.0
    for tw in (4.0, 8.0):
        rod = base.with_imposed_twist(tw)
        r = der.solve(der.Scene(rod, contacts=[der.self_contact(0.05)]), state=start_state(rod, state, welded, tw, 0.01, 1.0),
                      stability=False)
        state, welded = r.state, tw
    assert r.contact["n_contacts"] > 0
    rod = base.with_imposed_twist(9.0)
    out = {}
    for banded in (True, False):
        implicit.BANDED_CONTACT = banded
        try:
            r = der.solve(der.Scene(rod, contacts=[der.self_contact(0.05)]), state=start_state(rod, state, 8.0, 9.0, 0.0, 1.0),
                          stability=False)
        finally:
            implicit.BANDED_CONTACT = True
        assert r.converged and r.linear_solves["sparse"] > 0
        out[banded] = (sum(r.energy.values()), dg.linking_number(rod, r.state)[2], r.contact["n_contacts"])
    assert out[True][0] == pytest.approx(out[False][0], rel=1e-7)
    assert out[True][1] == pytest.approx(out[False][1], abs=1e-6)
    assert out[True][2] == out[False][2]


def _line(n):
    """An open rod laid out as a plectoneme-like polyline whose strands are well apart (for the broad phase)."""
    x = plectoneme_polyline(n, h=0.25, rho=0.5, pitch=0.1)
    rod = der.rod_from_shape(der.shapes.straight(0.25 * n, n), 1.0, 1.5, EA=1e4)
    return rod, rod.displaced(rod.rest_state(), x - x[0] - rod.rest_state().positions)


def test_verlet_list_holds_every_pair_within_dhat():
    """The self-contact term's reused candidate list (built within dhat + margin) holds every pair a fresh broad
    phase finds within dhat, for moves up to the margin's reuse limit, and is rebuilt beyond it."""
    from der.contact import candidate_pairs

    rod, start = _line(120)
    scene = der.Scene(rod, constraints=[der.clamp("start")], contacts=[der.self_contact(0.45)])
    from der.solvers.options import SolverOptions
    from der.solvers.system import build_system, prepare_state

    system = build_system(scene, SolverOptions())
    state = prepare_state(system, start)
    term = system.terms[0]
    pos = term.positions(state)
    term.candidates(pos)
    assert term.broad_phases == 1
    rng = np.random.default_rng(0)
    limit = 0.5 * term.margin / np.sqrt(3.0)
    for _ in range(20):
        moved = pos + rng.uniform(-limit, limit, pos.shape) * 0.999
        listed = {tuple(p) for p in term.candidates(moved)}
        fresh = {tuple(p) for p in candidate_pairs(moved, term.topo, term.dhat)}
        gaps_fresh = term._pair_data(moved, np.array(sorted(fresh)))[0] if fresh else np.array([])
        within = {p for p, g in zip(sorted(fresh), gaps_fresh) if g < term.dhat}
        assert within <= listed
    assert term.broad_phases == 1            # all reused
    term.candidates(pos + 2 * term.margin)
    assert term.broad_phases == 2            # moved beyond the margin: rebuilt


@pytest.mark.parametrize("samples", [None, 4])
def test_long_step_list_holds_every_pair_within_dhat_on_the_step(samples):
    """The pair list of one Newton step (BoundSelfContact.step_candidates, built once for the whole step q -> q + p
    and reused by every line-search trial) holds every pair within range (dhat, plus the sampled barrier's extra)
    at every sampled fraction alpha of the step, by brute force over all non-neighbour pairs -- for short steps
    (filtered from the Verlet list) and long ones (a broad phase with the boxes inflated by each node's reach) --
    and the trials on the step get that list back without another broad phase."""
    from der.contact.broadphase import excluded
    from der.solvers.options import SolverOptions
    from der.solvers.system import build_system, prepare_state

    rod, start = _line(60)
    # r = 0.1: the start is admissible (smallest gap 0.11), the Verlet margin is r
    scene = der.Scene(rod, constraints=[der.clamp("start")], contacts=[der.self_contact(0.1, samples=samples)])
    system = build_system(scene, SolverOptions())
    term = system.terms[0]
    pos = term.positions(prepare_state(system, start))
    topo = term.topo
    m = topo.edges.shape[0]
    every = np.array([(i, j) for i in range(m) for j in range(i + 1, m)
                      if not excluded(i, j, topo.rod_of_edge, topo.local_edge, topo.rod_n_edges, topo.rod_closed,
                                      topo.rod_k)], dtype=np.int64)
    rng_ = term.dhat + term.pair_range_extra
    rng = np.random.default_rng(1)
    seen_in_range = listed_steps = 0

    def check(listed, dpos, alphas):
        nonlocal seen_in_range
        listed_set = {tuple(p) for p in listed}
        assert len(listed_set) == len(listed)
        phases = term.broad_phases
        for alpha in alphas:
            x = pos + alpha * dpos
            gap = term._pair_data(x, every)[0]
            within = {tuple(p) for p in every[gap < rng_]}
            seen_in_range += len(within)
            assert within <= listed_set, (alpha, within - listed_set)
            assert term.candidates(x) is listed           # a trial on the step: the step's list
        assert term.broad_phases == phases

    for size in (0.002, 0.01, 0.03, 0.1, 0.3, 1.0):     # short and long steps
        for _ in range(4):
            dpos = rng.normal(size=pos.shape) * size
            listed, full = term.step_candidates(pos, dpos, ccd=False)
            assert full
            check(listed, dpos, np.linspace(0.0, 1.0, 21))
            # the solver's path: max_step lists the step up to its CCD-safe fraction, where the trials stay
            delta = np.zeros(term.n_dof)
            delta.reshape(-1, 4)[:term.n_nodes, :3] = dpos
            term._step = None
            tau = term.max_step(prepare_state(system, start), delta)
            assert 0.0 < tau <= 1.0
            if term._step is not None:     # (a long step whose safe part is long too: the Verlet list, as before)
                listed_steps += 1
                check(term._step[2], dpos, np.linspace(0.0, tau, 21))
    assert seen_in_range > 0 and listed_steps >= 8
    # the list is narrower than the Verlet list it comes from on a short step
    dpos = rng.normal(size=pos.shape) * 1e-3
    assert len(term.step_candidates(pos, dpos)[0]) < len(term._list[1])


def test_arc_trials_reuse_the_step_list_only_within_its_reach():
    """The second-order-corrected line search's arc trials q + a' delta + a'^2 c (a' <= a) and the chords their
    passage proof checks get the step's pair list back (BoundSelfContact.cover_arc, widened to each node's reach
    a |delta_i| + a^2 |c_i|) without another broad phase, and that list holds every pair within dhat on them, by
    brute force over all non-neighbour pairs -- for short arcs (from the Verlet list) and long ones (a broad
    phase with the boxes inflated by the reach). A state beyond that reach does not get it (fails safe). Fails
    with ARC_STEP_LIST = False (the arc states took the Verlet list or a new broad phase)."""
    from der.contact.broadphase import excluded
    from der.solvers.options import SolverOptions
    from der.solvers.system import build_system, prepare_state

    rod, start = _line(60)
    scene = der.Scene(rod, constraints=[der.clamp("start")], contacts=[der.self_contact(0.1)])
    system = build_system(scene, SolverOptions())
    term = system.terms[0]
    state = prepare_state(system, start)
    pos = term.positions(state)
    topo = term.topo
    m = topo.edges.shape[0]
    every = np.array([(i, j) for i in range(m) for j in range(i + 1, m)
                      if not excluded(i, j, topo.rod_of_edge, topo.local_edge, topo.rod_n_edges, topo.rod_closed,
                                      topo.rod_k)], dtype=np.int64)
    rng = np.random.default_rng(2)
    seen_in_range = 0
    for size in (0.002, 0.01, 0.03, 0.1, 0.3):
        for _ in range(3):
            dpos = rng.normal(size=pos.shape) * size
            cpos = rng.normal(size=pos.shape) * 0.5 * size
            delta = np.zeros(term.n_dof)
            delta.reshape(-1, 4)[:term.n_nodes, :3] = dpos
            term._step = None
            a = term.max_step(state, delta)
            assert 0.0 < a <= 1.0
            assert term.cover_arc(pos, dpos, cpos, a)
            listed = term._step[2]
            listed_set = {tuple(p) for p in listed}
            phases = term.broad_phases
            for frac in (1.0, 0.5, 0.25):
                b = a * frac
                for t in np.linspace(0.0, 1.0, 11):
                    x = pos + t * b * dpos + (t * b) ** 2 * cpos
                    gap = term._pair_data(x, every)[0]
                    within = {tuple(p) for p in every[gap < term.dhat]}
                    seen_in_range += len(within)
                    assert within <= listed_set, (size, b, t, within - listed_set)
                    assert term.candidates(x) is listed
                assert term.candidates(pos, pos + b * dpos + b * b * cpos) is listed     # the proof's chord
            assert term.broad_phases == phases
            # beyond the reach: not this list
            far = pos + 3.0 * (a * dpos + a * a * cpos) + 0.01
            assert term.candidates(far) is not listed
    assert seen_in_range > 0


def test_long_step_trials_reuse_the_swept_list_only_on_the_step():
    """A long step (beyond the Verlet margin) keeps the CCD's swept-box list for its straight trials
    (LONG_STEP_LIST): every trial pos + a delta, a in [0, 1], gets it back without another broad phase and it holds
    every pair within dhat there (brute force); a state off the step does not get it (fails safe). Fails with
    LONG_STEP_LIST = False (each trial took the Verlet list, rebuilt)."""
    from der.contact.broadphase import excluded
    from der.solvers.options import SolverOptions
    from der.solvers.system import build_system, prepare_state

    rod, start = _line(60)
    scene = der.Scene(rod, constraints=[der.clamp("start")], contacts=[der.self_contact(0.1)])
    system = build_system(scene, SolverOptions())
    term = system.terms[0]
    pos = term.positions(prepare_state(system, start))
    topo = term.topo
    m = topo.edges.shape[0]
    every = np.array([(i, j) for i in range(m) for j in range(i + 1, m)
                      if not excluded(i, j, topo.rod_of_edge, topo.local_edge, topo.rod_n_edges, topo.rod_closed,
                                      topo.rod_k)], dtype=np.int64)
    rng = np.random.default_rng(3)
    seen_in_range = 0
    for size in (0.1, 0.3, 1.0):
        for _ in range(3):
            dpos = rng.normal(size=pos.shape) * size
            listed, full = term.step_candidates(pos, dpos)
            assert not full                       # a long step: the CCD's swept boxes
            listed_set = {tuple(p) for p in listed}
            phases = term.broad_phases
            for alpha in np.linspace(0.0, 1.0, 21):
                x = pos + alpha * dpos
                gap = term._pair_data(x, every)[0]
                within = {tuple(p) for p in every[gap < term.dhat]}
                seen_in_range += len(within)
                assert within <= listed_set, (size, alpha, within - listed_set)
                assert term.candidates(x) is listed
            assert term.broad_phases == phases
            off = pos + 0.5 * dpos + 0.01 * rng.normal(size=pos.shape)        # not on the step
            assert term.candidates(off) is not listed
            assert term.candidates(pos + 1.5 * dpos) is not listed           # beyond its end
    assert seen_in_range > 0


def test_independent_ring_energy_gradient_and_writhe():
    sys.path.insert(0, os.path.join(ROOT, "tools"))
    from ring_contact_check import Ring

    ring = Ring(5, 64, 0.3, 2.0)
    rng = np.random.default_rng(1)
    c = np.zeros((10, 3))
    c[0, 0], c[5, 1] = 1.0, 1.0
    c += 0.2 * rng.standard_normal(c.shape)
    g, g_fd = ring.grad(c.ravel(), 1e3), ring.grad_fd(c.ravel(), 1e3)
    assert np.abs(g - g_fd).max() <= 1e-6 * np.abs(g_fd).max()
    assert ring.parts(c.ravel())["overlap"] > 0         # the contact penalty's gradient is exercised
    # a planar circle: bending energy A1 pi / a0 (length 2 pi), writhe 0
    circle = np.zeros((10, 3))
    circle[0, 0], circle[5, 1] = 1.0, 1.0
    p = ring.parts(circle.ravel())
    assert abs(p["bend"] - np.pi) < 1e-10 and abs(p["writhe"]) < 1e-12


def test_plectoneme_side_by_side_end_quantities_of_a_twisted_straight_rod():
    """tools/bench_plectoneme_pyelastica.py judges both codes by the same end quantities: on a straight rod along
    y twisted by 1.25 turns, Tw = 1.25, Wr = 0, Lk = 1.25, the extension is L and no strands come close."""
    sys.path.insert(0, os.path.join(ROOT, "tools"))
    import bench_plectoneme_pyelastica as b

    rod = der.rod_from_shape(der.shapes.straight(b.L, b.N_ELEM), 1.0, 1.5)
    turned = rod.displaced(rod.rest_state(), dtheta=2 * np.pi * 1.25 * (np.arange(rod.n_edges) + 0.5) / rod.n_edges)
    d1, d2, t = b._der_frames(rod, turned)
    P = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]], float)
    frames = np.stack([np.stack(f) for f in zip(d1, d2, t)]) @ P
    q = b.end_quantities(turned.positions @ P, frames)
    assert q["twist"] == pytest.approx(1.25 * (1 - 1 / rod.n_edges), abs=1e-9)
    # node to node: der's polygon is n h long with (n - 1) h = L (its end cross-sections, at the end edges'
    # midpoints, are L apart)
    assert abs(q["writhe"]) < 1e-9 and q["extension"] == pytest.approx(b.L * b.N_ELEM / (b.N_ELEM - 1), rel=1e-9)
    assert q["min_distance"] > 2 * b.R


def test_symmetric_part_of_a_band_in_place():
    """``reorder.symmetric_part`` (the CONTACT_SYMMETRIC measurement, docs/contact.md section 9.6) replaces a general
    band by (A + A^T) / 2 and returns max |A - A^T| / 2."""
    from der.contact.reorder import symmetric_part
    from der.linalg import band_to_coo

    rng = np.random.default_rng(3)
    n, kl = 23, 4
    ab = np.zeros((3 * kl + 1, n), order="F")
    for j in range(n):
        for i in range(max(0, j - kl), min(n - 1, j + kl) + 1):
            ab[2 * kl + i - j, j] = rng.normal()
    perm = np.arange(n, dtype=np.int64)
    r, c, v = band_to_coo(ab, kl, kl, perm)
    A = np.zeros((n, n))
    A[r, c] = v
    skew = symmetric_part(ab, kl, kl)
    r, c, v = band_to_coo(ab, kl, kl, perm)
    S = np.zeros((n, n))
    S[r, c] = v
    assert np.allclose(S, 0.5 * (A + A.T), rtol=0, atol=1e-15)
    assert skew == pytest.approx(0.5 * np.abs(A - A.T).max(), rel=1e-14)


def test_sorted_pairs_is_the_lexicographic_order():
    """The term's pair lists are sorted (der.terms.contact.sorted_pairs, a two-pass counting sort) into exactly
    numpy's lexicographic order, so that every list yields its active pairs in one order."""
    from der.terms.contact import sorted_pairs

    rng = np.random.default_rng(4)
    i = rng.integers(0, 500, 5000)
    p = np.stack([i, i + rng.integers(1, 40, i.size)], axis=1)
    p = np.unique(p, axis=0)[rng.permutation(np.unique(p, axis=0).shape[0])]
    assert np.array_equal(sorted_pairs(p), p[np.lexsort((p[:, 1], p[:, 0]))])
    assert sorted_pairs(np.empty((0, 2), dtype=np.int64)).shape == (0, 2)
