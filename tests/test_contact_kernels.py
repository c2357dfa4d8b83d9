"""Contact kernels (der/contact): distances, barrier, CCD, broad phase and obstacles, each against an
independent check (brute-force sampling, finite differences, exact trajectories, an O(n^2) pair search) and,
where ipctk is installed, against the IPC Toolkit."""
import numpy as np
import pytest

from der.contact import barrier_system, candidate_pairs, safe_step, topology
from der.contact.barrier import (
    GAP, SQUARED, barrier, barrier_first_derivative, barrier_second_derivative, pair_barrier, pair_subspace,
    project_psd_in_subspace,
)
from der.contact.broadphase import brute_force_pairs, edge_boxes, excluded, exclusion_k, hash_grid_pairs
from der.contact.ccd import segment_ccd
from der.contact.samples import min_distance, plectoneme_polyline
from der.contact.distance import (
    EDGE_EDGE, POINT_POINT, S_FREE, T_FREE, closest_parameters, segment_distance2,
    segment_distance2_derivatives,
)
from der.contact.obstacles import (
    CYLINDER, PLANE, SPHERE, edge_obstacle_barrier, edge_obstacle_ccd, edge_obstacle_gap, node_plane_barrier,
)


def sampled_distance2(x, n=401):
    """min over an n x n grid of (s, t) of |a(s) - b(t)|^2 (an upper bound of the exact value)."""
    s = np.linspace(0.0, 1.0, n)
    A = x[0:3] + s[:, None] * (x[3:6] - x[0:3])
    B = x[6:9] + s[:, None] * (x[9:12] - x[6:9])
    return ((A[:, None, :] - B[None, :, :]) ** 2).sum(-1).min()


def special_pairs(rng):
    """Random pairs plus parallel, anti-parallel, collinear, degenerate and intersecting ones."""
    out = [rng.normal(size=12) for _ in range(30)]
    a0, u = rng.normal(size=3), rng.normal(size=3)
    out.append(np.concatenate([a0, a0 + u, a0 + 0.3 * u + [0, 0, 0.5], a0 + 1.8 * u + [0, 0, 0.5]]))   # parallel
    out.append(np.concatenate([a0, a0 + u, a0 + 1.5 * u + [0.1, 0, 0], a0 - 0.5 * u + [0.1, 0, 0]]))   # anti
    out.append(np.concatenate([a0, a0 + u, a0 + 0.5 * u, a0 + 2.0 * u]))                               # collinear
    out.append(np.concatenate([a0, a0 + u, a0 + 2.0 * u, a0 + 3.0 * u]))                               # collinear apart
    out.append(np.concatenate([a0, a0, a0 + [1, 0, 0], a0 + [1, 1, 1]]))                               # a is a point
    out.append(np.concatenate([a0, a0 + u, a0 + [0, 1, 0], a0 + [0, 1, 0]]))                           # b is a point
    out.append(np.concatenate([a0, a0, a0 + [0, 1, 0], a0 + [0, 1, 0]]))                               # two points
    out.append(np.array([-1, 0, 0, 1, 0, 0, 0, -1, 0, 0, 1, 0], dtype=float))                          # crossing
    out.append(np.concatenate([a0, a0 + u, a0 + 0.4 * u + [0, 0, 0.2] + 1e-9 * rng.normal(size=3),
                               a0 + 1.4 * u + [0, 0, 0.2]]))                                            # near-parallel
    return out


def test_distance_against_brute_force_sampling():
    rng = np.random.default_rng(1)
    for x in special_pairs(rng):
        D, s, t, region = closest_parameters(x)
        r = (1 - s) * x[0:3] + s * x[3:6] - (1 - t) * x[6:9] - t * x[9:12]
        assert abs(r @ r - D) <= 1e-12 * max(1.0, D)             # D is attained at (s, t)
        Ds = sampled_distance2(x)
        assert D <= Ds + 1e-12 * max(1.0, Ds)                    # and it is the minimum
        # grid spacing 1/400: the sampled minimum is within the Lipschitz bound of the exact one
        step = (np.linalg.norm(x[3:6] - x[0:3]) + np.linalg.norm(x[9:12] - x[6:9])) / 800
        assert np.sqrt(Ds) - np.sqrt(D) <= step + 1e-12


def fd_gradient(f, x, h=1e-6):
    return np.array([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(len(x))])


def region_pairs(rng):
    """(x, expected region) with random perturbations of a template in each region."""
    cases = []
    for _ in range(4):
        p = 0.05 * rng.normal(size=12)
        cases.append((np.array([-1, 0, 0, 1, 0, 0, 0.2, -1, 0.5, 0.3, 1, 0.6]) + p, EDGE_EDGE))
        cases.append((np.array([0, 0, 0, 1, 0, 0, 0.5, 1, 0.3, 0.5, 2, 0.5]) + p, S_FREE))        # b0 vs a
        cases.append((np.array([0.5, 1, 0.3, 0.5, 2, 0.5, 0, 0, 0, 1, 0, 0]) + p, T_FREE))        # a0 vs b
        cases.append((np.array([0, 0, 0, 1, 0, 0, 2, 1, 0.5, 3, 2, 1]) + p, POINT_POINT))          # a1 vs b0
        # near-parallel (angle ~1e-3), overlapping: interior region with an ill-conditioned 2x2 system
        # (noise only across z: a z tilt of the valley would move the minimum to the boundary)
        q = np.array([0, 0, 0, 1, 0, 0, 0.3, -1e-3, 0.4, 1.3, 1e-3, 0.4])
        q[[0, 1, 3, 4, 6, 7, 9, 10]] += 1e-5 * rng.normal(size=8)
        cases.append((q, EDGE_EDGE))
    return cases


def test_distance_gradient_and_hessian_by_finite_differences_in_each_region():
    rng = np.random.default_rng(2)
    g = np.empty(12)
    H = np.empty((12, 12))
    g2 = np.empty(12)
    H2 = np.empty((12, 12))

    def grad_of(y):
        segment_distance2_derivatives(y, g2, H2)
        return g2.copy()

    for x, expected in region_pairs(rng):
        D, region = segment_distance2_derivatives(x, g, H)
        assert region == expected
        # near-parallel: a large Hessian (~ 1 / angle^2) needs a smaller step against truncation error
        h = 1e-8 if expected == EDGE_EDGE and abs(x[10] - x[7]) < 0.01 else 1e-6
        fg = fd_gradient(segment_distance2, x, h)
        assert np.abs(g - fg).max() <= 1e-7 * max(1.0, np.abs(g).max())
        fH = np.array([(grad_of(x + h * e) - grad_of(x - h * e)) / (2 * h) for e in np.eye(12)])
        assert np.abs(H - fH).max() <= 1e-5 * max(1.0, np.abs(H).max())
        assert np.abs(H - H.T).max() <= 1e-12 * max(1.0, np.abs(H).max())


def test_barrier_scalar_derivatives_and_c2_at_dhat():
    zh = 0.3
    for z in (1e-4, 0.01, 0.1, 0.2999):
        h = 1e-7 * z
        assert barrier(z, zh) > 0
        fd1 = (barrier(z + h, zh) - barrier(z - h, zh)) / (2 * h)
        fd2 = (barrier_first_derivative(z + h, zh) - barrier_first_derivative(z - h, zh)) / (2 * h)
        assert abs(barrier_first_derivative(z, zh) - fd1) <= 1e-6 * max(1.0, abs(fd1))
        assert abs(barrier_second_derivative(z, zh) - fd2) <= 1e-6 * max(1.0, abs(fd2))
    for f in (barrier, barrier_first_derivative, barrier_second_derivative):
        assert abs(f(zh * (1 - 1e-6), zh)) < 1e-5 and f(zh, zh) == 0.0 and f(2 * zh, zh) == 0.0
    assert barrier(0.0, zh) == np.inf


@pytest.mark.parametrize("mode", [GAP, SQUARED])
def test_pair_barrier_derivatives_by_finite_differences(mode):
    rng = np.random.default_rng(3)
    off, dhat, kappa = 0.2, 0.15, 2.0
    g, H, g2, H2 = np.empty(12), np.empty((12, 12)), np.empty(12), np.empty((12, 12))
    n_active = 0
    for x, _ in region_pairs(rng):
        # scale the pair so its distance lies inside the barrier range (off, off + dhat)
        D = segment_distance2(x)
        c = 0.5 * (x[0:3] + x[6:9])
        target = off + dhat * rng.uniform(0.1, 0.9)
        y = x.copy()
        for k in range(4):
            y[3 * k:3 * k + 3] = c + (x[3 * k:3 * k + 3] - c) * target / np.sqrt(D)
        e, z = pair_barrier(y, off, dhat, kappa, mode, False, g, H)
        assert 0 < e < np.inf
        n_active += 1
        fe = fd_gradient(lambda q: pair_barrier(q, off, dhat, kappa, mode, False, g2, H2)[0], y, 1e-7)
        assert np.abs(g - fe).max() <= 1e-5 * max(1.0, np.abs(g).max())

        def grad_of(q):
            pair_barrier(q, off, dhat, kappa, mode, False, g2, H2)
            return g2.copy()

        fH = np.array([(grad_of(y + 1e-7 * e_) - grad_of(y - 1e-7 * e_)) / 2e-7 for e_ in np.eye(12)])
        assert np.abs(H - fH).max() <= 1e-4 * max(1.0, np.abs(H).max())
        # the projected Hessian is PSD and differs from H by a PSD matrix (only negative modes removed)
        Hp = np.empty((12, 12))
        pair_barrier(y, off, dhat, kappa, mode, True, g2, Hp)
        scale = np.abs(H).max()
        assert np.linalg.eigvalsh(Hp).min() >= -1e-10 * scale
        assert np.linalg.eigvalsh(Hp - H).min() >= -1e-10 * scale
        assert np.allclose(g2, g, rtol=0, atol=1e-14 * max(1.0, np.abs(g).max()))
    assert n_active == 20
    # beyond dhat: nothing; inside off: inadmissible
    far = np.array([0, 0, 0, 1, 0, 0, 0, 5, 0, 1, 5, 0], dtype=float)
    assert pair_barrier(far, off, dhat, kappa, GAP, False, g, H)[0] == 0.0 and not g.any()
    touching = np.array([0, 0, 0, 1, 0, 0, 0, 0.1, 0, 1, 0.1, 0], dtype=float)
    assert pair_barrier(touching, off, dhat, kappa, GAP, False, g, H)[0] == np.inf


def test_subspace_psd_projection_equals_full_eigen_clamping():
    """The 5-dim projection equals numpy's eigen-clamping of the whole 12 x 12 pair Hessian, in every region."""
    rng = np.random.default_rng(4)
    off, dhat = 0.2, 0.15
    g, H, Hp, Q = np.empty(12), np.empty((12, 12)), np.empty((12, 12)), np.empty((12, 5))
    n_indefinite = 0
    for x, _ in region_pairs(rng):
        c = 0.5 * (x[0:3] + x[6:9])
        y = c + (x.reshape(4, 3) - c) * (off + 0.5 * dhat) / np.sqrt(segment_distance2(x))
        y = y.ravel()
        for mode in (GAP, SQUARED):
            pair_barrier(y, off, dhat, 1.0, mode, False, g, H)
            k = pair_subspace(y, Q)
            assert np.abs(H - Q[:, :k] @ Q[:, :k].T @ H @ Q[:, :k] @ Q[:, :k].T).max() <= 1e-10 * np.abs(H).max()
            w, V = np.linalg.eigh(H)
            n_indefinite += w[0] < -1e-8 * np.abs(w).max()
            expect = (V * np.clip(w, 0, None)) @ V.T
            pair_barrier(y, off, dhat, 1.0, mode, True, g, Hp)
            assert np.abs(Hp - expect).max() <= 1e-10 * np.abs(expect).max()
    assert n_indefinite > 10
    # a PSD matrix in the subspace is left as it is
    B = Q[:, :k] @ rng.normal(size=(k, k))
    Hpsd = B @ B.T
    H2 = Hpsd.copy()
    project_psd_in_subspace(H2, Q, k)
    assert np.abs(H2 - Hpsd).max() <= 1e-12 * np.abs(Hpsd).max()


def gap_along(x0, dx, off, taus):
    return np.array([np.sqrt(segment_distance2(x0 + t * dx)) - off for t in taus])


def test_ccd_random_pairs_never_break_the_promised_gap():
    rng = np.random.default_rng(5)
    f, off = 0.1, 0.1
    n_limited = 0
    for _ in range(300):
        x0 = rng.normal(size=12)
        if np.sqrt(segment_distance2(x0)) - off <= 1e-3:
            continue
        dx = rng.normal(size=12) * rng.choice([0.3, 3.0, 30.0])
        tau, it = segment_ccd(x0, dx, off, f, 1e-6, 10000)
        assert 0.0 < tau <= 1.0 and it >= 0
        g0 = np.sqrt(segment_distance2(x0)) - off
        gaps = gap_along(x0, dx, off, np.linspace(0.0, tau, 400))
        assert gaps.min() >= f * g0 * (1 - 1e-9)
        n_limited += tau < 1.0
        # not needlessly conservative: a little past tau the trajectory either got close or the step ended
        if tau < 1.0 and it < 10000:
            assert np.sqrt(segment_distance2(x0 + tau * dx)) - off <= f * g0 * (1 + 1e-5) + 1e-6 * g0
    assert n_limited > 50


def test_ccd_stops_head_on_and_fast_passages():
    off, f = 0.2, 0.1
    # a along x at z = 0; b along y at z = 1, thrown through a (down to z = -speed + 1)
    for speed in (2.0, 20.0, 2e3, 2e6):
        x0 = np.array([-1, 0, 0, 1, 0, 0, 0, -1, 1, 0, 1, 1], dtype=float)
        dx = np.zeros(12)
        dx[[8, 11]] = -speed
        tau, _ = segment_ccd(x0, dx, off, f, 1e-6, 10000)
        t_contact = (1.0 - off) / speed                  # the gap closes exactly here (then they pass)
        t_target = (1.0 - off) * (1 - f) / speed         # where the gap falls to f g0
        assert tau < t_contact
        assert tau >= t_target * (1 - 1e-6)             # motion along the normal: the bound is tight
        assert np.sqrt(segment_distance2(x0 + tau * dx)) - off >= f * 0.8 * (1 - 1e-9)
    # a rotating-like sweep: b's ends cross a on opposite sides (a scissor); still stopped before touching
    x0 = np.array([-1, 0, 0, 1, 0, 0, -1, 0.5, 0.5, 1, -0.5, 0.5], dtype=float)
    dx = np.zeros(12)
    dx[6:9] = [2, -1, -1]
    dx[9:12] = [-2, 1, -1]
    tau, _ = segment_ccd(x0, dx, off, f, 1e-6, 10000)
    taus = np.linspace(0, 1, 20001)
    gaps = gap_along(x0, dx, off, taus)
    assert gaps.min() < 0                                # the full step passes through
    assert tau < taus[np.argmax(gaps <= 0)]
    assert gap_along(x0, dx, off, np.linspace(0, tau, 2000)).min() >= f * gaps[0] * (1 - 1e-9)
    # inadmissible start
    assert segment_ccd(np.array([0, 0, 0, 1, 0, 0, 0, 0.1, 0, 1, 0.1, 0.]), dx, off, f, 1e-6, 100) == (0.0, -1)


def random_walk(rng, n, h=1.0, bend=0.9):
    """A persistent random walk of n steps of length h (it crosses near itself: many near pairs)."""
    pos = np.zeros((n + 1, 3))
    t = np.array([1.0, 0, 0])
    for i in range(n):
        t = t + bend * rng.normal(size=3)
        t /= np.linalg.norm(t)
        pos[i + 1] = pos[i] + h * t
    return pos


def test_broad_phase_matches_brute_force_with_exclusion_and_ring_wrap():
    rng = np.random.default_rng(6)
    n_open, n_ring, h, r, dhat = 160, 80, 0.3, 0.2, 0.1
    topo = topology([(n_open, False, r, h), (n_ring, True, r, h)], dhat)
    assert topo.rod_k.tolist() == [exclusion_k(h, r, dhat)] * 2 == [2, 2]
    walk = random_walk(rng, n_open, h)
    th = np.linspace(0, 2 * np.pi, n_ring, endpoint=False)
    R = n_ring * h / (2 * np.pi)
    ring = np.stack([R * np.cos(th), R * np.sin(th), 0.3 * np.sin(3 * th)], 1) + walk[n_open // 2]
    pos = np.concatenate([walk, ring])
    # boxes: the hash grid finds exactly the brute-force set of overlapping, non-excluded boxes
    m = topo.edges.shape[0]
    lo, hi = np.empty((m, 3)), np.empty((m, 3))
    edge_boxes(pos, topo.edges, topo.edge_radius + 0.5 * dhat, lo, hi)
    args = (topo.rod_of_edge, topo.local_edge, topo.rod_n_edges, topo.rod_closed, topo.rod_k)
    grid_list = hash_grid_pairs(lo, hi, *args)
    grid = {tuple(p) for p in grid_list}
    brute = {tuple(p) for p in brute_force_pairs(lo, hi, *args)}
    assert grid == brute and len(grid) > 50
    assert len(grid_list) == len(grid) and np.all(grid_list[:, 0] < grid_list[:, 1])   # each pair once
    # distances: broad phase + exact gap filter == all non-neighbour pairs within the cutoff, by brute force
    pairs = candidate_pairs(pos, topo, dhat)

    def gap(a, b):
        x = np.concatenate([pos[topo.edges[a]].ravel(), pos[topo.edges[b]].ravel()])
        return np.sqrt(segment_distance2(x)) - 2 * r

    near = {(a, b) for a, b in pairs if gap(a, b) < dhat}
    expect = set()
    for a in range(m):
        for b in range(a + 1, m):
            same = topo.rod_of_edge[a] == topo.rod_of_edge[b]
            di = abs(topo.local_edge[a] - topo.local_edge[b])
            if same and topo.rod_closed[topo.rod_of_edge[a]]:
                di = min(di, n_ring - di)
            if same and di <= 2:
                continue
            if gap(a, b) < dhat:
                expect.add((a, b))
    assert near == expect and len(expect) > 10
    assert any(topo.rod_of_edge[a] != topo.rod_of_edge[b] for a, b in expect)     # rod-rod contacts too
    ring0 = n_open
    # across the ring's wrap: index distance 1 and 2 are neighbours, 3 is not; edges of two rods never are
    assert (ring0, ring0 + n_ring - 1) not in grid and (ring0 + 1, ring0 + n_ring - 1) not in grid
    assert excluded(ring0, ring0 + n_ring - 2, *args) and not excluded(ring0, ring0 + n_ring - 3, *args)
    assert not excluded(0, ring0, *args) and excluded(0, 2, *args) and not excluded(0, 3, *args)
    for a, b in grid:
        if topo.rod_of_edge[a] == topo.rod_of_edge[b] == 1:
            di = abs(topo.local_edge[a] - topo.local_edge[b])
            assert min(di, n_ring - di) > 2


def test_exclusion_rule_and_bad_input():
    assert exclusion_k(1.0, 0.2, 0.1) == 1           # 2r + dhat < h: only edges sharing a node
    assert exclusion_k(0.1, 0.2, 0.1) == 5           # (2r + dhat) / h = 5 exactly: m = 6 has gap dhat
    assert exclusion_k(0.1, 0.2, 0.1, arc=np.pi * 0.2) == 7
    for bad in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(ValueError, match="radius"):
            exclusion_k(1.0, bad, 0.1)


def test_barrier_system_assembly_matches_pair_sums_and_rejects_overlap():
    n, kappa = 60, 3.0
    pos = plectoneme_polyline(n)
    probe = topology([(n, False, 1e-3, 0.5)], 0.5)
    dmin = min_distance(pos, probe.edges, candidate_pairs(pos, probe, 0.8))
    r, dhat = 0.45 * dmin, 0.15 * dmin                # closest pairs sit at gap 0.1 dmin < dhat
    topo = topology([(n, False, r, 0.7)], dhat)
    pairs = candidate_pairs(pos, topo, dhat)
    node_dof = 4 * np.arange(n + 1)                   # der's layout: (x, y, z, theta) per node
    energy, grad, (rows, cols, vals), n_active, min_gap = barrier_system(
        pos, topo, pairs, dhat, kappa, node_dof, 4 * (n + 1))
    assert np.isclose(min_gap, dmin - 2 * r) and energy > 0
    assert n_active > 0
    # gradient by finite differences of the total energy over the node positions
    def total(p):
        return barrier_system(p, topo, pairs, dhat, kappa, node_dof, 4 * (n + 1))[0]
    active_nodes = np.flatnonzero(np.abs(grad.reshape(-1, 4)[:, :3]).max(1) > 0)
    assert len(active_nodes) > 4
    for node in active_nodes[:6]:
        for i in range(3):
            dp = np.zeros_like(pos)
            dp[node, i] = 1e-7
            fd = (total(pos + dp) - total(pos - dp)) / 2e-7
            assert abs(grad[4 * node + i] - fd) <= 1e-5 * max(1.0, np.abs(grad).max())
    assert not grad[3::4].any()                      # no force on theta
    import scipy.sparse as sp
    Hs = sp.coo_matrix((vals, (rows, cols)), shape=(4 * (n + 1),) * 2).toarray()
    assert np.abs(Hs - Hs.T).max() <= 1e-10 * np.abs(Hs).max()
    assert np.linalg.eigvalsh(Hs).min() >= -1e-9 * np.abs(Hs).max()      # sum of PSD blocks
    bad = pos * np.array([0.8, 0.8, 1.0])              # strands pushed inside each other's radius
    with pytest.raises(ValueError, match="edges .* overlap"):
        p2 = candidate_pairs(bad, topo, dhat)
        barrier_system(bad, topo, p2, dhat, kappa, node_dof, 4 * (n + 1))


def test_safe_step_blocks_a_strand_thrown_through_another():
    r, dhat = 0.1, 0.05
    topo = topology([(10, False, r, 0.25), (10, False, r, 0.25)], dhat)
    s = np.linspace(-1.25, 1.25, 11)
    a = np.stack([s, 0 * s, 0 * s], 1)
    b = np.stack([0 * s, s, 0 * s + 1.0], 1)
    pos0 = np.concatenate([a, b])
    dpos = np.zeros_like(pos0)
    dpos[11:, 2] = -50.0                              # b goes from z = 1 to z = -49 in one step
    tau, pair = safe_step(pos0, dpos, topo, dhat)
    assert tau < (1.0 - 2 * r) / 50.0
    assert pair is not None and topo.rod_of_edge[pair[0]] != topo.rod_of_edge[pair[1]]


def test_obstacles_gaps_derivatives_and_ccd():
    r, dhat, kappa = 0.1, 0.2, 1.5
    plane = np.array([0, 0, -1.0, 0, 0, 1.0, 0])
    sphere = np.array([0.3, 0.2, -0.9, 0, 0, 0, 0.5])
    axis = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    cyl = np.concatenate([[0.0, 0.0, -0.95], axis, [0.6]])
    pos = np.array([[0.1, 0.0, -0.2], [0.6, 0.3, -0.25]])
    # closed forms
    assert np.isclose(edge_obstacle_gap(pos, 0, 1, PLANE, plane, r), min(pos[:, 2]) + 1 - r)
    s = np.linspace(0, 1, 20001)[:, None]
    pts = pos[0] + s * (pos[1] - pos[0])
    assert np.isclose(edge_obstacle_gap(pos, 0, 1, SPHERE, sphere, r),
                      np.linalg.norm(pts - sphere[:3], axis=1).min() - 0.5 - r, atol=1e-8)
    rel = pts - cyl[:3]
    perp = rel - (rel @ axis)[:, None] * axis
    assert np.isclose(edge_obstacle_gap(pos, 0, 1, CYLINDER, cyl, r),
                      np.linalg.norm(perp, axis=1).min() - 0.6 - r, atol=1e-8)
    g6, H6, gq, Hq = np.empty(6), np.empty((6, 6)), np.empty(6), np.empty((6, 6))
    for kind, prm in ((SPHERE, sphere), (CYLINDER, cyl)):
        e, z = edge_obstacle_barrier(pos, 0, 1, kind, prm, r, dhat, kappa, g6, H6)
        assert 0 < z < dhat and e > 0

        def en(y):
            return edge_obstacle_barrier(y.reshape(2, 3), 0, 1, kind, prm, r, dhat, kappa, gq, Hq)[0]

        def gr(y):
            edge_obstacle_barrier(y.reshape(2, 3), 0, 1, kind, prm, r, dhat, kappa, gq, Hq)
            return gq.copy()

        y = pos.ravel()
        assert np.allclose(g6, fd_gradient(en, y, 1e-7), rtol=1e-5, atol=1e-7)
        fH = np.array([(gr(y + 1e-7 * e_) - gr(y - 1e-7 * e_)) / 2e-7 for e_ in np.eye(6)])
        assert np.allclose(H6, fH, rtol=1e-4, atol=1e-5 * np.abs(H6).max())
    g3, H3 = np.empty(3), np.empty((3, 3))
    x = np.array([0.0, 0.0, -0.8])
    e, z = node_plane_barrier(x, plane, r, dhat, kappa, g3, H3)
    assert np.isclose(z, 0.1) and np.isclose(g3[2], kappa * barrier_first_derivative(0.1, dhat))
    assert np.isclose(H3[2, 2], kappa * barrier_second_derivative(0.1, dhat)) and g3[0] == 0
    # CCD: an edge thrown through each obstacle stops before touching, and keeps f of its gap
    f = 0.1
    dpos = np.tile([0.2, -0.1, -30.0], (2, 1))
    for kind, prm in ((PLANE, plane), (SPHERE, sphere), (CYLINDER, cyl)):
        g0 = edge_obstacle_gap(pos, 0, 1, kind, prm, r)
        tau, it = edge_obstacle_ccd(pos, dpos, 0, 1, kind, prm, r, f, 1e-6, 10000)
        assert 0 < tau < 1 and it >= 0
        gaps = [edge_obstacle_gap(pos + t * dpos, 0, 1, kind, prm, r) for t in np.linspace(0, tau, 500)]
        assert min(gaps) >= f * g0 * (1 - 1e-9)
        assert edge_obstacle_gap(pos + tau * dpos, 0, 1, kind, prm, r) <= f * g0 * 1.01 + 1e-9


try:
    import ipctk
except ImportError:          # the comparisons below are skipped without the optional extra
    ipctk = None

needs_ipctk = pytest.mark.skipif(ipctk is None, reason="ipctk not installed (pip install der[contact])")


@needs_ipctk
def test_distance_derivatives_agree_with_ipctk():
    rng = np.random.default_rng(8)
    g, H = np.empty(12), np.empty((12, 12))
    for x in [rng.normal(size=12) for _ in range(200)] + [x for x, _ in region_pairs(rng)]:
        D, region = segment_distance2_derivatives(x, g, H)
        a0, a1, b0, b1 = (x[3 * k:3 * k + 3] for k in range(4))
        assert abs(D - ipctk.edge_edge_distance(a0, a1, b0, b1)) <= 1e-12 * max(1.0, D)
        gi = ipctk.edge_edge_distance_gradient(a0, a1, b0, b1).ravel()
        assert np.abs(g - gi).max() <= 1e-10 * max(1, np.abs(g).max())
        assert np.abs(H - ipctk.edge_edge_distance_hessian(a0, a1, b0, b1)).max() <= 1e-8 * max(1, np.abs(H).max())


@needs_ipctk
def test_ccd_of_der_and_ipctk_stop_random_fast_passages():
    """Random crossing pairs thrown through each other at speeds up to 1e4 (segment lengths ~1): the whole
    step passes through (sampled), and every CCD (der, ipctk additive, ipctk tight inclusion) stops before
    the first touch."""
    rng = np.random.default_rng(9)
    off = 0.1
    p = lambda y: [y[3 * k:3 * k + 3] for k in range(4)]  # noqa: E731
    n_checked = 0
    for _ in range(40):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        u = np.cross(n, rng.normal(size=3))
        v = np.cross(n, rng.normal(size=3))
        a_mid, b_mid = rng.normal(size=3), None
        b_mid = a_mid + n * rng.uniform(0.3, 1.0)     # b above a along n, their projections cross
        x0 = np.concatenate([a_mid - u, a_mid + u, b_mid - v, b_mid + v])
        if np.sqrt(segment_distance2(x0)) - off <= 0.05:
            continue
        dx = np.zeros(12)
        dx[6:] = np.tile(-n * 10 ** rng.uniform(0, 4), 2) + 0.3 * rng.normal(size=6)
        taus = np.linspace(0, 1, 4001)
        gaps = gap_along(x0, dx, off, taus)
        if gaps.min() >= 0:
            continue
        t_touch = taus[np.argmax(gaps < 0)]
        tau, _ = segment_ccd(x0, dx, off, 0.1, 1e-6, 10000)
        assert tau < t_touch
        assert gap_along(x0, dx, off, np.linspace(0, tau, 500)).min() > 0
        for ccd in (ipctk.AdditiveCCD(), ipctk.TightInclusionCCD()):
            hit, toi = ccd.edge_edge_ccd(*p(x0), *p(x0 + dx), min_distance=off)
            assert hit and toi < t_touch
        n_checked += 1
    assert n_checked > 20


@needs_ipctk
def test_ccd_agrees_with_ipctk_on_passages():
    off = 0.2
    x0 = np.array([-1, 0, 0, 1, 0, 0, 0, -1, 1, 0, 1, 1], dtype=float)
    dx = np.zeros(12)
    dx[[8, 11]] = -2e3
    x1 = x0 + dx
    p = lambda y: [y[3 * k:3 * k + 3] for k in range(4)]  # noqa: E731
    hit, toi = ipctk.AdditiveCCD().edge_edge_ccd(*p(x0), *p(x1), min_distance=off)
    tau, _ = segment_ccd(x0, dx, off, 0.1, 1e-6, 10000)
    t_contact = (1.0 - off) / 2e3
    assert hit and toi < t_contact and tau < t_contact


def test_python_layer_rejects_bad_input_before_work():
    topo = topology([(4, False, 0.1, 1.0)], 0.05)
    pos = np.stack([np.arange(5.0), np.zeros(5), np.zeros(5)], 1)
    with pytest.raises(ValueError, match="pos must be an"):
        candidate_pairs(pos[:3], topo, 0.05)
    bad = pos.copy()
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        candidate_pairs(bad, topo, 0.05)
    with pytest.raises(TypeError, match="float64"):
        candidate_pairs(pos.astype(np.float32), topo, 0.05)
    with pytest.raises(ValueError, match="dhat"):
        candidate_pairs(pos, topo, -1.0)
    pairs = candidate_pairs(pos, topo, 0.05)
    for kw, msg in (({"kappa": 0.0}, "kappa"), ({"dhat": np.inf}, "dhat"), ({"mode": 7}, "mode")):
        args = {"dhat": 0.05, "kappa": 1.0, "mode": GAP} | kw
        with pytest.raises(ValueError, match=msg):
            barrier_system(pos, topo, pairs, args["dhat"], args["kappa"], 4 * np.arange(5), 20, mode=args["mode"])
    with pytest.raises(ValueError, match="node_dof"):
        barrier_system(pos, topo, pairs, 0.05, 1.0, 4 * np.arange(5), 12)
    with pytest.raises(ValueError, match="min_gap_fraction"):
        safe_step(pos, np.zeros_like(pos), topo, 0.05, min_gap_fraction=1.0)
    with pytest.raises(ValueError, match="dpos"):
        safe_step(pos, np.zeros((4, 3)), topo, 0.05)
    with pytest.raises(ValueError, match="positive integer"):
        topology([(0, False, 0.1, 1.0)], 0.05)


def test_import_der_does_not_load_contact():
    import subprocess
    import sys
    code = "import sys, der; assert not any(m.startswith('der.contact') for m in sys.modules), 'loaded'"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
