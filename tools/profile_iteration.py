"""Where a Newton iteration of the implicit solver goes: the CPU time of each call the loop makes, per iteration,
in units of one LAPACK ``dgbsv`` (banded factor-and-solve) of the Newton matrix at the final state, timed after the
solve (der's ``band_solve`` is a symmetric LDL^T where its backward error passes, issue 17).

    python tools/profile_iteration.py [--problem helix_winding|ring_torsion] [--n 10000]

The problems are those of ``tools/scaling.py``. Each call of the loop (``der.solvers.implicit``'s module-level
names: evaluate_system by order, band_solve, load_scales, floor_forces, transport, ...) is wrapped with a process
CPU-time clock (CPU time, not wall time: on a loaded machine wall time counts the waits for a core); "other" is
the loop's CPU time not inside a wrapped call (Python, temporaries). The final result's diagnostics are not
counted (as in ``SolveResult.wall_time``).
"""
import argparse
import collections
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

CALLS = ("evaluate_forces", "load_scales", "floor_forces", "residual_floor", "band_solve", "transport", "residual_vector", "residual_norm",
         "max_strain", "add_diagonal", "constrain_system", "floor_verdict", "expand", "dot", "dot_abs",
         "multiplier_update")


def profile(problem, n):
    import der
    import scaling
    from der.solvers import implicit

    der.warmup()
    scene, state, _ = scaling._problem(problem, n)
    spent, calls = collections.defaultdict(float), collections.Counter()
    originals = {}

    def wrap(name, key=None):
        f = originals[name] = getattr(implicit, name)

        def timed(*args, **kwargs):
            k = key(args) if key else name
            c = time.process_time()
            try:
                return f(*args, **kwargs)
            finally:
                spent[k] += time.process_time() - c
                calls[k] += 1
        setattr(implicit, name, timed)

    wrap("evaluate_system", lambda a: f"evaluate_system (order {a[2]})")
    for name in CALLS:
        if hasattr(implicit, name):
            wrap(name)
    marks = {}
    orig_relax, orig_final = implicit._relax, implicit.final_result

    def relax(*args, **kwargs):
        marks.setdefault("start", time.process_time())
        return orig_relax(*args, **kwargs)

    def final_result(*args, **kwargs):
        marks["end"] = time.process_time()
        return orig_final(*args, **kwargs)

    implicit._relax, implicit.final_result = relax, final_result
    try:
        res = der.solve(scene, state=state, stability=False, raise_on_failure=False,
                        options=der.SolverOptions(tol=scaling.TOL))
    finally:
        implicit._relax, implicit.final_result = orig_relax, orig_final
        for name, f in originals.items():
            setattr(implicit, name, f)
    loop = marks["end"] - marks["start"]
    # the unit: one LAPACK dgbsv of the Newton matrix at the final state (CPU time, best of 3), as in scaling.py
    # (der's band_solve is its symmetric LDL^T path where that is accepted, no longer dgbsv itself)
    unit = scaling.dgbsv_seconds(scene, res.state)[2]["dgbsv_cpu_s"]
    return res, loop, dict(spent), dict(calls), unit


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problem", default="helix_winding", choices=("helix_winding", "ring_torsion"))
    ap.add_argument("--n", type=int, default=10000)
    args = ap.parse_args(argv)
    from der.linalg import BAND_SOLVES

    res, loop, spent, calls, unit = profile(args.problem, args.n)
    it = max(res.iterations, 1)
    print(f"{args.problem}, n = {args.n}: {res.status} in {res.iterations} iterations; loop CPU {loop:.3f} s = "
          f"{loop / it / unit:.2f} dgbsv per iteration (one LAPACK dgbsv of the final Newton matrix: "
          f"{unit * 1e3:.2f} ms CPU; band solves by path, warm-up included: {BAND_SOLVES})")
    for k in sorted(spent, key=lambda k: -spent[k]):
        print(f"  {k:<28} {calls[k]:>4} calls  {spent[k] / it / unit:6.2f} dgbsv per iteration")
    print(f"  {'other':<28}             {(loop - sum(spent.values())) / it / unit:6.2f}")


if __name__ == "__main__":
    main()
