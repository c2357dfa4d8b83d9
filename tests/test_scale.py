"""Fast paths for large rods (issue 17) against the per-vertex reference construction they replace."""
import numpy as np
import pytest

import der
from der.energies.bend import material_curvatures
from der.geometry import curvature_binormal, edge_frames, reference_twist_angle, tangents

SHAPES = {
    "helix": lambda: der.shapes.helix(1.0, 0.6, 3, 301),
    "straight": lambda: der.shapes.straight(2.0, 57, axis=(1, 0, 0), director=(0, 0, 1)),
    "ring": lambda: der.shapes.ring(1.0, 97),
    "arc": lambda: der.shapes.arc(1.0, 3.0, 88),
}


def _unit(e):
    """e / |e| in the kernels' scalar arithmetic (np.linalg.norm may sum in another order, so not bitwise)."""
    le = np.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    return np.array([e[0] / le, e[1] / le, e[2] / le])


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_rod_from_shape_equals_per_vertex_reference(name):
    """rest twist, natural curvatures and tangents from the batch kernels are bitwise those of the per-vertex
    kernels (the Python loops rod_from_shape used before)."""
    rod = der.rod_from_shape(SHAPES[name](), 1.0, 1.5)
    q, d1 = rod.rest_q, rod.rest_d1
    t = np.array([_unit(q[4 * b:4 * b + 3] - q[4 * a:4 * a + 3]) for a, b in rod.edge_nodes])
    assert np.array_equal(tangents(q, rod.edge_nodes), t)
    twist = np.array([reference_twist_angle(t[a], d1[a], t[b], d1[b]) for a, b in rod.vertex_edges])
    assert np.array_equal(rod.rest_twist, twist)
    assert np.array_equal(rod.twist_bar, twist)
    ed = edge_frames(q, rod.edge_nodes, d1)
    weld = np.zeros(rod.n_vertices)
    kb_edges = np.array([material_curvatures(ed, rod.vertex_edges, weld, v)
                         for v in range(rod.n_vertices)]).reshape(-1, 2, 2)
    assert np.array_equal(rod.kappa_bar_edges, kb_edges)
    kb = np.array([curvature_binormal(t[a], t[b]) for a, b in rod.vertex_edges])
    from der.geometry import curvature_binormals
    assert np.array_equal(curvature_binormals(t, rod.vertex_edges), kb)


def test_straight_director_parallel_to_an_edge_is_refused():
    with pytest.raises(ValueError, match="director is parallel to edge"):
        der.rod_from_shape(der.shapes.Shape(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]), director=(1, 0, 0)), 1, 1)


def test_max_row_norm_equals_row_norms():
    from der.solvers.system import max_row_norm, row_norms

    rng = np.random.default_rng(1)
    for a in (rng.standard_normal((50, 3)), 1e200 * rng.standard_normal((7, 3)), np.zeros((4, 3)),
              1e-300 * rng.standard_normal((5, 3))):
        assert max_row_norm(a) == row_norms(a).max()
    a = rng.standard_normal((5, 3))
    a[2, 1] = np.nan
    assert np.isnan(max_row_norm(a))
    a[2, 1] = np.inf
    assert max_row_norm(a) == np.inf


def test_fused_bend_twist_assembly_equals_separate_terms():
    """The fused vertex pass (bend + twist in one scatter) gives the matrix of bend_hessian + twist_hessian to
    round-off, on an open rod and on a (folded) ring with a weld."""
    from der.energies.bend import bend_hessian
    from der.energies.twist import twist_hessian
    from der.energies.vertex import bend_twist_hessian
    from der.geometry import edge_frames
    from der.linalg import band_layout, new_band
    from der.scene import make_plan

    rng = np.random.default_rng(2)
    for rod in (der.rod_from_shape(der.shapes.helix(1.0, 0.6, 2, 40), 1.0, 1.5),
                der.rod_from_shape(der.shapes.ring(1.0, 30), 1.0, 1.5).with_imposed_twist(0.7)):
        state = rod.rest_state()
        q = state.q + 1e-2 * rng.standard_normal(rod.n_dof)
        plan = make_plan(der.Scene(rod), np.ones(rod.n_edges))
        kl, ku, perm = band_layout(rod.n_nodes, rod.closed)
        ed = edge_frames(q, rod.edge_nodes, state.d1)
        g1, ab1 = np.zeros(rod.n_dof), new_band(rod.n_dof, kl, ku)
        eb = bend_hessian(ed, plan.vertex_nodes, plan.vertex_edges, plan.weld, plan.kappa_bar, plan.voronoi,
                          plan.A1, g1, ab1, kl, ku, perm)
        et = twist_hessian(q, ed, plan.vertex_nodes, plan.vertex_edges, state.reference_twist, plan.weld,
                           plan.twist_bar, plan.voronoi, plan.A2, g1, ab1, kl, ku, perm)
        g2, ab2 = np.zeros(rod.n_dof), new_band(rod.n_dof, kl, ku)
        eb2, et2 = bend_twist_hessian(q, ed, plan.vertex_nodes, plan.vertex_edges, state.reference_twist, plan.weld,
                                      plan.kappa_bar, plan.twist_bar, plan.voronoi, plan.A1, plan.A2, g2, ab2, kl, ku,
                                      perm)
        assert eb2 == eb and et2 == et
        assert np.abs(g2 - g1).max() <= 1e-13 * np.abs(g1).max()
        assert np.abs(ab2 - ab1).max() <= 1e-13 * np.abs(ab1).max()
        assert np.abs(ab1).max() > 0


@pytest.mark.parametrize("closed", [False, True])
def test_evaluate_equals_term_by_term_assembly(closed):
    """scene.evaluate at order 2 (bending and twisting fused into one vertex pass, the band zeroed and scattered
    column by column) against the term kernels called one after the other on a zeroed band: same energy,
    gradient and Jacobian (with the frame-transport term) to round-off; on an open rod and a folded, welded
    ring."""
    from der.energies.bend import bend_hessian
    from der.energies.stretch import stretch_hessian
    from der.energies.twist import twist_hessian
    from der.geometry import add_transport_jacobian, edge_frames
    from der.linalg import band_layout, new_band
    from der.scene import evaluate, make_plan

    rng = np.random.default_rng(3)
    if closed:
        rod = der.rod_from_shape(der.shapes.ring(1.0, 31), 1.0, 1.5).with_imposed_twist(0.4)
    else:
        rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 2, 45), 1.0, 1.5)
    state = rod.rest_state()
    q = state.q + 1e-2 * rng.standard_normal(rod.n_dof)
    lam = 0.1 * rng.standard_normal(rod.n_edges)
    k = 10.0 + rng.random(rod.n_edges)
    plan = make_plan(der.Scene(rod), k)
    kl, ku, perm = band_layout(rod.n_nodes, rod.closed)
    g, f, ab = np.zeros(rod.n_dof), np.zeros(rod.n_dof), new_band(rod.n_dof, kl, ku)
    ab[:] = np.nan   # every entry must be overwritten
    energy = evaluate(plan, q, state.d1, state.reference_twist, lam, 2, g, f, ab, kl, ku, perm)
    assert plan.counters[:4].tolist() == [1, 1, 1, 1]
    g0, ab0 = np.zeros(rod.n_dof), new_band(rod.n_dof, kl, ku)
    ed = edge_frames(q, rod.edge_nodes, state.d1)
    e0 = stretch_hessian(q, plan.edge_nodes, plan.l_bar, plan.k_stretch, lam, g0, ab0, kl, ku, perm)
    e0 += bend_hessian(ed, plan.vertex_nodes, plan.vertex_edges, plan.weld, plan.kappa_bar, plan.voronoi, plan.A1,
                       g0, ab0, kl, ku, perm)
    e0 += twist_hessian(q, ed, plan.vertex_nodes, plan.vertex_edges, state.reference_twist, plan.weld,
                        plan.twist_bar, plan.voronoi, plan.A2, g0, ab0, kl, ku, perm)
    add_transport_jacobian(q, rod.edge_nodes, g0[3::4][:rod.n_edges].copy(), ab0, kl, ku, perm)
    assert abs(energy - e0) <= 1e-13 * abs(e0)
    assert np.abs(g - g0).max() <= 1e-13 * np.abs(g0).max()
    assert np.isfinite(ab).all()
    assert np.abs(ab - ab0).max() <= 1e-13 * np.abs(ab0).max()
    # and the order-1 gradient (term kernels) is the same gradient
    g1 = np.zeros(rod.n_dof)
    evaluate(plan, q, state.d1, state.reference_twist, lam, 1, g1, f, ab0, kl, ku, perm)
    assert np.abs(g1 - g).max() <= 1e-13 * np.abs(g).max()


def test_dot_equals_numpy_to_round_off():
    from der.linalg import dot

    rng = np.random.default_rng(4)
    for n in (0, 1, 3, 4, 7, 1001):
        a, b = rng.standard_normal(n), rng.standard_normal(n)
        assert abs(dot(a, b) - float(a @ b)) <= 1e-14 * max(float(np.abs(a) @ np.abs(b)), 1e-300)


def test_implicit_solve_reports_its_time_split():
    rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1, 60), 1.0, 1.5)
    scene = der.Scene(rod, loads=[der.end_force([0, 0, 1e-3])], constraints=[der.clamp("start")])
    res = der.solve(scene, stability=False)
    assert res.converged and res.iterations > 0
    assert set(res.timings) == {"assembly", "factorisation", "line_search"}
    assert all(v > 0 for v in res.timings.values())
    assert sum(res.timings.values()) <= res.wall_time


def test_dot_abs_equals_numpy_to_round_off():
    from der.linalg import dot_abs

    rng = np.random.default_rng(5)
    for n in (0, 1, 3, 4, 7, 1001):
        a, b = rng.standard_normal(n), rng.standard_normal(n)
        ref = float(a @ np.abs(b))
        assert abs(dot_abs(a, b) - ref) <= 1e-14 * max(float(np.abs(a) @ np.abs(b)), 1e-300)


def test_implicit_band_path_keeps_one_band_in_memory():
    """The band path factorises the Jacobian in place: the solve's NumPy peak is one band plus n-sized arrays,
    two bands less than with the band copied before each attempt (main before issue 17's change: a copy of the
    Jacobian and a work copy). Measured: 2.3 bands in place, 4.3 copying."""
    import tracemalloc

    from der.solvers import implicit

    rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 6, 1200), 0.67, 1.0)
    scene = der.Scene(rod, loads=[der.end_force([0, 0, 1e-3])], constraints=[der.clamp("start")])
    band_bytes = (2 * 10 + 10 + 1) * rod.n_dof * 8
    peaks = {}
    try:
        for in_place in (True, False):
            implicit.IN_PLACE = in_place
            der.solve(scene, stability=False, raise_on_failure=False)   # first-call allocations first
            tracemalloc.start()
            try:
                res = der.solve(scene, stability=False, raise_on_failure=False)
                peaks[in_place] = tracemalloc.get_traced_memory()[1] / band_bytes
            finally:
                tracemalloc.stop()
            assert res.converged and res.iterations > 2
    finally:
        implicit.IN_PLACE = True
    # one band plus n-sized arrays: 2.3 bands when this test was written; the loop's work arrays now allocated
    # once and kept (the million-edge run's page faults, issue 17) add n-sized arrays: 2.94 bands measured on that
    # change, 3.08 with this round's other merges (a band is 31 n_dof doubles, an n-sized array 1/31 of one)
    assert peaks[True] < 3.5, peaks
    assert peaks[False] - peaks[True] > 1.5, peaks


def test_implicit_retried_steps_reassemble_the_factorised_band():
    """A step that is refused (the band already overwritten by its LU factors) is retried on a band assembled
    again: a solve that needs retries ends where the same solve with the band copied before each attempt (the
    path contact scenes take) ends, bitwise."""
    from der.solvers import implicit

    # a cantilever bent far by a transverse end force: Newton's first steps are refused and retried
    rod = der.rod_from_shape(der.shapes.straight(2.0, 80, axis=(1, 0, 0), director=(0, 0, 1)), 1.0, 1.5)
    scene = der.Scene(rod, loads=[der.end_force(np.array([0.0, 1.0, 1.0]))], constraints=[der.clamp("start")])
    calls = []
    orig = implicit.shrink

    def counting(dt, options):
        calls.append(dt)
        return orig(dt, options)

    results = {}
    implicit.shrink = counting
    try:
        for in_place in (True, False):
            implicit.IN_PLACE = in_place
            results[in_place] = der.solve(scene, stability=False, raise_on_failure=False)
    finally:
        implicit.shrink = orig
        implicit.IN_PLACE = True
    assert calls, "the scene must exercise a retried step"
    a, b = results[True], results[False]
    assert a.converged and a.iterations == b.iterations
    assert a.residual == b.residual
    assert np.array_equal(a.state.q, b.state.q)


@pytest.mark.parametrize("closed", [False, True])
def test_assembly_energy_part_is_exactly_symmetric(closed):
    """The vertex pass of all three terms (energies.vertex, issue 17) forms each local Hessian as its upper triangle
    and writes it into both triangles of the band: without the frame-transport term the band is exactly symmetric
    (before, its triangles differed by round-off), equal to the term kernels' band to 1e-14 of its largest entry,
    every entry written (the pass zeroes the columns itself); with the transport term added inside the pass it
    equals the energy part plus geometry.add_transport_jacobian to round-off."""
    from der.energies.bend import bend_hessian
    from der.energies.stretch import stretch_hessian
    from der.energies.twist import twist_hessian
    from der.energies.vertex import stretch_bend_twist_hessian
    from der.geometry import add_transport_jacobian, edge_array, edge_frames
    from der.linalg import band_layout, band_to_sparse, new_band
    from der.scene import evaluate, make_plan

    rng = np.random.default_rng(11)
    if closed:
        rod = der.rod_from_shape(der.shapes.ring(1.0, 31), 1.0, 1.5).with_imposed_twist(0.4)
    else:
        rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 2, 45), 1.0, 1.5)
    state = rod.rest_state()
    q = state.q + 1e-2 * rng.standard_normal(rod.n_dof)
    lam = 0.1 * rng.standard_normal(rod.n_edges)
    plan = make_plan(der.Scene(rod), 10.0 + rng.random(rod.n_edges))
    kl, ku, perm = band_layout(rod.n_nodes, rod.closed)
    E = edge_array(q, rod.edge_nodes, None, True)
    ed = edge_frames(q, rod.edge_nodes, state.d1, E)
    g, ab = np.zeros(rod.n_dof), new_band(rod.n_dof, kl, ku)
    ab[:] = np.nan
    stretch_bend_twist_hessian(q, ed, plan.edge_nodes, plan.vertex_nodes, plan.vertex_edges, plan.l_bar,
                               plan.k_stretch, lam, state.reference_twist, plan.weld, plan.kappa_bar, plan.twist_bar,
                               plan.voronoi, plan.A1, plan.A2, g, ab, kl, ku, perm, E, False)
    assert np.isfinite(ab).all()
    H = band_to_sparse(ab, kl, ku, perm).toarray()
    assert np.array_equal(H, H.T)
    g0, ab0 = np.zeros(rod.n_dof), new_band(rod.n_dof, kl, ku)
    stretch_hessian(q, plan.edge_nodes, plan.l_bar, plan.k_stretch, lam, g0, ab0, kl, ku, perm, E)
    bend_hessian(ed, plan.vertex_nodes, plan.vertex_edges, plan.weld, plan.kappa_bar, plan.voronoi, plan.A1, g0, ab0,
                 kl, ku, perm)
    twist_hessian(q, ed, plan.vertex_nodes, plan.vertex_edges, state.reference_twist, plan.weld, plan.twist_bar,
                  plan.voronoi, plan.A2, g0, ab0, kl, ku, perm)
    assert np.abs(ab - ab0).max() <= 1e-14 * np.abs(ab0).max()
    assert np.abs(g - g0).max() <= 1e-13 * np.abs(g0).max()
    # the full evaluation: the transport term inside the pass
    g2, f2, ab2 = np.zeros(rod.n_dof), np.zeros(rod.n_dof), new_band(rod.n_dof, kl, ku)
    ab2[:] = np.nan
    evaluate(plan, q, state.d1, state.reference_twist, lam, 2, g2, f2, ab2, kl, ku, perm)
    assert np.array_equal(g2, g)
    add_transport_jacobian(q, plan.edge_nodes, g[3::4][:rod.n_edges].copy(), ab, kl, ku, perm, E)
    assert np.isfinite(ab2).all()
    assert np.abs(ab2 - ab).max() <= 1e-15 * np.abs(ab).max()
    K = band_to_sparse(ab2, kl, ku, perm).toarray()
    assert np.abs(K - K.T).max() > 1e-6 * np.abs(K).max()    # the transport term's skew part is there


@pytest.mark.parametrize("closed", [False, True])
def test_order_one_pass_sums_as_the_assembly(closed):
    """scene.evaluate at order 1 (the solver's residual pass) gives bitwise the energy, gradient and loads of the
    order-2 assembly (the same fused pass without the band), and in the same pass the edge forces and vertex
    moments of the load scale bitwise as diagnostics._edge_forces on the same compensated edges; on an open
    helix under dead and follower loads and a welded ring."""
    from der.diagnostics import _edge_forces
    from der.linalg import band_layout, new_band
    from der.scene import evaluate, make_plan

    rng = np.random.default_rng(7)
    if closed:
        rod = der.rod_from_shape(der.shapes.ring(1.0, 31), 1.0, 1.5).with_imposed_twist(0.4)
        loads = []
    else:
        rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 2, 45), 1.0, 1.5)
        loads = [der.end_force([0.1, 0.0, 0.2]), der.end_torque([0.0, 0.3, 0.1])]
    state = rod.rest_state()
    q = state.q + 1e-2 * rng.standard_normal(rod.n_dof)
    q_lo = 1e-19 * rng.standard_normal(rod.n_dof)
    lam = 0.1 * rng.standard_normal(rod.n_edges)
    plan = make_plan(der.Scene(rod, loads=loads), 10.0 + rng.random(rod.n_edges))
    kl, ku, perm = band_layout(rod.n_nodes, rod.closed)
    g1, f1, g2, f2 = (np.zeros(rod.n_dof) for _ in range(4))
    ab = new_band(rod.n_dof, kl, ku)
    F, M = np.full((rod.n_edges, 3), np.nan), np.full(rod.n_vertices, np.nan)
    e1 = evaluate(plan, q, state.d1, state.reference_twist, lam, 1, g1, f1, ab, kl, ku, perm, q_lo, F, M)
    e2 = evaluate(plan, q, state.d1, state.reference_twist, lam, 2, g2, f2, ab, kl, ku, perm, q_lo)
    assert e1 == e2
    assert np.array_equal(g1, g2) and np.array_equal(f1, f2)
    F0, M0 = _edge_forces(q, state.d1, state.reference_twist, lam, rod.edge_nodes, rod.vertex_nodes,
                          rod.vertex_edges, rod.l_bar, plan.k_stretch, plan.kappa_bar, rod.twist_bar, plan.weld,
                          rod.voronoi, plan.A1, plan.A2, True, True, True, q_lo)
    assert np.array_equal(F, F0) and np.array_equal(M, M0)


def test_implicit_assembles_the_band_only_for_steps():
    """The band path evaluates the residual without the band and assembles it only for a step it factorises:
    an inextensible ring twisted by an end torque (multiplier updates, no step) converges with exactly one
    assembly per band factorisation, bitwise where the path that assembles at every iteration ends (IN_PLACE
    False, the contact scenes' path). Before: one assembly more per multiplier update and at the converged check."""
    from der import closed_forms as cf
    from der.solvers import implicit

    rod = der.rod_from_shape(der.shapes.arc(1.0, 3.0, 60), 1.0, 1.0 / 0.67)
    scene = der.Scene(rod, loads=[der.end_torque(1e-3 * cf.ring_end_basis(1.0, 3.0)[0])],
                      constraints=[der.clamp("start")])
    orig = implicit.evaluate_system
    orders = []

    def counting(system, state, order, *args):
        orders.append(order)
        return orig(system, state, order, *args)

    results, assemblies = {}, {}
    implicit.evaluate_system = counting
    try:
        for in_place in (True, False):
            implicit.IN_PLACE = in_place
            orders.clear()
            results[in_place] = der.solve(scene, stability=False, raise_on_failure=False)
            assemblies[in_place] = orders.count(2)
    finally:
        implicit.evaluate_system = orig
        implicit.IN_PLACE = True
    a, b = results[True], results[False]
    assert a.status == "converged" and b.status == "converged"
    assert a.iterations == b.iterations and a.residual == b.residual
    assert np.array_equal(a.state.q, b.state.q)
    assert assemblies[True] == a.linear_solves["band"]
    assert assemblies[False] > assemblies[True]


@pytest.mark.parametrize("closed", [False, True])
def test_scatter_band_is_the_reference_scatter(closed):
    """stencils.scatter_band (unsigned band indices, issue 17) adds exactly what the plain indexed scatter adds:
    bitwise the same band, on consecutive DOFs (the dense block) and on a ring's wrapped stencil."""
    from der.linalg import band_layout, new_band
    from der.stencils import scatter_band, vertex_dofs

    rod = der.rod_from_shape(der.shapes.ring(1.0, 12) if closed else der.shapes.arc(1.0, 2.0, 12), 1.0, 1.5)
    kl, ku, perm = band_layout(rod.n_nodes, rod.closed)
    ab = new_band(rod.n_dof, kl, ku)
    ref = np.zeros_like(ab)
    rng = np.random.default_rng(7)
    dofs = np.empty(11, dtype=np.int64)
    for v in range(rod.n_vertices):
        H = rng.standard_normal((11, 11))
        vertex_dofs(rod.vertex_nodes, rod.vertex_edges, v, dofs)
        scatter_band(ab, kl, ku, perm, dofs, H, 1.0)
        for a in range(11):
            for b in range(11):
                i, j = perm[dofs[a]], perm[dofs[b]]
                ref[kl + ku + i - j, j] += H[a, b]
    assert ab.tobytes() == ref.tobytes()
    assert np.count_nonzero(ab) > 0


def _solver_system(closed):
    from der.solvers.system import build_system, prepare_state

    rod = der.rod_from_shape(der.shapes.ring(1.0, 40) if closed else der.shapes.helix(1.0, 0.6, 2, 50), 1.0, 1.5)
    scene = der.Scene(rod, constraints=[] if closed else [der.clamp("start")],
                      loads=[] if closed else [der.end_torque([0.0, 0.0, 1e-2])])
    system = build_system(scene, der.SolverOptions())
    state = prepare_state(system, rod.rest_state())
    rng = np.random.default_rng(11)
    state.q += 1e-2 * rng.standard_normal(state.q.shape)
    state.q_lo[:] = 1e-18 * rng.standard_normal(state.q.shape)
    state.reference_twist[::3] += 4.0         # some twists above 1 rad: they set the angle's rounding
    return system, state


@pytest.mark.parametrize("closed", [False, True])
def test_solver_work_arrays_give_bitwise_the_numpy_results(closed):
    """The implicit loop's work arrays (issue 17): residual vector, residual norm, rounding scale and floor forces
    written into reused arrays by kernels are bitwise the NumPy expressions they replaced (kept here), and the
    evaluation's edge arrays live on the plan."""
    from der.linalg import band_matvec, condense_vector
    from der.solvers.system import (
        FLOOR_ROUNDINGS, _node_edge_max, evaluate_system, floor_forces, residual_norm, residual_vector,
        rounding_scale, state_edges,
    )

    system, state = _solver_system(closed)
    rod = system.rod
    evaluate_system(system, state, 2)
    assert system.plan.work_E.shape == (rod.n_edges, 6) and system.plan.work_ed.shape == (rod.n_edges, 16)
    # rounding scale (reference: as it was, NumPy)
    le = np.sqrt((state_edges(system, state) ** 2).sum(axis=1))
    w_ref = np.repeat(_node_edge_max(le, rod.edge_nodes, rod.n_nodes), 4)
    w_ref[3::4] = np.maximum(np.abs(state.q[3::4]), 1.0)
    twist = np.abs(state.reference_twist)
    w_ref[4 * rod.vertex_edges[:, 1] + 3] = np.maximum(w_ref[4 * rod.vertex_edges[:, 1] + 3], twist)
    w_ref = FLOOR_ROUNDINGS * w_ref
    work = np.full(rod.n_dof, np.nan)
    assert rounding_scale(system, state, work) is work
    assert work.tobytes() == w_ref.tobytes()
    assert rounding_scale(system, state).tobytes() == w_ref.tobytes()
    # floor forces
    ref = np.empty(rod.n_dof)
    band_matvec(system.ab, system.kl, system.ku, system.perm, w_ref, ref, True)
    lk = system.links
    condense_vector(ref, lk.tri_dep, lk.tri_master, np.abs(lk.tri_coef), system.fixed)
    ref = np.finfo(float).eps * ref
    out = np.empty(rod.n_dof)
    assert floor_forces(system, state, out) is out
    assert out.tobytes() == ref.tobytes() == floor_forces(system, state).tobytes()
    # residual vector and norm
    R_ref = system.fext - system.grad
    condense_vector(R_ref, lk.tri_dep, lk.tri_master, lk.tri_coef, system.fixed)
    R = residual_vector(system, np.empty(rod.n_dof))
    assert R.tobytes() == R_ref.tobytes() == residual_vector(system).tobytes()
    for scales in ((0.3, 1.7), (2.0, 0.1)):
        s = np.where(system.is_theta, scales[1], scales[0])
        assert residual_norm(system, R, scales) == float(np.max(np.abs(R) / s))
    R[5] = np.nan
    assert np.isnan(residual_norm(system, R, (1.0, 1.0)))


def test_dot_difference_is_dot_of_the_difference():
    """linalg.dot_difference(a, x, y) is bitwise dot(a, x - y) (and dot_abs with ``absolute``): the implicit
    solver's step products without the step array (issue 17)."""
    from der.linalg import dot, dot_abs, dot_difference

    rng = np.random.default_rng(5)
    for n in (0, 1, 7, 1001):
        a, x, y = rng.standard_normal((3, n))
        x = y + 1e-7 * x
        assert dot_difference(a, x, y) == dot(a, x - y)
        assert dot_difference(a, x, y, True) == dot_abs(a, x - y)
