"""Property-based test over the public API (the rule in tests/fuzzing.py): every outcome is a specific
input error from der, a converged solve (at tol, or at the round-off floor and said so), or a ConvergenceError
with a finite residual and last state. Bounded to well under a minute; tools/fuzz.py runs the larger sweep."""
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import der
from fuzzing import HypothesisDraw, classify, random_case


def setup_module():
    der.warmup()


@settings(max_examples=120, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(st.data())
def test_every_outcome_is_honest(data):
    case = random_case(HypothesisDraw(data), p_bad=0.15, max_edges=16)
    outcome, detail, _ = classify(case, budget=0.5, limit=8.0)
    assert outcome != "other", f"{detail}\ncase: {case}"


def test_classifier_catches_a_false_verdict():
    """The classifier itself can fail: a generic numpy error and a silent hang are 'other'."""
    case = {"kind": "straight", "n": 5, "length": 1.0, "axis": (0, 0, 1), "director": (1, 0, 0), "A1": 1.0,
            "A2": 1.0, "EA": None, "loads": [], "constraints": [{"constraint": "clamp", "end": "start"}],
            "perturb": 0.0, "seed": 0, "solver": "implicit", "tol": 1e-8, "max_iterations": 10, "max_steps": 100}
    assert classify(case)[0] == "converged"
    import fuzzing

    original = fuzzing.build

    def generic_failure(c):
        raise ValueError("could not convert string to float: 'x'")

    def hang(c):
        while True:
            pass

    try:
        fuzzing.build = generic_failure
        assert classify(case)[0] == "other"
        fuzzing.build = hang
        assert classify(case, limit=0.5)[0] == "other"
    finally:
        fuzzing.build = original


def test_rings_of_three_and_four_edges_solve_and_are_analysed():
    """Found by `tools/fuzz.py --examples 5000` (12 cases): on a ring of 3 or 4 edges the band is wider than the
    matrix, and the stability analysis's symmetry check sliced past its end (a numpy broadcast error)."""
    for n, EA in ((3, None), (3, 1e4), (4, None)):
        case = {"kind": "ring", "n": n, "radius": 1.0, "A1": 1.0, "A2": 1.0, "EA": EA, "loads": [],
                "constraints": [], "perturb": 0.0, "seed": 0, "solver": "implicit", "tol": 1e-8,
                "max_iterations": 100, "max_steps": 100}
        outcome, detail, _ = classify(case)
        assert outcome in ("converged", "converged_at_floor"), f"n = {n}, EA = {EA}: {outcome} {detail}"
