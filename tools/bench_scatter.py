"""stencils.scatter_band against its previous form (signed band indices: numba tests each for a negative
index), side by side in one process: every vertex stencil of a 10^5-edge open helix and ring scattered into
the band, best CPU time of 15 interleaved runs (issue 17).

    python tools/bench_scatter.py [--n 100000]
"""
import argparse
import os
import sys
import time

import numpy as np
from numba import njit

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import der  # noqa: E402
from der.linalg import band_layout, new_band  # noqa: E402
from der.stencils import scatter_band, vertex_dofs  # noqa: E402


@njit(cache=True)
def signed_scatter(ab, kl, ku, perm, dofs, H, scale):
    """scatter_band before issue 17's change (the baseline)."""
    m = dofs.shape[0]
    off = kl + ku
    base = perm[dofs[0]]
    contiguous = True
    for a in range(1, m):
        if perm[dofs[a]] != base + a:
            contiguous = False
            break
    if contiguous:
        for b in range(m):
            r0 = off - b
            j = base + b
            for a in range(m):
                ab[r0 + a, j] += scale * H[a, b]
        return
    for b in range(m):
        j = perm[dofs[b]]
        for a in range(m):
            i = perm[dofs[a]]
            ab[off + i - j, j] += scale * H[a, b]


@njit(cache=True)
def scatter_all(f, ab, kl, ku, perm, vertex_nodes, vertex_edges, H):
    dofs = np.empty(11, dtype=np.int64)
    for v in range(vertex_nodes.shape[0]):
        vertex_dofs(vertex_nodes, vertex_edges, v, dofs)
        f(ab, kl, ku, perm, dofs, H, 1.0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100000)
    args = ap.parse_args(argv)
    for closed in (False, True):
        shape = der.shapes.ring(1.0, args.n) if closed else der.shapes.helix(1.0, 0.6, args.n / 200, args.n)
        rod = der.rod_from_shape(shape, 1.0, 1.0)
        kl, ku, perm = band_layout(rod.n_nodes, rod.closed)
        H = np.random.default_rng(0).standard_normal((11, 11))
        bands = []
        for f in (signed_scatter, scatter_band):
            ab = new_band(rod.n_dof, kl, ku)
            scatter_all(f, ab, kl, ku, perm, rod.vertex_nodes, rod.vertex_edges, H)
            bands.append(ab)
        assert bands[0].tobytes() == bands[1].tobytes()     # bitwise the same band
        best = [np.inf, np.inf]
        for _ in range(15):
            for i, f in enumerate((signed_scatter, scatter_band)):
                c = time.process_time()
                scatter_all(f, ab, kl, ku, perm, rod.vertex_nodes, rod.vertex_edges, H)
                best[i] = min(best[i], time.process_time() - c)
        print(f"{'ring' if closed else 'open'} n={args.n}: signed indices {1e3 * best[0]:.2f} ms, unsigned "
              f"(scatter_band) {1e3 * best[1]:.2f} ms CPU, ratio {best[0] / best[1]:.2f} (bands bitwise equal)")


if __name__ == "__main__":
    main()
