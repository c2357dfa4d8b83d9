"""Greenhill past its threshold with contact: a loop, then a plectoneme, instead of lost turns.

A straight rod of length L and radius r along z, both ends clamped, the top end free to slide along z (no axial
force unless --force), is turned about z by its top clamp in a continuation from 0 to --over times Greenhill's
critical end rotation in --sweep steps, each solve starting from the last state. The straight rod is stable up
to the torque M L / A1 = 2 x 4.4934 (tan x = x; with an axial pulling force F, the first root of the clamped
rod's buckling condition, scenarios/plectoneme.py ``buckling_torque``), i.e. N_c = M_c L / (2 pi A2) turns
(1.4303 A1 / A2 for F = 0). Past it the rod writhes: without contact (``--no-contact``), pulled, it passes
through itself, loses two turns of Lk at a time and returns towards the straight state (with no force it closes
into a ring whose end edges coincide, where Lk of the open rod is not defined); with ``der.rod_contact(r)`` it
forms a loop whose strands touch, then a plectoneme (two interwound strands), and Lk = N at every step.

The lateral imperfection (--perturb) moves the free nodes only (the clamps hold their end edges where the start
state has them: a nudged node 1 tilted the bottom clamp); a straight state the solve returns past N_c, unstable,
is kicked along its unstable mode and solved again (der.continuation.leave_unstable).

Reported per step (lists): ``turns`` N, ``twist`` Tw and ``writhe`` Wr (turns; the open centreline closed as
in scenarios/plectoneme.py), ``linking_number`` Tw + Wr, ``extension`` (top minus bottom end height),
``lateral`` (largest distance of a node from the axis), ``torque`` (A2 times the mean twist density),
``min_distance`` (smallest centreline distance of non-neighbour edges) and ``contacts`` (pairs in contact);
scalars ``greenhill_turns`` (theory N_c), ``buckling_turns`` (the last step still straight: lateral < 1e-2 L),
``loop_turns`` (the first step with a contact), ``plectoneme_turns`` (the first step whose contacts span more
than a loop: contact pairs along at least 10 % of the rod), ``lk_error_max``, ``clamp_tilt_max`` (the largest
angle, rad, of the bottom clamp's end edge against z over the steps, ``clamp_tilt`` per step: 0 to round-off).

The check (exit 3 otherwise): with contact, |Lk - N| < 1e-6 and min_distance >= 2r at every step.

    python scenarios/greenhill.py [--A1 1] [--A2 1] [--L 1] [--radius 0.02] [--over 2.5] [--sweep 40]
                                  [--n 100] [--no-contact] [--json]
"""
import importlib.util
import os
import sys

import numpy as np

import der
from der import diagnostics as dg
from der.cli import check_contact_resolution, scenario_main
from der.continuation import leave_unstable

PARAMETERS = [
    ("A1", 1.0, float, "bending stiffness"),
    ("A2", 1.0, float, "twisting stiffness"),
    ("L", 1.0, float, "rod length"),
    ("EA", 1e4, float, "axial stiffness (times L^2 / A1: the rod is nearly inextensible)"),
    ("radius", 0.02, float, "rod radius r (contact at centreline distance 2r)"),
    ("force", 0.0, float, "axial pulling force F on the sliding top end (0: Greenhill's problem)"),
    ("over", 2.5, float, "end rotation at the end of the continuation, in units of Greenhill's critical one"),
    ("sweep", 40, int, "continuation steps (at most 1/8 turn each)"),
    ("perturb", 1e-3, float, "lateral imperfection (fraction of L) added to the start of each step while straight "
     "(not on the clamped nodes), and the kick along the unstable mode of a straight state the solve returns"),
    ("contact", True, bool, "self-contact of the rod (--no-contact: the rod passes through itself)"),
]

STRAIGHT = 1e-2          # lateral deflection (fraction of L) below which the rod counts as straight
PLECTONEME_SPAN = 0.1    # contact pairs along at least this fraction of the rod: more than one loop's touch point
MAX_ITERATIONS = 5000    # per step: the snap into a loop is a long transient
TAN_ROOT = 4.493409457909064     # first positive root of tan x = x


def _plectoneme():
    """scenarios/plectoneme.py (its closure of the open centreline and its buckling condition)."""
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "plectoneme.py")
    spec = importlib.util.spec_from_file_location("plectoneme_scenario", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def critical_turns(p):
    """Greenhill's threshold in turns of the end: N_c = M_c L / (2 pi A2), M_c = 2 x 4.4934 A1 / L without an
    axial force (the clamped rod's first buckling torque), else plectoneme.buckling_torque(A1, F, L)."""
    Mc = 2 * TAN_ROOT * p.A1 / p.L if p.force == 0 else _plectoneme().buckling_torque(p.A1, p.force, p.L)
    return Mc * p.L / (2 * np.pi * p.A2)


def observe(P, rod, result, N, p):
    st = result.state
    x = st.positions
    tw = dg.total_twist(rod, st) / (2 * np.pi)
    wr = P.closed_writhe(x, p.L)
    bottom, top = 0.5 * (x[0] + x[1]), 0.5 * (x[-2] + x[-1])
    c = result.contact or {}
    term = (c.get("terms") or [{}])[0]
    pairs = np.asarray(term.get("pairs", []), dtype=int).reshape(-1, 2)
    # the length of rod along which the strands touch: a loop touches itself at one crossing (the first edges of
    # its pairs bunch together), a plectoneme along its whole interwound part
    span = (pairs[:, 0].max() - pairs[:, 0].min() + 1) / rod.n_edges if pairs.size else 0.0
    return {
        "turns": float(N), "converged": result.converged, "status": result.status,
        "twist": float(tw), "writhe": float(wr), "linking_number": float(tw + wr),
        "extension": float(top[2] - bottom[2]), "lateral": float(np.linalg.norm(x[:, :2], axis=1).max()),
        "torque": float(p.A2 * dg.material_twist_density(rod, st).mean()),
        "min_distance": c.get("min_distance"), "contacts": int(c.get("n_contacts", 0)), "contact_span": float(span),
        # the bottom clamp's end edge against the z axis (rad): 0 to round-off, the clamp is not tilted
        "clamp_tilt": P.bottom_tilt(x),
        "iterations": result.iterations, "runtime_s": result.wall_time,
    }


def run(p, solver):
    P = _plectoneme()
    rod = der.rod_from_shape(der.shapes.straight(p.L, p.n), p.A1, p.A2, EA=p.EA * p.A1 / p.L ** 2)
    Nc = critical_turns(p)
    turns = np.linspace(0.0, p.over * Nc, p.sweep + 1)[1:]
    contacts = [der.rod_contact(p.radius)] if p.contact else []
    loads = [der.end_force([0.0, 0.0, p.force])] if p.force else []
    xi = rod.rest_q.reshape(-1, 4)[:, 2] / p.L
    bump = np.zeros((rod.n_nodes, 3))
    bump[:, 0] = p.perturb * p.L * np.sin(np.pi * np.clip(xi, 0, 1))
    # not on the nodes the clamps hold (each clamp holds its end edge where the start state has it, so a
    # nudged node 1 would tilt the bottom clamp, by a little more at every nudged step)
    bump[:2] = 0.0
    bump[-2:] = 0.0
    state = rod.rest_state()
    steps = []
    for N in turns:
        scene = der.Scene(rod, loads=loads, contacts=contacts, constraints=[
            der.clamp("start"), der.clamp("end", rotation=P.rotation_z(2 * np.pi * N), slide=2)])
        start = state
        straight = not steps or steps[-1]["lateral"] < STRAIGHT * p.L
        if p.perturb and straight:
            start = rod.displaced(state, bump)      # the straight state is unstable past N_c: a nudge
        result = solver.solve(scene, state=start, stability=False, max_iterations=MAX_ITERATIONS)
        if p.perturb and straight and result.converged:
            # past N_c the solve may still return the straight state (an equilibrium, unstable: a root finder
            # finds saddles too); kicked along its unstable mode (p.perturb L) and solved again, it leaves it
            first = result
            result, kicks = leave_unstable(scene, result, p.perturb, solve=solver.solve, max_iterations=MAX_ITERATIONS)
            if kicks:
                result.iterations += first.iterations        # (every solve of the step counts)
                result.wall_time += first.wall_time
        steps.append(observe(P, rod, result, N, p))
        if not result.converged:
            break
        state = result.state
    return summarise(p, steps, Nc)


def summarise(p, steps, Nc):
    N = np.array([s["turns"] for s in steps])
    out = {k: [s[k] for s in steps] for k in ("turns", "twist", "writhe", "linking_number", "extension", "lateral",
                                              "torque", "min_distance", "contacts", "contact_span")}
    out["converged"] = all(s["converged"] for s in steps) and len(steps) == p.sweep
    lk_err = np.abs(np.array(out["linking_number"]) - N)
    out["lk_error_max"] = float(lk_err.max()) if lk_err.size else None
    bent = [k for k, s in enumerate(steps) if s["lateral"] >= STRAIGHT * p.L]
    out["buckling_turns"] = float(N[bent[0] - 1]) if bent and bent[0] > 0 else None
    touching = [k for k, s in enumerate(steps) if s["contacts"] > 0]
    out["loop_turns"] = float(N[touching[0]]) if touching else None
    plect = [k for k, s in enumerate(steps) if s["contact_span"] >= PLECTONEME_SPAN]
    out["plectoneme_turns"] = float(N[plect[0]]) if plect else None
    out["greenhill_turns"] = float(Nc)
    out["clamp_tilt_max"] = float(max(s["clamp_tilt"] for s in steps)) if steps else None
    out["final"] = {"turns": float(N[-1]) if N.size else None, "writhe": out["writhe"][-1] if steps else None,
                    "linking_number": out["linking_number"][-1] if steps else None,
                    "contacts": out["contacts"][-1] if steps else None}
    err = {}
    if out["buckling_turns"] is not None:
        err["buckling_turns"] = (out["buckling_turns"] - Nc) / Nc      # within one step below N_c
        err["buckling_step"] = float(N[1] - N[0]) / Nc if N.size > 1 else None
    out["errors"] = err
    out["error"] = out["lk_error_max"]
    out["reference"] = "Lk = N at every step (absolute, turns); Greenhill's threshold N_c in greenhill_turns"
    out["sweep"] = steps
    if p.contact and steps:
        d = [s["min_distance"] for s in steps if s["min_distance"] is not None]
        if out["lk_error_max"] > 1e-6:
            out["check_failed"] = (f"Lk differs from N by {out['lk_error_max']:.3g} turns: a strand passed through "
                                   "another")
        elif d and min(d) < 2 * p.radius:
            out["check_failed"] = f"min_distance {min(d):.6g} < 2r = {2 * p.radius:.6g}"
    return out


def validate(p):
    for name in ("A1", "A2", "L", "EA", "radius", "over"):
        if not getattr(p, name) > 0:
            raise ValueError(f"--{name} must be > 0; got {getattr(p, name)}")
    if not p.force >= 0:
        raise ValueError(f"--force must be >= 0 (a pulling force); got {p.force}")
    if p.sweep < 1:
        raise ValueError(f"--sweep must be >= 1; got {p.sweep}")
    if p.over > 10:
        raise ValueError(f"--over must be at most 10 (times the critical rotation); got {p.over}")
    step_turns = p.over * 1.4303 * p.A1 / p.A2 / p.sweep
    if p.force == 0 and step_turns > 0.125:
        raise ValueError(f"--sweep {p.sweep} is too coarse for --over {p.over}: {step_turns:.3g} turns per step, at "
                         f"most 1/8 (--sweep >= {int(np.ceil(p.over * 1.4303 * p.A1 / p.A2 / 0.125))})")
    check_contact_resolution(p)


run.validate = validate

if __name__ == "__main__":
    sys.exit(scenario_main("greenhill", __doc__.splitlines()[0], PARAMETERS, run, n_default=100, n_min=10,
                           tol_default=1e-6))
