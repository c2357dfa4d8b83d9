"""The public API: every name documented (and its examples run), short reprs, the first-solve compilation kept
out of the solve time, and argument errors that name the function, the argument, what it got and what is
allowed -- raised before any work."""
import doctest
import inspect
import sys
import types

import numpy as np
import pytest

import der
import der.constraints
import der.loads
import der.rod
import der.scene
import der.shapes
import der.solvers
import der.solvers.options
from der import diagnostics

warmup_module = sys.modules["der.warmup"]   # der.warmup is the function
rod_module = sys.modules["der.rod"]         # der.rod is the constructor


def _public_functions(module):
    return [(name, obj) for name, obj in vars(module).items()
            if not name.startswith("_") and inspect.isfunction(obj) and obj.__module__ == module.__name__]


def _documented(obj):
    doc = inspect.getdoc(obj) or ""
    return len(doc) > 120 and ("Parameters" in doc or "Example" in doc or "Attributes" in doc)


def test_every_public_name_has_a_docstring():
    missing = []
    for name in der.__all__:
        obj = getattr(der, name)
        if isinstance(obj, types.ModuleType):
            if not _documented(obj):
                missing.append(name)
            missing += [f"{name}.{f}" for f, fn in _public_functions(obj) if not _documented(fn)]
        elif not _documented(obj):
            missing.append(name)
    for cls in (der.Rod, der.RodState):
        for attr, member in vars(cls).items():
            if attr.startswith("_"):
                continue
            target = member.fget if isinstance(member, property) else member
            if callable(target) and not (inspect.getdoc(target) or "").strip():
                missing.append(f"{cls.__name__}.{attr}")
    for fn in (der.Rod.with_natural, der.Rod.displaced, der.Rod.with_stiffness, der.Rod.with_imposed_twist,
               der.Rod.rest_state, der.Rod.start_state):
        if not _documented(fn):
            missing.append(fn.__qualname__)
    assert not missing, f"public names without a docstring of substance: {missing}"


@pytest.mark.parametrize("module", [der, der.loads, der.constraints, der.shapes, der.sections, rod_module, der.scene,
                                    diagnostics,
                                    der.solvers, der.solvers.options, der.dynamics], ids=lambda m: m.__name__)
def test_docstring_examples_run(module):
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0


def test_the_docstrings_say_what_users_asked():
    assert "3-vector" in der.end_torque.__doc__ and "scalar" in der.end_torque.__doc__
    assert "(3, 3)" in der.clamp.__doc__ and "CENTRE" in der.clamp.__doc__   # issue 13: about the end centre
    assert "REST length" in der.distributed_force.__doc__
    assert "half an edge" in der.Rod.__doc__
    assert "REST END FRAME" in diagnostics.end_motion.__doc__


# --------------------------------------------------------------------------------------------- reprs


def _small_solve():
    rod = der.rod_from_shape(der.shapes.helix(kappa0=1.0, omega0=0.6, turns=1, n=40), A1=1.0, A2=1.5)
    scene = der.Scene(rod, loads=[der.end_force([0, 0, 1e-3]), der.end_torque(2e-3, follower=True)],
                      constraints=[der.clamp("start")])
    return rod, der.solve(scene)


def test_short_reprs():
    rod, result = _small_solve()
    text = repr(result)
    assert str(result) == text
    assert len(text.splitlines()) <= 5 and len(text) < 700, text
    assert result.status in text and f"after {result.iterations} iteration" in text
    assert "tol 1e-08" in text and f"{result.residual:.2e}" in text
    assert f"min eigenvalue {result.min_eigenvalue:.4g}" in text
    assert "array" not in text
    assert repr(rod).startswith("Rod(open, n_edges=40, L=")
    assert "A1=1, A2=1.5, EA=None" in repr(rod)
    assert repr(result.state).startswith("RodState(n_edges=40, n_nodes=41")
    assert repr(der.SolverOptions(tol=1e-10)) == "SolverOptions(tol=1e-10)"


def test_repr_of_a_failed_solve_says_so():
    rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.5)
    scene = der.Scene(rod, loads=[der.end_force([1e-2, 0, 0])], constraints=[der.clamp("start")])
    result = der.solve(scene, max_iterations=1, newton_first=False, raise_on_failure=False)
    assert not result.converged
    assert "NOT converged" in repr(result) and "> tol" in repr(result)


# --------------------------------------------------------------------------------------------- compilation


def test_first_solve_compiles_before_its_clock_and_says_so(monkeypatch, capsys):
    der.warmup()
    assert not warmup_module.cache_is_cold()          # everything der runs is in the cache after a warmup
    monkeypatch.setattr(warmup_module, "_DONE", False)
    monkeypatch.setattr(warmup_module, "cache_is_cold", lambda: True)
    rod = der.rod_from_shape(der.shapes.straight(1.0, 10), A1=1.0, A2=1.5)
    scene = der.Scene(rod, loads=[der.end_torque(1e-3, follower=True)], constraints=[der.clamp("start")])
    first = der.solve(scene)
    second = der.solve(scene)
    err = capsys.readouterr().err
    assert err.count("compiling der's kernels (first run only, a few minutes)") == 1
    assert first.compile_time > 0 and second.compile_time == 0.0
    assert "compiling or loading the kernels, not in wall time" in repr(first)


def test_no_message_on_a_warm_cache(monkeypatch, capsys):
    der.warmup()
    monkeypatch.setattr(warmup_module, "_DONE", False)
    der.warmup()
    assert "compiling" not in capsys.readouterr().err


# --------------------------------------------------------------------------------------------- messages


@pytest.fixture
def no_work(monkeypatch):
    """Any solve that gets as far as building its system fails the test: errors must come before work."""
    def refuse(*args, **kwargs):
        raise AssertionError("work started before the argument was refused")
    monkeypatch.setattr(der.solvers, "build_system", refuse)
    monkeypatch.setattr(der.solvers, "_compile_first", lambda: 0.0)


ROD = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.5)

CASES = [
    # (call, exception, every fragment the message must contain)
    (lambda: der.distributed_force(np.zeros((21, 3))), ValueError,
     ["der.distributed_force: density", "single finite 3-vector", "(21, 3)", "der.point_force"]),
    (lambda: der.end_torque(1e-3), ValueError,
     ["der.end_torque", "dead torque", "3-vector", "0.001", "follower=True"]),
    (lambda: der.end_torque([0, 0, 1e-3], follower=True), ValueError,
     ["der.end_torque", "follower torque", "scalar", "[0, 0, 0.001]", "follower=False"]),
    (lambda: der.twisting_moment([0, 0, 1e-3]), ValueError,
     ["der.twisting_moment: density", "single number", "[0, 0, 0.001]"]),
    (lambda: der.shapes.straight(1.0, 10, axis="z"), TypeError,
     ["der.shapes.straight: axis", "3-vector", "(0, 0, 1)", "'z'"]),
    (lambda: der.clamp(rotation="identity"), TypeError,
     ["der.clamp: rotation", "3x3 rotation matrix", "'identity'"]),
    (lambda: der.clamp("end", rotation=2 * np.eye(3)), ValueError,
     ["der.clamp: rotation", "proper 3x3 rotation matrix", "det 8"]),
    (lambda: der.end_force(None), TypeError, ["der.end_force: force", "3-vector", "None"]),
    (lambda: der.pin(None), TypeError, ["der.pin: node", "integer", "None"]),
    (lambda: der.point_force(2.5, [1, 0, 0]), ValueError, ["der.point_force: node", "integer", "2.5", "whole"]),
    (lambda: der.rod_from_shape(der.shapes.straight(1.0, 10), 1.0, 1.0, rho_A="1"), TypeError,
     ["der.rod_from_shape: rho_A", "number > 0", "'1'"]),
    (lambda: der.rod_from_shape(der.shapes.straight(1.0, 10), 1 + 0j, 1.0), TypeError,
     ["der.rod_from_shape: A1", "complex"]),
    (lambda: der.end_force([1j, 0, 0]), TypeError, ["der.end_force: force", "complex"]),
    (lambda: der.end_torque(1e-3j, follower=True), TypeError, ["der.end_torque: torque", "complex"]),
    (lambda: der.shapes.helix(1.0, 0.5 + 0j, 1, 10), TypeError, ["der.shapes.helix: omega0", "complex"]),
    (lambda: der.shapes.helix(1.0, [1, 2], 1, 10), TypeError, ["der.shapes.helix: omega0", "one number", "[1, 2]"]),
    (lambda: der.shapes.ring(1.0, 10.5), ValueError, ["der.shapes.ring: n", "integer", "10.5"]),
    (lambda: ROD.displaced(ROD.rest_state(), np.zeros((5, 3))), ValueError,
     ["Rod.displaced: dx", f"({ROD.n_nodes}, 3)", "(5, 3)"]),
    (lambda: ROD.displaced(ROD.rest_state(), dtheta=np.zeros(3)), ValueError,
     ["Rod.displaced: dtheta", f"({ROD.n_edges},)", "(3,)"]),
    (lambda: ROD.with_natural(kappa_bar=np.zeros((3, 2))), ValueError,
     ["Rod.with_natural: kappa_bar", f"({ROD.n_vertices}, 2)", "(3, 2)"]),
    (lambda: ROD.with_natural(twist_bar="0"), TypeError, ["Rod.with_natural: twist_bar", "'0'"]),
    (lambda: der.end_torque([0, 0, 1], end="tip"), ValueError, ["der.end_torque: end", "'start' or 'end'", "'tip'"]),
    (lambda: der.end_torque(1.0, follower="yes"), TypeError, ["der.end_torque: follower", "True or False"]),
]


@pytest.mark.parametrize("case", range(len(CASES)))
def test_messages_name_the_argument(case):
    call, exc, fragments = CASES[case]
    with pytest.raises(exc) as info:
        call()
    for fragment in fragments:
        assert fragment in str(info.value), (fragment, str(info.value))


def test_whole_valued_indices_are_accepted():
    assert der.point_force(np.int64(3), [1, 0, 0]).node == 3
    assert der.point_force(3.0, [1, 0, 0]).node == 3
    assert der.pin(-1).node == -1
    assert der.clamp("end", slide=np.int32(2)).slide == (2,)


def test_two_pins_on_one_node_with_different_positions_are_refused(no_work):
    with pytest.raises(ValueError, match=r"two pins on node 3 with different positions"):
        der.Scene(ROD, constraints=[der.pin(3, [0, 0, 0.1]), der.pin(3, [0, 0, 0.2])])
    der.Scene(ROD, constraints=[der.pin(3, [0, 0, 0.1]), der.pin(3, [0, 0, 0.1])])   # the same pin twice: fine


def test_profile_refuses_a_state_of_another_rod():
    other = der.rod_from_shape(der.shapes.straight(1.0, 12), A1=1.0, A2=1.5)
    with pytest.raises(ValueError, match=r"der.diagnostics.profile: state does not belong to this rod: it has 12 "
                                         r"edges .* the rod 20 edges"):
        diagnostics.profile(ROD, other.rest_state())
    with pytest.raises(ValueError, match=r"der.diagnostics.end_motion: state does not belong to this rod"):
        diagnostics.end_motion(ROD, other.rest_state())
    with pytest.raises(TypeError, match=r"state must be a der.RodState"):
        diagnostics.profile(ROD, ROD.rest_state().q)


def test_unknown_load_lists_every_load():
    with pytest.raises(ValueError) as info:
        der.Scene(ROD, loads=[("force", [1, 0, 0])])
    for name in ("der.point_force", "der.end_force", "der.distributed_force", "der.end_torque",
                 "der.twisting_moment"):
        assert name in str(info.value)


def test_record_into_a_missing_folder_is_refused_before_the_solve(tmp_path, no_work):
    scene = der.Scene(ROD, constraints=[der.clamp("start")])
    with pytest.raises(ValueError, match=r"der.solve: record: cannot write .*the folder .*missing.* does not exist"):
        der.solve(scene, record=tmp_path / "missing" / "run.rrd")
    with pytest.raises(ValueError, match=r"der.solve: record: .* is a directory"):
        der.solve(scene, record=tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_records_built_by_hand_are_checked_by_the_scene(no_work):
    from der.loads import EndTorque, PointForce

    with pytest.raises(ValueError, match=r"der.point_force: node must be an integer node index; got 2.5"):
        der.Scene(ROD, loads=[PointForce(2.5, (1.0, 0.0, 0.0))])
    with pytest.raises(TypeError, match=r"der.end_torque: torque .* must be a finite real number; got 'x'"):
        der.Scene(ROD, loads=[EndTorque("end", "x", True)])


def test_solve_and_check_stability_refuse_what_is_not_theirs(no_work):
    with pytest.raises(TypeError, match=r"der.solve: scene must be a der.Scene .*got Rod"):
        der.solve(ROD)
    other = der.rod_from_shape(der.shapes.straight(1.0, 12), A1=1.0, A2=1.5)
    with pytest.raises(ValueError, match=r"der.check_stability: state does not belong to this rod"):
        der.check_stability(der.Scene(ROD), other.rest_state())
