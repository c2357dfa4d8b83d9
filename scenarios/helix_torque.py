"""Helix under tension and torque (paper Section 6.3.1), with P and T independent.

One full turn of a helix (kappa0, omega0), clamped at xi = 0; at xi = l a dead force along the helix axis,
F_end = (P sqrt(kappa0^2 + omega0^2) / omega0) e3, whose tangential component is P (Eq. 52), and a follower
torque T about the end tangent.

Correct closed form (docs/derivations.md, "Helix under tension and torque"): the problem is statically
determinate, M(xi) = T t(l) + (R(l) - R(xi)) x F_end, so with D = P/omega0 - T and phi = lam xi,
Mn = (kappa0/lam) D sin(phi), Mb = -(kappa0 omega0/lam^2) D (1 - cos phi), Mt = T + (kappa0^2/lam^2) D (1 - cos phi),
F = (P, 0, P kappa0/omega0) in (t, n, b), dalpha = Mn/(A1 kappa0), dkappa = Mb/A1, domega = Mt/A2 - D cos(phi)/A1.
The paper's ansatz omega = omega0 (Eq. 53) contradicts its Eq. 55 and forces P = T omega0 (1 + A1/A2) (Eq. 71);
its profiles (Eqs. 66-70) are reported beside. The headline error is the worst relative error over the profiles
Mn, Mb, Mt, Ft, Fb, dalpha, dkappa, domega.

    python scenarios/helix_torque.py [--A1 1] [--A2 1.4925] [--kappa0 1] [--omega0 0.6] [--P 1e-5] [--T 2e-5]
"""
import sys

import numpy as np

import der
from der import closed_forms as cf
from der import diagnostics as dg
from der.cli import POSITIVE, Range, scenario_main, validator

PARAMETERS = [
    ("A1", 1.0, float, "bending stiffness", POSITIVE),
    ("A2", 1.0 / 0.67, float, "twisting stiffness", POSITIVE),
    ("kappa0", 1.0, float, "natural curvature", POSITIVE),
    ("omega0", 0.6, float, "natural torsion (> 0 right-handed, < 0 left-handed)",
     Range(lambda p: -100 * p.kappa0, lambda p: 100 * p.kappa0, nonzero=True,
           why="|omega0| up to 100 kappa0, and not 0: a planar ring has no axis to pull along")),
    ("P", 1e-5, float, "tangential end force F_t(l) (small: the closed form is linear)",
     Range(lambda p: -p.A1 * p.kappa0 ** 2, lambda p: p.A1 * p.kappa0 ** 2,
           why="|P| <= A1 kappa0^2: the closed form is linear in the loads")),
    ("T", 2e-5, float, "follower end torque about the end tangent (positive over-twists)",
     Range(lambda p: -p.A1 * p.kappa0, lambda p: p.A1 * p.kappa0,
           why="|T| <= A1 kappa0: the closed form is linear in the loads")),
    ("symmetric", False, bool, "solve at +load and -load and compare the odd part (removes the O(load^2) error)"),
]
KEYS = ("Mn", "Mb", "Mt", "Ft", "Fn", "Fb", "dalpha", "dkappa", "domega")
HEADLINE = ("Mn", "Mb", "Mt", "Ft", "Fb", "dalpha", "dkappa", "domega")


def build(p, sign=1.0):
    rod = der.rod_from_shape(der.shapes.helix(p.kappa0, p.omega0, 1.0, p.n), p.A1, p.A2,
                              EA=getattr(p, "EA", None))
    loads = [der.end_force(cf.helix_end_force(p.kappa0, p.omega0, sign * p.P)),
             der.end_torque(sign * p.T, follower=True)]
    return der.Scene(rod, loads=loads, constraints=[der.clamp("start")])


def changes(rod, state, rest):
    prof = dg.profile(rod, state)
    out = {k: prof[k] for k in ("xi", "Mn", "Mb", "Mt", "Ft", "Fn", "Fb")}
    out["dalpha"] = prof["alpha"] - rest["alpha"]
    out["dkappa"] = prof["kappa"] - rest["kappa"]
    out["domega"] = prof["omega"] - rest["omega"]
    return out


def run(p, solver):
    scene = build(p)
    rod = scene.rod
    rest = dg.profile(rod, rod.rest_state())
    result = solver.solve(scene)
    sim = changes(rod, result.state, rest)
    if p.symmetric:
        minus = changes(rod, solver.solve(build(p, -1.0)).state, rest)
        sim = {k: (sim[k] - minus[k]) / 2 if k != "xi" else sim[k] for k in sim}
    xi = sim["xi"]
    ref = cf.helix_profiles(xi, p.A1, p.A2, p.kappa0, p.omega0, p.P, p.T)
    paper = cf.paper_helix_profiles(xi, p.A1, p.A2, p.kappa0, p.omega0, p.P, p.T)

    def rel(a, b):
        return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))

    errors = {k: rel(sim[k], ref[k]) for k in HEADLINE}
    paper_errors = {k: rel(sim[k], paper[k]) if np.max(np.abs(paper[k])) > 0 else rel(paper[k], sim[k])
                    for k in HEADLINE}
    return {
        "error": max(errors.values()),
        "reference": "corrected closed form, profiles (docs/derivations.md, Helix under tension and torque)",
        "errors": errors, "paper_errors": paper_errors,
        "paper_P_for_this_T": cf.paper_helix_P(p.A1, p.A2, p.omega0, p.T),
        "profile": {**{k: sim[k] for k in ("xi",) + KEYS},
                    **{f"{k}_reference": ref[k] for k in KEYS}, **{f"{k}_paper": paper[k] for k in KEYS}},
    }


def validate(p):
    if p.P == 0 and p.T == 0:
        raise ValueError("--P and --T cannot both be zero (the error is relative to the response)")


run.validate = validator(PARAMETERS, validate)

if __name__ == "__main__":
    sys.exit(scenario_main("helix_torque", __doc__.splitlines()[0], PARAMETERS, run, n_default=200))
