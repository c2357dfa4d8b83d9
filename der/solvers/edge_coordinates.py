"""Edge coordinates of an open rod held at its start: x_0, the edge vectors e_j = x_{j+1} - x_j and the edge
angles (q = T z, T: cumulative sums of the node slots). The one home of the change of variables that both the
stability analysis (der.solvers.stability, method "edge shift-invert") and the implicit solver's opt-in Newton
steps (``SolverOptions(edge_newton=True)``, der.solvers.implicit) use.

Why: in node coordinates the stiffness entries are of order A1/h^3 while K v is of order lambda h for a smooth
bending mode, and a Newton step or an eigenvalue resolves only what survives that cancellation (condition number
~ n^4: a cantilever's Newton steps are round-off at n = 10^5). The edge stiffness K_e = T^T K T is read off the
assembled band by translation invariance (every row and column of K sums to zero over the nodes, per component)
in a few terms per entry, without the cancellation (``EdgeCoordinates.band``), and checked on a random vector
(``EdgeCoordinates.check_band``); the stretch penalty becomes block-diagonal and the condition number falls to
~ n^2. It is banded, half-bandwidth EDGE_BAND = 7 (against 10 in node coordinates).
"""
import numpy as np
from numba import njit

from ..constraints import END_SUPPORTS, FixTheta, Pin, _eliminate, _support_equations
from ..linalg import _is_identity, band_matvec

EDGE_BAND = 7          # half-bandwidth of the stiffness in edge coordinates (interleaved slots)
EDGE_CHECK_TOL = 1e-11  # K_x = T^-T K_e T^-1 on a random vector, relative to |K_x| |v|


class EdgeCoordinates:
    """The eigenproblem of an open rod held at its start in edge coordinates z: slot 0 holds x_0, node slot c >= 1
    holds the edge vector e_{c-1} = x_c - x_{c-1}, the theta slots are unchanged, q = T z (T: cumulative sums of
    the node slots). The stiffness K_e = T^T K T is read off the assembled K in a few terms per entry by its
    translation invariance (every row and column of K sums to zero over the nodes, per component), with no
    cancellation of the large node-coordinate entries: for node slots c <= d,
    K_e[c, d] = -sum_{a < c, b >= d} K[a, b] (non-zero only for d <= c + 1: the bending stencils couple two edges),
    K_e[c, theta_j] = sum_{a >= c} K[a, theta_j] (zero for c <= j - 1 and c >= j + 3), and the x_0 rows are zero.
    The supports at the start become links between slots 0 and 1 (their equations on x_0, x_1 = x_0 + e_0). The
    mass M_e = T^T M T is dense but only applied (cumulative sums, O(n)), and factored as R^T R with
    R = M^1/2 T T_L (M the lumped mass in node coordinates, T_L the supports' links)."""

    def __init__(self, system, state, mass=None):
        rod = system.rod
        self.N = rod.n_nodes
        self.n_dof = n_dof = rod.n_dof
        fixed = np.zeros(n_dof, dtype=bool)
        fixed[3::4] = system.fixed[3::4]            # edge angles (fix_theta, clamps) and the dummy slot
        x = state.positions
        tri = []
        for c in system.scene.constraints:
            if isinstance(c, Pin):
                fixed[0:3] = True
            elif isinstance(c, END_SUPPORTS):
                G, _ = _support_equations(c, x[0], x[1], rigid_edge=rod.inextensible)
                # x_0 = z_0, x_1 = z_0 + z_1
                Gz = G @ np.block([[np.eye(3), np.zeros((3, 3))], [np.eye(3), np.eye(3)]])
                local = np.array([0, 1, 2, 4, 5, 6])
                for col, _, coefs in _eliminate(Gz, np.zeros(G.shape[0]), ([0, 1, 2], [3, 4, 5])):
                    fixed[local[col]] = True
                    tri.extend((int(local[col]), int(local[c2]), a) for c2, a in coefs.items())
        tri = np.array(tri, dtype=float).reshape(-1, 3)
        self.tri_dep = tri[:, 0].astype(np.int64)
        self.tri_master = tri[:, 1].astype(np.int64)
        self.tri_coef = tri[:, 2].copy()
        self.fixed = fixed
        self.idx = np.flatnonzero(~fixed)
        self.perm = np.arange(n_dof, dtype=np.int64)
        # the eigenproblem's lumped mass per DOF (der.solvers.stability.eigen_mass; None for Newton steps)
        self.mass = mass
        if mass is not None:
            self.massive = np.flatnonzero(mass > 0)
            self.root = np.sqrt(mass[self.massive])

    # q = T z and its transpose, on (n_dof,) or (n_dof, k) arrays
    def to_q(self, z):
        q = z.copy()
        v = q.reshape((self.N, 4) + z.shape[1:])
        v[:, :3] = np.cumsum(v[:, :3], axis=0)
        return q

    def to_z(self, q):
        """z = T^-1 q (differences)."""
        z = q.copy()
        v = z.reshape((self.N, 4) + q.shape[1:])
        qv = q.reshape(v.shape)
        v[1:, :3] = qv[1:, :3] - qv[:-1, :3]
        return z

    def transpose_to_z(self, f):
        """T^T f: the generalized force on z of the node forces f (suffix sums)."""
        g = f.copy()
        v = g.reshape((self.N, 4) + f.shape[1:])
        v[:, :3] = np.cumsum(v[::-1, :3], axis=0)[::-1]
        return g

    def transpose_to_q(self, g):
        """T^-T g (the node forces whose generalized force on z is g)."""
        f = g.copy()
        v = f.reshape((self.N, 4) + g.shape[1:])
        gv = g.reshape(v.shape)
        v[:-1, :3] = gv[:-1, :3] - gv[1:, :3]
        return f

    def expand(self, y):
        """The full z (links applied) of the free variables y."""
        z = np.zeros((self.n_dof,) + y.shape[1:])
        z[self.idx] = y
        if self.tri_dep.size:
            c = self.tri_coef if y.ndim == 1 else self.tri_coef[:, None]
            np.add.at(z, self.tri_dep, c * z[self.tri_master])
        return z

    def condense_full(self, g):
        """T_L^T g on the free z, zero on the held and dependent ones (g a generalized force on the full z)."""
        g = g.copy()
        if self.tri_dep.size:
            c = self.tri_coef if g.ndim == 1 else self.tri_coef[:, None]
            np.add.at(g, self.tri_master, c * g[self.tri_dep])
        g[self.fixed] = 0.0
        return g

    def mass_dot(self, y):
        q = self.to_q(self.expand(y))
        m = self.mass if y.ndim == 1 else self.mass[:, None]
        return self.condense_full(self.transpose_to_z(m * q))[self.idx]

    def band(self, ab, kl, ku):
        """K_e (see the class docstring) in general-band storage with half-bandwidth EDGE_BAND, from the assembled
        node-coordinate band ``ab`` (identity order, half-bandwidths kl = ku = 10)."""
        abz = np.zeros((3 * EDGE_BAND + 1, self.n_dof), order="F")
        edge_band_fill(ab, kl, ku, self.N, abz, EDGE_BAND)
        return abz

    def check_band(self, ab, kl, ku, abz):
        """Relative error of K_x v = T^-T K_e T^-1 v on a random v, against max |K_x v| (round-off if K is
        translation invariant and has the rod's stencil pattern; O(1) if not, e.g. a term tying the rod to the
        ground)."""
        v = np.random.default_rng(1).uniform(-1.0, 1.0, self.n_dof)
        kx = np.empty(self.n_dof)
        band_matvec(ab, kl, ku, self.perm, v, kx, False)
        ke = np.empty(self.n_dof)
        band_matvec(abz, EDGE_BAND, EDGE_BAND, self.perm, self.to_z(v), ke, False)
        return float(np.abs(self.transpose_to_q(ke) - kx).max() / max(np.abs(kx).max(), 1e-300))



@njit(cache=True)
def edge_band_fill(ab, kl, ku, n_nodes, abz, kb):
    """abz <- K_e (general-band storage, half-bandwidth kb) from the node-coordinate band ab (identity order): the
    sums of ``_EdgeCoordinates.band``, entry by entry."""
    off = kl + ku
    offz = 2 * kb
    N = n_nodes
    for c in range(1, N):
        for a in range(3):
            for b in range(3):
                i = 4 * c + a
                j = 4 * c + b
                v = -ab[off + 4 * (c - 1) + a - j, j]
                if c >= 2:
                    v -= ab[off + 4 * (c - 2) + a - j, j]
                if c <= N - 2:
                    jj = 4 * (c + 1) + b
                    v -= ab[off + 4 * (c - 1) + a - jj, jj]
                    abz[offz + i - jj, jj] = -ab[off + 4 * (c - 1) + a - jj, jj]      # slots c, c + 1
                    ii = 4 * (c + 1) + a
                    jc = 4 * (c - 1) + b
                    abz[offz + ii - j, j] = -ab[off + ii - jc, jc]                    # slots c + 1, c
                abz[offz + i - j, j] = v
    for e in range(N - 1):
        t = 4 * e + 3
        for a in range(3):
            acc_r = 0.0
            acc_c = 0.0
            for s in range(2, -1, -1):          # node slots c = e + s: suffix sums over the nodes a >= c
                c = e + s
                if c <= N - 1 and c >= 1:
                    i = 4 * c + a
                    acc_r += ab[off + i - t, t]
                    acc_c += ab[off + t - i, i]
                    abz[offz + i - t, t] = acc_r
                    abz[offz + t - i, i] = acc_c
        for s in range(-1, 2):
            k = e + s
            if k >= 0 and k <= N - 2:
                u = 4 * k + 3
                abz[offz + t - u, u] = ab[off + t - u, u]



@njit(cache=True)
def cumulative_edges(z, n_nodes, hi, lo):
    """(hi, lo) <- q = T z as compensated pairs: for each node slot c the positions x_0 + e_0 + ... + e_{c-1}
    summed with TwoSum (the running error carried and renormalised), so that hi + lo is the exact prefix sum to
    about eps^2; the theta slots are copied (lo 0)."""
    for i in range(z.shape[0]):
        hi[i] = z[i]
        lo[i] = 0.0
    for a in range(3):
        s = 0.0
        c = 0.0
        for k in range(n_nodes):
            x = z[4 * k + a]
            t = s + x
            bb = t - s
            c += (s - (t - bb)) + (x - bb)
            h = t + c
            c = c - (h - t)
            s = h
            hi[4 * k + a] = s
            lo[4 * k + a] = c


def edge_eligible(system):
    """Whether the edge-coordinate path applies: one open rod without contact or follower loads, held at its start
    (a clamp, hinge or roller at the start, or a pin on node 0), nothing else holding a node (fix_theta anywhere)."""
    rod = system.rod
    if rod.closed or system.parts is not None or getattr(system, "terms", ()) or getattr(system, "contact_coo", None):
        return False
    if system.kl != 10 or system.ku != 10 or not _is_identity(system.perm):
        return False
    plan = system.plan
    if plan.has_follower or plan.has_follower_torques:
        # a follower load's stiffness changes the net force (t^T K != 0), which reading K_e off the band assumes
        # away; on a fine mesh it can pass the symmetry and band checks (f h^3 / A1 below their thresholds)
        return False
    held = False
    for c in system.scene.constraints:
        if isinstance(c, FixTheta):
            continue
        if isinstance(c, Pin) and c.node % rod.n_nodes == 0:
            held = True
        elif isinstance(c, END_SUPPORTS) and c.end in ("start", 0):
            held = True
        else:
            return False
    return held



@njit(cache=True)
def band_asymmetry(ab, kb, fixed):
    """max |A_ij - A_ji| / max |A_ij| over the free rows and columns of a general band (half-bandwidth kb,
    identity order)."""
    n = ab.shape[1]
    off = 2 * kb
    big = 0.0
    asym = 0.0
    for j in range(n):
        if fixed[j]:
            continue
        for i in range(j + 1, min(n - 1, j + kb) + 1):
            if fixed[i]:
                continue
            low = ab[off + i - j, j]
            up = ab[off + j - i, i]
            big = max(big, abs(low), abs(up))
            asym = max(asym, abs(low - up))
        big = max(big, abs(ab[off, j]))
    return asym / big if big > 0.0 else 0.0




class EdgeNewton:
    """Newton steps of the implicit solver in edge coordinates (``SolverOptions(edge_newton=True)``, for the scenes
    ``edge_eligible`` accepts): the step solves

        (K_e + D_e / dt) dz = T^T R,    delta = T dz,

    on the free z (the end supports at the start as links between slots 0 and 1, as in the stability analysis),
    K_e = T^T K T read off the band assembled in node coordinates (``EdgeCoordinates.band``), D_e = diag |K_e| the
    pseudo-time damping in these coordinates (dt -> infinity: Newton's method, whatever the damping). The step in
    node coordinates is delta = T dz (prefix sums). ``prepare`` refuses (returns False) a band that fails
    ``check_band``: the caller then takes its node-coordinate step."""

    def __init__(self, system, state):
        from ..linalg import BandLDLT

        self.ez = ez = EdgeCoordinates(system, state)
        n = ez.n_dof
        self.abz = np.zeros((3 * EDGE_BAND + 1, n), order="F")
        self.work = np.zeros_like(self.abz, order="F")
        self.ldlt = BandLDLT(n, EDGE_BAND)
        self.diag = np.ones(n)
        self.refused = 0          # bands refused by the check (node-coordinate steps taken instead)
        self.step_lo = None       # the low part of the last step in q (``step`` returns the high part)

    def prepare(self, ab, kl, ku):
        """K_e from the band ``ab`` assembled at the current state (not modified). False if the check fails."""
        ez = self.ez
        edge_band_fill(ab, kl, ku, ez.N, self.abz, EDGE_BAND)
        if not ez.check_band(ab, kl, ku, self.abz) <= EDGE_CHECK_TOL:
            self.refused += 1
            return False
        d = np.abs(self.abz[2 * EDGE_BAND])
        d[d == 0.0] = 1.0
        self.diag[:] = d
        return True

    def step(self, f, dt):
        """(delta, info): the step in node coordinates for the out-of-balance node forces ``f`` = f_ext - dE/dq
        (full, not condensed) and the pseudo-time step ``dt``; info != 0 for an exactly singular matrix (dgbsv).
        ``delta`` is the high part of the compensated step, ``self.step_lo`` its low part (``_to_q``): the caller
        adds both to the compensated positions."""
        from ..linalg import add_diagonal, band_solve, condense_band, constrain_band

        ez = self.ez
        g = ez.condense_full(ez.transpose_to_z(f))       # T_L^T T^T f on the free z, zero on held slots
        work = self.work
        work[:] = self.abz
        if ez.tri_dep.size:
            condense_band(work, EDGE_BAND, EDGE_BAND, ez.perm, ez.tri_dep, ez.tri_master, ez.tri_coef)
        add_diagonal(work, EDGE_BAND, EDGE_BAND, ez.perm, self.diag, 1.0 / dt)
        constrain_band(work, EDGE_BAND, EDGE_BAND, ez.perm, ez.fixed, 1.0)
        z, info = band_solve(work, EDGE_BAND, EDGE_BAND, ez.perm, g, ldlt=self.ldlt)
        if info != 0:
            return z, info
        delta, self.step_lo = self._to_q(z)
        return delta, 0

    def _to_q(self, z):
        """(hi, lo): the step in q of the edge-coordinate solution z (held slots zeroed, links applied), the
        cumulative sums of the edges as a compensated pair hi + lo (``cumulative_edges``). Rounded
        to a plain sum, the step's differences -- the edges the rod sees -- carry eps |q| rather than their own
        rounding: at 10^5 edges the first step's relative residual was 3.5 with the plain sum, 8.3e-5 with the
        pair (tools/newton_step_accuracy.py, docs/scaling.md)."""
        from ..linalg import expand_step

        ez = self.ez
        z[ez.fixed] = 0.0
        expand_step(z, ez.tri_dep, ez.tri_master, ez.tri_coef)
        hi = np.empty_like(z)
        lo = np.empty_like(z)
        cumulative_edges(z, ez.N, hi, lo)
        return hi, lo

    def resolve(self, f):
        """The step in node coordinates (rounded: the high part of ``_to_q``) for the node forces ``f`` with
        the factors of the last ``step``'s matrix (no new factorisation: ``linalg.band_resolve``); None if that
        step left none. Used by the implicit solver's second-order correction (``SolverOptions(
        second_order_correction=True)``)."""
        from ..linalg import band_resolve

        ez = self.ez
        z = band_resolve(self.work, EDGE_BAND, EDGE_BAND, ez.perm, ez.condense_full(ez.transpose_to_z(f)),
                         self.ldlt)
        if z is None:
            return None
        return self._to_q(z)[0]
