"""Configurations with many near contacts, for the contact tests and tools/bench_contact.py."""
import numpy as np

from .distance import segment_distance2


def plectoneme_polyline(n_edges, h=1.0, rho=0.35, pitch=1.0):
    """Nodes (n_edges + 1, 3) of one open rod folded into a plectoneme: up along the helix
    (rho cos phi, rho sin phi, pitch phi), over a half-ellipse end loop of width 2 rho, and down along the
    helix turned by pi (the second strand), edges of length about h. The two strands are interwound at a
    centreline distance of about 2 rho: every edge has a few near partners on the other strand."""
    if n_edges < 8:
        raise ValueError(f"plectoneme_polyline: n_edges must be >= 8, got {n_edges!r}")
    ds = np.hypot(rho, pitch)                       # helix arc length per radian
    n_loop = max(1, int(round(np.pi * rho / h)))
    n_strand = (n_edges - n_loop) // 2
    n_loop = n_edges - 2 * n_strand
    phi_max = n_strand * h / ds
    phi = np.linspace(0.0, phi_max, n_strand + 1)
    up = np.stack([rho * np.cos(phi), rho * np.sin(phi), pitch * phi], 1)
    down = np.stack([-rho * np.cos(phi), -rho * np.sin(phi), pitch * phi], 1)[::-1]
    er = np.array([np.cos(phi_max), np.sin(phi_max), 0.0])
    psi = np.linspace(0.0, np.pi, n_loop + 1)[1:-1]
    top = pitch * phi_max
    # half-ellipse end loop, its height chosen so that its n_loop chords are about h long
    height = np.sqrt(max(2.0 * (n_loop * h / np.pi) ** 2 - rho * rho, rho * rho))
    loop = (rho * np.cos(psi)[:, None] * er + np.array([0, 0, top])
            + height * np.sin(psi)[:, None] * np.array([0, 0, 1.0]))
    return np.concatenate([up, loop, down])


def min_distance(pos, edges, pairs):
    """Smallest centreline distance over the given edge pairs (n_pairs, 2)."""
    best = np.inf
    for a, b in pairs:
        x = np.concatenate([pos[edges[a]].ravel(), pos[edges[b]].ravel()])
        best = min(best, segment_distance2(x))
    return float(np.sqrt(best))
