"""A perversion: a rod whose natural curvature is a step, relaxed from a straight start (issue 13).

The rod (length L, bending stiffness A1, twisting stiffness A2, inextensible) has natural material curvature
kappa1 = +kappa0 towards m1 = e1 on [0, L/2) and -kappa0 on (L/2, L] (two arcs of opposite curvature), no
natural twist, and starts straight along e3 (``der.rod(rest=der.shapes.strains(...), start="straight")``). It
is clamped at xi = 0; its far end is clamped parallel (tangent e3, no rotation) but free to slide along e3 and
pulled along e3 by a force P. It relaxes into an S-shape with an inflection at the step: a planar perversion.

Reference: the planar Kirchhoff equations solved with scipy's solve_bvp (``der.references.perversion``; the two
halves as one system joined at the step). The headline error is the largest distance of a node in [0, L]
from the reference curve, over L (second order when n - 1 is even, so that the step falls on an edge
midpoint, a boundary of the vertices' cells; with n - 1 odd it falls on a vertex, which gets the mean
curvature 0, and the error is first order). Also reported: the clamp reactions against the reference
(transverse force Fx and moment M0).

    python scenarios/perversion.py [--L 2] [--kappa0 1.5] [--A1 1] [--A2 1] [--P 1] [--EA none] [--n 81]
"""
import sys

import numpy as np

import der
import der.references as ref
from der.cli import POSITIVE, Range, scenario_main, validator

PARAMETERS = [
    ("L", 2.0, float, "rest length", POSITIVE),
    ("kappa0", 1.5, float, "natural curvature of each half (+ on the first, - on the second), 1/length",
     Range(0.0, lambda p: 6.0 / p.L, open_lo=True, why="0 < kappa0 L / 2 <= 3: each half turns by at most 3 rad")),
    ("A1", 1.0, float, "bending stiffness", POSITIVE),
    ("A2", 1.0, float, "twisting stiffness", POSITIVE),
    ("P", 1.0, float, "pull on the sliding end along e3 (force)",
     Range(0.0, lambda p: 20.0 * p.A1 / p.L ** 2, why="0 <= P <= 20 A1 / L^2")),
    ("EA", None, float, "axial stiffness (default: inextensible, as the reference; a finite EA adds an error "
                        "of order P / EA, and lets the explicit solver hold the sliding clamp)", POSITIVE),
]


def natural_curvature(p, xi):
    """+kappa0 before L/2, -kappa0 after, 0 on a vertex that sits on the step."""
    h = p.L / (p.n - 1)
    d = xi - 0.5 * p.L
    return np.where(np.abs(d) < 1e-9 * h, 0.0, np.where(d < 0, p.kappa0, -p.kappa0))


def build(p):
    rest = der.shapes.strains(p.L, p.n, kappa1=lambda xi: natural_curvature(p, xi))
    rod = der.rod(rest=rest, start="straight", A1=p.A1, A2=p.A2, EA=p.EA)
    return der.Scene(rod, loads=[der.end_force([0.0, 0.0, p.P])],
                     constraints=[der.clamp("start"), der.clamp("end", slide=(0.0, 0.0, 1.0))])


def run(p, solver):
    scene = build(p)
    rod = scene.rod
    result = solver.solve(scene)
    pos, Fx, M0 = ref.perversion(p.L, p.kappa0, p.A1, p.P)
    xi = rod.xi_nodes[1:-1]
    x = result.state.positions[1:-1]
    xr = pos(xi)
    err = np.abs(x[:, [0, 2]] - xr.T).max() / p.L
    start = result.reactions[0]
    # the reaction on the rod at the start clamp is minus the internal force and moment there
    fx, m0 = -float(start["force"][0]), -float(start["moment"][1])
    return {
        "error": float(err),
        "reference": "solve_bvp of the planar Kirchhoff equations (der.references.perversion)",
        "step_on_vertex": bool((p.n - 1) % 2),
        "transverse_force": fx, "transverse_force_reference": Fx,
        "error_transverse_force": abs(fx - Fx) / max(abs(Fx), 1e-300),
        "clamp_moment": m0, "clamp_moment_reference": M0,
        "error_clamp_moment": abs(m0 - M0) / max(abs(M0), 1e-300),
        "max_deflection": float(np.abs(x[:, 0]).max()),
        "out_of_plane": float(np.abs(x[:, 1]).max()),
        "profile": {"xi": xi, "x": x[:, 0], "z": x[:, 2], "x_reference": xr[0], "z_reference": xr[1]},
    }


run.validate = validator(PARAMETERS)

if __name__ == "__main__":
    sys.exit(scenario_main("perversion", __doc__.splitlines()[0], PARAMETERS, run, n_default=81, n_min=3))
