"""Contact in the Scene and the implicit solver (issue 14): obstacles, self-contact, CCD, bad input, cost."""
import os
import subprocess
import sys

import numpy as np
import pytest

import der
from der import closed_forms as cf
from der import diagnostics as dg

A1, A2 = 1.0, 1.0 / 0.67


def _vertical_rod(n=20):
    """A straight rod along z, top end clamped in rotation and sliding along z (it can be pushed down)."""
    return der.rod_from_shape(der.shapes.straight(1.0, n), A1=A1, A2=A2)


@pytest.mark.parametrize("obstacle", ["plane", "sphere"])
def test_rod_pressed_onto_obstacle_stops_at_offset_and_carries_the_load(obstacle):
    rod = _vertical_rod()
    r, F = 0.02, 0.5
    zb = rod.rest_state().positions[0, 2]
    gap0 = 0.5 * r                     # start above the barrier range (dhat = 0.1 r)
    if obstacle == "plane":
        term = der.plane([0, 0, zb - r - gap0], [0, 0, 1], radius=r)
        surface = zb - r - gap0
    else:
        R = 1.0
        term = der.sphere([0, 0, zb - r - gap0 - R], R, radius=r)
        surface = zb - r - gap0
    scene = der.Scene(rod, loads=[der.end_force([0, 0, -F])], constraints=[der.clamp("end", slide=2)],
                      contacts=[term])
    res = der.solve(scene, tol=1e-10)
    bottom = res.state.positions[0, 2]
    gap = bottom - surface - r
    dhat = 0.1 * r
    assert 0.0 < gap < dhat                        # at the offset r, within the barrier range
    c = res.contact
    assert c["n_contacts"] >= 1
    assert c["total_force"] == pytest.approx(F, rel=1e-8)     # the contact force balances the load
    assert c["min_distance"] == pytest.approx(r + gap, rel=1e-9)
    assert res.energy["contact"] > 0


def test_ccd_stops_a_step_that_would_jump_through_a_thin_cylinder():
    """A cantilever along x, a thin cylinder across it just below, a tip force so large that the first linear
    (Newton) step would carry the rod through the cylinder to the far side, where every gap is positive again.
    An energy-only line search accepts a step there (the rod then hangs below the cylinder, checked by hand
    with max_step forced to 1); the CCD-limited one keeps it above: the rod drapes over the cylinder."""
    rod = der.rod_from_shape(der.shapes.straight(1.0, 20, axis=(1, 0, 0), director=(0, 0, 1)), A1=A1, A2=1.5)
    R, r = 0.05, 0.02
    zc = -(R + r + 0.03)
    scene = der.Scene(rod, loads=[der.end_force([0, 0, -50.0])], constraints=[der.clamp("start")],
                      contacts=[der.cylinder([0.5, 0, zc], [0, 1, 0], R, radius=r)])
    res = der.solve(scene)
    x = res.state.positions
    over = np.abs(x[:, 0] - 0.5) < 0.05
    assert over.any() and np.all(x[over, 2] > zc + R)     # still above the cylinder's axis level + R
    assert r < res.contact["min_distance"] < r + 0.1 * r


def _ring(n):
    base = der.rod_from_shape(der.shapes.ring(1.0, n), A1, A2)
    return base.with_natural(kappa_bar=base.kappa_bar * 0.0)     # naturally straight, closed into a ring


def _bent(rod, state, twist_from, twist_to, eps):
    n = rod.n_edges
    x0 = rod.rest_q.reshape(-1, 4)[:, :3]
    phi = np.arctan2(x0[:, 1], x0[:, 0])
    dx = np.zeros_like(x0)
    dx[:, 2] = eps * 0.5 * (np.cos(2 * phi) + np.sin(3 * phi))
    return rod.displaced(state, dx, (twist_to - twist_from) * np.arange(n) / n)


def test_twisted_ring_past_michell_keeps_its_linking_number_with_self_contact():
    """Without contact the writhing ring passes through itself past Michell's threshold and Lk jumps by 2
    (scenarios/twisted_ring.py notes it); with self-contact Lk = twist / 2 pi at every step and the strands
    stay 2r apart."""
    base = _ring(60)
    r = 0.05
    th = cf.michell_twist(A1, A2)
    state, welded = base.rest_state(), 0.0
    contacts_seen = 0
    for twist in np.linspace(0.5 * th, 2.5 * th, 9):
        rod = base.with_imposed_twist(twist)
        scene = der.Scene(rod, contacts=[der.self_contact(r)])
        # kick the planar ring out of its plane; once its strands touch, a kick could push them into each other
        kick = 0.01 if contacts_seen == 0 else 0.0
        res = der.solve(scene, state=_bent(rod, state, welded, twist, kick), stability=False)
        lk, tw, wr = dg.linking_number(rod, res.state)
        assert lk == pytest.approx(twist / (2 * np.pi), abs=1e-6)
        assert res.contact["min_distance"] >= 2 * r
        contacts_seen = max(contacts_seen, res.contact["n_contacts"])
        state, welded = res.state, twist
    assert contacts_seen > 0 and wr > 1.5            # it did writhe into self-contact
    assert res.linear_solves["sparse"] > 0


def test_scene_without_contact_takes_the_banded_path_and_imports_nothing():
    rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=A1, A2=1.5)
    res = der.solve(der.Scene(rod, loads=[der.end_torque(1.0, follower=True)], constraints=[der.clamp("start")]))
    assert res.contact is None and res.linear_solves["sparse"] == 0 and res.linear_solves["band"] > 0
    code = ("import sys, der\nrod = der.rod_from_shape(der.shapes.straight(1.0, 10), 1.0, 1.5)\n"
            "der.solve(der.Scene(rod, constraints=[der.clamp('start')], loads=[der.end_force([0, 1e-3, 0])]))\n"
            "print(sorted(m for m in sys.modules if m.startswith('der.contact') or m.startswith('der.terms.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=os.path.dirname(os.path.dirname(os.path.abspath(der.__file__))))
    assert "der.contact" not in out.stdout


def test_inactive_contact_term_keeps_the_banded_path():
    rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=A1, A2=1.5)
    scene = der.Scene(rod, loads=[der.end_torque(1.0, follower=True)], constraints=[der.clamp("start")],
                      contacts=[der.self_contact(0.01)])
    res = der.solve(scene)
    assert res.linear_solves["sparse"] == 0 and res.contact["n_contacts"] == 0


@pytest.mark.parametrize("radius", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_radius(radius):
    with pytest.raises(ValueError, match="radius"):
        der.self_contact(radius)
    with pytest.raises(ValueError, match="radius"):
        der.plane([0, 0, 0], [0, 0, 1], radius=radius)


def test_start_violating_the_distance_names_the_edges():
    # a helix of pitch 0.05: consecutive turns are 0.05 apart, closer than 2r = 0.08
    rod = der.rod_from_shape(der.shapes.helix(kappa0=4.0, omega0=0.1, turns=2, n=80), A1=A1, A2=1.5)
    pitch = 2 * np.pi * 0.1 / (4.0 ** 2 + 0.1 ** 2)
    assert pitch < 0.08
    scene = der.Scene(rod, constraints=[der.clamp("start")], contacts=[der.self_contact(0.04)])
    with pytest.raises(ValueError, match=r"edges \d+ and \d+ are [0-9.e-]+ apart"):
        der.solve(scene)


def test_obstacle_intersecting_the_start():
    rod = _vertical_rod()
    scene = der.Scene(rod, constraints=[der.clamp("end")], contacts=[der.sphere([0.01, 0, 0.5], 0.1, radius=0.02)])
    with pytest.raises(ValueError, match="intersects the obstacle: edge"):
        der.solve(scene)


def test_radius_larger_than_the_radius_of_curvature():
    rod = der.rod_from_shape(der.shapes.ring(0.1, 40), A1, A2)        # natural radius of curvature 0.1
    with pytest.raises(ValueError, match="radius of curvature"):
        der.Scene(rod, contacts=[der.self_contact(0.2)])


def test_obstacle_needs_a_radius_and_contact_needs_the_implicit_solver():
    rod = _vertical_rod()
    with pytest.raises(ValueError, match="radius"):
        der.Scene(rod, contacts=[der.plane([0, 0, -1], [0, 0, 1])])
    with pytest.raises(TypeError, match="not a contact term"):
        der.Scene(rod, contacts=["floor"])
    scene = der.Scene(rod, constraints=[der.clamp("end")], contacts=[der.plane([0, 0, -1], [0, 0, 1], radius=0.01)])
    with pytest.raises(ValueError, match="implicit"):
        der.solve(scene, solver="explicit")


def _plectoneme_module():
    import importlib.util

    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenarios", "plectoneme.py")
    spec = importlib.util.spec_from_file_location("plectoneme_scenario", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_plectoneme_theory_limits():
    P = _plectoneme_module()
    # clamped Greenhill without tension: M L / A1 = 2 x 4.4934 (tan x = x); long rod: 2 sqrt(A1 F)
    assert P.buckling_torque(1.0, 1e-3, 1.0) == pytest.approx(8.98682, rel=2e-4)
    assert P.buckling_torque(2.0, 1.0, 200.0) == pytest.approx(2 * np.sqrt(2.0), rel=1e-3)
    assert P.buckling_torque(2.0, 1.0, 200.0) > 2 * np.sqrt(2.0)
    # interwound plateau: small-angle forms theta = (2 r^2 F / 3 A1)^(1/4), M = 2 A1 theta^3 / r
    r, F, A1 = 0.002, 1.0, 1.0
    Mp, theta, slope = P.plectoneme_theory(A1, F, r)
    t0 = (2 * r * r * F / (3 * A1)) ** 0.25
    assert theta == pytest.approx(t0, rel=2e-2)
    assert Mp == pytest.approx(2 * A1 * t0 ** 3 / r, rel=3e-2)
    assert slope == pytest.approx(-4 * np.pi * r / np.sin(2 * theta), rel=1e-12)


def test_plectoneme_scenario_contract_and_linking_number():
    script = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenarios", "plectoneme.py")
    out = subprocess.run([sys.executable, script, "--L", "10", "--n", "100", "--turns", "3", "--sweep", "12",
                          "--json"], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    import json

    d = json.loads(out.stdout.strip().splitlines()[-1])
    for key in ("turns", "extension", "torque", "twist", "writhe", "linking_number", "min_distance", "contacts"):
        assert len(d[key]) == 12
    for key in ("buckling_turns", "torque_plateau", "extension_slope"):
        assert key in d
    assert np.allclose(d["linking_number"], d["turns"], atol=1e-9, rtol=0)     # Lk = N: no strand passage
    assert max(d["contacts"]) > 0 and min(d["min_distance"]) >= 2 * 0.05
    # the imperfection nudges the free nodes only: the bottom clamp stays along z (it tilted by 3e-3 rad per
    # nudged step when node 1 was nudged too)
    assert d["clamp_tilt_max"] < 1e-12
    th = d["theory"]
    assert d["buckling_turns"] < th["buckling_turns"] < d["buckling_turns"] + 0.25 + 1e-12


def test_recording_shows_the_contacts(tmp_path):
    pytest.importorskip("rerun")
    from der.recording import read_scalars

    rod = _vertical_rod()
    zb = rod.rest_state().positions[0, 2]
    scene = der.Scene(rod, loads=[der.end_force([0, 0, -0.5])], constraints=[der.clamp("end", slide=2)],
                      contacts=[der.plane([0, 0, zb - 0.03], [0, 0, 1], radius=0.02)])
    path = tmp_path / "contact.rrd"
    der.solve(scene, record=str(path))
    _, values = read_scalars(str(path), "contact/0_plane/n_contacts")
    assert list(values) == [1.0]


def test_twisted_ring_scenario_with_radius_supercoils_without_passage():
    """scenarios/twisted_ring.py --radius (issue 14): past Michell's threshold the naturally straight ring, kicked
    out of plane, passes through itself without contact (Lk jumps by 2, exit 3) and settles into a
    self-contacting supercoil with it (Lk = twist / 2 pi at every step, strands >= 2r apart, exit 0)."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=str(root))
    args = [sys.executable, str(root / "scenarios" / "twisted_ring.py"), "--kappa0", "0", "--twist", "14",
            "--sweep", "7", "--n", "60", "--perturb", "0.01", "--json"]
    free = subprocess.run(args, capture_output=True, text=True, env=env, timeout=300)
    assert free.returncode == 3 and json.loads(free.stdout.splitlines()[-1])["strand_passage_at"] is not None
    held = subprocess.run(args + ["--radius", "0.05"], capture_output=True, text=True, env=env, timeout=300)
    out = json.loads(held.stdout.splitlines()[-1])
    assert held.returncode == 0, held.stderr
    assert out["strand_passage_at"] is None and out["lk_error_max"] < 1e-9
    assert out["writhe"] > 1.0 and out["contacts"] > 0 and out["min_distance"] >= 2 * 0.05
    assert all(s["lk_error"] < 1e-9 and s["min_distance"] >= 0.1 for s in out["sweep"])
