"""Twist of a closed loop (paper Section 6.1): a planar ring under a uniform twisting moment.

A closed ring of radius a0 (kappa0 = 1/a0, omega0 = 0) loaded by a uniform moment m_t per unit length about the
current tangent (a follower, circulatory load). The paper's solution (Eqs. 39-40) is correct: the ring stays a
planar circle and every cross-section turns by the same angle, sin(alpha) = m_t a0^2 / A1, up to the fold at
m_t = A1 / a0^2. Whether that planar state is *stable* the paper does not say: ``--sweep K`` continues from
m_t = 0 to ``--mt`` in K steps and finds, from the sign of the lowest eigenvalue of the stiffness at each
step, where the planar state stops being stable -- an out-of-plane bifurcation before the fold for some A1/A2.
With ``--perturb EPS`` each step starts from the previous state bent out of plane by EPS a0, so that beyond
that point the solver follows the ring out of the plane instead of holding the unstable planar state.

    python scenarios/loop_twist.py --through-fold [--n 100] --json    (der.continuation through the fold)
    python scenarios/loop_twist.py [--A1 1] [--A2 1.4925] [--a0 1] [--mt 0.5] [--sweep K] [--perturb EPS]
"""
import sys

import numpy as np

import der
from der import closed_forms as cf
from der import diagnostics as dg
from der.cli import POSITIVE, Range, scenario_main, validator

PARAMETERS = [
    ("A1", 1.0, float, "bending stiffness", POSITIVE),
    ("A2", 1.0 / 0.67, float, "twisting stiffness (A1/A2 = 0.67, DNA)", POSITIVE),
    ("a0", 1.0, float, "radius of the ring", POSITIVE),
    ("mt", 0.5, float, "twisting moment per unit length about the tangent (fold at A1/a0^2)",
     Range(lambda p: -2 * p.A1 / p.a0 ** 2, lambda p: 2 * p.A1 / p.a0 ** 2, nonzero=True,
           why="up to twice the fold A1/a0^2")),
    ("sweep", 0, int, "number of continuation steps K, at m_t = mt/K, 2 mt/K, ..., mt (0: a single solve)",
     Range(0, 10000)),
    ("perturb", 0.0, float, "out-of-plane perturbation (fraction of a0) applied at the start of every step",
     Range(0.0, 0.5, open_hi=True)),
    ("locate", False, bool, "after the sweep, bisect on m_t between the last stable and first unstable step"),
    ("through-fold", False, bool, "follow the planar branch through the fold by der.continuation (pseudo-arclength)"),
]


def perturbed(rod, state, eps, a0):
    """``state`` with its nodes moved out of plane by eps a0 (cos 2 phi + sin 3 phi) / 2, frames transported."""
    if eps == 0:
        return state
    x0 = rod.rest_q.reshape(-1, 4)[:, :3]
    phi = np.arctan2(x0[:, 1], x0[:, 0])
    dx = np.zeros_like(x0)
    dx[:, 2] = eps * a0 * 0.5 * (np.cos(2 * phi) + np.sin(3 * phi))
    return rod.displaced(state, dx)


def observe(rod, result, mt, p):
    st = result.state
    al = dg.alpha(rod, st)
    x = st.positions
    c = x - x.mean(axis=0)
    normal = np.linalg.svd(c, full_matrices=False)[2][-1]
    prof = dg.profile(rod, st)
    ref = float(cf.loop_alpha(mt, p.A1, p.a0))
    mean = float(np.nanmean(al))
    return {
        "mt": mt, "converged": result.converged, "status": result.status,
        "alpha": mean, "alpha_reference": ref, "alpha_spread": float(np.nanmax(al) - np.nanmin(al)),
        "kappa_mean": float(np.mean(prof["kappa"])), "omega_max_abs": float(np.nanmax(np.abs(prof["omega"]))),
        "out_of_plane": float(np.abs(c @ normal).max() / p.a0),
        "min_eigenvalue": result.min_eigenvalue, "stable": result.stable, "flutter": result.flutter,
    }


def through_fold(p):
    """The planar branch followed through its fold by pseudo-arclength continuation (der.continuation): alpha
    passes pi/2, m_t turns back, and the branch beyond is reported unstable."""
    rod = der.rod_from_shape(der.shapes.ring(p.a0, p.n), p.A1, p.A2, EA=getattr(p, "EA", None))
    fold = cf.loop_fold(p.A1, p.a0)
    branch = der.continuation(lambda mt: der.Scene(rod, loads=[der.twisting_moment(mt)]), 0.05 * fold,
                              parameter="mt", bounds=(0.0, 1.5 * fold), ds=0.2, locate_tol=1e-9,
                              summaries={"alpha": lambda scene, st: float(np.nanmean(dg.alpha(rod, st)))},
                              stop=lambda r: r["alpha"] > 2.5, max_steps=100, tol=p.tol)
    folds = [s for s in branch.special if s["kind"] == "fold"]
    fold_mt = folds[0]["mt"] / fold if folds else None
    return {"converged": bool(folds) and branch.status == "completed", "status": branch.status,
            "message": branch.message, "fold_mt": fold_mt, "fold_alpha": folds[0]["alpha"] if folds else None,
            "error": None if fold_mt is None else abs(fold_mt - 1.0),
            "reference": "fold of Eq. 40 at m_t a0^2/A1 = 1 (alpha = pi/2); error O(1/n^2)",
            "special": [{k: v for k, v in s.items() if k not in ("state", "tangent")} for s in branch.special],
            "continuation_s": branch.wall_time,
            "branch": [{"mt": r["mt"] / fold, "alpha": r["alpha"], "stable": r["stable"],
                        "min_eigenvalue": r["min_eigenvalue"]} for r in branch.points]}


def run(p, solver):
    if getattr(p, "through_fold", False):
        return through_fold(p)
    rod = der.rod_from_shape(der.shapes.ring(p.a0, p.n), p.A1, p.A2, EA=getattr(p, "EA", None))
    fold = cf.loop_fold(p.A1, p.a0)
    steps = np.linspace(p.mt / p.sweep, p.mt, p.sweep) if p.sweep else np.array([p.mt])
    state = rod.rest_state()
    sweep = []
    for mt in steps:
        scene = der.Scene(rod, loads=[der.twisting_moment(mt)])
        result = solver.solve(scene, state=perturbed(rod, state, p.perturb, p.a0))
        sweep.append(observe(rod, result, float(mt), p))
        if not result.converged:
            break
        state = result.state
    last = sweep[-1]
    out = {k: last[k] for k in ("alpha", "alpha_spread", "kappa_mean", "omega_max_abs", "out_of_plane",
                                "min_eigenvalue", "stable")}
    out["fold_mt"] = fold
    # alpha against Eq. 40 on the planar branch; within 10 % of the fold d(alpha)/d(m_t) = 1/cos(alpha) blows
    # up and with it any discretisation error, so those steps are left out of the headline error
    planar = [s for s in sweep if s["converged"] and s["out_of_plane"] < 1e-6 and abs(s["mt"]) <= 0.9 * fold]
    if planar:
        errs = [abs(s["alpha"] - s["alpha_reference"]) / abs(s["alpha_reference"]) for s in planar]
        out["error"] = max(errs)
        out["error_at_mt"] = planar[int(np.argmax(errs))]["mt"]
    else:
        out["error"] = None
    out["reference"] = "paper Eq. 40, sin(alpha) = m_t a0^2 / A1 (correct; docs/derivations.md, Loop twist)"
    out.update(_verdict(sweep, fold))
    theory, mode = cf.loop_threshold(p.A1, p.A2, p.a0)
    out["threshold_theory"], out["threshold_theory_mode"] = theory, mode
    if p.locate and out["threshold_kind"] and out["threshold_kind"].startswith("bifurcation"):
        out["threshold_mt"] = _bisect(p, solver, rod, sweep)
        out["threshold_located_by"] = "bisection on the sign of the lowest eigenvalue (relative width 1e-6)"
    if out["threshold_mt"] is not None:
        out["threshold_error"] = abs(out["threshold_mt"] - theory) / theory
    if p.sweep:
        out["sweep"] = sweep
        # the sweep is a success if every step either converged or was past the end of the planar branch
        out["converged"] = all(s["converged"] for s in sweep) or (not last["converged"] and last["mt"] > fold)
    return out


def _bisect(p, solver, rod, sweep):
    """Bisection on m_t for the sign change of the lowest eigenvalue, on the planar branch."""
    stable = [s for s in sweep if s["stable"]]
    unstable = [s for s in sweep if s["stable"] is False]
    lo, hi = stable[-1]["mt"], unstable[0]["mt"]
    state = rod.rest_state()
    while hi - lo > 1e-6 * hi:
        mid = 0.5 * (lo + hi)
        result = solver.solve(der.Scene(rod, loads=[der.twisting_moment(mid)]), state=state)
        if not result.converged:
            raise RuntimeError(f"bisection solve failed at m_t = {mid}: {result.message}")
        if result.stable:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _verdict(sweep, fold):
    """Where the planar state stops being a stable equilibrium, and what happens beyond."""
    out = {"threshold_mt": None, "threshold_kind": None, "beyond": "the planar ring is stable at every step"}
    prev = None
    for s in sweep:
        if not s["converged"]:
            if s["mt"] > fold:
                out["beyond"] = (f"no equilibrium at m_t = {s['mt']:.6g} ({s['status']}): past the fold "
                                 f"m_t = A1/a0^2 = {fold:.6g} the cross-sections rotate without bound")
            else:
                out["beyond"] = (f"no equilibrium found at m_t = {s['mt']:.6g} ({s['status']}): the ring left the "
                                 f"plane (out_of_plane = {s['out_of_plane']:.3g} a0) and the damped dynamics did "
                                 "not settle within the limits")
            if out["threshold_mt"] is None and s["mt"] > fold:
                out["threshold_mt"], out["threshold_kind"] = fold, "fold (no planar equilibrium beyond)"
            break
        if s["stable"] is False and out["threshold_mt"] is None:
            if prev is not None and prev["min_eigenvalue"] is not None:
                a, b = prev["min_eigenvalue"], s["min_eigenvalue"]
                out["threshold_mt"] = prev["mt"] + (s["mt"] - prev["mt"]) * a / (a - b)
            else:
                out["threshold_mt"] = s["mt"]
            out["threshold_kind"] = "bifurcation (an eigenvalue crosses zero before the fold)"
            out["beyond"] = ("the planar ring is an unstable equilibrium; with --perturb the solver leaves the "
                             "plane")
        if out["threshold_mt"] is not None and s["out_of_plane"] > 1e-3:
            out["beyond"] = (f"the ring leaves the plane: out_of_plane = {s['out_of_plane']:.3g} a0 at "
                             f"m_t = {s['mt']:.6g}, stable = {s['stable']}")
        prev = s
    return out


def validate(p):
    if getattr(p, "through_fold", False):
        return
    if not p.sweep and abs(p.mt) > cf.loop_fold(p.A1, p.a0):
        raise ValueError(f"--mt = {p.mt} is past the fold A1/a0^2 = {cf.loop_fold(p.A1, p.a0):.6g}: no planar "
                         "equilibrium exists; use --sweep to continue up to and past it")


run.validate = validator(PARAMETERS, validate)

if __name__ == "__main__":
    sys.exit(scenario_main("loop_twist", __doc__.splitlines()[0], PARAMETERS, run, n_default=200, n_min=3))
