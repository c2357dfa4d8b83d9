"""The IPC log barrier on the gap between two thick rods, its pair gradient and Hessian, and their assembly.

Barrier (Li et al. 2020, Eq. 6):  b(z; zh) = -(z - zh)^2 log(z / zh) for 0 < z < zh, 0 for z >= zh.
b, b' and b'' all vanish at z = zh (so the energy is C2 where pairs enter or leave the active set) and
b -> +inf as z -> 0+.

Which z. Two edges of centreline distance dist = sqrt(D) touch when dist = off = r_a + r_b (2r for one rod).
- GAP (default): z = dist - off, zh = dhat. The barrier acts on the physical gap between the surfaces: dhat is
  a length with a direct meaning (the range of the contact force), the force on the pair is -kappa b'(z) along
  the closest-point normal, and the activation zone is the same shell of width dhat around every edge. dist
  >= off > 0 on every admissible state, so sqrt(D) is smooth there (the sqrt singularity at D = 0 is never
  reached), and dz/dD = 1 / (2 dist), d2z/dD2 = -1 / (4 dist^3).
- SQUARED: z = D - off^2, zh = (off + dhat)^2 - off^2 = 2 off dhat + dhat^2 (same activation distance
  off + dhat). No square root; it is IPC Toolkit's convention for a minimum distance dmin = off, which lets the
  benchmark check our assembly against ipctk's BarrierPotential term by term. Its barrier is b of a quantity
  (dist - off)(dist + off) ~ 2 off (dist - off) near contact: the same log singularity, a different shape.
Both: E = kappa b(z), dE/dx = kappa b'(z) z' dD/dx, d2E/dx2 = kappa [(b'' z'^2 + b' z'') dD dD^T + b' z' d2D].

Units: D in length^2, dhat in length, kappa in energy / (unit of b) (b has units z^2: length^2 in GAP mode,
length^4 in SQUARED mode). Layout: positions (n_nodes, 3); edges (n_edges, 2) node indices; pairs (n_pairs, 2)
edge indices; node_dof (n_nodes,) index of each node's x coordinate in the global DOF vector (y, z follow).
"""
import numpy as np
from numba import njit

from .distance import closest_parameters, segment_distance2, segment_distance2_derivatives

GAP, SQUARED = 0, 1


@njit(cache=True)
def barrier(z, zh):
    """b(z) = -(z - zh)^2 log(z / zh) for 0 < z < zh; 0 beyond; +inf for z <= 0."""
    if z >= zh:
        return 0.0
    if z <= 0.0:
        return np.inf
    return -(z - zh) ** 2 * np.log(z / zh)


@njit(cache=True)
def barrier_first_derivative(z, zh):
    """b'(z) = (zh - z) (2 log(z / zh) - zh / z + 1); 0 beyond zh."""
    if z >= zh:
        return 0.0
    return (zh - z) * (2.0 * np.log(z / zh) - zh / z + 1.0)


@njit(cache=True)
def barrier_second_derivative(z, zh):
    """b''(z) = (zh / z + 2) zh / z - 2 log(z / zh) - 3; 0 beyond zh."""
    if z >= zh:
        return 0.0
    q = zh / z
    return (q + 2.0) * q - 2.0 * np.log(z / zh) - 3.0


@njit(cache=True)
def gap_variable(D, off, dhat, mode):
    """(z, zh, dz/dD, d2z/dD2) for the squared distance D, offset off = r_a + r_b and activation gap dhat."""
    if mode == GAP:
        dist = np.sqrt(D)
        return dist - off, dhat, 0.5 / dist, -0.25 / (dist * D)
    return D - off * off, 2.0 * off * dhat + dhat * dhat, 1.0, 0.0


@njit(cache=True)
def pair_subspace(x, Q):
    """Orthonormal basis Q[:, :k] (12, <=5) of a subspace holding the range of every pair Hessian at x.

    With r = sum_k ca_k p_k the closest-point difference (distance.py), dD = 2 (ca x I)^T r, J^T J = (ca ca^T) x I
    and the mixed terms are ca x u + ds x r, ca x v + dt x r (x: Kronecker product; ds = (-1, 1, 0, 0),
    dt = (0, 0, -1, 1)), so the barrier Hessian of the pair lives in span{ca x e_i (i = 1..3), ds x r, dt x r}.
    Returns k."""
    D, s, t, region = closest_parameters(x)
    c0, c1, c2, c3 = 1.0 - s, s, t - 1.0, -t
    r0 = c0 * x[0] + c1 * x[3] + c2 * x[6] + c3 * x[9]
    r1 = c0 * x[1] + c1 * x[4] + c2 * x[7] + c3 * x[10]
    r2 = c0 * x[2] + c1 * x[5] + c2 * x[8] + c3 * x[11]
    Q.fill(0.0)
    # columns 0..2: ca x e_i, mutually orthogonal, norm |ca|
    nca = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2 + c3 * c3)
    for i in range(3):
        Q[i, i], Q[3 + i, i], Q[6 + i, i], Q[9 + i, i] = c0 / nca, c1 / nca, c2 / nca, c3 / nca
    k = 3
    rr = (r0, r1, r2)
    for c in range(2):                         # ds x r, dt x r, Gram-Schmidt against the columns so far
        v = np.zeros(12)
        lo = 6 * c
        for i in range(3):
            v[lo + i] = -rr[i]
            v[lo + 3 + i] = rr[i]
        n0 = 0.0
        for m in range(12):
            n0 += v[m] * v[m]
        for j in range(k):
            d = 0.0
            for m in range(12):
                d += Q[m, j] * v[m]
            for m in range(12):
                v[m] -= d * Q[m, j]
        nv = 0.0
        for m in range(12):
            nv += v[m] * v[m]
        if nv > 1e-20 * n0:
            nv = np.sqrt(nv)
            for m in range(12):
                Q[m, k] = v[m] / nv
            k += 1
    return k


@njit(cache=True)
def jacobi_eigh(M, V, k):
    """Eigen-decomposition of the symmetric k x k block M[:k, :k] by cyclic Jacobi rotations (in place):
    on return diag(M) holds the eigenvalues and V[:k, :k] the eigenvectors (columns). For the tiny blocks
    of pair Hessians this is several times faster than a LAPACK call from numba. At most 50 sweeps (it
    converges quadratically, in ~6 for k = 5)."""
    for i in range(k):
        for j in range(k):
            V[i, j] = 1.0 if i == j else 0.0
    for sweep in range(50):
        off = 0.0
        scale = 0.0
        for i in range(k):
            scale += M[i, i] * M[i, i]
            for j in range(i + 1, k):
                off += M[i, j] * M[i, j]
        if off <= 1e-30 * scale or off == 0.0:
            return
        for p in range(k - 1):
            for q in range(p + 1, k):
                apq = M[p, q]
                if apq == 0.0:
                    continue
                theta = (M[q, q] - M[p, p]) / (2.0 * apq)
                t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + np.sqrt(theta * theta + 1.0))
                c = 1.0 / np.sqrt(t * t + 1.0)
                s = t * c
                for i in range(k):             # M <- M G (columns p, q)
                    mip, miq = M[i, p], M[i, q]
                    M[i, p] = c * mip - s * miq
                    M[i, q] = s * mip + c * miq
                for i in range(k):             # M <- G^T M (rows p, q)
                    mpi, mqi = M[p, i], M[q, i]
                    M[p, i] = c * mpi - s * mqi
                    M[q, i] = s * mpi + c * mqi
                for i in range(k):
                    vip, viq = V[i, p], V[i, q]
                    V[i, p] = c * vip - s * viq
                    V[i, q] = s * vip + c * viq


@njit(cache=True)
def project_psd_in_subspace(H, Q, k):
    """Eigen-clamp symmetric H (m, m) whose range lies in span Q[:, :k] (orthonormal): the same result as
    the 12 x 12 eigen-clamping, from a k x k eigenproblem (k <= 5 for a pair; measured ~4 us against ~16 us
    for LAPACK's 12 x 12 dsyevd called from numba)."""
    m = H.shape[0]
    HQ = np.zeros((m, 5))
    for i in range(m):
        for j in range(k):
            acc = 0.0
            for l in range(m):
                acc += H[i, l] * Q[l, j]
            HQ[i, j] = acc
    M = np.zeros((5, 5))
    for i in range(k):
        for j in range(i, k):
            acc = 0.0
            for l in range(m):
                acc += Q[l, i] * HQ[l, j]
            M[i, j] = acc
            M[j, i] = acc
    V = np.empty((5, 5))
    jacobi_eigh(M, V, k)
    negative = False
    for j in range(k):
        if M[j, j] < 0.0:
            negative = True
    if not negative:
        return
    B = np.zeros((m, 5))                       # B = Q V: eigenvectors in the 12 coordinates
    for i in range(m):
        for j in range(k):
            acc = 0.0
            for l in range(k):
                acc += Q[i, l] * V[l, j]
            B[i, j] = acc
    for i in range(m):
        for j in range(m):
            acc = 0.0
            for l in range(k):
                if M[l, l] > 0.0:
                    acc += M[l, l] * B[i, l] * B[j, l]
            H[i, j] = acc


@njit(cache=True)
def pair_barrier(x, off, dhat, kappa, mode, project, grad, hess):
    """Barrier energy of one edge pair x = [a0, a1, b0, b1] (12,); writes its gradient (12,) and Hessian
    (12, 12) (eigen-clamped to PSD if ``project``). Returns (energy, gap z); energy is +inf if z <= 0 and 0 with
    zero derivatives if the pair is beyond the activation distance."""
    dD = np.empty(12)
    HD = np.empty((12, 12))
    D, region = segment_distance2_derivatives(x, dD, HD)
    z, zh, z1, z2 = gap_variable(D, off, dhat, mode)
    if z >= zh:
        grad.fill(0.0)
        hess.fill(0.0)
        return 0.0, z
    if z <= 0.0:
        grad.fill(0.0)
        hess.fill(0.0)
        return np.inf, z
    b1 = barrier_first_derivative(z, zh)
    b2 = barrier_second_derivative(z, zh)
    c1 = kappa * b1 * z1
    c2 = kappa * (b2 * z1 * z1 + b1 * z2)
    for m in range(12):
        grad[m] = c1 * dD[m]
        for n in range(12):
            hess[m, n] = c2 * dD[m] * dD[n] + c1 * HD[m, n]
    if project:
        Q = np.empty((12, 5))
        project_psd_in_subspace(hess, Q, pair_subspace(x, Q))
    return kappa * barrier(z, zh), z


@njit(cache=True)
def kept_pairs(pairs, keep, n):
    """The n rows of ``pairs`` (k, 2) whose ``keep`` flag is set, in order."""
    out = np.empty((n, 2), dtype=np.int64)
    q = 0
    for p in range(pairs.shape[0]):
        if keep[p]:
            out[q, 0] = pairs[p, 0]
            out[q, 1] = pairs[p, 1]
            q += 1
    return out


@njit(cache=True)
def active_pairs(pos, edges, pairs, edge_radius, dhat):
    """The rows of pairs (n_pairs, 2) whose gap is below dhat (the barrier's support), so that the triplet
    buffers can be sized to the active set rather than to all candidates."""
    keep = np.zeros(pairs.shape[0], dtype=np.bool_)
    x = np.empty(12)
    n = 0
    for p in range(pairs.shape[0]):
        ea, eb = pairs[p, 0], pairs[p, 1]
        nodes = (edges[ea, 0], edges[ea, 1], edges[eb, 0], edges[eb, 1])
        for k in range(4):
            for i in range(3):
                x[3 * k + i] = pos[nodes[k], i]
        off = edge_radius[ea] + edge_radius[eb]
        if np.sqrt(segment_distance2(x)) - off < dhat:
            keep[p] = True
            n += 1
    return kept_pairs(pairs, keep, n)


@njit(cache=True)
def assemble_pairs(pos, edges, pairs, edge_radius, dhat, kappa, mode, project, node_dof,
                   grad_out, rows, cols, vals):
    """Add the barrier of every pair in ``pairs`` to grad_out (n_dof,) and write its Hessian blocks as COO
    triplets into rows, cols, vals (each of length >= 144 * n_pairs).

    Returns (energy, n_active, n_triplets, min_gap). energy is +inf if any pair has z <= 0 (an inadmissible
    state: the caller must reject it)."""
    x = np.empty(12)
    g = np.empty(12)
    H = np.empty((12, 12))
    dof = np.empty(12, dtype=np.int64)
    energy = 0.0
    n_active = 0
    nt = 0
    min_gap = np.inf
    for p in range(pairs.shape[0]):
        ea, eb = pairs[p, 0], pairs[p, 1]
        nodes = (edges[ea, 0], edges[ea, 1], edges[eb, 0], edges[eb, 1])
        for k in range(4):
            for i in range(3):
                x[3 * k + i] = pos[nodes[k], i]
                dof[3 * k + i] = node_dof[nodes[k]] + i
        off = edge_radius[ea] + edge_radius[eb]
        e, z = pair_barrier(x, off, dhat, kappa, mode, project, g, H)
        if mode == GAP:
            gap = z
        else:
            gap = np.sqrt(z + off * off) - off
        if gap < min_gap:
            min_gap = gap
        if e == 0.0 and gap >= dhat:
            continue
        energy += e
        n_active += 1
        for m in range(12):
            grad_out[dof[m]] += g[m]
            for n in range(12):
                rows[nt] = dof[m]
                cols[nt] = dof[n]
                vals[nt] = H[m, n]
                nt += 1
    return energy, n_active, nt, min_gap
