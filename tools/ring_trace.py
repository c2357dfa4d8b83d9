"""Per-iteration trace of the implicit solver on ring torsion (tools/scaling.py's problem): residual, strain,
energy, pseudo-time step, accepted step fraction, line-search halvings, the arc (second-order correction) used,
and every multiplier update (largest change of lam, largest lam, penalty k, elongation g). Measurement only: it
sets ``der.solvers.implicit.TRACE`` for this process.

    python tools/ring_trace.py --n 30000 [--penalty 10] [--node] [--soc] [--edge] [--budget 120] [--json]
"""
import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=30000)
    ap.add_argument("--penalty", type=float, default=None, help="SolverOptions.inextensible_penalty")
    ap.add_argument("--soc", action="store_true", help="SolverOptions.second_order_correction=True")
    ap.add_argument("--edge", action="store_true", help="SolverOptions.edge_newton=True")
    ap.add_argument("--node", action="store_true",
                    help="edge_newton=False, second_order_correction=False (the default path before stop 27; "
                         "--soc / --edge then force one of them back on)")
    ap.add_argument("--budget", type=float, default=120.0, help="time budget, s")
    ap.add_argument("--json", action="store_true", help="one JSON line per event instead of a table")
    args = ap.parse_args(argv)

    import der
    from der.solvers import implicit
    from tools import scaling

    der.warmup()
    scene, state, error = scaling._problem("ring_torsion", args.n)
    events = []

    def trace(kind, **v):
        v = {"kind": kind, **{k: (float(x) if not isinstance(x, (bool, str)) else x) for k, x in v.items()}}
        events.append(v)
        if args.json:
            print(json.dumps(v), flush=True)
        elif kind == "iteration":
            print(f"it {v['it']:4.0f} res {v['residual']:.3e} strain {v['strain']:.2e} constr {v['constraint']:.2e} "
                  f"E {v['energy']:+.12e} dt {v['dt']:.1e} since_best {v['since_best']:.0f}", flush=True)
        elif kind == "step":
            print(f"     step a {v['a']:.4g} halvings {v['ls']:.0f} arc {v['arc']} shrinks {v['attempts']:.0f} "
                  f"dPot {v['change']:+.3e}", flush=True)
        else:
            print(f"     MULTIPLIERS dlam {v['dlam']:.3e} |lam| {v['lam']:.3e} k {v['k']:.3e} |g| {v['g']:.3e}",
                  flush=True)

    opts = {"time_budget": args.budget, "tol": scaling.TOL}
    if args.penalty is not None:
        opts["inextensible_penalty"] = args.penalty
    if args.node:
        opts.update(edge_newton=False, second_order_correction=False)
    if args.soc:
        opts["second_order_correction"] = True
    if args.edge:
        opts["edge_newton"] = True
    implicit.TRACE = trace
    c0 = time.process_time()
    try:
        res = der.solve(scene, state=state, stability=False, raise_on_failure=False, options=der.SolverOptions(**opts))
    finally:
        implicit.TRACE = None
    summary = {"n": args.n, "status": res.status, "iterations": res.iterations, "residual": res.residual,
               "error": error(res.state), "cpu_s": time.process_time() - c0,
               "multiplier_updates": sum(e["kind"] == "multipliers" for e in events), "message": res.message}
    print(json.dumps(summary) if args.json else summary)


if __name__ == "__main__":
    main()
