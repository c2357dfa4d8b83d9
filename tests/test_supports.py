"""Supports on the end cross-sections (clamp, hinge, roller), their reactions, and the loads of issue 13
(point torques on interior edges, follower distributed forces), against textbook values and statics."""
import warnings

import numpy as np
import pytest

import der
from der.linalg import band_to_sparse, condense_band, constrain_band
from der.solvers.options import SolverOptions
from der.solvers.system import build_system, evaluate_system, prepare_state, transport

L = 1.0
A1 = 1.0
# first root of tan x = x: the pinned-clamped column buckles at x^2 A1 / L^2 = 2.0457 pi^2 A1 / L^2
X_PC = 4.493409457909064


def beam(n, EA=1e4, axis=(1, 0, 0), director=(0, 0, 1)):
    return der.rod_from_shape(der.shapes.straight(L, n, axis=axis, director=director), A1, 1.0, EA=EA)


def solve(scene, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", der.RoundoffFloorWarning)
        res = der.solve(scene, **kw)
    assert res.converged, res.message
    return res


def centre(x, end):
    return 0.5 * (x[0] + x[1]) if end == "start" else 0.5 * (x[-1] + x[-2])


def order(errors):
    return np.log2(errors[0] / errors[1])


# -- the textbook values, second order ------------------------------------------------------------------------

def test_tension_bar_stretches_exactly_PL_over_EA_with_both_solvers():
    # issue 13: with the end edge held and full-weight end edges it stretched 1.5% short (EA = 100, n = 50)
    EA, P = 100.0, 1.0
    rod = beam(50, EA=EA)
    scene = der.Scene(rod, loads=[der.end_force([P, 0, 0])], constraints=[der.clamp("start")])
    for solver in ("implicit", "explicit"):
        res = solve(scene, solver=solver, stability=False, tol=1e-10)
        x = res.state.positions
        stretch = (centre(x, "end") - centre(x, "start"))[0] - L
        assert stretch == pytest.approx(P * L / EA, rel=1e-6)
        assert np.abs(centre(x, "start")).max() < 1e-12         # the clamp holds the cross-section's centre
        # the reaction is the end force, at the clamped cross-section
        assert res.reactions[0]["force"] == pytest.approx([-P, 0, 0], abs=1e-8)


@pytest.mark.parametrize("solver", ["implicit", "explicit"])
def test_simply_supported_beam_central_load_is_PL3_over_48A1_second_order(solver):
    P = 1e-3
    errors = []
    for n in (20, 40):
        rod = beam(n)
        mid = n // 2                      # node n/2 is at xi = L/2 (the nodes lie at (k - 1/2) L / (n - 1))
        assert rod.xi_nodes[mid] == pytest.approx(L / 2)
        scene = der.Scene(rod, loads=[der.point_force(mid, [0, -P, 0])],
                          constraints=[der.hinge("start"), der.roller("end", along=(1, 0, 0)), der.fix_theta(0)])
        res = solve(scene, solver=solver, stability=False, tol=1e-9)
        x = res.state.positions
        errors.append(abs(-x[mid, 1] / (P * L ** 3 / (48 * A1)) - 1))
        # the supports act on the end cross-sections: their centres stay on the axis
        assert abs(centre(x, "start")).max() < 1e-12 and abs(centre(x, "end")[1:]).max() < 1e-12
        # each support carries half the load, normal to the roller's line
        for r in res.reactions[:2]:
            assert r["force"] == pytest.approx([0, P / 2, 0], abs=1e-6 * P)
    # the old node-pinned beam was 3% off at any n (span L + h or L - h)
    assert errors[0] < 6e-3 and errors[1] < 1.5e-3
    assert order(errors) > 1.9


def _lowest_eigenvalue(n, P, clamped_start):
    rod = beam(n, EA=None)
    start = der.clamp("start") if clamped_start else der.hinge("start")
    constraints = [start, der.roller("end", along=(1, 0, 0))] + ([] if clamped_start else [der.fix_theta(0)])
    scene = der.Scene(rod, loads=[der.end_force([-P, 0, 0])], constraints=constraints)
    return solve(scene, n_eigenvalues=2).min_eigenvalue


def _critical_load(n, clamped_start, guess):
    """The compressive end load at which the lowest stability eigenvalue changes sign (secant iterations)."""
    P0, P1 = 0.95 * guess, 1.05 * guess
    l0, l1 = _lowest_eigenvalue(n, P0, clamped_start), _lowest_eigenvalue(n, P1, clamped_start)
    assert l0 > 0 > l1
    for _ in range(3):
        P0, l0, P1 = P1, l1, P1 - l1 * (P1 - P0) / (l1 - l0)
        l1 = _lowest_eigenvalue(n, P1, clamped_start)
    return P1


@pytest.mark.parametrize("clamped_start, reference", [(False, np.pi ** 2 * A1 / L ** 2),
                                                      (True, X_PC ** 2 * A1 / L ** 2)],
                         ids=["pinned-pinned", "pinned-clamped"])
def test_euler_columns_buckle_at_their_textbook_loads_second_order(clamped_start, reference):
    errors = [abs(_critical_load(n, clamped_start, reference) / reference - 1) for n in (20, 40)]
    assert errors[1] < 1.2e-3
    assert order(errors) > 1.9


def test_fixed_fixed_beam_with_a_turned_end_has_the_textbook_end_moments_and_shear():
    th = 1e-3
    R = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1.0]])   # about z
    errors = []
    for n in (20, 40):
        scene = der.Scene(beam(n, EA=1e4), constraints=[der.clamp("start"), der.clamp("end", rotation=R)])
        res = solve(scene, stability=False, tol=1e-10)
        near, far = res.reactions
        values = np.array([near["moment"][2] / (2 * A1 * th / L), far["moment"][2] / (4 * A1 * th / L),
                           near["force"][1] / (6 * A1 * th / L ** 2), -far["force"][1] / (6 * A1 * th / L ** 2)])
        errors.append(np.abs(values - 1).max())
        # the turned clamp turned about its cross-section's centre: it has not moved
        assert np.abs(centre(res.state.positions, "end") - [L, 0, 0]).max() < 1e-12
    assert errors[1] < 3e-3
    assert order(errors) > 1.9


# -- reactions against statics --------------------------------------------------------------------------------

def _statics(res, scene):
    """Sum of reactions and loads (force, moment about the origin), from the load records (independently of
    the generalized forces the solver used): end forces at the end cross-sections, point forces at their
    nodes, distributed forces at the nodes with their Voronoi lengths, torques as given."""
    rod = scene.rod
    x = res.state.positions
    F = np.zeros(3)
    M = np.zeros(3)
    for r in res.reactions:
        F += r["force"]
        M += np.cross(r["at"], r["force"]) + r["moment"]
    for load in scene.loads:
        if isinstance(load, der.loads.EndForce):
            f, at = np.asarray(load.force), centre(x, load.end)
        elif isinstance(load, der.loads.PointForce):
            f, at = np.asarray(load.force), x[load.node]
        elif isinstance(load, der.loads.DistributedForce):
            w = rod.node_weights()
            F += w.sum() * np.asarray(load.density)
            M += np.cross(x, w[:, None] * np.asarray(load.density)[None, :]).sum(axis=0)
            continue
        elif isinstance(load, der.loads.PointTorque):
            M += np.asarray(load.torque)
            continue
        F += f
        M += np.cross(at, f)
    return F, M


@pytest.mark.parametrize("support", ["hinge", "clamp", "roller"])
def test_reactions_balance_the_loads_forces_and_moments(support):
    rod = der.rod_from_shape(der.shapes.helix(kappa0=2.0, omega0=0.5, turns=0.6, n=40), A1=1.0, A2=1.5, EA=300.0)
    far = {"hinge": der.hinge("end"), "clamp": der.clamp("end", slide=(1.0, 2.0, 0.5)),
           "roller": der.roller("end", normal=(0.3, 0.2, 1.0))}[support]
    loads = [der.point_force(12, [0.02, -0.01, 0.03]), der.end_force([0.01, 0.02, -0.02]),
             der.distributed_force([0.0, -0.01, 0.005]), der.point_torque(25, [0.003, 0.01, -0.004])]
    scene = der.Scene(rod, loads=loads, constraints=[der.clamp("start"), far])
    res = solve(scene, stability=False, tol=1e-11)
    F, M = _statics(res, scene)
    assert np.abs(F).max() < 1e-9 and np.abs(M).max() < 1e-9
    # the diagnostics function gives the same from the state alone
    for a, b in zip(der.diagnostics.reactions(scene, res.state), res.reactions):
        assert a["support"] == b["support"] and np.abs(a["force"] - b["force"]).max() < 1e-12
        assert np.abs(a["moment"] - b["moment"]).max() < 1e-12
    # a support reacts only where it holds: not along a roller's plane or a sliding clamp's direction
    r = res.reactions[1]["force"]
    if support == "roller":
        nrm = np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0])
        assert np.abs(r - nrm * (nrm @ r)).max() < 1e-9 and abs(nrm @ r) > 1e-3
    if support == "clamp":
        s = np.array([1.0, 2.0, 0.5]) / np.linalg.norm([1.0, 2.0, 0.5])
        assert abs(s @ r) < 1e-9 and np.linalg.norm(r) > 1e-3
    if support != "clamp":
        assert np.abs(res.reactions[1]["moment"]).max() < 1e-9      # a hinge and a roller hold no moment


def test_a_turned_clamp_turns_about_its_cross_section_centre():
    # issue 13: the clamp turned about its outer node, moving the end cross-section by h theta / 2. A cantilever
    # whose clamp is turned by R and whose load is turned by R is the unturned solution turned by R about the
    # clamped cross-section's centre.
    rod = beam(10)
    phi = 0.3
    R = np.array([[np.cos(phi), -np.sin(phi), 0], [np.sin(phi), np.cos(phi), 0], [0, 0, 1.0]])
    P = np.array([0.0, 0.05, 0.02])
    plain = solve(der.Scene(rod, loads=[der.end_force(P)], constraints=[der.clamp("start")]), stability=False)
    turned = solve(der.Scene(rod, loads=[der.end_force(R @ P)], constraints=[der.clamp("start", rotation=R)]),
                   stability=False)
    x = turned.state.positions
    assert np.abs(centre(x, "start")).max() < 1e-12
    assert x == pytest.approx(plain.state.positions @ R.T, abs=1e-9)
    assert turned.reactions[0]["moment"] == pytest.approx(R @ plain.reactions[0]["moment"], abs=1e-10)


def test_old_axis_slide_still_works_and_a_clamp_slides_along_any_direction():
    rod = beam(12)
    assert der.clamp("end", slide=2).slide == (2,)
    s = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    scene = der.Scene(rod, loads=[der.end_force([0.0, 1e-3, 0.0])],
                      constraints=[der.clamp("start"), der.clamp("end", slide=(1, 1, 0))])
    res = solve(scene, stability=False)
    c = centre(res.state.positions, "end")
    d = c - [L, 0, 0]
    assert np.abs(d - s * (s @ d)).max() < 1e-14 and s @ d > 1e-8    # it slid along s, only along s
    assert abs(s @ res.reactions[1]["force"]) < 1e-10


# -- the change of variables keeps the band -------------------------------------------------------------------

@pytest.mark.parametrize("support", [der.hinge, der.clamp, lambda end: der.roller(end, normal=(1, 2, 3))])
def test_condensed_band_is_T_transpose_K_T(support):
    rod = der.rod_from_shape(der.shapes.helix(kappa0=1.0, omega0=0.4, turns=0.5, n=12), A1=1.0, A2=1.3, EA=50.0)
    scene = der.Scene(rod, loads=[der.end_force([0.1, 0, 0])], constraints=[support("start"), support("end")])
    system = build_system(scene, SolverOptions())
    state = prepare_state(system, rod.rest_state())
    evaluate_system(system, state, 2)
    K = band_to_sparse(system.ab, system.kl, system.ku, system.perm).toarray()
    lk = system.links
    n = rod.n_dof
    T = np.eye(n)
    T[:, system.fixed] = 0.0
    for d, m, a in zip(lk.tri_dep, lk.tri_master, lk.tri_coef):
        T[d, m] += a
    free = ~system.fixed
    expected = (T.T @ K @ T)[np.ix_(free, free)]
    ab = system.ab.copy(order="F")
    condense_band(ab, system.kl, system.ku, system.perm, lk.tri_dep, lk.tri_master, lk.tri_coef)
    constrain_band(ab, system.kl, system.ku, system.perm, system.fixed, 1.0)
    got = band_to_sparse(ab, system.kl, system.ku, system.perm).toarray()
    assert np.abs(got[np.ix_(free, free)] - expected).max() <= 1e-12 * np.abs(K).max()
    # and q = c + T y: the prepared state satisfies the links
    q = state.q
    linked = dict(zip(lk.dep.tolist(), lk.const.tolist()))
    for d, m, a in zip(lk.tri_dep, lk.tri_master, lk.tri_coef):
        linked[int(d)] += a * q[m]
    assert max(abs(q[d] - v) for d, v in linked.items()) < 1e-12


# -- loads: point torques and follower forces, stiffness by finite differences --------------------------------

@pytest.mark.parametrize("load", [der.follower_force((0.3, -0.2, 0.1)), der.follower_force((0.0, 0.0, 0.5)),
                                  der.point_torque(4, [0.2, -0.1, 0.3]),
                                  der.point_torque(4, [0.2, -0.1, 0.3], follower=True)],
                         ids=["follower", "tangential", "dead", "follower_torque"])
def test_load_stiffness_matches_finite_differences(load):
    rod = der.rod_from_shape(der.shapes.helix(kappa0=1.5, omega0=0.7, turns=0.4, n=8), A1=1.0, A2=1.3, EA=50.0)
    scene = der.Scene(rod, energies=(), loads=[load])
    system = build_system(scene, SolverOptions())
    state = prepare_state(system, rod.rest_state())
    state.q[3::4][: rod.n_edges] += 0.3 * np.sin(np.arange(rod.n_edges))   # material frames off the Frenet frame
    transport(system, state.copy(), state.q, state)
    evaluate_system(system, state, 2)
    K = band_to_sparse(system.ab, system.kl, system.ku, system.perm).toarray()
    f0 = system.fext.copy()
    eps = 1e-6
    fd = np.zeros_like(K)
    trial = state.copy()
    for i in range(rod.n_dof - 1):
        cols = []
        for sgn in (1, -1):
            q = state.q.copy()
            q[i] += sgn * eps
            assert transport(system, state, q, trial)
            evaluate_system(system, trial, 1)
            cols.append(system.fext.copy())
        fd[:, i] = -(cols[0] - cols[1]) / (2 * eps)
    scale = np.abs(fd).max()
    assert scale > 0 and np.abs(f0).max() > 0
    assert np.abs(K[:-1, :-1] - fd[:-1, :-1]).max() < 1e-7 * scale


def test_follower_force_is_a_pressure_along_the_current_director():
    # a straight cantilever along x with m1 = z under f1 = -p along m1 bends; the load stays normal to the rod
    p = 0.05
    rod = beam(30, EA=None)
    res = solve(der.Scene(rod, loads=[der.follower_force((-p, 0.0))], constraints=[der.clamp("start")]),
                stability=False, tol=1e-10)
    # small load: the dead-load tip deflection p L^4 / 8 A1 (corrections O(p^2))
    tip = centre(res.state.positions, "end")
    assert tip[2] == pytest.approx(-p * L ** 4 / (8 * A1), rel=0.02)
    # the clamp's reaction balances the follower load as it is in the deformed state
    F = res.reactions[0]["force"]
    ed = der.geometry.edge_frames(res.state.q, rod.edge_nodes, res.state.d1)
    w = 0.5 * rod.l_bar
    total = np.zeros(3)
    for j in range(rod.n_edges):
        share = w[j] * (0.0 if j == 0 else 1.0) + w[j] * (0.0 if j == rod.n_edges - 1 else 1.0)
        total += share * (-p) * ed[j, 4:7]
    assert F + total == pytest.approx(np.zeros(3), abs=1e-10)


def test_point_torque_on_an_interior_edge_bends_a_cantilever_like_beam_theory():
    # a moment M at xi = a on a cantilever: the tip turns by M a / A1 and moves by M a (L - a/2) / A1
    M = 1e-4
    errors = []
    for n in (21, 41):
        rod = beam(n)
        j = (n - 1) // 2                      # edge j's midpoint is at xi = j L / (n - 1) = L / 2
        a = rod.xi_edges[j]
        assert a == pytest.approx(L / 2)
        res = solve(der.Scene(rod, loads=[der.point_torque(j, [0, 0, M])], constraints=[der.clamp("start")]),
                    stability=False, tol=1e-10)
        tip = centre(res.state.positions, "end")
        errors.append(abs(tip[1] / (M * a * (L - a / 2) / A1) - 1))
        assert res.reactions[0]["moment"] == pytest.approx([0, 0, -M], abs=1e-12)
    assert errors[1] < 1e-3


# -- bad input --------------------------------------------------------------------------------------------------

def test_bad_supports_are_refused_before_any_work():
    rod = beam(10)
    with pytest.raises(ValueError, match="exactly one of along= .* and normal="):
        der.roller("end")
    with pytest.raises(ValueError, match="exactly one of along="):
        der.roller("end", along=(1, 0, 0), normal=(0, 0, 1))
    with pytest.raises(ValueError, match="der.hinge: slide must be a non-zero direction"):
        der.hinge("start", slide=(0, 0, 0))
    with pytest.raises(ValueError, match="two supports at the 'start' end"):
        der.Scene(rod, constraints=[der.clamp("start"), der.hinge("start")])
    with pytest.raises(ValueError, match="der.pin on a node of the 'start' end edge"):
        der.Scene(rod, constraints=[der.hinge("start"), der.pin(1)])
    with pytest.raises(ValueError, match="point torque on edge 12: out of range"):
        der.Scene(rod, loads=[der.point_torque(12, [0, 0, 1])])
    with pytest.raises(ValueError, match="follower_force: density must be"):
        der.follower_force((1.0,))
    ring = der.rod_from_shape(der.shapes.ring(1.0, 12), 1.0, 1.0)
    with pytest.raises(ValueError, match="a closed ring has no ends"):
        der.Scene(ring, constraints=[der.hinge("start")])


def test_no_equilibrium_is_refused_with_supports_on_skew_lines():
    # a roller on a line off the coordinate axes cannot react along that line: a net force along it is refused
    rod = beam(10)
    s = (1.0, 1.0, 0.0)
    scene = der.Scene(rod, loads=[der.end_force([1e-3, 1e-3, 0.0])],
                      constraints=[der.hinge("start", slide=s), der.roller("end", along=s)])
    with pytest.raises(ValueError, match=r"cannot react along \(0.707107, 0.707107, 0\)"):
        der.solve(scene)
    # a force normal to that line is balanced (no false refusal): the beam bends
    ok = der.Scene(rod, loads=[der.point_force(5, [1e-3, -1e-3, 0.0])],
                   constraints=[der.hinge("start", slide=s), der.roller("end", along=s), der.fix_theta(0)])
    assert solve(ok, stability=False).converged
    # a dead torque on a rod held by one hinge turns it about the hinge: refused
    with pytest.raises(ValueError, match="free to rotate about"):
        der.solve(der.Scene(rod, loads=[der.end_torque([0, 0, 1e-3])], constraints=[der.hinge("start")]))


def test_scenario_json_carries_every_supports_reaction(capsys):
    import importlib.util
    import json
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scenarios" / "straight_twist.py"
    spec = importlib.util.spec_from_file_location("straight_twist", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    from der.cli import scenario_main

    assert scenario_main("straight_twist", "", mod.PARAMETERS, mod.run, argv=["--n", "20", "--json"]) == 0
    record = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    (clamp,) = record["reactions"]
    assert clamp["support"] == "clamp" and clamp["end"] == "start"
    # the clamp holds the end torque: its moment about the tangent balances it
    assert clamp["moment"][2] == pytest.approx(-record["params"]["T"], rel=1e-9)
    assert np.abs(clamp["force"]).max() < 1e-12


def test_follower_end_moment_in_the_material_frame_bends_a_cantilever_into_a_circle():
    # a moment M along m2 of the last edge, turning with it: uniform curvature M / A1, the end on a circle
    M = np.pi / 2                     # a quarter circle
    chords = []
    for n in (20, 40):
        rod = beam(n, EA=None)
        res = solve(der.Scene(rod, loads=[der.point_torque(-1, [0.0, M, 0.0], follower=True)],
                              constraints=[der.clamp("start")]), stability=False, tol=1e-10)
        tip = centre(res.state.positions, "end")
        assert abs(tip[1]) < 1e-10                        # m2 = t x m1 = -y: bending in the x-z plane
        chords.append(np.linalg.norm(tip))
    R = A1 / M
    errors = [abs(c / (2 * R * np.sin(L / (2 * R))) - 1) for c in chords]
    assert errors[1] < 1e-3 and order(errors) > 1.9
