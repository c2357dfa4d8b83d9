"""Self-contact of a rod: no two non-neighbouring parts come closer than 2r between centrelines, and no strand
passes through another within a step (IPC: Li et al. 2020). The barrier kappa b(gap; dhat) on the gap
dist - 2r of every edge pair within dhat (GAP variable, der/contact/barrier.py), its PSD-projected Hessian as
COO triplets (the solver then factorises a sparse matrix), and a CCD bound on every step (der/contact/ccd.py).
Design and the choice of dhat and kappa: docs/contact.md, section 6.
"""
import math
from dataclasses import dataclass

import numpy as np

from .. import validate
from . import register

# dhat = DHAT_FRACTION r by default: the range of the contact force, and the bound on its geometric error
DHAT_FRACTION = 0.1
# CCD: every gap keeps at least this fraction of its start value over a step
MIN_GAP_FRACTION = 0.1
KAPPA_RANGE = 100.0          # kappa_max / kappa_min
# broad phase: candidate pairs are listed within dhat + VERLET_MARGIN r and reused while every node stays within
# half that margin of where the list was built (a Verlet list; docs/contact.md, "Fewer broad phases")
VERLET_MARGIN = 1.0
# one pair list per Newton step, for all its line-search trials (BoundSelfContact.step_candidates); False: the
# Verlet list for every trial, as before (kept for the side-by-side benchmark, tools/bench_contact_newton.py)
STEP_LIST = True
# the pair lists of a Newton step's line search cover its arc trials too (q + a delta + a^2 c of the second-order
# corrected search, der/solvers/implicit.py): the step's list is widened to each node's reach along the arc while
# that fits in the Verlet margin, and a CCD over a chord within the reach uses it (BoundSelfContact.cover_arc);
# False: every arc trial, and its passage proof, on the Verlet list or a new broad phase, as before (kept for the
# side-by-side benchmark, tools/profile_contact_iteration.py --set ARC_STEP_LIST=0)
ARC_STEP_LIST = True
# a long step's swept-box pair list (the CCD's, whose boxes hold every pair within range anywhere on the straight
# step, widened by the trials' rounding) is kept for the trials on that step and the state it accepts
# (BoundSelfContact.candidates); False: those trials take the Verlet list, rebuilt at each trial, as before
LONG_STEP_LIST = True
# b''(dhat / 2) / 1 for the GAP barrier: (q + 2) q - 2 log(1/q) - 3 at q = zh / z = 2
_B2_HALF = 8.0 + 2.0 * math.log(2.0) - 3.0


def sorted_pairs(pairs):
    """The rows of a pair list (n, 2) in lexicographic order: every list a term filters its active pairs from
    (the Verlet list, a step's list, a fresh broad phase) then yields them in the same order, so the barrier's
    sums -- and the Newton path -- do not depend on which list, built where, held them."""
    if pairs.shape[0] < 2:
        return pairs
    from ..contact.broadphase import sort_pairs

    return sort_pairs(np.ascontiguousarray(pairs, dtype=np.int64), int(pairs.max()) + 1)


def on_segment(pos, x0, d, slack):
    """True if pos lies within ``slack`` (per node, Euclidean) of x0 + s d for one s in [0, 1]: a trial of the
    straight step x0 -> x0 + d, rounded (s fitted by least squares, then clamped)."""
    dx = pos - x0
    dd = float(np.vdot(d, d))
    s = min(max(float(np.vdot(dx, d)) / dd, 0.0), 1.0) if dd > 0.0 else 0.0
    dx -= s * d
    return bool(float(np.einsum("ij,ij->i", dx, dx).max()) <= slack * slack)


def positive_radius(value, name):
    value = validate.finite_number(value, name)
    if not value > 0:
        raise ValueError(f"{name} must be a positive finite length (the rod's radius); got {value!r}")
    return float(value)


def stiffness_bounds(system, dhat):
    """(kappa_min, kappa_max) of the adaptive barrier stiffness (docs/contact.md section 6): the barrier's
    curvature at gap dhat/2 equals the bending stiffness of one node, kappa_min b''(dhat/2) = A1 / h^3
    (energy / length^2, GAP mode), and kappa_max = KAPPA_RANGE kappa_min."""
    rod = system.rod
    h = float(np.mean(rod.l_bar))
    k_min = float(np.max(rod.A1)) / h ** 3 / _B2_HALF
    return k_min, KAPPA_RANGE * k_min


def curvature_radius_check(rod, state, radius, where, tight_bend="refuse"):
    """ValueError if the rod's natural curvature radius is not larger than ``radius`` (bad input: a rod cannot be
    made tighter than its own radius), and for the start ``state`` bent tighter than ``radius``: a ValueError
    ("refuse": a user's start) or a TightBendWarning ("warn": the start is the model's own equilibrium, as in a
    continuation's steps -- neighbours within an arc pi r + dhat are not contact partners, so the model allows
    such a bend; the warning says where)."""
    kb = np.linalg.norm(np.asarray(rod.kappa_bar, float).reshape(rod.n_vertices, -1), axis=1)
    if kb.size:
        k0 = float((kb / rod.voronoi).max())
        if k0 * radius >= 1.0:
            v = int(np.argmax(kb / rod.voronoi))
            raise ValueError(f"{where}: radius {radius:g} is not smaller than the rod's natural radius of curvature "
                             f"{1 / k0:.6g} (at vertex {v}); a rod cannot bend tighter than its own radius")
    if state is not None and rod.n_vertices:
        R, v = min_curvature_radius(rod, state)
        if R <= radius:
            msg = (f"{where}: the starting state bends to a radius of curvature {R:.6g} at vertex {v}, not larger "
                   f"than the radius {radius:g}")
            if tight_bend == "refuse":
                raise ValueError(msg)
            import warnings

            from ..solvers.options import TightBendWarning

            warnings.warn(msg + " (a continuation step from the model's own equilibrium: solved on; neighbours "
                          "within an arc pi r + dhat are not contact partners)", TightBendWarning, stacklevel=4)


def min_curvature_radius(rod, state):
    """(the smallest radius of curvature of ``state``, its vertex): 1 / max kappa_i (der.diagnostics.curvature;
    inf for a straight rod, vertex -1 for a rod without vertices)."""
    if not rod.n_vertices:
        return math.inf, -1
    from ..diagnostics import curvature

    k = curvature(rod, state)
    v = int(np.argmax(k))
    return (1.0 / float(k[v]) if k[v] > 0 else math.inf), v


@register
@dataclass(frozen=True)
class SelfContact:
    """Self-contact of the scene's rod; build it with ``der.self_contact``."""

    radius: float
    dhat: float | None = None
    kappa: float | None = None
    samples: int | None = None
    constructor = "self_contact(radius)"

    @property
    def explicit_ok(self):
        """The explicit solver handles the segment barrier (der/solvers/explicit_contact.py), not the sampled one."""
        return self.samples is None

    def check_scene(self, scene):
        curvature_radius_check(scene.rod, None, self.radius, "der.self_contact")
        h = float(scene.rod.l_bar.min())
        if scene.rod.closed and scene.rod.n_edges <= 2 * math.ceil((math.pi * self.radius + self.dhat_value) / h) + 1:
            raise ValueError(f"der.self_contact: the ring has {scene.rod.n_edges} edges, too few for its neighbour "
                             f"exclusion (an arc pi r + dhat = {math.pi * self.radius + self.dhat_value:.4g} on each "
                             f"side, edge length {h:.4g}); refine the ring or reduce the radius")

    @property
    def dhat_value(self):
        return DHAT_FRACTION * self.radius if self.dhat is None else self.dhat

    def bind(self, system):
        return BoundSelfContact(self, system)


def self_contact(radius, dhat=None, kappa=None, samples=None):
    """Self-contact of a rod of radius ``radius`` (length): non-neighbouring edges stay more than 2r apart
    (centreline distance) and never pass through each other, also within a solver step.

    Parameters
    ----------
    radius : float > 0
        The rod's (hard-core) radius r. It must be smaller than the rod's radius of curvature.
    dhat : float > 0, optional
        The range of the contact barrier (a gap, length; default 0.1 r): contact forces act on pairs whose
        surfaces are closer than dhat, and the equilibrium gap of a loaded contact lies in (0, dhat).
    kappa : float > 0, optional
        Barrier stiffness (energy / length^2). Default: adaptive (docs/contact.md section 6).

    samples : int >= 1, optional
        None (default): the barrier acts on the segment-segment distances of edge pairs (IPC). An integer m: on
        the distances between m points per edge (nodes included), offset so that the centrelines stay more than
        2r apart (der/contact/sampled.py). That distance is smooth, so Newton's method with the exact barrier
        Hessian converges quadratically on line contacts (plectonemes), where the segment distance's region
        switches make it linear (docs/contact.md section 9). Implicit solver only.

    Neighbours along the rod within an arc pi r + dhat are not contact partners (a rod bent to a radius of
    curvature near r would otherwise touch itself on the inside of the bend).

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.5)
    >>> scene = der.Scene(rod, constraints=[der.clamp("start")], contacts=[der.self_contact(0.01)])
    """
    radius = positive_radius(radius, "der.self_contact: radius")
    if dhat is not None:
        dhat = positive_radius(dhat, "der.self_contact: dhat")
    if kappa is not None:
        kappa = validate.finite_number(kappa, "der.self_contact: kappa")
        if not kappa > 0:
            raise ValueError(f"der.self_contact: kappa must be > 0 (or None: adaptive); got {kappa!r}")
    if samples is not None:
        if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or not 1 <= samples <= 64:
            raise ValueError(f"der.self_contact: samples must be None (segment distances) or an integer in [1, 64] "
                             f"(sample points per edge); got {samples!r}")
        samples = int(samples)
    return SelfContact(radius, dhat, kappa, samples)


class BoundBarrier:
    """What self-contact and obstacles share within one solve: the adaptive barrier stiffness."""

    couples_dofs = False

    def _init_stiffness(self, term_kappa, system):
        self.kappa_min, self.kappa_max = stiffness_bounds(system, self.dhat)
        self.adaptive = term_kappa is None
        self.kappa = self.kappa_min if term_kappa is None else float(term_kappa)
        self.prev_gap = np.inf
        self.min_gap = np.inf
        self.force_scale = 0.0
        self.n_active = 0
        self.kappa_updates = 0
        # PSD-project the pair Hessians (IPC); the implicit solver switches to the exact Hessian in Newton's end
        # game, where the projection would turn its quadratic convergence into a slow linear one
        self.project = True

    def positions(self, state):
        return np.ascontiguousarray(state.q.reshape(-1, 4)[:self.n_nodes, :3])

    def start_stiffness(self, state, system):
        """IPC's initial stiffness: the least-squares balance of the elastic residual and the barrier gradient,
        kappa = (R . g_B) / (g_B . g_B) over the free DOFs (g_B at kappa = 1), clamped to [kappa_min,
        kappa_max]; kappa_min if no pair is active."""
        if not self.adaptive:
            return
        from ..scene import evaluate

        n = system.n_dof
        R = np.zeros(n)
        # the elastic residual of each rod (one, or several side by side: der/solvers/multi.py)
        parts = system.parts if system.parts is not None else (system,)
        rod_states = state.rods if system.parts is not None else (state,)
        off = 0
        for p, s in zip(parts, rod_states):
            m = p.n_dof
            grad, fext = np.zeros(m), np.zeros(m)
            evaluate(p.plan, s.q, s.d1, s.reference_twist, s.lam, 1, grad, fext, p.ab, p.kl, p.ku, p.perm)
            R[off:off + m] = fext - grad
            off += m
        kappa, self.kappa = self.kappa, 1.0
        gB = np.zeros(n)
        self.evaluate(state, 1, gB, system.ab, [])
        self.kappa = kappa
        free = system.free
        gg = float(gB[free] @ gB[free])
        if gg > 0:
            # the barrier pushes along -g_B; it balances the elastic residual R when -kappa g_B ~ R
            self.kappa = min(max(-float(R[free] @ gB[free]) / gg, self.kappa_min), self.kappa_max)

    def after_step(self, state):
        """IPC's update: double kappa (up to kappa_max) while the smallest gap keeps falling below 1e-3 dhat.
        Needs ``min_gap`` from the last evaluate. Returns True if kappa changed."""
        changed = False
        if self.adaptive and self.min_gap < 1e-3 * self.dhat and self.min_gap < self.prev_gap \
                and self.kappa < self.kappa_max:
            self.kappa = min(2.0 * self.kappa, self.kappa_max)
            self.kappa_updates += 1
            changed = True
        self.prev_gap = self.min_gap
        return changed


class BoundSelfContact(BoundBarrier):
    couples_dofs = True
    _step = None              # (positions, reach per node, pairs) of the last step (step_candidates)
    _segment = None           # (positions, step, slack, pairs) of the last long step (step_candidates)
    samples = None            # sample points per edge (der/contact/sampled.py), None: segment distances
    pair_range_extra = 0.0    # the broad phase lists edge pairs within dhat + this

    def _init_samples(self, m, rods):
        """The sampled barrier's data (m points per edge): rest edge lengths, which edges carry their rod's end
        node, and the broad phase's extra range (the largest sample offset beyond r_a + r_b)."""
        self.samples = m
        if m is None:
            return
        from ..contact import sampled

        self.S = sampled
        self.edge_len = np.ascontiguousarray(np.concatenate([np.asarray(r.l_bar, float) for r in rods]))
        owns = []
        for r in rods:
            o = np.zeros(r.n_edges, dtype=np.int64)
            if not r.closed:
                o[-1] = 1
            owns.append(o)
        self.owns_end = np.concatenate(owns)
        self.pair_range_extra = float(sampled.max_offset_excess(self.topo.edge_radius, self.edge_len, m))
        self.exact_hessian_below = np.inf    # smooth: Newton with the exact Hessian, projected only as a fallback

    def __init__(self, term, system):
        from .. import contact as C
        from ..contact import assembly

        self.C, self.A = C, assembly
        rod = system.rod
        self.term = term
        self.rod = rod
        self.radius = term.radius
        self.dhat = term.dhat_value
        h_min = float(rod.l_bar.min())
        topo = C.topology([(rod.n_edges, rod.closed, self.radius, h_min)], self.dhat)
        # exclude an arc pi r + dhat (docs/contact.md section 4: a rod bent to radius ~r)
        k = C.exclusion_k(h_min, self.radius, self.dhat, arc=np.pi * self.radius + self.dhat)
        self.topo = topo._replace(rod_k=np.array([k], dtype=np.int64))
        self.n_nodes = rod.n_nodes
        self.n_dof = rod.n_dof
        self.node_dof = 4 * np.arange(rod.n_nodes, dtype=np.int64)
        self._init_stiffness(term.kappa, system)
        self.margin = VERLET_MARGIN * self.radius
        self._list = None            # (positions where built, pairs within dhat + margin)
        self.broad_phases = 0
        self._init_samples(term.samples, [rod])

    def candidates(self, pos, pos1=None):
        """Pairs that may be within dhat at pos (and, with pos1, anywhere on the straight step pos -> pos1): the
        list of the last step (``step_candidates``) while pos lies within its reach -- every line-search trial of
        that step and the state it accepts -- else the Verlet list below.

        A pair left out of a list built at x0 within dhat + margin had its boxes (inflated by r + (dhat +
        margin) / 2) apart, so a gap > dhat + margin at x0; while every node stays within margin / 2 of x0 each
        segment moves by at most margin / 2, the gap stays > dhat, and, the distance from x0 being convex along
        a straight step, that holds on the whole step if it holds at both of its ends. With ``ARC_STEP_LIST`` the
        step's list serves a straight step pos -> pos1 too when both ends lie within its reach: each node's reach
        is a ball about x0, so every point between them does (``cover_arc``: the arc's passage proof)."""
        if self._step is not None and (pos1 is None or ARC_STEP_LIST):
            x0, reach, pairs = self._step
            if self.C.within_reach(pos, x0, reach) and (pos1 is None or self.C.within_reach(pos1, x0, reach)):
                return pairs
        if pos1 is None and self._segment is not None and LONG_STEP_LIST:
            x0, d, slack, pairs = self._segment
            if on_segment(pos, x0, d, slack):
                return pairs
        if self._list is not None:
            x0, pairs = self._list
            move = float(np.abs(pos - x0).max())
            if pos1 is not None:
                move = max(move, float(np.abs(pos1 - x0).max()))
            if np.sqrt(3.0) * move <= 0.5 * self.margin:
                return pairs
        self.broad_phases += 1
        if pos1 is not None and np.sqrt(3.0) * float(np.abs(pos1 - pos).max()) > 0.5 * self.margin:
            # a long step: its swept boxes, not listed for reuse
            return sorted_pairs(self.C.candidate_pairs(pos, self.topo, self.dhat + self.pair_range_extra, pos1=pos1))
        pairs = sorted_pairs(self.C.candidate_pairs(pos, self.topo, self.dhat + self.pair_range_extra + self.margin))
        self._list = (pos.copy(), pairs)
        return pairs if pos1 is None else self.candidates(pos, pos1)

    def step_candidates(self, pos, dpos, ccd=True):
        """The pair list of one Newton step pos -> pos + dpos, built once and reused by all its line-search trials
        (``candidates``): every pair whose gap can come within range (dhat, plus the sampled barrier's extra) on
        any state whose node i stays within reach_i = |dpos_i| of pos -- so on every fraction of the step. Filtered
        from a list that holds all such pairs (the Verlet list while the whole reach stays inside its margin, else
        a broad phase with the boxes inflated by the reach) by the CCD's distance bound (der/contact/ccd.py
        ``reach_pairs``: gap >= gap(pos) - the two edges' largest reaches). A pair left out keeps its gap above
        the range on the whole step: no barrier, no contact, no CCD needed.

        Returns (pairs, listed). A step beyond the Verlet margin, with ``ccd``: the CCD's candidates from the boxes
        swept over it (tighter than the reach along a straight step) and listed False -- ``max_step`` then lists
        the step's CCD-safe part only (a Newton step far from equilibrium can be long and cut to a small fraction,
        and the trials never go beyond it)."""
        if not STEP_LIST:
            return self.candidates(pos, pos + dpos), False
        C = self.C
        rng = self.dhat + self.pair_range_extra
        reach = np.empty(pos.shape[0])
        C.step_reach(dpos, 1e-13 * (1.0 + float(np.abs(pos).max())), reach)
        wide = None
        if 2.0 * float(reach.max()) <= self.margin:
            # a short step: the Verlet list, or a new one at pos, holds it (and, likely, the next steps)
            wide = self._verlet_within(pos, reach)
        if wide is None:
            self.broad_phases += 1
            if ccd:
                if not LONG_STEP_LIST:
                    return sorted_pairs(C.candidate_pairs(pos, self.topo, rng, pos1=pos + dpos)), False
                # the boxes swept over the step, widened by the trials' rounding: a pair left out keeps its gap
                # above the range at every trial rounded onto the step (``candidates`` gives them this list)
                slack = 1e-13 * (1.0 + float(np.abs(pos).max()))
                pairs = sorted_pairs(C.candidate_pairs(pos, self.topo, rng + 2.0 * slack, pos1=pos + dpos))
                self._segment = (pos.copy(), dpos.copy(), slack, pairs)
                return pairs, False
            # a long step: boxes inflated by the reach (not kept)
            wide = sorted_pairs(C.candidate_pairs(pos, self.topo, rng, reach=reach))
        pairs = C.reach_pairs(pos, reach, self.topo.edges, wide, self.topo.edge_radius, rng)
        self._step = (pos.copy(), reach, pairs)
        return pairs, True

    def cover_arc(self, pos, dd, cc, a):
        """Widen the step's pair list (``step_candidates``, built at pos) to the arc trials q + a' delta + a'^2 c
        for every a' <= a, and to the chords their passage proof runs the CCD on: node i then moves by at most
        a |delta_i| + a^2 |c_i| (componentwise), so that reach (joined to the straight step's, or to a |delta_i|
        where this step has no list) bounds every such state. The list is filtered by ``reach_pairs`` from the
        Verlet list while the reach fits in its margin, else from one broad phase with the boxes inflated by the
        reach. Before (ARC_STEP_LIST = False) each arc trial, its passage proof and the next Newton step's first
        evaluation each took the Verlet list or a new broad phase. Returns True if the step's list covers the arc."""
        if not ARC_STEP_LIST:
            return False
        slack = 1e-13 * (1.0 + float(np.abs(pos).max()))
        arc_reach = np.empty(pos.shape[0])
        self.C.step_reach(np.ascontiguousarray(a * np.abs(dd) + (a * a) * np.abs(cc)), slack, arc_reach)
        if self._step is None or self._step[0].shape != pos.shape or not np.array_equal(self._step[0], pos):
            # no list for this step (a long step whose CCD-safe part exceeds the margin): one for the arc alone
            # (which bounds the straight trials at a' <= a as well)
            x0, wide_reach = pos.copy(), arc_reach
        else:
            x0, reach, _ = self._step
            if bool(np.all(arc_reach <= reach)):
                return True
            wide_reach = np.maximum(reach, arc_reach)
        if 2.0 * float(wide_reach.max()) <= self.margin:
            wide = self._verlet_within(pos, wide_reach)
        else:
            # beyond the margin: one broad phase with each box inflated by its nodes' reach, for this arc's trials
            self.broad_phases += 1
            wide = sorted_pairs(self.C.candidate_pairs(pos, self.topo, self.dhat + self.pair_range_extra,
                                                       reach=wide_reach))
        self._step = (x0, wide_reach, self.C.reach_pairs(pos, wide_reach, self.topo.edges, wide,
                                                          self.topo.edge_radius, self.dhat + self.pair_range_extra))
        return True

    def _verlet_within(self, pos, reach):
        """The Verlet list if it holds every pair that can come within range (dhat + extra) on states whose node
        i stays within reach[i] of pos, else a new Verlet list at pos (2 max reach <= margin required)."""
        if self._list is not None:
            x0, pairs = self._list
            room = 0.5 * self.margin - reach
            if float(room.min()) >= 0.0 and self.C.within_reach(pos, x0, room):
                return pairs
        self.broad_phases += 1
        wide = sorted_pairs(self.C.candidate_pairs(pos, self.topo, self.dhat + self.pair_range_extra + self.margin))
        self._list = (pos.copy(), wide)
        return wide

    def check_start(self, state, tight_bend="refuse"):
        curvature_radius_check(self.rod, state, self.radius, "der.self_contact", tight_bend)
        pos = self.positions(state)
        pairs = self.C.candidate_pairs(pos, self.topo, 0.0)
        if pairs.shape[0]:
            gap, force, pa, pb = self._pair_data(pos, pairs)
            p = int(np.argmin(gap))
            if gap[p] <= 0.0:
                ea, eb = (int(e) for e in pairs[p])
                raise ValueError(f"der.self_contact: the starting state violates the contact distance: edges {ea} and "
                                 f"{eb} are {gap[p] + 2 * self.radius:.6g} apart (centrelines), not more than 2r = "
                                 f"{2 * self.radius:.6g}")
        if self.samples is not None:
            near = self.C.candidate_pairs(pos, self.topo, self.pair_range_extra)
            tau, k = self.S.sampled_ccd(pos, np.zeros_like(pos), self.topo.edges, near, self.topo.edge_radius,
                                        self.edge_len, self.owns_end, self.samples, MIN_GAP_FRACTION)
            if tau == 0.0:
                ea, eb = (int(e) for e in near[k])
                raise ValueError(f"der.self_contact: the starting state is too close for samples={self.samples}: edges "
                                 f"{ea} and {eb} have sample points closer than their offset sqrt((2r)^2 + (l_a^2 + "
                                 "l_b^2) / 4) (l = edge length / samples); use more samples or start farther apart")

    def _pair_data(self, pos, pairs):
        m = pairs.shape[0]
        gap, force = np.empty(m), np.empty(m)
        pa, pb = np.empty((m, 3)), np.empty((m, 3))
        self.A.pair_forces(pos, self.topo.edges, pairs, self.topo.edge_radius, self.dhat, self.kappa, gap, force,
                           pa, pb)
        return gap, force, pa, pb

    def evaluate(self, state, order, grad, ab, coo):
        pos = self.positions(state)
        topo = self.topo
        pairs = self.candidates(pos)
        if self.samples is not None:
            return self._evaluate_sampled(pos, pairs, order, grad, coo)
        if order == 0:
            return float(self.A.pairs_energy(pos, topo.edges, pairs, topo.edge_radius, self.dhat, self.kappa))
        act = self.C.active_pairs(pos, topo.edges, pairs, topo.edge_radius, self.dhat)
        self.n_active = act.shape[0]
        if act.shape[0] == 0:
            self.force_scale, self.min_gap = 0.0, np.inf
            return 0.0
        g = np.zeros(self.n_dof)
        m = 144 * act.shape[0]
        rows, cols, vals = np.empty(m, dtype=np.int64), np.empty(m, dtype=np.int64), np.empty(m)
        energy, n_active, nt, min_gap = self.C.assemble_pairs(
            pos, topo.edges, act, topo.edge_radius, self.dhat, self.kappa, self.C.GAP, order >= 2 and self.project, self.node_dof,
            g, rows, cols, vals)
        self.min_gap = float(min_gap)
        if not np.isfinite(energy):
            return np.inf
        grad += g
        self.force_scale = float(np.linalg.norm(g.reshape(-1, 4)[:, :3], axis=1).max())
        if order >= 2:
            coo.append((rows[:nt], cols[:nt], vals[:nt]))
        return float(energy)

    def _evaluate_sampled(self, pos, pairs, order, grad, coo):
        topo, S = self.topo, self.S
        if order == 0:
            e, *_ = S.sampled_system(pos, topo.edges, pairs, topo.edge_radius, self.edge_len, self.owns_end,
                                     self.samples, self.dhat, self.kappa, 0, True, self.node_dof, np.empty(0),
                                     np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0))
            return float(e)
        act = S.sampled_active_pairs(pos, topo.edges, pairs, topo.edge_radius, self.edge_len, self.owns_end,
                                     self.samples, self.dhat)
        self.n_active = act.shape[0]
        if act.shape[0] == 0:
            self.force_scale, self.min_gap = 0.0, np.inf
            return 0.0
        g = np.zeros(self.n_dof)
        m = 144 * act.shape[0] if order >= 2 else 0
        rows, cols, vals = np.empty(m, dtype=np.int64), np.empty(m, dtype=np.int64), np.empty(m)
        energy, n_active, nt, min_gap, _ = S.sampled_system(
            pos, topo.edges, act, topo.edge_radius, self.edge_len, self.owns_end, self.samples, self.dhat,
            self.kappa, min(order, 2), self.project, self.node_dof, g, rows, cols, vals)
        self.min_gap = float(min_gap)
        if not np.isfinite(energy):
            return np.inf
        grad += g
        self.force_scale = float(np.linalg.norm(g.reshape(-1, 4)[:, :3], axis=1).max())
        if order >= 2 and nt:
            coo.append((rows[:nt], cols[:nt], vals[:nt]))
        return float(energy)

    def max_step(self, state, delta):
        pos = self.positions(state)
        dpos = np.ascontiguousarray(delta.reshape(-1, 4)[:self.n_nodes, :3])
        pairs, listed = self.step_candidates(pos, dpos)
        tau, worst, _ = self.C.pairs_ccd(pos, dpos, self.topo.edges, pairs, self.topo.edge_radius, MIN_GAP_FRACTION,
                                         1e-6, 10000)
        self.ccd_pair = (int(pairs[worst, 0]), int(pairs[worst, 1])) if tau < 1.0 and worst >= 0 else None
        if self.samples is not None and tau > 0.0:
            # the sampled barrier stays finite: every sample pair keeps 10 % of its gap as well
            tau_s, _ = self.S.sampled_ccd(pos, dpos, self.topo.edges, pairs, self.topo.edge_radius, self.edge_len,
                                          self.owns_end, self.samples, MIN_GAP_FRACTION)
            tau = min(tau, tau_s)
        if STEP_LIST and not listed and 0.0 < 2.0 * tau * float(np.sqrt((dpos * dpos).sum(axis=1)).max()) <= self.margin:
            # a long step cut short by the CCD: the trials' list for its CCD-safe part [0, tau] (the line search
            # starts at most there), if that fits in the Verlet margin; else the trials use the Verlet list, as
            # before (measured: a list for the reach of a long step holds many more pairs than one at the trial)
            self.step_candidates(pos, tau * dpos, ccd=False)
        return float(tau)

    @property
    def arc_ok(self):
        """``arc_step_safe`` proves no passage along a curved step (the segment barrier; the sampled one's own
        sample CCD has no such bound here)."""
        return self.samples is None

    def arc_step_safe(self, state, delta, arc, a):
        """True if no strand passes through another anywhere on the curved path q + t a delta + t^2 a^2 arc, t in
        [0, 1] (the second-order-corrected line search of der/solvers/implicit.py). The path leaves its chord
        q -> q + a delta + a^2 arc by at most dev = a^2 max_i |arc_i| / 4 at any node (the parabola's deviation
        t (1 - t) a^2 arc_i), so every point of an edge by at most dev and every edge-edge distance by at most
        2 dev: the CCD on the chord with each radius widened by dev (offset 2r + 2 dev) keeps the path's gaps
        above its own 10 % of the widened gap, hence > 0 (no passage, finite barrier). Pairs are those the chord
        can bring within dhat; dev is held below dhat / 4, so a pair left out keeps a gap > dhat / 2 on the
        path. False if any of that fails (the caller then searches along the straight step)."""
        if not self.arc_ok:
            return False
        pos = self.positions(state)
        dd = delta.reshape(-1, 4)[:self.n_nodes, :3]
        cc = arc.reshape(-1, 4)[:self.n_nodes, :3]
        chord = np.ascontiguousarray(a * dd + (a * a) * cc)
        dev = 0.25 * a * a * float(np.sqrt((cc * cc).sum(axis=1)).max()) * (1.0 + 1e-9) \
            + 1e-13 * (1.0 + float(np.abs(pos).max()))
        if not (np.isfinite(dev) and np.isfinite(chord).all()) or dev > 0.25 * self.dhat:
            return False
        self.cover_arc(pos, dd, cc, a)
        pairs = self.candidates(pos, pos + chord)
        tau, _, _ = self.C.pairs_ccd(pos, chord, self.topo.edges, pairs, self.topo.edge_radius + dev, MIN_GAP_FRACTION,
                                     1e-6, 10000)
        return tau >= 1.0

    def _min_curvature_radius(self, state):
        """The tightest bend over the rods this term sees (one rod, or those of der.rod_contact)."""
        rods = getattr(self, "rods", None)
        if rods is None:
            return min_curvature_radius(self.rod, state)[0]
        return min(min_curvature_radius(r, s)[0] for r, s in zip(rods, getattr(state, "rods", [state])))

    def diagnostics(self, state):
        """Pairs in contact (gap < dhat), their gaps, forces (-kappa b'(gap), force units), forces per length
        (over the pair's mean rest edge length), contact points, and the smallest centreline distance over all
        non-neighbour pairs (over the pairs a broad phase finds within 4r; if none is that close, brute force up to
        4000 edges)."""
        pos = self.positions(state)
        topo = self.topo
        pairs = self.C.candidate_pairs(pos, topo, self.dhat + self.pair_range_extra)
        gap, force, pa, pb = self._pair_data(pos, pairs)
        if self.samples is not None:
            # the sampled barrier: a pair is in contact when one of its sample pairs is within dhat of its offset,
            # and its force is the sum of theirs
            self.S.sampled_pair_forces(pos, topo.edges, pairs, topo.edge_radius, self.edge_len, self.owns_end,
                                       self.samples, self.dhat, self.kappa, force)
            keep = force > 0.0
        else:
            keep = gap < self.dhat
        pairs, gap, force, pa, pb = pairs[keep], gap[keep], force[keep], pa[keep], pb[keep]
        l_bar = self.rod.l_bar
        per_length = force / (0.5 * (l_bar[pairs[:, 0]] + l_bar[pairs[:, 1]])) if pairs.size else force
        # the pairs within 4r by the broad phase (a superset of those with gap < 4r, in the brute force's order):
        # if one is, the smallest gap is among them; else brute force up to 4000 edges (O(n^2))
        near = self.C.candidate_pairs(pos, topo, 4.0 * self.radius)
        near = near[np.lexsort((near[:, 1], near[:, 0]))]
        g = self._pair_data(pos, near)[0] if near.size else np.array([np.inf])
        p = int(np.argmin(g))
        g_min, ea, eb = (float(g[p]), *near[p]) if near.size else (np.inf, -1, -1)
        if not g_min < 4.0 * self.radius and topo.edges.shape[0] <= 4000:
            g_min, ea, eb = self.A.min_pair_gap(pos, topo.edges, topo.rod_of_edge, topo.local_edge, topo.rod_n_edges,
                                                topo.rod_closed, topo.rod_k, topo.edge_radius)
        return {
            "kind": "self_contact", "radius": self.radius, "dhat": self.dhat, "kappa": self.kappa,
            "n_contacts": int(pairs.shape[0]), "pairs": pairs.tolist(), "gap": gap.tolist(), "force": force.tolist(),
            "force_per_length": per_length.tolist(), "total_force": float(force.sum()),
            "points": (0.5 * (pa + pb)).tolist(), "normals": _unit(pa - pb).tolist(),
            "min_distance": float(g_min + 2 * self.radius), "min_distance_edges": [int(ea), int(eb)],
            "min_curvature_radius": self._min_curvature_radius(state),
        }


def _unit(v):
    n = np.linalg.norm(v, axis=1, keepdims=True) if v.size else np.ones((0, 1))
    return v / np.where(n > 0, n, 1.0)


@register
@dataclass(frozen=True)
class RodContact:
    """Contact between the rods of a scene (and within each); build it with ``der.rod_contact``."""

    radius: float | tuple
    dhat: float | None = None
    kappa: float | None = None
    within: bool = True
    constructor = "rod_contact(radius)"
    explicit_ok = True          # on one rod (a scene of several rods needs the implicit solver)

    def radii(self, n_rods):
        """One radius per rod."""
        if isinstance(self.radius, tuple):
            if len(self.radius) != n_rods:
                raise ValueError(f"der.rod_contact: radius gives {len(self.radius)} radii for a scene of {n_rods} "
                                 "rods; give one radius, or one per rod")
            return self.radius
        return (self.radius,) * n_rods

    @property
    def dhat_value(self):
        r = min(self.radius) if isinstance(self.radius, tuple) else self.radius
        return DHAT_FRACTION * r if self.dhat is None else self.dhat

    def check_scene(self, scene):
        for i, (rod, r) in enumerate(zip(scene.rods, self.radii(len(scene.rods)))):
            where = f"der.rod_contact (rod {i})"
            curvature_radius_check(rod, None, r, where)
            h = float(rod.l_bar.min())
            if self.within and rod.closed and rod.n_edges <= 2 * math.ceil((math.pi * r + self.dhat_value) / h) + 1:
                raise ValueError(f"{where}: the ring has {rod.n_edges} edges, too few for its neighbour exclusion "
                                 f"(an arc pi r + dhat = {math.pi * r + self.dhat_value:.4g} on each side, edge "
                                 f"length {h:.4g}); refine the ring or reduce the radius")

    def bind(self, system):
        return BoundRodContact(self, system)


def rod_contact(radius, dhat=None, kappa=None, within=True):
    """Contact between the rods of a scene of several rods -- and, with ``within`` (the default), of each rod
    with itself: no two non-neighbouring edges of the scene come closer than r_a + r_b (centreline distance) and
    none passes through another, also within a solver step (IPC barrier with a CCD-limited step, as
    ``der.self_contact``). Pairs of edges of two rods couple their DOFs like self-contact pairs: the implicit
    solver factorises a sparse matrix while a pair is active, the banded one otherwise.

    Parameters
    ----------
    radius : float > 0, or a sequence of them (one per rod)
        The rods' (hard-core) radius r (length): two rods touch at centreline distance r_a + r_b.
    dhat : float > 0, optional
        The range of the barrier (a gap, length; default 0.1 times the smallest radius).
    kappa : float > 0, optional
        Barrier stiffness (energy / length^2). Default: adaptive (docs/contact.md section 6).
    within : bool
        Also each rod with itself (neighbours along a rod within an arc pi r + dhat excluded, as
        ``der.self_contact``); False for contact between different rods only.

    In a one-rod scene it is that rod's self-contact. Obstacles (``der.plane``, ...) in the same scene take its
    radius unless given their own.

    Example
    -------
    Two crossed rods (A along x, clamped at both ends; B along y above it, in sleeves along z, pushed down):

    >>> import der
    >>> a = der.rod_from_shape(der.shapes.straight(1.0, 20, axis=[1, 0, 0], director=[0, 0, 1]), A1=1.0, A2=1.5,
    ...                        EA=1e3)
    >>> x_b = der.shapes.straight(1.0, 21, axis=[0, 1, 0], director=[0, 0, 1]).positions + [0.5, -0.5, 0.1]
    >>> b = der.rod_from_shape(der.shapes.Shape(x_b, director=[0, 0, 1]), A1=1.0, A2=1.5, EA=1e3)
    >>> scene = der.Scene([der.Scene(a, constraints=[der.clamp("start"), der.clamp("end")]),
    ...                    der.Scene(b, loads=[der.distributed_force([0, 0, -0.5])],
    ...                              constraints=[der.clamp("start", slide=2), der.clamp("end", slide=2)])],
    ...                   contacts=[der.rod_contact(0.02)])
    >>> result = der.solve(scene)
    >>> round(float(sum(r["force"][2] for r in result.rods[0]["reactions"])), 6)   # A's clamps carry the push
    0.5
    """
    if isinstance(radius, (list, tuple, np.ndarray)):
        radius = tuple(positive_radius(r, f"der.rod_contact: radius[{i}]") for i, r in enumerate(radius))
        if not radius:
            raise ValueError("der.rod_contact: radius is an empty sequence; give one radius, or one per rod")
    else:
        radius = positive_radius(radius, "der.rod_contact: radius")
    if dhat is not None:
        dhat = positive_radius(dhat, "der.rod_contact: dhat")
    if kappa is not None:
        kappa = validate.finite_number(kappa, "der.rod_contact: kappa")
        if not kappa > 0:
            raise ValueError(f"der.rod_contact: kappa must be > 0 (or None: adaptive); got {kappa!r}")
    if not isinstance(within, (bool, np.bool_)):
        raise ValueError(f"der.rod_contact: within must be True or False; got {within!r}")
    return RodContact(radius, dhat, kappa, bool(within))


class BoundRodContact(BoundSelfContact):
    """``der.rod_contact`` within one solve: the self-contact machinery over all the scene's edges, numbered rod
    after rod (der/solvers/multi.py RodGroup), with a neighbour exclusion per rod (all of a rod's own pairs
    without ``within``)."""

    def __init__(self, term, system):
        from .. import contact as C
        from ..contact import assembly

        self.C, self.A = C, assembly
        self.term = term
        scene = system.scene
        self.rods = scene.rods
        self.radii = term.radii(len(self.rods))
        self.radius = float(max(self.radii))
        self.dhat = term.dhat_value
        spec = [(r.n_edges, r.closed, rad, float(r.l_bar.min())) for r, rad in zip(self.rods, self.radii)]
        topo = C.topology(spec, self.dhat)
        ks = [C.exclusion_k(h, rad, self.dhat, arc=np.pi * rad + self.dhat) if term.within else n
              for (n, _, rad, h) in spec]
        self.topo = topo._replace(rod_k=np.array(ks, dtype=np.int64))
        self.rod = system.rod                   # a Rod, or the RodGroup of several
        self.edge_offsets = np.concatenate([[0], np.cumsum([r.n_edges for r in self.rods])]).astype(np.int64)
        self.n_nodes = sum(r.n_nodes for r in self.rods)
        self.n_dof = 4 * self.n_nodes
        self.node_dof = 4 * np.arange(self.n_nodes, dtype=np.int64)
        self._init_stiffness(term.kappa, system)
        self.margin = VERLET_MARGIN * self.radius     # the Verlet list of BoundSelfContact.candidates
        self._list = None
        self.broad_phases = 0

    def rod_edge(self, e):
        """(rod, local edge) of the global edge e."""
        i = int(np.searchsorted(self.edge_offsets, e, side="right") - 1)
        return i, int(e - self.edge_offsets[i])

    def check_start(self, state, tight_bend="refuse"):
        rod_states = getattr(state, "rods", [state])
        for i, (rod, s, r) in enumerate(zip(self.rods, rod_states, self.radii)):
            curvature_radius_check(rod, s, r, f"der.rod_contact (rod {i})", tight_bend)
        pos = self.positions(state)
        pairs = self.C.candidate_pairs(pos, self.topo, 0.0)
        if pairs.shape[0]:
            gap, *_ = self._pair_data(pos, pairs)
            p = int(np.argmin(gap))
            if gap[p] <= 0.0:
                (ra, ea), (rb, eb) = self.rod_edge(pairs[p, 0]), self.rod_edge(pairs[p, 1])
                off = self.topo.edge_radius[pairs[p, 0]] + self.topo.edge_radius[pairs[p, 1]]
                raise ValueError(f"der.rod_contact: the starting state violates the contact distance: edge {ea} of rod "
                                 f"{ra} and edge {eb} of rod {rb} are {gap[p] + off:.6g} apart (centrelines), not "
                                 f"more than r_a + r_b = {off:.6g}")

    def diagnostics(self, state):
        """As ``der.self_contact``'s, with the pairs' edges numbered rod after rod, ``pair_rods`` (the two rods
        of each pair) and ``local_pairs`` (each edge's index along its rod)."""
        out = super().diagnostics(state)
        pairs = np.asarray(out["pairs"], dtype=np.int64).reshape(-1, 2)
        loc = [[self.rod_edge(a), self.rod_edge(b)] for a, b in pairs]
        out.update(kind="rod_contact", radii=list(self.radii), pair_rods=[[a[0], b[0]] for a, b in loc],
                   local_pairs=[[a[1], b[1]] for a, b in loc])
        ea, eb = out["min_distance_edges"]
        if ea >= 0:
            off = self.topo.edge_radius[ea] + self.topo.edge_radius[eb]
            out["min_distance"] = float(out["min_distance"] - 2 * self.radius + off)
            out["min_distance_rods"] = [self.rod_edge(ea)[0], self.rod_edge(eb)[0]]
        return out
