"""Throughput of the energy kernels: numba against a plain vectorised NumPy implementation, side by side.

    python tools/bench_kernels.py [--json] [--repeat 7] [--n 100 1000 10000] [--closed]

For each n (edges) it times one full gradient evaluation (stretch + bend + twist) and one gradient + Hessian
evaluation (banded), with der's numba kernels and with the NumPy version written below (same formulas,
vectorised over vertices, scattered with np.add.at; its bending Hessian is assembled one curvature component
at a time, unlike the kernel), on the same random configuration of a helix. It first
checks that both give the same numbers. Reported: best CPU seconds (process time) of ``--repeat`` runs, node-evaluations per
second and the NumPy/numba ratio. Compilation is excluded (warm-up call first) and reported apart.

Side by side in the same run (issue 17): the gradient + band Hessian assembly against the gradient alone
(``hess_over_grad``; the gradient is der's order-1 pass, which sums exactly as the assembly, and
``grad_separate_s`` the three separate passes it replaced), the assembly as it was before issue 17
(``hess_legacy_s``, kept below as the baseline: row-by-row scattering, bending and twisting scattered in two
passes) and one LAPACK ``dgbsv`` on the same band (``dgbsv_s``), the floor of a Newton iteration, beside der's
``band_solve`` (``ldlt_solve_s``: symmetric LDL^T refined against the band and checked, else dgbsv). And the
assembly as it was at c7e7f53 (``hess_before_s``, kept below: full 8 x 8 local Hessians expanded to 11 x 11 and
scattered entry by entry, the band zeroed and the frame-transport term added in passes of their own), timed in
alternation with der's and the gradient (``hess_before_over_grad``, ``before_over_new``); its band equals der's to
``max_rel_diff_before`` (<= 1e-14, checked) and its gradient bitwise.
"""
import argparse
import json
import os
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import der  # noqa: E402
from der.geometry import transport_frames  # noqa: E402
from der import linalg  # noqa: E402
from der.linalg import BandLDLT, band_layout, band_solve, new_band  # noqa: E402
from der.scene import evaluate, make_plan  # noqa: E402
from numba import njit  # noqa: E402
from der.energies.bend import _bend_local, bend_gradient  # noqa: E402
from der.energies.stretch import stretch_gradient  # noqa: E402
from der.energies.twist import twist_gradient  # noqa: E402
from der.energies.stretch import _stretch_local  # noqa: E402
from der.energies.twist import _twist_local  # noqa: E402
from der.geometry import add_transport_jacobian, edge_array, edge_array_into, edge_frames  # noqa: E402
from der.energies.stiffness import bending_at, twisting_at  # noqa: E402
from der.linalg import zero_band  # noqa: E402
from der.stencils import edge_dofs, expand_vertex_hessian, scatter_vertex_gradient, vertex_dofs  # noqa: E402

# ---------------------------------------------------------------------------------------------
# the assembly as it was before issue 17 (the baseline of the "hess_legacy" column): the band zeroed and
# scattered row by row (2 kl + ku + 1 doubles between consecutive writes), bending and twisting in two passes,
# each expanded and scattered on its own. Same local kernels as der's.
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def _scatter_rowwise(ab, kl, ku, perm, dofs, H):
    m = dofs.shape[0]
    off = kl + ku
    for a in range(m):
        i = perm[dofs[a]]
        for b in range(m):
            j = perm[dofs[b]]
            ab[off + i - j, j] += H[a, b]


@njit(cache=True)
def legacy_hessian(plan, q, d1, reference_twist, lam, grad, ab, kl, ku, perm):
    grad[:] = 0.0
    ab[:, :] = 0.0
    g6 = np.empty(6)
    H6 = np.empty((6, 6))
    d6 = np.empty(6, dtype=np.int64)
    energy = 0.0
    E = edge_array(q, plan.edge_nodes)
    for j in range(plan.edge_nodes.shape[0]):
        energy += _stretch_local(E, j, plan.l_bar[j], plan.k_stretch[j], lam[j], 2, g6, H6)
        edge_dofs(plan.edge_nodes, j, d6)
        for a in range(6):
            grad[d6[a]] += g6[a]
        _scatter_rowwise(ab, kl, ku, perm, d6, H6)
    ed = edge_frames(q, plan.edge_nodes, d1)
    g8 = np.empty(8)
    H8 = np.empty((8, 8))
    H11 = np.empty((11, 11))
    work = np.empty((5, 8))
    dofs = np.empty(11, dtype=np.int64)
    vn, ve = plan.vertex_nodes, plan.vertex_edges
    for term in range(2):
        for v in range(ve.shape[0]):
            if term == 0:
                b = plan.A1 / plan.voronoi[v]
                energy += _bend_local(ed, ve, plan.weld, v, plan.kappa_bar, b, b, 2, g8, H8, work)
            else:
                energy += _twist_local(q, ed, ve, reference_twist, plan.weld, v, plan.twist_bar[v],
                                       plan.A2 / plan.voronoi[v], 2, g8, H8, work)
            scatter_vertex_gradient(grad, vn[v, 0], vn[v, 1], vn[v, 2], ve[v, 0], ve[v, 1], g8)
            expand_vertex_hessian(H8, H11)
            vertex_dofs(vn, ve, v, dofs)
            _scatter_rowwise(ab, kl, ku, perm, dofs, H11)
    n_edges = plan.edge_nodes.shape[0]
    dE_dtheta = np.empty(n_edges)
    for j in range(n_edges):
        dE_dtheta[j] = grad[4 * j + 3]
    add_transport_jacobian(q, plan.edge_nodes, dE_dtheta, ab, kl, ku, perm)
    return energy


# ---------------------------------------------------------------------------------------------
# the assembly as it was at c7e7f53, before this round of issue 17 (the baseline of the "hess_before" column): the
# band zeroed in a pass of its own, per vertex the full 8 x 8 local Hessians of bending and twisting (each term
# one pass over the local array) expanded to the full 11 x 11 and scattered entry by entry, the frame-transport
# term in a pass of its own as a dense 6 x 6 block through the permutation. Same local kernels as der's.
# ---------------------------------------------------------------------------------------------


# positions of an edge's 6 DOFs [x_a (3), x_b (3)] in the vertex stencil [x0, theta_e, x1, theta_f, x2]
_EDGE_IN_STENCIL = ((0, 1, 2, 4, 5, 6), (4, 5, 6, 8, 9, 10))


@njit(cache=True)
def _scatter_band_before(ab, kl, ku, perm, dofs, H):
    """stencils.scatter_band at c7e7f53 (scale 1): column by column, positions looked up per entry."""
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
            j = np.uint64(base + b)
            for a in range(m):
                ab[np.uint64(r0 + a), j] += H[a, b]
        return
    for b in range(m):
        j = perm[dofs[b]]
        col = np.uint64(j)
        for a in range(m):
            i = perm[dofs[a]]
            ab[np.uint64(off + i - j), col] += H[a, b]


@njit(cache=True)
def before_hessian(plan, q, d1, reference_twist, lam, grad, ab, kl, ku, perm):
    """scene.evaluate at order 2 of a rod with all three terms, as at c7e7f53."""
    E = edge_array_into(q, plan.edge_nodes, None, True, plan.work_E)
    grad[:] = 0.0
    zero_band(ab)
    ed = edge_frames(q, plan.edge_nodes, d1, E, plan.work_ed)
    edge_nodes, vertex_nodes, vertex_edges = plan.edge_nodes, plan.vertex_nodes, plan.vertex_edges
    n_edges = edge_nodes.shape[0]
    g8 = np.empty(8)
    H8 = np.empty((8, 8))
    H11 = np.empty((11, 11))
    g6 = np.empty(6)
    H6 = np.empty((6, 6))
    work = np.empty((5, 8))
    dofs = np.empty(11, dtype=np.int64)
    owner = np.full(n_edges, -1, dtype=np.int64)
    side = np.zeros(n_edges, dtype=np.int64)
    for v in range(vertex_edges.shape[0]):
        for s in (1, 0):
            j = vertex_edges[v, s]
            if owner[j] < 0:
                owner[j] = v
                side[j] = s
    energy = 0.0
    for v in range(vertex_edges.shape[0]):
        a1, a2 = bending_at(plan.A1, v)
        energy += _bend_local(ed, vertex_edges, plan.weld, v, plan.kappa_bar, a1 / plan.voronoi[v],
                              a2 / plan.voronoi[v], 2, g8, H8, work)
        energy += _twist_local(q, ed, vertex_edges, reference_twist, plan.weld, v, plan.twist_bar[v],
                               twisting_at(plan.A2, v) / plan.voronoi[v], 2, g8, H8, work, True)
        scatter_vertex_gradient(grad, vertex_nodes[v, 0], vertex_nodes[v, 1], vertex_nodes[v, 2],
                                vertex_edges[v, 0], vertex_edges[v, 1], g8)
        expand_vertex_hessian(H8, H11)
        for s in range(2):
            j = vertex_edges[v, s]
            if owner[j] != v or side[j] != s:
                continue
            energy += _stretch_local(E, j, plan.l_bar[j], plan.k_stretch[j], lam[j], 2, g6, H6)
            a = 4 * edge_nodes[j, 0]
            c = 4 * edge_nodes[j, 1]
            for i in range(3):
                grad[a + i] += g6[i]
                grad[c + i] += g6[3 + i]
            m = _EDGE_IN_STENCIL[s]
            for r in range(6):
                for t in range(6):
                    H11[m[r], m[t]] += H6[r, t]
        vertex_dofs(vertex_nodes, vertex_edges, v, dofs)
        _scatter_band_before(ab, kl, ku, perm, dofs, H11)
    # the frame-transport term, a pass of its own (geometry.add_transport_jacobian at c7e7f53)
    d6 = np.empty(6, dtype=np.int64)
    B = np.zeros((6, 6))
    for j in range(n_edges):
        g = grad[4 * j + 3]
        if g == 0.0:
            continue
        e0 = E[j, 0]
        e1 = E[j, 1]
        e2 = E[j, 2]
        le = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        c = 0.5 * g / (le * le * le)
        B[0, 1] = -c * e2
        B[0, 2] = c * e1
        B[1, 0] = c * e2
        B[1, 2] = -c * e0
        B[2, 0] = -c * e1
        B[2, 1] = c * e0
        for r in range(3):
            for s in range(3):
                B[3 + r, 3 + s] = B[r, s]
                B[r, 3 + s] = -B[r, s]
                B[3 + r, s] = -B[r, s]
        edge_dofs(edge_nodes, j, d6)
        _scatter_band_before(ab, kl, ku, perm, d6, B)
    return energy


@njit(cache=True)
def separate_gradient(plan, q, d1, reference_twist, lam, grad):
    """The gradient as der's order-1 evaluation computed it before the fused gradient pass (issue 17): stretching,
    bending and twisting in three passes (the baseline of the "grad_separate" column)."""
    grad[:] = 0.0
    E = edge_array(q, plan.edge_nodes)
    energy = stretch_gradient(q, plan.edge_nodes, plan.l_bar, plan.k_stretch, lam, grad, E)
    ed = edge_frames(q, plan.edge_nodes, d1, E)
    energy += bend_gradient(ed, plan.vertex_nodes, plan.vertex_edges, plan.weld, plan.kappa_bar, plan.voronoi,
                            plan.A1, grad)
    energy += twist_gradient(q, ed, plan.vertex_nodes, plan.vertex_edges, reference_twist, plan.weld,
                             plan.twist_bar, plan.voronoi, plan.A2, grad)
    return energy


# ---------------------------------------------------------------------------------------------
# the NumPy reference implementation (vectorised over edges and vertices)
# ---------------------------------------------------------------------------------------------


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def _outer(a, b):
    return a[:, :, None] * b[:, None, :]


def _crossmat(a):
    z = np.zeros(len(a))
    return np.stack([np.stack([z, -a[:, 2], a[:, 1]], 1), np.stack([a[:, 2], z, -a[:, 0]], 1),
                     np.stack([-a[:, 1], a[:, 0], z], 1)], 1)


def _sym(a, b):
    return _outer(a, b) + _outer(b, a)


_B = np.zeros((8, 11))   # local (e, f, theta_e, theta_f) <- the 11 stencil DOFs
for _i in range(3):
    _B[_i, 4 + _i], _B[_i, _i] = 1.0, -1.0          # e = x1 - x0
    _B[3 + _i, 8 + _i], _B[3 + _i, 4 + _i] = 1.0, -1.0   # f = x2 - x1
_B[6, 3] = _B[7, 7] = 1.0


def numpy_evaluate(rod, q, d1, ref_twist, k, lam, hessian, kl, ku, perm):
    en, vn, ve = rod.edge_nodes, rod.vertex_nodes, rod.vertex_edges
    nn, ne, nv = rod.n_nodes, rod.n_edges, rod.n_vertices
    X = q.reshape(-1, 4)
    x, theta = X[:, :3], X[:ne, 3]
    e = x[en[:, 1]] - x[en[:, 0]]
    le = np.linalg.norm(e, axis=1)
    t = e / le[:, None]
    grad = np.zeros((nn, 4))
    # stretch
    tension = lam + k * (le - rod.l_bar)
    np.add.at(grad[:, :3], en[:, 1], tension[:, None] * t)
    np.add.at(grad[:, :3], en[:, 0], -tension[:, None] * t)
    # frames
    d2 = np.cross(t, d1)
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    m1, m2 = c * d1 + s * d2, -s * d1 + c * d2
    ie, jf = ve[:, 0], ve[:, 1]
    te, tf, lE, lF = t[ie], t[jf], le[ie][:, None], le[jf][:, None]
    chi = (1.0 + _dot(te, tf))[:, None]
    kb = 2.0 * np.cross(te, tf) / chi
    m1e, m2e, m1f, m2f = m1[ie], m2[ie], m1[jf], m2[jf]
    # bending per edge frame: components k_c = kb . u_c with u = m2_e, -m1_e, m2_f, -m1_f (u' = du/dtheta)
    sb = rod.A1 / rod.voronoi
    kbar = rod.natural_curvature_edges().reshape(-1, 4)
    tt = (te + tf) / chi
    comps = []
    for c, (u, up, own) in enumerate(((m2e, -m1e, 6), (-m1e, -m2e, 6), (m2f, -m1f, 7), (-m1f, -m2f, 7))):
        kc = _dot(kb, u)
        dk = np.zeros((nv, 8))
        dk[:, 0:3] = (-kc[:, None] * tt + 2.0 * np.cross(tf, u) / chi) / lE
        dk[:, 3:6] = (-kc[:, None] * tt - 2.0 * np.cross(te, u) / chi) / lF
        dk[:, own] = _dot(kb, up)
        comps.append((kc, u, up, own, dk, 0.5 * sb, kc - kbar[:, c]))   # weight A1 / (2 D): two sides per cell
    # twist
    st = rod.A2 / rod.voronoi
    mt = theta[jf] - theta[ie] + ref_twist
    rt = mt - rod.twist_bar
    dm = np.zeros((nv, 8))
    dm[:, 0:3] = 0.5 * kb / lE
    dm[:, 3:6] = 0.5 * kb / lF
    dm[:, 6], dm[:, 7] = -1.0, 1.0
    g8 = sum((w * r)[:, None] * dk for _, _, _, _, dk, w, r in comps) + (st * rt)[:, None] * dm
    g11 = g8 @ _B
    dofs = np.concatenate([4 * vn[:, :1] + np.arange(3), 4 * ie[:, None] + 3, 4 * vn[:, 1:2] + np.arange(3),
                           4 * jf[:, None] + 3, 4 * vn[:, 2:3] + np.arange(3)], axis=1)
    flat = grad.ravel()
    np.add.at(flat, dofs.ravel(), g11.ravel())
    if not hessian:
        return flat, None
    # Hessian: Gauss-Newton part + curvature of each bending component (one at a time) and of the twist
    H = st[:, None, None] * _outer(dm, dm)
    s3 = (st * rt)[:, None, None]
    I3 = np.eye(3)[None]
    chi_, lE_, lF_ = chi[:, :, None], lE[:, :, None], lF[:, :, None]
    lelf = lE_ * lF_
    tete, tftf, tttt = _outer(te, te), _outer(tf, tf), _outer(tt, tt)
    for kc, u, up, own, dk, w, r in comps:
        H += w[:, None, None] * _outer(dk, dk)
        sc = (w * r)[:, None, None]
        k_ = kc[:, None, None]
        dd = 2.0 * u / chi
        frame = _sym(kb, u) / 2.0
        H[:, 0:3, 0:3] += sc * (2 * k_ * tttt / lE_ ** 2 - _sym(np.cross(tf, dd), tt) / lE_ ** 2
                                - k_ / (chi_ * lE_ ** 2) * (I3 - tete) + (own == 6) * frame / lE_ ** 2)
        H[:, 3:6, 3:6] += sc * (2 * k_ * tttt / lF_ ** 2 + _sym(np.cross(te, dd), tt) / lF_ ** 2
                                - k_ / (chi_ * lF_ ** 2) * (I3 - tftf) + (own == 7) * frame / lF_ ** 2)
        ef = sc * (-k_ / (chi_ * lelf) * (I3 + _outer(te, tf)) + 2 * k_ * tttt / lelf
                   + (-_outer(np.cross(tf, dd), tt) + _outer(tt, np.cross(te, dd)) - _crossmat(dd)) / lelf)
        H[:, 0:3, 3:6] += ef
        H[:, 3:6, 0:3] += np.transpose(ef, (0, 2, 1))
        H[:, own, own] += sc[:, 0, 0] * (-kc)
        kbu = _dot(kb, up)[:, None]
        ce = sc[:, :, 0] / lE * (-kbu * tt + 2.0 * np.cross(tf, up) / chi)
        cf = sc[:, :, 0] / lF * (-kbu * tt - 2.0 * np.cross(te, up) / chi)
        H[:, 0:3, own] += ce
        H[:, own, 0:3] += ce
        H[:, 3:6, own] += cf
        H[:, own, 3:6] += cf
    # twist curvature terms
    H[:, 0:3, 0:3] += -s3 * _sym(kb, te + tt) / (4 * lE_ ** 2)
    H[:, 3:6, 3:6] += -s3 * _sym(kb, tf + tt) / (4 * lF_ ** 2)
    eft = s3 * (_crossmat(te) / chi_ - 0.5 * _outer(kb, tt)) / lelf
    H[:, 0:3, 3:6] += eft
    H[:, 3:6, 0:3] += np.transpose(eft, (0, 2, 1))
    H11 = np.einsum("ai,nab,bj->nij", _B, H, _B)
    # stretch Hessian blocks
    cT = (tension / le)[:, None, None]
    Hs = (k[:, None, None] - cT) * _outer(t, t) + cT * np.eye(3)[None]
    ab = new_band(rod.n_dof, kl, ku)
    rows = perm[dofs][:, :, None]
    colsj = perm[dofs][:, None, :]
    np.add.at(ab, (kl + ku + rows - colsj, np.broadcast_to(colsj, H11.shape)), H11)
    sd = np.concatenate([4 * en[:, :1] + np.arange(3), 4 * en[:, 1:2] + np.arange(3)], axis=1)
    H6 = np.block([[Hs, -Hs], [-Hs, Hs]])
    r6, c6 = perm[sd][:, :, None], perm[sd][:, None, :]
    np.add.at(ab, (kl + ku + r6 - c6, np.broadcast_to(c6, H6.shape)), H6)
    return flat, ab


# ---------------------------------------------------------------------------------------------


def timed(fn, repeat):
    """Best CPU seconds (process time) of ``repeat`` calls: on a shared machine wall-clock medians count the waits
    for a core, which fall unevenly on the columns compared (issue 17)."""
    times = []
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        times.append(time.process_time() - t0)
    return float(np.min(times))


def timed_alternating(fns, repeat):
    """``timed`` of each of ``fns``, their calls alternating: best CPU seconds of each."""
    times = [[] for _ in fns]
    for _ in range(repeat):
        for k, fn in enumerate(fns):
            t0 = time.process_time()
            fn()
            times[k].append(time.process_time() - t0)
    return [float(np.min(t)) for t in times]


def setup(n, rng, closed=False):
    if closed:    # a ring (folded band, half-bandwidth 19)
        rod = der.rod_from_shape(der.shapes.ring(1.0, n), 1.0, 1.5)
    else:
        rod = der.rod_from_shape(der.shapes.helix(1.0, 0.6, max(1.0, n / 100), n), 1.0, 1.5)
    base = rod.rest_state()
    st = base.copy()
    st.q += 1e-3 * rng.standard_normal(st.q.shape)
    if not closed:
        st.q[-1] = 0.0
    transport_frames(st.q, rod.edge_nodes, rod.vertex_edges, base.tangents, base.d1, base.reference_twist,
                     st.tangents, st.d1, st.reference_twist)
    k = 10.0 * rod.A1 / rod.l_bar ** 3
    lam = 0.1 * rng.standard_normal(rod.n_edges)
    return rod, st, k, lam


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[100, 1000, 10000])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--closed", action="store_true", help="a ring instead of the open helix")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    rod, st, k, lam = setup(20, rng)
    plan = make_plan(der.Scene(rod), k)
    kl, ku, perm = band_layout(rod.n_nodes, rod.closed)
    g, f, ab = np.zeros(rod.n_dof), np.zeros(rod.n_dof), new_band(rod.n_dof, kl, ku)
    evaluate(plan, st.q, st.d1, st.reference_twist, lam, 2, g, f, ab, kl, ku, perm)
    legacy_hessian(plan, st.q, st.d1, st.reference_twist, lam, g, ab, kl, ku, perm)
    before_hessian(plan, st.q, st.d1, st.reference_twist, lam, g, ab, kl, ku, perm)
    separate_gradient(plan, st.q, st.d1, st.reference_twist, lam, g)
    compile_s = time.perf_counter() - t0
    rows = []
    for n in args.n:
        rod, st, k, lam = setup(n, rng, args.closed)
        plan = make_plan(der.Scene(rod), k)
        kl, ku, perm = band_layout(rod.n_nodes, rod.closed)
        g, f, ab = np.zeros(rod.n_dof), np.zeros(rod.n_dof), new_band(rod.n_dof, kl, ku)

        def numba_grad():
            evaluate(plan, st.q, st.d1, st.reference_twist, lam, 1, g, f, ab, kl, ku, perm)

        def numba_hess():
            evaluate(plan, st.q, st.d1, st.reference_twist, lam, 2, g, f, ab, kl, ku, perm)

        g_old, ab_old = np.zeros(rod.n_dof), new_band(rod.n_dof, kl, ku)

        def legacy_hess():
            legacy_hessian(plan, st.q, st.d1, st.reference_twist, lam, g_old, ab_old, kl, ku, perm)

        g_before, ab_before = np.zeros(rod.n_dof), new_band(rod.n_dof, kl, ku)

        def before_hess():
            before_hessian(plan, st.q, st.d1, st.reference_twist, lam, g_before, ab_before, kl, ku, perm)

        g_sep = np.zeros(rod.n_dof)

        def separate_grad():
            separate_gradient(plan, st.q, st.d1, st.reference_twist, lam, g_sep)

        work = new_band(rod.n_dof, kl, ku)

        def dgbsv():   # LAPACK factor-and-solve of the band (on a copy: it overwrites); the copy is timed apart
            work[:] = ab
            linalg.USE_LDLT = False
            try:
                band_solve(work, kl, ku, perm, rhs)
            finally:
                linalg.USE_LDLT = True

        ldlt_work = BandLDLT(rod.n_dof, kl)

        def ldlt():    # der's band_solve: symmetric LDL^T, refined against the band, checked (else dgbsv)
            work[:] = ab
            band_solve(work, kl, ku, perm, rhs, ldlt=ldlt_work)

        def copy():
            work[:] = ab

        rhs = rng.standard_normal(rod.n_dof)

        # same numbers? (the numba Jacobian also holds the frame-transport term; compare the gradient and the
        # symmetric part of the band)
        gn, abn = numpy_evaluate(rod, st.q, st.d1, st.reference_twist, k, lam, True, kl, ku, perm)
        numba_hess()
        g_err = np.abs(gn - g).max() / np.abs(g).max()
        abt = new_band(rod.n_dof, kl, ku)
        add_transport_jacobian(st.q, rod.edge_nodes, g[3::4][: rod.n_edges].copy(), abt, kl, ku, perm)
        h_err = np.abs(abn - (ab - abt)).max() / np.abs(ab).max()
        assert g_err < 1e-9 and h_err < 1e-9, (g_err, h_err)
        legacy_hess()
        legacy_diff = max(np.abs(g_old - g).max() / np.abs(g).max(), np.abs(ab_old - ab).max() / np.abs(ab).max())
        assert legacy_diff < 1e-12, legacy_diff
        before_hess()
        before_grad_bitwise = bool(np.array_equal(g_before, g))
        before_diff = np.abs(ab_before - ab).max() / np.abs(ab).max()
        assert before_grad_bitwise and before_diff <= 1e-14, before_diff
        # the order-1 pass sums exactly as the assembly (bitwise); the old separate passes to round-off
        g_hess = g.copy()
        numba_grad()
        grad_bitwise = bool(np.array_equal(g, g_hess))
        assert grad_bitwise
        separate_grad()
        separate_diff = np.abs(g_sep - g).max() / np.abs(g).max()
        assert separate_diff < 1e-12, separate_diff
        # a solvable band for the dgbsv timing: a dominant diagonal
        ab[:, :] += 1e3 * np.abs(ab).max() * (np.arange(ab.shape[0]) == kl + ku)[:, None]
        t_copy = timed(copy, args.repeat)
        t_solve = max(timed(dgbsv, args.repeat) - t_copy, 1e-9)
        solves0 = dict(linalg.BAND_SOLVES)
        t_ldlt = max(timed(ldlt, args.repeat) - t_copy, 1e-9)
        ldlt_accepted = linalg.BAND_SOLVES["ldlt"] > solves0["ldlt"]
        numba_hess()
        # the assembly, its c7e7f53 form and the gradient alone, timed alternately (drifts of a shared machine's
        # load fall on all three)
        t_grad, t_hess, t_before = timed_alternating((numba_grad, numba_hess, before_hess), args.repeat)
        r = {"n": n, "grad_numba_s": t_grad,
             "grad_numpy_s": timed(lambda: numpy_evaluate(rod, st.q, st.d1, st.reference_twist, k, lam, False,
                                                          kl, ku, perm), args.repeat),
             "grad_separate_s": timed(separate_grad, args.repeat),
             "grad_same_as_assembly_bitwise": grad_bitwise, "max_rel_diff_grad_separate": separate_diff,
             "hess_numba_s": t_hess, "hess_before_s": t_before, "max_rel_diff_before": before_diff,
             "grad_before_bitwise": before_grad_bitwise,
             "hess_legacy_s": timed(legacy_hess, args.repeat),
             "dgbsv_s": t_solve, "max_rel_diff_legacy": legacy_diff,
             "ldlt_solve_s": t_ldlt, "ldlt_accepted": ldlt_accepted, "ldlt_over_dgbsv": t_ldlt / t_solve,
             "hess_numpy_s": timed(lambda: numpy_evaluate(rod, st.q, st.d1, st.reference_twist, k, lam, True,
                                                          kl, ku, perm), args.repeat),
             "max_rel_diff_grad": g_err, "max_rel_diff_hess": h_err}
        r["grad_ratio"] = r["grad_numpy_s"] / r["grad_numba_s"]
        r["hess_ratio"] = r["hess_numpy_s"] / r["hess_numba_s"]
        r["hess_over_grad"] = r["hess_numba_s"] / r["grad_numba_s"]
        r["hess_over_grad_separate"] = r["hess_numba_s"] / r["grad_separate_s"]
        r["hess_legacy_over_grad"] = r["hess_legacy_s"] / r["grad_numba_s"]
        r["legacy_over_new"] = r["hess_legacy_s"] / r["hess_numba_s"]
        r["hess_before_over_grad"] = r["hess_before_s"] / r["grad_numba_s"]
        r["before_over_new"] = r["hess_before_s"] / r["hess_numba_s"]
        r["grad_node_evals_per_s"] = rod.n_nodes / r["grad_numba_s"]
        r["hess_node_evals_per_s"] = rod.n_nodes / r["hess_numba_s"]
        rows.append(r)
    ns = np.array([r["n"] for r in rows], float)
    exps = {}
    if len(ns) > 1:
        for key in ("grad_numba_s", "hess_numba_s"):
            exps[key.replace("_s", "_exponent")] = float(np.polyfit(np.log(ns), np.log([r[key] for r in rows]), 1)[0])
    print(f"compile (or cache load): {compile_s:.2f} s   machine: {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, numpy {np.__version__}")
    print(f"{'n':>7} {'grad numba':>11} {'grad numpy':>11} {'ratio':>7} {'hess numba':>11} {'hess numpy':>11} "
          f"{'ratio':>7} {'node-evals/s (grad)':>20}")
    for r in rows:
        print(f"{r['n']:>7} {r['grad_numba_s']:>11.2e} {r['grad_numpy_s']:>11.2e} {r['grad_ratio']:>7.1f} "
              f"{r['hess_numba_s']:>11.2e} {r['hess_numpy_s']:>11.2e} {r['hess_ratio']:>7.1f} "
              f"{r['grad_node_evals_per_s']:>20.3e}")
    print("assembly of gradient + band Hessian against the gradient alone, der's against the pre-issue-17 kernel "
          "(same run), and one dgbsv of the same band:")
    print(f"{'n':>7} {'hess/grad':>10} {'hess/grad_sep':>14} {'legacy/grad':>12} {'legacy/new':>11} {'dgbsv s':>10} "
          f"{'hess/dgbsv':>11} {'grad/dgbsv':>11} {'ldlt s':>10} {'ldlt/dgbsv':>11}")
    for r in rows:
        print(f"{r['n']:>7} {r['hess_over_grad']:>10.1f} {r['hess_over_grad_separate']:>14.1f} "
              f"{r['hess_legacy_over_grad']:>12.1f} {r['legacy_over_new']:>11.2f} {r['dgbsv_s']:>10.2e} "
              f"{r['hess_numba_s'] / r['dgbsv_s']:>11.2f} {r['grad_numba_s'] / r['dgbsv_s']:>11.2f} "
              f"{r['ldlt_solve_s']:>10.2e} {r['ldlt_over_dgbsv']:>11.2f}{'' if r['ldlt_accepted'] else ' (refused)'}")
    print("(ldlt: der's band_solve, LDL^T of the symmetric band refined against the band with its frame-transport "
          "term and accepted on its backward error; dgbsv: LAPACK's banded LU with partial pivoting)")
    print("(grad: der's order-1 pass, the assembly's sums without the band; grad_sep: the separate stretching, "
          "bending and twisting passes it replaced)")
    print("this round's assembly against c7e7f53's (hess_before: full local Hessians, 121-entry scatter, zeroing "
          "and frame-transport passes of their own; same run, alternating calls):")
    print(f"{'n':>7} {'hess s':>10} {'before s':>10} {'before/new':>11} {'hess/grad':>10} {'before/grad':>12} "
          f"{'max rel diff':>13}")
    for r in rows:
        print(f"{r['n']:>7} {r['hess_numba_s']:>10.2e} {r['hess_before_s']:>10.2e} {r['before_over_new']:>11.2f} "
              f"{r['hess_over_grad']:>10.2f} {r['hess_before_over_grad']:>12.2f} {r['max_rel_diff_before']:>13.1e}")
    if exps:
        print("time ~ n^p: " + ", ".join(f"{k} = {v:.2f}" for k, v in exps.items()))
    if args.json:
        print(json.dumps({"compile_s": compile_s, "rows": rows, **exps}))


if __name__ == "__main__":
    main()
