"""Fast paths for large rods (issue 17) against the per-vertex reference construction they replace."""
import numpy as np
import pytest

import der
from der.energies.bend import material_curvatures
from der.geometry import curvature_binormal, edge_frames, reference_twist_angle, tangents

SHAPES = {
    "helix": lambda: der.shapes.helix(1.0, 0.6, 3, 301),
    "straight": lambda: der.shapes.straight(2.0, 57, axis=(1, 0, 0), director=(0, 0, 1)),
    "ring": lambda: der.shapes.ring(1.0, 97),
    "arc": lambda: der.shapes.arc(1.0, 3.0, 88),
}


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_rod_from_shape_equals_per_vertex_reference(name):
    """rest twist, natural curvatures and tangents from the batch kernels are bitwise those of the per-vertex
    kernels (the Python loops rod_from_shape used before)."""
    rod = der.rod_from_shape(SHAPES[name](), 1.0, 1.5)
    q, d1 = rod.rest_q, rod.rest_d1
    t = np.array([(q[4 * b:4 * b + 3] - q[4 * a:4 * a + 3]) / np.linalg.norm(q[4 * b:4 * b + 3] - q[4 * a:4 * a + 3])
                  for a, b in rod.edge_nodes])
    assert np.array_equal(tangents(q, rod.edge_nodes), t)
    twist = np.array([reference_twist_angle(t[a], d1[a], t[b], d1[b]) for a, b in rod.vertex_edges])
    assert np.array_equal(rod.rest_twist, twist)
    assert np.array_equal(rod.twist_bar, twist)
    ed = edge_frames(q, rod.edge_nodes, d1)
    weld = np.zeros(rod.n_vertices)
    kb_edges = np.array([material_curvatures(ed, rod.vertex_edges, weld, v)
                         for v in range(rod.n_vertices)]).reshape(-1, 2, 2)
    assert np.array_equal(rod.kappa_bar_edges, kb_edges)
    kb = np.array([curvature_binormal(t[a], t[b]) for a, b in rod.vertex_edges])
    from der.geometry import curvature_binormals
    assert np.array_equal(curvature_binormals(t, rod.vertex_edges), kb)


def test_straight_director_parallel_to_an_edge_is_refused():
    with pytest.raises(ValueError, match="director is parallel to edge"):
        der.rod_from_shape(der.shapes.Shape(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]), director=(1, 0, 0)), 1, 1)
