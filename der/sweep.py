"""Parameter sweeps: independent solves or continuations over a grid, in parallel through Dask.

``der.sweep(function, grid)`` calls ``function(**point)`` for every point of the grid and returns a table. The
points run on a ``dask.distributed`` cluster: a local one started for the sweep (``workers`` processes, one
thread each) or an existing one given by its scheduler address (``scheduler="tcp://HOST:PORT"``; start one
with ``dask scheduler`` and ``dask worker tcp://HOST:PORT`` on each machine). ``workers=0`` runs serially in
this process, with no Dask at all. The function must be importable or picklable by cloudpickle (a
module-level function, or one defined in a script), and each point runs exactly as it would serially, so a
sweep returns the same numbers bit for bit whatever runs it.

Dask is an optional extra: ``pip install -e '.[sweep]'``; it is imported only when a sweep runs on a cluster.
"""
import csv
import io
import itertools
import json
import sys
import time


class SweepResult:
    """The table of a sweep: one row per grid point, in grid order.

    Attributes
    ----------
    rows : list of dicts: the point's parameters, then what the function returned (a dict; a Branch is given
        as its ``to_dict()``; any other value as ``value``), then ``ok`` and ``error`` (the exception, as
        "Type: message", when the point failed; None otherwise).
    task_seconds : the seconds each point took where it ran, and task_cpu_seconds the CPU seconds of the
        process that ran it over the same time (not part of the rows: the rows are the same on every run; on a
        loaded machine CPU < wall says how much of a core the point got), and task_thread_cpu_seconds the CPU
        seconds of the thread that ran it (on a Dask worker, without its event loop's threads). wall_time : seconds for the whole sweep (without starting a local cluster);
        startup_time : seconds to start (or connect to) the cluster. workers : how many ran it (0: serial).
    """

    def __init__(self, rows, task_seconds, wall_time, startup_time, workers, scheduler, task_cpu_seconds=None,
                 task_thread_cpu_seconds=None):
        self.rows, self.task_seconds = rows, task_seconds
        self.task_cpu_seconds = list(task_cpu_seconds) if task_cpu_seconds is not None else [None] * len(rows)
        self.task_thread_cpu_seconds = (list(task_thread_cpu_seconds) if task_thread_cpu_seconds is not None
                                        else [None] * len(rows))
        self.wall_time, self.startup_time, self.workers, self.scheduler = wall_time, startup_time, workers, scheduler

    def __len__(self):
        return len(self.rows)

    def __repr__(self):
        bad = len(self.failures)
        where = "serial" if not self.workers else f"{self.workers} workers"
        return (f"SweepResult({len(self.rows)} points, {bad} failed, {where}, {self.wall_time:.3g} s)")

    @property
    def failures(self):
        """The rows of the points that failed."""
        return [r for r in self.rows if not r["ok"]]

    @property
    def columns(self):
        cols = []
        for r in self.rows:
            for k in r:
                if k not in cols:
                    cols.append(k)
        return cols

    def table(self):
        """The rows as columns: {name: list}."""
        return {c: [r.get(c) for r in self.rows] for c in self.columns}

    def to_dataframe(self):
        """A pandas DataFrame of the rows (pandas must be installed)."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError("SweepResult.to_dataframe needs pandas (pip install pandas); to_csv and to_json "
                              "work without it") from None
        return pd.DataFrame(self.rows)

    def to_json(self, path=None):
        """The rows as a JSON list (written to ``path`` if given); non-finite numbers become null."""
        text = json.dumps([_jsonable(r) for r in self.rows], allow_nan=False)
        if path is not None:
            with open(path, "w") as f:
                f.write(text + "\n")
        return text

    def to_csv(self, path=None):
        """The rows as CSV (written to ``path`` if given); lists and dicts are JSON-encoded in their cell. Floats
        are written with repr, so they read back exactly."""
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        cols = self.columns
        w.writerow(cols)
        for r in self.rows:
            w.writerow([_cell(r.get(c)) for c in cols])
        if path is not None:
            with open(path, "w") as f:
                f.write(buf.getvalue())
        return buf.getvalue()


def grid_points(grid):
    """The points of ``grid``: a dict {name: sequence} gives the Cartesian product (the last name varies
    fastest); a sequence of dicts is taken as it is."""
    if isinstance(grid, dict):
        if not grid:
            raise ValueError("der.sweep: grid is an empty dict; give {name: [values, ...], ...}")
        names = list(grid)
        for name in names:
            if not isinstance(name, str) or not name.isidentifier():
                raise ValueError(f"der.sweep: grid names must be identifiers (keyword arguments); got {name!r}")
            try:
                if len(grid[name]) == 0:
                    raise ValueError(f"der.sweep: grid[{name!r}] is empty")
            except TypeError:
                raise TypeError(f"der.sweep: grid[{name!r}] must be a sequence of values; got "
                                f"{type(grid[name]).__name__}") from None
        return [dict(zip(names, values)) for values in itertools.product(*(list(grid[n]) for n in names))]
    try:
        points = list(grid)
    except TypeError:
        raise TypeError(f"der.sweep: grid must be a dict of sequences or a sequence of dicts; got "
                        f"{type(grid).__name__}") from None
    if not points:
        raise ValueError("der.sweep: the grid has no points")
    for i, p in enumerate(points):
        if not isinstance(p, dict):
            raise TypeError(f"der.sweep: grid point {i} must be a dict of keyword arguments; got {type(p).__name__}")
    return [dict(p) for p in points]


def run_point(function, point):
    """Run one point: (row, seconds, CPU seconds of this process). An exception becomes a row with ok False and
    its reason, never a raise."""
    row, seconds, cpu, _ = _run_point_timed(function, point)
    return row, seconds, cpu


# The local cluster der.sweep starts: no statistical profiler in the workers (a thread that samples every
# thread's stack each 10 ms, competing for the GIL with the task) and no MALLOC_TRIM_THRESHOLD_ (Dask's nanny sets
# it to 64 KiB before spawning a worker; glibc then returns freed memory at once, and every array of a few hundred
# kB is a fresh mmap with its page faults). Measured on the phase diagram's tasks (tools/phase_diagram.py, docs/
# continuation.md): with both, a task cost 31-37 % more CPU in a worker than serially; without, 2-16 %.
LOCAL_CLUSTER_CONFIG = {"distributed.worker.profile.enabled": False,
                        "distributed.nanny.pre-spawn-environ": {"MALLOC_TRIM_THRESHOLD_": None}}


def local_cluster(workers, **kwargs):
    """A dask.distributed LocalCluster of ``workers`` processes, one thread each, configured for CPU-bound
    numba tasks (LOCAL_CLUSTER_CONFIG); the cluster der.sweep starts."""
    import dask
    from dask.distributed import LocalCluster

    config = {}
    for key, value in LOCAL_CLUSTER_CONFIG.items():
        if isinstance(value, dict):    # merged into Dask's (which holds OMP_NUM_THREADS=1 and the like)
            value = {**dask.config.get(key, {}), **value}
        config[key] = value
    with dask.config.set(config):
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                            **kwargs)


def _run_point_timed(function, point):
    """run_point, plus the CPU seconds of the thread that ran it (the task alone, without the other threads of a
    Dask worker: its event loop, heartbeats, memory monitor)."""
    t0, c0, th0 = time.perf_counter(), time.process_time(), time.thread_time()
    row = dict(point)
    try:
        out = function(**point)
        if hasattr(out, "to_dict"):
            out = out.to_dict()
        if not isinstance(out, dict):
            out = {"value": out}
        clash = [k for k in out if k in point or k in ("ok", "error")]
        if clash:
            raise ValueError(f"the function returned keys {clash} that are grid names or 'ok'/'error'")
        row.update(out)
        row["ok"], row["error"] = True, None
    except Exception as exc:       # a failed point reports its reason and does not stop the sweep
        row["ok"], row["error"] = False, f"{type(exc).__name__}: {exc}"
    return row, time.perf_counter() - t0, time.process_time() - c0, time.thread_time() - th0


def sweep(function, grid, *, scheduler=None, workers=2, progress=True, client=None):
    """Run ``function(**point)`` for every point of ``grid`` and return the table (a SweepResult).

    Parameters
    ----------
    function : callable taking the grid names as keyword arguments and returning a dict of results (or a
        der.continuation Branch, or a single value). It runs in a worker process: define it at module level.
    grid : {name: sequence} (Cartesian product, last name fastest) or a sequence of dicts.
    scheduler : address of a running Dask scheduler ("tcp://HOST:PORT"); None starts a local cluster of
        ``workers`` processes (one thread each, no profiler, no MALLOC_TRIM_THRESHOLD_: ``local_cluster``) for
        this sweep and closes it afterwards.
    workers : local cluster size; 0 runs serially in this process without Dask.
    progress : a progress bar on stderr (tqdm if installed, otherwise a line per tenth of the points).
    client : an existing ``dask.distributed.Client`` to use instead (then ``scheduler`` and ``workers`` are
        ignored and the client is left open).

    Returns
    -------
    SweepResult (rows in grid order; a failed point has ``ok`` False and ``error`` its reason).

    Raises
    ------
    TypeError / ValueError for a bad grid or function before any work; ImportError with the install command
    when a cluster is asked for and dask.distributed is not installed; OSError when the scheduler cannot be
    reached.

    Example
    -------
    >>> import der
    >>> def square(x):
    ...     return {"y": x * x}
    >>> der.sweep(square, {"x": [1.0, 2.0]}, workers=0, progress=False).rows
    [{'x': 1.0, 'y': 1.0, 'ok': True, 'error': None}, {'x': 2.0, 'y': 4.0, 'ok': True, 'error': None}]
    """
    if not callable(function):
        raise TypeError(f"der.sweep: function must be callable; got {type(function).__name__}")
    points = grid_points(grid)
    if client is None and scheduler is None:
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 0:
            raise ValueError(f"der.sweep: workers must be an integer >= 0 (0: serial); got {workers!r}")
    if scheduler is not None and not (isinstance(scheduler, str) and scheduler):
        raise ValueError(f"der.sweep: scheduler must be an address like 'tcp://127.0.0.1:8786'; got {scheduler!r}")
    bar = _Progress(len(points), progress)
    if client is None and scheduler is None and workers == 0:
        t0 = time.perf_counter()
        rows, secs, cpus, threads = [], [], [], []
        for p in points:
            row, s, c, th = _run_point_timed(function, p)
            rows.append(row)
            secs.append(s)
            cpus.append(c)
            threads.append(th)
            bar.update()
        bar.close()
        return SweepResult(rows, secs, time.perf_counter() - t0, 0.0, 0, None, cpus, threads)
    try:
        from dask.distributed import Client, as_completed
    except ImportError:
        raise ImportError("der.sweep on a cluster needs dask.distributed: pip install -e '.[sweep]' (or run "
                          "serially with workers=0)") from None
    t0 = time.perf_counter()
    cluster = None
    own = client is None
    if own:
        if scheduler is not None:
            try:
                client = Client(scheduler, timeout="20s")
            except OSError as exc:
                raise OSError(f"der.sweep: cannot reach the Dask scheduler at {scheduler}: {exc}") from None
        else:
            cluster = local_cluster(workers)
            client = Client(cluster)
    try:
        n_workers = len(client.scheduler_info().get("workers", {}))
        startup = time.perf_counter() - t0
        t1 = time.perf_counter()
        futures = client.map(_run_point_timed, [function] * len(points), points, pure=False)
        for _ in as_completed(futures):
            bar.update()
        bar.close()
        out = client.gather(futures)
        wall = time.perf_counter() - t1
    finally:
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
    return SweepResult([o[0] for o in out], [o[1] for o in out], wall, startup, n_workers,
                       scheduler or ("local" if cluster is not None else "client"), [o[2] for o in out],
                       [o[3] for o in out])


class _Progress:
    def __init__(self, total, enabled):
        self.total, self.done, self.bar = total, 0, None
        self.enabled = bool(enabled)
        if self.enabled:
            try:
                from tqdm import tqdm

                self.bar = tqdm(total=total, file=sys.stderr, desc="der.sweep", unit="point")
            except ImportError:
                self.bar = None

    def update(self):
        self.done += 1
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.update(1)
        elif self.done == self.total or self.done % max(1, self.total // 10) == 0:
            print(f"[der] sweep: {self.done}/{self.total} points", file=sys.stderr, flush=True)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _cell(v):
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple, dict)):
        return json.dumps(_jsonable(v))
    return v


def _jsonable(value):
    """JSON-ready copy of ``value`` (the scenario contract's conversion, der.cli; imported on use)."""
    from .cli import _jsonable as jsonable

    return jsonable(value)


__all__ = ["sweep", "SweepResult", "grid_points", "run_point", "local_cluster", "LOCAL_CLUSTER_CONFIG"]
