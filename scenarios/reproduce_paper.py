"""The paper reproduced in one command: every scenario at its defaults, a Results table, one .rrd each.

    python scenarios/reproduce_paper.py [--out recordings] [--n N] [--solver implicit|explicit] [--json]

Runs loop_twist, ring_torsion, helix_torque and helix_winding (and straight_twist, the classical check, and
twisted_ring: Michell's instability of the naturally straight ring, and the paper's naturally curved ring writhing
under an imposed twist) as subprocesses following the scenario contract, writes ``<out>/<label>.rrd``, and
prints one row per run:
the closed form used (the paper's, or our correction), the headline error, the solve time and the command.
Exit status 0 if every scenario converged, 3 otherwise.
"""
import argparse
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))

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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="recordings", help="folder for the .rrd recordings (default: recordings)")
    ap.add_argument("--n", type=int, default=None, help="edges (default: each scenario's own)")
    ap.add_argument("--solver", choices=("implicit", "explicit"), default="implicit")
    ap.add_argument("--json", action="store_true", help="print the rows as one JSON list on the last line")
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    rows = []
    print(f"der: reproducing Drozdov & Rabin; recordings in {os.path.abspath(args.out)}/", file=sys.stderr)
    for label, name, closed_form, extra in SCENARIOS:
        rrd = os.path.join(args.out, f"{label}.rrd")
        cmd = [sys.executable, os.path.join(HERE, f"{name}.py"), "--json", "--rrd", rrd, "--solver", args.solver]
        if args.n:
            cmd += ["--n", str(args.n)]
        cmd += extra
        t0 = time.perf_counter()
        out = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        shown = " ".join([f"python scenarios/{name}.py", *extra]) + (f" --n {args.n}" if args.n else "") + \
            (f" --solver {args.solver}" if args.solver != "implicit" else "")
        try:
            rec = json.loads(out.stdout.strip().splitlines()[-1])
        except (ValueError, IndexError):
            rec = {"converged": False, "error": None, "runtime_s": None, "n": args.n, "status": "crashed",
                   "message": out.stderr.strip().splitlines()[-1] if out.stderr.strip() else "no output"}
        rows.append({"scenario": label, "closed_form": closed_form, "n": rec.get("n"), "converged": rec["converged"],
                     "error": rec.get("error"), "runtime_s": rec.get("runtime_s"), "wall_s": wall,
                     "status": rec.get("status"), "rrd": rrd, "command": shown})
    print(f"\n{'scenario':<15} {'reference used':<68} {'n':>5} {'error':>10} {'solve s':>8}  command")
    for r in rows:
        err = f"{r['error']:.2e}" if r["error"] is not None else "-"
        rt = f"{r['runtime_s']:.3f}" if r["runtime_s"] is not None else "-"
        flag = "" if r["converged"] else f"  NOT CONVERGED ({r['status']})"
        print(f"{r['scenario']:<15} {r['closed_form']:<68} {r['n'] or '':>5} {err:>10} {rt:>8}  {r['command']}{flag}")
    if args.json:
        print(json.dumps(rows))
    return 0 if all(r["converged"] for r in rows) else 3


if __name__ == "__main__":
    sys.exit(main())
