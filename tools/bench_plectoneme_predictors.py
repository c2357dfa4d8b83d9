"""Per-step record of scenarios/plectoneme.py's continuation under predictor / barrier / tolerance variants
(docs/contact.md section 9.3): Newton iterations, CPU time, status and barrier stiffness of every der.solve.

    python tools/bench_plectoneme_predictors.py [--turns 6 --sweep 24 --n 400] [--tol 1e-4] [--samples m]
                                                [--predictor last|secant|tangent] [--projected-tangent] [--json]

--predictor is the scenario's (der.continuation's; default "last"); predictor="tangent" takes its tangent on the exact
barrier Hessian, --projected-tangent on the PSD-projected one instead (an experiment switch: it turns the
continuation's exact_contact off). The last line printed is a JSON summary: CPU of the whole run
(time.process_time, numba compilation included when the cache is cold: the first solve's CPU shows it), the
Newton iterations of all solves, the number of solves (a failed solve halves the step and is retried), and the
scenario's plateau, slope, Lk error and smallest centreline distance.
"""
import argparse
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--turns", type=float, default=6.0)
    ap.add_argument("--sweep", type=int, default=24)
    ap.add_argument("--n", type=int, default=400)
    ap.add_argument("--tol", type=float, default=1e-4)
    ap.add_argument("--samples", type=int, default=None)
    ap.add_argument("--predictor", default="last")
    ap.add_argument("--projected-tangent", action="store_true")
    ap.add_argument("--json", action="store_true", help="print the per-step log as JSON too")
    a = ap.parse_args(argv)

    import der
    sys.path.insert(0, os.path.join(HERE, "..", "scenarios"))
    import plectoneme as P

    log = []

    class Runner:
        class args:
            tol = a.tol

        def solve(self, scene, **kw):
            c0 = time.process_time()
            kw.setdefault("tol", a.tol)
            r = der.solve(scene, raise_on_failure=False, **kw)
            kappa = r.contact["terms"][0].get("kappa") if r.contact else None
            log.append({"iterations": r.iterations, "cpu_s": time.process_time() - c0, "status": r.status,
                        "kappa": kappa, "residual": r.residual})
            return r

    if a.projected_tangent:
        C = sys.modules["der.continuation"]
        init = C._Problem.__init__

        def projected(self, settings):
            init(self, settings)
            self.exact_contact = False

        C._Problem.__init__ = projected
    p = argparse.Namespace(A1=1.0, A2=1 / 0.67, L=20.0, EA=1e5, radius=0.05, force=1.0, turns=a.turns,
                           sweep=a.sweep, perturb=1e-3, png=None, n=a.n, samples=a.samples,
                           predictor=a.predictor)
    c0 = time.process_time()
    out = P.run(p, Runner())
    cpu = time.process_time() - c0
    for i, s in enumerate(log):
        print(f"solve {i:3d}: {s['iterations']:5d} iterations, {s['cpu_s']:7.2f} s CPU, {s['status']}, "
              f"residual {s['residual']:.2e}, kappa {s['kappa']}")
    if a.json:
        print(json.dumps(log))
    print(json.dumps({"cpu_s": cpu, "iterations": sum(s["iterations"] for s in log), "solves": len(log),
                      "points": len(out["turns"]), "status": out["continuation"]["status"],
                      "lk_error_max": out["lk_error_max"], "torque_plateau": out["torque_plateau"],
                      "extension_slope": out["extension_slope"], "buckling_turns": out["buckling_turns"],
                      "min_distance": min(out["min_distance"]), "predictor": a.predictor,
                      "projected_tangent": a.projected_tangent, "samples": a.samples, "tol": a.tol}))


if __name__ == "__main__":
    main()
