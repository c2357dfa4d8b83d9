"""Supports at the end cross-sections against their textbook values, with the observed orders (issue 13).

    python tools/validate_supports.py [--n 20 40 80] [--json]

Prints a markdown table (docs/validation.md carries its output) or, with --json, one JSON object as the last
line. Every case is a straight rod of length L = 1, A1 = 1, A2 = 1 along x with m1 = z:

* simply supported beam (hinge + roller + fix_theta(0)), central load P = 1e-3, EA = 1e4: mid deflection
  against P L^3 / 48 A1;
* pinned-pinned and pinned-clamped Euler columns (inextensible; roller at the loaded end): the compressive end
  load at which the lowest stability eigenvalue changes sign (secant iterations), against pi^2 A1 / L^2 and
  x^2 A1 / L^2 with tan x = x (2.0457 pi^2 A1 / L^2);
* fixed-fixed beam, EA = 1e4, far clamp turned by theta = 1e-3 about z: end moments 2 A1 theta / L (near),
  4 A1 theta / L (far), from the supports' reactions;
* tension bar, EA = 100, end force P = 1: elongation between the end cross-sections' centres against P L / EA;
* statics: a curved rod (helix, EA = 300) clamped at the start and hinged at the end under point, end and
  distributed forces and a dead point torque: |sum of reactions and loads|, forces and moments.
"""
import argparse
import json
import sys
import warnings

import numpy as np

import der

L = 1.0
A1 = 1.0
X_PC = 4.493409457909064      # first root of tan x = x


def _solve(scene, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", der.RoundoffFloorWarning)
        res = der.solve(scene, **kw)
    if not res.converged:
        raise RuntimeError(res.message)
    return res


def _beam(n, EA):
    return der.rod_from_shape(der.shapes.straight(L, n, axis=(1, 0, 0), director=(0, 0, 1)), A1, 1.0, EA=EA)


def _centre(x, end):
    return 0.5 * (x[0] + x[1]) if end == "start" else 0.5 * (x[-1] + x[-2])


def simply_supported(n, P=1e-3):
    rod = _beam(n, 1e4)
    mid = n // 2
    scene = der.Scene(rod, loads=[der.point_force(mid, [0, -P, 0])],
                      constraints=[der.hinge("start"), der.roller("end", along=(1, 0, 0)), der.fix_theta(0)])
    x = _solve(scene, stability=False, tol=1e-9).state.positions
    return -x[mid, 1] / (P * L ** 3 / (48 * A1)) - 1


def _eigenvalue(n, P, clamped):
    rod = _beam(n, None)
    start = der.clamp("start") if clamped else der.hinge("start")
    cons = [start, der.roller("end", along=(1, 0, 0))] + ([] if clamped else [der.fix_theta(0)])
    return _solve(der.Scene(rod, loads=[der.end_force([-P, 0, 0])], constraints=cons),
                  n_eigenvalues=2).min_eigenvalue


def column(n, clamped):
    ref = (X_PC if clamped else np.pi) ** 2 * A1 / L ** 2
    P0, P1 = 0.95 * ref, 1.05 * ref
    l0, l1 = _eigenvalue(n, P0, clamped), _eigenvalue(n, P1, clamped)
    for _ in range(4):
        P0, l0, P1 = P1, l1, P1 - l1 * (P1 - P0) / (l1 - l0)
        l1 = _eigenvalue(n, P1, clamped)
    return P1 / ref - 1


def fixed_fixed(n, th=1e-3):
    R = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1.0]])
    res = _solve(der.Scene(_beam(n, 1e4), constraints=[der.clamp("start"), der.clamp("end", rotation=R)]),
                 stability=False, tol=1e-10)
    near, far = res.reactions
    return near["moment"][2] / (2 * A1 * th / L) - 1, far["moment"][2] / (4 * A1 * th / L) - 1


def tension_bar(n, EA=100.0, P=1.0):
    scene = der.Scene(_beam(n, EA), loads=[der.end_force([P, 0, 0])], constraints=[der.clamp("start")])
    x = _solve(scene, stability=False, tol=1e-10).state.positions
    return ((_centre(x, "end") - _centre(x, "start"))[0] - L) / (P * L / EA) - 1


def statics(n):
    rod = der.rod_from_shape(der.shapes.helix(kappa0=2.0, omega0=0.5, turns=0.6, n=n), A1=1.0, A2=1.5, EA=300.0)
    loads = [der.point_force(n // 3, [0.02, -0.01, 0.03]), der.end_force([0.01, 0.02, -0.02]),
             der.distributed_force([0.0, -0.01, 0.005]), der.point_torque(2 * n // 3, [0.003, 0.01, -0.004])]
    res = _solve(der.Scene(rod, loads=loads, constraints=[der.clamp("start"), der.hinge("end")]),
                 stability=False, tol=1e-11)
    x = res.state.positions
    F, M = np.zeros(3), np.zeros(3)
    for r in res.reactions:
        F += r["force"]
        M += np.cross(r["at"], r["force"]) + r["moment"]
    w = rod.node_weights()
    for f, at in ((loads[0].force, x[n // 3]), (loads[1].force, _centre(x, "end"))):
        F += f
        M += np.cross(at, f)
    F += w.sum() * np.asarray(loads[2].density)
    M += np.cross(x, w[:, None] * np.asarray(loads[2].density)[None, :]).sum(axis=0)
    M += np.asarray(loads[3].torque)
    return float(np.abs(F).max()), float(np.abs(M).max())


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, nargs="+", default=[20, 40, 80], help="edge counts (default 20 40 80)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    ns = args.n
    rows = {
        "simply supported beam, central load (PL^3/48A1)": [simply_supported(n) for n in ns],
        "pinned-pinned column (pi^2 A1/L^2)": [column(n, False) for n in ns],
        "pinned-clamped column (2.0457 pi^2 A1/L^2)": [column(n, True) for n in ns],
    }
    ff = [fixed_fixed(n) for n in ns]
    rows["fixed-fixed, turned end: near moment (2 A1 theta/L)"] = [a for a, _ in ff]
    rows["fixed-fixed, turned end: far moment (4 A1 theta/L)"] = [b for _, b in ff]
    rows["tension bar elongation (PL/EA)"] = [tension_bar(n) for n in ns]
    st = [statics(n) for n in ns]
    out = {"n": ns, "relative_errors": {}, "orders": {},
           "statics_force": [f for f, _ in st], "statics_moment": [m for _, m in st]}
    for name, errs in rows.items():
        out["relative_errors"][name] = errs
        e = np.abs(errs)
        out["orders"][name] = [float(np.log2(e[i] / e[i + 1])) if e[i + 1] > 1e-12 else None
                               for i in range(len(ns) - 1)]
    if args.json:
        print(json.dumps(out))
        return 0
    print("| case | " + " | ".join(f"n = {n}" for n in ns) + " | observed order |")
    print("|---|" + "---|" * len(ns) + "---|")
    for name, errs in rows.items():
        orders = ", ".join("exact" if o is None else f"{o:.2f}" for o in out["orders"][name])
        print(f"| {name} | " + " | ".join(f"{e:.2e}" for e in errs) + f" | {orders} |")
    print("| statics: max abs(sum of reactions and loads), force | " + " | ".join(f"{f:.1e}" for f, _ in st)
          + " | (balance to round-off) |")
    print("| statics: max abs(sum of moments about the origin) | " + " | ".join(f"{m:.1e}" for _, m in st)
          + " | (balance to round-off) |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
