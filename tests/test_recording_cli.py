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
    assert len(its) >= 3 and its == sorted(its)
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


def test_keyboard_interrupt_keeps_the_state_and_a_valid_recording(tmp_path, monkeypatch):
    original = implicit_module.evaluate_system
    calls = {"n": 0}

    def interrupted(system, state, order):
        calls["n"] += 1
        if calls["n"] == 6:
            raise KeyboardInterrupt
        return original(system, state, order)

    monkeypatch.setattr(implicit_module, "evaluate_system", interrupted)
    path = tmp_path / "ctrlc.rrd"
    with pytest.raises(der.ConvergenceError) as info:
        der.solve(helix_scene(), record=path)
    assert info.value.result.status == "interrupted"
    assert np.isfinite(info.value.result.state.q).all()
    ok, msg = verify(path)
    assert ok, msg


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
    proc = subprocess.Popen([sys.executable, str(ROOT / "scenarios" / "straight_twist.py"), "--solver", "explicit",
                             "--n", "3000", "--tol", "1e-12", "--rrd", str(path), "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    # interrupt once the solver reports progress (a line per second on stderr), i.e. inside the solve
    deadline = time.time() + 120
    line = ""
    while time.time() < deadline and "iteration" not in line:
        line = proc.stderr.readline()
        if not line and proc.poll() is not None:
            break
    assert proc.poll() is None, "the solve ended before it could be interrupted"
    proc.send_signal(signal.SIGINT)
    stdout, _ = proc.communicate(timeout=120)
    assert proc.returncode == 3
    record = json.loads(stdout.strip().splitlines()[-1])
    assert record["status"] == "interrupted"
    ok, msg = verify(path)
    assert ok, msg
