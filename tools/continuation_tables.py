"""The special points der.continuation locates, against their closed forms, at two resolutions and extrapolated.

    python tools/continuation_tables.py [--n 20 40] [--json]

Three tables (a0 = A1 = 1):
  fold         the twisted loop's planar branch (paper Section 6.1), A1/A2 = 0.67: fold at m_t a0^2/A1 = 1;
  bifurcation  the same loop, A1/A2 = 5: two-wave bifurcation at sqrt(3 (2A - 5))/(A - 1) before the fold;
  michell      the naturally straight ring (scenarios/twisted_ring.py --kappa0 0), A1/A2 = 2/3, in imposed
               twist: Michell's threshold 2 pi sqrt(3) A1/A2; then the writhing branch after Branch.switch.
Each row: the located point at n and 2n edges, the error ratio (4 for O(1/n^2)), the Richardson extrapolation
(4 x(2n) - x(n))/3 and its relative error, the width it was located to, the point's kind and the run time.
"""
import argparse
import json
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import der  # noqa: E402
from der import closed_forms as cf  # noqa: E402
from der import diagnostics as dg  # noqa: E402


def mean_alpha(scene, state):
    return float(np.nanmean(dg.alpha(scene.rod, state)))


def writhe(scene, state):
    return float(dg.linking_number(scene.rod, state)[2])


def loop_special(n, A2):
    rod = der.rod_from_shape(der.shapes.ring(1.0, n), 1.0, A2)
    branch = der.continuation(lambda mt: der.Scene(rod, loads=[der.twisting_moment(mt)]), 0.9, parameter="mt",
                              bounds=(0.0, 1.2), ds=0.2, locate_tol=1e-9, summaries={"alpha": mean_alpha},
                              stop=lambda r: not r["stable"] or r["dp_ds"] < 0, progress=False)
    return branch, branch.special[0], "mt"


def michell_special(n):
    rod = der.rod_from_shape(der.shapes.ring(1.0, n), 1.0, 1.5)
    rod = rod.with_natural(kappa_bar=rod.kappa_bar * 0.0)
    welded = rod.with_imposed_twist(1.0)
    start = welded.displaced(welded.rest_state(), None, np.arange(n) / n)

    def scene_of(twist):
        return der.Scene(rod.with_imposed_twist(twist))

    branch = der.continuation(scene_of, 1.0, 12.0, state=start, parameter="twist", ds=0.2, locate_tol=1e-9,
                              summaries={"writhe": writhe}, stop=lambda r: not r["stable"], progress=False)
    return branch, branch.special[0], "twist"


def row(name, reference, located):
    (n1, sp1, key, t1), (n2, sp2, _, t2) = located
    x1, x2 = sp1[key], sp2[key]
    rich = (4 * x2 - x1) / 3
    return {"case": name, "closed_form": reference, "n": [n1, n2], "located": [x1, x2],
            "kind": [sp1["kind"], sp2["kind"]], "located_to": [sp1["located_to"], sp2["located_to"]],
            "error": [abs(x1 - reference) / reference, abs(x2 - reference) / reference],
            "ratio": (x1 - reference) / (x2 - reference) if x2 != reference else None,
            "richardson": rich, "richardson_error": abs(rich - reference) / reference, "seconds": [t1, t2]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs=2, default=[20, 40], help="the two resolutions (default 20 40)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    der.warmup()
    cases = [("loop fold, A1/A2 = 0.67", cf.loop_fold(1.0, 1.0), lambda n: loop_special(n, 1.0 / 0.67)),
             ("loop two-wave bifurcation, A1/A2 = 5", cf.loop_threshold(1.0, 0.2, 1.0)[0],
              lambda n: loop_special(n, 0.2)),
             ("Michell's threshold (twist), A1/A2 = 2/3", cf.michell_twist(1.0, 1.5), michell_special)]
    rows, last = [], None
    for name, ref, fn in cases:
        located = []
        for n in args.n:
            t0 = time.perf_counter()
            branch, sp, key = fn(n)
            located.append((n, sp, key, time.perf_counter() - t0))
            last = branch
        rows.append(row(name, ref, located))
    # the writhing branch of the finer Michell ring
    t0 = time.perf_counter()
    switched = last.switch(0, ds=0.05, max_steps=6)
    writhing = [{"twist": p["twist"], "writhe": p["writhe"], "stable": p["stable"],
                 "min_eigenvalue": p["min_eigenvalue"], "dp_ds": p["dp_ds"]} for p in switched.points]
    print(f"{'case':<42} {'closed form':>11} {'n':>7} {'located':>23} {'ratio':>6} {'Richardson':>11} "
          f"{'rel. error':>10} {'kind':>12}")
    for r in rows:
        print(f"{r['case']:<42} {r['closed_form']:11.7f} {'/'.join(map(str, r['n'])):>7} "
              f"{r['located'][0]:11.7f} {r['located'][1]:11.7f} {r['ratio']:6.2f} {r['richardson']:11.7f} "
              f"{r['richardson_error']:10.2e} {r['kind'][1]:>12}")
    print(f"\nwrithing branch of the n = {args.n[1]} ring after Branch.switch ({time.perf_counter() - t0:.1f} s; "
          f"special points on it: {[(s['kind'], round(s['twist'], 6)) for s in switched.special]}):")
    print(f"{'twist':>10} {'writhe':>9} {'dtwist/ds':>10} {'min eigenvalue':>15} stable")
    for p in writhing:
        print(f"{p['twist']:10.6f} {p['writhe']:9.5f} {p['dp_ds']:10.4f} {p['min_eigenvalue']:15.5g} {p['stable']}")
    if args.json:
        print(json.dumps({"tool": "continuation_tables", "rows": rows, "writhing_branch": writhing,
                          "writhing_special": [{"kind": s["kind"], "twist": s["twist"]} for s in switched.special]}))
    ok = all(r["kind"][0] == r["kind"][1] for r in rows) and not any(math.isnan(r["richardson"]) for r in rows)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
