"""How accurately the implicit solver's first Newton step of ring torsion solves its linear system, in node
coordinates (LAPACK's pivoted band LU, as the solver does; after a Jacobi equilibration of the band; and after
iterative refinement against the assembled band) and in edge coordinates (``SolverOptions.edge_newton``).

    python tools/newton_step_accuracy.py [--n 300 1000 3000 10000 30000 100000] [--refinements 2] [--json]

Measured at the rest state of ring torsion (tools/scaling.py's problem: an arc of length 3, radius 1, clamped at
its start, end torque 1e-3 about the end tangent), Newton's matrix (dt -> infinity) with the clamp's DOFs removed.
``eta`` is the step's relative residual ||T^T R - K_e T^-1 d|| / ||T^T R|| on the free edge coordinates, with K
applied as T^-T K_e T^-1 (the edge-coordinate stiffness read off the band: no cancellation of the node-coordinate
entries c A1 / h^3, so the measure itself is not drowned by the rounding it measures); ``eta_edge_z`` the same for
the edge-coordinate solution z itself, before it is turned into a step of the positions (q = T z, cumulative
sums, whose rounding the edges then see again); ``eta_edge`` is the step as the solver applies it (a compensated
pair, ``EdgeNewton.step``), ``eta_edge_hi`` its high part alone (what the solver applied before). Refinement: d += K^-1 (R -
K d) with the same LU factors and the residual formed from a copy of the node band (what iterative refinement in
working precision can do; it contracts only while the factors' error times the condition number is below 1).
"""
import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))


def measure(n, refinements=2):
    import der
    from der import closed_forms as cf
    from der.linalg import add_diagonal, band_matvec, band_resolve, band_solve
    from der.solvers.edge_coordinates import EDGE_BAND, EdgeNewton, edge_eligible
    from der.solvers.system import (
        build_system, condense_forces, constrain_system, evaluate_system, expand, prepare_state, residual_vector,
    )

    A1, A2, a0, L, T = 1.0, 1.0 / 0.67, 1.0, 3.0, 1e-3
    rod = der.rod_from_shape(der.shapes.arc(a0, L, n), A1, A2)
    scene = der.Scene(rod, loads=[der.end_torque(T * cf.ring_end_basis(a0, L)[0])], constraints=[der.clamp("start")])
    system = build_system(scene, der.SolverOptions())
    state = prepare_state(system, rod.rest_state())
    evaluate_system(system, state, 2)
    R = residual_vector(system).copy()
    if not edge_eligible(system):
        raise SystemExit("edge coordinates do not apply")
    edge = EdgeNewton(system, state)
    if not edge.prepare(system.ab, system.kl, system.ku):
        raise SystemExit("edge coordinates do not apply (the band check failed)")
    abz = edge.abz.copy(order="F")
    ez = edge.ez
    to_q = edge._to_q
    solved = {}
    edge._to_q = lambda z: (solved.setdefault("z", z.copy()), to_q(z))[1]    # keep z before it becomes a step in q
    f = system.fext - system.grad         # the node forces (full), as the solver passes them
    dz, _ = edge.step(f, 1e30)
    dz[system.fixed] = 0.0
    expand(system, dz)
    rz = ez.condense_full(ez.transpose_to_z(R))

    def eta(d, lo=None):
        kz = np.empty(d.size)
        z = ez.to_z(d)
        if lo is not None:       # a compensated step: its edges are the differences of both parts
            z = z + ez.to_z(lo)
        band_matvec(abz, EDGE_BAND, EDGE_BAND, ez.perm, z, kz, False)
        return float(np.linalg.norm(ez.condense_full(kz) - rz) / np.linalg.norm(rz))

    ab = system.ab.copy(order="F")
    diag = np.abs(ab[system.kl + system.ku, :][system.perm])
    diag[diag == 0] = 1.0
    add_diagonal(ab, system.kl, system.ku, system.perm, diag, 1e-30)       # the solver's D / dt at dt = 1e30
    constrain_system(system, ab, 1.0)
    A = ab.copy(order="F")                                                   # the band before it is factorised
    # equilibrated: S^-1 K S^-1 (S d) = S^-1 R with S = sqrt(|diag K|) (Jacobi scaling), the same LU
    S = np.sqrt(np.abs(A[system.kl + system.ku, :]))          # band order
    Ae = A / S[None, :]
    off = system.kl + system.ku
    for j in range(Ae.shape[1]):
        lo, hi = max(0, j - system.ku), min(Ae.shape[1] - 1, j + system.kl)
        Ae[off + lo - j:off + hi - j + 1, j] /= S[lo:hi + 1]
    Sq = S[system.perm]                                        # DOF order
    de, _ = band_solve(np.asfortranarray(Ae), system.kl, system.ku, system.perm, R / Sq)
    de = expand(system, de / Sq)
    dq, info = band_solve(ab, system.kl, system.ku, system.perm, R, ldlt=system.ldlt)
    expand(system, dq)
    kz = np.empty(dz.size)
    band_matvec(abz, EDGE_BAND, EDGE_BAND, ez.perm, solved["z"], kz, False)
    eta_z = float(np.linalg.norm(ez.condense_full(kz) - rz) / np.linalg.norm(rz))
    out = {"n": n, "node_path": system.ldlt.factors, "eta_node": eta(dq), "eta_node_equilibrated": eta(de),
           "eta_edge": eta(dz, edge.step_lo), "eta_edge_hi": eta(dz), "eta_edge_z": eta_z}
    d = dq.copy()
    for k in range(refinements):
        Ad = np.empty(d.size)
        band_matvec(A, system.kl, system.ku, system.perm, d, Ad, False)
        r = condense_forces(system, R - Ad)
        c = band_resolve(ab, system.kl, system.ku, system.perm, r, system.ldlt)
        if c is None:
            break
        d += expand(system, c)
        out[f"eta_node_refined_{k + 1}"] = eta(d)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[300, 1000, 3000, 10000, 30000, 100000])
    ap.add_argument("--refinements", type=int, default=2)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    rows = [measure(n, args.refinements) for n in args.n]
    keys = [k for k in rows[0] if k.startswith("eta")]
    print(f"{'n':>7}  {'node solve':>10}  " + "  ".join(f"{k:>20}" for k in keys))
    for r in rows:
        print(f"{r['n']:>7}  {str(r['node_path']):>10}  " + "  ".join(f"{r.get(k, float('nan')):>20.2e}" for k in keys))
    if args.json:
        print(json.dumps(rows))


if __name__ == "__main__":
    main()
