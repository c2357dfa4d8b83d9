"""Twisted ring: a closed rod welded with extra twist, Michell's instability, and writhe.

A ring of length L = 2 pi a0 (a regular polygon of n edges on the circle of radius a0) with natural curvature
kappa0 (``--kappa0 0``: a naturally straight rod closed into a ring; the default 1/a0: a naturally circular
rod, the paper's) and natural twist 0, whose ends were welded after a rotation by ``--twist`` radians about
the tangent: the extra linking number is twist / 2 pi. The twist is spread uniformly over the edge angles at
the start and the ring relaxed. Reported: Tw (total material twist, turns), Wr (writhe, turns, the Gauss
integral of the centreline polygon), Lk = Tw + Wr (must stay twist / 2 pi to round-off), how far the ring left
its plane, and the stability of the equilibrium.

Naturally straight ring: the planar ring with uniform twist is an equilibrium for every twist and stable up
to Michell's threshold twist = 2 pi sqrt(3) A1 / A2 (Michell 1889, Zajac 1962). ``--sweep K`` continues from
twist / K to twist in K steps, finds the step where the lowest stiffness eigenvalue changes sign and locates it
with ``der.continuation`` (``--locate``, default: pseudo-arclength from the last stable step, the change of
stability found by a secant on the lowest eigenvalue to 1e-9; ``--no-locate`` interpolates). With ``--perturb EPS`` every step starts from the previous state bent out
of plane by EPS a0 (until the first contact, with ``--radius``), so that past the threshold the ring writhes (Tw turns into Wr at constant Lk).

Naturally curved ring: twisting the cross-section away from the ring's normal costs bending energy (the
paper's term -2 A1 kappa kappa0 cos(alpha), Eq. 17), so the weld's twist stays near the weld instead of
spreading, the ring leaves the plane at once, and the sweep finds where that branch stops being stable.

    python scenarios/twisted_ring.py [--A1 1] [--A2 1.4925] [--a0 1] [--kappa0 1/a0] [--twist RAD]
                                     [--sweep K] [--perturb EPS] [--no-locate] [--png PATH]
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
    ("a0", 1.0, float, "radius of the ring (L = 2 pi a0)", POSITIVE),
    ("kappa0", None, float, "natural curvature: 0 (naturally straight) or 1/a0 (naturally circular; default: 1/a0)",
     Range(0.0, lambda p: 100.0 / p.a0, why="0 (naturally straight) up to 100/a0")),
    ("twist", None, float, "imposed twist in radians, the weld rotation (extra linking number x 2 pi); default: "
     "1.5 x Michell's threshold for kappa0 = 0, 1.5 pi (Lk = 3/4) otherwise",
     Range(-20 * np.pi, 20 * np.pi, why="an extra linking number of at most 10 turns")),
    ("sweep", 0, int, "number of continuation steps K, at twist/K, 2 twist/K, ..., twist (0: a single solve)",
     Range(0, 10000)),
    ("perturb", 0.0, float, "out-of-plane perturbation (fraction of a0) applied at the start of every step "
     "until the first contact",
     Range(0.0, 0.5, open_hi=True)),
    ("radius", None, float, "rod radius r for self-contact (issue 14): strands stay 2r apart and never pass through "
     "each other (default: no contact)", Range(0.0, lambda p: 0.5 * p.a0, open_lo=True, why="0 < r < a0/2")),
    ("locate", True, bool, "locate the stability threshold found by the sweep with der.continuation "
     "(--no-locate: interpolate it)"),
    ("png", None, str, "write a picture of the final ring (with --sweep: four states along it) to this PNG"),
]

LOCATE_TOL = 1e-9      # relative width of the final bracket of der.continuation's secant


def make_rod(p):
    """The ring rod of the parameters, without the weld (``with_imposed_twist`` adds it)."""
    rod = der.rod_from_shape(der.shapes.ring(p.a0, p.n), p.A1, p.A2)
    kappa0 = 1.0 / p.a0 if p.kappa0 is None else p.kappa0
    # the rest polygon's integrated curvature, rescaled: natural curvature kappa0 on the same Frenet frame
    return rod.with_natural(kappa_bar=rod.kappa_bar * (kappa0 * p.a0)), kappa0


def start_state(rod, state, twist_from, twist_to, eps, a0):
    """``state`` (welded with ``twist_from``) with the extra twist spread uniformly over the edge angles and
    bent out of plane by eps a0 (cos 2 phi + sin 3 phi) / 2."""
    n = rod.n_edges
    dtheta = (twist_to - twist_from) * np.arange(n) / n
    dx = None
    if eps:
        x0 = rod.rest_q.reshape(-1, 4)[:, :3]
        phi = np.arctan2(x0[:, 1], x0[:, 0])
        dx = np.zeros_like(x0)
        dx[:, 2] = eps * a0 * 0.5 * (np.cos(2 * phi) + np.sin(3 * phi))
    return rod.displaced(state, dx, dtheta)


def contacts(p):
    """The contact terms of the scene: self-contact of radius --radius, or none."""
    return [der.self_contact(p.radius)] if p.radius else []


def observe(rod, result, twist, p):
    st = result.state
    lk, tw, wr = dg.linking_number(rod, st)
    x = st.positions
    c = x - x.mean(axis=0)
    normal = np.linalg.svd(c, full_matrices=False)[2][-1]
    strain = dg.material_twist_density(rod, st) - rod.twist_bar / rod.voronoi
    return {
        "twist": twist, "converged": result.converged, "status": result.status,
        "twist_total": tw, "writhe": wr, "linking_number": lk, "lk_error": abs(lk - twist / (2 * np.pi)),
        "out_of_plane": float(np.abs(c @ normal).max() / p.a0),
        "twist_strain_spread": float((strain.max() - strain.min()) * p.a0),
        "energy": float(sum(result.energy.values())) if result.energy else None,
        "min_eigenvalue": result.min_eigenvalue, "stable": result.stable,
        "min_distance": _min_distance(result), "contacts": _n_contacts(result),
    }


def _min_distance(result):
    c = getattr(result, "contact", None)
    return None if not c else c.get("min_distance")


def _n_contacts(result):
    c = getattr(result, "contact", None)
    return 0 if not c else int(sum(t.get("n_contacts", 0) for t in c.get("terms", [])))


def default_twist(p):
    kappa0 = 1.0 / p.a0 if p.kappa0 is None else p.kappa0
    return 1.5 * cf.michell_twist(p.A1, p.A2) if kappa0 == 0.0 else 1.5 * np.pi


def run(p, solver):
    base, kappa0 = make_rod(p)
    if p.twist is None:
        p.twist = default_twist(p)
    steps = np.linspace(p.twist / p.sweep, p.twist, p.sweep) if p.sweep else np.array([p.twist])
    state, welded = base.rest_state(), 0.0
    sweep, states = [], []
    eps = p.perturb
    for twist in steps:
        rod = base.with_imposed_twist(twist)
        scene = der.Scene(rod, contacts=contacts(p))
        result = solver.solve(scene, state=start_state(rod, state, welded, twist, eps, p.a0))
        if _n_contacts(result):
            # in contact the strands sit a barrier gap (< dhat) apart: a kick of eps a0 could push them through
            # each other before the solve starts (as in scenarios/plectoneme.py: the imperfection before contact)
            eps = 0.0
        sweep.append(observe(rod, result, float(twist), p))
        states.append(result.state)
        if not result.converged:
            break
        state, welded = result.state, float(twist)
    last = sweep[-1]
    out = {k: last[k] for k in ("twist_total", "writhe", "linking_number", "lk_error", "out_of_plane",
                                "twist_strain_spread", "min_eigenvalue", "stable", "energy", "min_distance",
                                "contacts")}
    out["radius"] = p.radius
    out["kappa0"] = kappa0
    out["lk_error_max"] = max(s["lk_error"] for s in sweep)
    michell = cf.michell_twist(p.A1, p.A2)
    out["michell_twist"] = michell
    out.update(_threshold(p, solver, base, sweep, states))
    # without --radius there is no self-contact: a writhing ring can pass through itself, which changes Lk by 2
    passages = [s for s in sweep if s["lk_error"] > 0.5]
    out["strand_passage_at"] = passages[0]["twist"] if passages else None
    if passages:
        jump = passages[0]["linking_number"] - passages[0]["twist"] / (2 * np.pi)
        out["note"] = (f"the ring passed through itself at twist {passages[0]['twist']:.6g} (Lk changed by "
                       f"{jump:+.3g}): without --radius there is no self-contact, so states beyond that are not those of a "
                       "real rod")
        # the run contradicts its own check (Lk conserved): exit 3 with this reason (der.cli)
        out["check_failed"] = out["note"]
    if passages:
        out["error"] = out["lk_error_max"]
        out["reference"] = "conservation of the linking number, Lk = twist / 2 pi (absolute error, turns)"
    elif kappa0 == 0.0 and out["threshold_twist"] is not None:
        out["error"] = abs(out["threshold_twist"] - michell) / michell
        out["reference"] = "Michell's threshold twist 2 pi sqrt(3) A1/A2 (relative error of the located one)"
    elif kappa0 == 0.0 and last["out_of_plane"] < 1e-8:
        # planar branch: the twist is uniform, Tw = twist / 2 pi, Wr = 0
        out["error"] = abs(last["twist_total"] - p.twist / (2 * np.pi)) / abs(p.twist / (2 * np.pi))
        out["reference"] = "planar ring with uniform twist: Tw = twist / 2 pi (relative error)"
    else:
        out["error"] = out["lk_error_max"]
        out["reference"] = "conservation of the linking number, Lk = twist / 2 pi (absolute error, turns)"
    if p.sweep:
        out["sweep"] = sweep
        out["converged"] = all(s["converged"] for s in sweep)
    if p.png:
        picks = [k for k, s in enumerate(sweep) if s["converged"] and s["lk_error"] < 0.5]
        picks = [picks[i] for i in sorted({round(x) for x in np.linspace(0, len(picks) - 1, 4)})] if picks else []
        _picture(base, [(sweep[k], states[k]) for k in picks or [len(sweep) - 1]], kappa0, p)
    return out


def _picture(base, items, kappa0, p):
    """Rings drawn in 3-D, each coloured by its twist strain, titled with Lk, Tw and Wr."""
    from der.plotting import pyplot

    plt = pyplot("twisted_ring.py")
    if plt is None:
        return
    fig = plt.figure(figsize=(3.0 * len(items) + 0.8, 3.6))
    elev, azim = 25, -60
    scale = max(float(np.abs(dg.material_twist_density(base.with_imposed_twist(o["twist"]), st)).max())
                for o, st in items) * p.a0
    for i, (obs, state) in enumerate(items):
        rod = base.with_imposed_twist(obs["twist"])
        x = state.positions - state.positions.mean(axis=0)   # centred: the free ring drifts as it writhes
        x = np.vstack([x, x[:1]])
        strain = dg.material_twist_density(rod, state) * p.a0   # twist per length, in 1/a0 (natural twist 0)
        ax = fig.add_subplot(1, len(items), i + 1, projection="3d")
        c = plt.cm.coolwarm(0.5 + 0.5 * np.clip(strain / max(scale, 1e-12), -1, 1))
        for j in range(rod.n_edges):
            ax.plot(x[j:j + 2, 0], x[j:j + 2, 1], x[j:j + 2, 2], color=c[j], lw=2.5)
        lim = max(1.0 * p.a0, float(np.abs(x).max()))
        ax.set(xlim=(-lim, lim), ylim=(-lim, lim), zlim=(-lim, lim))
        ax.set_box_aspect((1, 1, 1), zoom=1.3)
        ax.set_axis_off()
        ax.view_init(elev=elev, azim=azim)
        ax.set_title(f"Lk = {obs['linking_number']:.3f}\nTw = {obs['twist_total']:.3f}, "
                     f"Wr = {obs['writhe']:.3f}", fontsize=9)
    fig.suptitle(f"twisted ring, kappa0 a0 = {kappa0 * p.a0:g}, A1/A2 = {p.A1 / p.A2:.3g}, n = {p.n}; each ring centred, "
                 f"seen from elevation {elev} deg, azimuth {azim} deg (z up, same scale)", fontsize=9)
    fig.subplots_adjust(left=0, right=1 - 0.8 / (3.0 * len(items) + 0.8), bottom=0.02, top=0.80, wspace=0)
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    cax = fig.add_axes([1 - 0.65 / (3.0 * len(items) + 0.8), 0.12, 0.012 * 12 / (3.0 * len(items) + 0.8), 0.6])
    bar = fig.colorbar(ScalarMappable(Normalize(-scale, scale), plt.cm.coolwarm), cax=cax)
    bar.set_label("material twist x a0", fontsize=8)
    bar.ax.tick_params(labelsize=7)
    fig.savefig(p.png, dpi=110)


def _threshold(p, solver, base, sweep, states):
    """The first loss of stability along the sweep: interpolated, then (``--locate``) located by
    ``der.continuation`` from the last stable step (secant on the lowest eigenvalue, or on dp/ds at a fold)."""
    out = {"threshold_twist": None, "threshold_located_by": None}
    for k, s in enumerate(sweep):
        if s["stable"] is not False:
            continue
        if k == 0 or sweep[k - 1]["min_eigenvalue"] is None:
            out["threshold_twist"] = s["twist"] if k == 0 else None
            out["threshold_located_by"] = "first sweep step already unstable" if k == 0 else None
            return out
        a, b = sweep[k - 1]["min_eigenvalue"], s["min_eigenvalue"]
        lo, hi = sweep[k - 1]["twist"], s["twist"]
        out["threshold_twist"] = lo + (hi - lo) * a / (a - b)
        out["threshold_located_by"] = "linear interpolation of the lowest eigenvalue between two sweep steps"
        if p.locate:
            found = _locate(p, base, states[k - 1], lo, hi)
            if found is not None:
                out["threshold_twist"] = found["twist"]
                out["threshold_kind"] = found["kind"]
                out["threshold_located_to"] = found["located_to"]
                out["threshold_located_by"] = (f"der.continuation from the last stable step: {found['located_by']} "
                                               f"(to {LOCATE_TOL:g} relative)")
        return out
    return out


def _locate(p, base, state, lo, hi):
    """The first special point of the branch through ``state`` (twist ``lo``, stable) towards ``hi``, found by
    der.continuation (pseudo-arclength in the twist, stability at every point); None if it finds none."""
    def scene_of(twist):
        return der.Scene(base.with_imposed_twist(twist), contacts=contacts(p))

    try:
        branch = der.continuation(scene_of, lo, hi, state=state, parameter="twist", ds=0.5, ds_max=0.5,
                                  locate_tol=LOCATE_TOL, max_steps=50, stop=lambda r: not r["stable"],
                                  progress=False, keep_states=False)
    except ValueError as exc:        # e.g. contact active: the continuation refuses it (the interpolation stays)
        print(f"twisted_ring.py: threshold not located by der.continuation: {exc}", file=sys.stderr)
        return None
    return branch.special[0] if branch.special else None


def validate(p):
    if p.twist is not None and p.twist == 0 and p.sweep:
        raise ValueError("--twist must be non-zero for a sweep (it is the end point)")
    if p.locate not in (0, 1, True, False):
        raise ValueError(f"--locate must be on or off; got {p.locate}")
    if p.png:
        from der.plotting import require_matplotlib
        require_matplotlib("--png")


def resolve(p):
    """Record the defaults that depend on other parameters as the values used."""
    if p.kappa0 is None:
        p.kappa0 = 1.0 / p.a0
    if p.twist is None:
        p.twist = float(default_twist(p))


run.validate = validator(PARAMETERS, validate)
run.resolve = resolve

if __name__ == "__main__":
    sys.exit(scenario_main("twisted_ring", __doc__.splitlines()[0], PARAMETERS, run, n_default=200, n_min=6))
