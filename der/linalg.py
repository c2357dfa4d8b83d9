"""Banded storage of the rod's stiffness matrix and its factorisation.

The stiffness of an open rod is banded in the interleaved DOF order (half-bandwidth 10: a vertex stencil spans
11 consecutive DOFs). A ring wraps around; reordering its nodes as 0, N-1, 1, N-2, 2, ... ("folding" the ring)
makes it banded again with half-bandwidth 19. Matrices are kept in LAPACK general-band storage
``ab[kl + ku + i - j, j] = A[i, j]`` (with ``kl`` spare rows for pivoting); ``band_solve`` factorises a band
with kl = ku by LDL^T without pivoting of its symmetric lower triangle (a quarter of the flops of banded LU; the
factor kept in the kl spare rows), refines the solution against the band and accepts it on its componentwise
backward error, else solves with LAPACK's ``dgbsv`` (issue 17). Nothing is ever dense.
"""
import numpy as np
from numba import njit


def safe_norm(v):
    """Euclidean norm of a vector without overflow or underflow (scaled by its largest entry, like np.hypot):
    |(1e200, 0, 0)| is 1e200, not inf."""
    v = np.asarray(v, dtype=float)
    m = float(np.abs(v).max()) if v.size else 0.0
    if m == 0.0 or not np.isfinite(m):
        return m
    return m * float(np.sqrt(((v / m) ** 2).sum()))


@njit(cache=True)
def dot(a, b):
    """a . b for 1-d float arrays, in this thread.

    The solvers' dot products go here rather than to ``a @ b``: OpenBLAS runs a dot product of more than about
    10^4 entries on all its threads, which then spin-wait after it; on a machine whose cores are busy that made
    every following kernel (assembly, dgbsv) of a Newton iteration 2-4x slower (issue 17: 0.52 s -> 0.18 s for
    a 10^4-edge helix)."""
    n = a.shape[0]
    s0 = s1 = s2 = s3 = 0.0
    m = n - n % 4
    for i in range(0, m, 4):
        s0 += a[i] * b[i]
        s1 += a[i + 1] * b[i + 1]
        s2 += a[i + 2] * b[i + 2]
        s3 += a[i + 3] * b[i + 3]
    for i in range(m, n):
        s0 += a[i] * b[i]
    return (s0 + s1) + (s2 + s3)


@njit(cache=True)
def dot_abs(a, b):
    """sum_i a_i |b_i| for 1-d float arrays, in this thread and without the temporary ``np.abs(b)`` (see ``dot``)."""
    n = a.shape[0]
    s0 = s1 = s2 = s3 = 0.0
    m = n - n % 4
    for i in range(0, m, 4):
        s0 += a[i] * abs(b[i])
        s1 += a[i + 1] * abs(b[i + 1])
        s2 += a[i + 2] * abs(b[i + 2])
        s3 += a[i + 3] * abs(b[i + 3])
    for i in range(m, n):
        s0 += a[i] * abs(b[i])
    return (s0 + s1) + (s2 + s3)


@njit(cache=True)
def dot_difference(a, x, y, absolute=False):
    """``dot(a, x - y)`` (``dot_abs(a, x - y)`` with ``absolute``) without the temporary ``x - y``: the same
    differences and sums in the same order, bitwise (the implicit solver's step, issue 17)."""
    n = a.shape[0]
    s0 = s1 = s2 = s3 = 0.0
    m = n - n % 4
    if absolute:
        for i in range(0, m, 4):
            s0 += a[i] * abs(x[i] - y[i])
            s1 += a[i + 1] * abs(x[i + 1] - y[i + 1])
            s2 += a[i + 2] * abs(x[i + 2] - y[i + 2])
            s3 += a[i + 3] * abs(x[i + 3] - y[i + 3])
        for i in range(m, n):
            s0 += a[i] * abs(x[i] - y[i])
    else:
        for i in range(0, m, 4):
            s0 += a[i] * (x[i] - y[i])
            s1 += a[i + 1] * (x[i + 1] - y[i + 1])
            s2 += a[i + 2] * (x[i + 2] - y[i + 2])
            s3 += a[i + 3] * (x[i + 3] - y[i + 3])
        for i in range(m, n):
            s0 += a[i] * (x[i] - y[i])
    return (s0 + s1) + (s2 + s3)


def band_layout(n_nodes, closed):
    """(kl, ku, perm): half-bandwidths and the DOF -> banded-position permutation."""
    n_dof = 4 * n_nodes
    if not closed:
        return 10, 10, np.arange(n_dof, dtype=np.int64)
    pos = np.empty(n_nodes, dtype=np.int64)
    k = np.arange(n_nodes)
    first = k <= (n_nodes - 1) // 2
    pos[first] = 2 * k[first]
    pos[~first] = 2 * (n_nodes - 1 - k[~first]) + 1
    perm = (4 * pos[:, None] + np.arange(4)[None, :]).ravel()
    return 19, 19, perm.astype(np.int64)


def new_band(n_dof, kl, ku):
    return np.zeros((2 * kl + ku + 1, n_dof), order="F")


@njit(cache=True)
def zero_band(ab):
    """ab <- 0, column by column (contiguous in Fortran order; ``ab[:, :] = 0`` in numba walks it row by row,
    one cache line per entry once the band outgrows the cache)."""
    for j in range(ab.shape[1]):
        for i in range(ab.shape[0]):
            ab[i, j] = 0.0


@njit(cache=True, inline="always")
def zero_band_column(ab, j):
    """ab[:, j] <- 0 (contiguous in Fortran order)."""
    for i in range(ab.shape[0]):
        ab[i, j] = 0.0


@njit(cache=True)
def constrain_band(ab, kl, ku, perm, fixed, diag):
    """Replace rows and columns of fixed DOFs by identity (times ``diag``), keeping the band."""
    n = ab.shape[1]
    off = kl + ku
    for d in range(fixed.shape[0]):
        if not fixed[d]:
            continue
        p = perm[d]
        for j in range(max(0, p - kl), min(n - 1, p + ku) + 1):   # row p
            ab[off + p - j, j] = 0.0
        for i in range(max(0, p - ku), min(n - 1, p + kl) + 1):   # column p
            ab[off + i - p, p] = 0.0
        ab[off, p] = diag


@njit(cache=True)
def add_diagonal(ab, kl, ku, perm, values, scale):
    off = kl + ku
    for d in range(values.shape[0]):
        p = perm[d]
        ab[off, p] += scale * values[d]


@njit(cache=True)
def band_diagonal_abs(ab, kl, ku, perm, out):
    """out[d] = |A_dd| for the band matrix in original DOF order (the implicit solver's damping diagonal): one
    entry per column of the Fortran-ordered band. (``np.take`` of the band's diagonal row, strided by 2 kl + ku + 1
    doubles, cost 0.16 s per call at 10^6 edges, 6x this loop.)"""
    off = kl + ku
    for d in range(perm.shape[0]):
        out[d] = abs(ab[off, perm[d]])
    return out


@njit(cache=True)
def band_matvec(ab, kl, ku, perm, x, out, absolute=False):
    """out = A x (or |A| |x| with ``absolute``) for the band matrix in original DOF order."""
    n = ab.shape[1]
    off = kl + ku
    xp = np.empty(n)
    for d in range(n):
        xp[perm[d]] = x[d]
    yp = np.zeros(n)
    # the branch outside the inner loops: each column's update of yp is then a straight loop (vectorised by the
    # compiler; the sums into each yp[i] keep their order, column by column, so the result is unchanged)
    if absolute:
        for j in range(n):
            xj = xp[j]
            for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
                yp[i] += abs(ab[off + i - j, j] * xj)
    else:
        for j in range(n):
            xj = xp[j]
            for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
                yp[i] += ab[off + i - j, j] * xj
    for d in range(n):
        out[d] = yp[perm[d]]


@njit(cache=True)
def band_to_coo(ab, kl, ku, perm):
    """(rows, cols, vals) of the non-zeros, in original DOF order."""
    n = ab.shape[1]
    off = kl + ku
    inv = np.empty(n, dtype=np.int64)
    for d in range(n):
        inv[perm[d]] = d
    cnt = 0
    for j in range(n):
        for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
            if ab[off + i - j, j] != 0.0:
                cnt += 1
    rows = np.empty(cnt, dtype=np.int64)
    cols = np.empty(cnt, dtype=np.int64)
    vals = np.empty(cnt)
    c = 0
    for j in range(n):
        for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
            v = ab[off + i - j, j]
            if v != 0.0:
                rows[c] = inv[i]
                cols[c] = inv[j]
                vals[c] = v
                c += 1
    return rows, cols, vals


def band_to_sparse(ab, kl, ku, perm):
    """The band matrix as a scipy CSR matrix in original DOF order (for eigen-solvers and tests)."""
    import scipy.sparse as sp

    rows, cols, vals = band_to_coo(ab, kl, ku, perm)
    n = ab.shape[1]
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


# band_solve: the symmetric LDL^T path's acceptance test, the componentwise backward error of the solution
# max_i |A x - b|_i / (|A| |x| + |b|)_i (Oettli-Prager: x solves a system whose every entry is that close to A's
# and b's). LDL^T refined reaches 2.6e-14 and 5.5e-13 on the wound helix's indefinite Newton matrix at its start
# (tools/scaling.py, 10^5 and 3 10^5 edges), where LAPACK's dgbsv itself reaches 6.4e-12 and 7.3e-12; at 10^6
# edges (3111 negative pivots) refinement stops at 1.3e-11 (dgbsv: 4.7e-12) and the solve goes to dgbsv.
# 1e-11 (dgbsv's level) let the writhed ring of test_stability end at another state (its symmetry analysis then
# failed); with this round's exact edge arithmetic so did 1e-13 and 1e-14 (the writhed ring at n = 80 ends at
# another point of its nearly free sliding valley, and the supercoiled ring of test_contact_perf at twist 8 took
# 500 iterations instead of 49): paths through nearly free modes follow the linear solve's rounding, so a solution
# is accepted only at 1e-15, as accurate as LAPACK's on such matrices. Measured: the helix's Newton solves pass
# at 10^4 edges (3 of 3); at 10^5 and 10^6 its start matrix (311 and 3111 negative pivots) is refused -- refined
# LDL^T stops at 4.9e-14 at 10^5, where dgbsv reaches 1.9e-11 (2.4e-16 after one refinement with its own
# factors), and at 1.3e-11 at 10^6 -- and the next ones, positive definite, pass after one refinement (3e-16);
# a threshold of dgbsv's level would change nothing at 10^6. See LDLT_RETRY_AFTER.
LDLT_BACKWARD_ERROR = 1e-15
LDLT_REFINEMENTS = 3
# after a refused LDL^T, a band_solve with the same BandLDLT goes straight to dgbsv this many times before it
# tries again: a Newton matrix whose skew part defeats refinement (the load stiffness of an end torque on a ring
# against its soft modes) stays so from iteration to iteration, and each refusal costs about one dgbsv. The first
# refusal of an indefinite matrix refined to within LDLT_RETRY_BELOW (near LAPACK's own unrefined backward error on
# such matrices, 5e-12 - 2e-11: the growth of its negative pivots, not a skew part, stopped the refinement) is
# instead followed by a new attempt at the next solve: Newton's matrices turn positive definite as it nears a
# stable equilibrium (the wound helix: its start matrix, with 311 negative pivots at 10^5 edges and 3111 at 10^6,
# is refined to 1e-13 and 1.3e-11 and refused; the next ones have none and pass after one refinement, a
# factorisation 6x cheaper than dgbsv's at 10^5). The ring under an end torque (1 negative pivot, refinement
# stuck at 8.5e-9 at 10^4 edges: its skew part) keeps waiting, as does a second refusal in a row.
LDLT_RETRY_AFTER = 8
LDLT_RETRY_BELOW = 1e-10
# False: every refusal waits LDLT_RETRY_AFTER solves (the code before; tools/scaling.py --baseline)
LDLT_RETRY_INDEFINITE = True
# which solver each band_solve used: the symmetric LDL^T (accepted), or dgbsv (by design: kl != ku, or after
# the LDL^T was refused: a zero pivot or a backward error that refinement did not bring down)
BAND_SOLVES = {"ldlt": 0, "dgbsv": 0, "ldlt_refused": 0}
# False: band_solve always uses dgbsv (the comparison runs of tools/bench_kernels.py and tools/scaling.py)
USE_LDLT = True
# band_solve keeps the unit lower factor L in the kl spare rows of the general-band storage (rows 0..kl-1, which
# dgbsv needs for its fill-in and ignores on entry; L[j, s - 1] = ab[s - 1, j], each column of the factor still
# contiguous): no second n x kl array (10^6 edges: 320 MB less at the peak, and no first touch of it), the
# solves ~1.3x slower (a column every 2 kl + ku + 1 doubles; measured 0.33 against 0.26 s for a refined solve at
# 4 10^6 unknowns, bitwise the same solution). False: a separate compact L (the code before; --baseline)
LDLT_IN_BAND = True


class BandLDLT:
    """Work arrays of the symmetric band factorisation ``band_ldlt_compact`` for matrices of ``n`` rows and
    half-bandwidth ``b`` (allocated by the first solve that uses them), reused from solve to solve
    (``band_solve(..., ldlt=...)``: no allocation, and no first touch of fresh pages, per Newton iteration; with
    LDLT_IN_BAND ``L`` is a view of the band's spare rows, valid until the band is assembled or factorised
    again). After a solve that used it: ``L``, ``D`` the factors of the
    symmetric part of the last matrix factorised (in band order) and ``negatives`` its number of negative
    pivots (= negative eigenvalues, Sylvester's law of inertia), ``accepted`` whether its solution passed the
    backward-error test (else the solve went to dgbsv), ``backward_error`` the error reached."""

    def __init__(self, n, b):
        self.n, self.b = n, b
        self.release()
        self.negatives = -1
        self.accepted = False
        self.backward_error = np.inf
        self.skip = 0           # band solves left to send straight to dgbsv after a refusal (LDLT_RETRY_AFTER)
        self.refusals = 0       # LDL^T attempts refused since the last accepted one
        # which factors the last band_solve left for band_resolve: "ldlt" (L, D; the band's entries untouched, its
        # kl spare rows holding L with LDLT_IN_BAND), "dgbsv" (the LU factors in the band itself, their pivots in
        # ``piv``) or None
        self.factors = None
        self.piv = None

    def release(self):
        """Drop the work arrays (allocated again by the next solve that uses them): after a refused
        factorisation, so that the dgbsv solves that follow do not carry them (10^6 edges: 416 MB)."""
        self.L = self.D = self.r = self.x = None
        self.factors = self.piv = self.lu = None

    def in_band(self, ab, b):
        """The work arrays for the band ``ab`` (general-band storage, ``b`` = kl = ku) with L in its spare rows
        (LDLT_IN_BAND): ``L`` a view, D and the solve's vectors allocated if missing or of another size."""
        n = ab.shape[1]
        if self.D is None or self.D.shape[0] != n:
            self.D = np.empty(n)
            self.r = np.empty(n)
            self.x = np.empty(n)
        self.n, self.b = n, b
        self.L = ab[:b, :].T

    def ensure(self, n, b):
        """The work arrays for ``n`` rows and half-bandwidth ``b`` (allocated if missing or of another size, or
        if ``L`` is a view of a band's spare rows: ``in_band``)."""
        if self.L is None or self.L.shape != (n, b) or not self.L.flags.c_contiguous:
            self.n, self.b = n, b
            self.L = np.empty((n, b))    # L[j, s - 1] = l_{j+s, j}: column j of the unit lower factor, contiguous
            self.D = np.empty(n)
            self.r = np.empty(n)
            self.x = np.empty(n)


@njit(cache=True)
def band_ldlt_compact(ab, kl, ku, L, D):
    """LDL^T factorisation without pivoting of the symmetric matrix M whose lower triangle is that of the band
    matrix A in ``ab`` (LAPACK general-band storage, ``kl`` = ``ku`` = b; not modified: M = A for a symmetric A,
    otherwise the solves refine against A), into ``L`` (n, b) -- ``L[j, s - 1]`` = l_{j+s, j}, each column of
    the factor contiguous: the triangular solves then stream it; a factor kept in the band's spare rows, one column
    every 2 kl + ku + 1 doubles, makes a refined solve ~1.3x slower (LDLT_IN_BAND) -- and the pivots
    ``D``. Right-looking by columns, the trailing b columns updated in ``L`` and ``D`` themselves (each enters
    from ``ab`` b steps before its turn): O(n b^2) flops, a quarter of banded LU with partial pivoting. Compiled
    with ``kl`` a constant for der's two bandwidths (10: an open rod, 19: a folded ring; its short loops unrolled,
    measured 1.5-1.8x faster; 7: edge coordinates).
    Returns the number of negative pivots (the inertia of M, Sylvester), or -1 on a zero or non-finite pivot."""
    # the half-bandwidths of der's bands spelled out: the kernel is inlined with b a constant (a literal-typed
    # dispatch from Python costs milliseconds per call)
    if kl == 10:
        return _band_ldlt_compact(ab, 10, ku, L, D)
    if kl == 7:          # edge coordinates (der.solvers.edge_coordinates)
        return _band_ldlt_compact(ab, 7, ku, L, D)
    if kl == 19:
        return _band_ldlt_compact(ab, 19, ku, L, D)
    return _band_ldlt_compact(ab, kl, ku, L, D)


@njit(cache=True, inline="always")
def _band_ldlt_compact(ab, b, ku, L, D):
    n = ab.shape[1]
    off = b + ku
    l = np.empty(b)
    negatives = 0
    for c in range(min(n, b)):               # the first b columns, before their turn
        D[c] = ab[off, c]
        for s in range(1, b + 1):
            L[c, s - 1] = ab[off + s, c] if c + s < n else 0.0
    for k in range(n):
        c = k + b                            # column k + b enters
        if c < n:
            D[c] = ab[off, c]
            for s in range(1, b + 1):
                L[c, s - 1] = ab[off + s, c] if c + s < n else 0.0
        dk = D[k]
        if dk == 0.0 or not np.isfinite(dk):
            return -1
        if dk < 0.0:
            negatives += 1
        inv = 1.0 / dk
        for s in range(b):
            l[s] = L[k, s] * inv
            L[k, s] = l[s]
        if k + b < n:                        # rank-1 update of the trailing columns k+1..k+b (full width)
            for t in range(1, b + 1):
                lt = l[t - 1] * dk
                D[k + t] -= l[t - 1] * lt
                for u in range(b - t):       # row k + t + 1 + u of column k + t
                    L[k + t, u] -= l[u + t] * lt
        else:
            for t in range(1, n - k):
                lt = l[t - 1] * dk
                D[k + t] -= l[t - 1] * lt
                for u in range(b - t):
                    L[k + t, u] -= l[u + t] * lt
    return negatives


@njit(cache=True, inline="always")
def _ldlt_compact_solve(L, D, y, b):
    """y <- (L D L^T)^-1 y in place (band order), with the factors of ``band_ldlt_compact`` (``b`` = L.shape[1])."""
    n = L.shape[0]
    for k in range(n):                       # L z = y, by columns of L
        yk = y[k]
        for s in range(1, min(b, n - 1 - k) + 1):
            y[k + s] -= L[k, s - 1] * yk
    for k in range(n):
        y[k] /= D[k]
    for k in range(n - 1, -1, -1):           # L^T x = z
        acc = y[k]
        for s in range(1, min(b, n - 1 - k) + 1):
            acc -= L[k, s - 1] * y[k + s]
        y[k] = acc


@njit(cache=True)
def ldlt_compact_solve_block(L, D, Y):
    """Y <- (L D L^T)^-1 Y in place for the columns of ``Y`` (n, m), C order, band order, with the factors of
    ``band_ldlt_compact``: one pass over the factor for all m right-hand sides (the innermost loop runs over them)."""
    n, b = L.shape
    m = Y.shape[1]
    for k in range(n):                       # L z = y, by columns of L
        for s in range(1, min(b, n - 1 - k) + 1):
            l = L[k, s - 1]
            if l != 0.0:
                for c in range(m):
                    Y[k + s, c] -= l * Y[k, c]
    for k in range(n):
        inv = 1.0 / D[k]
        for c in range(m):
            Y[k, c] *= inv
    for k in range(n - 1, -1, -1):           # L^T x = z
        for s in range(1, min(b, n - 1 - k) + 1):
            l = L[k, s - 1]
            if l != 0.0:
                for c in range(m):
                    Y[k, c] -= l * Y[k + s, c]


@njit(cache=True, inline="always")
def componentwise_ratio(r, s):
    """max_i |r_i| / s_i over the rows of s, the componentwise backward error of a residual r against s = |A| |x| + |b| (a row whose
    residual is 0 counts 0; one with a residual and a zero or non-finite denominator, or a non-finite residual:
    infinity)."""
    worst = 0.0
    for i in range(s.shape[0]):
        ri = abs(r[i])
        if ri == 0.0:
            continue
        if not (s[i] > 0.0) or not np.isfinite(ri):
            return np.inf
        worst = max(worst, ri / s[i])
    return worst


@njit(cache=True, inline="always")
def _band_residual(ab, kl, ku, x, rhs, r):
    """r = rhs - A x (band order, A in rows kl.. of the general-band storage) and the componentwise backward
    error max_i |r_i| / (|A| |x| + |rhs|)_i, in one pass over the band (a row whose residual is 0 counts 0; one
    with a residual and a zero denominator: infinity)."""
    n = ab.shape[1]
    off = kl + ku
    s = np.empty(n)
    for i in range(n):
        r[i] = rhs[i]
        s[i] = abs(rhs[i])
    for j in range(n):
        xj = x[j]
        axj = abs(xj)
        for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
            a = ab[off + i - j, j]
            r[i] -= a * xj
            s[i] += abs(a) * axj
    return componentwise_ratio(r, s)


@njit(cache=True)
def _ldlt_solve_refined(ab, kl, ku, L, D, bp, x, r, tol, refinements):
    """x with A x = bp (band order) from the LDL^T of A's symmetric part (``band_ldlt_compact``), refined against
    A itself (x += M^-1 (bp - A x): a non-symmetric A converges as fast as its skew part is small) until the
    backward error is at most ``tol``. Returns the backward error reached. (``kl`` = ``ku`` constants for der's
    two bandwidths, as in ``band_ldlt_compact``.)"""
    if kl == 10 and ku == 10:
        return _ldlt_solve_refined_b(ab, 10, 10, L, D, bp, x, r, tol, refinements)
    if kl == 7 and ku == 7:
        return _ldlt_solve_refined_b(ab, 7, 7, L, D, bp, x, r, tol, refinements)
    if kl == 19 and ku == 19:
        return _ldlt_solve_refined_b(ab, 19, 19, L, D, bp, x, r, tol, refinements)
    return _ldlt_solve_refined_b(ab, kl, ku, L, D, bp, x, r, tol, refinements)


@njit(cache=True, inline="always")
def _ldlt_solve_refined_b(ab, kl, ku, L, D, bp, x, r, tol, refinements):
    for i in range(x.shape[0]):
        x[i] = bp[i]
    _ldlt_compact_solve(L, D, x, kl)
    err = _band_residual(ab, kl, ku, x, bp, r)
    for _ in range(refinements):
        if err <= tol:
            break
        _ldlt_compact_solve(L, D, r, kl)
        for i in range(x.shape[0]):
            x[i] += r[i]
        last = err
        err = _band_residual(ab, kl, ku, x, bp, r)
        if not err <= 0.1 * last:
            break        # not contracting (a skew part as stiff as the softest mode): refused, no more passes
    return err


@njit(cache=True)
def _is_identity(perm):
    for d in range(perm.shape[0]):
        if perm[d] != d:
            return False
    return True


def band_solve(ab, kl, ku, perm, rhs, overwrite=True, ldlt=None):
    """Solve A x = rhs (A in general-band storage, ``rhs`` (n,) or (n, k) in DOF order); ``ab`` is overwritten
    by factors (with ``overwrite``; else a copy is factorised).

    A band with kl = ku is first factorised by LDL^T without pivoting of its symmetric part
    (``band_ldlt_compact``: a quarter of the flops of banded LU; the entries of ``ab`` untouched, its kl spare rows
    -- the rows dgbsv fills in, ignored on entry -- holding L with LDLT_IN_BAND), each solution refined against
    A and accepted only when its componentwise backward error is at most LDLT_BACKWARD_ERROR (what LU with partial
    pivoting achieves); otherwise -- a zero pivot, an indefinite matrix whose pivots grow, a skew part too large
    -- the same ``ab`` goes to LAPACK's ``dgbsv``. ``ldlt``: a ``BandLDLT`` whose work arrays are reused (and
    which then holds the factors and the inertia of the last matrix); ``BAND_SOLVES`` counts the paths.

    Returns ``(x, info)``; ``info > 0`` means an exactly singular pivot of dgbsv (x is then invalid).
    """
    from scipy.linalg.lapack import dgbsv

    if not overwrite:
        ab = ab.copy(order="F")
    rhs = np.asarray(rhs, dtype=float)
    n = ab.shape[1]
    identity = _is_identity(perm)
    if ldlt is not None and ldlt.skip > 0:
        ldlt.skip -= 1
        ldlt.accepted, ldlt.negatives, ldlt.backward_error = False, -1, np.inf
    elif USE_LDLT and kl == ku and ab.shape[0] == 2 * kl + ku + 1 and n > 0:
        if ldlt is None:
            ldlt = BandLDLT(n, kl)
        if LDLT_IN_BAND:
            ldlt.in_band(ab, kl)
        else:
            ldlt.ensure(n, kl)
        ldlt.accepted, ldlt.backward_error = False, np.inf
        ldlt.factors, ldlt.piv = None, None
        ldlt.negatives = band_ldlt_compact(ab, kl, ku, ldlt.L, ldlt.D)
        if ldlt.negatives >= 0:
            # (no copies of a vector beyond the solution: a 10^6-edge rod's vectors are 32 MB each)
            cols = rhs.reshape(n, -1)
            xs = np.empty_like(cols)
            worst = 0.0
            for c in range(cols.shape[1]):
                bc = np.ascontiguousarray(cols[:, c]) if identity else cols[:, c][np.argsort(perm)]
                err = _ldlt_solve_refined(ab, kl, ku, ldlt.L, ldlt.D, bc, ldlt.x, ldlt.r, LDLT_BACKWARD_ERROR,
                                          LDLT_REFINEMENTS)
                worst = max(worst, err)
                if not err <= LDLT_BACKWARD_ERROR:
                    break
                xs[:, c] = ldlt.x if identity else ldlt.x[perm]
            ldlt.backward_error = worst
            if worst <= LDLT_BACKWARD_ERROR:
                ldlt.accepted = True
                ldlt.factors = "ldlt"
                ldlt.refusals = 0
                BAND_SOLVES["ldlt"] += 1
                return xs.reshape(rhs.shape), 0
        BAND_SOLVES["ldlt_refused"] += 1
        ldlt.refusals += 1
        # an indefinite matrix refused for the first time, refined near LAPACK's own accuracy (the factor's
        # growth, not a skew part, stopped it): try again at the next solve (LDLT_RETRY_AFTER)
        retry = (LDLT_RETRY_INDEFINITE and ldlt.negatives > 0 and ldlt.backward_error <= LDLT_RETRY_BELOW
                 and ldlt.refusals == 1)
        ldlt.skip = 0 if retry else LDLT_RETRY_AFTER
        if ldlt.skip > 0 or not LDLT_IN_BAND:
            ldlt.release()
        else:       # tried again at the next solve: its vectors kept (no first touch again), L's rows go to dgbsv
            ldlt.L = None
    b = np.empty_like(rhs)
    b[perm] = rhs
    BAND_SOLVES["dgbsv"] += 1
    lub, piv, xp, info = dgbsv(kl, ku, ab, b, overwrite_ab=True, overwrite_b=True)
    if ldlt is not None:
        # (``lub`` is ``ab`` itself when ``ab`` is a Fortran-ordered double band, as der's are: no copy kept)
        ldlt.factors, ldlt.piv, ldlt.lu = ("dgbsv" if info == 0 else None), piv, lub
    return xp[perm], info


def band_resolve(ab, kl, ku, perm, rhs, ldlt):
    """x with A x = rhs for the matrix the last ``band_solve(ab, ..., ldlt=ldlt)`` factorised, reusing its factors
    (no new factorisation, O(n b)): the LDL^T factors refined against the band (its entries untouched on that path), or
    dgbsv's LU factors and pivots (``dgbtrs``). ``rhs`` (n,) in DOF order. None if that solve left no factors
    (it failed, or ``ab`` was factorised since)."""
    from scipy.linalg.lapack import dgbtrs

    if ldlt is None or ldlt.factors is None:
        return None
    rhs = np.asarray(rhs, dtype=float)
    n = ab.shape[1]
    b = np.empty(n)
    b[perm] = rhs
    if ldlt.factors == "ldlt":
        _ldlt_solve_refined(ab, kl, ku, ldlt.L, ldlt.D, b, ldlt.x, ldlt.r, LDLT_BACKWARD_ERROR, LDLT_REFINEMENTS)
        return ldlt.x[perm]
    x, info = dgbtrs(ldlt.lu, kl, ku, b, ldlt.piv)
    return x[perm] if info == 0 else None


@njit(cache=True)
def band_negative_pivots(ab, kl, ku, perm, shift, mass, fixed):
    """Number of negative eigenvalues of the symmetric matrix ``K - shift M`` (K in band storage, fixed DOFs
    removed), by Sylvester's law of inertia on a banded LDL^T factorisation without pivoting (``band_ldlt``).

    Returns -1 if a pivot is too small for the count to be trusted (then the caller falls back)."""
    return band_ldlt(ab, kl, ku, perm, shift, mass, fixed, 1e-13)[2]


@njit(cache=True)
def band_ldlt(ab, kl, ku, perm, shift, mass, fixed, pivot_tol=1e-13):
    """Banded LDL^T factorisation without pivoting of the symmetric part of ``K - shift M`` (K in band storage,
    ``kl`` = ``ku`` = b; fixed DOFs replaced by identity rows), in band order. Returns ``(L, D, negatives)``:
    ``L[i, s]`` = l_{i, i-s} (unit diagonal implied), the pivots D, and the number of negative pivots (= negative
    eigenvalues, Sylvester), or -1 if a pivot is at most ``pivot_tol`` times the largest diagonal entry (an
    ill-conditioned positive definite matrix has pivots far below 1e-13 of it: a caller that checks the factors'
    backward error instead passes 0, refusing only a zero pivot). O(n b^2); solves by ``band_ldlt_solve``, O(n b)."""
    n = ab.shape[1]
    off = kl + ku
    b = kl
    inv = np.empty(n, dtype=np.int64)
    for d in range(n):
        inv[perm[d]] = d
    # symmetric band, lower part: A[i, i - s] for s = 0..b, stored as low[i, s]
    low = np.zeros((n, b + 1))
    for i in range(n):
        di = inv[i]
        for s in range(0, min(b, i) + 1):
            j = i - s
            dj = inv[j]
            if fixed[di] or fixed[dj]:
                v = 1.0 if s == 0 else 0.0
            else:
                v = 0.5 * (ab[off + i - j, j] + ab[off + j - i, i])   # symmetric part
                if s == 0:
                    v -= shift * mass[di]
            low[i, s] = v
    L = np.zeros((n, b + 1))   # L[i, s] = l_{i, i-s}, unit diagonal implied
    D = np.zeros(n)
    scale = 0.0
    for i in range(n):
        scale = max(scale, abs(low[i, 0]))
    negatives = 0
    for k in range(n):
        dk = low[k, 0]
        for s in range(1, min(b, k) + 1):
            j = k - s
            dk -= L[k, s] * L[k, s] * D[j]
        if abs(dk) <= pivot_tol * scale or not np.isfinite(dk):
            return L, D, -1
        D[k] = dk
        if dk < 0.0:
            negatives += 1
        for i in range(k + 1, min(n - 1, k + b) + 1):
            s_ik = i - k
            v = low[i, s_ik]
            for s in range(1, min(b, k) + 1):
                j = k - s
                if i - j <= b:
                    v -= L[i, i - j] * L[k, s] * D[j]
            L[i, s_ik] = v / dk
    return L, D, negatives


def band_ldlt_solve(L, D, perm, rhs):
    """x with L D L^T x = rhs (factors of ``band_ldlt``), ``rhs`` (n,) or (n, k) in original DOF order."""
    rhs = np.asarray(rhs, dtype=float)
    if rhs.ndim == 1:
        return _band_ldlt_solve1(L, D, perm, rhs)
    return _band_ldlt_solve(L, D, perm, np.ascontiguousarray(rhs))


@njit(cache=True, inline="always")
def band_ldlt_solve_inplace(L, D, y):
    """y <- (L D L^T)^-1 y in place, with the factors of ``band_ldlt`` in their own (band) order."""
    n, b1 = L.shape
    b = b1 - 1
    for k in range(n):                       # L y = rhs
        acc = y[k]
        for s in range(1, min(b, k) + 1):
            acc -= L[k, s] * y[k - s]
        y[k] = acc
    for k in range(n):                       # D z = y
        y[k] /= D[k]
    for k in range(n - 1, -1, -1):           # L^T x = z
        acc = y[k]
        for s in range(1, min(b, n - 1 - k) + 1):
            acc -= L[k + s, s] * y[k + s]
        y[k] = acc


@njit(cache=True)
def _band_ldlt_solve1(L, D, perm, rhs):
    n = L.shape[0]
    y = np.empty(n)
    for d in range(n):
        y[perm[d]] = rhs[d]
    band_ldlt_solve_inplace(L, D, y)
    out = np.empty(n)
    for d in range(n):
        out[d] = y[perm[d]]
    return out


@njit(cache=True)
def _band_ldlt_solve(L, D, perm, r2):
    n, b1 = L.shape
    b = b1 - 1
    m = r2.shape[1]
    y = np.empty((n, m))
    for d in range(n):
        for c in range(m):
            y[perm[d], c] = r2[d, c]
    for k in range(n):                       # L y = rhs
        for s in range(1, min(b, k) + 1):
            l = L[k, s]
            if l != 0.0:
                for c in range(m):
                    y[k, c] -= l * y[k - s, c]
    for k in range(n):                       # D z = y
        for c in range(m):
            y[k, c] /= D[k]
    for k in range(n - 1, -1, -1):           # L^T x = z
        for s in range(1, min(b, n - 1 - k) + 1):
            l = L[k + s, s]
            if l != 0.0:
                for c in range(m):
                    y[k, c] -= l * y[k + s, c]
    out = np.empty((n, m))
    for d in range(n):
        for c in range(m):
            out[d, c] = y[perm[d], c]
    return out


class BandLU:
    """LU factorisation of a band matrix (LAPACK dgbtrf), reused for any number of solves (dgbtrs): O(n b^2)
    once, O(n b) per solve, in original DOF order. ``ab`` (general-band storage, ``kl`` spare rows) is
    overwritten by the factors. ``info > 0`` marks an exactly singular pivot (solves are then invalid)."""

    def __init__(self, ab, kl, ku, perm):
        from scipy.linalg.lapack import dgbtrf

        self.kl, self.ku, self.perm = kl, ku, perm
        self.lu, self.piv, self.info = dgbtrf(ab, kl, ku, overwrite_ab=True)

    def solve(self, rhs, trans=False):
        """x with A x = rhs (or A^T x = rhs with ``trans``); ``rhs`` (n,) or (n, k) in DOF order."""
        from scipy.linalg.lapack import dgbtrs

        if self.info > 0:
            raise np.linalg.LinAlgError(f"band matrix exactly singular (zero pivot {self.info})")
        b = np.empty_like(rhs, dtype=float)
        b[self.perm] = rhs
        x, info = dgbtrs(self.lu, self.kl, self.ku, b if b.ndim == 2 else b[:, None], self.piv,
                         trans=1 if trans else 0)
        x = x if b.ndim == 2 else x[:, 0]
        return x[self.perm]


@njit(cache=True)
def condense_band(ab, kl, ku, perm, tri_dep, tri_master, tri_coef):
    """A <- T^T A T (in place) for the change of variables q = c + T y of the end supports: with q_d = c_d +
    sum a_dm q_m for each triplet (d, m, a), row m += a row d, then column m += a column d. The rows and columns
    of the dependents d are left as they are (the caller replaces them, e.g. by ``constrain_band``). Dependents
    are never masters, and every master lies on the same end edge, inward of or beside its dependent, so the
    result keeps the band; an entry that would leave it raises ValueError."""
    n = ab.shape[1]
    off = kl + ku
    for k in range(tri_dep.shape[0]):
        pd = perm[tri_dep[k]]
        pm = perm[tri_master[k]]
        a = tri_coef[k]
        for j in range(max(0, pd - kl), min(n - 1, pd + ku) + 1):      # row pm += a row pd
            v = ab[off + pd - j, j]
            if v == 0.0:
                continue
            if j < pm - kl or j > pm + ku:
                raise ValueError("condense_band: a support link leaves the band")
            ab[off + pm - j, j] += a * v
    for k in range(tri_dep.shape[0]):
        pd = perm[tri_dep[k]]
        pm = perm[tri_master[k]]
        a = tri_coef[k]
        for i in range(max(0, pd - ku), min(n - 1, pd + kl) + 1):      # column pm += a column pd
            v = ab[off + i - pd, pd]
            if v == 0.0:
                continue
            if i < pm - ku or i > pm + kl:
                raise ValueError("condense_band: a support link leaves the band")
            ab[off + i - pm, pm] += a * v


@njit(cache=True)
def condense_vector(r, tri_dep, tri_master, tri_coef, fixed):
    """r <- T^T r (in place) on the free DOFs, zero on held ones: r_m += a r_d, then r[fixed] = 0."""
    for k in range(tri_dep.shape[0]):
        r[tri_master[k]] += tri_coef[k] * r[tri_dep[k]]
    for i in range(r.shape[0]):
        if fixed[i]:
            r[i] = 0.0


@njit(cache=True)
def expand_step(delta, tri_dep, tri_master, tri_coef):
    """delta <- T delta (in place) for a step with zero entries on the dependents: delta_d = sum a delta_m."""
    for k in range(tri_dep.shape[0]):
        delta[tri_dep[k]] = 0.0
    for k in range(tri_dep.shape[0]):
        delta[tri_dep[k]] += tri_coef[k] * delta[tri_master[k]]
