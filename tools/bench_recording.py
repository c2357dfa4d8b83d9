"""What writing a rerun recording costs: the same solve with and without ``record=``, in one process.

    python tools/bench_recording.py [--n 2000] [--repeat 3]

The scene is twisted_ring's default: a naturally circular ring of n edges welded with 3/4 turn, which writhes
out of its plane over many implicit iterations (capped at ``--iterations``; a ring, so that the recording logs
Lk, Tw and the O(n^2) writhe); the wall-clock time of ``der.solve`` (stability analysis off, kernels compiled
first) is the median of ``--repeat`` runs with and without a recording to a temporary file. Prints the iterations, both times,
the overhead (recorded / plain - 1) and the per-iteration recording cost.
"""
import argparse
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import der  # noqa: E402
from der.warmup import warmup  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--iterations", type=int, default=60)
    args = ap.parse_args(argv)
    warmup()
    ring = der.rod_from_shape(der.shapes.ring(1.0, args.n), 1.0, 1.0 / 0.67)
    rod = ring.with_imposed_twist(1.5 * np.pi)
    # the weld's twist spread uniformly over the edge angles (twisted_ring.start_state)
    start = rod.displaced(rod.rest_state(), None, 1.5 * np.pi * np.arange(args.n) / args.n)
    scene = der.Scene(rod)
    kw = dict(state=start, stability=False, progress=False, raise_on_failure=False, max_iterations=args.iterations)
    with tempfile.TemporaryDirectory() as tmp:
        # one recorded solve first: imports rerun and starts its writer, outside the timings
        der.solve(scene, record=os.path.join(tmp, "warm.rrd"), **kw)
        plain, recorded, its = [], [], None
        for k in range(args.repeat):
            t0 = time.perf_counter()
            res = der.solve(scene, **kw)
            plain.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            der.solve(scene, record=os.path.join(tmp, f"r{k}.rrd"), **kw)
            recorded.append(time.perf_counter() - t0)
            its = res.iterations
        size = os.path.getsize(os.path.join(tmp, "r0.rrd"))
    tp, tr = float(np.median(plain)), float(np.median(recorded))
    print(f"ring n = {args.n}: {its} iterations; solve {tp:.3f} s, with recording {tr:.3f} s; overhead "
          f"{100 * (tr / tp - 1):.1f} % ({(tr - tp) / max(its, 1) * 1e3:.1f} ms per iteration); file {size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
