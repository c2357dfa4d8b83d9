"""Several rods in one scene (issue 14): rods without a coupling term solve as each alone; crossed rods pressed
together carry the applied force through contact at distance r_a + r_b, and no strand passes through the other
at any step of the solve; the recording shows every rod; bad input is refused before any work."""
import numpy as np
import pytest

import der
from der.contact import segment_distance2

R = 0.02            # rod radius
F = 0.5             # total downward force on rod B (a distributed load of F per unit length over L = 1)


def _rods(n=20, h0=0.2):
    """Rod A along x through the origin; rod B along y, crossing it at height h0."""
    xa = der.shapes.straight(1.0, n, axis=[1, 0, 0]).positions - [0.5, 0.0, 0.0]
    xb = der.shapes.straight(1.0, n + 1, axis=[0, 1, 0]).positions - [0.0, 0.5, -h0]
    a = der.rod_from_shape(der.shapes.Shape(xa, False, [0, 0, 1]), A1=1.0, A2=1.5, EA=1e3)
    b = der.rod_from_shape(der.shapes.Shape(xb, False, [0, 0, 1]), A1=1.0, A2=1.5, EA=1e3)
    return a, b


def _crossed_scene(force=F, h0=0.2, n=20):
    """A clamped at both ends; B clamped at both ends in sleeves along z (free to move down), pushed by a
    distributed force: only the contact with A can hold B up."""
    a, b = _rods(n, h0)
    sa = der.Scene(a, constraints=[der.clamp("start"), der.clamp("end")])
    sb = der.Scene(b, loads=[der.distributed_force([0, 0, -force])],
                   constraints=[der.clamp("start", slide=2), der.clamp("end", slide=2)])
    return der.Scene([sa, sb], contacts=[der.rod_contact(R)])


def _vertical_contact_force(term):
    """The z component of the contact forces on the upper rod: sum of |force| |n_z| over the pairs."""
    return float(np.sum(np.asarray(term["force"]) * np.abs(np.asarray(term["normals"]).reshape(-1, 3)[:, 2])))


def _min_distance_between(xa, xb, rod_a, rod_b):
    """Smallest centreline distance between an edge of A and an edge of B (brute force)."""
    best = np.inf
    for i, j in rod_a.edge_nodes:
        for k, m in rod_b.edge_nodes:
            best = min(best, np.sqrt(segment_distance2(np.concatenate([xa[i], xa[j], xb[k], xb[m]]))))
    return best


def test_two_rods_without_contact_solve_exactly_as_each_alone():
    helix = der.rod_from_shape(der.shapes.helix(kappa0=1.0, omega0=0.6, turns=1, n=30), A1=1.0, A2=1.5)
    straight = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.5)
    sa = der.Scene(helix, loads=[der.end_force([0, 0, 1e-2])], constraints=[der.clamp("start")])
    sb = der.Scene(straight, loads=[der.end_force([0.02, 0, 0]), der.end_torque(1e-2, follower=True)],
                   constraints=[der.clamp("start")])
    alone = [der.solve(sa, tol=1e-10), der.solve(sb, tol=1e-10)]
    both = der.solve(der.Scene([sa, sb]), tol=1e-10)
    assert both.converged and len(both.states) == 2
    assert both.linear_solves["sparse"] == 0          # no coupling term: the banded path
    for one, state, rod in zip(alone, both.states, (helix, straight)):
        scale = np.abs(one.state.q).max()
        assert np.abs(state.q - one.state.q).max() <= 1e-9 * scale
        assert both.state.rods[0] is both.states[0]
    # energies add up; the per-rod energies are each rod's own
    for k in ("bend", "twist"):
        assert both.energy[k] == pytest.approx(alone[0].energy[k] + alone[1].energy[k], rel=1e-9)
        assert both.rods[1]["energy"][k] == pytest.approx(alone[1].energy[k], rel=1e-8, abs=1e-15)
    assert both.stable and alone[0].stable and alone[1].stable


def test_crossed_rods_carry_the_applied_force_through_contact_at_two_radii():
    res = der.solve(_crossed_scene(), tol=1e-9)
    assert res.converged
    c = res.contact
    term = c["terms"][0]
    assert term["kind"] == "rod_contact" and c["n_contacts"] >= 1
    assert all(sorted(p) == [0, 1] for p in term["pair_rods"])        # between the two rods only
    # statics: the contact force equals the applied force; A's clamps carry it, B's sleeves carry nothing along z
    assert c["total_force"] == pytest.approx(F, rel=1e-3)
    assert _vertical_contact_force(term) == pytest.approx(F, rel=1e-4)
    assert sum(e["force"][2] for e in res.rods[0]["reactions"]) == pytest.approx(F, rel=1e-6)
    assert abs(sum(e["force"][2] for e in res.rods[1]["reactions"])) <= 1e-8 * F
    # at the contact distance: 2r <= d < 2r + dhat, B above A
    d = _min_distance_between(res.states[0].positions, res.states[1].positions, *_crossed_scene().rods)
    assert 2 * R < d < 2 * R + term["dhat"]
    assert c["min_distance"] == pytest.approx(d, rel=1e-12)
    mid_b = res.states[1].positions[res.states[1].positions.shape[0] // 2]
    assert mid_b[2] > 0.0
    assert res.linear_solves["sparse"] > 0             # the pair coupled the two rods' DOFs


def test_no_passage_under_a_large_step(monkeypatch):
    """B starts half a radius above contact and is pushed by 100 times the force: the first Newton steps would
    throw it far through A. Every state the solver tries (line search included) keeps the two centrelines more
    than 2r apart."""
    import der.solvers.implicit as implicit

    scene = _crossed_scene(force=100 * F, h0=2.5 * R)
    rod_a, rod_b = scene.rods
    tried = []
    original = implicit.transport

    def watching(system, base, q_new, out):
        ok = original(system, base, q_new, out)
        tried.append(_min_distance_between(out.rods[0].positions, out.rods[1].positions, rod_a, rod_b))
        return ok

    monkeypatch.setattr(implicit, "transport", watching)
    res = der.solve(scene, tol=1e-8)
    assert res.converged and len(tried) >= 3
    assert min(tried) > 2 * R
    assert _vertical_contact_force(res.contact["terms"][0]) == pytest.approx(100 * F, rel=1e-4)
    mid_a = res.states[0].positions[rod_a.n_nodes // 2]
    mid_b = res.states[1].positions[rod_b.n_nodes // 2]
    assert mid_b[2] > mid_a[2] + 2 * R                 # still on top of A: it never went through


def test_recording_shows_every_rod(tmp_path):
    from der.recording import read_centrelines

    path = tmp_path / "two.rrd"
    res = der.solve(_crossed_scene(), tol=1e-8, record=str(path))
    for i, rod in enumerate(_crossed_scene().rods):
        its, lines = read_centrelines(str(path), entity=f"rod{i}")
        assert len(its) >= 2 and lines[-1].shape == (rod.n_nodes, 3)
        np.testing.assert_allclose(lines[-1], res.states[i].positions, atol=1e-6)


def test_bad_input_is_refused_before_any_work():
    a, b = _rods()
    with pytest.raises(ValueError, match="only contacts on the outer scene"):
        der.Scene([a, b], loads=[der.end_force([0, 0, 1])])
    with pytest.raises(ValueError, match="rod 1 of the list"):
        der.Scene([a, "b"])
    with pytest.raises(ValueError, match="2 rods"):
        der.Scene([a, b], contacts=[der.rod_contact([R, R, R])])
    with pytest.raises(ValueError, match="radius"):
        der.rod_contact(-1.0)
    # rods that already overlap at the start: the error names both rods, their edges and the distance
    overlap = der.Scene([der.Scene(a, constraints=[der.clamp("start")]), der.Scene(_rods(h0=R)[1])],
                        contacts=[der.rod_contact(R)])
    with pytest.raises(ValueError, match=r"edge \d+ of rod 0 and edge \d+ of rod 1 are"):
        der.solve(overlap)
    with pytest.raises(ValueError, match="one per rod"):
        der.solve(der.Scene([a, b]), state=a.rest_state())


def test_a_ring_and_an_inextensible_rod_solve_as_each_alone():
    """Different band layouts side by side (a ring's interleaved band, half-bandwidth 19, and an open rod's, 10)
    and an inextensible rod's multiplier updates inside a scene of several rods."""
    ring = der.rod_from_shape(der.shapes.ring(1.0, 40), A1=1.0, A2=1.5)
    sr = der.Scene(ring, loads=[der.point_force(10, [0, 0.3, 0]), der.point_force(30, [0, -0.3, 0])],
                   constraints=[der.pin(0), der.pin(20)])
    rod = der.rod_from_shape(der.shapes.straight(1.0, 30), A1=1.0, A2=1.5)       # inextensible
    sb = der.Scene(rod, loads=[der.end_force([0.5, 0, 0])], constraints=[der.clamp("start")])
    alone = [der.solve(sb, tol=1e-10), der.solve(sr, tol=1e-10)]
    both = der.solve(der.Scene([sb, sr]), tol=1e-10)
    assert both.converged and both.linear_solves["sparse"] == 0
    for one, state in zip(alone, both.states):
        assert np.abs(state.q - one.state.q).max() <= 1e-9 * np.abs(one.state.q).max()
    assert both.strain <= 1e-8


def test_two_rods_pressed_onto_a_floor_carry_their_loads_through_it():
    """An obstacle in a scene of several rods acts on every rod (its radius from der.rod_contact)."""
    r, F = 0.02, (0.5, 0.2)
    scenes = []
    for i, f in enumerate(F):
        x = der.shapes.straight(1.0, 20).positions + [0.3 * i, 0.0, 0.0]
        rod = der.rod_from_shape(der.shapes.Shape(x, False, [1, 0, 0]), A1=1.0, A2=1.5)
        scenes.append(der.Scene(rod, loads=[der.end_force([0, 0, -f])], constraints=[der.clamp("end", slide=2)]))
    zb = scenes[0].rod.rest_state().positions[0, 2]
    floor = der.plane([0, 0, zb - r - 0.5 * r], [0, 0, 1])
    res = der.solve(der.Scene(scenes, contacts=[der.rod_contact(r), floor]), tol=1e-10)
    assert res.converged
    plane = [t for t in res.contact["terms"] if t["kind"] == "plane"][0]
    assert plane["total_force"] == pytest.approx(sum(F), rel=1e-8)
    assert {e for e in plane["elements"]} <= {0, scenes[0].rod.n_nodes}      # the two bottom nodes
    assert len(plane["elements"]) == 2


def test_contact_diagnostics_of_a_scene_of_several_rods_and_refusals():
    scene = _crossed_scene()
    res = der.solve(scene, tol=1e-9)
    again = der.diagnostics.contact_forces(scene, res.states)
    # the same pairs and distance (the forces use the term's start stiffness, not the adapted one)
    assert sorted(again["terms"][0]["pairs"]) == sorted(res.contact["terms"][0]["pairs"])
    assert again["min_distance"] == pytest.approx(res.contact["min_distance"], rel=1e-12)
    with pytest.raises(ValueError, match="several rods"):
        der.check_stability(scene, res.state)
    with pytest.raises(ValueError, match="several rods"):
        der.continuation(lambda p: scene, 0.0, 1.0)
