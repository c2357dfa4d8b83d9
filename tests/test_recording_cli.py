"""Rerun recordings (read back, verified, flushed on failure) and the scenario command-line contract."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import der
import der.solvers.implicit as implicit_module

ROOT = Path(__file__).resolve().parents[1]
RERUN = Path(sys.executable).parent / "rerun"
# the subprocesses import this checkout's der, not whichever one is installed
ENV = dict(os.environ, RERUN_ANALYTICS="0", PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))


def verify(path):
    out = subprocess.run([str(RERUN), "rrd", "verify", str(path)], capture_output=True, text=True, env=ENV)
    return out.returncode == 0, out.stdout + out.stderr


def helix_scene():
    rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, 1.5, 40), 1.0, 1.5)
    return der.Scene(rod, loads=[der.end_force([0, 0, 0.1]), der.end_torque(0.05, follower=True)],
                     constraints=[der.clamp("start")])


def test_recording_reads_back_the_returned_state(tmp_path):
    from der.recording import read_centrelines

    path = tmp_path / "run.rrd"
    res = der.solve(helix_scene(), record=path)
    its, centrelines = read_centrelines(path)
    assert len(its) >= 2 and its == sorted(set(its))   # frames beyond the recording's time budget are skipped
    x = res.state.positions
    # rerun stores float32
    assert np.abs(centrelines[-1] - x).max() <= 2e-7 * np.abs(x).max()
    assert np.abs(centrelines[0] - x).max() > 1e-3   # the first logged step is not the last
    ok, msg = verify(path)
    assert ok, msg


def test_recording_of_a_ring(tmp_path):
    from der.recording import read_centrelines

    rod = der.rod_from_shape(der.shapes.ring(1.0, 20), 1.0, 1.0)
    res = der.solve(der.Scene(rod, loads=[der.twisting_moment(0.3)]), record=tmp_path / "ring.rrd")
    _, centrelines = read_centrelines(tmp_path / "ring.rrd")
    assert centrelines[-1].shape == res.state.positions.shape


def test_recording_is_flushed_when_the_solve_raises(tmp_path, monkeypatch):
    original = implicit_module.evaluate_system
    calls = {"n": 0}

    def failing(system, state, order):
        calls["n"] += 1
        if calls["n"] == 6:
            raise RuntimeError("boom")
        return original(system, state, order)

    monkeypatch.setattr(implicit_module, "evaluate_system", failing)
    path = tmp_path / "crash.rrd"
    with pytest.raises(RuntimeError, match="boom"):
        der.solve(helix_scene(), record=path)
    ok, msg = verify(path)
    assert ok, msg


def interrupt_evaluation(monkeypatch, at):
    """Make the implicit solver's ``at``-th force evaluation raise KeyboardInterrupt (a Ctrl-C inside a solve);
    returns the call counter ``{"n": calls so far}``. The kernels are compiled first: a Ctrl-C in the warm-up's
    own solves ends the warm-up (test_ctrl_c_during_the_warmup_reaches_the_caller), not the solve under test."""
    der.warmup()
    original = implicit_module.evaluate_system
    calls = {"n": 0}

    def interrupted(system, state, order):
        calls["n"] += 1
        if calls["n"] == at:
            raise KeyboardInterrupt
        return original(system, state, order)

    monkeypatch.setattr(implicit_module, "evaluate_system", interrupted)
    return calls


def test_keyboard_interrupt_keeps_the_state_and_a_valid_recording(tmp_path, monkeypatch):
    interrupt_evaluation(monkeypatch, at=6)
    path = tmp_path / "ctrlc.rrd"
    with pytest.raises(der.ConvergenceError) as info:
        der.solve(helix_scene(), record=path)
    assert info.value.result.status == "interrupted"
    assert np.isfinite(info.value.result.state.q).all()
    ok, msg = verify(path)
    assert ok, msg


def test_ctrl_c_during_the_warmup_reaches_the_caller(monkeypatch):
    # The first solve of a process compiles der's kernels by running small solves (der.warmup); each of them
    # answers Ctrl-C with an "interrupted" result, which the warm-up took for a finished solve: a Ctrl-C while a
    # fresh clone compiled (a minute or more) was lost and the user's solve then ran to its end.
    warmup_module = sys.modules["der.warmup"]     # (der.warmup is the function)

    def interrupted(system, state, order):
        raise KeyboardInterrupt

    monkeypatch.setattr(warmup_module, "_DONE", False)
    monkeypatch.setattr(implicit_module, "evaluate_system", interrupted)
    with pytest.raises(KeyboardInterrupt):
        der.warmup()
    assert not warmup_module.is_done()       # the next solve warms up again


def test_a_scenario_stops_at_the_first_interrupted_solve(monkeypatch, capsys, tmp_path):
    # Ctrl-C in one solve of a scenario (here the first of several) ends the scenario: exit 3, status
    # "interrupted", the recording valid; no further solve starts
    from der.cli import scenario_main

    def run(p, solver):
        for _ in range(3):
            solver.solve(helix_scene())
        return {"error": 0.0, "reference": "none"}

    calls = interrupt_evaluation(monkeypatch, at=4)
    path = tmp_path / "several.rrd"
    code = scenario_main("fake", "a fake scenario", [("x", 1.0, float, "x")], run,
                         argv=["--n", "10", "--json", "--rrd", str(path)])
    out, err = capsys.readouterr()
    record = json.loads(out.strip().splitlines()[-1])
    assert code == 3 and record["status"] == "interrupted" and record["iterations"] < 50, (record, err)
    assert calls["n"] < 20                    # the two solves after the interrupted one did not run
    ok, msg = verify(path)
    assert ok, msg


def test_ctrl_c_while_the_kernels_compile_exits_3_without_a_recording(monkeypatch, capsys, tmp_path):
    import der.cli as cli

    def compiling():
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "warmup", compiling)
    path = tmp_path / "never.rrd"
    code = cli.scenario_main("fake", "a fake scenario", [("x", 1.0, float, "x")],
                             lambda p, solver: pytest.fail("no solve may start"),
                             argv=["--n", "10", "--json", "--rrd", str(path)])
    out, err = capsys.readouterr()
    record = json.loads(out.strip().splitlines()[-1])
    assert code == 3 and record["status"] == "interrupted" and record["rrd"] is None
    assert len(err.strip().splitlines()) == 1 and "while der's kernels compiled" in err, err


def run_scenario(*args, timeout=600):
    return subprocess.run([sys.executable, str(ROOT / "scenarios" / "straight_twist.py"), *args],
                          capture_output=True, text=True, timeout=timeout, env=ENV)


def test_scenario_json_contract(tmp_path):
    out = run_scenario("--json", "--rrd", str(tmp_path / "t.rrd"))
    assert out.returncode == 0, out.stderr
    record = json.loads(out.stdout.strip().splitlines()[-1])
    for key in ("scenario", "params", "n", "solver", "converged", "residual", "iterations", "runtime_s", "compile_s",
                "error", "reference", "end_twist"):
        assert key in record
    assert record["params"] == {"L": 1.0, "A1": 1.0, "A2": 1.5, "T": 0.5}
    assert record["converged"] is True and record["error"] < 1e-8
    ok, msg = verify(tmp_path / "t.rrd")
    assert ok, msg


def test_perversion_scenario_json_contract_and_recording(tmp_path):
    """Issue 13's new scenario: the JSON contract (error, converged, reactions) and a valid rerun recording."""
    out = subprocess.run([sys.executable, str(ROOT / "scenarios" / "perversion.py"), "--json", "--n", "41", "--rrd",
                          str(tmp_path / "p.rrd")], capture_output=True, text=True, timeout=600, env=ENV)
    assert out.returncode == 0, out.stderr
    record = json.loads(out.stdout.strip().splitlines()[-1])
    assert record["converged"] is True and record["error"] < 5e-4
    assert record["params"] == {"L": 2.0, "kappa0": 1.5, "A1": 1.0, "A2": 1.0, "P": 1.0, "EA": None}
    assert [r["end"] for r in record["reactions"]] == ["start", "end"]
    assert abs(sum(r["force"][0] for r in record["reactions"])) < 1e-8      # the transverse reactions balance
    ok, msg = verify(tmp_path / "p.rrd")
    assert ok, msg


def test_scenario_invalid_input_exits_2_with_one_line():
    out = run_scenario("--n", "0")
    assert out.returncode == 2
    assert out.stdout == ""
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "--n must be an integer from 2 to 1,000,000" in lines[0]
    out = run_scenario("--A2", "-1")
    assert out.returncode == 2 and "--A2 must be in [1e-06, 1e+06]" in out.stderr


def test_scenario_not_converged_exits_3_with_json():
    # the straight rod is linear (one Newton step); the ring's inextensibility needs multiplier updates
    out = subprocess.run([sys.executable, str(ROOT / "scenarios" / "ring_torsion.py"), "--json", "--n", "40",
                          "--max-iterations", "1"], capture_output=True, text=True, timeout=600, env=ENV)
    assert out.returncode == 3
    record = json.loads(out.stdout.strip().splitlines()[-1])
    assert record["converged"] is False and record["status"] == "max_iterations"


def test_ctrl_c_leaves_a_valid_recording(tmp_path):
    path = tmp_path / "sigint.rrd"
    # the child takes Ctrl-C as a terminal would deliver it, whatever this process inherited: a test run started
    # in the background of a non-interactive shell (`bash .ci/run &`) ignores SIGINT, its children inherit the
    # ignore, and Python then installs no KeyboardInterrupt (the solve ran to its end and exited 0)
    proc = subprocess.Popen([sys.executable, str(ROOT / "scenarios" / "straight_twist.py"), "--solver", "explicit",
                             "--n", "3000", "--tol", "1e-12", "--rrd", str(path), "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    # interrupt once the solver reports progress (a line per second on stderr), i.e. inside the solve. Not
    # before: a Ctrl-C while a fresh clone compiles (der.warmup, minutes on a busy machine) ends the run before
    # any recording exists (test_ctrl_c_while_the_kernels_compile_exits_3_without_a_recording); this test's old
    # 120 s wait ran out there, and the warm-up swallowed the Ctrl-C (test_ctrl_c_during_the_warmup_reaches_the_caller)
    deadline = time.time() + 900
    lines = []
    while time.time() < deadline and not (lines and "iteration" in lines[-1]):
        lines.append(proc.stderr.readline())
        if not lines[-1] and proc.poll() is not None:
            break
    assert proc.poll() is None and "iteration" in lines[-1], f"no progress line to interrupt: {lines[-5:]}"
    proc.send_signal(signal.SIGINT)
    stdout, err = proc.communicate(timeout=120)
    assert proc.returncode == 3, (proc.returncode, err)
    record = json.loads(stdout.strip().splitlines()[-1])
    assert record["status"] == "interrupted"
    ok, msg = verify(path)
    assert ok, msg


# --- the scenario contract, case by case (issue 12): exit code and ONE line on stderr ------------------------

def run_many(cases, timeout=600):
    """Run ``(script, args)`` subprocesses two at a time (the machine's cores); returns CompletedProcess-likes."""
    procs, done = [], []
    for script, args in cases:
        procs.append(subprocess.Popen([sys.executable, str(ROOT / "scenarios" / script), *args], env=ENV,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
        if len(procs) - len(done) >= 2:
            done.append(procs[len(done)].communicate(timeout=timeout))
    while len(done) < len(procs):
        done.append(procs[len(done)].communicate(timeout=timeout))
    return [(p.returncode, out, err) for p, (out, err) in zip(procs, done)]


INVALID = [
    (("straight_twist.py", ["--rrd", "{tmp}"]), "--rrd: {tmp} is a directory"),
    (("straight_twist.py", ["--rrd", "/proc/der_test.rrd"]), "--rrd: cannot write /proc/der_test.rrd"),
    (("straight_twist.py", ["--n", "100000000"]), "--n must be an integer from 2 to 1,000,000"),
    (("loop_twist.py", ["--a0", "1e300"]), "--a0 must be in [1e-06, 1e+06]"),
    (("helix_torque.py", ["--omega0", "1e300"]), "--omega0 must be in [-100, 100], non-zero"),
    (("ring_torsion.py", ["--T", "1e300"]), "--T must be in [-1, 1], non-zero"),
    (("helix_winding.py", ["--A", "1e300"]), "--A1 must be in [0.001, 1000]"),
    (("helix_winding.py", ["--P0", "1e300"]), "--P0 must be in [-100, 100]"),
    (("straight_twist.py", ["--L", "1e300"]), "--L must be in [1e-06, 1e+06]"),
    (("helix_winding.py", ["--phi", "1e300"]), "--phi must be in (-1, 1]"),
    (("ring_torsion.py", ["--symmetric", "2"]), "--symmetric is a flag"),
    (("loop_twist.py", ["--locate", "3"]), "--locate is a flag"),
    (("ring_torsion.py", ["--time-budget", "0"]), "--time-budget must be > 0"),
    (("perversion.py", ["--kappa0", "100"]), "--kappa0 must be in (0, 3]"),
    (("perversion.py", ["--P", "-1"]), "--P must be in [0, 5]"),
    (("reproduce_paper.py", ["--n", "0"]), "--n must be an integer from 2 to 1,000,000"),
    (("reproduce_paper.py", ["--n", "1"]), "--n must be an integer from 2 to 1,000,000"),
    (("reproduce_paper.py", ["--rrd", "/proc/der_test_dir"]), "--rrd: cannot write into /proc/der_test_dir"),
]


# Runs each case as ``python scenarios/<script> args`` would (runpy, __main__), all in ONE subprocess: a process
# per case would spend ~1.5 s each importing numba and scipy
BATCH = """
import contextlib, io, json, runpy, sys, traceback
out = []
for script, args in json.loads(sys.argv[1]):
    sys.argv = [script, *args]
    o, e = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(o), contextlib.redirect_stderr(e):
        try:
            runpy.run_path(script, run_name="__main__")
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
        except Exception:
            traceback.print_exc()   # the contract's failure mode before issue 12: a traceback, exit 1
            code = 1
    out.append((code, o.getvalue(), e.getvalue()))
print(json.dumps(out))
"""


def run_batch(cases):
    arg = json.dumps([(str(ROOT / "scenarios" / script), args) for script, args in cases])
    done = subprocess.run([sys.executable, "-c", BATCH, arg], capture_output=True, text=True, env=ENV, timeout=600)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_invalid_input_exits_2_with_one_line_naming_the_argument(tmp_path):
    cases = [(script, [a.replace("{tmp}", str(tmp_path)) for a in args]) for (script, args), _ in INVALID]
    for (case, expected), (code, out, err) in zip(INVALID, run_batch(cases)):
        lines = err.strip().splitlines()
        assert code == 2, (case, code, err)
        assert len(lines) == 1 and "invalid input: " in lines[0], (case, err)
        assert expected.replace("{tmp}", str(tmp_path)) in lines[0], (case, lines[0])
        assert out == "" or case[0] == "reproduce_paper.py", (case, out)
    assert list(tmp_path.iterdir()) == []    # nothing written


def test_failures_exit_3_with_the_reason_on_one_line():
    cases = [
        # the ring passes through itself: the scenario's own check (Lk conserved) fails
        ("twisted_ring.py", ["--twist", "6.2831853", "--sweep", "40", "--n", "100", "--json"]),
        # the explicit solver at its step limit: the reason, and the implicit solver suggested
        ("straight_twist.py", ["--solver", "explicit", "--n", "200", "--max-iterations", "1", "--json"]),
        # a time budget used up
        ("ring_torsion.py", ["--n", "40", "--time-budget", "1e-9", "--json"]),
    ]
    (c1, o1, e1), (c2, o2, e2), (c3, o3, e3) = run_many(cases)
    for code, err in ((c1, e1), (c2, e2), (c3, e3)):
        assert code == 3 and len(err.strip().splitlines()) == 1, err
    rec = json.loads(o1.strip().splitlines()[-1])
    assert e1.startswith("twisted_ring.py: check failed: the ring passed through itself")
    assert rec["check_passed"] is False and rec["strand_passage_at"] == pytest.approx(6.2831853)
    # the values used are recorded, not null
    assert rec["params"]["kappa0"] == 1.0 and rec["params"]["twist"] == 6.2831853 and rec["params"]["locate"] is True
    assert "not converged: max_iterations" in e2 and "try --solver implicit" in e2
    assert "not converged: time_budget" in e3
    assert json.loads(o3.strip().splitlines()[-1])["status"] == "time_budget"


def test_deprecated_forms_still_work_with_a_note():
    cases = [("ring_torsion.py", ["--n", "20", "--symmetric", "1", "--json"]),
             ("helix_winding.py", ["--n", "24", "--A", "0.5", "--json"])]
    (c1, o1, e1), (c2, o2, e2) = run_many(cases)
    assert c1 == 0 and e1.strip() == "ring_torsion.py: note: '--symmetric 1' is deprecated, use --symmetric"
    assert json.loads(o1.strip().splitlines()[-1])["params"]["symmetric"] is True
    assert c2 == 0 and e2.strip() == "helix_winding.py: note: --A is deprecated, use --A1"
    assert json.loads(o2.strip().splitlines()[-1])["params"]["A1"] == 0.5


def _load(name):
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, ROOT / "scenarios" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_memory_and_numerical_failures_exit_3_with_one_line(capsys):
    from der.cli import scenario_main

    def out_of_memory(p, solver):
        np.empty(1)   # a real allocation path is not needed: numpy's _ArrayMemoryError is a MemoryError
        raise MemoryError("Unable to allocate 74.5 GiB for an array with shape (100000001, 100)")

    def arpack(p, solver):
        from scipy.sparse.linalg import ArpackError
        raise ArpackError(-9999)

    def overflow(p, solver):
        raise OverflowError("math range error")

    for run, expected in ((out_of_memory, "failed: out of memory at n = 10"), (arpack, "numerical failure: ArpackError"),
                          (overflow, "numerical failure: OverflowError: math range error")):
        code = scenario_main("fake", "a fake scenario", [("x", 1.0, float, "x")], run, argv=["--n", "10"])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 3 and len(err) == 1 and expected in err[0], (run.__name__, err)


def test_missing_matplotlib_exits_2_before_any_work(monkeypatch, capsys, tmp_path):
    import der.plotting

    monkeypatch.setattr(der.plotting, "have_matplotlib", lambda: False)
    mod = _load("helix_winding")
    from der.cli import scenario_main

    code = scenario_main("helix_winding", "", mod.PARAMETERS, mod.run,
                         argv=["--figure", "1", "--png", str(tmp_path / "f.png")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--png needs matplotlib" in err[0] and "[plot]" in err[0]
    assert not (tmp_path / "f.png").exists()


def test_twisted_ring_records_the_defaults_it_used():
    mod = _load("twisted_ring")
    p = argparse_namespace(mod, n=20)
    mod.run.resolve(p)
    assert p.kappa0 == 1.0 and p.twist == pytest.approx(1.5 * np.pi)
    p = argparse_namespace(mod, n=20, kappa0=0.0)
    mod.run.resolve(p)
    from der import closed_forms as cf
    assert p.twist == pytest.approx(1.5 * cf.michell_twist(1.0, 1 / 0.67))


def argparse_namespace(mod, **kw):
    import argparse

    return argparse.Namespace(**{**{q[0]: q[1] for q in mod.PARAMETERS}, **kw})


def test_recording_one_row_per_iteration_log10_residual_and_blueprint(tmp_path):
    """A ring's solve reports some iterations twice (multiplier updates of the inextensible rod): one row each."""
    from der.recording import Recorder, read_scalars

    rod = der.rod_from_shape(der.shapes.ring(1.0, 20), 1.0, 1.0)
    path = tmp_path / "ring.rrd"
    res = der.solve(der.Scene(rod, loads=[der.twisting_moment(0.3)]),
                    record=Recorder(path, rod, max_overhead=None))
    its, log_res = read_scalars(path, "residual/log10")
    assert its == list(range(res.iterations + 1))
    assert log_res[-1] == pytest.approx(np.log10(res.residual), abs=1e-6)
    assert read_scalars(path, "residual")[0] == []     # the old name, which did not say log10, is gone
    its_lk, _ = read_scalars(path, "ring/linking_number")
    assert its_lk == its
    printed = subprocess.run([str(RERUN), "rrd", "print", str(path)], capture_output=True, text=True, env=ENV)
    assert "Blueprint" in printed.stdout + printed.stderr


class _TickingClock:
    """A stand-in for ``time`` in der.recording whose perf_counter advances by one tick per call, so that the
    recorder's budget decisions are the same on a quiet and a loaded machine (no timing in a test)."""

    def __init__(self, tick):
        self.now, self.tick = 0.0, tick

    def perf_counter(self):
        self.now += self.tick
        return self.now


def test_recording_overhead_is_bounded(tmp_path, monkeypatch):
    """By default a frame is skipped when the recording's own time would pass its budget: a solve of many
    iterations on a 400-edge ring writes fewer frames than iterations, the first and last always, and the time
    spent on frames after the first stays within the budget (40 % of max_overhead of the elapsed time, or the
    minimal budget) plus the final frame and its writhe. The recorder's clock ticks once per call."""
    import der.recording
    from der.recording import MIN_BUDGET_SECONDS, Recorder, read_centrelines

    clock = _TickingClock(MIN_BUDGET_SECONDS / 4)
    monkeypatch.setattr(der.recording, "time", clock)
    n = 400
    rod = der.rod_from_shape(der.shapes.ring(1.0, n), 1.0, 1 / 0.67).with_imposed_twist(1.5 * np.pi)
    start = rod.displaced(rod.rest_state(), None, 1.5 * np.pi * np.arange(n) / n)
    rec = Recorder(tmp_path / "r.rrd", rod)
    res = der.solve(der.Scene(rod), state=start, record=rec, stability=False, raise_on_failure=False,
                    max_iterations=40)
    rec.close()
    its, _ = read_centrelines(tmp_path / "r.rrd")
    assert its[0] == 0 and its[-1] == res.iterations and its == sorted(set(its))
    assert rec.skipped > 0 and len(its) < res.iterations + 1
    budget = max(0.4 * rec.max_overhead * (clock.now - rec.t_start), MIN_BUDGET_SECONDS)
    assert rec.spent <= budget + rec.frame_cost + rec.spent_per_writhe()


def test_killed_run_recovers_with_the_documented_command(tmp_path):
    """SIGKILL loses the footer; `rerun rrd merge killed.rrd > fixed.rrd` (README, Recordings) restores a file
    that verifies, with the frames written before the kill."""
    path = tmp_path / "killed.rrd"
    proc = subprocess.Popen([sys.executable, str(ROOT / "scenarios" / "straight_twist.py"), "--solver", "explicit",
                             "--n", "3000", "--tol", "1e-12", "--rrd", str(path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    deadline, seen = time.time() + 120, 0
    while time.time() < deadline and seen < 2:     # two progress lines: a second of frames flushed
        line = proc.stderr.readline()
        if not line and proc.poll() is not None:
            break
        seen += "iteration" in line
    assert proc.poll() is None, "the solve ended before it could be killed"
    time.sleep(1.5)
    proc.kill()
    proc.communicate(timeout=60)
    ok, msg = verify(path)
    assert not ok and "footer" in msg.lower()
    fixed = tmp_path / "fixed.rrd"
    with open(fixed, "wb") as fh:
        subprocess.run([str(RERUN), "rrd", "merge", str(path)], stdout=fh, stderr=subprocess.DEVNULL, env=ENV,
                       check=True)
    ok, msg = verify(fixed)
    assert ok, msg
    from der.recording import read_centrelines
    its, _ = read_centrelines(fixed)
    assert len(its) >= 2


def test_a_continuation_records_the_linking_number_of_the_rod_being_solved(tmp_path):
    """twisted_ring's sweep solves a new rod (its weld's twist) at each step into ONE recording: each solve's last
    row carries that step's Lk = twist / 2 pi (it showed the first step's rod throughout)."""
    import argparse

    from der.cli import SolveRunner
    from der.recording import read_scalars

    mod = _load("twisted_ring")
    p = argparse.Namespace(**{**{q[0]: q[1] for q in mod.PARAMETERS}, "n": 30, "sweep": 3, "twist": 3.0,
                              "solver": "implicit", "tol": 1e-8, "rrd": str(tmp_path / "c.rrd"),
                              "max_iterations": None, "time_budget": None})
    mod.run.validate(p)
    runner = SolveRunner(p)
    out = mod.run(p, runner)
    runner.close()
    its, lk = read_scalars(p.rrd, "ring/linking_number")
    ends = np.cumsum([r.iterations + 1 for r in runner.results]) - 1
    got = {it: v for it, v in zip(its, lk)}
    assert [round(got[e], 9) for e in ends] == [round(t / (2 * np.pi), 9) for t in (1.0, 2.0, 3.0)]
    assert out["lk_error_max"] < 1e-9
