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

from ..linalg import componentwise_ratio


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
def symmetric_part(ab, kl, ku):
    """The band ``ab`` (LAPACK general-band layout, kl = ku) replaced in place by its symmetric part (A + A^T) / 2;
    returns max |A - A^T| / 2 over the band (the skew part dropped)."""
    n = ab.shape[1]
    off = kl + ku
    skew = 0.0
    for j in range(n):
        for i in range(j + 1, min(n - 1, j + kl) + 1):
            a = ab[off + i - j, j]
            b = ab[off + j - i, i]
            m = 0.5 * (a + b)
            skew = max(skew, abs(a - m))
            ab[off + i - j, j] = m
            ab[off + j - i, i] = m
    return skew


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


def banded_solve(ab, kl, ku, perm, rows, cols, vals, rhs, newpos, kl2, ku2, chol=None, keep=None):
    """Solve (band + triplets) x = rhs in the reordered band: with ``chol`` (a BandCholesky) and a symmetric
    pattern (kl2 = ku2) first by the banded Cholesky (``cholesky_solve``), else, or if that is refused, by LAPACK's
    dgbsv. Returns (x, info). With ``keep`` (a dict) the factors are left there for ``banded_resolve``."""
    from scipy.linalg.lapack import dgbsv

    from ..linalg import LDLT_BACKWARD_ERROR

    n = rhs.shape[0]
    if chol is not None and kl2 == ku2:
        if chol.skip > 0:
            chol.skip -= 1
        else:
            x = cholesky_solve(ab, kl, ku, perm, rows, cols, vals, rhs, newpos, kl2, chol, LDLT_BACKWARD_ERROR)
            if x is not None:
                chol.counts["cholesky"] += 1
                if keep is not None:
                    keep.update(kind="cholesky", factors=chol.factors, newpos=newpos)
                return x, 0
            chol.counts["cholesky_refused"] += 1
            chol.skip = CHOLESKY_RETRY_AFTER
        chol.counts["dgbsv"] += 1
    out = np.zeros((2 * kl2 + ku2 + 1, n), order="F")
    scatter(ab, kl, ku, perm, rows, cols, vals, newpos, kl2, ku2, out)
    b = np.empty(n)
    b[newpos] = rhs
    lu, piv, x, info = dgbsv(kl2, ku2, out, b, overwrite_ab=True, overwrite_b=True)
    if keep is not None and info == 0:
        keep.update(kind="lu", factors=(lu, piv, kl2, ku2), newpos=newpos)
    return x[newpos], int(info)


def banded_resolve(keep, rhs):
    """x = A^-1 rhs with the factors a ``banded_solve(..., keep=keep)`` left (no new factorisation, no refinement:
    for a correction of the step that solve gave); None if there are none. On the Cholesky path the factor is that
    of A's lower triangle taken as symmetric, so x solves A up to its skew part (the frame transport's): an
    approximate correction, which the line search's energy test and passage check judge like any other."""
    from scipy.linalg.lapack import dgbtrs, dpbtrs

    kind = keep.get("kind")
    if kind is None:
        return None
    newpos = keep["newpos"]
    b = np.empty(rhs.shape[0])
    b[newpos] = rhs
    if kind == "cholesky":
        y, info = dpbtrs(keep["factors"], b, lower=1)
    else:
        lu, piv, kl2, ku2 = keep["factors"]
        y, info = dgbtrs(lu, kl2, ku2, b, piv)
    return y[newpos] if info == 0 else None


# the symmetric path (banded_solve with a BandCholesky): LAPACK's banded Cholesky (dpbtrf, a quarter of the flops
# of dgbsv's LU with partial pivoting; measured 0.75 against 2.6-4.4 ms on the plectoneme's Newton matrices at
# n = 400, kl2 = 43-50) of the matrix's lower triangle, each solution refined against the whole matrix and accepted
# at the no-contact band path's backward error (der/linalg.py LDLT_BACKWARD_ERROR: what LU with partial pivoting
# achieves); otherwise -- not positive definite, a skew part that refinement does not bring down -- dgbsv, and
# dgbsv straight away for the next CHOLESKY_RETRY_AFTER solves
CHOLESKY_REFINEMENTS = 3
CHOLESKY_RETRY_AFTER = 8


class BandCholesky:
    """What the symmetric path keeps from one contact solve to the next: the lower band's buffer, the count of
    solves left to send straight to dgbsv after a refusal, and how each solve went (``counts``)."""

    def __init__(self):
        self.low = None
        self.factors = None
        self.skip = 0
        self.counts = {"cholesky": 0, "dgbsv": 0, "cholesky_refused": 0}

    def buffer(self, kd, n):
        if self.low is None or self.low.shape != (kd + 1, n):
            self.low = np.zeros((kd + 1, n), order="F")
        else:
            self.low.fill(0.0)
        return self.low


@njit(cache=True)
def scatter_lower(ab, kl, ku, perm, rows, cols, vals, newpos, kd, out):
    """out (kd + 1, n), LAPACK's lower symmetric band layout in the new order (out[i - j, j] = A[i, j], i >= j),
    += the lower triangle of the band ``ab`` + the triplets (the upper triangle is not read)."""
    n = perm.shape[0]
    inv = np.empty(n, dtype=np.int64)
    for d in range(n):
        inv[perm[d]] = d
    off = kl + ku
    for j in range(n):
        pj = newpos[inv[j]]
        for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
            v = ab[off + i - j, j]
            if v != 0.0:
                d = newpos[inv[i]] - pj
                if d >= 0:
                    out[d, pj] += v
    for k in range(rows.shape[0]):
        d = newpos[rows[k]] - newpos[cols[k]]
        if d >= 0:
            out[d, newpos[cols[k]]] += vals[k]


@njit(cache=True)
def residual(ab, kl, ku, perm, rows, cols, vals, x, rhs, r):
    """r = rhs - A x for A = the band ``ab`` + the triplets (DOF order), and the componentwise backward error
    max_i |r_i| / (|A| |x| + |rhs|)_i (a row with a residual and a zero denominator: infinity)."""
    n = perm.shape[0]
    inv = np.empty(n, dtype=np.int64)
    for d in range(n):
        inv[perm[d]] = d
    s = np.empty(n)
    for i in range(n):
        r[i] = rhs[i]
        s[i] = abs(rhs[i])
    off = kl + ku
    for j in range(n):
        dj = inv[j]
        xj = x[dj]
        axj = abs(xj)
        for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
            a = ab[off + i - j, j]
            di = inv[i]
            r[di] -= a * xj
            s[di] += abs(a) * axj
    for k in range(rows.shape[0]):
        a = vals[k]
        xj = x[cols[k]]
        r[rows[k]] -= a * xj
        s[rows[k]] += abs(a) * abs(xj)
    return componentwise_ratio(r, s)


def cholesky_solve(ab, kl, ku, perm, rows, cols, vals, rhs, newpos, kd, chol, tol):
    """x with (band + triplets) x = rhs from the banded Cholesky of the reordered lower triangle, refined against
    the whole matrix; None if it is not positive definite or the backward error stays above ``tol``."""
    from scipy.linalg.lapack import dpbtrf, dpbtrs

    n = rhs.shape[0]
    low = chol.buffer(kd, n)
    scatter_lower(ab, kl, ku, perm, rows, cols, vals, newpos, kd, low)
    c, info = dpbtrf(low, lower=1, overwrite_ab=1)
    if info != 0:
        return None
    chol.factors = c
    x = np.zeros(n)
    r = np.array(rhs, dtype=float)
    b = np.empty(n)
    last = np.inf
    for _ in range(1 + CHOLESKY_REFINEMENTS):
        b[newpos] = r
        y, info = dpbtrs(c, b, lower=1, overwrite_b=1)
        if info != 0:
            return None
        x += y[newpos]
        err = residual(ab, kl, ku, perm, rows, cols, vals, x, rhs, r)
        if err <= tol:
            return x
        if not err <= 0.1 * last:
            return None
        last = err
    return None
