"""The cosseratbench adapter (der/bench.py) on the contact experiments, at small n (skipped without cosseratbench)."""
import numpy as np
import pytest

pytest.importorskip("cosseratbench")

from der.bench import DerSolver  # noqa: E402


def test_crossing_two_ropes_in_contact_hold_each_other_up():
    from cosseratbench.experiments.crossing import build, lift_error, shape_error

    sc = build(1e6, 0.1)
    tr = DerSolver().run(sc, n_elements=21, n_frames=3)
    assert lift_error(sc, tr) < 0.1             # the contact force carried: without it the error is 1
    assert shape_error(sc, tr) < 5e-3


@pytest.mark.parametrize("overhang, holds", [(0.8, True), (1.5, False)])
def test_capstan_experiment_holds_below_and_slides_above_the_heavy_rope_capstan_limit(overhang, holds):
    from cosseratbench.experiments.capstan import build, slide

    sc = build(overhang, 0.3)
    tr = DerSolver().run(sc, n_elements=50, n_frames=21)
    s = slide(sc, tr)
    assert np.isfinite(s)
    if holds:
        assert s < 2e-3                       # the start settling and creep only (mm)
    else:
        assert s > 0.05                       # it slid off
