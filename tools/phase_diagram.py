"""Phase diagram of the twisted loop (paper Section 6.1): where the planar ring under a twisting moment m_t per
unit length stops being stable, over A1/A2 from 0.1 to 10, against the closed form.

Each grid point (A = A1/A2, n) is one ``der.continuation`` of the planar ring in m_t from 0.02 A1/a0^2 until
the first special point, located by secant to 1e-9: the fold m_t a0^2/A1 = 1 (A <= 4) or the two-wave
bifurcation sqrt(3 (2A - 5))/(A - 1) (A > 4). Each A runs at n and 2n edges; the discretisation error is
O(1/n^2), so the Richardson extrapolation (4 m(2n) - m(n)) / 3 is what is compared with the closed form. The
grid runs serially and on the other runs below, and every table must agree bit for bit with the serial one. A no-op sweep on the same cluster
measures the per-task overhead.

    python tools/phase_diagram.py [--json] [--scheduler tcp://HOST:PORT] [--workers 2] [--n 32] [--count 16]
                                  [--png docs/figures/phase_diagram.png] [--csv PATH] [--no-serial] [--no-plain]
                                  [--no-local]

Runs the same grid serially, on --workers plain processes side by side (no Dask: the hardware's own cost of
running them at once), on a local Dask cluster (der.sweep.local_cluster) and, with --scheduler, on the cluster
at that address, and prints them side by side: wall, CPU per task (of the process, and of the task's thread),
CPU against serial, the cores each run obtained, speedup and the ideal one from the CPU obtained, worker idle time
per task. Last line with --json: {"points", "worst_boundary_error", "serial_s", "cluster_s" (the last cluster),
"workers", "runs", ...}.
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
    ap.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (tcp://HOST:PORT): "
                    "the separately started cluster, run after the local one")
    ap.add_argument("--workers", type=int, default=2, help="local cluster size (default 2)")
    ap.add_argument("--n", type=int, default=32, help="coarse number of edges (the fine one is 2n; default 32)")
    ap.add_argument("--count", type=int, default=16, help="number of A1/A2 values (default 16)")
    ap.add_argument("--noop", type=int, default=200, help="no-op tasks for the overhead measurement (default 200)")
    ap.add_argument("--no-serial", action="store_true", help="skip the serial run (no bit-for-bit check)")
    ap.add_argument("--no-plain", action="store_true", help="skip the run on --workers plain processes (no Dask)")
    ap.add_argument("--no-local", action="store_true", help="skip the local cluster (with --scheduler)")
    ap.add_argument("--png", default=os.path.join(ROOT, "docs", "figures", "phase_diagram.png"))
    ap.add_argument("--csv", default=None, help="write the per-point table (CSV) here")
    args = ap.parse_args(argv)
    if args.n < 8 or args.count < 2 or args.workers < 1 or args.noop < 0 or (args.no_local and not args.scheduler):
        print("phase_diagram.py: invalid input: need --n >= 8, --count >= 2, --workers >= 1, --noop >= 0, and "
              "--scheduler with --no-local", file=sys.stderr)
        return 2
    grid = [{"A": A, "n": nn} for A in default_ratios(args.count) for nn in (args.n, 2 * args.n)]
    load_before = os.getloadavg()
    der.warmup()
    runs = []          # (label, SweepResult, noop SweepResult or None, startup seconds)
    if not args.no_serial:
        runs.append(("serial", der.sweep(boundary, grid, workers=0, progress=True), None, 0.0))
    if not args.no_plain:
        runs.append((f"{args.workers} plain processes (no Dask)", plain_processes(grid, args.workers), None, 0.0))
    from dask.distributed import Client

    from der.sweep import local_cluster

    targets = ([] if args.no_local else [("local", None)]) + ([("separate", args.scheduler)] if args.scheduler else [])
    for kind, address in targets:
        t0 = time.perf_counter()
        cluster = None if address else local_cluster(args.workers)
        client = Client(address, timeout="20s") if address else Client(cluster)
        startup = time.perf_counter() - t0
        try:
            client.run(der.warmup)      # compile (or load from numba's cache) on every worker before timing
            over = der.sweep(noop, {"i": list(range(args.noop))}, client=client, progress=False) if args.noop else None
            res = der.sweep(boundary, grid, client=client, progress=True)
            workers = len(client.scheduler_info()["workers"])
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
        runs.append((f"{kind} cluster ({address or 'LocalCluster'}, {workers} workers)", res, over, startup))
    clustered = runs[-1][1]
    serial = runs[0][1] if not args.no_serial else None
    identical = None if serial is None else all(strip(serial.rows) == strip(r.rows) for _, r, _, _ in runs[1:])
    table = compare(clustered.rows, args.n)
    errors = [t["error"] for t in table if t.get("error") is not None]
    png = plot(args.png, table, clustered.rows, args.n)
    if args.csv:
        clustered.to_csv(args.csv)
    workers = clustered.workers
    compute = float(sum(clustered.task_seconds))
    measured = [run_timing(label, r, over, startup, serial) for label, r, over, startup in runs]
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
        "overhead_per_task_s": (max(workers, 1) * clustered.wall_time - compute) / len(grid),
        "identical_to_serial": identical, "png": png,
        "runs": measured, "load_average": load_before + os.getloadavg(),
        "table": table,
    }
    print(comparison_table(measured, out["load_average"]))
    if args.json:
        print(json.dumps(_json(out), allow_nan=False))
    else:
        for t in table:
            print(f"A1/A2 = {t['A']:7.4g}: closed form {t['closed_form']:.6f}, der {t.get('mt_extrapolated')}, "
                  f"error {t.get('error')}")
        print({k: v for k, v in out.items() if k not in ("table", "failed", "runs")})
    return 0 if (identical in (None, True) and not out["failed"]) else 1


def _plain_init():
    der.warmup()


def plain_processes(grid, workers):
    """The same points on ``workers`` plain processes side by side (concurrent.futures, spawned, no Dask): the
    hardware's own cost of running that many at once (shared caches and memory bandwidth), against which Dask's
    own overhead is told apart."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from der.sweep import SweepResult, _run_point_timed

    t0 = time.perf_counter()
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"), initializer=_plain_init) as ex:
        # start (and warm) every process before timing
        list(ex.map(time.sleep, [0.2] * workers))
        startup = time.perf_counter() - t0
        t1 = time.perf_counter()
        out = list(ex.map(_run_point_timed, [boundary] * len(grid), grid))
        wall = time.perf_counter() - t1
    return SweepResult([o[0] for o in out], [o[1] for o in out], wall, startup, workers, "processes",
                       [o[2] for o in out], [o[3] for o in out])


def run_timing(label, res, over, startup, serial):
    """What a run cost: wall, the tasks' CPU seconds (of the process that ran each: a Dask worker's include its
    event loop's threads; and of the task's own thread), the cores it obtained (CPU seconds / wall seconds: on a
    shared machine below 1 per process), its speedup over the serial run, the ideal speedup from the CPU obtained
    (its cores obtained / the serial run's: what the run would gain if a task cost the same CPU as serially) and
    the worker idle time per task."""
    n = len(res.rows)
    cpu = float(sum(c for c in res.task_cpu_seconds if c is not None))
    thread = float(sum(c for c in res.task_thread_cpu_seconds if c is not None))
    workers = max(res.workers, 1)
    out = {"run": label, "wall_s": res.wall_time, "task_cpu_s": cpu, "cpu_per_task_s": cpu / n,
           "thread_cpu_per_task_s": thread / n, "cores_used": cpu / res.wall_time,
           "idle_per_task_s": (workers * res.wall_time - float(sum(res.task_seconds))) / n if res.workers else 0.0,
           "noop_task_s": None if over is None else over.wall_time / len(over.rows), "startup_s": startup}
    if serial is not None:
        s_cpu = float(sum(serial.task_cpu_seconds))
        out.update({"speedup": serial.wall_time / res.wall_time, "cpu_vs_serial": cpu / s_cpu,
                    "thread_cpu_vs_serial": thread / float(sum(serial.task_thread_cpu_seconds)),
                    "ideal_speedup_from_cpu": (cpu / res.wall_time) / (s_cpu / serial.wall_time),
                    "idle_machine_bound": workers * s_cpu / cpu})
    return out


def comparison_table(runs, load):
    """The runs side by side (text)."""
    head = ("run", "wall s", "CPU/task ms", "thread CPU/task ms", "CPU vs serial", "cores obtained", "speedup",
            "ideal from CPU obtained", "idle machine bound", "idle/task ms", "no-op ms", "start s")

    def f(x, fmt):
        return "-" if x is None else format(x, fmt)

    rows = [head]
    for r in runs:
        rows.append((r["run"], f(r["wall_s"], ".2f"), f(1e3 * r["cpu_per_task_s"], ".0f"),
                     f(1e3 * r["thread_cpu_per_task_s"], ".0f"), f(r.get("cpu_vs_serial"), ".3f"),
                     f(r["cores_used"], ".2f"), f(r.get("speedup"), ".2f"), f(r.get("ideal_speedup_from_cpu"), ".2f"),
                     f(r.get("idle_machine_bound"), ".2f"), f(1e3 * r["idle_per_task_s"], ".0f"),
                     f(None if r["noop_task_s"] is None else 1e3 * r["noop_task_s"], ".1f"), f(r["startup_s"], ".2f")))
    w = [max(len(r[i]) for r in rows) for i in range(len(head))]
    lines = ["| " + " | ".join(c.ljust(w[i]) for i, c in enumerate(r)) + " |" for r in rows]
    lines.insert(1, "|" + "|".join("-" * (x + 2) for x in w) + "|")
    lines.append("CPU/task: time.process_time of the process that ran the task (a Dask worker's include its event "
                 "loop's threads); thread CPU: the task's own thread. Load average "
                 f"{', '.join(f'{x:.1f}' for x in load[:3])} before, {', '.join(f'{x:.1f}' for x in load[3:])} after")
    return "\n".join(lines)


def _json(value):
    from der.sweep import _jsonable

    return _jsonable(value)


if __name__ == "__main__":
    sys.exit(main())
