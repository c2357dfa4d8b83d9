"""Rods that vary along their length (issue 13): per-vertex stiffness, anisotropic bending, rest states given
apart from the start, cross-section helpers and shapes -- against finite differences, closed forms and
``solve_bvp`` solutions of the Kirchhoff equations (``der.references``), with their convergence orders.

``python tests/test_varying.py`` prints the validation tables of docs/validation.md."""
import warnings

import numpy as np
import pytest

import der
import der.references as ref
from der.scene import Scene
from helpers import Evaluator, free_mask, moved, perturbed_state

NS = (20, 40, 80)


def _solve(scene, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", der.RoundoffFloorWarning)
        res = der.solve(scene, **kw)
    assert res.converged, res.message
    return res


def _order(errors, ns):
    return float(np.polyfit(np.log(ns), np.log(errors), 1)[0] * -1)


def _end_centre(state):
    """The end cross-section's centre: the midpoint of the last edge."""
    x = state.positions
    return 0.5 * (x[-1] + x[-2])


# --------------------------------------------------------------------------------------------- studies


PERVERSION = dict(L=2.0, kappa0=1.5, A1=1.0, A2=1.0, P=1.0)


def perversion_rod(n, L=2.0, kappa0=1.5, A1=1.0, A2=1.0):
    """Natural curvature +kappa0 on [0, L/2), -kappa0 on (L/2, L] towards m1 = e1, straight at start along e3.
    With n - 1 even the step falls on an edge midpoint (a cell boundary of the vertices)."""
    rest = der.shapes.strains(L, n, kappa1=lambda s: np.where(s < 0.5 * L, kappa0, -kappa0))
    return der.rod(rest=rest, start="straight", A1=A1, A2=A2)


def perversion_errors(cells=NS, **p):
    """Max distance of the nodes in [0, L] from the solve_bvp solution, / L, and the reaction errors."""
    p = {**PERVERSION, **p}
    pos, Fx, M0 = ref.perversion(p["L"], p["kappa0"], p["A1"], p["P"])
    out = []
    for c in cells:
        rod = perversion_rod(c + 1, p["L"], p["kappa0"], p["A1"], p["A2"])
        scene = Scene(rod, loads=[der.end_force([0, 0, p["P"]])],
                      constraints=[der.clamp("start"), der.clamp("end", slide=(0, 0, 1))])
        res = _solve(scene, tol=1e-10)
        xi = rod.xi_nodes[1:-1]
        x = res.state.positions[1:-1][:, [0, 2]]
        err = np.abs(x - pos(xi).T).max() / p["L"]
        react = res.reactions[0]
        out.append((err, abs(react["force"][0] + Fx) / abs(Fx), abs(react["moment"][1] + M0) / abs(M0)))
    return np.array(out)


def anisotropic_linear_errors(ns=NS, L=1.0, A1=1.0, ratio=10.0, P=1e-5):
    """Relative error of the two tip-deflection components of the A1' = 10 A1 cantilever, tip force at 45 deg."""
    F = P * np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    d1, d2 = ref.anisotropic_cantilever_linear(L, F[:2], A1, ratio * A1)
    out = []
    for n in ns:
        rod = der.rod(rest=der.shapes.straight(L, n), A1=A1, A1prime=ratio * A1, A2=1.0)
        res = _solve(Scene(rod, loads=[der.end_force(F)], constraints=[der.clamp("start")]), tol=1e-10)
        tip = _end_centre(res.state)
        out.append((abs(tip[0] - d1) / d1, abs(tip[1] - d2) / d2))
    return np.array(out)


def anisotropic_large_errors(ns=NS, L=1.0, A1=1.0, ratio=10.0, A2=1.0, P=3.0):
    """|tip - r(L)| / L against the solve_bvp large-deflection solution (tip force P at 45 deg, P L^2 / A1 = 3)."""
    F = P * np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    sol = ref.anisotropic_cantilever(L, F, A1, ratio * A1, A2)
    r_tip = sol.sol(L)[:3]
    out = []
    for n in ns:
        rod = der.rod(rest=der.shapes.straight(L, n), A1=A1, A1prime=ratio * A1, A2=A2)
        res = _solve(Scene(rod, loads=[der.end_force(F)], constraints=[der.clamp("start")]), tol=1e-10)
        out.append(np.linalg.norm(_end_centre(res.state) - r_tip) / L)
    return np.array(out), r_tip


def tapered_errors(ns=NS, L=1.0, A_root=2.0, A_tip=0.5, P=1e-5):
    """Relative tip-deflection error of the cantilever with A1 linear from A_root to A_tip (closed form)."""
    exact = ref.tapered_tip_deflection(L, P, A_root, A_tip)
    out = []
    for n in ns:
        rod = der.rod(rest=der.shapes.straight(L, n), A1=lambda s: A_root + (A_tip - A_root) * s / L, A2=1.0)
        res = _solve(Scene(rod, loads=[der.end_force([P, 0, 0])], constraints=[der.clamp("start")]), tol=1e-10)
        out.append(abs(_end_centre(res.state)[0] - exact) / exact)
    return np.array(out)


# --------------------------------------------------------------------------------------------- validation


def test_perversion_matches_the_solve_bvp_kirchhoff_solution_second_order():
    e = perversion_errors()
    assert e[-1, 0] < 2e-4 and _order(e[:, 0], NS) > 1.8, e
    # the reactions at the start clamp: transverse force and moment, second order too
    assert e[-1, 1] < 1e-3 and e[-1, 2] < 1e-3 and _order(e[:, 1], NS) > 1.8, e


def test_anisotropic_cantilever_tip_deflections_are_PL3_over_3A1_and_3A1prime_second_order():
    e = anisotropic_linear_errors()
    for c in range(2):
        assert e[-1, c] < 1e-4 and _order(e[:, c], NS) > 1.8, e


def test_anisotropic_cantilever_large_deflection_matches_solve_bvp_second_order():
    e, r_tip = anisotropic_large_errors()
    assert r_tip[0] > 0.3 and r_tip[1] > 0.05       # really large and really anisotropic
    assert e[-1] < 3e-4 and _order(e, NS) > 1.8, e


def test_tapered_cantilever_tip_deflection_second_order():
    e = tapered_errors()
    assert e[-1] < 1e-4 and _order(e, NS) > 1.8, e


def test_the_bvp_references_agree_with_the_closed_forms():
    """The BVP code itself: small load against the linear closed form; no pull against a hand check."""
    sol = ref.anisotropic_cantilever(1.0, (1e-4, 2e-4, 0.0), 1.0, 10.0, 1.0)
    d1, d2 = ref.anisotropic_cantilever_linear(1.0, (1e-4, 2e-4), 1.0, 10.0)
    assert np.allclose(sol.sol(1.0)[:2], [d1, d2], rtol=1e-3)
    # tapered closed form against quadrature
    from scipy.integrate import quad
    assert np.isclose(ref.tapered_tip_deflection(1.0, 1.0, 2.0, 0.5),
                      quad(lambda s: (1 - s) ** 2 / (2.0 - 1.5 * s), 0, 1)[0], rtol=1e-12)


def test_bar_with_varying_EA_stretches_by_the_integral_of_P_over_EA_second_order():
    """Per-edge EA (a function of xi at the edge midpoints): a bar pulled by P stretches by P int ds / EA(s)."""
    P, errs = 0.01, []
    exact = P * np.log(2.0)                       # EA(s) = 1 + s on [0, 1]
    for n in NS:
        rod = der.rod(rest=der.shapes.straight(1.0, n), A1=1.0, A2=1.0, EA=lambda s: 1.0 + s)
        res = _solve(Scene(rod, loads=[der.end_force([0, 0, P])], constraints=[der.clamp("start")]), tol=1e-12)
        errs.append(abs(_end_centre(res.state)[2] - 1.0 - exact) / exact)
    assert errs[-1] < 1e-4 and _order(errs, NS) > 1.8, errs


def test_with_stiffness_takes_per_vertex_arrays():
    rod = der.rod_from_shape(der.shapes.straight(1.0, 10), 1.0, 1.0)
    a = np.linspace(1.0, 2.0, rod.n_vertices)
    varied = rod.with_stiffness(A1=a, A1prime=2 * a, EA=np.full(rod.n_edges, 50.0))
    assert np.array_equal(varied.bending_stiffness(), np.stack([a, 2 * a], axis=1))
    assert not varied.isotropic and varied.bending_scale == 4.0 and varied.axial_stiffness().shape == (10,)
    assert rod.with_stiffness(A1prime=None).isotropic
    with pytest.raises(ValueError, match="A1prime"):
        rod.with_stiffness(A1prime=np.ones(3))


# --------------------------------------------------------------------------------------------- kernels


def _varying_rod():
    n = 12
    shape = der.shapes.helix(1.0, 0.6, 1.2, n)
    rng = np.random.default_rng(3)
    nv = n - 1
    return der.rod(rest=shape, A1=1.0 + rng.random(nv), A1prime=3.0 + rng.random(nv), A2=0.5 + rng.random(nv),
                   EA=50.0 + 10 * rng.random(n))


def test_anisotropic_varying_gradient_and_hessian_match_finite_differences():
    rod = _varying_rod()
    ev = Evaluator(Scene(rod), k_stretch=rod.axial_stiffness() / rod.l_bar)
    state = perturbed_state(rod, np.random.default_rng(5), amplitude=0.1, twist=0.4)
    E, g, _, K = ev(state, order=2)
    mask = free_mask(rod)
    eps = 1e-6
    g_fd = np.zeros_like(g)
    K_fd = np.zeros_like(K)
    for i in np.flatnonzero(mask):
        qp, qm = state.q.copy(), state.q.copy()
        qp[i] += eps
        qm[i] -= eps
        Ep, gp, _, _ = ev(moved(rod, state, qp))
        Em, gm, _, _ = ev(moved(rod, state, qm))
        g_fd[i] = (Ep - Em) / (2 * eps)
        K_fd[:, i] = (gp - gm) / (2 * eps)
    assert np.abs(g - g_fd)[mask].max() < 1e-6 * np.abs(g).max()
    sub = np.ix_(mask, mask)
    assert np.abs(K[sub] - K_fd[sub]).max() < 1e-5 * np.abs(K).max()


def test_isotropic_arrays_give_bitwise_the_uniform_results():
    shape = der.shapes.helix(1.0, 0.6, 1.0, 30)
    uniform = der.rod_from_shape(shape, 1.3, 1.7)
    nv = uniform.n_vertices
    arrays = der.rod(rest=shape, A1=np.full(nv, 1.3), A1prime=np.full(nv, 1.3), A2=np.full(nv, 1.7))
    same = der.rod(rest=shape, A1=1.3, A2=1.7)
    for name in ("l_bar", "voronoi", "kappa_bar", "kappa_bar_edges", "twist_bar", "rest_q", "rest_d1", "rest_twist"):
        assert np.array_equal(getattr(uniform, name), getattr(same, name)), name
    loads = [der.end_force([0.01, 0.0, 0.02]), der.end_torque(0.01, follower=True)]
    results = [_solve(Scene(r, loads=loads, constraints=[der.clamp("start")])) for r in (uniform, arrays)]
    assert np.array_equal(results[0].state.q, results[1].state.q)


def test_a_rest_given_by_strains_is_force_free_and_reached_from_a_straight_start():
    """kappa1, kappa2 and omega0 varying along the rod: the free rod relaxes to zero energy (a state of exactly
    these discrete strains exists), and its measured strains are the given ones."""
    L, n = 2.0, 30
    rest = der.shapes.strains(L, n, kappa1=lambda s: 1.0 + 0.5 * s, kappa2=lambda s: 0.3 * np.sin(s),
                              omega=lambda s: 0.4 - 0.2 * s)
    rod = der.rod(rest=rest, start="straight", A1=1.0, A1prime=2.0, A2=lambda s: 1.0 + 0.1 * s)
    res = _solve(Scene(rod, constraints=[der.clamp("start")]), tol=1e-10)
    from der.diagnostics import internal_moments
    assert np.abs(internal_moments(rod, res.state)).max() < 1e-8
    # the relaxed state has the given strains
    from der.energies.bend import material_curvatures_all
    from der.geometry import edge_frames
    k = material_curvatures_all(edge_frames(res.state.q, rod.edge_nodes, res.state.d1), rod.vertex_edges,
                                rod.weld).reshape(-1, 2, 2)
    assert np.abs(k - rod.kappa_bar_edges).max() < 1e-8


def test_strains_with_unequal_rest_lengths_relax_to_the_same_curve():
    """Explicit rest edge lengths: an arc of curvature 1 with unequal edges is force-free and has curvature 1."""
    n, L = 24, 2.0
    w = 1.0 + 0.5 * np.sin(np.arange(n))
    lengths = w * L / (w.sum() - 0.5 * (w[0] + w[-1]))
    rest = der.shapes.strains(L, n, kappa1=1.0, lengths=lengths)
    assert np.allclose(rest.xi, np.cumsum(lengths)[:-1] - 0.5 * lengths[0])
    rod = der.rod(rest=rest, A1=1.0, A2=1.0)
    assert np.array_equal(rod.l_bar, lengths) and np.isclose(rod.length, L)
    res = _solve(Scene(rod, constraints=[der.clamp("start")]), tol=1e-10)
    from der.diagnostics import internal_moments
    assert np.abs(internal_moments(rod, res.state)).max() < 1e-8
    with pytest.raises(ValueError, match="lengths must add up to length"):
        der.shapes.strains(L + 0.1, n, lengths=lengths)


def test_a_rest_shape_with_a_straight_start_relaxes_to_the_rest_shape():
    arc = der.shapes.arc(1.0, 2.5, 24)
    rod = der.rod(rest=arc, start="straight", A1=1.0, A2=1.5)
    assert np.abs(rod.start_state().positions[:, :2]).max() == 0.0
    res = _solve(Scene(rod, constraints=[der.clamp("start")]), tol=1e-10)
    x, y = res.state.positions, arc.positions
    dist = lambda p: np.linalg.norm(p[:, None] - p[None], axis=2)   # noqa: E731
    assert np.abs(dist(x) - dist(y)).max() < 1e-8


def test_rod_from_shape_is_rod_with_rest_equal_start():
    shape = der.shapes.helix(1.0, -0.4, 0.8, 20)
    a, b = der.rod_from_shape(shape, 1.0, 2.0, EA=100.0), der.rod(rest=shape, A1=1.0, A2=2.0, EA=100.0)
    for name in ("l_bar", "kappa_bar_edges", "twist_bar", "rest_q", "rest_d1", "rest_twist"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.A1 == b.A1 and a.EA == b.EA and b.isotropic


@pytest.mark.parametrize("call, words", [
    (lambda: der.rod(rest=42, A1=1.0, A2=1.0), ["rest", "int"]),
    (lambda: der.rod(rest=der.shapes.arc(1, 2, 10), start=der.shapes.straight(1, 12), A1=1.0, A2=1.0),
     ["start", "10 edges", "12"]),
    (lambda: der.rod(rest=der.shapes.strains(1.0, 10), start="rest", A1=1.0, A2=1.0), ["start='rest'"]),
    (lambda: der.rod(rest=der.shapes.strains(1.0, 10, closed=True), A1=1.0, A2=1.0), ["straight", "ring"]),
    (lambda: der.rod(rest=der.shapes.straight(1, 10), A1=np.ones(3), A2=1.0), ["A1", "9", "(3,)"]),
    (lambda: der.rod(rest=der.shapes.straight(1, 10), A1=lambda s: 1 - 2 * s, A2=1.0), ["A1", "> 0"]),
    (lambda: der.rod(rest=der.shapes.straight(1, 10), A1=1.0, A2=1.0, EA=np.ones(9)), ["EA", "10", "edge"]),
    (lambda: der.rod(rest=der.shapes.straight(1, 10), A1=1.0, A2=1.0, A1prime=-1.0), ["A1prime", "> 0"]),
    (lambda: der.shapes.strains(1.0, 10, kappa1=np.ones(4)), ["kappa1", "(9,)"]),
    (lambda: der.shapes.strains(1.0, 10, omega=lambda s: np.nan * s), ["omega", "finite"]),
    (lambda: der.sections.circle(1.0, E=1.0), ["G", "nu"]),
    (lambda: der.sections.rectangle(1.0, -0.1, E=1.0, nu=0.3), ["b", "> 0"]),
    (lambda: der.shapes.polyline([[0, 0, 0], [1, 0, 0], [2, 0, 0]], director=np.ones((5, 3))), ["director", "2"]),
    (lambda: der.shapes.spline([[0, 0, 0], [0, 0, 0], [1, 0, 0]], 10), ["coincide"]),
])
def test_bad_input_is_refused_naming_the_argument(call, words):
    with pytest.raises((TypeError, ValueError)) as info:
        call()
    for w in words:
        assert w in str(info.value), (w, str(info.value))


def _refused(call):
    """The error der raises for a bad argument: a TypeError/ValueError from der's own code, with a message."""
    from fuzzing import GENERIC_MESSAGES, _raised_by_der
    try:
        out = call()
    except (TypeError, ValueError) as exc:
        assert _raised_by_der(exc), f"not raised by der: {exc!r}"
        assert not any(g in str(exc) for g in GENERIC_MESSAGES), str(exc)
        return str(exc)
    return out


def test_every_careless_value_of_every_new_argument_is_refused_or_finite():
    """Each argument of der.rod, der.shapes.strains and der.sections with each careless value: refused naming the
    argument, or (1e300 where it is still a valid number) a rod without a NaN."""
    from fuzzing import BAD_SCALARS
    shape = der.shapes.straight(1.0, 6)
    good = dict(rest=shape, A1=1.0, A2=1.0, EA=None, A1prime=None)
    for name in ("A1", "A2", "EA", "A1prime"):
        for bad in BAD_SCALARS:
            if bad is None and name in ("EA", "A1prime"):
                continue                                   # None is allowed: inextensible / isotropic
            out = _refused(lambda: der.rod(**{**good, name: bad}))
            if isinstance(out, str):
                assert name in out, (name, bad, out)
            else:
                assert np.all(np.isfinite(out.bending_stiffness())), (name, bad)
    for bad in (*(b for b in BAD_SCALARS if b is not None), "bent", np.zeros(3)):   # None: the default start
        out = _refused(lambda: der.rod(rest=shape, start=bad, A1=1.0, A2=1.0))
        assert isinstance(out, str) and "start" in out, (bad, out)
    for name in ("kappa1", "kappa2", "omega"):
        for bad in BAD_SCALARS:
            out = _refused(lambda: der.shapes.strains(1.0, 6, **{name: bad}))
            if isinstance(out, str):
                assert name in out, (name, bad, out)
            else:
                assert np.all(np.isfinite(out.kappa)) and np.all(np.isfinite(out.omega)), (name, bad)
    for fn, args in ((der.sections.circle, (0.1,)), (der.sections.rectangle, (0.1, 0.2)),
                     (der.sections.ellipse, (0.1, 0.2)), (der.sections.annulus, (0.2, 0.1))):
        for bad in BAD_SCALARS:
            out = _refused(lambda: fn(*args, E=bad, nu=0.3))
            assert isinstance(out, str) and "E" in out or np.all(np.isfinite(out.A1)), (fn.__name__, bad, out)


# --------------------------------------------------------------------------------------------- sections, shapes


def test_section_formulas():
    E, G = 3.0, 1.2
    c = der.sections.circle(0.5, E=E, G=G)
    e = der.sections.ellipse(0.5, 0.5, E=E, G=G)
    for name in ("A1", "A1prime", "A2", "EA"):
        assert np.isclose(getattr(c, name), getattr(e, name), rtol=1e-14)
    assert np.isclose(der.sections.annulus(0.5, 1e-4, E=E, G=G).A1, c.A1, rtol=1e-12)
    assert np.isclose(der.sections.circle(1.0, E=E, nu=0.25).A2, np.pi / 2 * E / 2.5)
    # Saint-Venant's rectangle: J = beta c d^3, beta tabulated by Timoshenko & Goodier (Sec. 109, 3 digits)
    for ratio, beta in ((1.0, 0.141), (1.5, 0.196), (2.0, 0.229), (3.0, 0.263), (5.0, 0.291), (10.0, 0.312)):
        assert abs(der.sections.rectangle_torsion_constant(ratio, 1.0) / ratio - beta) < 6e-4, ratio
    # a thin strip: c d^3 / 3 (1 - 0.630 d / c)
    assert np.isclose(der.sections.rectangle_torsion_constant(100.0, 1.0), 100 / 3 * (1 - 0.630 / 100), rtol=1e-4)
    r = der.sections.rectangle(0.3, 0.1, E=E, G=G)
    assert np.isclose(r.A1 / r.A1prime, 9.0) and np.isclose(r.EA, E * 0.03)
    kw = der.sections.circle(np.array([0.1, 0.2]), E=1.0, G=1.0).stiffness()
    assert kw["A1prime"] is None and kw["A1"].shape == (2,)


def test_polyline_director_sets_the_material_frame_everywhere():
    s = np.linspace(0, 1, 15)
    pts = np.stack([s, 0.2 * s ** 2, 0 * s], axis=1)
    rod = der.rod(rest=der.shapes.polyline(pts, director=(0, 0, 1)), A1=1.0, A1prime=5.0, A2=1.0)
    assert np.allclose(rod.rest_d1, [0, 0, 1])          # m1 = e3: the curve bends towards m2 (kappa2 != 0)
    assert np.abs(rod.kappa_bar[:, 0]).max() < 1e-14 and np.abs(rod.kappa_bar[:, 1]).min() > 0
    res = _solve(Scene(rod, constraints=[der.clamp("start")]))
    assert np.abs(res.state.positions - pts).max() < 1e-9             # force-free rest


def test_spline_through_circle_points_is_equally_spaced_with_the_circle_curvature():
    phi = np.linspace(0, 1.5, 25)       # dense enough that the spline's own curvature error is ~1e-3
    pts = np.stack([np.cos(phi), np.sin(phi), 0 * phi], axis=1)
    errs = []
    for n in (20, 40):
        x = der.shapes.spline(pts, n).positions
        le = np.linalg.norm(np.diff(x, axis=0), axis=1)
        assert np.ptp(le) < 1e-4 * le.mean()        # equal arc length: chords differ by O(h^3 kappa kappa')
        # the end cross-section (end-edge midpoint) at the first point, to the sagitta h^2 kappa / 8 of the chord
        assert np.linalg.norm(0.5 * (x[0] + x[1]) - pts[0]) < 0.2 * le.mean() ** 2
        rod = der.rod(rest=der.shapes.spline(pts, n), A1=1.0, A2=1.0)
        errs.append(np.abs(np.linalg.norm(rod.kappa_bar, axis=1) / rod.voronoi - 1.0).max())
    assert max(errs) < 1e-2, errs
    # a closed spline through points on a circle: a ring of equal edges and curvature 1
    phi = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    ring = der.shapes.spline(np.stack([np.cos(phi), np.sin(phi), 0 * phi], axis=1), 30, closed=True)
    rod = der.rod(rest=ring, A1=1.0, A2=1.0)
    assert rod.closed and np.ptp(rod.l_bar) < 1e-4 * rod.l_bar.mean()
    assert np.abs(np.linalg.norm(rod.kappa_bar, axis=1) / rod.voronoi - 1.0).max() < 2e-2


def test_varying_helix_has_the_given_curvature_and_torsion_second_order():
    kappa = lambda s: 1.0 + 0.5 * s             # noqa: E731
    omega = lambda s: 0.6 - 0.2 * s             # noqa: E731
    errs = []
    for n in (20, 40, 80):
        rod = der.rod(rest=der.shapes.varying_helix(kappa, omega, 3.0, n), A1=1.0, A2=1.0)
        xi = rod.xi_nodes[rod.vertex_nodes[:, 1]]
        k = np.linalg.norm(rod.kappa_bar, axis=1) / rod.voronoi
        w = rod.twist_bar / rod.voronoi
        errs.append(max(np.abs(k - kappa(xi)).max(), np.abs(w - omega(xi))[1:-1].max()))
    assert errs[-1] < 5e-3 and _order(errs, (20, 40, 80)) > 1.8, errs
    # constant curvature and torsion: the helix of der.shapes.helix, up to a rigid motion
    a = der.shapes.varying_helix(1.0, 0.6, der.shapes.helix_length(1.0, 0.6, 1.0), 30).positions
    b = der.shapes.helix(1.0, 0.6, 1.0, 30).positions
    d = lambda p: np.linalg.norm(p[:, None] - p[None], axis=2)   # noqa: E731
    assert np.abs(d(a) - d(b)).max() < 1e-9


# --------------------------------------------------------------------------------------------- tables


def main():
    def table(title, rows, cols):
        print(f"\n{title}\n")
        print("| " + " | ".join(cols) + " |")
        print("|" + "---|" * len(cols))
        for r in rows:
            print("| " + " | ".join(r) + " |")

    e = perversion_errors()
    rows = [[str(c), f"{a:.3e}", f"{b:.3e}", f"{m:.3e}"] for c, (a, b, m) in zip(NS, e)]
    rows.append(["order", *(f"{_order(e[:, k], NS):.2f}" for k in range(3))])
    table("perversion (cells n - 1; step on a cell boundary)", rows,
          ["cells", "max node error / L", "reaction Fx rel. error", "clamp moment rel. error"])
    e = anisotropic_linear_errors()
    rows = [[str(n), f"{a:.3e}", f"{b:.3e}"] for n, (a, b) in zip(NS, e)]
    rows.append(["order", f"{_order(e[:, 0], NS):.2f}", f"{_order(e[:, 1], NS):.2f}"])
    table("anisotropic cantilever, linear", rows,
          ["n", "tip x rel. error (P L^3/3A1)", "tip y rel. error (P L^3/3A1')"])
    e, r_tip = anisotropic_large_errors()
    rows = [[str(n), f"{a:.3e}"] for n, a in zip(NS, e)] + [["order", f"{_order(e, NS):.2f}"]]
    table(f"anisotropic cantilever, large deflection (BVP tip {np.round(r_tip, 5).tolist()})", rows,
          ["n", "distance of the tip from r(L), / L"])
    e = tapered_errors()
    rows = [[str(n), f"{a:.3e}"] for n, a in zip(NS, e)] + [["order", f"{_order(e, NS):.2f}"]]
    table("tapered cantilever A1 = 2 -> 0.5", rows, ["n", "tip rel. error"])


if __name__ == "__main__":
    main()
