"""Plectoneme: a rod under constant tension turned at one end (magnetic tweezers), with self-contact.

A straight rod of length L and radius r along z, its bottom end clamped, its top end clamped in rotation but
free to slide along z under a constant axial force F (pulling), is turned by N turns about z in a continuation
from 0 to --turns in --sweep steps, each solve starting from the last state. Without contact the rod would
pass through itself once it buckles; with ``der.self_contact(r)`` it forms a plectoneme (two interwound
strands in contact) and Lk = N at every step.

Reported per step: ``turns`` N, ``extension`` (height of the top end cross-section above the bottom one),
``torque`` (A2 times the mean twist density: the axial moment the clamps transmit), ``twist`` Tw and
``writhe`` Wr (turns; Lk = Tw + Wr), ``linking_number``, ``min_distance`` (smallest centreline distance of
non-neighbour edges) and ``contacts`` (pairs within the barrier range). Writhe of the open rod: its
centreline is closed by the standard "extended" closure of magnetic-tweezers models -- straight segments from
both ends far along the axis (+-1e4 L), joined by a far rectangle -- and the Gauss integral of the closed
polygon (der.diagnostics, exact per segment pair) is taken; with end tangents along the axis the closure
adds no writhe of its own in the limit (checked: a straight twisted rod gives Wr = 0, Lk = Tw = N).

Zero-temperature theory (docs/derivations.md, "Plectoneme"): the straight rod buckles at the torque of the
clamped finite rod under tension (2 sqrt(A1 F) for a long rod, with its finite-length root), i.e. at
N_b = M_b L / (2 pi A2); the plectonemic phase of two strands of superhelical radius r with pitch angle theta
has the torque plateau M_p and extension slope dz/dN = -4 pi r / sin(2 theta) from
min_theta [A1 sin^4(theta) / (2 r^2) + F - M sin(2 theta) / (2 r)] = 0.

    python scenarios/plectoneme.py [--A1 1] [--A2 1.4925] [--L 20] [--radius 0.05] [--force 1]
                                   [--turns 6] [--sweep 48] [--n 400] [--samples m] [--predictor last]
                                   [--png PATH] [--json]
"""
import sys

import numpy as np
from scipy.optimize import brentq, minimize_scalar

import der
from der import diagnostics as dg
from der.cli import check_contact_resolution, scenario_main

PARAMETERS = [
    ("A1", 1.0, float, "bending stiffness"),
    ("A2", 1.0 / 0.67, float, "twisting stiffness (A1/A2 = 0.67, DNA)"),
    ("L", 20.0, float, "rod length"),
    ("EA", 1e5, float, "axial stiffness (the strain F/EA is kept small; the inextensible limit resists the "
     "lateral imperfection's tiny elongation, a known slow case of its multiplier update)"),
    ("radius", 0.05, float, "rod radius r (contact at centreline distance 2r)"),
    ("force", 1.0, float, "constant axial pulling force F on the sliding top end"),
    ("turns", 6.0, float, "number of turns N at the end of the continuation"),
    ("sweep", 48, int, "continuation steps from 0 to --turns (at most 1/4 turn each)"),
    ("perturb", 1e-3, float, "lateral imperfection (fraction of L) added to the start of every step before contact "
     "(not on the clamped nodes), and the kick along the unstable mode of an unstable equilibrium a step returns "
     "(der.continuation's leave_unstable)"),
    ("samples", None, int, "contact barrier on m sample points per edge (der.self_contact(r, samples=m): smooth, "
     "exact Newton; docs/contact.md section 9) instead of segment distances"),
    ("predictor", "last", str, "each step's start: 'last' (the last point), 'secant' or 'tangent' (along dq/dN "
     "from the last point's exact Hessian; with --samples and steps of 1/8 turn, docs/contact.md section 9.3)"),
    ("png", None, str, "write extension and torque against N to this PNG"),
]

CLOSURE = 1e4      # the closure segments' length, in units of L
MAX_ITERATIONS = 5000   # per step: the snap from the straight rod into a plectoneme is a long transient


# ---- zero-temperature theory (docs/derivations.md) -------------------------------------------------------

def buckling_torque(A1, F, L):
    """Torque at which the straight clamped rod of length L under tension F buckles: the first root above
    M_c = 2 sqrt(A1 F) of 2 sin(phi1) sin(phi2) = L k1 k2 sin(phi1 - phi2) / (k1 - k2), k1,2 the roots of
    A1 k^2 - M k + F = 0 and phi = k L / 2 (docs/derivations.md)."""
    Mc = 2.0 * np.sqrt(A1 * F)

    def h(M):
        q = np.sqrt(max(M * M - 4.0 * A1 * F, 0.0))
        k1, k2 = (M + q) / (2 * A1), (M - q) / (2 * A1)
        d = q / A1
        return 2.0 * np.sin(k1 * L / 2) * np.sin(k2 * L / 2) - L * (F / A1) * (L / 2) * np.sinc(d * L / (2 * np.pi))

    grid = np.linspace(Mc, Mc + 60.0 * A1 / L, 60001)[1:]
    # h on the whole grid at once (the same arithmetic as h; a Python loop over it cost ~1 s of CPU per run)
    q = np.sqrt(np.maximum(grid * grid - 4.0 * A1 * F, 0.0))
    k1, k2 = (grid + q) / (2 * A1), (grid - q) / (2 * A1)
    vals = 2.0 * np.sin(k1 * L / 2) * np.sin(k2 * L / 2) - L * (F / A1) * (L / 2) * np.sinc(q / A1 * L / (2 * np.pi))
    i = np.flatnonzero(np.sign(vals[1:]) != np.sign(vals[:-1]))
    return brentq(h, grid[i[0]], grid[i[0] + 1]) if i.size else np.nan


def plectoneme_theory(A1, F, r):
    """(torque plateau M_p, pitch angle theta, extension per turn -4 pi r / sin 2 theta) of two interwound
    strands in contact (superhelical radius r): M_p is the smallest torque at which
    g(theta) = A1 sin^4(theta) / (2 r^2) + F - M sin(2 theta) / (2 r) reaches 0."""
    def gmin(M):
        res = minimize_scalar(lambda t: A1 * np.sin(t) ** 4 / (2 * r * r) + F - M * np.sin(2 * t) / (2 * r),
                              bounds=(1e-6, np.pi / 4), method="bounded", options={"xatol": 1e-12})
        return res.fun, res.x
    Mp = brentq(lambda M: gmin(M)[0], 1e-9, 4.0 * np.sqrt(A1 * F) + 10 * A1 / r, xtol=1e-14)
    theta = gmin(Mp)[1]
    return Mp, theta, -4.0 * np.pi * r / np.sin(2.0 * theta)


# ---- the rod and its observables ---------------------------------------------------------------------------

def rotation_z(phi):
    c, s = np.cos(phi), np.sin(phi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def closed_writhe(x, L):
    """Writhe (turns) of the open centreline x (n_nodes, 3) closed by straight segments along -z from its bottom
    and +z from its top, CLOSURE L long, joined by a far rectangle."""
    far = CLOSURE * L
    b, t = x[0], x[-1]
    closure = np.array([[t[0], t[1], t[2] + far], [t[0] + far, t[1], t[2] + far],
                        [b[0] + far, b[1], b[2] - far], [b[0], b[1], b[2] - far]])
    return float(dg._writhe(np.ascontiguousarray(np.vstack([x, closure]))))


def bottom_tilt(x):
    """Angle (rad) between the bottom clamp's end edge x[1] - x[0] and the z axis."""
    e = x[1] - x[0]
    return float(np.arctan2(np.hypot(e[0], e[1]), e[2]))


def run(p, solver):
    """The continuation in N (der.continuation, natural parameter, fixed steps of --turns / --sweep, each solve
    warm-started from the last state, the lateral imperfection added to each start until the first contact, on the
    free nodes only, and a step that converged to an unstable equilibrium kicked along its lowest mode and solved
    again: der.continuation's leave_unstable)."""
    rod = der.rod_from_shape(der.shapes.straight(p.L, p.n), p.A1, p.A2, EA=p.EA)
    contact = der.self_contact(p.radius, samples=p.samples)
    xi = rod.rest_q.reshape(-1, 4)[:, 2] / p.L
    bump = np.zeros((rod.n_nodes, 3))
    bump[:, 0] = p.perturb * p.L * np.sin(np.pi * np.clip(xi, 0, 1))
    # not on the nodes the clamps hold (each clamp holds its end edge where the start state has it, so a
    # nudged node 1 would tilt the bottom clamp, by a little more at every nudged step)
    bump[:2] = 0.0
    bump[-2:] = 0.0

    def scene_of(N):
        return der.Scene(rod, loads=[der.end_force([0.0, 0.0, p.force])],
                         constraints=[der.clamp("start"), der.clamp("end", rotation=rotation_z(2 * np.pi * N), slide=2)],
                         contacts=[contact])

    seen = {}

    def contact_of(scene, state):
        key = state.q.tobytes()
        if key not in seen:
            seen.clear()
            seen[key] = der.diagnostics.contact_forces(scene, state)
        return seen[key]

    last = {"contacts": 0}

    def contacts(scene, state):
        last["contacts"] = contact_of(scene, state)["n_contacts"]
        return last["contacts"]

    def perturb(N, state):
        return rod.displaced(state, bump) if p.perturb and not last["contacts"] else None

    def extension(scene, st):
        x = st.positions
        return float(0.5 * (x[-2, 2] + x[-1, 2]) - 0.5 * (x[0, 2] + x[1, 2]))

    summaries = {
        "extension": extension,
        "torque": lambda scene, st: float(p.A2 * dg.material_twist_density(rod, st).mean()),
        "twist": lambda scene, st: dg.total_twist(rod, st) / (2 * np.pi),
        "writhe": lambda scene, st: closed_writhe(st.positions, p.L),
        "min_distance": lambda scene, st: contact_of(scene, st)["min_distance"],
        # the bottom clamp's end edge against the z axis (rad): 0 to round-off, the clamp is not tilted
        "clamp_tilt": lambda scene, st: bottom_tilt(st.positions),
        "contacts": contacts,
    }
    branch = der.continuation(scene_of, 0.0, p.turns, parameter="turns", method="natural", dp=p.turns / p.sweep,
                              predictor=getattr(p, "predictor", "last"), perturb=perturb, stability=False,
                              leave_unstable=p.perturb or None,
                              tol=solver.args.tol,
                              options=der.SolverOptions(max_iterations=MAX_ITERATIONS), summaries=summaries,
                              max_steps=8 * p.sweep, progress=False, keep_states=False, solve=solver.solve)
    steps = []
    for pt in branch.points[1:]:
        row = {k: pt[k] for k in ("turns", "extension", "torque", "twist", "writhe", "min_distance", "clamp_tilt")}
        row["linking_number"] = row["twist"] + row["writhe"]
        row.update(contacts=int(pt["contacts"]), converged=True, iterations=pt["newton_iterations"],
                   runtime_s=pt["step_time"])
        steps.append(row)
    out = summarise(p, steps)
    # every point is a converged solve; a step the continuation could not make (halved down to its smallest
    # step) ends it short of --turns with its message
    out["converged"] = branch.status == "completed" and bool(steps)
    out["continuation"] = {"status": branch.status, "message": branch.message, "points": len(steps),
                           "wall_s": branch.wall_time}
    return out


def summarise(p, steps):
    N = np.array([s["turns"] for s in steps])
    ext = np.array([s["extension"] for s in steps])
    torque = np.array([s["torque"] for s in steps])
    out = {k: [s[k] for s in steps] for k in ("turns", "extension", "torque", "twist", "writhe", "linking_number",
                                              "min_distance", "contacts")}
    out["converged"] = all(s["converged"] for s in steps) and len(steps) == p.sweep
    out["lk_error_max"] = float(np.max(np.abs(np.array(out["linking_number"]) - N)))
    if all("clamp_tilt" in s for s in steps):
        out["clamp_tilt_max"] = float(max(s["clamp_tilt"] for s in steps))
    # measured: buckling = the first step with a self-contact or with the torque below the last one
    buckled = [k for k in range(len(steps)) if steps[k]["contacts"] > 0 or (k and torque[k] < torque[k - 1] - 1e-9)]
    kb = buckled[0] if buckled else None
    out["buckling_turns"] = float(N[kb - 1]) if kb else None       # the last straight step
    plateau = [k for k in range(len(steps)) if kb is not None and k >= kb + 2 and steps[k]["contacts"] > 0]
    if len(plateau) >= 3:
        tail = plateau[len(plateau) // 3:]
        out["torque_plateau"] = float(np.mean(torque[tail]))
        out["extension_slope"] = float(np.polyfit(N[tail], ext[tail], 1)[0])
    else:
        out["torque_plateau"] = out["extension_slope"] = None
    Mb = buckling_torque(p.A1, p.force, p.L)
    Mp, theta, slope = plectoneme_theory(p.A1, p.force, p.radius)
    out["theory"] = {
        "buckling_torque_long_rod": 2 * np.sqrt(p.A1 * p.force),
        "buckling_torque": Mb, "buckling_turns": Mb * p.L / (2 * np.pi * p.A2),
        "torque_plateau": Mp, "pitch_angle": theta, "extension_slope": slope,
        "pre_buckling_torque_slope": 2 * np.pi * p.A2 / p.L,
    }
    pre = [k for k in range(len(steps)) if kb is None or k < kb]
    err = {}
    if pre:
        err["pre_buckling_torque"] = float(np.max(np.abs(torque[pre] - 2 * np.pi * p.A2 * N[pre] / p.L))
                                           / (2 * np.pi * p.A2 * N[pre[-1]] / p.L))
    if out["buckling_turns"] is not None:
        # the buckling lies between the last straight step and the next one
        nb = out["theory"]["buckling_turns"]
        err["buckling_turns"] = (out["buckling_turns"] - nb) / nb
        err["buckling_step"] = float(N[1] - N[0]) / nb
    if out["torque_plateau"] is not None:
        err["torque_plateau"] = (out["torque_plateau"] - Mp) / Mp
        err["extension_slope"] = (out["extension_slope"] - slope) / slope
        # the barrier keeps the strands a gap in (0, dhat) apart: the same theory at the contact distance the
        # solve reached (superhelical radius r_eff = min_distance / 2) separates that from the model's error
        r_eff = 0.5 * float(np.mean([steps[k]["min_distance"] for k in tail]))
        Mp_e, theta_e, slope_e = plectoneme_theory(p.A1, p.force, r_eff)
        out["theory"].update({"contact_radius_reached": r_eff, "torque_plateau_at_r_eff": Mp_e,
                              "extension_slope_at_r_eff": slope_e})
        err["torque_plateau_at_r_eff"] = (out["torque_plateau"] - Mp_e) / Mp_e
        err["extension_slope_at_r_eff"] = (out["extension_slope"] - slope_e) / slope_e
    out["errors"] = err
    out["error"] = out["lk_error_max"]
    out["reference"] = "Lk = N at every step (absolute, turns); theory errors in 'errors' (relative)"
    out["sweep"] = steps
    if p.png:
        picture(p, out)
    return out


def picture(p, out):
    from der.plotting import pyplot

    plt = pyplot("plectoneme.py")
    if plt is None:
        return
    N = np.array(out["turns"])
    th = out["theory"]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.6))
    ax1.plot(N, out["extension"], "o-", ms=3, label="der")
    if out["torque_plateau"] is not None:
        nb = th["torque_plateau"] * p.L / (2 * np.pi * p.A2)
        ax1.plot([0, nb, N[-1]], [p.L, p.L, p.L + th["extension_slope"] * (N[-1] - nb)], "k--", lw=1,
                 label="interwound theory (global minimum, no end loop)")
        k = int(np.argmax(np.array(out["contacts"]) > 0))
        ax1.plot([N[k], N[-1]], [out["extension"][k], out["extension"][k] + th["extension_slope"] * (N[-1] - N[k])],
                 "k:", lw=1, label="theory slope -4 pi r / sin 2 theta")
    ax1.set(xlabel="turns N", ylabel="extension", ylim=(0, 1.05 * p.L))
    ax1.legend(fontsize=8)
    ax2.plot(N, out["torque"], "o-", ms=3, label="der")
    nb = th["buckling_turns"]
    ax2.plot([0, nb], [0, th["buckling_torque"]], "k:", lw=1, label="2 pi A2 N / L up to buckling (theory)")
    ax2.axvline(nb, color="0.6", lw=0.8)
    ax2.axhline(th["torque_plateau"], color="k", ls="--", lw=1, label="plateau (theory)")
    ax2.set(xlabel="turns N", ylabel="torque")
    ax2.legend(fontsize=8)
    fig.suptitle(f"plectoneme: A1={p.A1:g}, A2={p.A2:.4g}, L={p.L:g}, r={p.radius:g}, F={p.force:g}, n={p.n}",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(p.png, dpi=110)


def validate(p):
    for name in ("A1", "A2", "L", "EA", "radius", "force", "turns"):
        if not getattr(p, name) > 0:
            raise ValueError(f"--{name} must be > 0; got {getattr(p, name)}")
    if p.sweep < 1:
        raise ValueError(f"--sweep must be >= 1; got {p.sweep}")
    from der.continuation import PREDICTORS

    if getattr(p, "predictor", "last") not in PREDICTORS:
        raise ValueError(f"--predictor must be one of {PREDICTORS}; got {p.predictor!r}")
    if p.turns / p.sweep > 0.25:
        raise ValueError(f"--sweep {p.sweep} is too coarse for --turns {p.turns}: at most 1/4 turn per step "
                         f"(--sweep >= {int(np.ceil(4 * p.turns))})")
    check_contact_resolution(p)


run.validate = validate

if __name__ == "__main__":
    sys.exit(scenario_main("plectoneme", __doc__.splitlines()[0], PARAMETERS, run, n_default=400, n_min=10, tol_default=1e-4))
