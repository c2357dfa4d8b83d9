"""Fuzz der's public API: random scenes (valid and invalid), each put in one outcome class.

    python tools/fuzz.py --examples 5000 --json [--seed S] [--budget 2] [--limit 20] [--show 10]

Classes (tests/fuzzing.py): invalid_input (a specific error from der, before work), converged,
converged_at_floor, not_converged (ConvergenceError with a finite residual and last state), and other -- any
other outcome, which is a defect: the tool lists the first ``--show`` of them with their cases and exits 1 if
there is one. The last line with --json is one object with the counts per class.
"""
import argparse
import json
import os
import sys
import time
from collections import Counter

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))

from fuzzing import OUTCOMES, RngDraw, classify, random_case  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", type=int, default=1000, help="number of random cases (default 1000)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--p-bad", type=float, default=0.1, help="chance that an argument is invalid (default 0.1)")
    parser.add_argument("--max-edges", type=int, default=40, help="largest number of edges (default 40)")
    parser.add_argument("--budget", type=float, default=2.0, help="solver time budget per case, s (default 2)")
    parser.add_argument("--limit", type=float, default=20.0, help="hang limit per case, s (default 20)")
    parser.add_argument("--show", type=int, default=10, help="how many 'other' cases to print (default 10)")
    parser.add_argument("--json", action="store_true", help="print the counts as one JSON object, last line")
    args = parser.parse_args(argv)
    if args.examples < 1 or not 0 <= args.p_bad <= 1 or args.budget <= 0 or args.limit <= args.budget:
        print("fuzz.py: invalid input: need --examples >= 1, 0 <= --p-bad <= 1, 0 < --budget < --limit",
              file=sys.stderr)
        return 2
    import der

    compile_s = der.warmup()
    draw = RngDraw(np.random.default_rng(args.seed))
    counts = Counter({k: 0 for k in OUTCOMES})
    others = []
    slowest = 0.0
    t0 = time.perf_counter()
    last = t0
    for i in range(args.examples):
        case = random_case(draw, p_bad=args.p_bad, max_edges=args.max_edges)
        outcome, detail, seconds = classify(case, budget=args.budget, limit=args.limit)
        counts[outcome] += 1
        slowest = max(slowest, seconds)
        if outcome == "other":
            others.append({"example": i, "detail": detail, "case": case})
        now = time.perf_counter()
        if now - last > 10:
            last = now
            print(f"[fuzz] {i + 1}/{args.examples}: {dict(counts)} ({now - t0:.0f} s)", file=sys.stderr, flush=True)
    for o in others[: args.show]:
        print(f"OTHER at example {o['example']}: {o['detail']}\n  case: {o['case']}", file=sys.stderr)
    summary = {"examples": args.examples, "seed": args.seed, "p_bad": args.p_bad, "counts": dict(counts),
               "other": counts["other"], "slowest_case_s": round(slowest, 3),
               "total_s": round(time.perf_counter() - t0, 1), "compile_s": round(compile_s, 2)}
    if args.json:
        print(json.dumps(summary, default=str))
    else:
        print(" ".join(f"{k}={v}" for k, v in counts.items()), f"({summary['total_s']} s)")
    return 1 if counts["other"] else 0


if __name__ == "__main__":
    sys.exit(main())
