"""Elongation and winding of a helix (paper Section 6.3.2, Eqs. 72-81, Figs. 1-2), with the corrected Eq. 78.

A helix of ``turns`` turns (kappa0 = 1, omega0 = lam, A2 = 1, A1 = A, the paper's A = A1/A2) deformed into a uniform helix of axial
elongation eta and overtwist phi. Two controls:

* displacement (``--eta --phi``): both ends clamped on the deformed uniform helix (positions and frames); the
  axial force P and axial torque T are measured in the middle of the rod;
* force (``--P0 --phi``): the axial force through the helix axis is prescribed with the winding held; eta is
  found by der.continuation in eta (displacement control) up to where the measured force reaches P0, located
  by its secant (a load-controlled test machine).

Correct closed form (docs/derivations.md, "Helix winding"): a force along the axis has a binormal component,
so F_t = P S1 (not P / S1 as in Eq. 78, S1 = t.e3), and P0 = P/(A2 omega0^2) = c sqrt(1+lam^2)/lam
[c eta - 1 - A eta (c - 1/r)], c = 1 + phi, r = sqrt(1 + lam^2 (1 - eta^2)); the paper's Eq. 81 is S1^2 times it.
``--figure 1`` / ``--figure 2`` regenerate the paper's Figures 1 and 2 (paper, corrected and simulated).

    python scenarios/helix_winding.py [--A1 0.67] [--lam 0.6] [--turns 3] [--eta 1.2] [--phi 0.1] [--P0 X]
                                      [--figure 1|2] [--png PATH]
"""
import sys

import numpy as np
from scipy.optimize import brentq

import der
from der import closed_forms as cf
from der import diagnostics as dg
from der.cli import Range, scenario_main, validator
from der.geometry import material_frames, reference_twists, tangents
from der.rod import RodState, frenet_frame_of_shape

PARAMETERS = [
    ("A1", 0.67, float, "bending stiffness A1 in units of A2 = 1, i.e. the paper's A = A1/A2 (--A: deprecated)",
     Range(1e-3, 1e3)),
    ("lam", 0.6, float, "omega0/kappa0 (kappa0 = 1)", Range(1e-2, 1e2)),
    ("turns", 1.0, float, "number of turns of the rest helix", Range(0.0, 100.0, open_lo=True)),
    ("eta", 1.2, float, "axial elongation (displacement control)"),
    ("phi", 0.1, float, "overtwist (winding held)",
     Range(-1.0, 1.0, open_lo=True, why="the winding ratio 1 + phi in (0, 2]; the paper's Figure 2 spans +-0.5")),
    ("P0", None, float, "axial force P/(A2 omega0^2): force control instead of --eta",
     Range(-100.0, 100.0, why="the paper's Figure 2 spans 0.1 to 10")),
    ("figure", 0, int, "1 or 2: regenerate the paper's Figure 1 or 2 instead of one point", Range(0, 2)),
    ("png", None, str, "with --figure: write the figure to this PNG (needs matplotlib)"),
]


def rest_rod(p):
    return der.rod_from_shape(der.shapes.helix(1.0, p.lam, p.turns, p.n), p.A1, 1.0, EA=getattr(p, "EA", None))


def deformed_state(rod, eta, phi, lam):
    """The discrete uniform helix at (eta, phi) with the rod's edge lengths, material frame on its Frenet frame."""
    g = cf.winding_geometry(eta, phi, lam)
    a, S, S1 = float(g["a"]), float(g["S"]), float(g["S1"])
    chord = float(rod.l_bar.mean())

    def f(h):
        return (2 * a * np.sin(S * h / 2)) ** 2 + (S1 * h) ** 2 - chord ** 2

    h = brentq(f, 0.5 * chord, 2.0 * chord, xtol=1e-15, rtol=1e-15)
    s = (np.arange(rod.n_nodes) - 0.5) * h
    x = np.stack([a * np.cos(S * s), a * np.sin(S * s), S1 * s], axis=1)
    t, d1, _ = frenet_frame_of_shape(x, False)
    q = np.zeros(rod.n_dof)
    q.reshape(-1, 4)[:, :3] = x
    ref = reference_twists(t, np.ascontiguousarray(d1), rod.vertex_edges)   # one kernel pass (4 s at 10^6 as a loop)
    return RodState(q, d1, tangents(q, rod.edge_nodes), ref, np.zeros(rod.n_edges))


def measure(rod, state, lam):
    """Axial force and torque (P0, T0) in the middle third, and the uniformity of kappa and omega there."""
    F = dg.internal_forces(rod, state)
    M = dg.internal_moments(rod, state)
    mid_e = slice(rod.n_edges // 3, 2 * rod.n_edges // 3)
    mid_v = slice(rod.n_vertices // 3, 2 * rod.n_vertices // 3)
    P = F[mid_e, 2].mean()
    T = M[mid_v, 2].mean()
    prof = dg.profile(rod, state)
    kap, om = prof["kappa"][mid_v], prof["omega"][mid_v]
    uniformity = max(np.ptp(kap) / abs(kap.mean()), np.ptp(om) / abs(om.mean()))
    horizontal = float(np.abs(F[mid_e, :2]).max() / max(abs(P), 1e-300))
    return {"P0": P / lam ** 2, "T0": T / lam, "kappa": float(kap.mean()), "omega": float(om.mean()),
            "uniformity": float(uniformity), "force_off_axis": horizontal,
            "alpha_max_abs": float(np.nanmax(np.abs(dg.alpha(rod, state))))}


def solve_at(p, solver, rod, eta, phi):
    scene = der.Scene(rod, constraints=[der.clamp("start"), der.clamp("end")])
    state = deformed_state(rod, eta, phi, p.lam)
    result = solver.solve(scene, state=state)
    return result, measure(rod, result.state, p.lam)


def end_clamps(rod, eta, phi, lam):
    """Both ends clamped where the discrete uniform helix at (eta, phi) has them: each end cross-section's centre
    and material frame (der.clamp's rotation is relative to the rest helix)."""
    rest, deformed = rod.rest_state(), deformed_state(rod, eta, phi, lam)
    clamps = []
    for end, j in (("start", 0), ("end", rod.n_edges - 1)):
        frames = []
        for st in (rest, deformed):
            m1, m2 = material_frames(st.q, st.tangents, st.d1)
            frames.append(np.stack([m1[j], m2[j], st.tangents[j]], axis=1))
        a, b = rod.edge_nodes[j]
        centre = 0.5 * (deformed.positions[a] + deformed.positions[b])
        clamps.append(der.clamp(end, rotation=frames[1] @ frames[0].T, position=centre))
    return clamps


def displacement_path(p, solver, rod, etas, phi):
    """The equilibria at the elongations ``etas`` (increasing), winding phi held: one der.continuation in eta
    (pseudo-arclength, warm-started, the clamps moving with eta) from each eta to the next; the first from the
    deformed uniform helix. Each landing point is handed to the scenario's solver (it converges at once, and the
    run's verdict and recording see it). Returns [(eta, measure(...), SolveResult)]."""
    def scene_of(eta):
        return der.Scene(rod, constraints=end_clamps(rod, eta, phi, p.lam))

    out = [(etas[0], solver.solve(scene_of(etas[0]), state=deformed_state(rod, etas[0], phi, p.lam)))]
    for a, b in zip(etas[:-1], etas[1:]):
        if not out[-1][1].converged:
            break
        branch = der.continuation(scene_of, a, b, state=out[-1][1].state, parameter="eta", ds=0.5, ds_max=1.0,
                                  stability=False, locate=False, max_steps=50, progress=False)
        if branch.points[-1]["eta"] != b:
            raise RuntimeError(f"helix_winding: the continuation in eta stopped at {branch.points[-1]['eta']:.6g} "
                               f"before {b:.6g}: {branch.message}")
        out.append((b, solver.solve(scene_of(b), state=branch.states[-1])))
    return [(e, measure(rod, res.state, p.lam), res) for e, res in out]


def force_control(p, solver, rod, P0, phi):
    """eta where the measured axial force equals P0 (the winding phi held): der.continuation in eta under
    displacement control, from the closed form's eta, until the summary P0 reaches the target (located by the
    continuation's secant to 1e-10 relative); the located state is handed to the scenario's solver (it converges
    at once, and the run's verdict and recording see it)."""
    guess = cf.winding_eta(P0, phi, p.lam, p.A1)
    e0 = guess if np.isfinite(guess) else 1.0
    em = float(cf.winding_eta_max(p.lam))

    def scene_of(eta):
        return der.Scene(rod, constraints=end_clamps(rod, eta, phi, p.lam))

    start = solver.solve(scene_of(e0), state=deformed_state(rod, e0, phi, p.lam))
    f0 = measure(rod, start.state, p.lam)["P0"]
    branch = der.continuation(scene_of, e0, state=start.state, parameter="eta", bounds=(1e-3 * em, 0.999 * em),
                              direction=1 if f0 < P0 else -1, ds=0.01, ds_max=0.1,
                              summaries={"P0": lambda scene, st: measure(rod, st, p.lam)["P0"]}, target=("P0", P0),
                              locate_tol=1e-10, stability=False, max_steps=100, progress=False)
    hits = [sp for sp in branch.special if sp["kind"] == "target"]
    if not hits:
        raise RuntimeError(f"helix_winding: P0 = {P0} not reached from eta = {e0:.6g} ({branch.status}: "
                           f"{branch.message})")
    eta = hits[0]["eta"]
    res = solver.solve(scene_of(eta), state=hits[0]["state"])
    return eta, res, measure(rod, res.state, p.lam)


def point(p, solver, rod):
    if p.P0 is None:
        res, m = solve_at(p, solver, rod, p.eta, p.phi)
        ref = np.array([cf.winding_P0(p.eta, p.phi, p.lam, p.A1), cf.winding_T0(p.eta, p.phi, p.lam, p.A1)])
        sim = np.array([m["P0"], m["T0"]])
        return {"control": "displacement", "eta": p.eta, "phi": p.phi, **m,
                "P0_reference": ref[0], "T0_reference": ref[1],
                "P0_paper": float(cf.paper_winding_P0(p.eta, p.phi, p.lam, p.A1)),
                "error": float(np.linalg.norm(sim - ref) / np.linalg.norm(ref)),
                "paper_error": float(abs(m["P0"] - cf.paper_winding_P0(p.eta, p.phi, p.lam, p.A1)) / abs(ref[0]))}
    eta, res, m = force_control(p, solver, rod, p.P0, p.phi)
    eta_ref = cf.winding_eta(p.P0, p.phi, p.lam, p.A1)
    eta_paper = cf.winding_eta(p.P0, p.phi, p.lam, p.A1, corrected=False)
    return {"control": "force", "eta": eta, "phi": p.phi, **m, "P0": p.P0, "eta_reference": eta_ref,
            "eta_paper": eta_paper, "error": abs(eta - eta_ref) / abs(eta_ref),
            "paper_error": abs(eta - eta_paper) / abs(eta_ref) if np.isfinite(eta_paper) else None}


def figure(p, solver, rod_for):
    """Tables of the paper's Figure 1 (P0 vs eta, phi = 0, lam = 0.5, 0.6, 0.7) or 2 (eta vs phi, lam = 0.6)."""
    A = 0.67
    curves, points = [], []
    if p.figure == 1:
        for lam in (0.5, 0.6, 0.7):
            em = float(cf.winding_eta_max(lam))
            eta = np.linspace(0.0, 0.995 * em, 300)
            curves.append({"lam": lam, "eta": eta, "P0_corrected": cf.winding_P0(eta, 0.0, lam, A),
                           "P0_paper": cf.paper_winding_P0(eta, 0.0, lam, A)})
            q = _with(p, lam=lam, A1=A)
            rod = rod_for(q)
            # the force-elongation curve followed by der.continuation in eta through the six points
            for e, m, _ in displacement_path(q, solver, rod, list(np.linspace(0.6, 0.9 * em, 6)), 0.0):
                ref = float(cf.winding_P0(e, 0.0, lam, A))
                points.append({"lam": lam, "eta": e, "P0_simulated": m["P0"], "P0_corrected": ref,
                               "P0_paper": float(cf.paper_winding_P0(e, 0.0, lam, A)),
                               "error": abs(m["P0"] - ref) / max(abs(ref), 1e-2)})
    else:
        lam = 0.6
        q = _with(p, lam=lam, A1=A)
        rod = rod_for(q)
        phis = np.linspace(-0.5, 0.5, 101)
        for P0 in (0.1, 1.0, 10.0):
            curves.append({"P0": P0, "phi": phis,
                           "eta_corrected": np.array([cf.winding_eta(P0, f, lam, A) for f in phis]),
                           "eta_paper": np.array([cf.winding_eta(P0, f, lam, A, corrected=False) for f in phis])})
            for f in np.linspace(-0.4, 0.4, 5):
                eta, _, m = force_control(q, solver, rod, P0, f)
                ref = cf.winding_eta(P0, f, lam, A)
                points.append({"P0": P0, "phi": f, "eta_simulated": eta, "eta_corrected": ref,
                               "eta_paper": cf.winding_eta(P0, f, lam, A, corrected=False),
                               "error": abs(eta - ref) / ref})
    if p.png:
        _plot(p.figure, curves, points, p.png)
    return {"figure": p.figure, "curves": curves, "points": points,
            "error": max(pt["error"] for pt in points)}


def _with(p, **kw):
    import copy
    q = copy.copy(p)
    for k, v in kw.items():
        setattr(q, k, v)
    return q


def _plot(fig_no, curves, points, path):
    from der.plotting import pyplot

    plt = pyplot("helix_winding.py")
    if plt is None:
        return
    fig, ax = plt.subplots(figsize=(9.5, 5))
    for i, c in enumerate(curves):
        col = f"C{i}"
        if fig_no == 1:
            label = rf"$\lambda={c['lam']}$"
            ax.plot(c["eta"], c["P0_corrected"], "-", color=col, label=f"corrected, {label}")
            ax.plot(c["eta"], c["P0_paper"], "--", color=col, label=f"paper Eq. 81, {label}")
            pts = [pt for pt in points if pt["lam"] == c["lam"]]
            ax.plot([pt["eta"] for pt in pts], [pt["P0_simulated"] for pt in pts], "o", color=col, mfc="none",
                    label=f"simulated, {label}")
        else:
            label = rf"$P_0={c['P0']:g}$"
            ax.plot(c["phi"], c["eta_corrected"], "-", color=col, label=f"corrected, {label}")
            ax.plot(c["phi"], c["eta_paper"], "--", color=col, label=f"paper Eq. 81, {label}")
            pts = [pt for pt in points if pt["P0"] == c["P0"]]
            ax.plot([pt["phi"] for pt in pts], [pt["eta_simulated"] for pt in pts], "o", color=col, mfc="none",
                    label=f"simulated, {label}")
    if fig_no == 1:
        ax.set(xlabel=r"axial elongation $\eta$", ylabel=r"$P_0 = P/(A_2\omega_0^2)$", ylim=(-2.5, 10),
               title=r"Figure 1: $A = 0.67$, $\varphi = 0$")
        ax.axhline(0, color="k", lw=0.5)
    else:
        ax.set(xlabel=r"overtwist $\varphi$", ylabel=r"axial elongation $\eta$",
               title=r"Figure 2: $A = 0.67$, $\lambda = 0.6$")
    # outside the axes: inside, it covered the P0 = 0.1 curves and the phi = 0.2 point of Figure 2
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def run(p, solver):
    if p.figure:
        out = figure(p, solver, rest_rod)
        out["reference"] = "corrected Eq. 81 (docs/derivations.md, Helix winding); worst simulated point"
        return out
    out = point(p, solver, rest_rod(p))
    out["reference"] = ("corrected Eq. 81 and axial torque (docs/derivations.md, Helix winding)"
                        if p.P0 is None else "eta from the corrected Eq. 81 (docs/derivations.md, Helix winding)")
    return out


def validate(p):
    em = float(cf.winding_eta_max(p.lam))
    if p.P0 is None and not 0 < p.eta < em:
        raise ValueError(f"--eta must be in (0, eta_max = sqrt(1 + 1/lam^2) = {em:.6g}); got {p.eta}")
    if p.figure not in (0, 1, 2):
        raise ValueError(f"--figure must be 1 or 2; got {p.figure}")
    if p.png and not p.figure:
        raise ValueError("--png needs --figure 1 or 2")
    if p.png:
        from der.plotting import require_matplotlib
        require_matplotlib("--png")
    if p.n < 12 * p.turns:
        raise ValueError(f"--n must be >= 12 per turn ({int(12 * p.turns)} for {p.turns} turns); got {p.n}")


run.validate = validator(PARAMETERS, validate)

if __name__ == "__main__":
    sys.exit(scenario_main("helix_winding", __doc__.splitlines()[0], PARAMETERS, run, n_default=200,
                           aliases={"--A": "--A1"}))
