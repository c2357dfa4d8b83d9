"""Cold compilation time of der's kernels: the first-run warm-up on an empty numba cache, per kernel.

    python tools/compile_time.py [--against REF] [--top 25] [--json]

Runs ``der.warmup()`` (what a first ``der.solve`` compiles) in a fresh process whose numba cache
(``NUMBA_CACHE_DIR``) is an empty temporary directory, so nothing is loaded from an earlier run, and records
numba's ``numba:compile`` events: for each kernel the seconds (wall clock) of its own compilation
(exclusive: the kernels it calls, compiled on the way, are counted on their own rows) and the number of
signatures compiled. The process's CPU time (user + sys) is the total to compare.

``--against REF`` runs the same on a detached checkout of the git revision REF (e.g. ``main`` or ``HEAD~3``),
one after the other in the same command, and prints both side by side: a kernel whose compilation grew shows
up by name (issue 17's fused vertex kernel, inlined into every caller, once doubled the warm-up: 195 -> 387 s).
Takes 3-7 minutes per revision on this 2-core machine.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

_CHILD = r"""
import json, resource, sys, time
from numba.core import event
rec = event.RecordingListener()
event.register("numba:compile", rec)
import der
der.warmup()
ru = resource.getrusage(resource.RUSAGE_SELF)
stack, excl, count = [], {}, {}
for ts, ev in rec.buffer:
    f = ev.data["dispatcher"].py_func
    name = f.__module__ + "." + f.__qualname__
    if ev.is_start:
        stack.append([name, ts, 0.0])
        continue
    n, t0, child = stack.pop()
    d = ts - t0
    excl[n] = excl.get(n, 0.0) + d - child
    count[n] = count.get(n, 0) + 1
    if stack:
        stack[-1][2] += d
json.dump({"cpu_s": ru.ru_utime + ru.ru_stime, "kernels": {n: [excl[n], count[n]] for n in excl}}, sys.stdout)
"""


def measure(root):
    """Cold warm-up of the der checkout at ``root``: {"cpu_s": ..., "kernels": {name: [seconds, signatures]}}."""
    with tempfile.TemporaryDirectory(prefix="der-numba-cache-") as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=root)
        out = subprocess.run([sys.executable, "-c", _CHILD], cwd=root, env=env, check=True,
                             stdout=subprocess.PIPE, text=True).stdout
    return json.loads(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--against", metavar="REF", help="also measure this git revision, side by side")
    ap.add_argument("--top", type=int, default=25, help="kernels to list (default 25)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    runs = {"this checkout": measure(ROOT)}
    if args.against:
        with tempfile.TemporaryDirectory(prefix="der-ref-") as tmp:
            ref_root = os.path.join(tmp, "der")
            subprocess.run(["git", "-C", ROOT, "worktree", "add", "-q", "--detach", ref_root, args.against],
                           check=True)
            try:
                runs[args.against] = measure(ref_root)
            finally:
                subprocess.run(["git", "-C", ROOT, "worktree", "remove", "--force", ref_root], check=False)
    if args.json:
        json.dump(runs, sys.stdout, indent=1)
        print()
        return 0
    names = list(runs)
    print("cold warm-up CPU (s): " + ", ".join(f"{k} {runs[k]['cpu_s']:.1f}" for k in names))
    order = sorted(set().union(*(r["kernels"] for r in runs.values())),
                   key=lambda n: -max(r["kernels"].get(n, [0, 0])[0] for r in runs.values()))
    print("  ".join(f"{k[:18]:>18}" for k in names) + "  kernel (own compilation s, signatures)")
    for n in order[:args.top]:
        cells = []
        for k in names:
            s, c = runs[k]["kernels"].get(n, [0.0, 0])
            cells.append(f"{s:12.1f} ({c:3d})")
        print("  ".join(f"{c:>18}" for c in cells) + "  " + n)
    return 0


if __name__ == "__main__":
    sys.exit(main())
