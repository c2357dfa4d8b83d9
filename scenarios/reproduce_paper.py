"""The paper reproduced in one command: every scenario at its defaults, a Results table, one .rrd each.

    python scenarios/reproduce_paper.py [--rrd DIR | --no-rrd] [--n N] [--solver implicit|explicit] [--tol TOL]
                                        [--time-budget S] [--json]

Runs loop_twist, ring_torsion, helix_torque and helix_winding (and straight_twist, the classical check, and
twisted_ring: Michell's instability of the naturally straight ring, and the paper's naturally curved ring writhing
under an imposed twist) as subprocesses following the scenario contract (der/cli.py), writes ``DIR/<label>.rrd``
(default DIR: ./recordings; ``--out`` is a deprecated name for ``--rrd``), and prints one row per scenario as it
finishes: the closed form used (the paper's, or our correction), the headline error, the solve time and the
command; a scenario that fails adds its own one-line reason below its row. ``--n``, ``--solver``, ``--tol`` and
``--time-budget`` are passed to every scenario. With ``--json`` the last line on stdout is one JSON list of rows.

Exit status (the scenario contract): 2 for invalid input (one line on stderr, nothing run; a scenario that refuses
the input, e.g. helix_winding at too small an --n, makes it 2 too, with that scenario's message), 3 if a scenario
did not converge or failed its check, 0 if all passed.
"""
import argparse
import json
import math
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)

from der.cli import EXIT_FAILED, EXIT_INVALID, EXIT_OK, MAX_EDGES, _one_line, _Parser  # noqa: E402

SCENARIOS = [
    # (label, scenario, closed form used, extra arguments)
    ("straight_twist", "straight_twist", "classical: end twist T L / A2", []),
    ("loop_twist", "loop_twist", "paper Eq. 40 (correct as printed)", []),
    ("ring_torsion", "ring_torsion", "corrected (paper Eq. 47 has wrong boundary conditions)", []),
    ("helix_torque", "helix_torque", "corrected (paper's omega = omega0 ansatz, Eq. 71, is inconsistent)", []),
    ("helix_winding", "helix_winding", "corrected Eq. 81 (paper's Eq. 78 drops the binormal force)", []),
    ("michell_ring", "twisted_ring", "Michell: threshold twist 2 pi sqrt(3) A1/A2 (kappa0 = 0)",
     ["--kappa0", "0", "--sweep", "40"]),
    ("writhing_ring", "twisted_ring", "invariant: Lk = Tw + Wr = twist / 2 pi (kappa0 = 1/a0)",
     ["--sweep", "12", "--twist", "6.0"]),
]
N_MIN = 2   # the contract's; a scenario with a larger minimum refuses the input itself, with its own message


def parse(argv):
    ap = _Parser(prog="reproduce_paper.py", description=__doc__.splitlines()[0])
    ap.add_argument("--rrd", "--out", dest="rrd", default="recordings",
                    help="folder for the per-scenario recordings DIR/<label>.rrd (default: recordings)")
    ap.add_argument("--no-rrd", action="store_true", help="write no recordings")
    ap.add_argument("--n", type=int, default=None, help="edges for every scenario (default: each scenario's own)")
    ap.add_argument("--solver", choices=("implicit", "explicit"), default="implicit")
    ap.add_argument("--tol", type=float, default=None, help="residual tolerance (default: each scenario's own)")
    ap.add_argument("--time-budget", type=float, default=None, help="wall-clock seconds per solve")
    ap.add_argument("--json", action="store_true", help="print the rows as one JSON list on the last line")
    args = ap.parse_args(argv)
    if args.n is not None and not N_MIN <= args.n <= MAX_EDGES:
        raise ValueError(f"--n must be an integer from {N_MIN} to {MAX_EDGES:,} (number of edges); got {args.n}")
    if args.tol is not None and not (math.isfinite(args.tol) and args.tol > 0):
        raise ValueError(f"--tol must be a finite number > 0; got {args.tol}")
    if args.time_budget is not None and not args.time_budget > 0:
        raise ValueError(f"--time-budget must be > 0 seconds; got {args.time_budget}")
    if not args.no_rrd:
        out = os.path.abspath(args.rrd)
        if os.path.exists(out) and not os.path.isdir(out):
            raise ValueError(f"--rrd: {out} is a file; give a folder for the per-scenario recordings")
        try:
            os.makedirs(out, exist_ok=True)
            probe = os.path.join(out, ".der_write_test")
            with open(probe, "w"):
                pass
            os.remove(probe)
        except OSError as exc:
            raise ValueError(f"--rrd: cannot write into {out} ({exc.strerror or exc})") from None
    return args


def run_one(args, label, name, closed_form, extra):
    cmd = [sys.executable, os.path.join(HERE, f"{name}.py"), "--json"]
    rrd = None if args.no_rrd else os.path.join(args.rrd, f"{label}.rrd")
    if rrd:
        cmd += ["--rrd", rrd]
    common = []
    if args.n:
        common += ["--n", str(args.n)]
    if args.tol is not None:
        common += ["--tol", f"{args.tol:g}"]
    if args.time_budget is not None:
        common += ["--time-budget", f"{args.time_budget:g}"]
    if args.solver != "implicit":
        common += ["--solver", args.solver]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([ROOT, os.environ.get("PYTHONPATH", "")]))
    t0 = time.perf_counter()
    out = subprocess.run(cmd + common + extra, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    lines = [ln for ln in out.stderr.strip().splitlines() if not ln.startswith("  iteration")]
    reason = lines[-1] if lines else ""
    try:
        rec = json.loads(out.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        rec = {}
    return {"scenario": label, "closed_form": closed_form, "n": rec.get("n", args.n), "exit": out.returncode,
            "converged": rec.get("converged", False), "check_passed": rec.get("check_passed"),
            "error": rec.get("error"), "runtime_s": rec.get("runtime_s"), "wall_s": wall,
            "status": rec.get("status"), "reason": reason if out.returncode != 0 else "", "rrd": rrd,
            "command": " ".join([f"python scenarios/{name}.py", *extra, *common])}


def main(argv=None):
    try:
        args = parse(argv)
    except ValueError as exc:
        print(f"reproduce_paper.py: invalid input: {_one_line(exc)}", file=sys.stderr)
        return EXIT_INVALID
    where = "no recordings" if args.no_rrd else f"recordings in {os.path.abspath(args.rrd)}/"
    print(f"der: reproducing Drozdov & Rabin, {len(SCENARIOS)} scenarios; {where}", file=sys.stderr)
    print(f"{'scenario':<15} {'reference used':<68} {'n':>5} {'error':>10} {'solve s':>8}  command", flush=True)
    rows = []
    for label, name, closed_form, extra in SCENARIOS:
        r = run_one(args, label, name, closed_form, extra)
        rows.append(r)
        err = f"{r['error']:.2e}" if r["error"] is not None else "-"
        rt = f"{r['runtime_s']:.3f}" if r["runtime_s"] is not None else "-"
        flag = {EXIT_OK: "", EXIT_INVALID: "  INVALID INPUT", EXIT_FAILED: "  FAILED"}.get(r["exit"],
                                                                                       f"  CRASHED (exit {r['exit']})")
        print(f"{r['scenario']:<15} {r['closed_form']:<68} {r['n'] or '':>5} {err:>10} {rt:>8}  {r['command']}{flag}",
              flush=True)
        if r["reason"]:
            print(f"    {r['reason']}", flush=True)
    if args.json:
        print(json.dumps(rows))
    codes = {r["exit"] for r in rows}
    if codes == {EXIT_OK}:
        return EXIT_OK
    return EXIT_INVALID if codes <= {EXIT_OK, EXIT_INVALID} else EXIT_FAILED


if __name__ == "__main__":
    sys.exit(main())
