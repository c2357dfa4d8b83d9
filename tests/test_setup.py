"""Setup in one kernel pass (issue 17): ``rod_from_shape`` builds its topology, edge lengths and tangents with
``geometry.rod_topology`` and ``geometry.shape_edges``; every array of the Rod is bitwise the one the NumPy
construction it replaced gives (kept here as the reference)."""
import dataclasses

import numpy as np
import pytest

import der
from der.geometry import rod_topology, shape_edges
from der.rod import Rod, _measure, frenet_frame_of_shape

SHAPES = {
    "straight": lambda: der.shapes.straight(2.0, 57, axis=(1, 0, 0), director=(0, 0, 1)),
    "arc": lambda: der.shapes.arc(1.0, 3.0, 88),
    "helix": lambda: der.shapes.helix(1.0, 0.6, 3, 301),
    "ring": lambda: der.shapes.ring(1.0, 97),
    "far_helix": lambda: der.shapes.polyline(der.shapes.helix(1.3, 0.4, 2, 123).positions + 1e4),
    "noisy_ring": lambda: der.shapes.polyline(
        der.shapes.ring(1.0, 64).positions + 1e-3 * np.random.default_rng(3).standard_normal((64, 3)), closed=True),
}


def _reference_topology(n_edges, closed):
    """rod.topology as it was (NumPy)."""
    n_nodes = n_edges if closed else n_edges + 1
    j = np.arange(n_edges)
    edge_nodes = np.stack([j, (j + 1) % n_nodes], axis=1).astype(np.int64)
    if closed:
        v = np.arange(n_edges)
        vertex_nodes = np.stack([(v - 1) % n_nodes, v, (v + 1) % n_nodes], axis=1)
        vertex_edges = np.stack([(v - 1) % n_edges, v], axis=1)
    else:
        v = np.arange(1, n_edges)
        vertex_nodes = np.stack([v - 1, v, v + 1], axis=1)
        vertex_edges = np.stack([v - 1, v], axis=1)
    return edge_nodes, vertex_nodes.astype(np.int64), vertex_edges.astype(np.int64)


def _reference_rod_from_shape(shape, A1, A2):
    """rod_from_shape as it was before the setup kernel: edges, lengths and tangents by NumPy expressions, the
    Frenet directors from ``frenet_frame_of_shape`` (uniform stiffness, inextensible, default inertia)."""
    x = np.asarray(shape.positions, dtype=float)
    closed = bool(shape.closed)
    n_edges = x.shape[0] if closed else x.shape[0] - 1
    edge_nodes, vertex_nodes, vertex_edges = _reference_topology(n_edges, closed)
    e = x[edge_nodes[:, 1]] - x[edge_nodes[:, 0]]
    le = np.linalg.norm(e, axis=1)
    t = e / le[:, None]
    director = getattr(shape, "director", None)
    _, d1, _ = frenet_frame_of_shape(x, closed, director)
    q, rest_twist, kappa_bar_edges = _measure(x, edge_nodes, vertex_edges, t, d1)
    voronoi = 0.5 * (le[vertex_edges[:, 0]] + le[vertex_edges[:, 1]])
    rod = der.rod_from_shape(shape, A1, A2)
    return Rod(closed=closed, A1=float(A1), A2=float(A2), EA=None, edge_nodes=edge_nodes, vertex_nodes=vertex_nodes,
               vertex_edges=vertex_edges, l_bar=le, voronoi=voronoi, kappa_bar=kappa_bar_edges.mean(axis=1),
               kappa_bar_edges=kappa_bar_edges, twist_bar=rest_twist.copy(), rest_q=q, rest_d1=d1,
               rest_twist=rest_twist, rho_A=1.0, rho_J=rod.rho_J)


def _same(a, b):
    """Bitwise the same value (arrays: dtype, shape and bytes; -0.0 is not 0.0)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    return type(a) is type(b) and (a == b or (a != a and b != b))


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_rod_from_shape_is_bitwise_the_numpy_construction(name):
    shape = SHAPES[name]()
    rod = der.rod_from_shape(shape, 1.0, 1.5)
    ref = _reference_rod_from_shape(shape, 1.0, 1.5)
    checked = 0
    for f in dataclasses.fields(Rod):
        a, b = getattr(rod, f.name), getattr(ref, f.name)
        assert _same(a, b), f"{name}: Rod.{f.name} differs from the NumPy construction"
        checked += isinstance(a, np.ndarray)
    assert checked >= 10      # every array of the Rod, not a few


@pytest.mark.parametrize("closed", [False, True])
@pytest.mark.parametrize("n_edges", [3, 4, 17])
def test_rod_topology_is_the_numpy_topology(n_edges, closed):
    for a, b in zip(rod_topology(n_edges, closed), _reference_topology(n_edges, closed)):
        assert _same(a, b)


def test_shape_edges_checks():
    """The kernel's finiteness flag, shortest edge and sharpest turn (what rod_from_shape's refusals read)."""
    x = np.array([[0, 0, 0], [1, 0, 0], [1, 0.5, 0], [1, 0.5, 2.0]])
    en, _, ve = rod_topology(3, False)
    le, t, finite, scale, j, v, cos_min = shape_edges(x, en, ve)
    assert finite and j == 1 and le[j] == 0.5 and scale == 2.0 and cos_min == 0.0
    x[2, 1] = np.nan
    assert not shape_edges(x, en, ve)[2]
    with pytest.raises(ValueError, match="finite; node 2"):
        der.rod_from_shape(der.shapes.Shape(x), 1.0, 1.0)
    with pytest.raises(ValueError, match="coincident nodes: edge 1"):
        der.rod_from_shape(der.shapes.Shape(np.array([[0, 0, 0], [1, 0, 0], [1, 0, 0], [2, 0, 0.0]])), 1.0, 1.0)
    with pytest.raises(ValueError, match="folds back onto itself at node 2"):
        der.rod_from_shape(der.shapes.Shape(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 0, 0.0]])), 1.0, 1.0)
