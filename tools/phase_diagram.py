"""Phase diagram of the twisted loop (paper Section 6.1): where the planar ring under a twisting moment m_t per
unit length stops being stable, over A1/A2 from 0.1 to 10, against the closed form.

Each grid point (A = A1/A2, n) is one ``der.continuation`` of the planar ring in m_t from 0.02 A1/a0^2 until
the first special point, located by secant to 1e-9: the fold m_t a0^2/A1 = 1 (A <= 4) or the two-wave
bifurcation sqrt(3 (2A - 5))/(A - 1) (A > 4). Each A runs at n and 2n edges; the discretisation error is
O(1/n^2), so the Richardson extrapolation (4 m(2n) - m(n)) / 3 is what is compared with the closed form. The
grid runs through ``der.sweep`` twice -- serially and on a Dask cluster (a local one with ``--workers``, or the
one at ``--scheduler``) -- and the two tables must agree bit for bit. A no-op sweep on the same cluster
measures the per-task overhead.

    python tools/phase_diagram.py [--json] [--scheduler tcp://HOST:PORT] [--workers 2] [--n 32] [--count 16]
                                  [--png docs/figures/phase_diagram.png] [--csv PATH] [--no-serial]

Prints the serial and cluster runs side by side (wall, the tasks' CPU seconds, the cores each run obtained,
speedup and the ideal one from the CPU obtained, per-task overhead). Last line with --json: {"points",
"worst_boundary_error", "serial_s", "cluster_s", "workers", ...}.
"""
import argparse
import json
import os
import sys
import time

# one BLAS thread, as in Dask's workers (its nanny sets these): the serial run is then the same arithmetic, bit
# for bit, and the comparison fair (multithreaded BLAS on 2 shared cores only spins)
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import der  # noqa: E402
from der import closed_forms as cf  # noqa: E402
from der import diagnostics as dg  # noqa: E402

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")


def mean_alpha(scene, state):
    return float(np.nanmean(dg.alpha(scene.rod, state)))


def boundary(A, n, locate_tol=1e-9):
    """The first special point of the planar ring's branch for A1/A2 = A (A1 = a0 = 1), with n edges.

    Starts at m_t = 0.02 (a ring with no load at all does not converge: its force scale is round-off)."""
    rod = der.rod_from_shape(der.shapes.ring(1.0, n), 1.0, 1.0 / A)
    branch = der.continuation(lambda mt: der.Scene(rod, loads=[der.twisting_moment(mt)]), 0.02, parameter="mt",
                              bounds=(0.0, 1.5), ds=0.2, ds_max=0.3, max_steps=60, locate_tol=locate_tol,
                              summaries={"alpha": mean_alpha},
                              stop=lambda row: not row["stable"] or row["dp_ds"] < 0, progress=False)
    if not branch.special:
        raise RuntimeError(f"no special point found on the planar branch ({branch.status}: {branch.message})")
    sp = branch.special[0]
    # the planar branch below the special point, for the diagram's shading
    return {"mt": sp["mt"], "kind": sp["kind"], "alpha": sp["alpha"], "branch_points": len(branch.points),
            "branch_mt": [p["mt"] for p in branch.points], "branch_stable": [p["stable"] for p in branch.points],
            "seconds": branch.wall_time}


def noop(i):
    return {"i": i}


def closed_form(A):
    return cf.loop_threshold(1.0, 1.0 / A, 1.0)[0]


def default_ratios(count):
    """A1/A2 from 0.1 to 10: log-spaced, plus the regime past 4 where the bifurcation comes first."""
    low = np.geomspace(0.1, 3.5, max(2, count // 2))
    high = np.linspace(5.0, 10.0, max(2, count - count // 2))
    return [float(a) for a in np.concatenate([low, high])]


def compare(rows, n):
    """Per A: the two resolutions, their Richardson extrapolation and its relative error against the closed
    form (None where a point failed or the two resolutions disagree on the kind)."""
    by = {}
    for r in rows:
        by.setdefault(r["A"], {})[r["n"]] = r
    out = []
    for A, res in sorted(by.items()):
        c, f = res.get(n), res.get(2 * n)
        ref = closed_form(A)
        row = {"A": A, "closed_form": ref, "kind_closed_form": "fold" if A <= 4 else "bifurcation"}
        if c and f and c["ok"] and f["ok"]:
            rich = (4.0 * f["mt"] - c["mt"]) / 3.0
            row.update({"mt_n": c["mt"], "mt_2n": f["mt"], "mt_extrapolated": rich, "kind": f["kind"],
                        "error_n": abs(c["mt"] - ref) / ref, "error_2n": abs(f["mt"] - ref) / ref,
                        "error": abs(rich - ref) / ref, "kinds_agree": c["kind"] == f["kind"] ==
                        row["kind_closed_form"]})
        else:
            row.update({"error": None, "failed": [r["error"] for r in (c, f) if r and not r["ok"]]})
        out.append(row)
    return out


def strip(rows):
    """Rows without the timing column (what must agree bit for bit)."""
    return [{k: v for k, v in r.items() if k != "seconds"} for r in rows]


def plot(path, table, rows, n):
    from der.plotting import pyplot

    plt = pyplot("tools/phase_diagram.py")
    if plt is None:
        return None
    fig, ax = plt.subplots(figsize=(6.6, 4.4))
    A = np.geomspace(0.1, 10, 400)
    ax.plot(A, [closed_form(a) for a in A], color="0.5", lw=3, alpha=0.6,
            label="closed form: fold 1 (A <= 4), sqrt(3(2A-5))/(A-1) (A > 4)")
    ok = [t for t in table if t.get("error") is not None]
    for kind, marker in (("fold", "o"), ("bifurcation", "s")):
        sel = [t for t in ok if t["kind"] == kind]
        ax.plot([t["A"] for t in sel], [t["mt_extrapolated"] for t in sel], marker, color="C0", ms=7,
                mfc="none" if kind == "fold" else "C0", label=f"der, Richardson n={n},{2 * n}: {kind}")
    for nn, color in ((n, "C1"), (2 * n, "C2")):
        sel = [r for r in rows if r["ok"] and r["n"] == nn]
        ax.plot([r["A"] for r in sel], [r["mt"] for r in sel], "x", color=color, ms=5, label=f"der, n = {nn}")
    for r in rows:
        if r["ok"] and r["n"] == 2 * n:
            st = np.array(r["branch_stable"], bool)
            m = np.array(r["branch_mt"])
            ax.plot(np.full(st.sum(), r["A"]), m[st], ".", color="C2", ms=2, alpha=0.5)
    ax.axvline(4.0, color="0.8", lw=0.8, ls=":")
    ax.set_xscale("log")
    ax.set_xlabel("A1 / A2")
    ax.set_ylabel("m_t a0^2 / A1")
    ax.set_ylim(0, 1.08)
    ax.set_title("Twisted loop: stable planar ring below the boundary", fontsize=10)
    ax.text(0.12, 0.35, "stable (planar)", fontsize=9, color="C2")
    ax.legend(fontsize=7, loc="lower left")
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object as the last line")
    ap.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (tcp://HOST:PORT); "
                    "default: a local cluster of --workers processes")
    ap.add_argument("--workers", type=int, default=2, help="local cluster size (default 2)")
    ap.add_argument("--n", type=int, default=32, help="coarse number of edges (the fine one is 2n; default 32)")
    ap.add_argument("--count", type=int, default=16, help="number of A1/A2 values (default 16)")
    ap.add_argument("--noop", type=int, default=200, help="no-op tasks for the overhead measurement (default 200)")
    ap.add_argument("--no-serial", action="store_true", help="skip the serial run (no bit-for-bit check)")
    ap.add_argument("--png", default=os.path.join(ROOT, "docs", "figures", "phase_diagram.png"))
    ap.add_argument("--csv", default=None, help="write the per-point table (CSV) here")
    args = ap.parse_args(argv)
    if args.n < 8 or args.count < 2 or args.workers < 1 or args.noop < 0:
        print("phase_diagram.py: invalid input: need --n >= 8, --count >= 2, --workers >= 1, --noop >= 0",
              file=sys.stderr)
        return 2
    grid = [{"A": A, "n": nn} for A in default_ratios(args.count) for nn in (args.n, 2 * args.n)]
    load_before = os.getloadavg()
    der.warmup()
    serial = None
    if not args.no_serial:
        serial = der.sweep(boundary, grid, workers=0, progress=True)
    from dask.distributed import Client, LocalCluster

    t0 = time.perf_counter()
    if args.scheduler:
        client, cluster = Client(args.scheduler, timeout="20s"), None
    else:
        cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
    startup = time.perf_counter() - t0
    try:
        client.run(der.warmup)          # compile (or load from numba's cache) on every worker before timing
        workers = len(client.scheduler_info()["workers"])
        over = der.sweep(noop, {"i": list(range(args.noop))}, client=client, progress=False) if args.noop else None
        clustered = der.sweep(boundary, grid, client=client, progress=True)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    identical = None if serial is None else strip(serial.rows) == strip(clustered.rows)
    table = compare(clustered.rows, args.n)
    errors = [t["error"] for t in table if t.get("error") is not None]
    png = plot(args.png, table, clustered.rows, args.n)
    if args.csv:
        clustered.to_csv(args.csv)
    compute = float(sum(clustered.task_seconds))
    timing = timings(serial, clustered, workers, over, args.noop, startup)
    out = {
        "tool": "phase_diagram", "points": len(grid), "ratios": len(table), "n": [args.n, 2 * args.n],
        "worst_boundary_error": max(errors) if len(errors) == len(table) else None,
        "worst_boundary_error_at_A": table[int(np.argmax([t.get("error") or 0 for t in table]))]["A"],
        "worst_error_n": max(t.get("error_n") or 0 for t in table),
        "worst_error_2n": max(t.get("error_2n") or 0 for t in table),
        "kinds_agree": all(t.get("kinds_agree") for t in table),
        "failed": [r for r in clustered.rows if not r["ok"]],
        "serial_s": None if serial is None else serial.wall_time, "cluster_s": clustered.wall_time,
        "workers": workers, "scheduler": args.scheduler or "local",
        "speedup": None if serial is None else serial.wall_time / clustered.wall_time,
        "task_compute_s": compute,
        # what the cluster spends per task beyond the computation, with every worker busy
        "overhead_per_task_s": (workers * clustered.wall_time - compute) / len(grid),
        "identical_to_serial": identical, "png": png,
        **timing, "load_average": load_before + os.getloadavg(),
        "table": table,
    }
    print(comparison_table(out))
    if args.json:
        print(json.dumps(_json(out), allow_nan=False))
    else:
        for t in table:
            print(f"A1/A2 = {t['A']:7.4g}: closed form {t['closed_form']:.6f}, der {t.get('mt_extrapolated')}, "
                  f"error {t.get('error')}")
        print({k: v for k, v in out.items() if k not in ("table", "failed")})
    return 0 if (identical in (None, True) and not out["failed"]) else 1


def timings(serial, clustered, workers, over, noop, startup):
    """What the runs cost: wall, the tasks' summed wall and CPU seconds, CPU per task, the cores each run
    obtained (CPU seconds / wall seconds: on a shared machine below 1 per process), and the speedups.

    ideal_speedup_from_cpu = cluster cores obtained / serial cores obtained: the speedup the CPU the machine
    gave each run allows if a task costs the same CPU on a worker as serially; the measured speedup is that
    times serial CPU per task / cluster CPU per task (the CPU the cluster path adds to each task)."""
    n = len(clustered.rows)
    c_cpu = float(sum(c for c in clustered.task_cpu_seconds if c is not None))
    out = {"cluster_task_wall_s": float(sum(clustered.task_seconds)), "cluster_task_cpu_s": c_cpu,
           "cluster_cpu_per_task_s": c_cpu / n, "cluster_cores_used": c_cpu / clustered.wall_time,
           "cluster_cpu_utilisation": c_cpu / (max(workers, 1) * clustered.wall_time),
           "noop_task_s": None if over is None else over.wall_time / noop, "cluster_startup_s": startup}
    if serial is not None:
        s_cpu = float(sum(serial.task_cpu_seconds))
        out.update({"serial_task_cpu_s": s_cpu, "serial_cpu_per_task_s": s_cpu / n,
                    "serial_cores_used": s_cpu / serial.wall_time,
                    "ideal_speedup_from_cpu": (c_cpu / clustered.wall_time) / (s_cpu / serial.wall_time),
                    "ideal_speedup_idle": max(workers, 1) * s_cpu / c_cpu})
    return out


def comparison_table(out):
    """The serial and cluster runs side by side (text)."""
    rows = [("run", "wall s", "task CPU s (sum)", "CPU per task ms", "cores obtained", "speedup")]
    if out.get("serial_s") is not None:
        rows.append(("serial", f"{out['serial_s']:.2f}", f"{out['serial_task_cpu_s']:.2f}",
                     f"{1e3 * out['serial_cpu_per_task_s']:.0f}", f"{out['serial_cores_used']:.2f}", "1"))
    rows.append((f"cluster ({out['scheduler']}, {out['workers']} workers)", f"{out['cluster_s']:.2f}",
                 f"{out['cluster_task_cpu_s']:.2f}", f"{1e3 * out['cluster_cpu_per_task_s']:.0f}",
                 f"{out['cluster_cores_used']:.2f}",
                 "-" if out.get("speedup") is None else f"{out['speedup']:.2f}"))
    w = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["| " + " | ".join(c.ljust(w[i]) for i, c in enumerate(r)) + " |" for r in rows]
    lines.insert(1, "|" + "|".join("-" * (x + 2) for x in w) + "|")
    if out.get("ideal_speedup_from_cpu") is not None:
        lines.append(f"ideal speedup from the CPU obtained {out['ideal_speedup_from_cpu']:.2f} (measured "
                     f"{out['speedup']:.2f}); on an idle machine at most {out['ideal_speedup_idle']:.2f}")
    noop = out.get("noop_task_s")
    lines.append(f"worker idle time per task {1e3 * out['overhead_per_task_s']:.1f} ms (Dask's overhead and the "
                 "tail where one worker has no task left)"
                 + (f", no-op task round trip {1e3 * noop:.1f} ms" if noop else "")
                 + f"; cluster start/connect {out['cluster_startup_s']:.2f} s; load average "
                   f"{', '.join(f'{x:.1f}' for x in out['load_average'][:3])} before, "
                   f"{', '.join(f'{x:.1f}' for x in out['load_average'][3:])} after")
    return "\n".join(lines)


def _json(value):
    from der.sweep import _jsonable

    return _jsonable(value)


if __name__ == "__main__":
    sys.exit(main())
