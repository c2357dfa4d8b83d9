"""Inextensibility as a constraint for the explicit solver: projections onto the edge-length manifold.

The constraints are ``g_j(q) = |e_j| - l_j = 0`` for every edge j. Their Jacobian ``C`` has the row
``(-t_j, +t_j)`` on the two nodes of edge j (t_j the unit tangent), so with the inverse lumped mass ``W``
(zero on fixed DOFs) the matrix ``A = C W C^T`` is tridiagonal for an open rod and cyclic tridiagonal for a
ring: every projection is one O(n) solve.

* ``project_force``: splits a generalized force f into its part tangent to the manifold,
  ``f - C^T mu`` with ``mu = A^-1 C W f``; ``mu`` is the multiplier (the edge tension, force units, positive
  in tension) that balances f at equilibrium, the same ``lam`` as the stretch energy's ``lam_j g_j``.
* ``project_positions``: the fast projection of Goldenthal et al. 2007 ("Efficient simulation of inextensible
  cloth"): ``q <- q - W C(q)^T A(q)^-1 g(q)`` repeated (a Newton iteration on the mass-weighted closest point
  of the manifold), quadratically convergent.
* ``project_velocity``: the RATTLE step, ``v <- v - W C^T A^-1 C v``: the velocity made tangent to the
  manifold at the projected positions (the M-orthogonal projection, so it can only lower the kinetic energy).

End supports (hinges, rollers, clamps, sliding or not: ``constraints.Links``, q = c + T y) are handled in the
free variables y: the Jacobian is C T, whose rows stay on the two nodes of each edge (a support links only its end
edge's nodes), so A stays (cyclic) tridiagonal; forces are condensed (T^T f), and position corrections are made
on the masters and expanded to the dependents (the links are linear).
Edges whose length no free variable changes (both nodes fully fixed by a clamp, or an inextensible rod's clamped
end edge, held whole by its links) have a zero row; their multiplier is left at 0 and their length is whatever
the constraints hold (``held_strain`` reports it).
All kernels work on the flat state vector ``q`` (4 entries per node: x, y, z, theta) and skip theta.
"""
import numpy as np
from numba import njit
# numba's cache keys a kernel on its own file only: this file was edited with the compensated edges of
# issue 17 (geometry.edge_array's low parts, stencils.curvature_binormal_of / elongation) so that its
# kernels are compiled again with them.

from ..geometry import add_compensated_one, edge_array
from ..linalg import expand_step


ROW_TOL = 1e-8   # a constraint row (unit-tangent entries) smaller than this on the free variables is no constraint


@njit(cache=True)
def _rows(q, edge_nodes, l_bar, w, R, g, q_lo=None, tri_dep=None, tri_master=None, tri_coef=None):
    """The constraint Jacobian's rows R (ne, 6) -- the entries of row j on the x, y, z of edge j's first node
    (R[j, :3]) and of its second node (R[j, 3:]) -- and the elongations g (ne,) at q; returns max |g_j| / l_j over
    the edges whose length can change, inf if an edge vanished. Without end-support links the row is
    (-t_j, +t_j), t_j the unit tangent. With them (``constraints.Links`` triplets: q = c + T y) it is the row of
    C T, the Jacobian in the free variables y: each dependent's entry is added, times its coefficient, to its
    master's and the dependent's set to 0. A support links only the two nodes of its end edge and an inner
    dependent only to inner masters, so every master stays on the edge's own nodes (else the rows are set to nan
    and inf is returned). A row that is zero on the free variables up to round-off (a clamped end edge held whole
    by its links, which may only slide rigidly) is set to 0: that edge keeps its length whatever the free
    variables do (``held_strain`` reports it). With ``q_lo`` (the low parts of compensated positions,
    ``RodState.q_lo``) the edges are formed from both parts, as ``geometry.edge_array`` does: each is then rounded
    at its own length, not at the size of the coordinates."""
    worst = 0.0
    ne = edge_nodes.shape[0]
    for j in range(ne):
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        e0 = q[b] - q[a]
        e1 = q[b + 1] - q[a + 1]
        e2 = q[b + 2] - q[a + 2]
        if q_lo is not None:
            e0 += q_lo[b] - q_lo[a]
            e1 += q_lo[b + 1] - q_lo[a + 1]
            e2 += q_lo[b + 2] - q_lo[a + 2]
        le = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        if not le > 0.0:
            return np.inf
        R[j, 0] = -e0 / le
        R[j, 1] = -e1 / le
        R[j, 2] = -e2 / le
        R[j, 3] = e0 / le
        R[j, 4] = e1 / le
        R[j, 5] = e2 / le
        g[j] = le - l_bar[j]
    if tri_dep is not None:
        ok = _condense_rows(edge_nodes, R, tri_dep, tri_master, tri_coef)
        if not ok:
            return np.inf
    for j in range(ne):
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        size = 0.0
        for c in range(3):
            if w[a + c] > 0.0:
                size += R[j, c] * R[j, c]
            if w[b + c] > 0.0:
                size += R[j, 3 + c] * R[j, 3 + c]
        if size <= ROW_TOL * ROW_TOL:
            for c in range(6):
                R[j, c] = 0.0
            continue
        r = abs(g[j]) / l_bar[j]
        if r > worst:
            worst = r
    return worst


@njit(cache=True)
def _slot(edge_nodes, j, dof):
    """Where the position entry ``dof`` of the state sits in row j of ``_rows`` (0..5), -1 if not on edge j."""
    node, c = dof // 4, dof % 4
    if c == 3:
        return -1
    if edge_nodes[j, 0] == node:
        return c
    if edge_nodes[j, 1] == node:
        return 3 + c
    return -1


@njit(cache=True)
def _condense_rows(edge_nodes, R, tri_dep, tri_master, tri_coef):
    """R <- R T on the rows of the edges that touch a dependent (the end supports' links): False if a master is
    not on such an edge (a coupling the band-preserving links never make)."""
    ne = edge_nodes.shape[0]
    for k in range(tri_dep.shape[0]):
        node = tri_dep[k] // 4
        for j in range(ne):
            if edge_nodes[j, 0] != node and edge_nodes[j, 1] != node:
                continue
            sd = _slot(edge_nodes, j, tri_dep[k])
            sm = _slot(edge_nodes, j, tri_master[k])
            if sm < 0:
                return False
            R[j, sm] += tri_coef[k] * R[j, sd]
    for k in range(tri_dep.shape[0]):
        node = tri_dep[k] // 4
        for j in range(ne):
            if edge_nodes[j, 0] == node or edge_nodes[j, 1] == node:
                R[j, _slot(edge_nodes, j, tri_dep[k])] = 0.0
    return True


@njit(cache=True)
def _assemble(edge_nodes, R, w, closed, diag, off):
    """A = C W C^T (C the rows R): diag[j] = A_jj, off[j] = A_{j, j+1} (cyclic for a ring; off[-1] unused for an
    open rod). Zero rows (both nodes fixed, or an edge held whole) get diag 1: with a zero right-hand side their
    multiplier stays 0."""
    ne = edge_nodes.shape[0]
    for j in range(ne):
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        d = 0.0
        for c in range(3):
            d += R[j, c] * R[j, c] * w[a + c] + R[j, 3 + c] * R[j, 3 + c] * w[b + c]
        diag[j] = d if d > 0.0 else 1.0
        off[j] = 0.0
    n_off = ne if closed else ne - 1
    for j in range(n_off):
        k = (j + 1) % ne
        s = 4 * edge_nodes[j, 1]          # the node shared by edges j (its end) and k (its start)
        o = 0.0
        for c in range(3):
            o += R[j, 3 + c] * R[k, c] * w[s + c]
        off[j] = o


@njit(cache=True)
def _solve(diag, off, rhs, closed, x, work_c, work_d):
    """Solve the symmetric (cyclic) tridiagonal system A x = rhs (A from ``_assemble``). Thomas' algorithm
    (A is symmetric positive definite when the constraints are independent); a ring by Sherman-Morrison on
    the corner entries."""
    n = diag.shape[0]
    if not closed or n < 3:
        _thomas(diag, off, rhs, x, work_c, work_d, 0.0, 0.0)
        return
    # A = T + u v^T, u = (gamma, 0, ..., 0, corner), v = (1, 0, ..., 0, corner / gamma): T is tridiagonal with
    # diag[0] - gamma and diag[-1] - corner^2 / gamma
    corner = off[n - 1]
    gamma = -diag[0]
    y = np.empty(n)
    z = np.empty(n)
    u = np.zeros(n)
    u[0] = gamma
    u[n - 1] = corner
    _thomas(diag, off, rhs, y, work_c, work_d, -gamma, corner * corner / gamma)
    _thomas(diag, off, u, z, work_c, work_d, -gamma, corner * corner / gamma)
    fact = (y[0] + corner / gamma * y[n - 1]) / (1.0 + z[0] + corner / gamma * z[n - 1])
    for i in range(n):
        x[i] = y[i] - fact * z[i]


@njit(cache=True)
def _thomas(diag, off, rhs, x, c, d, shift0, shiftn):
    """Tridiagonal solve with diag[0] += shift0 and diag[-1] -= shiftn (off[j] couples j and j+1)."""
    n = diag.shape[0]
    b0 = diag[0] + shift0
    if n == 1:
        x[0] = rhs[0] / (b0 - shiftn)
        return
    c[0] = off[0] / b0
    d[0] = rhs[0] / b0
    for i in range(1, n):
        bi = diag[i] - (shiftn if i == n - 1 else 0.0)
        m = bi - off[i - 1] * c[i - 1]
        if i < n - 1:
            c[i] = off[i] / m
        d[i] = (rhs[i] - off[i - 1] * d[i - 1]) / m
    x[n - 1] = d[n - 1]
    for i in range(n - 2, -1, -1):
        x[i] = d[i] - c[i] * x[i + 1]


@njit(cache=True)
def _c_times(edge_nodes, R, u, out):
    """out = C u: the rate of change of each edge length along u."""
    for j in range(edge_nodes.shape[0]):
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        s = 0.0
        for c in range(3):
            s += R[j, c] * u[a + c] + R[j, 3 + c] * u[b + c]
        out[j] = s


@njit(cache=True)
def _add_ct(edge_nodes, R, mu, scale, w, out):
    """out += scale * W C^T mu (w = None-like: pass ones for plain C^T mu)."""
    for j in range(edge_nodes.shape[0]):
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        for c in range(3):
            out[a + c] += scale * mu[j] * R[j, c] * w[a + c]
            out[b + c] += scale * mu[j] * R[j, 3 + c] * w[b + c]


@njit(cache=True)
def project_force(q, edge_nodes, l_bar, w, closed, f, mu, q_lo=None, tri_dep=None, tri_master=None, tri_coef=None):
    """f <- f - C^T mu with mu = A^-1 C W f (mu written to ``mu``): the part of the force f that does work along
    the manifold. At an equilibrium the remainder vanishes and mu is the edge tension. ``w`` is the inverse
    mass, zero on fixed DOFs (f must be zero there too); ``q_lo`` the low parts of compensated positions (or None).
    With the end supports' link triplets (``constraints.Links``; f then the force on the free variables,
    ``linalg.condense_vector``) C is the Jacobian in the free variables, C T (``_rows``).
    Returns False if an edge vanished."""
    ne = edge_nodes.shape[0]
    R = np.empty((ne, 6))
    g = np.empty(ne)
    if not np.isfinite(_rows(q, edge_nodes, l_bar, w, R, g, q_lo, tri_dep, tri_master, tri_coef)):
        return False
    diag = np.empty(ne)
    off = np.empty(ne)
    _assemble(edge_nodes, R, w, closed, diag, off)
    wf = f * w
    rhs = np.empty(ne)
    _c_times(edge_nodes, R, wf, rhs)
    _solve(diag, off, rhs, closed, mu, np.empty(ne), np.empty(ne))
    ones = np.ones(f.shape[0])
    _add_ct(edge_nodes, R, mu, -1.0, ones, f)
    for i in range(f.shape[0]):
        if w[i] == 0.0:
            f[i] = 0.0
    return True


@njit(cache=True)
def project_positions(q, edge_nodes, l_bar, w, closed, max_iter, target, q_lo=None, tri_dep=None, tri_master=None,
                      tri_coef=None):
    """Fast projection of q onto |e_j| = l_j (in place; fixed DOFs, w = 0, never move). Iterates while the
    largest strain exceeds ``target``, at most ``max_iter`` times, and stops early where it no longer falls
    fourfold below 1e-9 (the round-off floor). With ``q_lo`` the positions are compensated pairs
    ``q + q_lo`` (``RodState.q_lo``): edges are formed from both parts and each correction is added without
    rounding it to the coordinate (``geometry.add_compensated``), so that the projection's floor is eps |e|, not
    eps |x|. With the end supports' link triplets the correction is made in the free variables and the
    dependents follow it (``linalg.expand_step``: the links are linear), so q stays on the supports' links.
    Returns the largest |strain| left (inf if an edge vanished)."""
    ne = edge_nodes.shape[0]
    R = np.empty((ne, 6))
    g = np.empty(ne)
    diag = np.empty(ne)
    off = np.empty(ne)
    dl = np.empty(ne)
    wc = np.empty(ne)
    wd = np.empty(ne)
    linked = tri_dep is not None and tri_dep.shape[0] > 0
    dq = np.zeros(q.shape[0]) if (q_lo is not None or linked) else np.zeros(0)
    worst = _rows(q, edge_nodes, l_bar, w, R, g, q_lo, tri_dep, tri_master, tri_coef)
    for it in range(max_iter):
        if not np.isfinite(worst) or worst <= target:
            break
        _assemble(edge_nodes, R, w, closed, diag, off)
        _solve(diag, off, g, closed, dl, wc, wd)
        if dq.shape[0] == 0:
            _add_ct(edge_nodes, R, dl, -1.0, w, q)
        else:
            dq[:] = 0.0
            _add_ct(edge_nodes, R, dl, -1.0, w, dq)
            if linked:
                expand_step(dq, tri_dep, tri_master, tri_coef)
            for i in range(q.shape[0]):
                if dq[i] != 0.0:
                    if q_lo is None:
                        q[i] += dq[i]
                    else:
                        add_compensated_one(q, q_lo, i, dq[i])
        new = _rows(q, edge_nodes, l_bar, w, R, g, q_lo, tri_dep, tri_master, tri_coef)
        stuck = not new < 0.25 * worst
        worst = new
        if stuck and worst < 1e-9:    # no longer quadratic at this size: the round-off floor
            break
    return worst


@njit(cache=True)
def project_velocity(q, edge_nodes, l_bar, w, closed, v, q_lo=None, tri_dep=None, tri_master=None, tri_coef=None):
    """v <- v - W C^T A^-1 C v (RATTLE): the velocity made tangent to the manifold at q (+ q_lo), in place (with
    link triplets: v on the free variables, C the Jacobian in them)."""
    ne = edge_nodes.shape[0]
    R = np.empty((ne, 6))
    g = np.empty(ne)
    if not np.isfinite(_rows(q, edge_nodes, l_bar, w, R, g, q_lo, tri_dep, tri_master, tri_coef)):
        return False
    diag = np.empty(ne)
    off = np.empty(ne)
    _assemble(edge_nodes, R, w, closed, diag, off)
    rhs = np.empty(ne)
    _c_times(edge_nodes, R, v, rhs)
    mu = np.empty(ne)
    _solve(diag, off, rhs, closed, mu, np.empty(ne), np.empty(ne))
    _add_ct(edge_nodes, R, mu, -1.0, w, v)
    return True


@njit(cache=True)
def tension_energy(q, edge_nodes, l_bar, lam, q_lo):
    """sum_j lam_j (|e_j| - l_j): the multipliers' share of the Lagrangian E + lam . g, whose change along a step
    is second order in the strain the step leaves (E's own is first order: lam times it). The energy guard of the
    projected FIRE compares E + lam . g, so that the strain a step leaves under the projection's target (its
    change of E is lam l strain, 1e-13 of a unit tension: above the guard's 64 eps) is not taken for an energy
    rise (a perversion pulled by P = A1 / l^2 had every step rejected at residual 6.6e-7)."""
    s = 0.0
    for j in range(edge_nodes.shape[0]):
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        le2 = 0.0
        for c in range(3):
            e = (q[b + c] - q[a + c]) + (q_lo[b + c] - q_lo[a + c])
            le2 += e * e
        s += lam[j] * (np.sqrt(le2) - l_bar[j])
    return s


def held_strain(rod, state, w, links=None):
    """(edges, strains): the edges whose length no free variable can change (both nodes fully fixed, or an end
    edge the supports' ``links`` hold whole) and the strain the constraints hold them at."""
    ne = rod.n_edges
    R = np.empty((ne, 6))
    g = np.empty(ne)
    tri = () if links is None or not links.tri_dep.size else (links.tri_dep, links.tri_master, links.tri_coef)
    _rows(state.q, rod.edge_nodes, rod.l_bar, w, R, g, state.q_lo, *tri)
    held = np.flatnonzero(~R.any(axis=1))
    length = np.linalg.norm(edge_array(state.q, rod.edge_nodes, state.q_lo)[held], axis=1)
    return held, np.abs(length - rod.l_bar[held]) / rod.l_bar[held]


def inverse_mass(system):
    """Inverse lumped mass per DOF, zero on the fixed ones (they take no constraint impulse)."""
    w = 1.0 / system.mass
    w[system.fixed] = 0.0
    return w
