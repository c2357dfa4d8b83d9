"""Where the edge-coordinate stability analysis spends its CPU time (issue 11's goal: the analysis under 20 % of
the solve at n = 10^4 and 10^5). The cantilever of tools/stability_scaling.py (A1 = rho_A = L = 1, tip load 1e-4
A1/L^2), solved with ``edge_newton=True``; then ``stability`` on a fresh system (it assembles its own Hessian,
which ``der.solve`` would reuse), ``--repeat`` times, with the CPU time (``time.process_time``, one BLAS thread) of
the analysis's parts accumulated by wrapping them (cumulative: a part includes the parts it calls).

    python tools/stability_profile.py [--n 10000 100000] [--repeat 3] [--baseline]

``--baseline``: also the previous block Lanczos (``stability.EDGE_LANCZOS = "baseline"``), the two variants
alternating run by run (the same machine state for both), printed side by side.
"""
import os

os.environ["OPENBLAS_NUM_THREADS"] = os.environ["OMP_NUM_THREADS"] = "1"

import argparse  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import der  # noqa: E402
import der.solvers.stability as st  # noqa: E402
from der.solvers.system import build_system  # noqa: E402

PARTS = ["evaluate_system", "_edge_eigen", "band_ldlt_compact", "_edge_block_lanczos_fused", "_edge_apply_block_fused",
         "_lanczos_sweep", "_lanczos_scale", "_edge_block_lanczos", "_edge_apply_block",
         "_cholesky_qr", "_edge_out", "_edge_checks", "band_asymmetry", "symmetry_modes"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[10000, 100000])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--baseline", action="store_true", help="also the previous block Lanczos, side by side")
    args = ap.parse_args()
    variants = ["fused", "baseline"] if args.baseline else ["fused"]
    acc = {}

    def wrap(name):
        f = getattr(st, name)

        def timed(*a, **k):
            c0 = time.process_time()
            try:
                return f(*a, **k)
            finally:
                acc[name] = acc.get(name, 0.0) + time.process_time() - c0
        setattr(st, name, timed)

    for name in PARTS:
        wrap(name)
    for n in args.n:
        rod = der.rod_from_shape(der.shapes.straight(1.0, n, axis=(0, 0, 1), director=(1, 0, 0)), 1.0, 1.0)
        scene = der.Scene(rod, loads=[der.end_force([1e-4, 0, 0])], constraints=[der.clamp("start")])
        res = der.solve(scene, stability=False, edge_newton=True, raise_on_failure=False)
        rows = {v: [] for v in variants}
        for _ in range(args.repeat + 1):            # (the first run compiles)
            for v in variants:
                st.EDGE_LANCZOS = v
                acc.clear()
                again = der.SolveResult(state=res.state, converged=True, status="converged", residual=res.residual,
                                        iterations=0, wall_time=0.0, message="")
                system = build_system(scene, der.SolverOptions())
                r0 = resource.getrusage(resource.RUSAGE_SELF)
                c0 = time.process_time()
                st.stability(system, again)
                c1 = time.process_time()
                r1 = resource.getrusage(resource.RUSAGE_SELF)
                rows[v].append((c1 - c0, dict(acc), again, r1.ru_utime - r0.ru_utime, r1.ru_stime - r0.ru_stime))
        st.EDGE_LANCZOS = "fused"
        best = {v: min(rows[v][1:], key=lambda r: r[0]) for v in variants}
        print(f"n = {n}: solve {res.status} in {res.iterations} iterations; analysis CPU (least of {args.repeat}) "
              + ", ".join(f"{v} {best[v][0]:.3f} s (user {best[v][3]:.3f}, system {best[v][4]:.3f})" for v in variants)
              + f"; lowest eigenvalue {best['fused'][2].min_eigenvalue:.9f}")
        for name in PARTS:
            if any(name in best[v][1] for v in variants):
                print(f"  {name:26s}" + "".join(
                    f"  {v} {best[v][1][name]:6.3f} s {best[v][1][name] / best[v][0]:6.1%}" if name in best[v][1]
                    else f"  {v} {'-':>16}" for v in variants))

if __name__ == "__main__":
    main()
