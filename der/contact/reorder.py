"""The Newton matrix with contact as a band again: reverse Cuthill-McKee on the node graph, then LAPACK's banded LU.

A rod's stiffness couples each node with its near neighbours along the rod (a band); contact adds blocks that
couple the nodes of two edges far apart along the rod. In a plectoneme, a supercoiled ring or a rod pressed on
itself, the contacts pair each point of one strand with a point of the other: the node graph is a ladder, and
reverse Cuthill-McKee (RCM) orders it with a small bandwidth (the two strands interleaved). The matrix in that
order is banded again and LAPACK's dgbsv factorises it in O(n kl^2) without symbolic analysis: measured faster
than scipy's splu (SuperLU, COLAMD) on the plectoneme (docs/contact.md, "Sparse factorisation"). When the
reordered bandwidth is large (contacts that do not form a ladder), the solver keeps splu.

DOFs come in blocks of 4 (x, y, z, theta per node, der's layout): the graph is over blocks, each block keeps its
four DOFs together.
"""
import numpy as np
from numba import njit


def block_order(ab, kl, ku, perm, rows, cols):
    """RCM permutation of the DOF blocks (4 DOFs each) for the band ``ab`` (LAPACK layout, DOF -> position
    ``perm``) plus the off-band triplets (rows, cols).

    Returns (newpos (n_dof,) int64: each DOF's position in the reordered matrix, kl2, ku2): the lower and upper
    bandwidths of the whole pattern in the new order."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    n = ab.shape[1]
    nb = (n + 3) // 4
    indptr, indices = block_graph(kl, ku, perm, rows, cols, nb)
    G = sp.csr_matrix((np.ones(indices.size, dtype=np.int8), indices, indptr), shape=(nb, nb))
    order = reverse_cuthill_mckee(G, symmetric_mode=True)
    newpos = new_positions(order.astype(np.int64), n)
    kl2, ku2 = bandwidths(kl, ku, perm, rows, cols, newpos)
    return newpos, kl2, ku2


@njit(cache=True)
def block_graph(kl, ku, perm, rows, cols, nb):
    """CSR (indptr, indices) of the symmetric block graph: blocks i, j (DOF // 4) are adjacent if a band
    position or a triplet couples their DOFs. Duplicates removed (a marker per row)."""
    n = perm.shape[0]
    inv = np.empty(n, dtype=np.int64)
    for d in range(n):
        inv[perm[d]] = d
    m = 0
    for j in range(n):
        m += min(n - 1, j + kl) - max(0, j - ku) + 1
    src = np.empty(2 * (m + rows.shape[0]), dtype=np.int64)
    dst = np.empty_like(src)
    c = 0
    for j in range(n):
        bj = inv[j] // 4
        for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
            bi = inv[i] // 4
            src[c] = bi
            dst[c] = bj
            src[c + 1] = bj
            dst[c + 1] = bi
            c += 2
    for k in range(rows.shape[0]):
        bi = rows[k] // 4
        bj = cols[k] // 4
        src[c] = bi
        dst[c] = bj
        src[c + 1] = bj
        dst[c + 1] = bi
        c += 2
    count = np.zeros(nb + 1, dtype=np.int64)
    for k in range(c):
        count[src[k] + 1] += 1
    for b in range(nb):
        count[b + 1] += count[b]
    fill = count[:-1].copy()
    tmp = np.empty(c, dtype=np.int64)
    for k in range(c):
        tmp[fill[src[k]]] = dst[k]
        fill[src[k]] += 1
    mark = np.full(nb, -1, dtype=np.int64)
    indptr = np.zeros(nb + 1, dtype=np.int64)
    indices = np.empty(c, dtype=np.int64)
    u = 0
    for b in range(nb):
        for k in range(count[b], count[b + 1]):
            t = tmp[k]
            if mark[t] != b:
                mark[t] = b
                indices[u] = t
                u += 1
        indptr[b + 1] = u
    return indptr, indices[:u].astype(np.int32)


@njit(cache=True)
def new_positions(order, n):
    """Each DOF's position when the blocks are taken in ``order`` (their DOFs kept together, in order)."""
    nb = order.shape[0]
    newpos = np.empty(n, dtype=np.int64)
    p = 0
    for k in range(nb):
        b = order[k]
        for d in range(4 * b, min(4 * b + 4, n)):
            newpos[d] = p
            p += 1
    return newpos


@njit(cache=True)
def bandwidths(kl, ku, perm, rows, cols, newpos):
    """Lower and upper bandwidths, in the new order, of the band's non-zero pattern and the triplets."""
    n = perm.shape[0]
    inv = np.empty(n, dtype=np.int64)
    for d in range(n):
        inv[perm[d]] = d
    lo = 0
    up = 0
    for j in range(n):
        pj = newpos[inv[j]]
        for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
            dd = newpos[inv[i]] - pj
            lo = max(lo, dd)
            up = max(up, -dd)
    for k in range(rows.shape[0]):
        dd = newpos[rows[k]] - newpos[cols[k]]
        lo = max(lo, dd)
        up = max(up, -dd)
    return lo, up


@njit(cache=True)
def scatter(ab, kl, ku, perm, rows, cols, vals, newpos, kl2, ku2, out):
    """out (2 kl2 + ku2 + 1, n), LAPACK's dgbsv layout in the new order, = the band ``ab`` + the triplets."""
    n = perm.shape[0]
    inv = np.empty(n, dtype=np.int64)
    for d in range(n):
        inv[perm[d]] = d
    off, off2 = kl + ku, kl2 + ku2
    for j in range(n):
        pj = newpos[inv[j]]
        for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
            v = ab[off + i - j, j]
            if v != 0.0:
                out[off2 + newpos[inv[i]] - pj, pj] += v
    for k in range(rows.shape[0]):
        i = newpos[rows[k]]
        j = newpos[cols[k]]
        out[off2 + i - j, j] += vals[k]


def banded_solve(ab, kl, ku, perm, rows, cols, vals, rhs, newpos, kl2, ku2):
    """Solve (band + triplets) x = rhs in the reordered band (LAPACK dgbsv). Returns (x, info)."""
    from scipy.linalg.lapack import dgbsv

    n = rhs.shape[0]
    out = np.zeros((2 * kl2 + ku2 + 1, n), order="F")
    scatter(ab, kl, ku, perm, rows, cols, vals, newpos, kl2, ku2, out)
    b = np.empty(n)
    b[newpos] = rhs
    _, _, x, info = dgbsv(kl2, ku2, out, b, overwrite_ab=True, overwrite_b=True)
    return x[newpos], int(info)
