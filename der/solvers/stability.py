"""Stability of an equilibrium: the lowest eigenvalues of the constrained stiffness pencil (K, M).

K is the full force Jacobian (energy Hessian, frame-transport term, load stiffness); it is symmetric for
conservative loads and not for circulatory ones (follower twisting moments, dead torques), in which case its
eigenvalues may be complex. ``stable`` is the static criterion: no eigenvalue with a negative real part (no
divergence; for conservative loads, a local energy minimum). Complex eigenvalues -- flutter of the undamped
rod, which the damped dynamics of the solvers suppresses -- are reported separately (``flutter``). For
example, a straight clamped rod under any axial end torque has complex pairs (its two bending modes are
degenerate), the classical non-conservative cantilever of Ziegler.

M is the mass of the rod lumped on [0, L]: each node carries the line density rho_A times the length of [0, L]
it stands for (``Rod.node_weights``: its Voronoi cell; the two outer nodes of an open rod, half an edge
outside [0, L], carry none), each edge angle the rotational inertia times ``Rod.edge_weights``. This is the
midpoint rule of the kinetic energy, so the eigenvalues converge at second order (lumping the outer half
edges onto the outer nodes, as the solvers' damping mass does, puts a mass h/2 half an edge beyond a free end
and costs a first-order error, -2h/L on the first cantilever mode). Massless DOFs have infinite eigenvalues.

Symmetries
----------
Fixed DOFs are removed. The symmetries of the scene are then constructed analytically and projected out
(M-orthogonally); which ones exist is decided from the scene -- constraints, loads, natural shape -- never
from the size of an eigenvalue:

* rigid translations u: the internal energy is invariant, every load is unchanged by a translation (dead
  forces have a potential -f.x that changes only linearly, -F_net.u, so the Hessian is unchanged; follower
  moments and dead torques depend on tangents only). A translation is a symmetry when the constraints leave
  it free.
* rigid rotations w (about the centroid; combined with translations, any axis): the internal energy and the
  follower moments are invariant (they rotate with the rod), but a dead force f on nodes changes its
  potential at second order, -f.(R(w) r) = -f.r - f.(w x r) - 1/2 f.(w x (w x r)), and its generalized force
  does not rotate with the rod (K (w x r) = w x f at an equilibrium): a rotation is a symmetry only about
  axes parallel to every dead force (point, end and distributed forces; gravity leaves the rotation about
  the vertical). A dead torque tau likewise only about tau. The admissible rigid motions (u, w) are the
  null space of the linear conditions "zero on every fixed DOF" and "w x f = 0 for every dead force/torque".
* the uniform rotation of all cross-sections about their tangents (every theta + c): a symmetry of an
  isotropic rod with no natural curvature (kappa_bar = 0), whatever the loads (no load depends on theta),
  when no angle is fixed. Without bending and twisting energies every angle alone is one.
* material sliding along the centreline of a closed ring that is uniform (equal edges, uniform natural
  curvature and twist per length, uniform stiffness; a weld with an imposed twist that is not a whole number
  of turns breaks it when there is natural curvature, whose direction it turns) with no constraint and no load that breaks it (only
  distributed forces and twisting moments, which are uniform): node k moves along its discrete tangent,
  (x_{k+1} - x_{k-1}) / 2 per edge of sliding, and each material frame follows the material, theta_j by
  the material twist rate (m_j + m_{j+1}) / 2. It is exact in the continuum; on the polygon it is a zero
  mode up to O(h^2) (the polygon has only the discrete symmetry of relabelling), and is removed as one.
  Left in, it is the lowest mode of a writhed ring and slightly negative (tests/test_stability.py,
  test_writhed_ring_is_stable_once_material_sliding_is_removed: -1.2e-4 at n = 40). On an inextensible rod its
  size also follows the stretch penalty's state (it stretches edges at O(h^2)), so it does not shrink like h^2
  alone: -3.0e-4 at n = 80 after der.solve's penalty updates.

Eigen-solvers
-------------
Small systems are solved densely (QZ on the projected pencil). Larger ones by ARPACK's Lanczos on the
shift-invert operator in standard symmetric form, M^1/2 (K - sigma M)^-1 M^1/2 on the massive DOFs: every solve
reuses one banded LDL^T factorisation of K - sigma M (no pivoting, O(n) per solve; accepted only if a test
solve's backward error is at round-off level, else LAPACK's pivoted band LU), whose pivots also count the
eigenvalues below sigma (Sylvester) for the stability verdict's inertia check; the
projection of the symmetry modes applied by a Woodbury update of rank 2m (m symmetry modes), and the
symmetry modes themselves moved to a large eigenvalue beta so they are never found. Every returned eigenpair
is checked by its residual ||K v - lambda M v|| / (|lambda| ||M v||) evaluated from the assembled K.

Accuracy limit: the entries of K are of order A1/h^3 while K v is of order lambda h for a smooth bending mode,
so rounding the assembled stiffness alone moves a bending eigenvalue by up to eps |v|^T |K| |v| / v^T M v
(reported per eigenpair as its floor), which grows like eps n^4. On the cantilever (tools/stability_scaling.py)
the lowest eigenvalue is second-order accurate up to n ~ 500 (error 7e-6 at n = 400), then round-off takes over:
2e-5 at n = 1,000, 1e-2 at 10,000, and at 100,000 the value is meaningless (its floor exceeds it by 1e4; the
note says so and the sign counts as unresolved). No eigen-solver can do better on this matrix in double
precision; it would take a stiffness assembled in relative coordinates (edge vectors, curvatures).
"""
import time

import numpy as np

from ..linalg import (BandLU, add_diagonal, band_ldlt, band_ldlt_solve, band_matvec, band_negative_pivots,
                      band_to_sparse,
                      constrain_band)
from ..loads import DistributedForce, EndForce, EndTorque, PointForce, TwistingMoment
from .system import condense_system_band, evaluate_system, rotational_inertia

DENSE_MAX_DOFS = 300   # dense eigen-solver only for small systems
RESIDUAL_TOL = 1e-6    # eigenpairs with a larger relative residual are reported as inaccurate


# ---------------------------------------------------------------------------------------------
# symmetry modes
# ---------------------------------------------------------------------------------------------


def eigen_mass(rod):
    """Lumped mass per DOF of the eigenproblem (see the module docstring): rho_A times the length of [0, L]
    each node stands for, the rotational inertia times the length each edge angle stands for."""
    mass = np.repeat(rod.rho_A * rod.node_weights(), 4)
    mass[3::4] = 0.0
    mass[4 * np.arange(rod.n_edges) + 3] = rotational_inertia(rod) * rod.edge_weights()
    return mass


def _dead_directions(scene):
    """Unit vectors of every non-zero dead force and dead torque of the scene (they break rotations)."""
    dirs = []
    for load in scene.loads:
        if isinstance(load, PointForce) or isinstance(load, EndForce):
            v = np.asarray(load.force, float)
        elif isinstance(load, DistributedForce):
            v = np.asarray(load.density, float)
        elif isinstance(load, EndTorque) and not load.follower:
            v = np.asarray(load.torque, float)
        else:
            continue
        big = np.abs(v).max()
        if big > 0 and np.isfinite(big):
            v = v / big                     # first scaled to order 1: the norm of a 1e300 force overflows
            dirs.append(v / np.linalg.norm(v))
    return dirs


def _rigid_generators(rod, state):
    """(n_dof, 6): translations along x, y, z and rotations about x, y, z through the centroid (each edge
    angle turning by t.w: a rigid rotation turns the material frame about the tangent by that much more than
    parallel transport does)."""
    x = state.positions
    t = state.tangents
    c = x.mean(axis=0)
    G = np.zeros((rod.n_dof, 6))
    Gv = G.reshape(rod.n_nodes, 4, 6)
    for a in range(3):
        Gv[:, a, a] = 1.0
        w = np.zeros(3)
        w[a] = 1.0
        Gv[:, :3, 3 + a] = np.cross(w, x - c)
        Gv[:rod.n_edges, 3, 3 + a] = t @ w
    return G


def _null_space(A, rtol=1e-9):
    """Orthonormal basis of the null space of A (columns); A is built from unit-size rows."""
    if A.shape[0] == 0:
        return np.eye(A.shape[1])
    _, s, vt = np.linalg.svd(A)
    smax = s.max(initial=0.0)
    rank = int(np.sum(s > rtol * max(smax, 1e-300)))
    return vt[rank:].T


def _ring_is_uniform(rod, rtol=1e-9):
    if not rod.closed:
        return False
    l = rod.l_bar
    D = rod.voronoi
    h = l.mean()
    kb = rod.kappa_bar / D[:, None]
    tb = rod.twist_bar / D

    def same(v, scale):
        return np.abs(v - v.mean(axis=0)).max() <= rtol * scale

    # a weld turns the natural curvature of the frame continued across it: uniform only if it turns it onto itself
    w = rod.weld[0]
    if np.abs(rod.kappa_bar).max(initial=0.0) > 0 and abs((w + np.pi) % (2 * np.pi) - np.pi) > 1e-12:
        return False
    return same(l, h) and same(D, h) and same(kb, max(np.abs(kb).max(), 1.0 / h) * 1e-3) \
        and same(tb, max(np.abs(tb).max(), 1.0 / h) * 1e-3)


def sliding_mode(rod, state):
    """Material sliding along a ring's centreline (per edge of sliding): node k moves by (x_{k+1} - x_{k-1})/2,
    edge angle j by the material twist rate (m_j + m_{j+1}) / 2, m_v = theta_f - theta_e + reference twist
    (+ weld) the integrated material twist at vertex v (vertex j joins edges j-1 and j)."""
    x = state.positions
    q = state.q
    n = rod.n_nodes
    v = np.zeros(rod.n_dof)
    vv = v.reshape(n, 4)
    vv[:, :3] = 0.5 * (np.roll(x, -1, axis=0) - np.roll(x, 1, axis=0))
    e, f = rod.vertex_edges[:, 0], rod.vertex_edges[:, 1]
    theta = q[3::4]
    m = theta[f] - theta[e] + state.reference_twist + rod.weld     # per vertex (vertex j at node j)
    vv[:, 3] = 0.5 * (m + np.roll(m, -1))                            # edge j between vertices j and j+1
    return v


def symmetry_modes(system, state):
    """The symmetry modes of the scene at ``state`` (list of n_dof vectors, zero on every fixed DOF; not
    orthonormalised, maybe linearly dependent; maybe empty). See the module docstring for which exist."""
    rod = system.rod
    scene = system.scene
    fixed = system.fixed
    free_th = np.zeros(rod.n_dof, dtype=bool)
    free_th[4 * np.arange(rod.n_edges) + 3] = True
    free_th &= ~fixed
    modes = []
    # rigid motions: null space of (values on fixed DOFs, w x f for dead loads) in (u, w)
    G = _rigid_generators(rod, state)
    col = np.linalg.norm(G, axis=0)
    G = G / col[None, :]
    rows = [G[fixed]]
    for d in _dead_directions(scene):
        # w x d = 0, i.e. [d]x w = 0, on the rotation coefficients (columns rescaled like G's)
        cross = np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])
        r = np.hstack([np.zeros((3, 3)), cross / col[None, 3:]])
        rows.append(r / max(np.abs(r).max(), 1e-300))
    N = _null_space(np.vstack(rows))
    for k in range(N.shape[1]):
        modes.append(G @ N[:, k])
    energies = set(scene.energies)
    straight = np.abs(rod.kappa_bar).max(initial=0.0) <= 1e-12
    if "twist" not in energies and ("bend" not in energies or straight):
        for d in np.flatnonzero(free_th):   # no energy depends on any angle
            v = np.zeros(rod.n_dof)
            v[d] = 1.0
            modes.append(v)
    elif straight and not (fixed & _edge_slots(rod)).any():
        v = np.zeros(rod.n_dof)
        v[4 * np.arange(rod.n_edges) + 3] = 1.0
        modes.append(v)
    if rod.closed and not fixed.any() and _ring_is_uniform(rod) \
            and all(isinstance(load, (DistributedForce, TwistingMoment)) for load in scene.loads):
        modes.append(sliding_mode(rod, state))
    for v in modes:
        v[fixed] = 0.0    # exact zeros (the rigid null space is zero there to round-off)
    return modes


def _edge_slots(rod):
    s = np.zeros(rod.n_dof, dtype=bool)
    s[4 * np.arange(rod.n_edges) + 3] = True
    return s


def _m_orthonormal(V, m):
    """M-orthonormal basis of span(V) (columns), dropping directions that are linearly dependent."""
    if V.shape[1] == 0:
        return V
    import scipy.linalg as la

    V = V / np.sqrt(np.einsum("ij,i,ij->j", V, m, V))[None, :]
    _, R, piv = la.qr(V * np.sqrt(m)[:, None], mode="economic", pivoting=True)
    # symmetry modes are either independent (|R_kk| ~ |R_00|) or dependent up to round-off in the state: cut at 1e-6
    rank = int(np.sum(np.abs(np.diag(R)) > 1e-6 * abs(R[0, 0])))
    # M-orthonormalise the independent columns through V itself (massless DOFs keep their part of the mode).
    # By the eigenvectors of their Gram matrix rather than its Cholesky factor: two modes that coincide to 1e-9
    # (a ring round to round-off, whose material sliding is a rotation about its axis) may pass the rank test
    # and leave a Gram matrix that Cholesky refuses ("not positive definite", loop_twist --locate)
    Vk = V[:, np.sort(piv[:rank])]
    w, U = np.linalg.eigh(Vk.T @ (m[:, None] * Vk))
    keep = w > 1e-12 * w.max()
    return (Vk @ U[:, keep]) / np.sqrt(w[keep])[None, :]


# ---------------------------------------------------------------------------------------------
# eigenvalues
# ---------------------------------------------------------------------------------------------


def lowest_modes(system, state, n_eigenvalues=6, dense_max=DENSE_MAX_DOFS):
    """The lowest eigenpairs of the constrained pencil (K, M) at ``state`` with the symmetry modes projected
    out. Returns a dict: ``eigenvalues`` (sorted by real part), ``vectors`` (n_dof, k; zero on fixed DOFs),
    ``residuals`` (relative, ||K v - lambda M v|| / (|lambda| ||M v||)), ``n_symmetry``, ``symmetric``,
    ``floors`` (round-off floor of each eigenvalue, absolute), ``n_free``, ``method``, ``scale`` (Gershgorin bound
    of M^-1 K)."""
    rod = system.rod
    evaluate_system(system, state, 2)
    condense_system_band(system, system.ab)   # end supports: T^T K T on their free variables (q = c + T y)
    free = system.free.copy()
    if not rod.closed:
        free[4 * rod.n_nodes - 1] = False
    idx = np.flatnonzero(free)
    n = idx.size
    mass = eigen_mass(rod)
    out = {"eigenvalues": np.zeros(0), "vectors": np.zeros((rod.n_dof, 0)), "residuals": np.zeros(0),
           "floors": np.zeros(0),
           "n_symmetry": 0, "symmetric": True, "n_free": n, "method": "none", "scale": 1.0}
    if n == 0:
        return out
    m = mass[idx]
    massive = m > 0
    if getattr(system, "contact_coo", None) or system.kl != system.ku:
        # contact (issue 14): the off-band barrier Hessian joins the band; a sparse matrix on the free DOFs
        K = _sparse_free(system, idx)
    else:
        K = _BandOperator(system, idx)     # the band itself: no sparse copy (O(n) products, numba)
    k_abs_rows = K.abs_dot(np.ones(n))
    scale = float(k_abs_rows[massive].max() / m[massive].min()) if massive.any() else 1.0
    symmetric = K.symmetric()
    Vfull = symmetry_modes(system, state)
    V = np.array([v[idx] for v in Vfull]).T if Vfull else np.zeros((n, 0))
    V = _m_orthonormal(V, m) if V.shape[1] else V
    out.update(n_symmetry=V.shape[1], symmetric=symmetric, scale=scale)
    n_finite = int(massive.sum()) - V.shape[1]
    k = max(0, min(n_eigenvalues, n_finite))
    if k == 0:
        out["method"] = "nothing to compute"
        return out
    if n <= dense_max or n_finite - k < 3:
        ev, vec = _dense_lowest(K, m, V, symmetric, k)
        out["method"] = "dense"
    else:
        ev, vec, n_below, sigma = _banded_lowest(system, K, idx, mass, m, V, k, symmetric, scale)
        out["method"] = "banded shift-invert"
        out["inertia"] = (n_below, sigma)
    order = np.argsort(ev.real)[:k]
    ev, vec = ev[order], vec[:, order]
    if symmetric:
        ev, vec = ev.real, vec.real
    # residuals with the projected stiffness P^T K P (P = I - V V^T M), from the assembled matrix
    Kv = _project_T(K @ _project(vec, V, m), V, m)
    Mv = m[:, None] * vec
    r = np.linalg.norm(Kv - Mv * ev[None, :], axis=0)
    den = np.maximum(np.abs(ev) * np.linalg.norm(Mv, axis=0), 1e-300)
    # round-off floor of each eigenvalue: eps |v|^T |K| |v| / v^T M v, the error of the Rayleigh quotient
    # from rounding the stiffness entries (each entry of K is of order A1/h^3 while K v is of order lambda h
    # for a smooth mode: the floor grows like eps n^4 for the bending modes of a rod)
    av = np.abs(vec)
    floor = np.finfo(float).eps * np.einsum("ij,ij->j", av, K.abs_dot(av)) / np.maximum(
        np.abs(np.einsum("ij,i,ij->j", vec.conj(), m, vec)), 1e-300)
    full = np.zeros((rod.n_dof, vec.shape[1]), dtype=vec.dtype)
    full[idx] = vec
    out.update(eigenvalues=ev, vectors=full, residuals=r / den, floors=floor)
    return out


class _BandOperator:
    """K on the free DOFs ``idx`` straight from the system's band (no sparse copy): products with K, K^T and
    |K|, the symmetry test, a dense copy for small systems. Numpy over the kl + ku + 1 diagonals, O(n b)."""

    def __init__(self, system, idx):
        self.kl, self.ku = system.kl, system.ku
        self.ab, self.perm, self.idx, self.n_full = system.ab, system.perm, idx, system.ab.shape[1]
        # the kl + ku + 1 diagonals, contiguous (the band is stored column-major): diag[ku + d, j] = A[j + d, j]
        self.diag = np.ascontiguousarray(system.ab[system.kl:2 * system.kl + system.ku + 1])
        self.nb = self.diag.shape[1]
        self.pos = system.perm[idx]          # band positions of the free DOFs
        self.shape = (idx.size, idx.size)
        self.transposed = False

    @property
    def T(self):
        t = _BandOperator.__new__(_BandOperator)
        t.__dict__.update(self.__dict__)
        t.transposed = not self.transposed
        return t

    def _mul(self, x, absolute=False):
        x = np.asarray(x)
        xb = np.zeros((self.nb,) + x.shape[1:], dtype=np.result_type(x, float))
        xb[self.pos] = np.abs(x) if absolute else x
        y = np.zeros_like(xb)
        nb = self.nb
        for d in range(-self.ku, self.kl + 1):        # A[j + d, j] = diag[ku + d, j]
            j0, j1 = max(0, -d), min(nb, nb - d)
            if j1 <= j0:                              # a band wider than the matrix (a ring of 3 edges)
                continue
            a = self.diag[self.ku + d, j0:j1]
            if absolute:
                a = np.abs(a)
            if x.ndim == 2:
                a = a[:, None]
            if self.transposed:
                y[j0:j1] += a * xb[j0 + d:j1 + d]
            else:
                y[j0 + d:j1 + d] += a * xb[j0:j1]
        return y[self.pos]

    def _mul_numba(self, x, absolute):
        if self.transposed:
            return self._mul(x, absolute)
        x = np.asarray(x, dtype=float)
        cols = x.reshape(x.shape[0], -1)
        out = np.empty_like(cols)
        full = np.zeros(self.n_full)
        res = np.empty(self.n_full)
        for c in range(cols.shape[1]):
            full[self.idx] = cols[:, c]
            band_matvec(self.ab, self.kl, self.ku, self.perm, full, res, absolute)
            out[:, c] = res[self.idx]
        return out.reshape(x.shape)

    def __matmul__(self, x):
        return self._mul_numba(x, False)

    def abs_dot(self, x):
        """|K| |x|."""
        return self._mul_numba(x, True)

    def symmetric(self):
        freeb = np.zeros(self.nb, dtype=bool)
        freeb[self.pos] = True
        kmax = asym = 0.0
        for d in range(0, min(self.kl, self.nb - 1) + 1):     # a band wider than the matrix (a ring of 3 edges)
            mask = freeb[:self.nb - d] & freeb[d:]
            low = self.diag[self.ku + d, :self.nb - d][mask]     # A[j + d, j]
            up = self.diag[self.ku - d, d:][mask]                # A[j, j + d]
            if low.size:
                kmax = max(kmax, np.abs(low).max(), np.abs(up).max())
                asym = max(asym, np.abs(low - up).max())
        return bool(asym <= 1e-10 * max(kmax, 1e-300))

    def toarray(self):
        return self._mul(np.eye(self.shape[0]))


class _SparseOperator:
    """K on the free DOFs as a scipy sparse matrix (contact: band plus the off-band barrier Hessian)."""

    def __init__(self, K):
        self.sparse = K.tocsr()
        self.shape = K.shape

    @property
    def T(self):
        return _SparseOperator(self.sparse.T)

    def __matmul__(self, x):
        return self.sparse @ x

    def abs_dot(self, x):
        return abs(self.sparse) @ np.abs(x)

    def symmetric(self):
        kmax = abs(self.sparse).max() if self.sparse.nnz else 0.0
        return bool(abs(self.sparse - self.sparse.T).max() <= 1e-10 * max(kmax, 1e-300))

    def toarray(self):
        return self.sparse.toarray()


def _sparse_free(system, idx):
    K = band_to_sparse(system.ab, system.kl, system.ku, system.perm).tocsr()
    if getattr(system, "contact_coo", None):        # contact (issue 14): the off-band barrier Hessian
        import scipy.sparse as sp

        for r, c, v in system.contact_coo:
            K = K + sp.csr_matrix((v, (r, c)), shape=K.shape)
    return _SparseOperator(K.tocsr()[idx][:, idx])


def _project(X, V, m):
    """P X with P = I - V V^T M (removes the symmetry modes, M-orthogonally)."""
    if V.shape[1] == 0:
        return X
    return X - V @ (V.T @ (m[:, None] * X if X.ndim == 2 else m * X))


def _project_T(X, V, m):
    """P^T X = X - M V V^T X."""
    if V.shape[1] == 0:
        return X
    return X - (m[:, None] * V) @ (V.T @ X)


def _dense_lowest(K, m, V, symmetric, k):
    """All finite eigenpairs of the pencil compressed to the M-complement of V (QZ; massless DOFs give
    infinite eigenvalues, dropped)."""
    import scipy.linalg as la

    n = K.shape[0]
    Kd = K.toarray()
    Z = la.null_space((m[:, None] * V).T) if V.shape[1] else np.eye(n)
    Kc = Z.T @ Kd @ Z
    Mc = Z.T @ (m[:, None] * Z)
    if symmetric:
        Kc = 0.5 * (Kc + Kc.T)
    massive = m > 0
    if massive.all() and symmetric:
        ev, y = la.eigh(Kc, Mc)
    else:
        ev, y = la.eig(Kc, Mc)
        ok = np.isfinite(ev)
        ev, y = ev[ok], y[:, ok]
    if symmetric and not massive.all():
        # QZ with massless DOFs (infinite eigenvalues) loses digits on the finite ones: two Rayleigh-quotient
        # iterations on the lowest ones restore them
        ev = ev.real
        order = np.argsort(ev)[:k]
        ev, y = ev[order], y[:, order].real
        for j in range(y.shape[1]):
            yj = y[:, j]
            for _ in range(2):
                try:
                    z = np.linalg.solve(Kc - ev[j] * Mc, Mc @ yj)
                except np.linalg.LinAlgError:
                    break
                if not np.all(np.isfinite(z)):
                    break
                yj = z / np.linalg.norm(z)
                ev[j] = (yj @ Kc @ yj) / (yj @ Mc @ yj)
            y[:, j] = yj
    vec = Z @ y
    vec = vec / np.maximum(np.sqrt(np.abs(np.einsum("ij,i,ij->j", vec.conj(), m, vec))), 1e-300)[None, :]
    return np.asarray(ev), vec


def _banded_lowest(system, K, idx, mass, m, V, k, symmetric, scale):
    """ARPACK shift-invert around sigma on the banded LU of K - sigma M, the symmetry modes projected out by
    a Woodbury update and moved to the eigenvalue beta."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    rod = system.rod
    n = idx.size
    # sigma: below zero by a small fraction of the bending scale, so that an exact (unexpected) zero mode
    # leaves K - sigma M regular; the eigenvalues nearest it are the lowest and any negative ones near zero
    bend_scale = rod.bending_scale / (rod.rho_A * rod.length ** 4)
    sigma = -1e-3 * bend_scale
    full = np.zeros(rod.n_dof)
    n_below = -1           # eigenvalues below sigma by inertia (-1: not counted)
    if isinstance(K, _SparseOperator):
        # contact couples DOFs off the band: factorise the sparse K - sigma M on the free DOFs instead
        sparse_lu = spla.splu((K.sparse - sigma * sp.diags(m)).tocsc())

        def solve_b(b):
            return sparse_lu.solve(np.asarray(b, float))
    else:
        fixed_full = ~_free_full(system)
        ldl = None
        if symmetric:
            # one banded LDL^T of K - sigma M (no pivoting) serves both the shift-invert solves and the inertia
            # count (Sylvester); it is refused (negatives = -1) on a pivot too small to trust, then LU below
            L, D, neg = band_ldlt(system.ab, system.kl, system.ku, system.perm, sigma, mass, fixed_full, 0.0)
            if neg >= 0:
                # without pivoting an indefinite matrix may grow its factors: accept them only if a solve's
                # backward error is at round-off level (else LU, which pivots)
                b = np.random.default_rng(0).standard_normal(n)
                full[:] = 0.0
                full[idx] = b
                x = band_ldlt_solve(L, D, system.perm, full)[idx]
                r = np.abs(K @ x - sigma * m * x - b).max()
                bound = (K.abs_dot(x) + abs(sigma) * m * np.abs(x) + np.abs(b)).max()
                if np.isfinite(r) and r <= 1e-10 * bound:
                    ldl, n_below = (L, D), int(neg)
        if ldl is not None:
            def solve_b(b):
                full[:] = 0.0
                if b.ndim == 2:
                    fb = np.zeros((rod.n_dof, b.shape[1]))
                    fb[idx] = b
                    return band_ldlt_solve(ldl[0], ldl[1], system.perm, fb)[idx]
                full[idx] = b
                return band_ldlt_solve(ldl[0], ldl[1], system.perm, full)[idx]
        else:
            ab = system.ab.copy(order="F")
            add_diagonal(ab, system.kl, system.ku, system.perm, mass, -sigma)
            constrain_band(ab, system.kl, system.ku, system.perm, fixed_full, 1.0)
            lu = BandLU(ab, system.kl, system.ku, system.perm)

            def solve_b(b):
                if b.ndim == 2:
                    return np.column_stack([solve_b(b[:, j]) for j in range(b.shape[1])])
                full[:] = 0.0
                full[idx] = b
                return lu.solve(full)[idx]

    Mdiag = sp.diags(m)
    if V.shape[1]:
        beta = 10.0 * scale
        X = m[:, None] * V
        Yr = K @ V
        Yl = K.T @ V
        S = V.T @ Yr
        mm = V.shape[1]
        # P^T K P + beta X X^T - sigma M = B + U C W^T, U = [X, Yr], W = [X, Yl]
        C = np.block([[S + beta * np.eye(mm), -np.eye(mm)], [-np.eye(mm), np.zeros((mm, mm))]])
        U = np.hstack([X, Yr])
        W = np.hstack([X, Yl])
        BiU = solve_b(U)
        cap = np.linalg.inv(C) + W.T @ BiU
        cap_lu = np.linalg.inv(cap)

        def op(b):
            y = solve_b(b)
            return y - BiU @ (cap_lu @ (W.T @ y))

        def amat(x):
            px = _project(x, V, m)
            return _project_T(K @ px, V, m) + beta * (X @ (X.T @ x))
        A = spla.LinearOperator((n, n), matvec=amat, dtype=float)
    else:
        op = solve_b
        A = spla.LinearOperator((n, n), matvec=lambda x: K @ x, dtype=float)
    OPinv = spla.LinearOperator((n, n), matvec=op, dtype=float)
    kk = min(k, n - 2)
    ncv = min(n - 1, max(2 * kk + 1, 12))   # the inverted spectrum decays fast: few Lanczos vectors
    massive = m > 0
    n_m = int(massive.sum())
    if symmetric and n_m > kk + 1:
        # the standard symmetric form of shift-invert: C = M^1/2 (K - sigma M)^-1 M^1/2 on the massive DOFs
        # (massless ones drop out: infinite eigenvalues), mu = 1 / (lambda - sigma), x = (K - sigma M)^-1
        # M^1/2 y / mu. Lanczos in the plain inner product: one solve per step and no M products (ARPACK's
        # generalized mode asks for three times as many reverse-communication calls)
        root = np.sqrt(m[massive])
        lift = np.zeros(n)

        def c_mat(y):
            lift[massive] = root * y
            return root * op(lift)[massive]

        C = spla.LinearOperator((n_m, n_m), matvec=c_mat, dtype=float)
        mu, y = spla.eigsh(C, k=kk, which="LM", ncv=min(n_m - 1, ncv))
        keep = mu != 0.0
        mu, y = mu[keep], y[:, keep]
        lifted = np.zeros((n, y.shape[1]))
        lifted[massive] = root[:, None] * y
        vec = op(lifted) / mu[None, :]
        ev = sigma + 1.0 / mu
    elif symmetric:
        ev, vec = spla.eigsh(A, k=kk, M=Mdiag, sigma=sigma, which="LM", OPinv=OPinv, ncv=ncv)
    else:
        ev, vec = spla.eigs(A, k=kk, M=Mdiag, sigma=sigma, which="LM", OPinv=OPinv, ncv=ncv)
    return ev, vec, n_below, sigma


def _free_full(system):
    free = system.free.copy()
    if not system.rod.closed:
        free[4 * system.rod.n_nodes - 1] = False
    return free


def stability(system, result, n_eigenvalues=6):
    """Fill ``result.min_eigenvalue``, ``result.eigenvalues``, ``result.stable``, ``result.flutter``,
    ``result.stability_note`` and ``result.stability_time`` (seconds; not part of ``wall_time``)."""
    t0 = time.perf_counter()
    state = result.state
    out = lowest_modes(system, state, n_eigenvalues)
    ev = out["eigenvalues"]
    symmetric = out["symmetric"]
    notes = []
    if out["n_free"] == 0:
        result.min_eigenvalue = np.inf
        result.eigenvalues = np.zeros(0)
        result.stable = True
        result.flutter = False
        result.stability_note = "every DOF is fixed: nothing can move, trivially in equilibrium and stable"
        result.stability_time = time.perf_counter() - t0
        return result
    if ev.size == 0:
        result.min_eigenvalue = np.inf
        result.eigenvalues = np.zeros(0)
        result.stable = True
        result.flutter = False
        result.stability_note = (f"every free DOF is a symmetry mode ({out['n_symmetry']} removed) or massless: "
                                 f"no finite eigenvalue, stable")
        result.stability_time = time.perf_counter() - t0
        return result
    floor = float(out["floors"][0])
    lam_min = float(ev.real[0])
    if symmetric and out["method"] != "dense":
        # shift-invert finds the eigenvalues nearest sigma: count all negative ones (below the floor) by
        # inertia as a check -- from the LDL^T factors of K - sigma M the eigen-solver used when it had them
        n_below, sigma = out.get("inertia", (-1, 0.0))
        floor_shift = -max(float(out["floors"].max()),
                           1e-3 * system.rod.bending_scale / (system.rod.rho_A * system.rod.length ** 4))
        shift, n_neg = sigma, n_below
        if n_neg < 0 or n_neg > int(np.sum(ev.real < sigma)):
            # not counted, or more below sigma than found: count below the round-off floor instead (round-off
            # can put eigenvalues between -floor and sigma at very large n)
            shift = floor_shift
            n_neg = band_negative_pivots(system.ab, system.kl, system.ku, system.perm, shift,
                                         eigen_mass(system.rod), ~_free_full(system))
        found = int(np.sum(ev.real < shift))
        if n_neg > found:
            notes.append(f"{n_neg} negative eigenvalues by inertia (the {found} nearest zero listed)")
            if found == 0:
                lam_min = min(lam_min, shift)
    complex_pairs = bool((not symmetric) and np.any(np.abs(ev.imag) > 1e-8 * np.abs(ev).max(initial=0)))
    # a negative eigenvalue within its round-off floor counts as neutral (stable; the note says its sign is not
    # resolved -- at very large n, see the module docstring)
    stable = bool(lam_min > -floor)
    if not symmetric:
        notes.append("circulatory loads: stiffness not symmetric, stability by the static (divergence) criterion")
        if complex_pairs:
            notes.append("complex eigenvalues among the lowest: the UNDAMPED rod would flutter")
    if out["n_symmetry"]:
        notes.append(f"{out['n_symmetry']} symmetry mode(s) removed")
    res_max = float(out["residuals"][0])
    if res_max > RESIDUAL_TOL:
        notes.append(f"lowest eigenpair residual {res_max:.1e} (relative), round-off floor of the eigenvalue "
                     f"{floor:.1e}")
    if abs(lam_min) <= floor:
        notes.append(f"lowest eigenvalue {lam_min:.3g} within its round-off floor {floor:.1e}: neutral, its sign "
                     f"is not resolved in double precision")
    result.min_eigenvalue = lam_min
    result.eigenvalues = ev
    result.stable = stable
    result.flutter = complex_pairs
    result.stability_note = "; ".join(notes)
    result.stability_time = time.perf_counter() - t0
    return result
