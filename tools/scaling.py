"""Time to equilibrium, cost per Newton iteration against one banded factorisation, round-off floor and peak
memory of the implicit solver from n = 100 to 100,000 edges (and a million with ``--million``).

    python tools/scaling.py [--json] [--n 100 1000 10000 100000] [--png PATH]
    python tools/scaling.py --million [--json] [--baseline] [--no-hugepages]
    python tools/scaling.py --setup [--n ...] [--json]     (the set-up alone: no solve)

Two problems: ring torsion (scenarios/ring_torsion.py: an arc clamped at one end, end torque; solved from the
rest state) and helix winding (scenarios/helix_winding.py: 200 edges per turn, so n/200 turns, both ends clamped
on the stretched and overwound helix; solved from the uniform helix). Each (problem, n) runs in a fresh process
(numba's cache makes that cheap) so that its peak resident memory is its own: reported is the growth of the
peak RSS over the process baseline after compilation (``rss_growth_mb``, per edge ``rss_per_edge_kb``), the
process peak (``peak_rss_mb``) and the peak of Python/NumPy allocations (tracemalloc, in a second short solve).

Reported per run (a JSON row with ``--json``): ``problem``, ``n``, ``converged``, ``status``, ``residual``,
``tol``, iterations, ``solve_s``, ``setup_s`` (shape, rod and initial state; the scenario module and its scipy
import are loaded before the timer), ``rod_s`` (``rod_from_shape`` alone), ``presolve_s`` (``der.solve`` up to its
first Newton iteration), ``setup_to_first_iteration_s`` (their sum), each also in CPU time (``*_cpu_s``),
``solve_minor_faults`` (page faults of the solve), ``s_per_iteration``, ``dgbsv_s``
(one LAPACK banded factor-and-solve of the same Newton matrix, timed in the same process after the solve, best
of 3 -- the iterations are averages, so on a shared machine the ratio leans against der: the floor of a Newton
iteration) and ``per_iteration_ratio_to_dgbsv``, the same in CPU time (``dgbsv_cpu_s``,
``per_iteration_cpu_ratio_to_dgbsv``, with the solver loop's CPU time ``solve_loop_cpu_s`` over the interval of
``wall_time``: less sensitive to the waits for a core on a loaded machine); the time split of the solve
(``assembly_s``, ``factorisation_s``, ``line_search_s``, from ``SolveResult.timings``); the error against the
closed form; and three round-off floors at the final state: ``residual_floor`` (the solver's bound eps |K| w, w
the rounding the kernels see: each edge at its own length), ``noise_floor`` (measured: how far the residual departs
from its linear response K dx when the nodes move by their edges' rounding, frames transported -- the jumps of the
evaluation; ``noise_floor_subgrid`` the same for a tenth of it) and ``noise_floor_absolute``
(measured the same way for plain absolute coordinates rounded at half an ulp of |x|: the floor der had before
compensated coordinates). Fitted: the exponent p of time per iteration, solve time, memory, setup, dgbsv and
floor ~ n^p over the converged runs with n >= 1000.

Positions are compensated pairs (``RodState.q_lo``) and edges are formed from them in one place
(``geometry.edge_array``): an edge carries the rounding of its own length, eps h, not that of the coordinates,
eps |x| (before: a floor growing like n^3 for ring torsion at fixed L, like n for helix winding at fixed h). The
curvature binormal and the elongation are formed from the edges' low parts too (``stencils.curvature_binormal_of``,
``stencils.elongation``): the rounding of unit tangents and of |e| (eps absolute against h kappa, eps |e| against
the elongation), which the stiffnesses A1 / h^3 and c A1 / h^3 turned into a noise growing like n, is gone; ring
torsion's measured noise is about 1e-11 at every n relative to the old force scale (where the clamp's reaction
couple set it), ~1.6e-12 n relative to the load since 14bdade (docs/scaling.md). ``--problems ring_torsion`` runs one problem,
``--time-budget`` sets the solve's wall-clock budget (default 120 s), ``--second-order-correction`` and
``--edge-newton`` solve with those ``SolverOptions`` (rows carry ``second_order_correction``,
``edge_newton`` and ``linear_solves``).
"""
import argparse
import contextlib
import json
import os
import platform
import resource
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))


TOL = 1e-8


def rounding_noise(system, state, scales, absolute, samples=3, seed=0, fraction=1.0):
    """The residual that rounding the state alone produces at ``state``, measured: the largest change of the
    residual vector (in residual units) when the state moves by one rounding step in a random direction, max over
    ``samples`` draws. With ``absolute`` the step is that of plain absolute coordinates (half an ulp of |x| per
    coordinate, no low parts): the floor der had before compensated coordinates (issue 17). Otherwise it is the
    rounding of each edge at its own length (half an ulp of the longest edge at a node, times ``fraction``, put
    into the low parts ``q_lo``), with the frames transported, and what is reported is the change of the residual
    beyond its linear response K dx: the jumps of the evaluation (zero for a residual that is a smooth function
    of the compensated positions; with ``fraction`` 1 and edges rounded to doubles inside the kernels, the floor
    of der's compensated coordinates before the curvature and the elongation took the edges' low parts)."""
    from der.linalg import band_matvec
    from der.solvers.system import evaluate_system, residual_norm, residual_vector, transport

    rng = np.random.default_rng(seed)
    q = state.q.copy()
    evaluate_system(system, state, 2)
    R0 = residual_vector(system)
    pos = np.zeros(q.size, dtype=bool)
    pos.reshape(-1, 4)[:, :3] = True
    pos &= ~system.fixed
    rod = system.rod
    if absolute:
        size = np.abs(q)
    else:
        le = np.linalg.norm(state.positions[rod.edge_nodes[:, 1]] - state.positions[rod.edge_nodes[:, 0]], axis=1)
        node = np.zeros(rod.n_nodes)
        np.maximum.at(node, rod.edge_nodes[:, 0], le)
        np.maximum.at(node, rod.edge_nodes[:, 1], le)
        size = fraction * np.repeat(node, 4)
    step = 0.5 * np.finfo(float).eps * size * pos
    ab = system.ab.copy(order="F")
    worst = 0.0
    trial = state.copy()
    lo = np.zeros_like(q) if state.q_lo is None else state.q_lo.copy()
    Kdx = np.zeros(q.size)
    for _ in range(samples):
        signs = rng.choice([-1.0, 1.0], size=q.size)
        if absolute:
            trial.q[:] = q + step * signs
            trial.q_lo = None
        else:
            trial.q[:] = q
            trial.q_lo = lo + step * signs
            transport(system, state, trial.q, trial)
            band_matvec(ab, system.kl, system.ku, system.perm, step * signs, Kdx)
            Kdx[system.fixed] = 0.0
        evaluate_system(system, trial, 1)
        worst = max(worst, residual_norm(system, residual_vector(system) - R0 + Kdx, scales))
    return worst


def dgbsv_seconds(scene, state, start=None, repeat=3):
    """Seconds of one LAPACK banded factor-and-solve (``dgbsv``) of the Newton matrix of ``scene`` at ``state``
    -- what one Newton iteration cannot go below -- measured here, beside der's iteration (best of ``repeat``;
    the copy of the band that dgbsv overwrites is timed apart and not counted). Also returns the round-off
    floor of the residual at ``state`` (``residual_floor``: eps |K| |q| against the force scale), and in the
    dict the CPU seconds of the same dgbsv (``dgbsv_cpu_s``, process time, best of ``repeat``)."""
    import der
    from der import linalg
    from der.linalg import add_diagonal, band_solve, constrain_band
    from der.solvers.system import (
        build_system, evaluate_system, load_scales, prepare_state, residual_floor, residual_vector,
    )

    system = build_system(scene, der.SolverOptions())
    st = prepare_state(system, state)
    evaluate_system(system, st, 2)
    scales = load_scales(system, st)
    floor = residual_floor(system, st, scales)
    noise = {"noise_floor": rounding_noise(system, st, scales, False),
             "noise_floor_subgrid": rounding_noise(system, st, scales, False, fraction=0.1),
             "noise_floor_absolute": rounding_noise(system, st, scales, True)}
    kl, ku, perm = system.kl, system.ku, system.perm
    best = best_cpu = np.inf
    for _ in range(repeat):   # assembled again each time rather than copied: no second band in memory
        evaluate_system(system, st, 2)
        ab = system.ab
        diag = np.abs(ab[kl + ku, :][perm])
        diag[diag == 0] = 1.0
        add_diagonal(ab, kl, ku, perm, diag, 1e-3)
        constrain_band(ab, kl, ku, perm, system.fixed, 1.0)
        R = residual_vector(system)
        linalg.USE_LDLT = False       # LAPACK's dgbsv itself, not der's symmetric path
        try:
            t0, c0 = time.perf_counter(), time.process_time()
            band_solve(ab, kl, ku, perm, R)
        finally:
            linalg.USE_LDLT = True
        best = min(best, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    noise["dgbsv_cpu_s"] = best_cpu
    return best, floor, noise


def single(problem, n, time_budget=120.0, trace=True, second_order_correction=None, edge_newton=None):
    """One run in this process; returns a dict (called in a child process). ``second_order_correction``,
    ``edge_newton``: the solver options of those names (``SolverOptions``)."""
    import tracemalloc

    import der

    compile_s = der.warmup()
    hw = _scenario_module()     # (scipy's import is not part of the set-up)
    base_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    scene, state, error, setup_times = _timed_setup(problem, n, hw)
    from der.linalg import BAND_SOLVES
    BAND_SOLVES.update({k: 0 for k in BAND_SOLVES})    # count this solve's only (not the warm-up's)
    cpu0 = resource.getrusage(resource.RUSAGE_SELF)
    with _loop_cpu_time() as loop_cpu:
        t_call, c_call = time.perf_counter(), time.process_time()
        res = der.solve(scene, state=state, stability=False, raise_on_failure=False,
                        options=der.SolverOptions(time_budget=time_budget, tol=TOL,
                                                  second_order_correction=second_order_correction,
                                                  edge_newton=edge_newton))
    cpu1 = resource.getrusage(resource.RUSAGE_SELF)
    peak_rss = cpu1.ru_maxrss
    band_solves = dict(BAND_SOLVES)   # the solve's band solves by path (symmetric LDL^T accepted, or dgbsv)
    s_per_iteration = res.wall_time / max(res.iterations, 1)
    start = state if state is not None else scene.rod.rest_state()
    t_dgbsv, floor, noise = dgbsv_seconds(scene, res.state, start)
    out = {"problem": problem, "n": n, "converged": res.converged, "status": res.status, "tol": TOL,
           "iterations": res.iterations, "solve_s": res.wall_time, **setup_times,
           # der.solve's preparation before its first iteration (system, band, working state, checks)
           "presolve_s": loop_cpu["wall_start"] - t_call, "presolve_cpu_s": loop_cpu["start"] - c_call,
           "setup_to_first_iteration_s": setup_times["setup_s"] + loop_cpu["wall_start"] - t_call,
           "setup_to_first_iteration_cpu_s": setup_times["setup_cpu_s"] + loop_cpu["start"] - c_call,
           "second_order_correction": second_order_correction, "edge_newton": edge_newton,
           "linear_solves": res.linear_solves,
           "s_per_iteration": s_per_iteration, "dgbsv_s": t_dgbsv,
           # CPU seconds of the solve (user, system): on a shared machine wall time also counts other processes
           "solve_cpu_user_s": cpu1.ru_utime - cpu0.ru_utime, "solve_cpu_system_s": cpu1.ru_stime - cpu0.ru_stime,
           # page faults during the solve (minor: a fresh page of memory touched for the first time)
           "solve_minor_faults": cpu1.ru_minflt - cpu0.ru_minflt, "solve_major_faults": cpu1.ru_majflt - cpu0.ru_majflt,
           "per_iteration_ratio_to_dgbsv": s_per_iteration / t_dgbsv,
           # the same ratio in CPU time (the solve's user + system time per iteration against dgbsv's): on a
           # loaded machine wall time also counts the waits for a core, which fall unevenly on the two
           "solve_loop_cpu_s": loop_cpu["s"],
           "per_iteration_cpu_ratio_to_dgbsv": loop_cpu["s"] / max(res.iterations, 1) / noise["dgbsv_cpu_s"],
           "residual": res.residual,
           "residual_floor": floor, **noise, "message": res.message, "error": error(res.state),
           "rss_growth_mb": (peak_rss - base_rss) / 1024.0, "peak_rss_mb": peak_rss / 1024.0,
           "rss_per_edge_kb": (peak_rss - base_rss) / n, "compile_s": compile_s, "band_solves": band_solves,
           "numpy_madvise_hugepage": os.environ.get("NUMPY_MADVISE_HUGEPAGE", "default"),
           **{f"{k}_s": v for k, v in res.timings.items()}}
    if not trace:
        return out
    # NumPy's share of the peak, in a second, short solve: tracemalloc slows allocation-heavy code, so it is
    # kept out of the timed run (the work arrays are all allocated in the first iterations)
    tracemalloc.start()
    der.solve(scene, state=state, stability=False, raise_on_failure=False,
              options=der.SolverOptions(max_iterations=3))
    _, traced_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    out["traced_peak_mb"] = traced_peak / 2 ** 20
    return out


@contextlib.contextmanager
def _loop_cpu_time(stop=None):
    """Process CPU seconds of the implicit solver over the interval its ``wall_time`` covers: from the entry of
    ``solve_implicit`` to the entry of its last ``final_result`` (the system's setup before and the result's
    diagnostics after are not counted, as in ``wall_time``). Yields a dict whose "s" is set on exit, and
    "start"/"wall_start" (process and wall clock at the entry of ``solve_implicit``: the first iteration).
    ``stop``: an exception class raised there instead of solving (``--setup``)."""
    from der.solvers import implicit

    marks = {"s": float("nan")}
    orig_solve, orig_final = implicit.solve_implicit, implicit.final_result

    def solve_implicit(*args, **kwargs):
        marks["start"] = time.process_time()
        marks["wall_start"] = time.perf_counter()
        if stop is not None:
            raise stop()
        return orig_solve(*args, **kwargs)

    def final_result(*args, **kwargs):
        marks["end"] = time.process_time()
        return orig_final(*args, **kwargs)

    implicit.solve_implicit, implicit.final_result = solve_implicit, final_result
    try:
        yield marks
    finally:
        implicit.solve_implicit, implicit.final_result = orig_solve, orig_final
        if "start" in marks and "end" in marks:
            marks["s"] = marks["end"] - marks["start"]


def _scenario_module():
    """scenarios/helix_winding.py as a module (it imports scipy: loaded before any timer starts)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("hw", os.path.join(HERE, "..", "scenarios", "helix_winding.py"))
    hw = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hw)
    return hw


def _problem(problem, n, times=None, hw=None):
    """(scene, initial state or None, error(state) against the closed form) of one benchmark problem. ``times``
    (a dict) receives ``rod_s`` and ``rod_cpu_s``: wall and CPU seconds of ``rod_from_shape`` alone; ``hw``: the
    helix scenario's module (``_scenario_module()``, loaded outside the timed setup)."""
    import der
    from der import closed_forms as cf
    from der import diagnostics as dg

    times = {} if times is None else times

    def build_rod(shape, A1, A2):
        t0, c0 = time.perf_counter(), time.process_time()
        rod = der.rod_from_shape(shape, A1, A2)
        times["rod_s"], times["rod_cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
        return rod

    if problem == "ring_torsion":
        A1, A2, a0, L, T = 1.0, 1.0 / 0.67, 1.0, 3.0, 1e-3
        rod = build_rod(der.shapes.arc(a0, L, n), A1, A2)
        scene = der.Scene(rod, loads=[der.end_torque(T * cf.ring_end_basis(a0, L)[0])],
                          constraints=[der.clamp("start")])
        ref = cf.ring_end_rotation(A1, A2, a0, L, T)

        def error(state):
            return float(np.linalg.norm(dg.end_motion(rod, state)[1] - ref) / np.linalg.norm(ref))
        return scene, None, error
    hw = _scenario_module() if hw is None else hw
    lam, eta, phi, A = 0.6, 1.2, 0.1, 0.67
    rod = build_rod(der.shapes.helix(1.0, lam, n / 200, n), A, 1.0)
    scene = der.Scene(rod, constraints=[der.clamp("start"), der.clamp("end")])
    ref = np.array([cf.winding_P0(eta, phi, lam, A), cf.winding_T0(eta, phi, lam, A)])

    def error(state):
        m = hw.measure(rod, state, lam)
        return float(np.linalg.norm(np.array([m["P0"], m["T0"]]) - ref) / np.linalg.norm(ref))
    return scene, hw.deformed_state(rod, eta, phi, lam), error


def _timed_setup(problem, n, hw):
    """``_problem`` timed: (scene, state, error, times) with ``setup_s``/``setup_cpu_s`` (shape, rod and initial
    state; the scenario module and its scipy import are loaded before) and ``rod_s``/``rod_cpu_s``."""
    times = {}
    t0, c0 = time.perf_counter(), time.process_time()
    scene, state, error = _problem(problem, n, times, hw)
    times["setup_s"], times["setup_cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
    return scene, state, error, times


class _FirstIteration(Exception):
    """Raised at the entry of the implicit solver by ``--setup``: the set-up is measured, the solve not run."""


def setup_only(problem, n, repeat=3):
    """Set-up alone (``--setup``), in this process after compilation: shape, rod and initial state (``setup_s``,
    ``rod_s``) and der.solve's own preparation up to the first Newton iteration (``presolve_s``: the system,
    band, working state and the pre-solve checks), wall and CPU seconds; the first run (what a script sees: fresh
    memory) and the best of ``repeat`` more (``*_best_*``)."""
    import der

    der.warmup()
    hw = _scenario_module()
    runs = []
    for _ in range(1 + repeat):
        scene, state, _, times = _timed_setup(problem, n, hw)
        with _loop_cpu_time(stop=_FirstIteration) as loop:
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                der.solve(scene, state=state, stability=False, raise_on_failure=False,
                          options=der.SolverOptions(tol=TOL))
            except _FirstIteration:
                pass
        times["presolve_s"], times["presolve_cpu_s"] = loop["wall_start"] - t0, loop["start"] - c0
        times["setup_to_first_iteration_s"] = times["setup_s"] + times["presolve_s"]
        times["setup_to_first_iteration_cpu_s"] = times["setup_cpu_s"] + times["presolve_cpu_s"]
        runs.append(times)
        del scene, state
    out = {"problem": problem, "n": n, **runs[0]}
    for k in runs[0]:
        out[k[:-2] + "_best_s"] = min(r[k] for r in runs[1:])
    return out


def fit(rows, key):
    pts = [(r["n"], r[key]) for r in rows if r["n"] >= 1000 and r.get("converged") and r.get(key) and r[key] > 0]
    if len(pts) < 2:
        return None
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def _child_env(args):
    """The environment of a solve's child process (``--no-hugepages``: NumPy's huge-page advice off)."""
    env = dict(os.environ)
    if getattr(args, "no_hugepages", False):
        env["NUMPY_MADVISE_HUGEPAGE"] = "0"
    return env


def _baseline():
    """``--baseline``: the paths this round replaced, kept as switches for side-by-side runs -- every refused
    LDL^T waits LDLT_RETRY_AFTER band solves (now an indefinite matrix is tried again at the next solve), and the
    LDL^T factor L is a separate n x kl array (now in the band's spare rows)."""
    from der import linalg

    linalg.LDLT_RETRY_INDEFINITE = False
    linalg.LDLT_IN_BAND = False


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[100, 300, 1000, 3000, 10000, 30000, 100000])
    ap.add_argument("--problems", nargs="+", default=["ring_torsion", "helix_winding"])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--png", default=None)
    ap.add_argument("--million", action="store_true",
                    help="only the 10^6-edge helix between clamps: solve time, peak RSS and the split of the time")
    ap.add_argument("--setup", action="store_true",
                    help="only the set-up: shape, rod (rod_from_shape) and initial state, and der.solve's preparation up "
                         "to the first Newton iteration, each (problem, n) in a fresh process; no solve")
    ap.add_argument("--single", nargs=2, metavar=("PROBLEM", "N"), help=argparse.SUPPRESS)
    ap.add_argument("--from-json", default=None, metavar="JSON",
                    help="only re-plot --png from the saved output of --json (no solve)")
    ap.add_argument("--no-trace", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--second-order-correction", action="store_true",
                    help="solve with SolverOptions(second_order_correction=True) (a refused Newton step corrected "
                         "for its chord error with the same factors, searched along an arc)")
    ap.add_argument("--edge-newton", action="store_true",
                    help="solve with SolverOptions(edge_newton=True) (Newton steps of an open rod held at its "
                         "start in edge coordinates; the helix between two clamps is not eligible)")
    ap.add_argument("--baseline", action="store_true",
                    help="the solver's paths before this round's changes to the million-edge run (issue 17), for "
                         "before/after comparisons in one command: see _baseline")
    ap.add_argument("--no-hugepages", action="store_true",
                    help="run the solves' processes with NUMPY_MADVISE_HUGEPAGE=0 (NumPy's transparent-huge-page "
                         "advice off): on the measuring VM the first touch of fresh huge pages cost ~3.3 s of "
                         "system time per GB against 1.2-2.5 s for 4 kB pages (docs/scaling.md)")
    ap.add_argument("--time-budget", type=float, default=120.0,
                    help="wall-clock budget of each solve in seconds (default 120; a loaded machine may need more)")
    args = ap.parse_args(argv)
    if args.baseline:
        _baseline()
    if args.png:
        from der.plotting import require_matplotlib
        try:
            require_matplotlib("--png")
        except ValueError as exc:
            print(f"scaling.py: invalid input: {exc}", file=sys.stderr)
            sys.exit(2)
    if args.from_json:
        if not args.png:
            print("scaling.py: invalid input: --from-json needs --png (it only re-plots)", file=sys.stderr)
            sys.exit(2)
        with open(args.from_json) as fh:
            text = fh.read().strip().splitlines()
        _plot(json.loads(text[-1])["rows"], args.png)   # the last line of a --json run
        return
    if args.single and args.setup:
        print(json.dumps(setup_only(args.single[0], int(args.single[1]))))
        return
    if args.setup:
        return setup_table(args)
    if args.single:
        print(json.dumps(single(args.single[0], int(args.single[1]), time_budget=args.time_budget,
                                trace=not args.no_trace, second_order_correction=args.second_order_correction or None,
                                edge_newton=args.edge_newton or None)))
        return
    if args.million:
        return million(args)
    rows = []
    for problem in args.problems:
        for n in args.n:
            out = subprocess.run([sys.executable, __file__, "--single", problem, str(n), "--time-budget",
                                  str(args.time_budget)]
                                 + (["--second-order-correction"] if args.second_order_correction else [])
                                 + (["--edge-newton"] if args.edge_newton else [])
                                 + (["--baseline"] if args.baseline else []),
                                 capture_output=True, text=True, env=_child_env(args))
            try:
                r = json.loads(out.stdout.strip().splitlines()[-1])
            except (ValueError, IndexError):
                r = {"problem": problem, "n": n, "converged": False, "status": "crashed",
                     "message": out.stderr.strip()[-300:]}
            rows.append(r)
            print(f"[scaling] {problem} n={n}: {r.get('status')} {r.get('solve_s', float('nan')):.3f} s",
                  file=sys.stderr)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores (one used)")
    print(f"{'problem':<14} {'n':>7} {'iter':>5} {'solve s':>9} {'s/iter':>9} {'/dgbsv':>7} {'cpu':>5} {'residual':>9} "
          f"{'floor':>8} {'noise':>8} {'noise|x|':>8} {'error':>9} {'setup s':>8} {'RSS MB':>8} {'numpy MB':>9}  status")
    for r in rows:
        if "solve_s" not in r:
            print(f"{r['problem']:<14} {r['n']:>7}  {r['status']}: {r['message']}")
            continue
        print(f"{r['problem']:<14} {r['n']:>7} {r['iterations']:>5} {r['solve_s']:>9.3f} {r['s_per_iteration']:>9.4f} "
              f"{r['per_iteration_ratio_to_dgbsv']:>7.2f} {r['per_iteration_cpu_ratio_to_dgbsv']:>5.2f} {r['residual']:>9.1e} "
              f"{r['residual_floor']:>8.1e} {r['noise_floor']:>8.1e} {r['noise_floor_absolute']:>8.1e} {r['error']:>9.1e} "
              f"{r['setup_s']:>8.3f} {r['rss_growth_mb']:>8.1f} {r['traced_peak_mb']:>9.1f}  "
              f"{r['status']}")
    fits = {}
    for problem in args.problems:
        pr = [r for r in rows if r["problem"] == problem and "solve_s" in r]
        fits[problem] = {"time_per_iteration_exponent": fit(pr, "s_per_iteration"),
                         "solve_time_exponent": fit(pr, "solve_s"),
                         "memory_exponent": fit(pr, "traced_peak_mb"),
                         "setup_exponent": fit(pr, "setup_s"),
                         "dgbsv_exponent": fit(pr, "dgbsv_s"),
                         "floor_exponent": fit(pr, "residual_floor")}
        f = {k: ("n/a" if v is None else f"{v:.2f}") for k, v in fits[problem].items()}
        print(f"{problem}: time/iteration ~ n^{f['time_per_iteration_exponent']}, "
              f"solve time ~ n^{f['solve_time_exponent']}, memory ~ n^{f['memory_exponent']}, "
              f"setup ~ n^{f['setup_exponent']}, dgbsv ~ n^{f['dgbsv_exponent']}, "
              f"floor ~ n^{f['floor_exponent']}  (fits over converged n >= 1000)")
    if args.png:
        _plot(rows, args.png)
    if args.json:
        print(json.dumps({"machine": platform.machine(), "rows": rows, "fits": fits}))


def setup_table(args):
    """``--setup``: the set-up times of each (problem, n), each in a fresh process."""
    rows = []
    for problem in args.problems:
        for n in args.n:
            out = subprocess.run([sys.executable, __file__, "--single", problem, str(n), "--setup"],
                                 capture_output=True, text=True)
            try:
                rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
            except (ValueError, IndexError):
                rows.append({"problem": problem, "n": n, "status": "crashed", "message": out.stderr.strip()[-300:]})
    print("set-up, CPU ms (first run in a fresh process / best of 3 more): rod_from_shape, shape + rod + initial "
          "state, der.solve's preparation, all to the first Newton iteration; wall ms of the last")
    print(f"{'problem':<14} {'n':>8} {'rod':>15} {'setup':>15} {'presolve':>15} {'to 1st iteration':>17} {'wall':>8}")
    for r in rows:
        if "setup_s" not in r:
            print(f"{r['problem']:<14} {r['n']:>8}  {r['status']}: {r['message']}")
            continue
        cell = lambda k: f"{1e3 * r[k + '_cpu_s']:.1f} / {1e3 * r[k + '_cpu_best_s']:.1f}"   # noqa: E731
        print(f"{r['problem']:<14} {r['n']:>8} {cell('rod'):>15} {cell('setup'):>15} {cell('presolve'):>15} "
              f"{cell('setup_to_first_iteration'):>17} {1e3 * r['setup_to_first_iteration_s']:>8.1f}")
    if args.json:
        print(json.dumps({"machine": platform.machine(), "setup_rows": rows}))


def million(args):
    """The 10^6-edge helix (stretched and overwound between clamps) in a fresh process."""
    out = subprocess.run([sys.executable, __file__, "--single", "helix_winding", "1000000", "--no-trace",
                          "--time-budget", str(args.time_budget)] + (["--baseline"] if args.baseline else []),
                         capture_output=True, text=True, env=_child_env(args))
    try:
        r = json.loads(out.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        r = {"problem": "helix_winding", "n": 1000000, "converged": False, "status": "crashed",
             "message": out.stderr.strip()[-300:]}
    if "solve_s" in r:
        other = r["solve_s"] - r.get("assembly_s", 0.0) - r.get("factorisation_s", 0.0) - r.get("line_search_s", 0.0)
        r["other_s"] = other
        print(f"helix_winding n = 10^6: {r['status']} in {r['iterations']} iterations, residual {r['residual']:.2e} "
              f"(tol {r['tol']:.0e}, floor {r['residual_floor']:.1e}), error {r['error']:.2e}")
        print(f"  setup {r['setup_s']:.2f} s; solve {r['solve_s']:.2f} s = assembly {r['assembly_s']:.2f} + "
              f"factorisation {r['factorisation_s']:.2f} + line search {r['line_search_s']:.2f} + other {other:.2f}; "
              f"one dgbsv {r['dgbsv_s']:.3f} s, per iteration {r['per_iteration_ratio_to_dgbsv']:.2f} x dgbsv "
              f"({r['per_iteration_cpu_ratio_to_dgbsv']:.2f} x in CPU time)")
        print(f"  CPU time of the solve: user {r['solve_cpu_user_s']:.2f} s, system {r['solve_cpu_system_s']:.2f} s "
              f"(system time: page faults, the first touch of the band's pages and of temporaries); "
              f"{r['solve_minor_faults']} minor page faults")
        print(f"  set-up: shape + rod + initial state {r['setup_s']:.2f} s ({r['setup_cpu_s']:.2f} s CPU; rod_from_shape "
              f"{r['rod_cpu_s']:.2f} s CPU), der.solve's preparation {r['presolve_s']:.2f} s ({r['presolve_cpu_s']:.2f} s "
              f"CPU), to the first iteration {r['setup_to_first_iteration_s']:.2f} s "
              f"({r['setup_to_first_iteration_cpu_s']:.2f} s CPU)")
        print(f"  peak RSS {r['peak_rss_mb']:.0f} MB (growth over the compiled process {r['rss_growth_mb']:.0f} MB, "
              f"{r['rss_per_edge_kb']:.2f} kB per edge)")
    else:
        print(f"helix_winding n = 10^6: {r['status']}: {r['message']}")
    if args.json:
        print(json.dumps(r))


def _plot(rows, path):
    from der.plotting import pyplot

    plt = pyplot("scaling.py")
    if plt is None:
        return
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
    unconverged_shown = False
    for i, problem in enumerate(sorted({r["problem"] for r in rows})):
        pr = [r for r in rows if r["problem"] == problem and "solve_s" in r]
        ns = [r["n"] for r in pr]
        axes[0].loglog(ns, [r["solve_s"] for r in pr], "-", color=f"C{i}", label=f"{problem}: solve")
        axes[0].loglog(ns, [r["s_per_iteration"] for r in pr], "--", color=f"C{i}", label=f"{problem}: per iteration")
        axes[1].loglog(ns, [max(r["traced_peak_mb"], 1e-3) for r in pr], "o-", color=f"C{i}", label=problem)
        # a solve that did not converge (e.g. the n = 1e5 ring at its time budget) is drawn hollow with a cross,
        # not like a converged point: its time is only the time until it stopped
        for r in pr:
            ok = r.get("converged", True)
            for key, marker in (("solve_s", "o"), ("s_per_iteration", "s")):
                axes[0].loglog([r["n"]], [r[key]], marker, color=f"C{i}", mfc=f"C{i}" if ok else "white", ms=6)
                if not ok:
                    axes[0].loglog([r["n"]], [r[key]], "x", color="k", ms=7,
                                   label=None if unconverged_shown else "not converged (stopped: time budget)")
                    unconverged_shown = True
            if not ok:
                axes[0].annotate(f"not converged ({r['status']})", (r["n"], r["solve_s"]), fontsize=7,
                                 xytext=(-8, -2), textcoords="offset points", ha="right", va="top")
    ns = np.array([100, 100000])
    axes[0].loglog(ns, 1e-5 * ns, "k:", lw=0.8, label="~ n")
    axes[0].set(xlabel="edges n", ylabel="seconds", title="implicit solver: time to equilibrium")
    axes[1].set(xlabel="edges n", ylabel="MB (NumPy peak during the solve)", title="memory")
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
