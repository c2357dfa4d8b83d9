"""der.continuation and der.sweep: the twisted loop (paper Section 6.1) followed through its fold, its two-wave
bifurcation located and switched onto, and sweeps on a local Dask cluster equal to the serial run bit for bit.

Small rings (20 and 40 edges); the discretisation error of the fold and of the bifurcation is O(1/n^2), so the
closed forms are checked through the error ratio between n and 2n and the Richardson extrapolation."""
import json
import math
import subprocess
import sys

import numpy as np
import pytest

import der
from der import closed_forms as cf
from der import diagnostics as dg


def mean_alpha(scene, state):
    return float(np.nanmean(dg.alpha(scene.rod, state)))


def out_of_plane(scene, state):
    c = state.positions - state.positions.mean(axis=0)
    normal = np.linalg.svd(c, full_matrices=False)[2][-1]
    return float(np.abs(c @ normal).max())


SUMMARIES = {"alpha": mean_alpha, "out_of_plane": out_of_plane}


def loop(n, A2):
    rod = der.rod_from_shape(der.shapes.ring(1.0, n), 1.0, A2)
    return lambda mt: der.Scene(rod, loads=[der.twisting_moment(mt)])


def first_special(n, A2, mt0, **kw):
    branch = der.continuation(loop(n, A2), mt0, parameter="mt", bounds=(0.0, 1.2), ds=0.2, locate_tol=1e-9,
                              summaries=SUMMARIES, stop=lambda r: not r["stable"] or r["dp_ds"] < 0, **kw)
    assert branch.special, branch.message
    return branch, branch.special[0]


def test_loop_followed_through_the_fold():
    """A1/A2 = 0.67: alpha passes pi/2 continuously, m_t turns back at the fold, the branch beyond is unstable."""
    branch = der.continuation(loop(20, 1.0 / 0.67), 0.3, parameter="mt", bounds=(0.2, 1.2), ds=0.2,
                              summaries=SUMMARIES, stop=lambda r: r["alpha"] > 2.2, locate_tol=1e-9)
    assert branch.status == "completed", branch.message
    alpha = np.array([p["alpha"] for p in branch.points])
    mt = np.array([p["mt"] for p in branch.points])
    stable = np.array([p["stable"] for p in branch.points])
    assert alpha[0] < 0.5 and alpha[-1] > 2.2
    assert np.all(np.diff(alpha) > 0) and np.max(np.diff(alpha)) < 0.6       # continuous through pi/2
    k = int(np.argmax(mt))
    assert 0 < k < len(mt) - 1 and mt[-1] < mt[k] - 0.1                       # m_t turns back
    assert np.all(stable[alpha < math.pi / 2 - 0.05]) and not np.any(stable[alpha > math.pi / 2 + 0.05])
    folds = [s for s in branch.special if s["kind"] == "fold"]
    assert len(folds) == 1 and len(branch.special) == 1
    fold = folds[0]
    # the discrete planar branch has its fold at alpha = pi/2 exactly (m_t ~ sin alpha): located to 1e-6
    assert abs(fold["alpha"] - math.pi / 2) < 1e-6
    assert fold["mt"] >= mt.max() - 1e-12
    assert all(p["residual"] <= 1e-8 for p in branch.points)
    table = json.loads(branch.to_json())
    assert table["special"][0]["kind"] == "fold" and len(table["points"]) == len(branch.points)
    csv = branch.to_csv().splitlines()
    assert csv[0].split(",")[:3] == ["mt", "s", "dp_ds"] and len(csv) == len(branch.points) + 1


def test_fold_against_closed_form():
    """m_t a0^2/A1 = 1 at the fold: error O(1/n^2) (ratio ~4 from n = 20 to 40), Richardson to 3e-4."""
    folds = []
    for n in (20, 40):
        _, sp = first_special(n, 1.0 / 0.67, 0.9)
        assert sp["kind"] == "fold"
        folds.append(sp["mt"])
    e20, e40 = folds[0] - 1.0, folds[1] - 1.0
    assert 3.5 < e20 / e40 < 4.5
    assert abs((4 * folds[1] - folds[0]) / 3 - cf.loop_fold(1.0, 1.0)) < 3e-4


def test_two_wave_bifurcation_and_branch_switching():
    """A1/A2 = 5: the planar ring loses stability at sqrt(3 (2A - 5))/(A - 1) = 0.96825 before the fold; the
    located point brackets the stability change of independent solves; the switched branch leaves the plane."""
    ref, mode = cf.loop_threshold(1.0, 0.2, 1.0)
    assert mode == 2 and abs(ref - 0.96825) < 1e-5
    found = []
    for n in (20, 40):
        branch, sp = first_special(n, 0.2, 0.85)
        assert sp["kind"] == "bifurcation" and sp["mt"] < branch.points[0]["mt"] + 0.3
        found.append(sp["mt"])
    e20, e40 = found[0] - ref, found[1] - ref
    assert 0 < e40 < e20 and e20 / e40 > 3.0
    assert abs((4 * found[1] - found[0]) / 3 - ref) / ref < 5e-3
    # independent check of the location (n = 40): der.solve just below is stable, just above unstable
    scene_of = loop(40, 0.2)
    state = sp["state"]
    below = der.solve(scene_of(sp["mt"] * (1 - 1e-4)), state=state)
    above = der.solve(scene_of(sp["mt"] * (1 + 1e-4)), state=state)
    assert below.stable and not above.stable
    # branch switching onto the out-of-plane branch
    switched = branch.switch(0, ds=0.05, max_steps=5, bounds=(0.5, 1.2))
    assert len(switched.points) >= 4, switched.message
    oop = [p["out_of_plane"] for p in switched.points]
    assert oop[0] < 1e-8 and min(oop[1:]) > 1e-2
    # its last point is an equilibrium by der.solve's own measure: it converges at once without moving
    last = switched.states[-1]
    check = der.solve(scene_of(switched.points[-1]["mt"]), state=last, stability=False)
    assert check.iterations <= 1 and np.abs(check.state.q - last.q).max() < 1e-6


def michell_ring(n, A1=1.0, A2=1.5):
    """The naturally straight ring (twisted_ring.py --kappa0 0) of n edges, as a function of the imposed twist."""
    rod = der.rod_from_shape(der.shapes.ring(1.0, n), A1, A2)
    rod = rod.with_natural(kappa_bar=rod.kappa_bar * 0.0)
    return rod, lambda twist: der.Scene(rod.with_imposed_twist(twist))


def writhe(scene, state):
    return float(dg.linking_number(scene.rod, state)[2])


def lk_error(scene, state):
    return float(abs(dg.linking_number(scene.rod, state)[0] - scene.rod.imposed_twist / (2 * math.pi)))


MICHELL_SUMMARIES = {"writhe": writhe, "lk_error": lk_error, "out_of_plane": out_of_plane}


def michell_branch(n):
    rod, scene_of = michell_ring(n)
    welded = rod.with_imposed_twist(1.0)
    start = welded.displaced(welded.rest_state(), None, np.arange(n) / n)     # the weld's twist spread uniformly
    branch = der.continuation(scene_of, 1.0, 12.0, state=start, parameter="twist", ds=0.2, locate_tol=1e-9,
                              summaries=MICHELL_SUMMARIES, stop=lambda r: not r["stable"])
    assert branch.special, branch.message
    return scene_of, branch


def test_michell_threshold_located_and_the_writhing_branch_followed():
    """The naturally straight twisted ring loses stability at Michell's 2 pi sqrt(3) A1/A2 (here A1/A2 = 2/3):
    located by der.continuation's secant on the lowest eigenvalue, error O(1/n^2) (ratio ~4 from n = 20 to 40),
    Richardson to 1e-3; independent solves bracket it; the branch switched onto writhes at constant Lk."""
    ref = cf.michell_twist(1.0, 1.5)
    assert abs(ref - 2 * math.pi * math.sqrt(3) / 1.5) < 1e-12
    found = []
    for n in (20, 40):
        scene_of, branch = michell_branch(n)
        sp = branch.special[0]
        assert sp["kind"] == "bifurcation" and len(branch.special) == 1
        assert sp["located_to"] < 1e-6 and abs(sp["min_eigenvalue"]) < 1e-6
        # the planar branch: no writhe, Lk = twist / 2 pi, stable below the point and unstable after it
        assert all(abs(p["writhe"]) < 1e-10 and p["lk_error"] < 1e-10 for p in branch.points)
        assert all(p["stable"] == (p["twist"] < sp["twist"]) for p in branch.points)
        assert all(p["stability_time"] >= 0 for p in branch.points)
        found.append(sp["twist"])
    e20, e40 = found[0] - ref, found[1] - ref
    assert 0 < e40 < e20 and 3.5 < e20 / e40 < 4.5
    assert abs((4 * found[1] - found[0]) / 3 - ref) / ref < 1e-3
    # independent check (n = 40): der.solve just below the located twist is stable, just above unstable
    state = sp["state"]
    below = der.solve(scene_of(sp["twist"] * (1 - 1e-4)), state=state)
    above = der.solve(scene_of(sp["twist"] * (1 + 1e-4)), state=state)
    assert below.stable and not above.stable
    # the writhing branch: out of the plane, writhe growing, Lk = Tw + Wr held at twist / 2 pi
    switched = branch.switch(0, ds=0.05, max_steps=4)
    assert len(switched.points) == 5, switched.message
    wr = np.array([abs(p["writhe"]) for p in switched.points])
    assert wr[0] < 1e-10 and np.all(np.diff(wr) > 1e-3) and wr[-1] > 0.05
    assert min(p["out_of_plane"] for p in switched.points[1:]) > 1e-2
    assert all(p["lk_error"] < 1e-9 for p in switched.points)
    last = switched.states[-1]
    check = der.solve(scene_of(switched.points[-1]["twist"]), state=last, stability=False)
    assert check.iterations <= 1 and np.abs(check.state.q - last.q).max() < 1e-6


def writhed_ring(n, r):
    """(scene_of(twist), twist, the solved start) of the naturally straight ring twisted to twice Michell's threshold
    and writhed into self-contact (rod radius r)."""
    rod, _ = michell_ring(n)
    twist = 2.0 * cf.michell_twist(1.0, 1.5)

    def scene_of(tw):
        return der.Scene(rod.with_imposed_twist(tw), contacts=[der.self_contact(r)])

    welded = rod.with_imposed_twist(twist)
    x0 = welded.rest_q.reshape(-1, 4)[:, :3]
    phi = np.arctan2(x0[:, 1], x0[:, 0])
    kick = np.zeros_like(x0)
    kick[:, 2] = 0.005 * (np.cos(2 * phi) + np.sin(3 * phi))
    start = der.solve(scene_of(twist), state=welded.displaced(welded.rest_state(), kick, twist * np.arange(n) / n),
                      stability=False)
    assert start.contact["n_contacts"] > 0 and writhe(scene_of(twist), start.state) > 1.0
    return scene_of, twist, start


def test_continuation_through_self_contact_uses_the_sparse_factorisation():
    """Past Michell's threshold the naturally straight ring (n = 40, rod radius 0.05) writhes into self-contact;
    from there der.continuation follows it in the imposed twist with contact pairs active: the bordered Newton
    factorises band + contact Hessian sparsely, Lk = Tw + Wr stays twist / 2 pi, and every point is an
    equilibrium by der.solve's measure with its strands at least 2r apart."""
    r = 0.05
    scene_of, twist, start = writhed_ring(40, r)
    branch = der.continuation(scene_of, twist, twist + 1.0, state=start.state, parameter="twist", ds=0.2,
                              max_steps=3, locate=False, summaries={"writhe": writhe, "lk_error": lk_error})
    assert len(branch.points) == 4, branch.message
    assert branch.sparse_factorisations > 0
    tw = np.array([p["twist"] for p in branch.points])
    assert np.all(np.diff(tw) > 0)
    assert all(p["lk_error"] < 1e-9 and p["residual"] <= 1e-8 for p in branch.points)
    for p, state in zip(branch.points[1:], branch.states[1:]):
        check = der.solve(scene_of(p["twist"]), state=state, stability=False)
        assert check.iterations <= 1 and np.abs(check.state.q - state.q).max() < 1e-6
        assert check.contact["n_contacts"] > 0 and check.contact["min_distance"] >= 2 * r


def test_natural_continuation_stops_at_the_fold():
    branch = der.continuation(loop(12, 1.0), 0.8, 1.2, method="natural", parameter="mt", ds=0.1, ds_min=1e-3,
                              stability=False)
    assert branch.status == "step_too_small"
    assert 0.9 < branch.points[-1]["mt"] <= 1.1          # up to the fold of the 12-edge ring (~1.06), not past


def test_natural_continuation_leaves_the_unstable_straight_rod_past_greenhills_threshold():
    """Greenhill (both ends clamped, the top sliding along z and turned): on a grid through the threshold the
    solves from the last point stay on the straight branch, unstable past it (a root finder finds saddles too);
    with leave_unstable each such point is kicked along its lowest mode and solved again, and the branch bends
    (stable) where the straight state turns unstable. The clamped end edges stay along z."""
    rod = der.rod_from_shape(der.shapes.straight(1.0, 20), 1.0, 1.0, EA=1e4)

    def scene_of(N):
        c, s = np.cos(2 * np.pi * N), np.sin(2 * np.pi * N)
        turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return der.Scene(rod, constraints=[der.clamp("start"), der.clamp("end", rotation=turn, slide=2)])

    lateral = {"lateral": lambda scene, st: float(np.hypot(*st.positions[:, :2].T).max()),
               "tilt": lambda scene, st: float(max(np.hypot(*(st.positions[1] - st.positions[0])[:2]),
                                                   np.hypot(*(st.positions[-1] - st.positions[-2])[:2])))}
    Nc = 2 * 4.493409457909064 / (2 * np.pi)      # M L / A1 = 2 x 4.4934, A1 = A2 = L = 1
    kw = dict(method="natural", parameter="N", dp=0.1 * Nc, predictor="last", summaries=lateral, tol=1e-8)
    plain = der.continuation(scene_of, 0.0, 1.3 * Nc, **kw)
    left = der.continuation(scene_of, 0.0, 1.3 * Nc, leave_unstable=1e-3, **kw)
    past = [pt for pt in plain.points if pt["N"] > 1.05 * Nc]
    assert past and all(not pt["stable"] and pt["lateral"] < 1e-6 for pt in past)     # straight and unstable
    for pt in left.points:
        assert pt["tilt"] < 1e-12
        if pt["N"] > 1.05 * Nc:
            assert pt["stable"] and pt["lateral"] > 0.05
        elif pt["N"] < 0.95 * Nc:
            assert pt["stable"] and pt["lateral"] < 1e-6
    with pytest.raises(ValueError, match="leave_unstable"):
        der.continuation(scene_of, 0.0, 1.0, leave_unstable=1e-3)        # an option of the natural method


def test_the_unstable_mode_is_the_same_on_every_call():
    """A straight rod turned past Greenhill's threshold has a degenerate pair of lowest modes (the two bending
    planes); which vector of that plane the shift-invert Lanczos returns depended on ARPACK's random start, so the
    kick of leave_unstable, and every step after it, changed from run to run (seen as a plectoneme test's
    iteration counts changing between identical runs). The start is seeded: the mode is bitwise the same."""
    from der.continuation import unstable_mode

    rod = der.rod_from_shape(der.shapes.straight(1.0, 40), 1.0, 1.0, EA=1e4)
    N = 1.2 * 2 * 4.493409457909064 / (2 * np.pi)
    c, s = np.cos(2 * np.pi * N), np.sin(2 * np.pi * N)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    scene = der.Scene(rod, constraints=[der.clamp("start"), der.clamp("end", rotation=turn, slide=2)])
    twisted = rod.displaced(rod.rest_state(), dtheta=2 * np.pi * N * (np.arange(rod.n_edges) + 0.5) / rod.n_edges)
    state = der.solve(scene, state=twisted, tol=1e-8, stability=False).state      # straight, N turns: unstable
    modes = [unstable_mode(scene, state) for _ in range(4)]
    assert all(m is not None and m[0] < 0 for m in modes)
    for ev, v in modes[1:]:
        assert ev == modes[0][0] and np.array_equal(v, modes[0][1])


def test_bad_arguments_are_refused_before_any_work():
    scene_of = loop(12, 1.0)
    with pytest.raises(TypeError, match="scene_of"):
        der.continuation("not a function", 0.1)
    with pytest.raises(ValueError, match="ds_min <= ds <= ds_max"):
        der.continuation(scene_of, 0.1, ds=1.0, ds_max=0.5)
    with pytest.raises(ValueError, match="method"):
        der.continuation(scene_of, 0.1, method="euler")
    with pytest.raises(ValueError, match="bounds"):
        der.continuation(scene_of, 0.1, bounds=(0.2, 0.3))
    with pytest.raises(TypeError, match="grid"):
        der.sweep(abs, 3, workers=0)
    with pytest.raises(ValueError, match="workers"):
        der.sweep(abs, {"x": [1]}, workers=-1)


def ring_point(mt, n):
    """A module-level task for the sweeps: one solve of the twisted ring (fails for mt past the fold)."""
    rod = der.rod_from_shape(der.shapes.ring(1.0, n), 1.0, 1.0)
    if mt > 1.2:
        raise ValueError(f"mt = {mt} is past the fold")
    r = der.solve(der.Scene(rod, loads=[der.twisting_moment(mt)]))
    return {"alpha": float(np.nanmean(dg.alpha(rod, r.state))), "min_eigenvalue": r.min_eigenvalue, "theta": r.state.theta.copy()}


GRID = {"mt": [0.2, 0.6, 1.5], "n": [12, 16]}


def test_sweep_serial_reports_failures_without_stopping():
    res = der.sweep(ring_point, GRID, workers=0, progress=False)
    assert len(res) == 6 and [r["mt"] for r in res.rows] == [0.2, 0.2, 0.6, 0.6, 1.5, 1.5]
    assert [r["ok"] for r in res.rows] == [True, True, True, True, False, False]
    assert res.failures[0]["error"] == "ValueError: mt = 1.5 is past the fold"
    assert abs(res.rows[0]["alpha"] - math.asin(0.2)) < 0.02
    rows = json.loads(res.to_json())
    assert "alpha" not in rows[4] and rows[4]["ok"] is False and rows[0]["alpha"] == res.rows[0]["alpha"]
    lines = res.to_csv().splitlines()
    assert lines[0] == "mt,n,alpha,min_eigenvalue,theta,ok,error" and float(lines[1].split(",")[2]) == res.rows[0]["alpha"]


def test_sweep_on_a_local_cluster_is_bit_for_bit_the_serial_run():
    pytest.importorskip("dask.distributed")
    serial = der.sweep(ring_point, GRID, workers=0, progress=False)
    cluster = der.sweep(ring_point, GRID, workers=2, progress=False)
    assert cluster.workers == 2 and len(cluster) == len(serial)
    assert [r["ok"] for r in cluster.rows] == [True, True, True, True, False, False]
    for a, b in zip(serial.rows, cluster.rows):
        assert a.keys() == b.keys()
        for k in a:
            if isinstance(a[k], np.ndarray):
                assert a[k].tobytes() == b[k].tobytes()
            else:
                assert a[k] == b[k] or (a[k] is None and b[k] is None), k


def test_import_der_loads_neither_dask_nor_matplotlib():
    code = ("import sys, der; heavy = [m for m in sys.modules if m.split('.')[0] in "
            "('dask', 'distributed', 'matplotlib', 'tqdm', 'pandas')]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_natural_tangent_predictor_starts_each_solve_nearer_its_equilibrium():
    """predictor="tangent" (natural method) starts each step along dq/dp = K^-1 dR/dp of the last point, an
    O(dp^2) prediction, against the O(dp) of starting from the last point: on a cantilever bent by a growing end
    force (a smooth branch) its starts lie much nearer the equilibria the solves reach, the branch is the same, and
    the solves take fewer iterations."""
    rod = der.rod_from_shape(der.shapes.straight(1.0, 16), 1.0, 1.5)

    def scene_of(force):
        return der.Scene(rod, loads=[der.end_force([0.0, force, 0.0])], constraints=[der.clamp("start")])

    runs = {}
    for predictor in ("last", "tangent"):
        starts = []

        def solve(scene, state=None, **kw):
            r = der.solve(scene, state=state, raise_on_failure=False, **kw)
            if state is not None:
                starts.append((np.abs(state.q - r.state.q).max(), r.iterations))
            return r

        branch = der.continuation(scene_of, 0.5, 3.5, method="natural", parameter="force", dp=0.5,
                                  predictor=predictor, stability=False, solve=solve, keep_states=True)
        assert branch.status == "completed", branch.message
        runs[predictor] = (branch, np.array(starts))
    (b_last, s_last), (b_tan, s_tan) = runs["last"], runs["tangent"]
    assert len(b_last.points) == len(b_tan.points) == 7
    for a, b in zip(b_last.states, b_tan.states):
        assert np.abs(a.q - b.q).max() < 1e-6                      # the same equilibria
    # every step's start: the tangent's error is a small fraction of the last point's
    assert np.all(s_tan[:, 0] < 0.2 * s_last[:, 0]), (s_tan[:, 0], s_last[:, 0])
    assert s_tan[:, 1].sum() < s_last[:, 1].sum()


def test_natural_tangent_predictor_through_self_contact():
    """predictor="tangent" with contact pairs active (the writhed ring of the test above): the tangent is taken on
    band + exact contact Hessian at the solve's barrier stiffness, its starts stay admissible (pulled back if not),
    and every point is an equilibrium with Lk = twist / 2 pi and the strands at least 2r apart."""
    r = 0.05
    scene_of, twist, start = writhed_ring(40, r)
    branch = der.continuation(scene_of, twist, twist + 0.5, state=start.state, parameter="twist", method="natural",
                              dp=0.25, predictor="tangent", stability=False,
                              summaries={"writhe": writhe, "lk_error": lk_error})
    assert branch.status == "completed" and len(branch.points) == 3, branch.message
    assert branch.sparse_factorisations > 0              # the tangents were solved with the contact Hessian
    assert all(p["lk_error"] < 1e-9 for p in branch.points)
    for p, state in zip(branch.points[1:], branch.states[1:]):
        check = der.solve(scene_of(p["twist"]), state=state, stability=False)
        assert check.iterations <= 1 and np.abs(check.state.q - state.q).max() < 1e-6
        assert check.contact["n_contacts"] > 0 and check.contact["min_distance"] >= 2 * r
