"""Scenes of several rods: what the multi-rod path costs, and that one-rod scenes without contact pay nothing.

    python tools/bench_multi.py [--n 1000] [--repeat 5] [--json]

Timed (median of ``--repeat`` solves after a warm-up solve; ``wall_time`` of der.solve, compilation excluded):
  one_rod      a helix (n edges) under an end force, clamped: the no-contact path (run it on main and on this
               branch to compare; nothing of the multi-rod code runs for it)
  each_alone   the helix and a straight rod (n edges, end force and follower torque) solved one after the other
  side_by_side the same two rods as one scene of two rods (no coupling term: the banded path); the ratio to
               each_alone is the multi-rod overhead
  crossed      two crossed rods pressed together by a distributed force (tests/test_multi_rod.py), n/10 edges
               each, with der.rod_contact: the sparse path while the pair is active
"""
import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import der  # noqa: E402


def median_wall(make, repeat):
    make()                       # warm-up (compilation, caches)
    times = [make().wall_time for _ in range(repeat)]
    return float(np.median(times))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    n = a.n
    helix = der.rod_from_shape(der.shapes.helix(kappa0=1.0, omega0=0.6, turns=3, n=n), A1=1.0, A2=1.5)
    straight = der.rod_from_shape(der.shapes.straight(1.0, n), A1=1.0, A2=1.5)
    sa = der.Scene(helix, loads=[der.end_force([0, 0, 1e-2])], constraints=[der.clamp("start")])
    sb = der.Scene(straight, loads=[der.end_force([0.02, 0, 0]), der.end_torque(1e-2, follower=True)],
                   constraints=[der.clamp("start")])
    opts = dict(tol=1e-8, stability=False)
    out = {"n": n, "repeat": a.repeat, "multi_rod_code": hasattr(der, "rod_contact")}
    out["one_rod_s"] = median_wall(lambda: der.solve(sa, **opts), a.repeat)
    if hasattr(der, "rod_contact"):
        class Both:
            def __init__(self):
                r1, r2 = der.solve(sa, **opts), der.solve(sb, **opts)
                self.wall_time = r1.wall_time + r2.wall_time

        out["each_alone_s"] = median_wall(Both, a.repeat)
        out["side_by_side_s"] = median_wall(lambda: der.solve(der.Scene([sa, sb]), **opts), a.repeat)
        out["side_by_side_over_each_alone"] = out["side_by_side_s"] / out["each_alone_s"]
        sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
        from test_multi_rod import _crossed_scene

        m = max(10, n // 10)
        out["crossed_n"] = m
        out["crossed_s"] = median_wall(lambda: der.solve(_crossed_scene(n=m), **opts), a.repeat)
    if a.json:
        print(json.dumps(out))
    else:
        for k, v in out.items():
            print(f"{k:32s} {v:.4g}" if isinstance(v, float) else f"{k:32s} {v}")


if __name__ == "__main__":
    main()
