"""Shared test helpers: random perturbed configurations and finite differences (independent of the kernels)."""
import numpy as np

import der
from der.geometry import transport_frames
from der.linalg import band_layout, band_to_sparse, new_band
from der.scene import evaluate, make_plan


def perturbed_state(rod, rng, amplitude=0.05, twist=0.3):
    """A random configuration near the rest shape, frames transported consistently."""
    base = rod.rest_state()
    q = base.q.copy()
    q += amplitude * rod.l_bar.mean() * rng.standard_normal(q.shape)
    q.reshape(-1, 4)[:, 3] = base.q.reshape(-1, 4)[:, 3] + twist * rng.standard_normal(rod.n_nodes)
    if not rod.closed:
        q[-1] = 0.0
    return moved(rod, base, q)


def moved(rod, base, q):
    """``base`` moved to ``q`` with its frames parallel-transported (the straight path from base to q)."""
    out = base.copy()
    out.q[:] = q
    ok = transport_frames(out.q, rod.edge_nodes, rod.vertex_edges, base.tangents, base.d1, base.reference_twist,
                          out.tangents, out.d1, out.reference_twist)
    assert ok
    return out


class Evaluator:
    """Energy, gradient, external force and Jacobian of a scene at arbitrary states."""

    def __init__(self, scene, k_stretch=None):
        rod = scene.rod
        self.rod = rod
        if k_stretch is None:
            k_stretch = (rod.EA if rod.EA is not None else 50.0) / rod.l_bar
        self.plan = make_plan(scene, k_stretch)
        self.kl, self.ku, self.perm = band_layout(rod.n_nodes, rod.closed)

    def __call__(self, state, order=1):
        n = self.rod.n_dof
        g, f = np.zeros(n), np.zeros(n)
        ab = new_band(n, self.kl, self.ku)
        E = evaluate(self.plan, state.q, state.d1, state.reference_twist, state.lam, order, g, f, ab, self.kl,
                     self.ku, self.perm)
        K = band_to_sparse(ab, self.kl, self.ku, self.perm).toarray() if order >= 2 else None
        return E, g, f, K


def free_mask(rod):
    m = np.ones(rod.n_dof, bool)
    if not rod.closed:
        m[-1] = False
    return m


def shapes_for_tests():
    """Open and closed test rods with natural curvature and twist."""
    return {
        "helix": der.shapes.helix(1.0, 0.6, 1.2, 11),
        "left_helix": der.shapes.helix(0.8, -0.5, 0.7, 9),
        "ring": der.shapes.ring(1.0, 9),
        "arc": der.shapes.arc(1.3, 3.0, 8),
    }
