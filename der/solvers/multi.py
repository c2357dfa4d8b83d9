"""Several rods in one scene (issue 14): the rods' systems side by side in one set of work arrays.

The DOFs of the rods are concatenated, rod after rod (``offsets``). Each rod keeps its own ``System`` (its
plan, supports, load scales), whose gradient, external force and band are *views* into the scene's arrays:
the band of rod i is the columns ``offsets[i]:offsets[i + 1]`` of one band matrix (Fortran order, so a
column slice is contiguous and the kernels compile once), with the band-position permutation shifted by the
offset. The concatenation of banded chains is banded with the same half-bandwidths, so a scene of several
rods without a coupling term is solved on the banded path like one rod; a contact term that couples two rods
adds off-band COO triplets, like self-contact, and the implicit solver then factorises a sparse matrix.

``MultiSystem`` offers the attributes of a ``System`` that the solvers and the terms read (``fixed``,
``links``, ``kl``/``ku``/``perm``, ``grad``/``fext``/``ab``, ``terms``, ``rod`` -- a ``RodGroup``, the rods'
edges in one numbering); the functions of ``system.py`` that need a rod's data delegate here (``parts`` is not
None). ``MultiState`` is the state: one ``RodState`` per rod whose ``q`` are views into one vector ``q``.
"""
import numpy as np

from ..constraints import Links
from ..linalg import new_band


class RodGroup:
    """The rods of a scene seen as one set of nodes and edges (for the contact terms): node k of rod i is node
    ``node_offsets[i] + k``, edge j of rod i is edge ``edge_offsets[i] + j``; its DOFs are at 4 (global node)."""

    def __init__(self, rods):
        self.rods = tuple(rods)
        n_nodes = [r.n_nodes for r in rods]
        n_edges = [r.n_edges for r in rods]
        self.node_offsets = np.concatenate([[0], np.cumsum(n_nodes)]).astype(np.int64)
        self.edge_offsets = np.concatenate([[0], np.cumsum(n_edges)]).astype(np.int64)
        self.n_nodes = int(self.node_offsets[-1])
        self.n_edges = int(self.edge_offsets[-1])
        self.n_dof = 4 * self.n_nodes
        self.edge_nodes = np.ascontiguousarray(np.concatenate(
            [r.edge_nodes + self.node_offsets[i] for i, r in enumerate(rods)]), dtype=np.int64)
        self.l_bar = np.concatenate([r.l_bar for r in rods])
        self.rest_q = np.concatenate([r.rest_q for r in rods])
        self.A1 = float(max(np.max(r.A1) for r in rods))
        self.closed = False
        self.inextensible = any(r.inextensible for r in rods)
        self.length = float(max(r.length for r in rods))

    def rod_edge(self, e):
        """(rod index, local edge index) of global edge ``e``."""
        i = int(np.searchsorted(self.edge_offsets, e, side="right") - 1)
        return i, int(e - self.edge_offsets[i])


class MultiState:
    """The state of a scene of several rods: ``rods[i]`` is rod i's ``der.RodState``; its ``q`` is a view into
    the scene's ``q`` (rod after rod), so that a solver can work on ``q`` as one vector.

    Example
    -------
    >>> result = der.solve(der.Scene([scene_a, scene_b]))     # doctest: +SKIP
    >>> result.state.rods[1].positions                        # doctest: +SKIP
    """

    # plain coordinates: the scene's q has no low parts (each rod's view keeps zero ones), so the solvers' floor
    # bound sees the rounding of absolute coordinates (system.rounding_scale)
    q_lo = None

    def __init__(self, rods):
        self.q = np.concatenate([r.q for r in rods])
        self.rods = []
        off = 0
        for r in rods:
            n = r.q.size
            view = r.copy()
            view.q = self.q[off:off + n]
            self.rods.append(view)
            off += n

    def copy(self):
        """An independent copy (all arrays copied)."""
        return MultiState([r.copy() for r in self.rods])

    def copy_from(self, other):
        """Overwrite this state's arrays in place with ``other``'s (same rods)."""
        self.q[:] = other.q
        for a, b in zip(self.rods, other.rods):
            a.copy_from(b)

    @property
    def positions(self):
        """All node positions, rod after rod, shape (n_nodes, 3) (a view into q)."""
        return self.q.reshape(-1, 4)[:, :3]

    def __repr__(self):
        return f"MultiState({len(self.rods)} rods: " + ", ".join(repr(r) for r in self.rods) + ")"


class MultiSystem:
    """The work arrays of a scene of several rods (see the module docstring)."""

    def __init__(self, scene, parts):
        self.scene = scene
        self.parts = tuple(parts)
        self.rod = RodGroup([p.rod for p in parts])
        n = [p.n_dof for p in parts]
        self.offsets = np.concatenate([[0], np.cumsum(n)]).astype(np.int64)
        total = int(self.offsets[-1])
        self.kl = max(p.kl for p in parts)
        self.ku = max(p.ku for p in parts)
        self.ab = new_band(total, self.kl, self.ku)
        self.grad = np.zeros(total)
        self.fext = np.zeros(total)
        for p, off, m in zip(parts, self.offsets, n):
            # each rod's kernels write into its columns of the one band, with the common half-bandwidths
            p.kl, p.ku = self.kl, self.ku
            p.ab = self.ab[:, off:off + m]
            p.grad = self.grad[off:off + m]
            p.fext = self.fext[off:off + m]
        self.perm = np.concatenate([p.perm + off for p, off in zip(parts, self.offsets)]).astype(np.int64)
        self.is_theta = np.concatenate([p.is_theta for p in parts])
        self.weights = np.concatenate([p.weights for p in parts])
        self.applied_force = max(p.applied_force for p in parts)
        self.applied_moment = max(p.applied_moment for p in parts)
        self.gather()
        self.terms = ()
        self.contact_coo = []
        self.linear_solves = {"band": 0, "sparse": 0}

    @property
    def n_dof(self):
        return int(self.offsets[-1])

    @property
    def counters(self):
        out = {}
        for p in self.parts:
            for k, v in p.counters.items():
                out[k] = out.get(k, 0) + v
        return out

    def gather(self):
        """The held mask, the end supports' links and the condensed mass of the scene from its rods' (after
        ``update_links`` of a rod)."""
        parts, offs = self.parts, self.offsets
        self.fixed = np.concatenate([p.fixed for p in parts])
        self.free = ~self.fixed
        self.mass = np.concatenate([p.mass for p in parts])
        self.mass_full = np.concatenate([p.mass_full for p in parts])
        cat = lambda name, shift, dtype: np.concatenate(  # noqa: E731
            [getattr(p.links, name) + (o if shift else 0) for p, o in zip(parts, offs)]).astype(dtype)
        self.links = Links(cat("dep", True, np.int64), cat("const", False, float), cat("tri_dep", True, np.int64),
                           cat("tri_master", True, np.int64), cat("tri_coef", False, float))

    def views(self, state):
        """(rod system, rod state) pairs."""
        return zip(self.parts, state.rods)


def build_multi_system(scene, options):
    from .system import build_system

    system = MultiSystem(scene, [build_system(s, options) for s in scene.scenes])
    system.terms = tuple(term.bind(system) for term in scene.contacts)
    return system


def prepare_multi_state(system, state):
    from .system import prepare_state

    rods = [prepare_state(p, s) for p, s in zip(system.parts, state.rods)]
    system.gather()
    return MultiState(rods)


# ---- the rod-dependent functions of system.py, for a MultiSystem ----

def evaluate_system(system, state, order):
    from .system import add_terms, evaluate_system as one

    energy = 0.0
    for p, s in system.views(state):
        energy += one(p, s, order)
    return energy + add_terms(system, state, order)


def rod_scales(system, state):
    """(F_s, M_s) of each rod (lists): its own load scale, raised by the contact forces of the scene."""
    from .system import contact_force_scale, load_scales

    fc = contact_force_scale(system)
    F, M = [], []
    for p, s in system.views(state):
        f, m = load_scales(p, s)
        if fc > f:
            f, m = fc, max(m, fc * p.rod.length)
        F.append(f)
        M.append(m)
    return F, M


def load_scales(system, state):
    """Per-DOF force and moment scales (arrays): each rod's residual is judged against its own loads."""
    F, M = rod_scales(system, state)
    n = np.diff(system.offsets)
    return np.repeat(F, n), np.repeat(M, n)


def max_strain(system, state):
    from .system import max_strain as one

    return max([one(p, s) for p, s in system.views(state) if p.rod.inextensible], default=0.0)


def constraint_residual(system, state, scales):
    from .system import constraint_residual as one

    out = 0.0
    for p, s, off in zip(system.parts, state.rods, system.offsets):
        if p.rod.inextensible:
            out = max(out, one(p, s, (scales[0][off], scales[1][off])))
    return out


def multiplier_update(system, state, previous=None):
    from .system import multiplier_update as one

    previous = previous if previous is not None else [None] * len(system.parts)
    return [one(p, s, g) if p.rod.inextensible else None for p, s, g in zip(system.parts, state.rods, previous)]


def transport(system, base, q_new, out):
    from .system import transport as one

    ok = True
    for p, b, o, off in zip(system.parts, base.rods, out.rods, system.offsets):
        ok = one(p, b, q_new[off:off + p.n_dof], o) and ok
    return ok


def energy_terms(system, state):
    from .system import energy_terms as one

    out = {}
    for p, s in system.views(state):
        for k, v in one(p, s).items():
            out[k] = out.get(k, 0.0) + v
    if system.terms:
        out["contact"] = float(sum(t.evaluate(state, 0, None, None, None) for t in system.terms))
    return out


def final_result(system, state, status, **fields):
    """A SolveResult for the scene (``state`` a MultiState), with ``states`` (one RodState per rod) and ``rods``
    (per rod: ``energy`` by term, ``reactions``, ``load_scale``)."""
    from .options import CONVERGED_STATUSES, SolveResult
    from .system import energy_terms as rod_energy
    from .system import residual_norm, residual_vector, support_reactions

    evaluate_system(system, state, 1)
    scales = load_scales(system, state)
    if status in CONVERGED_STATUSES and not (np.isfinite(scales[0]).all() and np.isfinite(scales[1]).all()):
        status = "nonfinite"
        fields["message"] = "a rod's force scale became non-finite; no verdict"
    per_length = residual_norm(system, residual_vector(system), scales, per_length=True)
    F, _ = rod_scales(system, state)
    rods, reactions = [], []
    for i, (p, s) in enumerate(system.views(state)):
        r = support_reactions(p, s)
        reactions += [dict(entry, rod=i) for entry in r]
        rods.append({"energy": rod_energy(p, s), "reactions": r, "load_scale": float(F[i])})
    fields.setdefault("reactions", reactions)
    return SolveResult(state=state, converged=status in CONVERGED_STATUSES, status=status,
                       load_scale=float(max(F)), energy=energy_terms(system, state), residual_per_length=per_length,
                       states=list(state.rods), rods=rods, **fields)
