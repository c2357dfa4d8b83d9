"""Bad input is refused before any work, with a ValueError that names the value and what is allowed."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import der
from der.shapes import Shape


def test_too_few_edges():
    with pytest.raises(ValueError, match=r"at least 2 edges; got 1"):
        der.rod_from_shape(Shape(np.array([[0, 0, 0], [1, 0, 0.0]])), 1.0, 1.0)
    with pytest.raises(ValueError, match=r"closed ring needs at least 3 edges; got 2"):
        der.rod_from_shape(Shape(np.array([[0, 0, 0], [1, 0, 0.0]]), closed=True), 1.0, 1.0)
    with pytest.raises(ValueError, match=r"n \(number of edges\) must be an integer >= 3; got 2"):
        der.shapes.ring(1.0, 2)


def test_non_finite_and_coincident_positions():
    x = der.shapes.helix(1.0, 0.5, 1.0, 10).positions.copy()
    x[4, 1] = np.nan
    with pytest.raises(ValueError, match=r"positions must be finite; node 4"):
        der.rod_from_shape(Shape(x), 1.0, 1.0)
    x = der.shapes.helix(1.0, 0.5, 1.0, 10).positions.copy()
    x[5] = x[4]
    with pytest.raises(ValueError, match=r"coincident nodes: edge 4"):
        der.rod_from_shape(Shape(x), 1.0, 1.0)
    ring = der.shapes.ring(1.0, 6).positions
    with pytest.raises(ValueError, match=r"do not repeat the first node"):
        der.rod_from_shape(Shape(np.vstack([ring, ring[:1]]), closed=True), 1.0, 1.0)


def test_folding_back_is_refused():
    x = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 0.0 + 1e-12], [0, 1, 0]], float)
    with pytest.raises(ValueError, match=r"folds back onto itself at node 1"):
        der.rod_from_shape(Shape(x), 1.0, 1.0)


@pytest.mark.parametrize("kw,msg", [
    ({"A1": 0.0}, r"A1 must be a finite number > 0.*got 0.0"),
    ({"A2": -1.0}, r"A2 must be a finite number > 0.*got -1.0"),
    ({"A1": np.inf}, r"A1 must be a finite number > 0"),
    ({"EA": 0.0}, r"EA must be None \(inextensible\) or a finite number > 0; got 0.0"),
])
def test_non_positive_stiffness(kw, msg):
    args = {"A1": 1.0, "A2": 1.0, "EA": None}
    args.update(kw)
    with pytest.raises(ValueError, match=msg):
        der.rod_from_shape(der.shapes.straight(1.0, 4), args["A1"], args["A2"], EA=args["EA"])


def test_array_sizes_that_do_not_match():
    with pytest.raises(ValueError, match=r"positions must have shape \(n_nodes, 3\); got \(5, 2\)"):
        der.rod_from_shape(Shape(np.zeros((5, 2))), 1.0, 1.0)
    with pytest.raises(ValueError, match=r"director must be a finite 3-vector or have shape \(4, 3\)"):
        der.rod_from_shape(Shape(der.shapes.straight(1.0, 4).positions, director=np.ones((3, 3))), 1.0, 1.0)
    rod = der.rod_from_shape(der.shapes.straight(1.0, 4), 1.0, 1.0)
    other = der.rod_from_shape(der.shapes.straight(1.0, 6), 1.0, 1.0)
    with pytest.raises(ValueError, match=r"state does not belong to this rod"):
        der.solve(der.Scene(rod), state=other.rest_state())


def test_bad_loads_constraints_and_options():
    rod = der.rod_from_shape(der.shapes.straight(1.0, 4), 1.0, 1.0)
    with pytest.raises(ValueError, match=r"point force on node 9: out of range for 5 nodes"):
        der.Scene(rod, loads=[der.point_force(9, [1, 0, 0])])
    with pytest.raises(ValueError, match=r"dead end torque must be a finite 3-vector"):
        der.Scene(rod, loads=[der.end_torque([1, 0, np.nan])])
    with pytest.raises(ValueError, match=r"end must be 'start' or 'end'; got 'middle'"):
        der.Scene(rod, constraints=[der.clamp("middle")])
    # (issue 13: a clamp may slide along any direction, not only along its end tangent)
    with pytest.raises(ValueError, match=r"der.clamp: slide must be a non-zero direction 3-vector"):
        der.Scene(rod, constraints=[der.clamp("end", slide=(0, 0, 0))])
    with pytest.raises(ValueError, match=r"clamp slide must name at most one coordinate axis"):
        der.Scene(rod, constraints=[der.clamp("end", slide=3)])
    with pytest.raises(ValueError, match=r"unknown energy term 'shear'"):
        der.Scene(rod, energies=("bend", "shear"))
    with pytest.raises(ValueError, match=r"SolverOptions.tol must be a number > 0; got -1"):
        der.SolverOptions(tol=-1)
    with pytest.raises(ValueError, match=r"solver must be one of"):
        der.solve(der.Scene(rod), solver="magic")
    ring = der.rod_from_shape(der.shapes.ring(1.0, 5), 1.0, 1.0)
    with pytest.raises(ValueError, match=r"closed ring has no ends"):
        der.Scene(ring, constraints=[der.clamp("start")])


@settings(max_examples=40, deadline=None)
@given(n=st.integers(min_value=-5, max_value=1), closed=st.booleans())
def test_property_too_few_nodes(n, closed):
    n_nodes = max(n, 0) + 1
    x = np.cumsum(np.ones((n_nodes, 3)), axis=0)
    with pytest.raises(ValueError, match=r"needs at least"):
        der.rod_from_shape(Shape(x, closed=closed), 1.0, 1.0)


@settings(max_examples=60, deadline=None)
@given(bad=st.sampled_from([0.0, -1.0, -1e-300, np.nan, np.inf, -np.inf]),
       which=st.sampled_from(["A1", "A2", "EA"]))
def test_property_bad_stiffness(bad, which):
    args = {"A1": 1.0, "A2": 1.0, "EA": None}
    args[which] = bad
    with pytest.raises(ValueError, match=which):
        der.rod_from_shape(der.shapes.helix(1.0, 0.3, 1.0, 5), args["A1"], args["A2"], EA=args["EA"])


@settings(max_examples=60, deadline=None)
@given(node=st.integers(min_value=0, max_value=6), coord=st.integers(min_value=0, max_value=2),
       bad=st.sampled_from([np.nan, np.inf, -np.inf]))
def test_property_non_finite_positions(node, coord, bad):
    x = der.shapes.helix(1.0, 0.3, 1.0, 6).positions.copy()
    x[node, coord] = bad
    with pytest.raises(ValueError, match=rf"node {node}"):
        der.rod_from_shape(Shape(x), 1.0, 1.0)


@settings(max_examples=40, deadline=None)
@given(node=st.integers(min_value=0, max_value=5))
def test_property_coincident_neighbours(node):
    x = der.shapes.helix(1.0, 0.3, 1.0, 6).positions.copy()
    x[node + 1] = x[node]
    with pytest.raises(ValueError, match=rf"coincident nodes: edge {node}"):
        der.rod_from_shape(Shape(x), 1.0, 1.0)
