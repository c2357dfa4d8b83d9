"""Contact in the explicit solver (issue 14): FIRE with the IPC barrier forces and a CCD-proven step.

The FIRE kernel of ``explicit.py`` with three additions, kept in this module so that a scene without contact
imports no contact code (``explicit.py`` imports this only when the scene has contact terms):

1. Forces: the barrier gradient of the self-contact pairs (``der.self_contact`` / ``der.rod_contact`` on one
   rod; ``barrier_gradient``: bounding spheres first, then the gradient without the distance Hessian) is added
   to dE/dq at every step, and the barrier energy to the energy the FIRE guard watches (the
   total kinetic + elastic + barrier - load work never increases, as without contact).
2. No passage: every step is first tried, then proven to keep every listed pair at least ``MIN_GAP_FRACTION``
   of its gap along the straight path from the old to the new positions -- by a bound when it holds
   (``step_bound_safe``: twice the largest node displacement at most (1 - MIN_GAP_FRACTION) times the smallest
   gap of the start, the distance of two segments being 1-Lipschitz in each one's displacement), otherwise by
   continuous collision detection (``der.contact.ccd.pairs_ccd``). A step that neither proves safe is rejected
   like one that raises the energy: back to the old state, at rest, with a smaller step. Accepted steps are
   therefore proven non-crossing, however large the forces. (FIRE steps are tiny against the gaps: the bound
   holds on almost every step, and the CCD over ~1,000 pairs, 140 us a step, is rarely run.)
3. Candidate pairs (a Verlet list): the broad phase runs in Python on boxes inflated by ``dhat + 2 margin``;
   pairs not in the list are then more than dhat + 2 margin apart. The kernel ends its call (status
   ``STATUS_REBUILD``) before any step that would move a node more than ``margin`` from where the list was
   built, so an unlisted pair never comes within dhat (no force missed) nor touches (no passage missed).

Layout as in ``explicit._fire_run``; contact arrays as in der/contact (edges (n_edges, 2) node indices,
pairs (n_pairs, 2) edge indices, edge_radius (n_edges,), node_dof (n_nodes,) the index of each node's x).
"""
import numpy as np
from numba import njit
# numba's cache keys a kernel on its own file only: this file was edited with the compensated edges of
# issue 17 (geometry.edge_array's low parts, stencils.curvature_binormal_of / elongation) so that its
# kernels are compiled again with them.

from ..contact.barrier import GAP, barrier, barrier_first_derivative, gap_variable, pair_barrier
from ..contact.ccd import pairs_ccd
from ..contact.distance import closest_parameters, segment_distance2
from ..geometry import add_compensated_one, edge_array, transport_frames
from ..linalg import condense_vector
from ..scene import evaluate
from .explicit import CAP_CUT, NOISE_FACTOR, STATUS_CONVERGED, STATUS_NONFINITE, STATUS_RUNNING, _follow_links
from .projection import project_force, project_positions, project_velocity, tension_energy

STATUS_REBUILD = 3
MIN_GAP_FRACTION = 0.1       # as the implicit solver's line search (der/terms/contact.py)
CCD_TOL, CCD_MAX_ITER = 1e-6, 10000


@njit(cache=True)
def pair_barrier_gradient(x, off, dhat, kappa, g):
    """``contact.barrier.pair_barrier``'s energy, gap and gradient (into g (12,)) of one edge pair x (12,), GAP
    variable, without the Hessian: the same arithmetic (closest points, dD/dx = 2 (ca x I)^T r, chain rule through
    the gap), bitwise the same gradient. Returns (energy, gap); energy 0 with g untouched beyond the support, +inf
    on an overlap."""
    D, s, t, region = closest_parameters(x)
    z, zh, z1, z2 = gap_variable(D, off, dhat, GAP)
    if z >= zh:
        return 0.0, z
    if z <= 0.0:
        return np.inf, z
    c1 = kappa * barrier_first_derivative(z, zh) * z1
    ca0, ca1, ca2, ca3 = 1.0 - s, s, t - 1.0, -t
    for i in range(3):
        r = 0.0
        r += ca0 * x[i]
        r += ca1 * x[3 + i]
        r += ca2 * x[6 + i]
        r += ca3 * x[9 + i]
        g[i] = c1 * (2.0 * ca0 * r)
        g[3 + i] = c1 * (2.0 * ca1 * r)
        g[6 + i] = c1 * (2.0 * ca2 * r)
        g[9 + i] = c1 * (2.0 * ca3 * r)
    return kappa * barrier(z, zh), z


@njit(cache=True)
def barrier_gradient(q, edges, pairs, edge_radius, dhat, kappa, grad, q_lo=None):
    """kappa sum b(gap) over the pairs (GAP variable), and its gradient added into ``grad`` (n_dof,) at the node
    DOFs 4 k (positions are q.reshape(-1, 4)[:, :3], plus the low parts ``q_lo`` of compensated positions if
    given). Returns (energy, min gap); energy +inf on an overlap. The min gap is a lower bound of every listed
    pair's gap (exact for the pairs within dhat; a pair farther than dhat by its bounding spheres is not measured
    and contributes that sphere bound), which is what ``step_bound_safe`` needs.

    Each pair within reach goes through ``pair_barrier_gradient`` (no distance Hessian): a FIRE step of the plectoneme at
    n = 400 spent 143 us on its ~400 candidate pairs (straight rod) and 1100 (plectoneme) with ``pair_barrier``'s
    12 x 12 Hessians (tools/bench_explicit_contact.py)."""
    x = np.empty(12)
    g = np.empty(12)
    energy = 0.0
    min_gap = np.inf
    for p in range(pairs.shape[0]):
        ea, eb = pairs[p, 0], pairs[p, 1]
        nodes = (edges[ea, 0], edges[ea, 1], edges[eb, 0], edges[eb, 1])
        for k in range(4):
            for i in range(3):
                x[3 * k + i] = q[4 * nodes[k] + i]
                if q_lo is not None:
                    x[3 * k + i] += q_lo[4 * nodes[k] + i]
        off = edge_radius[ea] + edge_radius[eb]
        # bounding spheres: every point of a segment lies within half its length of its midpoint, so
        # |m_a - m_b| - (l_a + l_b) / 2 - off is a lower bound of the gap; beyond dhat the pair has no force
        mm = 0.0
        la = 0.0
        lb = 0.0
        for i in range(3):
            mm += (0.5 * (x[i] + x[3 + i] - x[6 + i] - x[9 + i])) ** 2
            la += (x[3 + i] - x[i]) ** 2
            lb += (x[9 + i] - x[6 + i]) ** 2
        bound = np.sqrt(mm) - 0.5 * (np.sqrt(la) + np.sqrt(lb)) - off
        if bound >= dhat * (1.0 + 1e-12):
            min_gap = min(min_gap, bound)
            continue
        e, z = pair_barrier_gradient(x, off, dhat, kappa, g)
        min_gap = min(min_gap, z)
        if e == 0.0:
            continue
        if not np.isfinite(e):
            return np.inf, min_gap
        energy += e
        for k in range(4):
            for i in range(3):
                grad[4 * nodes[k] + i] += g[3 * k + i]
    return energy, min_gap


@njit(cache=True)
def barrier_rows(q, edges, pairs, edge_radius, dhat, kappa, mass, rows, q_lo=None):
    """rows[d] += sum_j |H_dj| / sqrt(m_d m_j) of the barrier Hessian H of the listed pairs (node DOFs 4 k + i):
    the contact barrier's share of the Gershgorin row sums (``explicit.stiffness_mass``)."""
    x = np.empty(12)
    g = np.empty(12)
    H = np.empty((12, 12))
    dof = np.empty(12, dtype=np.int64)
    for p in range(pairs.shape[0]):
        ea, eb = pairs[p, 0], pairs[p, 1]
        nodes = (edges[ea, 0], edges[ea, 1], edges[eb, 0], edges[eb, 1])
        for k in range(4):
            for i in range(3):
                dof[3 * k + i] = 4 * nodes[k] + i
                x[3 * k + i] = q[4 * nodes[k] + i]
                if q_lo is not None:
                    x[3 * k + i] += q_lo[4 * nodes[k] + i]
        off = edge_radius[ea] + edge_radius[eb]
        if np.sqrt(segment_distance2(x)) - off >= dhat:
            continue
        e, z = pair_barrier(x, off, dhat, kappa, GAP, False, g, H)
        if e == 0.0 or not np.isfinite(e):
            continue
        for a in range(12):
            s = 0.0
            for b in range(12):
                s += abs(H[a, b]) / np.sqrt(mass[dof[a]] * mass[dof[b]])
            rows[dof[a]] += s
    return rows


@njit(cache=True)
def _positions(q, n_nodes, out):
    for k in range(n_nodes):
        for i in range(3):
            out[k, i] = q[4 * k + i]


@njit(cache=True)
def _max_shift(q, x_ref):
    """Largest node displacement |x_k - x_ref_k|."""
    m = 0.0
    for k in range(x_ref.shape[0]):
        s = 0.0
        for i in range(3):
            s += (q[4 * k + i] - x_ref[k, i]) ** 2
        m = max(m, s)
    return np.sqrt(m)


@njit(cache=True)
def step_bound_safe(q, q_lo, q_old, lo_old, n_nodes, min_gap, fraction):
    """True if the step q_old -> q provably keeps every listed pair's gap above ``fraction`` of its start value
    without CCD. The distance of two segments is 1-Lipschitz in the displacement of each: along the straight
    path, a pair's gap falls by at most s_a + s_b <= 2 s, s the largest node displacement of the step. So if
    2 s <= (1 - fraction) min_gap, every pair keeps gap0 - 2 s >= gap0 - (1 - fraction) gap0 = fraction gap0 over
    the whole step (the gaps of the start state, ``min_gap`` their minimum, as ``barrier_gradient`` returns it).
    A relative 1e-12 of the coordinates covers the rounding of the positions."""
    if not (min_gap > 0.0) or not np.isfinite(min_gap):
        return False
    s2 = 0.0
    xmax = 0.0
    for k in range(n_nodes):
        d2 = 0.0
        for i in range(3):
            j = 4 * k + i
            d = (q[j] - q_old[j]) + (q_lo[j] - lo_old[j])
            d2 += d * d
            xmax = max(xmax, abs(q[j]))
        s2 = max(s2, d2)
    return 2.0 * np.sqrt(s2) + 1e-12 * (1.0 + xmax) <= (1.0 - fraction) * min_gap


@njit(cache=True)
def _forces(plan, q, q_lo, d1, twist, lam, grad, fext, ab, kl, ku, perm, edges, pairs, edge_radius, dhat, kappa):
    """(elastic + barrier energy, smallest gap of the listed pairs); grad <- dE/dq (barrier included), fext <- the
    loads."""
    energy = evaluate(plan, q, d1, twist, lam, np.int64(1), grad, fext, ab, kl, ku, perm, q_lo)
    e_c, gap = barrier_gradient(q, edges, pairs, edge_radius, dhat, kappa, grad, q_lo)
    return energy + e_c, gap


@njit(cache=True)
def fire_run_contact(plan, q, q_lo, d1, tangents, twist, lam, v, mass, fixed, inv_scale, tol, n_steps, dt, dt_max,
                     alpha, n_pos, n_min, f_inc, f_dec, alpha0, f_alpha, kl, ku, perm, e_total, work_done, guard,
                     project, w, closed, target, max_strain, noise, link_dep, link_const, tri_dep, tri_master,
                     tri_coef, edges, pairs, edge_radius, dhat, kappa, x_ref, margin, fresh):
    """``explicit._fire_run`` with contact (module docstring). Returns (status, steps, residual, dt, alpha, n_pos,
    e_total, work_done, rejected, dt_max, ccd_rejected); status STATUS_REBUILD when the next step would move a
    node more than ``margin`` from ``x_ref`` (the state is the last accepted one: rebuild the pair list and call
    again). ``fresh``: the list was just built at this state (then such a step is rejected with a smaller dt
    instead, so that every call advances)."""
    n = q.shape[0]
    n_nodes = x_ref.shape[0]
    grad = np.zeros(n)
    fext = np.zeros(n)
    ab = np.zeros((1, 1)).T    # Fortran-ordered like the solvers' bands: the kernels compile once for both
    q_old = q.copy()
    lo_old = q_lo.copy()
    d1_old = d1.copy()
    t_old = tangents.copy()
    tw_old = twist.copy()
    f = np.zeros(n)
    pos0 = np.empty((n_nodes, 3))
    dpos = np.empty((n_nodes, 3))
    energy, gap = _forces(plan, q, q_lo, d1, twist, lam, grad, fext, ab, kl, ku, perm, edges, pairs, edge_radius,
                          dhat, kappa)
    if project:
        energy += tension_energy(q, plan.edge_nodes, plan.l_bar, lam, q_lo)
    new_gap = gap
    residual = np.inf
    rejected = 0
    ccd_rejected = 0
    for step in range(n_steps):
        residual = 0.0
        for i in range(n):
            f[i] = fext[i] - grad[i]
        condense_vector(f, tri_dep, tri_master, tri_coef, fixed)
        if project and not project_force(q, plan.edge_nodes, plan.l_bar, w, closed, f, lam, q_lo,
                                                 tri_dep, tri_master, tri_coef):
            return (STATUS_NONFINITE, step, residual, dt, alpha, n_pos, e_total, work_done, rejected, dt_max,
                    ccd_rejected)
        for i in range(n):
            r = abs(f[i]) * inv_scale[i]
            if r > residual:
                residual = r
        if not np.isfinite(residual) or not np.isfinite(energy):
            return (STATUS_NONFINITE, step, residual, dt, alpha, n_pos, e_total, work_done, rejected, dt_max,
                    ccd_rejected)
        if residual <= tol:
            return (STATUS_CONVERGED, step, residual, dt, alpha, n_pos, e_total, work_done, rejected, dt_max,
                    ccd_rejected)
        power = 0.0
        vnorm2 = 0.0
        fnorm2 = 0.0
        pnoise2 = 0.0
        for i in range(n):
            power += f[i] * v[i]
            vnorm2 += mass[i] * v[i] * v[i]
            fnorm2 += f[i] * f[i] / mass[i]
            pnoise2 += (noise[i] * v[i]) ** 2
        if power > -NOISE_FACTOR * np.sqrt(pnoise2):
            if fnorm2 > 0.0:
                c = alpha * np.sqrt(vnorm2 / fnorm2)
                for i in range(n):
                    v[i] = (1.0 - alpha) * v[i] + c * f[i] / mass[i]
            n_pos += 1
            if n_pos > n_min:
                dt = min(dt * f_inc, dt_max)
                alpha *= f_alpha
        else:
            for i in range(n):
                v[i] = 0.0
            dt *= f_dec
            alpha = alpha0
            n_pos = 0
        q_old[:] = q
        lo_old[:] = q_lo
        d1_old[:, :] = d1
        t_old[:, :] = tangents
        tw_old[:] = twist
        v_old = v.copy()
        for i in range(n):
            if not fixed[i]:
                v[i] += dt * f[i] / mass[i]
                add_compensated_one(q, q_lo, i, dt * v[i])
        _follow_links(q, q_lo, link_dep, link_const, tri_dep, tri_master, tri_coef)
        ok = True
        if project:
            ok = project_positions(q, plan.edge_nodes, plan.l_bar, w, closed, 20, target, q_lo, tri_dep,
                                   tri_master, tri_coef) <= max_strain
            if ok:
                ok = project_velocity(q, plan.edge_nodes, plan.l_bar, w, closed, v, q_lo, tri_dep, tri_master,
                                      tri_coef)
        if ok and _max_shift(q, x_ref) > margin:
            if not (fresh and step == 0):
                # the pair list no longer covers this step: end the call at the last accepted state
                q[:] = q_old
                q_lo[:] = lo_old
                v[:] = v_old
                return (STATUS_REBUILD, step, residual, dt, alpha, n_pos, e_total, work_done, rejected, dt_max,
                        ccd_rejected)
            ok = False          # a single step larger than the margin: reject it, smaller dt
        if ok and pairs.shape[0] and not step_bound_safe(q, q_lo, q_old, lo_old, n_nodes, gap, MIN_GAP_FRACTION):
            # no passage: the straight path q_old -> q must keep every listed pair's gap above a fraction of its
            # start value (a step CCD does not prove safe is rejected below)
            _positions(q_old, n_nodes, pos0)
            _positions(q, n_nodes, dpos)
            for k in range(n_nodes):
                for i in range(3):
                    dpos[k, i] -= pos0[k, i]
            tau, _, _ = pairs_ccd(pos0, dpos, edges, pairs, edge_radius, MIN_GAP_FRACTION, CCD_TOL, CCD_MAX_ITER)
            if tau < 1.0:
                ok = False
                ccd_rejected += 1
        ok = ok and transport_frames(q, plan.edge_nodes, plan.vertex_edges, t_old, d1_old, tw_old, tangents, d1,
                                     twist, edge_array(q, plan.edge_nodes, q_lo))
        fext_old_dot = 0.0
        for i in range(n):
            fext_old_dot += fext[i] * ((q[i] - q_old[i]) + (q_lo[i] - lo_old[i]))
        new_energy = np.inf
        if ok:
            new_energy, new_gap = _forces(plan, q, q_lo, d1, twist, lam, grad, fext, ab, kl, ku, perm, edges, pairs,
                                          edge_radius, dhat, kappa)
            if project:       # the Lagrangian E + lam . g (projection.tension_energy)
                new_energy += tension_energy(q, plan.edge_nodes, plan.l_bar, lam, q_lo)
        kinetic = 0.0
        fext_new_dot = 0.0
        for i in range(n):
            kinetic += 0.5 * mass[i] * v[i] * v[i]
            fext_new_dot += fext[i] * ((q[i] - q_old[i]) + (q_lo[i] - lo_old[i]))
        new_work = work_done + 0.5 * (fext_old_dot + fext_new_dot)
        new_total = kinetic + new_energy - new_work
        slack = guard * (abs(new_energy) + abs(new_work) + abs(kinetic))
        if not ok or not (new_total <= e_total + slack):
            rejected += 1
            if dt > 0.5 * dt_max:
                dt_max *= CAP_CUT
            q[:] = q_old
            q_lo[:] = lo_old
            d1[:, :] = d1_old
            tangents[:, :] = t_old
            twist[:] = tw_old
            for i in range(n):
                v[i] = 0.0
            dt *= f_dec
            alpha = alpha0
            n_pos = 0
            energy, gap = _forces(plan, q, q_lo, d1, twist, lam, grad, fext, ab, kl, ku, perm, edges, pairs,
                                  edge_radius, dhat, kappa)
            if project:
                energy += tension_energy(q, plan.edge_nodes, plan.l_bar, lam, q_lo)
            e_total = energy - work_done
            continue
        energy = new_energy
        gap = new_gap
        work_done = new_work
        e_total = new_total
    return (STATUS_RUNNING, n_steps, residual, dt, alpha, n_pos, e_total, work_done, rejected, dt_max,
            ccd_rejected)


class ContactRun:
    """The Python side of the explicit solver's contact (module docstring): the Verlet pair list of the scene's
    self-contact term, rebuilt when the kernel asks, and a ``run`` with the signature of ``explicit._fire_run``.
    Only terms with edge-pair barriers (``der.self_contact``, ``der.rod_contact`` on one rod) are handled."""

    def __init__(self, system):
        terms = system.terms
        bad = [t for t in terms if not hasattr(t, "topo")]
        if bad or len(terms) != 1:
            raise ValueError("the explicit solver handles one self-contact term (der.self_contact or "
                             "der.rod_contact on one rod); obstacles and several contact terms need "
                             "solver='implicit'")
        self.term = terms[0]
        self.system = system
        self.margin = self.term.radius
        self.x_ref = None
        self.pairs = None
        self.rebuilds = 0
        self.ccd_rejected = 0

    def energy(self, state):
        """The barrier energy at ``state`` (for the FIRE guard's starting total)."""
        t = self.term
        return float(t.evaluate(state, 0, None, None, None))

    def barrier_rows(self, state, mass, rows):
        """Add the barrier Hessian's Gershgorin rows at ``state`` (``barrier_rows``) into ``rows``; the pair list is
        (re)built first if the state has left its margin."""
        t = self.term
        if self.x_ref is None or _max_shift(state.q, self.x_ref) > self.margin:
            self._rebuild(state.q)
        return barrier_rows(state.q, t.topo.edges, self.pairs, t.topo.edge_radius, t.dhat, t.kappa, mass, rows,
                            state.q_lo)

    def _rebuild(self, q):
        from .. import contact as C

        t = self.term
        self.x_ref = np.ascontiguousarray(q.reshape(-1, 4)[:t.n_nodes, :3])
        self.pairs = C.candidate_pairs(self.x_ref, t.topo, t.dhat + 2.0 * self.margin)
        self.rebuilds += 1

    def run(self, plan, q, q_lo, d1, tangents, twist, lam, v, mass, fixed, inv_scale, tol, n_steps, *rest):
        """``explicit._fire_run``'s contract, run in calls of the contact kernel between pair-list rebuilds
        (bounded: every call after a rebuild takes or rejects at least one step)."""
        t = self.term
        (dt, dt_max, alpha, n_pos, n_min, f_inc, f_dec, alpha0, f_alpha, kl, ku, perm, e_total, work_done, guard,
         project, w, closed, target, max_strain, noise, link_dep, link_const, tri_dep, tri_master, tri_coef) = rest
        done_total, rejected_total = 0, 0
        status, residual = STATUS_RUNNING, np.inf
        fresh = self.x_ref is None or _max_shift(q, self.x_ref) > self.margin
        while done_total < n_steps:
            if fresh:
                self._rebuild(q)
            out = fire_run_contact(
                plan, q, q_lo, d1, tangents, twist, lam, v, mass, fixed, inv_scale, tol, n_steps - done_total, dt, dt_max,
                alpha, n_pos, n_min, f_inc, f_dec, alpha0, f_alpha, kl, ku, perm, e_total, work_done, guard, project,
                w, closed, target, max_strain, noise, link_dep, link_const, tri_dep, tri_master, tri_coef,
                t.topo.edges, self.pairs, t.topo.edge_radius, t.dhat, t.kappa, self.x_ref, self.margin, fresh)
            status, done, residual, dt, alpha, n_pos, e_total, work_done, rejected, dt_max, ccd = out
            done_total += done
            rejected_total += rejected
            self.ccd_rejected += ccd
            if status != STATUS_REBUILD:
                break
            fresh = True
        if status == STATUS_REBUILD:
            status = STATUS_RUNNING
        return status, done_total, residual, dt, alpha, n_pos, e_total, work_done, rejected_total, dt_max


_WARM = []


def warmup():
    """Compile (or load from numba's cache) the explicit solver's contact kernels once per process: a few FIRE
    steps of a small twisted ring with self-contact, so that a solve's wall time holds no compilation. Returns
    the seconds it took (0 afterwards)."""
    if _WARM:
        return 0.0
    import time

    from .. import shapes
    from ..rod import rod_from_shape
    from ..scene import Scene
    from ..terms.contact import self_contact
    from . import solve
    from .system import raise_if_interrupted

    _WARM.append(0.0)              # (the solve below calls this again)
    t0 = time.perf_counter()
    base = rod_from_shape(shapes.ring(1.0, 24), 1.0, 1.5)
    ring = base.with_natural(kappa_bar=base.kappa_bar * 0.0)
    raise_if_interrupted(solve(Scene(ring, contacts=[self_contact(0.02)]), solver="explicit", max_steps=20,
                               stability=False, raise_on_failure=False))
    _WARM[0] = time.perf_counter() - t0
    return _WARM[0]
