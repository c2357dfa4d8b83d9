"""Stiff and extreme cases: every one ends converged (and checked against a closed form where one exists) or
with a clear, specific error -- never a NaN, a hang or a silently wrong answer.

    python tools/stability.py [--json] [--budget 120] [--quick]

Cases (each with a time budget):
  stiffness   EA L^2/A1 from 1e2 to 1e12, cantilever with a small tip load (both solvers; n = 50 and, implicit
              only, n = 1000): tip deflection against P L^3 / (3 A1); the explicit solver's cost grows with the
              stiffness until the budget stops it;
  A1/A2       1e-3 ... 1e3, ring torsion against its corrected closed form;
  n           2 ... 100,000 edges, a straight rod twisted by an end torque against T L / A2 (exact for any n;
              solved to the round-off floor, tol 1e-13, since the end twist sums the per-node residual);
  load        1e-12 ... 1e3 times A1/L^2 on a cantilever: linear theory at small loads, the elastica (solve_bvp)
              at large ones; the loop moment at 0.999 and 1.001 of the fold A1/a0^2;
  helix       50 turns, lam = omega0/kappa0 from 0.01 to 100, nearly straight and nearly fully stretched, against
              the corrected helix-winding force and torque;
  greenhill   a straight rod clamped at both ends, the far end sliding along the axis and turned past Greenhill's
              torque 8.9868 A1/L: the straight state is found unstable; kicked, the rod leaves it and writhes;
  dt          the explicit solver asked for a step above its stable limit: refused.
Outcomes: converged (checked), unstable (converged to an equilibrium reported unstable), not converged (status
and message: budget, no equilibrium, round-off floor), invalid input (ValueError). "Unexplained" would be any
other exception, a NaN, or a converged result that fails its check; the tool exits 1 if there is one.
"""
import argparse
import json
import os
import sys
import time
import traceback

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import der  # noqa: E402
from der import closed_forms as cf  # noqa: E402
from der import diagnostics as dg  # noqa: E402

CASES = []


def case(group):
    def wrap(fn):
        CASES.append((group, fn))
        return fn
    return wrap


def solve(scene, budget, **kw):
    """der.solve with a time budget; never raises ConvergenceError (the result says what happened)."""
    return der.solve(scene, raise_on_failure=False, time_budget=budget, **kw)


def outcome(res, check=None, tol=None, note=""):
    """One result row from a SolveResult and an optional relative error against a closed form."""
    row = {"status": res.status, "converged": res.converged, "residual": res.residual,
           "iterations": res.iterations, "solve_s": res.wall_time, "stable": res.stable,
           "message": res.message, "note": note}
    if res.converged and check is not None:
        row["check"] = check
        row["check_tol"] = tol
        row["check_ok"] = bool(check <= tol)
    if res.converged and res.stable is False:
        row["outcome"] = "unstable equilibrium"
    elif res.converged:
        row["outcome"] = "converged"
    else:
        row["outcome"] = f"not converged ({res.status})"
    return row


# ------------------------------------------------------------------------------------------- stiffness ratio
def cantilever(n, P, EA=None, L=1.0, A1=1.0):
    rod = der.rod_from_shape(der.shapes.straight(L, n), A1, 1.0, EA=EA)
    return der.Scene(rod, loads=[der.end_force([P, 0.0, 0.0])], constraints=[der.clamp("start")])


def tip(res):
    x = res.state.positions
    return 0.5 * (x[-1] + x[-2])


def stiffness_cases(quick):
    ratios = [1e2, 1e4, 1e6, 1e8, 1e10, 1e12]
    out = []
    for solver, n in (("implicit", 50), ("explicit", 50), ("implicit", 1000)):
        for S in ratios:
            if quick and (n == 1000 or S in (1e4, 1e8)):
                continue
            out.append((f"EA L^2/A1 = {S:.0e}, n = {n}, {solver}", solver, n, S))
    return out


@case("stiffness")
def stiffness(budget, quick):
    rows = []
    for name, solver, n, S in stiffness_cases(quick):
        P = 1e-3
        res = solve(cantilever(n, P, EA=S), budget, solver=solver)
        exact = P / 3.0                      # P L^3 / (3 A1); extension is second order for a transverse load
        err = abs(tip(res)[0] - exact) / exact if res.converged else None
        # discretisation error 0.26/n^2 at these n (measured, tests/test_solvers.py) and 1/S from extensibility
        rows.append({"case": name, "solver": solver, "n": n, "ratio": S,
                     **outcome(res, err, 0.3 / n ** 2 + 10.0 / S + 1e-6,
                               "tip deflection vs P L^3/(3 A1)")})
    return rows


# ------------------------------------------------------------------------------------------------- A1 / A2
@case("A1/A2")
def stiffness_ratio(budget, quick):
    rows = []
    for ratio in ([1e-3, 1.0, 1e3] if quick else [1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3]):
        A1, A2, a0, L, n = 1.0, 1.0 / ratio, 1.0, 3.0, 100
        T = 1e-4 * min(A1, A2) / L
        rod = der.rod_from_shape(der.shapes.arc(a0, L, n), A1, A2)
        res = solve(der.Scene(rod, loads=[der.end_torque(T, follower=True)], constraints=[der.clamp("start")]),
                    budget)
        err = None
        if res.converged:
            _, rot = dg.end_motion(rod, res.state)
            ref = cf.ring_end_rotation(A1, A2, a0, L, T)
            err = float(np.linalg.norm(rot - ref) / np.linalg.norm(ref))
        rows.append({"case": f"ring torsion, A1/A2 = {ratio:g}, n = {n}", "solver": "implicit", "n": n,
                     **outcome(res, err, 2e-3, "end rotation vs corrected closed form (disc. error ~3e-4)")})
    return rows


# ------------------------------------------------------------------------------------------------------ n
@case("n")
def many_edges(budget, quick):
    rows = []
    for n in ([2, 100, 10000] if quick else [2, 3, 10, 100, 1000, 10000, 100000]):
        L, A2, T = 1.0, 1.5, 0.5
        rod = der.rod_from_shape(der.shapes.straight(L, n), 1.0, A2)
        # the end twist sums the per-node residual over n vertices (error <= residual_per_length): asked for
        # tol 1e-13, the solve goes down to the round-off floor and the discrete answer's exactness shows
        res = solve(der.Scene(rod, loads=[der.end_torque([0, 0, T])], constraints=[der.clamp("start")]), budget,
                    stability=n <= 10000, tol=1e-13)
        err = abs(res.state.theta[-1] - res.state.theta[0] - T * L / A2) / (T * L / A2) if res.converged else None
        rows.append({"case": f"straight rod twist, n = {n}, tol 1e-13", "solver": "implicit", "n": n,
                     **outcome(res, err, 1e-10, "end twist vs T L / A2 (exact for any n)")})
    return rows


# ------------------------------------------------------------------------------------------------- loads
def elastica_tip(load, L=1.0):
    """Tip (x, z) of the planar elastica with a transverse tip force, by solve_bvp with load continuation."""
    from scipy.integrate import solve_bvp

    s = np.linspace(0, L, 2001)
    y = np.zeros((4, s.size))
    y[3] = s
    for p in np.geomspace(1e-2, load, 40) if load > 1e-2 else [load]:
        sol = solve_bvp(lambda s, y: np.vstack([y[1], -p * np.cos(y[0]), np.sin(y[0]), np.cos(y[0])]),
                        lambda a, b: np.array([a[0], b[1], a[2], a[3]]), s, y, tol=1e-9, max_nodes=500000)
        if not sol.success:
            raise RuntimeError(f"elastica reference failed at load {p}")
        s, y = sol.x, sol.y
    return sol.sol(L)[2], sol.sol(L)[3]


@case("load")
def loads(budget, quick):
    rows = []
    levels = [1e-12, 1e-4, 1.0, 1e3] if quick else [1e-12, 1e-8, 1e-4, 1e-2, 1.0, 10.0, 100.0, 1e3]
    for P in levels:
        n = 100 if P < 100 else 400        # the clamp boundary layer sqrt(A1/P) needs resolving at large loads
        res = solve(cantilever(n, P), budget)
        err = None
        if res.converged:
            x = tip(res)
            if P <= 1e-4:
                exact = P / 3.0
                err = abs(x[0] - exact) / exact
                # discretisation (0.26/n^2) + positions rounded to eps |x| ~ eps L, against a deflection of P/3
                tol = 1e-4 + 10 * np.finfo(float).eps / exact
                note = "vs linear P L^3/(3 A1); round-off of the positions allowed for"
            else:
                xr, zr = elastica_tip(P)
                err = float(np.hypot(x[0] - xr, x[2] - zr))
                tol, note = 3e-3, "tip vs elastica (solve_bvp), absolute / L"
        else:
            tol, note = None, ""
        rows.append({"case": f"cantilever, P L^2/A1 = {P:g}, n = {n}", "solver": "implicit", "n": n,
                     **outcome(res, err, tol, note)})
    for f in (0.999, 1.001):
        rod = der.rod_from_shape(der.shapes.ring(1.0, 200), 1.0, 1.0 / 0.67)
        res = solve(der.Scene(rod, loads=[der.twisting_moment(f)]), budget, max_iterations=300)
        err = None
        if res.converged:
            err = abs(np.nanmean(dg.alpha(rod, res.state)) - np.arcsin(f)) / np.arcsin(f)
        note = ("alpha vs arcsin(m_t a0^2/A1); 1/cos(alpha) = 22 magnifies the O(h^2) shift of the discrete fold"
                if f < 1 else "past the fold: no equilibrium exists, the solve must say so")
        row = {"case": f"loop moment {f} x A1/a0^2, n = 200", "solver": "implicit", "n": 200,
               **outcome(res, err, 1e-2, note)}
        if f > 1:
            row["expected"] = "not converged"
        rows.append(row)
    return rows


# ------------------------------------------------------------------------------------------------- helices
def winding(lam, eta, phi, turns, per_turn, budget):
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "helix_winding", os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scenarios",
                                      "helix_winding.py"))
    hw = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hw)
    n = int(per_turn * turns)
    rod = der.rod_from_shape(der.shapes.helix(1.0, lam, turns, n), 0.67, 1.0)
    state = hw.deformed_state(rod, eta, phi, lam)
    scene = der.Scene(rod, constraints=[der.clamp("start"), der.clamp("end")])
    res = solve(scene, budget, state=state, stability=False)
    err, note = None, ""
    if res.converged:
        m = hw.measure(rod, res.state, lam)
        ref = np.array([cf.winding_P0(eta, phi, lam, 0.67), cf.winding_T0(eta, phi, lam, 0.67)])
        err = float(np.linalg.norm(np.array([m["P0"], m["T0"]]) - ref) / np.linalg.norm(ref))
        if m["uniformity"] > 1e-2:
            err, note = None, "converged to a non-uniform shape"
    else:
        # why: is the uniform helix itself stable? (a few Newton steps bring it to its equilibrium)
        near = solve(scene, budget, state=state, stability=False, max_iterations=8)
        st = der.check_stability(scene, near.state)
        if not st.stable:
            note = (f"the uniform helix is an UNSTABLE equilibrium here (lowest eigenvalues "
                    f"{np.round(np.real(st.eigenvalues[:2]), 8).tolist()}): the rod leaves it and no nearby "
                    "equilibrium was reached within the limits")
    return n, res, err, note


@case("helix")
def helices(budget, quick):
    rows = []
    lams = [0.01, 1.0, 100.0] if quick else [0.01, 0.1, 1.0, 10.0, 100.0]
    for lam in lams:
        em = float(cf.winding_eta_max(lam))
        eta = min(1.05, 0.5 * (1 + em))
        n, res, err, note = winding(lam, eta, 0.05, 50, 40, budget)
        rows.append({"case": f"helix 50 turns, lam = {lam:g}, eta = {eta:.4g}, phi = 0.05", "solver": "implicit",
                     "n": n, **outcome(res, err, 2e-2, note or "(P0, T0) vs corrected Eq. 81 (disc. ~6e-3)")})
    em = float(cf.winding_eta_max(0.6))
    n, res, err, note = winding(0.6, 0.995 * em, 0.0, 50, 40, budget)
    rows.append({"case": "helix 50 turns, lam = 0.6, nearly stretched: eta = 0.995 eta_max", "solver": "implicit",
                 "n": n, **outcome(res, err, 2e-2, note or "(P0, T0) vs corrected Eq. 81")})
    return rows


# ----------------------------------------------------------------------------------------------- Greenhill
@case("greenhill")
def greenhill(budget, quick):
    """Greenhill's problem: both ends clamped, the far end free to slide along the axis (no axial force) and
    turned. With the distance between the clamps held fixed instead, an inextensible rod cannot leave the
    straight state at all (any deflection would stretch it) and the axial reaction is indeterminate."""
    L, A1, A2, n = 1.0, 1.0, 1.0, 60
    crit = 8.9868 * A1 / A2 * L          # end rotation at Greenhill's torque T L / A1 = 2.8606 pi (clamped ends)
    rod = der.rod_from_shape(der.shapes.straight(L, n, axis=(0, 0, 1)), A1, A2)
    rows = []

    def scene_of(phi):
        R = np.array([[np.cos(phi), -np.sin(phi), 0], [np.sin(phi), np.cos(phi), 0], [0, 0, 1.0]])
        return der.Scene(rod, constraints=[der.clamp("start"), der.clamp("end", rotation=R, slide=2)])

    # the straight branch followed by der.continuation (pseudo-arclength in the end rotation, the lowest
    # eigenvalue at every point); the change of stability located by its secant on the lowest eigenvalue
    branch = der.continuation(scene_of, 0.1, 1.2 * crit, parameter="phi", ds=0.15, ds_max=0.15, locate_tol=1e-9,
                              max_steps=100, time_budget=budget, progress=False)
    cross = next((sp["phi"] for sp in branch.special if sp["kind"] == "bifurcation"), None)
    # the last point, at 1.2 x critical: a der.solve from it (converged at once) gives the row its SolveResult
    res = solve(scene_of(branch.points[-1]["phi"]), budget, state=branch.states[-1])
    state = res.state
    straight = float(np.abs(state.positions[:, :2]).max())
    row = {"case": f"Greenhill: clamped, far end sliding along the axis and turned to 1.2 x critical, n = {n}",
           "solver": "implicit", "n": n, **outcome(res, abs(cross - crit) / crit if cross else None, 2e-2,
                                                   "eigenvalue sign change (der.continuation) vs 8.9868 A1/A2 "
                                                   "(disc. error ~1e-3)")}
    row["threshold"] = cross
    row["branch_points"] = len(branch.points)
    row["branch_status"] = branch.status
    row["stability_s"] = float(sum(p["stability_time"] for p in branch.points))
    row["lateral_deflection"] = straight
    rows.append(row)
    # kicked out of the unstable straight state (a small lateral bulge, clamped nodes left alone). Newton's
    # method from the start goes to the nearest equilibrium -- the straight one, reported unstable; the
    # damped start (newton_first=False) follows the dynamics out of it. Check of the latter: 0.01 L / (largest
    # lateral deflection) below 1, i.e. it left the straight state.
    bulge = np.zeros((rod.n_nodes, 3))
    bulge[2:-2, 0] = 1e-3 * np.sin(np.pi * rod.xi_nodes[2:-2] / L)
    kicked = rod.displaced(state, bulge)
    for newton_first in (True, False):
        R = np.array([[np.cos(1.2 * crit), -np.sin(1.2 * crit), 0], [np.sin(1.2 * crit), np.cos(1.2 * crit), 0],
                      [0, 0, 1.0]])
        scene = der.Scene(rod, constraints=[der.clamp("start"), der.clamp("end", rotation=R, slide=2)])
        relaxed = solve(scene, budget, state=kicked, newton_first=newton_first)
        deflection = float(np.abs(relaxed.state.positions[:, :2]).max())
        lost = (dg.total_twist(rod, state) - dg.total_twist(rod, relaxed.state)) / (2 * np.pi)
        what = (f"lateral deflection {deflection:.2g} L, {lost:.3f} turns of twist turned into writhe, "
                f"end slid by {relaxed.state.positions[-1, 2] - state.positions[-1, 2]:.3f} L")
        r2 = {"case": f"Greenhill: same, kicked, newton_first={newton_first}, n = {n}", "solver": "implicit", "n": n,
              **(outcome(relaxed, note="back to the straight state, " + what) if newton_first else
                 outcome(relaxed, 0.01 * L / max(deflection, 1e-300), 1.0, "leaves the straight state: " + what))}
        r2["lateral_deflection"] = deflection
        r2["twist_to_writhe_turns"] = float(lost)
        rows.append(r2)
    return rows


# ---------------------------------------------------------------------------------------------- explicit dt
@case("dt")
def explicit_dt(budget, quick):
    scene = cantilever(50, 1e-3, EA=1e6)
    try:
        der.solve(scene, solver="explicit", dt=1.0)
        return [{"case": "explicit dt = 1 (far above the stable limit)", "solver": "explicit", "n": 50,
                 "outcome": "UNEXPLAINED: accepted", "status": "accepted"}]
    except ValueError as exc:
        return [{"case": "explicit dt = 1 (far above the stable limit)", "solver": "explicit", "n": 50,
                 "outcome": "invalid input (refused)", "status": "ValueError", "message": str(exc)}]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=float, default=120.0, help="time budget per solve, seconds")
    ap.add_argument("--quick", action="store_true", help="a subset (for tests)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    compile_s = der.warmup()
    rows = []
    for group, fn in CASES:
        t0 = time.perf_counter()
        try:
            got = fn(args.budget, args.quick)
        except Exception as exc:   # anything escaping a case is by definition unexplained
            got = [{"case": f"{group}: {type(exc).__name__}", "outcome": "UNEXPLAINED exception",
                    "message": "".join(traceback.format_exception_only(type(exc), exc)).strip()}]
        for r in got:
            r["group"] = group
            r["wall_s"] = time.perf_counter() - t0
        rows += got
        print(f"[stability] {group}: {len(got)} cases in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    for r in rows:
        nan = any(isinstance(v, float) and v != v for k, v in r.items() if k in ("residual", "check"))
        r["nan"] = bool(nan)
        unexplained = r["outcome"].startswith("UNEXPLAINED") or nan or r.get("check_ok") is False
        if r.get("expected") == "not converged" and r.get("converged"):
            unexplained = True
        r["unexplained"] = bool(unexplained)
    print(f"compile (or cache load): {compile_s:.2f} s")
    print(f"{'group':<10} {'case':<74} {'outcome':<34} {'residual':>9} {'iter':>8} {'solve s':>8} {'check':>9}")
    for r in rows:
        res = f"{r['residual']:.1e}" if isinstance(r.get("residual"), float) else "-"
        chk = f"{r['check']:.1e}" if isinstance(r.get("check"), float) else "-"
        it = str(r.get("iterations", "-"))
        st = f"{r['solve_s']:.3f}" if isinstance(r.get("solve_s"), float) else "-"
        flag = "  <-- UNEXPLAINED" if r["unexplained"] else ""
        print(f"{r['group']:<10} {r['case'][:74]:<74} {r['outcome'][:34]:<34} {res:>9} {it:>8} {st:>8} {chk:>9}{flag}")
        if not r.get("converged") or r.get("lateral_deflection") is not None:
            why = r.get("note") or r.get("message") or ""
            extra = f" lateral deflection {r['lateral_deflection']:.3g};" if r.get("lateral_deflection") is not None \
                else ""
            print(f"{'':<10}   ->{extra} {why[:160]}")
    counts = {}
    for r in rows:
        counts[r["outcome"]] = counts.get(r["outcome"], 0) + 1
    summary = {"cases": len(rows), "outcomes": counts, "nan": sum(r["nan"] for r in rows),
               "unexplained": sum(r["unexplained"] for r in rows),
               "hangs": 0, "budget_s": args.budget}
    print("\n" + ", ".join(f"{k}: {v}" for k, v in counts.items()))
    print(f"{summary['cases']} cases; NaN: {summary['nan']}; unexplained: {summary['unexplained']}; every solve had a "
          f"{args.budget:g} s budget")
    if args.json:
        print(json.dumps({"compile_s": compile_s, "summary": summary, "rows": rows}, default=str))
    return 1 if summary["unexplained"] else 0


if __name__ == "__main__":
    sys.exit(main())
