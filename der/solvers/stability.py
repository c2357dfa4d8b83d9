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
  isotropic rod with no natural curvature (kappa_bar = 0) unless a load turns with the sections (a follower force
  along m1 or m2, a follower point torque with an m1 or m2 component).
  It joins the rigid motions as a seventh generator, so the null space also finds its combinations with
  them: a rod held at both ends by clamps on one axis (Euler, Greenhill) turns about that axis, every edge
  angle by t.w - 1, leaving both clamped frames where they were (the two clamped edges lie along w, t.w = 1).
  With no angle fixed it is the shift alone. Without a twisting energy, and bending only of a straight rod (isotropic
  or unbent), every angle alone is one.
  An anisotropic rod (A1' != A1) has it only while unbent: bent, turning its sections turns its stiff axis.
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

Accuracy limit in node coordinates: the entries of K are of order A1/h^3 while K v is of order lambda h for a
smooth bending mode, so rounding the assembled stiffness alone moves a bending eigenvalue by up to
eps |v|^T |K| |v| / v^T M v (reported per eigenpair as its floor), which grows like eps n^4. On the cantilever
(tools/stability_scaling.py) the lowest eigenvalue was second-order accurate up to n ~ 500, then round-off took
over: 2e-5 at n = 1,000, 1e-2 at 10,000, and at 100,000 the value was meaningless.

Edge coordinates
----------------
An open rod held at its start (a clamp, hinge or roller at the start, or a pin on node 0; fix_theta anywhere;
nothing else holding a node; no contact) with a symmetric stiffness and no symmetry mode is analysed in edge
coordinates instead (``der.solvers.edge_coordinates``, method "edge shift-invert"): x_0, the edge vectors
e_j = x_{j+1} - x_j and the angles. Its stiffness K_e = T^T K T (T: cumulative sums) is read off the assembled band by translation
invariance in a few terms per entry, without the cancellation of the node-coordinate entries, and checked
(K x = T^-T K_e T^-1 x on a random vector to round-off, else node coordinates); it is banded (half-bandwidth 7
against 10). The mass T^T M T is dense but only applied, by cumulative sums, and factored as R^T R, R = M^1/2 T:
block Lanczos (``_edge_block_lanczos_fused``; ARPACK if it does not converge within its basis) runs on R K_e^-1 R^T,
shift-invert at sigma = 0 on one banded LDL^T of K_e (``linalg.band_ldlt_compact``), whose pivots count the
negative eigenvalues exactly (Sylvester) -- the stability verdict. Two right-hand sides per pass over the factor
(a straight rod bends alike in two planes: single-vector Lanczos, ARPACK's, needs round-off to find the second of
each degenerate pair, and missed the second 3806.5 of the cantilever at n = 10^4, returning 14617 in its place);
the Ritz pairs are residual-checked by the block Lanczos relation after every pass and the loop stops when the
lowest eigenvalue's pair is below 1e-9 (relative) and the other k - 1 below 1e-7 (their eigenvalues' errors are
quadratic in it), 8-9 passes for k = 6 on the cantilever; the eigenvectors by k / 2 more passes on the Ritz
vectors. Its passes over the long vectors are numba sweeps (``_edge_block_lanczos_fused``): at 10^5 the previous
numpy products (``EDGE_LANCZOS = "baseline"``, kept for comparison; it stores every pass's solves for the
eigenvectors) made a fresh 6 MB temporary per update, and inside der.solve fresh pages cost the baseline 0.33-0.38
s of system time per analysis against 0.02-0.11 s. When the analysis follows der.solve's implicit solver, the
Hessian at the final state comes from the solver's last force evaluation (``system.take_hessian``). The eigenvalues' round-off floors
grow like eps n^2 (cantilever, lowest eigenvalue: error 8e-9 at n = 10^4, 4e-7 at 10^5, against its floor 3e-6;
3.6e-9 at 10^5 for the loaded state solved with ``edge_newton``). Residuals
are evaluated in node coordinates, K x as T^-T K_e z (differences), with their round-off level (eps n^3 for a
bending mode; the eigenvalue's error is quadratic in the residual). Rings, free rods, rods held elsewhere and
scenes with symmetry modes keep the node-coordinate paths above.
"""
import time

import numpy as np
from numba import njit

from ..linalg import (BandLU, add_diagonal, band_ldlt, band_ldlt_compact, band_ldlt_solve, band_ldlt_solve_inplace,
                      band_matvec, band_negative_pivots, band_to_sparse, condense_band, constrain_band,
                      ldlt_compact_solve_block)
from .edge_coordinates import EDGE_BAND, EDGE_CHECK_TOL, EdgeCoordinates, band_asymmetry, edge_eligible
from .system import condense_system_band, evaluate_system, rotational_inertia, take_hessian

DENSE_MAX_DOFS = 300   # dense eigen-solver only for small systems
EDGE_METHOD = "edge shift-invert"
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
        v = load.dead_vector()
        if v is None:
            continue
        big = np.abs(v).max()
        if big > 0 and np.isfinite(big):
            v = v / big                     # first scaled to order 1: the norm of a 1e300 force overflows
            dirs.append(v / np.linalg.norm(v))
    return dirs


def _loads_turn_with_sections(scene):
    """Whether a load depends on the sections' angles: a follower force with a component along m1 or m2, a follower
    point torque given along (m1, m2, t) with one of the first two. Such a load breaks the uniform section turn
    (every theta + c); dead loads, twisting moments and moments about the tangent do not."""
    return any(load.turns_with_sections() for load in scene.loads)


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


def _rigid_generator_rows(rod, state, rows):
    """Rows ``rows`` of ``_rigid_generators`` and its column norms, without forming it: the norms from the second
    moments of the nodes about their centroid and of the tangents (|e_a x r|^2 = r_b^2 + r_c^2), O(n) in 3 x 3
    sums (a scene whose held DOFs leave no rigid motion never needs the whole (n_dof, 6) matrix)."""
    x = state.positions
    t = state.tangents
    r = x - x.mean(axis=0)
    S = r.T @ r
    Tt = t.T @ t
    col = np.empty(6)
    col[:3] = np.sqrt(rod.n_nodes)
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        col[3 + a] = np.sqrt(S[b, b] + S[c, c] + Tt[a, a])
    G = np.zeros((rows.size, 6))
    node, slot = rows // 4, rows % 4
    pos = slot < 3
    G[np.flatnonzero(pos), slot[pos]] = 1.0
    for i in np.flatnonzero(pos):              # e_a x r, component slot: the rows of [r]x^T
        rx, ry, rz = r[node[i]]
        G[i, 3:] = np.array([[0.0, rz, -ry], [-rz, 0.0, rx], [ry, -rx, 0.0]])[slot[i]]
    ang = np.flatnonzero(~pos & (node < rod.n_edges))
    G[ang, 3:] = t[node[ang]]
    return G, col


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
    energies = set(scene.energies)
    straight = np.abs(rod.kappa_bar).max(initial=0.0) <= 1e-12
    # an anisotropic rod's sections turn freely only while it is unbent (kappa = 0 whatever their orientation);
    # no section turns freely under a load that turns with it
    unbent = rod.closed is False and np.abs(np.diff(state.tangents, axis=0)).max(initial=0.0) <= 1e-12
    turnable = (rod.isotropic or unbent) and not _loads_turn_with_sections(scene)
    every_angle_free = turnable and "twist" not in energies and ("bend" not in energies or straight)
    # the uniform section rotation (every theta + 1) as a seventh generator beside the rigid motions
    shift = straight and turnable and not every_angle_free
    fixed_rows = np.flatnonzero(fixed)
    Gf, col = _rigid_generator_rows(rod, state, fixed_rows)
    if shift:
        Gf = np.hstack([Gf, (_edge_slots(rod)[fixed_rows]).astype(float)[:, None]])
        col = np.append(col, np.sqrt(rod.n_edges))
    rows = [Gf / col[None, :]]
    for d in _dead_directions(scene):
        # w x d = 0, i.e. [d]x w = 0, on the rotation coefficients (columns rescaled like G's)
        cross = np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])
        r = np.hstack([np.zeros((3, 3)), cross / col[None, 3:6], np.zeros((3, col.size - 6))])
        rows.append(r / max(np.abs(r).max(), 1e-300))
    N = _null_space(np.vstack(rows))
    if N.shape[1]:
        G = _rigid_generators(rod, state)
        if shift:
            G = np.hstack([G, _edge_slots(rod).astype(float)[:, None]])
        G = G / col[None, :]
        for k in range(N.shape[1]):
            v = G @ N[:, k]
            # a combination that cancels to round-off is no motion at all: on a straight rod along its axis the turn
            # about the axis is the shift itself, and their difference moves nothing (judged against the same sum
            # without cancellation, so the test does not depend on the rod's units or size)
            if np.linalg.norm(v) > 1e-12 * np.linalg.norm(np.abs(G) @ np.abs(N[:, k])):
                modes.append(v)
    if every_angle_free:
        for d in np.flatnonzero(free_th):   # no energy depends on any angle
            v = np.zeros(rod.n_dof)
            v[d] = 1.0
            modes.append(v)
    if rod.closed and not fixed.any() and _ring_is_uniform(rod) \
            and all(load.keeps_ring_sliding() for load in scene.loads):
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


def lowest_modes(system, state, n_eigenvalues=6, dense_max=DENSE_MAX_DOFS, edge=True, assembled=False):
    """The lowest eigenpairs of the constrained pencil (K, M) at ``state`` with the symmetry modes projected
    out. Returns a dict: ``eigenvalues`` (sorted by real part), ``vectors`` (n_dof, k; zero on fixed DOFs),
    ``residuals`` (relative, ||K v - lambda M v|| / (|lambda| ||M v||)), ``n_symmetry``, ``symmetric``,
    ``floors`` (round-off floor of each eigenvalue, absolute), ``n_free``, ``method`` ("dense", "banded shift-invert"
    in node coordinates, or "edge shift-invert" in edge coordinates, see ``EdgeCoordinates``), ``scale``
    (Gershgorin bound of M^-1 K, banded path), ``residual_floors`` (edge path: the round-off level of the
    residuals) and ``inertia`` (shift-invert paths: the number of eigenvalues below the shift, and the shift).
    ``edge=False`` keeps large systems in node coordinates (for comparisons). ``assembled``: ``system.ab`` already
    holds the Hessian at ``state`` (``system.take_hessian``), not assembled again."""
    rod = system.rod
    if not assembled:
        evaluate_system(system, state, 2)
    ez = None
    if edge and edge_eligible(system) and 4 * rod.n_nodes > dense_max:
        # edge coordinates (see EdgeCoordinates), read off the assembled band before the end supports condense it
        ez = EdgeCoordinates(system, state, eigen_mass(rod))
        abz_raw = ez.band(system.ab, system.kl, system.ku)
        if not ez.check_band(system.ab, system.kl, system.ku, abz_raw) <= EDGE_CHECK_TOL:
            ez = None
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
    elif ez is None:
        K = _BandOperator(system, idx)     # the band itself: no sparse copy (O(n) products, numba)
    else:
        K = None                           # made below only if the edge path does not finish
    if K is None:
        symmetric = bool(band_asymmetry(abz_raw, EDGE_BAND, ez.fixed) <= 1e-10)   # K_e = T^T K T: the same test
    else:
        symmetric = K.symmetric()
    Vfull = symmetry_modes(system, state)
    V = np.array([v[idx] for v in Vfull]).T if Vfull else np.zeros((n, 0))
    V = _m_orthonormal(V, m) if V.shape[1] else V
    out.update(n_symmetry=V.shape[1], symmetric=symmetric)
    n_finite = int(massive.sum()) - V.shape[1]
    k = max(0, min(n_eigenvalues, n_finite))
    if k == 0:
        out["method"] = "nothing to compute"
        return out
    edge = None
    if K is None and (n <= dense_max or n_finite - k < 3 or not symmetric or V.shape[1]):
        K = _BandOperator(system, idx)
    if n <= dense_max or n_finite - k < 3:
        ev, vec = _dense_lowest(K, m, V, symmetric, k)
        out["method"] = "dense"
    elif ez is not None and symmetric and V.shape[1] == 0:
        edge = _edge_eigen(ez, abz_raw, k)
    if edge is not None:
        return _edge_out(system, ez, abz_raw, edge, idx, mass, k, out)
    if out["method"] != "dense":
        if K is None:
            K = _BandOperator(system, idx)   # the edge path refused its factorisation: node coordinates
        scale = float(K.abs_dot(np.ones(n))[massive].max() / m[massive].min()) if massive.any() else 1.0
        out["scale"] = scale
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



# ---------------------------------------------------------------------------------------------
# edge coordinates (open rods held at their start)
# ---------------------------------------------------------------------------------------------

@njit(cache=True)
def _edge_rt_solve(w, L, D, massive, root, fixed, tri_dep, tri_master, tri_coef, n_nodes):
    """z = T_L K^-1 T_L^T T^T M^1/2 w (full z, links applied): the solve of the edge-coordinate operator."""
    n = fixed.shape[0]
    f = np.zeros(n)
    for i in range(massive.shape[0]):
        f[massive[i]] = root[i] * w[i]
    for a in range(3):                         # T^T: suffix sums over the node slots
        acc = 0.0
        for c in range(n_nodes - 1, -1, -1):
            acc += f[4 * c + a]
            f[4 * c + a] = acc
    for k in range(tri_dep.shape[0]):
        f[tri_master[k]] += tri_coef[k] * f[tri_dep[k]]
    for i in range(n):
        if fixed[i]:
            f[i] = 0.0
    z = f
    band_ldlt_solve_inplace(L, D, z)           # L D L^T z = f in place (band_ldlt's factors, identity order)
    for k in range(tri_dep.shape[0]):
        z[tri_dep[k]] = 0.0
    for k in range(tri_dep.shape[0]):
        z[tri_dep[k]] += tri_coef[k] * z[tri_master[k]]
    return z


@njit(cache=True)
def _edge_apply(w, L, D, massive, root, fixed, tri_dep, tri_master, tri_coef, n_nodes):
    """R K^-1 R^T w, R = M^1/2 T T_L (the Lanczos operator of ``_edge_lowest``)."""
    z = _edge_rt_solve(w, L, D, massive, root, fixed, tri_dep, tri_master, tri_coef, n_nodes)
    for a in range(3):                         # T: prefix sums
        acc = 0.0
        for c in range(n_nodes):
            acc += z[4 * c + a]
            z[4 * c + a] = acc
    out = np.empty(massive.shape[0])
    for i in range(massive.shape[0]):
        out[i] = root[i] * z[massive[i]]
    return out


@njit(cache=True)
def _edge_apply_block(W, out, Zout, Z, L, D, massive, root, fixed, tri_dep, tri_master, tri_coef, n_nodes):
    """For the rows w of ``W`` (m, n_massive): ``out`` <- R K^-1 R^T w and ``Zout`` <- z = T_L K^-1 T_L^T T^T M^1/2 w
    (full z, links applied; rows), R = M^1/2 T T_L, K = L D L^T (``band_ldlt_compact``'s factors, identity order):
    one pass over the factor for all m right-hand sides (``ldlt_compact_solve_block``, in the scratch ``Z``
    (n_dof, m))."""
    n = fixed.shape[0]
    m = W.shape[0]
    Z[:, :] = 0.0
    for i in range(massive.shape[0]):
        r = root[i]
        row = massive[i]
        for c in range(m):
            Z[row, c] = r * W[c, i]
    acc = np.empty(m)
    for a in range(3):                         # T^T: suffix sums over the node slots
        acc[:] = 0.0
        for node in range(n_nodes - 1, -1, -1):
            i = 4 * node + a
            for c in range(m):
                acc[c] += Z[i, c]
                Z[i, c] = acc[c]
    for k in range(tri_dep.shape[0]):          # T_L^T
        for c in range(m):
            Z[tri_master[k], c] += tri_coef[k] * Z[tri_dep[k], c]
    for i in range(n):
        if fixed[i]:
            for c in range(m):
                Z[i, c] = 0.0
    ldlt_compact_solve_block(L, D, Z)
    for k in range(tri_dep.shape[0]):          # T_L: the dependents from their masters
        for c in range(m):
            Z[tri_dep[k], c] = 0.0
    for k in range(tri_dep.shape[0]):
        for c in range(m):
            Z[tri_dep[k], c] += tri_coef[k] * Z[tri_master[k], c]
    for i in range(n):
        for c in range(m):
            Zout[c, i] = Z[i, c]
    for a in range(3):                         # T: prefix sums, kept in Z, then M^1/2 on the massive slots
        acc[:] = 0.0
        for node in range(n_nodes):
            i = 4 * node + a
            for c in range(m):
                acc[c] += Z[i, c]
                Z[i, c] = acc[c]
    for j in range(massive.shape[0]):
        i = massive[j]
        r = root[j]
        for c in range(m):
            out[c, j] = r * Z[i, c]


EDGE_LANCZOS_TOL = 1e-9     # relative residual ||C y - mu y|| / |mu| of every returned Ritz pair (C = R K^-1 R^T)
EDGE_LANCZOS_BLOCK = 2      # block size (>= the multiplicity of the eigenvalues: a straight rod's bend in 2 planes)
EDGE_LANCZOS_MAX_DIM = 60   # largest basis before giving up (ARPACK then)


def _cholesky_qr(W):
    """(Q, R) with W = Q R for the rows of ``W`` (b, n): Q (b, n) orthonormal rows, R (b, b) upper triangular, by
    Cholesky QR twice (one pass over W each, against the several passes of Householder QR on a long and thin W;
    twice for orthogonality to round-off). Householder QR if W is numerically rank-deficient (Cholesky refuses its
    Gram matrix)."""
    R = np.eye(W.shape[0])
    Q = W
    for _ in range(2):
        try:
            C = np.linalg.cholesky(Q @ Q.T)        # lower: Q^T = (Q_new^T) C^T
        except np.linalg.LinAlgError:
            q, r = np.linalg.qr(W.T)
            return np.ascontiguousarray(q.T), r
        Q = np.linalg.inv(C) @ Q
        R = C.T @ R
    return Q, R


def _edge_block_lanczos(ez, L, D, k, tol=EDGE_LANCZOS_TOL, block=EDGE_LANCZOS_BLOCK, max_dim=EDGE_LANCZOS_MAX_DIM):
    """Block Lanczos with full reorthogonalisation on C = R K^-1 R^T (shift-invert at 0 in standard symmetric
    form, as ``_edge_lowest``), each step one pass over the LDL^T factor for ``block`` right-hand sides
    (``_edge_apply_block``). After each step the Ritz pairs of the basis are checked by their residuals, exactly
    ||C y - mu y|| = ||B_{j+1} s_last|| (the block Lanczos relation with a full orthogonal basis), and the loop stops
    when the k of largest |mu| (the eigenvalues nearest zero) are all below ``tol`` relative to |mu|; the
    eigenvectors in z are the same combinations of the stored solves (no more solves). Returns (eigenvalues, list
    of full z, number of operator passes), or None if the basis reached ``max_dim`` first."""
    args = (L, D, ez.massive, ez.root, ez.fixed, ez.tri_dep, ez.tri_master, ez.tri_coef, ez.N)
    n_m = ez.massive.size
    max_dim = min(max_dim, n_m - block)
    if max_dim < k + block:
        return None
    # the basis and the solves by rows (each vector contiguous: the projections are plain matrix products)
    Q = np.empty((max_dim + block, n_m))
    Zs = np.empty((max_dim, ez.n_dof))
    H = np.zeros((max_dim, max_dim))
    W = np.empty((block, n_m))
    scratch = np.empty((ez.n_dof, block))
    Q[:block] = _cholesky_qr(np.random.default_rng(0).standard_normal((block, n_m)))[0]
    m = 0
    passes = 0
    while m + block <= max_dim:
        m1 = m + block
        _edge_apply_block(Q[m:m1], W, Zs[m:m1], scratch, *args)
        passes += 1
        # Gram-Schmidt twice: first against the last two blocks, where the cancellation is (exactly, C q_j lies in
        # the span of q_{j-1}, q_j, q_{j+1}: the three-term recurrence), then against the whole basis, which removes
        # what rounding (eps |C q_j|) and the first pass put along every earlier vector -- the accuracy of two
        # full passes of classical Gram-Schmidt for the price of one
        lo = max(0, m - block)
        Ql = Q[lo:m1]
        h = np.zeros((m1, block))
        h[lo:] = Ql @ W.T
        W -= h[lo:].T @ Ql
        Qb = Q[:m1]
        h2 = Qb @ W.T
        W -= h2.T @ Qb
        h += h2
        H[:m1, m:m1] = h
        H[m:m1, :m1] = h.T
        Qn, B = _cholesky_qr(W)
        theta, S = np.linalg.eigh(0.5 * (H[:m1, :m1] + H[:m1, :m1].T))
        order = np.argsort(-np.abs(theta))[:k]
        if m1 >= k:
            res = np.linalg.norm(B @ S[m:m1, order], axis=0) / np.maximum(np.abs(theta[order]), 1e-300)
            if np.all(res <= tol) and np.all(theta[order] != 0.0):
                mu = theta[order]
                z = (S[:, order].T @ Zs[:m1]) / mu[:, None]
                return 1.0 / mu, list(z), passes
        Q[m1:m1 + block] = Qn
        m = m1
    return None


# The block Lanczos above, in numba sweeps over the long vectors (``_edge_block_lanczos_fused``): the same
# recurrence, the same Gram-Schmidt (the last two blocks, then the whole basis) and Cholesky QR twice, but each pass
# over the basis a chunked sweep that subtracts one set of coefficients and accumulates the next dot products in the
# same read (numpy's products read the basis once per operation and make a fresh temporary of every update), and
# the operator's scatter, cumulative sums and gather in two sweeps around the factor's solve. The previous function
# stays as the measured baseline (``EDGE_LANCZOS = "baseline"``, tools/stability_scaling.py --baseline).

EDGE_LANCZOS = "fused"      # "fused" (_edge_block_lanczos_fused) or "baseline" (_edge_block_lanczos)
EDGE_LANCZOS_TOL_REST = 1e-7  # the fused path's relative residual for the Ritz pairs other than the lowest
_SWEEP_CHUNK = 512          # columns per chunk of a sweep (the block's slice of W stays in the first-level cache)


@njit(cache=True, fastmath={"reassoc", "contract"})
def _lanczos_sweep(Q, W, sub_lo, sub_hi, hsub, dot_lo, dot_hi, hdot, gram):
    """One chunked sweep over the columns: W[c] -= sum_{r in [sub_lo, sub_hi)} hsub[r - sub_lo, c] Q[r], then
    hdot[r - dot_lo, c] = Q[r] . W[c] for r in [dot_lo, dot_hi) and gram[c, d] = W[c] . W[d] of the updated W
    (hdot and gram overwritten)."""
    b, n = W.shape
    hdot[:, :] = 0.0
    gram[:, :] = 0.0
    buf = np.empty((b, _SWEEP_CHUNK))          # W's chunk (a local array: no aliasing with Q, the loops vectorise)
    for i0 in range(0, n, _SWEEP_CHUNK):
        i1 = min(n, i0 + _SWEEP_CHUNK)
        w = i1 - i0
        for c in range(b):
            for i in range(w):
                buf[c, i] = W[c, i0 + i]
        for r in range(sub_lo, sub_hi):
            q = Q[r, i0:i1]
            for c in range(b):
                a = hsub[r - sub_lo, c]
                if a != 0.0:
                    for i in range(w):
                        buf[c, i] -= a * q[i]
        if sub_hi > sub_lo:
            for c in range(b):
                for i in range(w):
                    W[c, i0 + i] = buf[c, i]
        for r in range(dot_lo, dot_hi):
            q = Q[r, i0:i1]
            for c in range(b):
                s = 0.0
                for i in range(w):
                    s += q[i] * buf[c, i]
                hdot[r - dot_lo, c] += s
        for c in range(b):
            for d in range(c + 1):
                s = 0.0
                for i in range(w):
                    s += buf[c, i] * buf[d, i]
                gram[c, d] += s
    for c in range(b):
        for d in range(c):
            gram[d, c] = gram[c, d]


@njit(cache=True, fastmath={"reassoc", "contract"})
def _lanczos_scale(W, Cinv, out, gram):
    """out <- Cinv W (Cinv lower triangular, rows; ``out`` may be ``W`` itself) and gram <- out out^T."""
    b, n = W.shape
    gram[:, :] = 0.0
    buf = np.empty((b, _SWEEP_CHUNK))
    res = np.empty((b, _SWEEP_CHUNK))
    for i0 in range(0, n, _SWEEP_CHUNK):
        i1 = min(n, i0 + _SWEEP_CHUNK)
        w = i1 - i0
        for c in range(b):
            for i in range(w):
                buf[c, i] = W[c, i0 + i]
        for c in range(b):
            for i in range(w):
                res[c, i] = 0.0
            for d in range(c + 1):
                a = Cinv[c, d]
                for i in range(w):
                    res[c, i] += a * buf[d, i]
        for c in range(b):
            for i in range(w):
                out[c, i0 + i] = res[c, i]
            for d in range(c + 1):
                s = 0.0
                for i in range(w):
                    s += res[c, i] * res[d, i]
                gram[c, d] += s
    for c in range(b):
        for d in range(c):
            gram[d, c] = gram[c, d]


@njit(cache=True)
def _edge_apply_block_fused(W, out, Zout, Z, L, D, slot, root, fixed_idx, tri_dep, tri_master, tri_coef, n_nodes,
                            keep_z=True):
    """``_edge_apply_block`` in two sweeps around the solve: ``slot`` (n_dof,) the index of each DOF among the
    massive ones (-1: massless), ``fixed_idx`` the held slots. The scatter M^1/2 w and the suffix sums T^T in one
    backward sweep over the nodes; the links T_L, the prefix sums T, the copy of z (``Zout``, only if ``keep_z``)
    and the gather M^1/2 in one forward sweep."""
    m = W.shape[0]
    acc = np.zeros((3, m))
    for node in range(n_nodes - 1, -1, -1):
        for a in range(4):
            i = 4 * node + a
            j = slot[i]
            if a < 3:
                for c in range(m):
                    if j >= 0:
                        acc[a, c] += root[j] * W[c, j]
                    Z[i, c] = acc[a, c]
            else:
                for c in range(m):
                    Z[i, c] = root[j] * W[c, j] if j >= 0 else 0.0
    for k in range(tri_dep.shape[0]):          # T_L^T
        for c in range(m):
            Z[tri_master[k], c] += tri_coef[k] * Z[tri_dep[k], c]
    for t in range(fixed_idx.shape[0]):
        for c in range(m):
            Z[fixed_idx[t], c] = 0.0
    ldlt_compact_solve_block(L, D, Z)
    for k in range(tri_dep.shape[0]):          # T_L: the dependents from their masters
        for c in range(m):
            Z[tri_dep[k], c] = 0.0
    for k in range(tri_dep.shape[0]):
        for c in range(m):
            Z[tri_dep[k], c] += tri_coef[k] * Z[tri_master[k], c]
    acc[:, :] = 0.0
    for node in range(n_nodes):
        for a in range(4):
            i = 4 * node + a
            j = slot[i]
            for c in range(m):
                v = Z[i, c]
                if keep_z:
                    Zout[c, i] = v
                if a < 3:
                    acc[a, c] += v
                    v = acc[a, c]
                if j >= 0:
                    out[c, j] = root[j] * v


def _cholesky_inverse(G):
    """(C^-1, C) for the lower Cholesky factor C of the small Gram matrix G, or None if Cholesky refuses it."""
    try:
        C = np.linalg.cholesky(G)
    except np.linalg.LinAlgError:
        return None
    return np.linalg.inv(C), C


def _edge_block_lanczos_fused(ez, L, D, k, tol=EDGE_LANCZOS_TOL, block=EDGE_LANCZOS_BLOCK,
                              max_dim=EDGE_LANCZOS_MAX_DIM, tol_rest=None):
    """``_edge_block_lanczos`` (the same recurrence, residual test, result and None) with its passes over the long
    vectors as numba sweeps (``_lanczos_sweep``, ``_lanczos_scale``, ``_edge_apply_block_fused``) and a seeded
    uniform start block. The Ritz pair of the lowest eigenvalue (the reported one) must reach ``tol``, the others
    ``tol_rest`` (default ``EDGE_LANCZOS_TOL_REST``: their eigenvalues' errors are quadratic in it, 1e-13 relative
    on the cantilever at 10^3-10^5, one pass of ten saved). A block whose Gram matrix Cholesky refuses
    (numerically rank-deficient) falls back to the baseline function."""
    if tol_rest is None:
        tol_rest = EDGE_LANCZOS_TOL_REST
    n_m = ez.massive.size
    max_dim = min(max_dim, n_m - block)
    if max_dim < k + block:
        return None
    slot = np.full(ez.n_dof, -1, dtype=np.int64)
    slot[ez.massive] = np.arange(n_m)
    args = (L, D, slot, ez.root, np.flatnonzero(ez.fixed), ez.tri_dep, ez.tri_master, ez.tri_coef, ez.N)
    Q = np.empty((max_dim + block, n_m))
    H = np.zeros((max_dim, max_dim))
    W = np.empty((block, n_m))
    scratch = np.empty((ez.n_dof, block))
    gram = np.empty((block, block))
    hloc = np.empty((2 * block, block))
    hfull = np.empty((max_dim, block))
    none = np.zeros((0, block))
    Q[:block] = np.random.default_rng(0).random((block, n_m)) - 0.5
    _lanczos_sweep(Q, Q[:block], 0, 0, none, 0, 0, hloc[:0], gram)
    for _ in range(2):
        got = _cholesky_inverse(gram)
        if got is None:
            return _edge_block_lanczos(ez, L, D, k, tol, block, max_dim)
        _lanczos_scale(Q[:block], got[0], Q[:block], gram)
    m = 0
    passes = 0
    while m + block <= max_dim:
        m1 = m + block
        _edge_apply_block_fused(Q[m:m1], W, W, scratch, *args, False)   # (the solves themselves not kept)
        passes += 1
        # Gram-Schmidt against the last two blocks (their dots in one sweep), then against the whole basis (its
        # dots in the sweep that subtracts the first; its subtraction in a third, with W's Gram matrix)
        lo = max(0, m - block)
        hl = hloc[:m1 - lo]
        _lanczos_sweep(Q, W, 0, 0, none, lo, m1, hl, gram)
        hf = hfull[:m1]
        _lanczos_sweep(Q, W, lo, m1, hl, 0, m1, hf, gram)
        h = hf.copy()
        h[lo:] += hl
        _lanczos_sweep(Q, W, 0, m1, hf, 0, 0, hloc[:0], gram)
        H[:m1, m:m1] = h
        H[m:m1, :m1] = h.T
        # Cholesky QR twice into the next block: W = Q_new B, B = C2^T C1^T
        Qn = Q[m1:m1 + block]
        got = _cholesky_inverse(gram)
        if got is None:
            return _edge_block_lanczos(ez, L, D, k, tol, block, max_dim)
        _lanczos_scale(W, got[0], Qn, gram)
        got2 = _cholesky_inverse(gram)
        if got2 is None:
            return _edge_block_lanczos(ez, L, D, k, tol, block, max_dim)
        _lanczos_scale(Qn, got2[0], Qn, gram)
        B = got2[1].T @ got[1].T
        theta, S = np.linalg.eigh(0.5 * (H[:m1, :m1] + H[:m1, :m1].T))
        order = np.argsort(-np.abs(theta))[:k]
        if m1 >= k:
            res = np.linalg.norm(B @ S[m:m1, order], axis=0) / np.maximum(np.abs(theta[order]), 1e-300)
            lim = np.full(res.size, tol_rest)
            with np.errstate(divide="ignore"):
                lim[np.argmin(1.0 / theta[order])] = tol
            if np.all(res <= lim) and np.all(theta[order] != 0.0):
                # the eigenvectors z = K^-1 R^T y / mu of the Ritz vectors y, by ceil(k / block) more passes in the
                # buffers already touched, rather than storing every pass's solves: at 10^5 their 64 MB of fresh
                # pages cost 0.1-0.2 s of system time inside der.solve
                mu = theta[order]
                z = np.empty((k, ez.n_dof))
                for j0 in range(0, k, block):
                    j1 = min(k, j0 + block)
                    y = W[:j1 - j0]
                    np.matmul(S[:, order[j0:j1]].T, Q[:m1], out=y)
                    sc = scratch if j1 - j0 == block else np.empty((ez.n_dof, j1 - j0))
                    _edge_apply_block_fused(y, Q[m1:m1 + j1 - j0], z[j0:j1], sc, *args, True)
                    z[j0:j1] /= mu[j0:j1, None]
                return 1.0 / mu, list(z), passes
        m = m1
    return None


def _edge_eigen(ez, abz_raw, k):
    """The k eigenpairs nearest zero in edge coordinates (K_e = ``abz_raw``, before the supports' links are
    condensed): one banded LDL^T of K (``band_ldlt_compact``, no
    pivoting; its negative pivots count the negative eigenvalues, Sylvester), then block Lanczos on it
    (``_edge_block_lanczos``), ARPACK (``_edge_lowest``) if that does not converge within its basis. Returns
    (eigenvalues, list of full z, negatives, method detail) or None if the factorisation is refused.

    The factorisation is accepted without a test solve when every pivot is positive: the computed factors are then
    the exact factors of K + E with |E_ij| <= c eps sqrt(K_ii K_jj) (the Cholesky backward error analysis, Higham,
    Accuracy and Stability of Numerical Algorithms, Thm 10.3, uses only that the computed pivots are positive: then
    |L| |D| |L|^T = L D L^T + O(eps), whose entries are bounded by its diagonal, which is K's to first order), as
    small as LU with pivoting achieves. With a negative pivot the growth of the factors is not bounded, and a test
    solve's backward error must be at round-off level, as before."""
    # the supports' links condensed and the held slots made identity in place, on K_e itself: they touch only the
    # columns within the bandwidth of a held, dependent or master slot, which are saved here and restored below
    # (abz_raw serves the residuals after this; a copy of the whole band costs its size in fresh pages)
    touched = np.concatenate([np.flatnonzero(ez.fixed), ez.tri_dep, ez.tri_master])
    cols = np.unique(np.clip((touched[:, None] + np.arange(-EDGE_BAND, EDGE_BAND + 1)[None, :]).ravel(), 0,
                             ez.n_dof - 1))
    saved = abz_raw[:, cols].copy()
    try:
        return _edge_eigen_factorised(ez, abz_raw, k)
    finally:
        abz_raw[:, cols] = saved


def _test_solve_is_round_off(ez, abz, solve):
    """Whether ``solve`` (the factors of the edge band ``abz``) answers a random right-hand side on the free z with
    a componentwise backward error at round-off level (1e-10): the acceptance test of an unpivoted LDL^T."""
    b = np.random.default_rng(0).standard_normal(ez.n_dof)
    b[ez.fixed] = 0.0
    xs = solve(b)
    kx = np.empty(ez.n_dof)
    ka = np.empty(ez.n_dof)
    band_matvec(abz, EDGE_BAND, EDGE_BAND, ez.perm, xs, kx, False)
    band_matvec(abz, EDGE_BAND, EDGE_BAND, ez.perm, xs, ka, True)
    free = ~ez.fixed
    return bool(np.abs(kx - b)[free].max() <= 1e-10 * (ka + np.abs(b))[free].max())


def _edge_eigen_factorised(ez, work, k):
    """``_edge_eigen`` on ``work`` (K_e, modified in place: links condensed, held slots identity)."""
    from ..linalg import BandLDLT

    if ez.tri_dep.size:
        condense_band(work, EDGE_BAND, EDGE_BAND, ez.perm, ez.tri_dep, ez.tri_master, ez.tri_coef)
    constrain_band(work, EDGE_BAND, EDGE_BAND, ez.perm, ez.fixed, 1.0)
    f = BandLDLT(ez.n_dof, EDGE_BAND)
    f.ensure(ez.n_dof, EDGE_BAND)
    neg = band_ldlt_compact(work, EDGE_BAND, EDGE_BAND, f.L, f.D)
    if neg < 0:
        return None
    if neg > 0:
        # backward error of a test solve at round-off level, else refused (no pivoting on an indefinite matrix)
        def solve(b):
            xs = b.copy()[:, None]
            ldlt_compact_solve_block(f.L, f.D, xs)
            return np.ascontiguousarray(xs[:, 0])

        if not _test_solve_is_round_off(ez, work, solve):
            return None
    lanczos = _edge_block_lanczos_fused if EDGE_LANCZOS == "fused" else _edge_block_lanczos
    got = lanczos(ez, f.L, f.D, k)
    if got is not None:
        ev, z, passes = got
        return ev, z, int(neg), f"block Lanczos, {passes} passes of {EDGE_LANCZOS_BLOCK}"
    old = _edge_lowest(ez, work, k)
    return None if old is None else old + ("ARPACK",)


def _edge_lowest(ez, abz, k, tol=1e-10):
    """Lanczos (ARPACK) on R K^-1 R^T (M_e = R^T R, K the condensed K_e on the free z), i.e. shift-invert at
    sigma = 0 in standard symmetric form on one banded LDL^T of K, whose pivots count its negative eigenvalues
    (Sylvester). Returns (eigenvalues, list of eigenvectors as full z with the links applied, negatives), or None
    if the factorisation is refused
    (a zero pivot, or a test solve whose backward error is not at round-off level)."""
    import scipy.sparse.linalg as spla

    L, D, neg = band_ldlt(abz, EDGE_BAND, EDGE_BAND, ez.perm, 0.0, ez.mass, ez.fixed, 0.0)
    if neg < 0:
        return None
    # backward error of a test solve at round-off level, else refused (no pivoting on an indefinite matrix)
    if not _test_solve_is_round_off(ez, abz, lambda b: band_ldlt_solve(L, D, ez.perm, b)):
        return None
    args = (L, D, ez.massive, ez.root, ez.fixed, ez.tri_dep, ez.tri_master, ez.tri_coef, ez.N)
    n_m = ez.massive.size
    kk = min(k, n_m - 2)
    ncv = min(n_m - 1, max(2 * kk + 1, 12))
    Cop = spla.LinearOperator((n_m, n_m), matvec=lambda w: _edge_apply(np.ascontiguousarray(w).ravel(), *args),
                              dtype=float)
    v0 = np.random.default_rng(0).standard_normal(n_m)       # (reproducible: a seeded start)
    mu, w = spla.eigsh(Cop, k=kk, which="LM", ncv=ncv, tol=tol, v0=v0)
    keep = mu != 0.0
    mu, w = mu[keep], w[:, keep]
    z = [_edge_rt_solve(np.ascontiguousarray(w[:, j]), *args) / mu[j] for j in range(w.shape[1])]
    return 1.0 / mu, z, int(neg)


@njit(cache=True)
def _edge_checks(abz, kb, Zr, lam, mass, n_nodes, tri_dep, tri_master, tri_coef, fixed, full):
    """For the eigenpairs (lam[c], Zr[c]) in edge coordinates (rows of full z, links applied), in one pass over the
    band: ``full`` (n, k) <- the node-coordinate vectors x = T z (zero on held DOFs), and per pair (columns of the
    returned (5, k)): ||r||^2 and ||c||^2 of the residual r = K x - lam M x and of c = M x on the free variables of
    the node coordinates (condensed by the links ``tri_*``, zero on ``fixed``), K x evaluated as T^-T (K_e z)
    (differences: no cancellation of the node-coordinate stiffness); ||a||^2 and sum a_i |z_i| of a = |K_e| |z|
    (round-off levels); x^T M x."""
    k, n = Zr.shape
    off = 2 * kb
    for c in range(k):
        for i in range(n):
            full[i, c] = Zr[c, i]
    KZ = np.empty((n, k))
    AZ = np.empty((n, k))
    s = np.empty(k)
    sa = np.empty(k)
    for i in range(n):                          # K_e z and |K_e| |z|, the k vectors side by side, by rows
        for c in range(k):
            s[c] = 0.0
            sa[c] = 0.0
        for j in range(max(0, i - kb), min(n - 1, i + kb) + 1):
            a = abz[off + i - j, j]
            if a == 0.0:
                continue
            for c in range(k):
                v = a * full[j, c]
                s[c] += v
                sa[c] += abs(v)
        for c in range(k):
            KZ[i, c] = s[c]
            AZ[i, c] = sa[c]
    acc = np.zeros((3, k))
    for node in range(n_nodes):                 # x = T z: prefix sums, the k vectors in one sweep
        for a in range(3):
            i = 4 * node + a
            for c in range(k):
                acc[a, c] += full[i, c]
                full[i, c] = acc[a, c]
    for node in range(n_nodes - 1):             # T^-T: differences
        for a in range(3):
            for c in range(k):
                KZ[4 * node + a, c] -= KZ[4 * (node + 1) + a, c]
    # T_L^T on the node coordinates' free variables touches only the first p slots (the start's links): r and c
    # there first, the links applied in their order; then one sweep over all slots
    p = 0
    for t in range(tri_dep.shape[0]):
        p = max(p, tri_master[t] + 1, tri_dep[t] + 1)
    rp = np.empty((p, k))
    cp = np.empty((p, k))
    for c in range(k):
        for i in range(p):
            mx = mass[i] * full[i, c]
            rp[i, c] = KZ[i, c] - lam[c] * mx
            cp[i, c] = mx
        for t in range(tri_dep.shape[0]):
            rp[tri_master[t], c] += tri_coef[t] * rp[tri_dep[t], c]
            cp[tri_master[t], c] += tri_coef[t] * cp[tri_dep[t], c]
    out = np.zeros((5, k))
    for i in range(n):
        for c in range(k):
            mx = mass[i] * full[i, c]
            if i < p:
                ri = rp[i, c]
                ci = cp[i, c]
            else:
                ri = KZ[i, c] - lam[c] * mx
                ci = mx
            out[2, c] += AZ[i, c] * AZ[i, c]
            out[3, c] += AZ[i, c] * abs(Zr[c, i])
            out[4, c] += full[i, c] * mx
            if fixed[i]:
                full[i, c] = 0.0
                continue
            out[0, c] += ri * ri
            out[1, c] += ci * ci
    return out


def _edge_out(system, ez, abz_raw, edge, idx, mass, k, out):
    """``lowest_modes``' result from the edge-coordinate eigenpairs: the vectors in node coordinates (x = T z);
    the residuals ||K x - lambda M x|| / (|lambda| ||M x||) on the free variables of the node coordinates, K x
    evaluated as T^-T K_e z (differences: no cancellation of the node-coordinate stiffness), with their round-off
    level (``residual_floors``: 2 eps || |K_e| |z| || / (|lambda| ||M x||), which grows like eps n^3 for a bending
    mode -- the first-order bound it gives on the eigenvalue is pessimistic, its error being quadratic in the
    residual); the eigenvalues' round-off floors eps |z|^T |K_e| |z| / x^T M x (eps n^2 for a bending mode, against
    eps n^4 in node coordinates)."""
    ev, zs, neg, detail = edge
    order = np.argsort(ev)[:k]
    ev = ev[order]
    eps = np.finfo(float).eps
    full = np.empty((system.rod.n_dof, order.size))
    Zr = np.array([zs[j] for j in order]).reshape(order.size, -1)
    lk = system.links
    sums = _edge_checks(abz_raw, EDGE_BAND, Zr, np.ascontiguousarray(ev), mass, ez.N, lk.tri_dep, lk.tri_master,
                        lk.tri_coef, system.fixed, full)
    den = np.maximum(np.abs(ev) * np.sqrt(sums[1]), 1e-300)
    res = np.sqrt(sums[0]) / den
    res_floor = 2.0 * eps * np.sqrt(sums[2]) / den
    floors = eps * sums[3] / np.maximum(sums[4], 1e-300)
    out.update(eigenvalues=ev, vectors=full, residuals=res, residual_floors=res_floor, floors=floors,
               method=EDGE_METHOD, inertia=(neg, 0.0), eigen_solver=detail)
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
        x = np.asarray(x)
        if np.iscomplexobj(x):        # eigenvectors of a non-symmetric pencil: the real and imaginary parts apart
            if absolute:
                return self._mul_numba(np.abs(x), True)
            return self._mul_numba(x.real, False) + 1j * self._mul_numba(x.imag, False)
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
        if symmetric and n_below >= 0:
            # the inertia counted B = K - sigma M; the eigen-solver's matrix is B + U C U^T (the symmetry modes
            # projected out, moved to beta). Haynsworth on [[B, U], [U^T, -C^-1]] both ways:
            # negatives(B + U C U^T) = negatives(B) + positives(cap) - positives(C), cap = C^-1 + U^T B^-1 U, and
            # positives(C) = mm (C = [[A, -I], [-I, 0]] has the inertia of A and -A^-1 together, A = S + beta I
            # regular). A symmetry mode slightly below sigma -- a writhed ring's material sliding, O(h^2) -- was
            # counted as a negative eigenvalue the projected pencil does not have
            n_below += int(np.sum(np.linalg.eigvalsh(0.5 * (cap + cap.T)) > 0)) - mm

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
        # ARPACK's start is random unless given: seeded, so that a run's modes (a degenerate pair's basis, the
        # kick of der.continuation.leave_unstable) are the same every run
        mu, y = spla.eigsh(C, k=kk, which="LM", ncv=min(n_m - 1, ncv),
                           v0=np.random.default_rng(0).standard_normal(n_m))
        keep = mu != 0.0
        mu, y = mu[keep], y[:, keep]
        lifted = np.zeros((n, y.shape[1]))
        lifted[massive] = root[:, None] * y
        vec = op(lifted) / mu[None, :]
        ev = sigma + 1.0 / mu
    elif symmetric:
        ev, vec = spla.eigsh(A, k=kk, M=Mdiag, sigma=sigma, which="LM", OPinv=OPinv, ncv=ncv,
                             v0=np.random.default_rng(0).standard_normal(n))
    else:
        ev, vec = spla.eigs(A, k=kk, M=Mdiag, sigma=sigma, which="LM", OPinv=OPinv, ncv=ncv,
                            v0=np.random.default_rng(0).standard_normal(n))
    return ev, vec, n_below, sigma


def _free_full(system):
    free = system.free.copy()
    if not system.rod.closed:
        free[4 * system.rod.n_nodes - 1] = False
    return free


def stability(system, result, n_eigenvalues=6):
    """Fill ``result.min_eigenvalue``, ``result.eigenvalues``, ``result.stable``, ``result.flutter``,
    ``result.stability_note``, ``result.stability_method`` (``lowest_modes``' method) and ``result.stability_time``
    (seconds; not part of ``wall_time``)."""
    t0, c0 = time.perf_counter(), time.process_time()
    state = result.state
    # the Hessian at the final state when the solver assembled it with its last force evaluation (its assembly
    # time counted here)
    assembly = take_hessian(system, state)
    out = lowest_modes(system, state, n_eigenvalues, assembled=assembly is not None)
    if assembly is not None:
        t0 -= assembly[0]
        c0 -= assembly[1]
    result.stability_method = out["method"]
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
        result.stability_cpu_time = time.process_time() - c0
        return result
    if ev.size == 0:
        result.min_eigenvalue = np.inf
        result.eigenvalues = np.zeros(0)
        result.stable = True
        result.flutter = False
        result.stability_note = (f"every free DOF is a symmetry mode ({out['n_symmetry']} removed) or massless: "
                                 f"no finite eigenvalue, stable")
        result.stability_time = time.perf_counter() - t0
        result.stability_cpu_time = time.process_time() - c0
        return result
    floor = float(out["floors"][0])
    lam_min = float(ev.real[0])
    n_below, sigma = out.get("inertia", (-1, 0.0))
    if symmetric and out["method"] == EDGE_METHOD:
        # the inertia of K itself (sigma = 0) counts the negative eigenvalues exactly; those within their round-off
        # floor of zero may be counted either way. More of them than found: they lie beyond every found one
        # (shift-invert finds the eigenvalues nearest zero), so the lowest is below -max |found|
        found = int(np.sum(ev.real < float(out["floors"].max())))
        if n_below > found:
            notes.append(f"{n_below} negative eigenvalues by inertia (the {found} nearest zero listed); the lowest "
                         f"is below {-np.abs(ev.real).max():.6g}")
            lam_min = min(lam_min, -float(np.abs(ev.real).max()))
    elif symmetric and out["method"] != "dense":
        # shift-invert finds the eigenvalues nearest sigma: count all negative ones (below the floor) by
        # inertia as a check -- from the LDL^T factors of K - sigma M the eigen-solver used when it had them
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
    # (edge path: the residual's own round-off level, eps n^3 for a bending mode, is known; a residual at it is no
    # sign of an inaccurate eigenpair -- the eigenvalue's error is quadratic in it)
    res_level = float(out["residual_floors"][0]) if "residual_floors" in out else 0.0
    if res_max > max(RESIDUAL_TOL, 10.0 * res_level):
        level = f"; its round-off level {res_level:.1e}" if res_level else ""
        notes.append(f"lowest eigenpair residual {res_max:.1e} (relative{level}), round-off floor of the eigenvalue "
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
    result.stability_cpu_time = time.process_time() - c0
    return result
