"""Stability of an equilibrium: the lowest eigenvalues of the constrained stiffness pencil (K, M).

K is the full force Jacobian (energy Hessian, frame-transport term, load stiffness); it is symmetric for
conservative loads and not for circulatory ones (follower twisting moments, dead torques), in which case its
eigenvalues may be complex. ``stable`` is the static criterion: no eigenvalue with a negative real part (no
divergence; for conservative loads, a local energy minimum). Complex eigenvalues -- flutter of the undamped
rod, which the damped dynamics of the solvers suppresses -- are reported separately (``flutter``). For
example, a straight clamped rod under any axial end torque has complex pairs (its two bending modes are
degenerate), the classical non-conservative cantilever of Ziegler. Fixed DOFs are removed; symmetry modes -- rigid
translations and rotations of an unconstrained rod, and the uniform rotation of all cross-sections of an
isotropic rod with no natural curvature -- are detected (admissible and annihilated by K) and deflated.

Small systems (n_edges <= 500) are solved densely on the deflated complement; larger ones with ARPACK in
shift-invert mode around zero on the sparse matrix, the symmetry modes shifted away by a rank-m update
(Brauer's theorem keeps the other eigenvalues), never forming a dense matrix.
"""
import numpy as np

from ..linalg import band_negative_pivots, band_to_sparse
from .system import evaluate_system

DENSE_MAX_DOFS = 300   # dense eigen-solver only for small systems (never above 500 edges)


def symmetry_modes(system, state):
    """Candidate symmetry modes (n_dof, m) that respect the constraints (M-orthonormal, maybe empty)."""
    rod = system.rod
    x = state.positions
    t = state.tangents
    fixed = system.fixed.copy()
    if not rod.closed:
        fixed[4 * rod.n_nodes - 1] = False   # the dummy slot is not a real constraint
    pinned = [k for k in range(rod.n_nodes) if fixed[4 * k:4 * k + 3].all()]
    centre = x[pinned[0]] if len(pinned) == 1 else x.mean(axis=0)
    modes = []
    for a in range(3):
        v = np.zeros(rod.n_dof)
        v.reshape(-1, 4)[:, a] = 1.0
        modes.append(v)
    for a in range(3):
        w = np.zeros(3)
        w[a] = 1.0
        v = np.zeros(rod.n_dof)
        v.reshape(-1, 4)[:, :3] = np.cross(w, x - centre)
        v[4 * np.arange(rod.n_edges) + 3] = t @ w
        modes.append(v)
    if np.abs(rod.kappa_bar).max() == 0.0:
        v = np.zeros(rod.n_dof)
        v[4 * np.arange(rod.n_edges) + 3] = 1.0
        modes.append(v)
    if not rod.closed:
        for v in modes:
            v[4 * rod.n_nodes - 1] = 0.0
    return [v for v in modes if np.abs(v[fixed]).max(initial=0.0) < 1e-12 * np.abs(v).max()]


def stability(system, result, n_eigenvalues=6):
    """Fill ``result.min_eigenvalue``, ``result.eigenvalues``, ``result.stable`` and ``result.stability_note``."""
    import scipy.linalg as la

    state = result.state
    evaluate_system(system, state, 2)
    K = band_to_sparse(system.ab, system.kl, system.ku, system.perm).tocsr()
    if getattr(system, "contact_coo", None):        # contact (issue 14): the off-band barrier Hessian
        import scipy.sparse as sp

        for r, c, v in system.contact_coo:
            K = K + sp.csr_matrix((v, (r, c)), shape=K.shape)
    free = system.free.copy()
    rod = system.rod
    if not rod.closed:
        free[4 * rod.n_nodes - 1] = False
    idx = np.flatnonzero(free)
    Kf = K[idx][:, idx]
    m = system.mass[idx]
    k_abs = abs(Kf)
    # Gershgorin bound of M^-1 K: sets the round-off floor of computed eigenvalues
    scale = float((k_abs @ np.ones(idx.size) / m).max()) if idx.size else 1.0
    asym = abs(Kf - Kf.T).max() if idx.size else 0.0
    symmetric = asym <= 1e-10 * max(abs(Kf).max(), 1e-300)
    # symmetry modes that K annihilates
    V = []
    for v in symmetry_modes(system, state):
        vf = v[idx]
        # |M^-1/2 K v| <= 1e-7 |A| |M^1/2 v|, A = M^-1/2 K M^-1/2
        if np.linalg.norm((Kf @ vf) / np.sqrt(m)) <= 1e-7 * scale * np.linalg.norm(np.sqrt(m) * vf):
            V.append(vf)
    V = _m_orthonormal(np.array(V).T if V else np.zeros((idx.size, 0)), m)
    k = max(1, min(n_eigenvalues, idx.size - V.shape[1] - 2))
    note = ""
    if idx.size <= DENSE_MAX_DOFS:
        s = 1.0 / np.sqrt(m)
        A = (Kf.toarray() * s[:, None]) * s[None, :]
        W = V * np.sqrt(m)[:, None]
        Z = la.null_space(W.T) if W.shape[1] else np.eye(idx.size)
        B = Z.T @ A @ Z
        ev = la.eigvalsh(B) if symmetric else la.eigvals(B)
    else:
        ev = _sparse_lowest(Kf, m, V, k, symmetric, scale)
    ev = np.asarray(ev)
    order = np.argsort(ev.real)
    ev = ev[order][:k]
    tol = 1e3 * np.finfo(float).eps * scale
    lam_min = float(ev.real[0]) if ev.size else np.inf
    if symmetric and idx.size > DENSE_MAX_DOFS:
        # the shift-invert eigenvalues are those nearest zero: count all negative ones by inertia as a check
        n_neg = band_negative_pivots(system.ab, system.kl, system.ku, system.perm, -tol, system.mass,
                                     ~_free_full(system))
        found = int(np.sum(ev.real < -tol))
        if n_neg > found:
            note = f"{n_neg} negative eigenvalues by inertia (the {found} nearest zero listed)"
            lam_min = min(lam_min, -tol) if found == 0 else lam_min
    complex_pairs = bool((not symmetric) and np.any(np.abs(ev.imag) > max(tol, 1e-8 * np.abs(ev).max(initial=0))))
    stable = bool(lam_min > -tol)
    if not symmetric:
        note = "circulatory loads: stiffness not symmetric, stability by the static (divergence) criterion"
        if complex_pairs:
            note += "; complex eigenvalues among the lowest: the UNDAMPED rod would flutter"
    if V.shape[1]:
        note = (note + "; " if note else "") + f"{V.shape[1]} symmetry mode(s) removed"
    if abs(lam_min) <= tol:
        note = (note + "; " if note else "") + "lowest eigenvalue at the round-off floor (neutral)"
    result.min_eigenvalue = lam_min
    result.eigenvalues = ev if not symmetric else ev.real
    result.stable = stable
    result.flutter = complex_pairs
    result.stability_note = note
    return result


def _free_full(system):
    free = system.free.copy()
    if not system.rod.closed:
        free[4 * system.rod.n_nodes - 1] = False
    return free


def _m_orthonormal(V, m):
    if V.shape[1] == 0:
        return V
    W = V * np.sqrt(m)[:, None]
    Q, R = np.linalg.qr(W)
    keep = np.abs(np.diag(R)) > 1e-10 * np.abs(np.diag(R)).max()
    return Q[:, keep] / np.sqrt(m)[:, None]


def _sparse_lowest(K, m, V, k, symmetric, scale):
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    n = K.shape[0]
    M = sp.diags(m)
    sigma = -1e-6 * scale * 1e-6
    B = (K - sigma * M).tocsc()
    lu = spla.splu(B)
    if V.shape[1]:
        beta = 10.0 * scale
        U = M @ V
        BiU = lu.solve(U)
        cap = np.eye(V.shape[1]) / beta + U.T @ BiU
        cap_inv = np.linalg.inv(cap)

        def op(b):
            y = lu.solve(b)
            return y - BiU @ (cap_inv @ (U.T @ y))
        Kd = spla.LinearOperator((n, n), matvec=lambda x: K @ x + beta * (U @ (U.T @ x)), dtype=float)
    else:
        def op(b):
            return lu.solve(b)
        Kd = K
    OPinv = spla.LinearOperator((n, n), matvec=op, dtype=float)
    k = min(k, n - 2)
    if symmetric:
        return spla.eigsh(Kd, k=k, M=M, sigma=sigma, which="LM", OPinv=OPinv, return_eigenvectors=False)
    return spla.eigs(Kd, k=k, M=M, sigma=sigma, which="LM", OPinv=OPinv, return_eigenvectors=False)
