"""cosseratbench adapter (issue 15): ``cosseratbench run EXPERIMENT --solver der``.

Registered as the ``der`` entry of the ``cosseratbench.solvers`` entry-point group (``pip install -e '.[bench]'``);
imported only by cosseratbench, never by ``import der``.

How a cosseratbench rod becomes a der rod: a rod of n_elements elements has n_elements + 1 material points at
s_k = k L / n_elements. der puts its end cross-sections at the midpoints of its end edges (its outer nodes lie
half an edge outside [0, L]), so a der rod of n = n_elements + 1 edges of rest length h = L / n_elements has its
edge midpoints exactly at the s_k: the suite's nodes are der's edge midpoints, its elements der's interior
nodes (a vertex each). The rest shape is straight (the suite's rods are), along the chord, with its material
director m1 along the rod's ``normal``; the start state is the suite's centreline (interpolated in unstretched
arc length, linearly extrapolated for the two outer nodes), reached by transporting the frames along the way,
so a planar start keeps m1 = normal. Stiffnesses: A1 = E I, A2 = G J (J = 2 I), EA = E A; masses rho_A = rho A,
rho_J = rho J. Clamped ends are ``der.clamp`` (driven: its rotation and position as functions of time; sliding
along ``slides_along``), pinned ends ``der.hinge``, end loads ``der.end_force``, gravity a body force.

Numerics: quasi-static experiments without driven ends go to ``der.solve`` (the final state is the equilibrium:
every frame after t = 0 is it); the others run ``der.simulate`` (Newmark average acceleration, no numerical
dissipation) with, for quasi-static ones, mass-proportional damping at twice the scenario's slowest frequency
(the rule of the suite's other adapters).

Contact (docs/dynamics.md): several rods (crossing: quasi-static, no driven ends) are solved together by
``der.solve`` on one ``der.Scene`` of the rods with ``der.rod_contact``; obstacles (capstan's cylinder, pile's floor)
are ``der.cylinder`` / ``der.plane`` offset by the rod's radius, with lagged smoothed Coulomb friction (the larger of
the obstacle's and the rod's coefficient, slip velocity 1e-4 rod lengths per second) in ``der.simulate``, and
self-contact (``der.self_contact``) where the scenario says the rod can reach itself (pile); der's self-contact is
frictionless (no ROD_FRICTION). Contact runs use the generalized-alpha step with rho_inf = 0 (the suite lets
quasi-static runs dissipate; the trapezoidal rule gains energy at stiff impacts and lets the rope ring on the
barrier). A rope lying on a cylinder (capstan) starts from its frictionless contact equilibrium with the middle of
the wrap pinned (``der.solve``), which gives the contact forces and the barrier's stiffness their right values;
friction takes over the pin's load in the first steps.
"""
import math

import numpy as np

import der
from cosseratbench.scenario import End, EndCondition
from cosseratbench.solver import Capability, Diverged
from cosseratbench.trajectory import Trajectory

STEP = 1e-2          # s: the implicit step at time_step_scale 1 (accuracy, not stability)


def _version():
    try:
        from importlib.metadata import version

        return version("der")
    except Exception:           # not installed as a distribution (PYTHONPATH)
        return "unknown"


class DerSolver:
    """The der adapter: discrete elastic rods, static ``der.solve`` or dynamic ``der.simulate``.

    Parameters
    ----------
    time_step_scale : float > 0
        Multiplies the time step (``STEP`` = 0.01 s, shortened to fit the frame interval).

    Example
    -------
    ``cosseratbench run pendulum --solver der`` (with ``pip install -e '.[bench]'``).
    """

    name = "der"
    backend_version = _version()
    capabilities = frozenset({Capability.STRETCH, Capability.ROD_CONTACT, Capability.CYLINDER_CONTACT,
                              Capability.PLANE_CONTACT})

    def __init__(self, time_step_scale: float = 1.0) -> None:
        if not (isinstance(time_step_scale, (int, float)) and math.isfinite(time_step_scale)
                and time_step_scale > 0):
            raise ValueError(f"time_step_scale must be a finite number > 0; got {time_step_scale!r}")
        self.time_step = STEP * time_step_scale

    def _numerics(self, scenario, n_frames):
        interval = scenario.duration / max(n_frames - 1, 1)
        steps = max(1, math.ceil(interval / self.time_step - 1e-9))
        driven = any(r.start_motion is not None or r.end_motion is not None for r in scenario.rods)
        # obstacles need the dynamics: friction (capstan) or a driven rope (pile)
        static = scenario.quasi_static and not driven and not scenario.obstacles
        contact = bool(scenario.obstacles)
        return {
            "method": "der.solve (static equilibrium)" if static else (
                "der.simulate (generalized-alpha, rho_inf 0, contact)" if contact
                else "der.simulate (Newmark average acceleration)"),
            "dt": interval / steps, "steps_per_frame": steps,
            "damping_rate": 2.0 * scenario.slowest_frequency() if scenario.quasi_static and not static else 0.0,
            "static": static,
            # contact runs: numerical dissipation of the unresolved modes (the rope ringing on the stiff barrier
            # makes the lagged normal force flicker; docs/dynamics.md, capstan), none otherwise
            "rho_inf": 0.0 if contact else 1.0,
        }

    def settings(self, scenario, *, n_elements, n_frames):
        """The numerical choices for a run (JSON values)."""
        out = dict(self._numerics(scenario, n_frames))
        out.pop("static")
        if scenario.obstacles:
            out["friction_slip_velocity"] = 1e-4 * scenario.rods[0].length
        return out

    def run(self, scenario, *, n_elements, n_frames):
        """Simulate ``scenario`` with ``n_elements`` elements per rod; ``n_frames`` evenly spaced frames."""
        numerics = self._numerics(scenario, n_frames)
        times = np.linspace(0.0, scenario.duration, n_frames)
        if len(scenario.rods) > 1 and numerics["static"]:
            # rods at rest together (crossing): one scene with contact between them. Driven rods side by side
            # (twist) run one by one, as before: der.simulate has one rod per scene (they do not touch there)
            return Trajectory(times, *self._run_rods(scenario, n_elements, n_frames, numerics))
        positions, directors = [], []
        for rod in scenario.rods:
            x, d = self._run_rod(scenario, rod, n_elements, n_frames, numerics)
            positions.append(x)
            directors.append(d)
        return Trajectory(times, tuple(positions), tuple(directors))

    # -- several rods in contact (crossing) ------------------------------------------------------

    def _run_rods(self, scenario, n_elements, n_frames, numerics):
        """Several rods touching each other: their equilibrium by ``der.solve`` on one scene with
        ``der.rod_contact`` (quasi-static, no driven ends, no obstacles)."""
        parts, rods, starts = [], [], []
        for rod in scenario.rods:
            drod, start, constraints, driven, loads = self._setup(scenario, rod, n_elements)
            g = np.asarray(scenario.gravity, float)
            if np.any(g):
                loads.append(der.distributed_force(drod.rho_A * g))
            parts.append(der.Scene(drod, loads=loads, constraints=[c for c in constraints if c is not None]))
            rods.append(drod)
            starts.append(start)
        radii = tuple(float(r.radius) for r in scenario.rods)
        scene = der.Scene(parts, contacts=[der.rod_contact(radii, within=bool(scenario.self_contact))])
        from der.solvers.multi import MultiState

        result = der.solve(scene, state=MultiState(starts), tol=1e-10, raise_on_failure=False)
        if not result.converged:
            raise Diverged(f"der.solve: {result.status}: {result.message}")
        positions, directors = [], []
        for drod, start, final in zip(rods, starts, result.state.rods):
            x, d = self._output(drod, [start] + [final] * (n_frames - 1))
            positions.append(x)
            directors.append(d)
        return tuple(positions), tuple(directors)

    # -- one rod ---------------------------------------------------------------------------------

    def _setup(self, scenario, rod, n_elements):
        """(der rod, start state, constraints (None for a driven clamp), driven ends, loads) of one rod."""
        m = rod.material
        area = math.pi * rod.radius ** 2
        inertia = math.pi * rod.radius ** 4 / 4.0
        L = rod.length
        n = n_elements + 1
        points = np.asarray(rod.centerline, float)
        chord = points[-1] - points[0]
        if np.linalg.norm(chord) < 1e-9 * L:
            raise NotImplementedError("a rod whose ends start at the same point (no chord for the rest axis)")
        axis = chord / np.linalg.norm(chord)
        drivens = [end for end in End if rod.condition(end) is EndCondition.CLAMPED and rod.motion(end) is not None]
        if len(drivens) == 1:
            # one driven clamp (the pile): the rest axis along its end's start tangent, so that the clamp holds
            # the start as it is (a bowed rope's chord is not its end tangent)
            i, j = (0, 1) if drivens[0] is End.START else (-1, -2)
            tangent = (points[j] - points[i]) * (1 if i == 0 else -1)
            tangent /= np.linalg.norm(tangent)
            if abs(tangent @ axis - 1) > 1e-9:
                axis = tangent
        normal = np.asarray(rod.normal, float)
        director = normal - (normal @ axis) * axis
        if np.linalg.norm(director) < 1e-9:
            raise NotImplementedError("the rod's normal is parallel to its chord")
        director /= np.linalg.norm(director)
        drod = der.rod_from_shape(der.shapes.straight(L, n, axis=tuple(axis), director=tuple(director)),
                                  A1=m.youngs_modulus * inertia, A2=m.shear_modulus * 2.0 * inertia,
                                  EA=m.youngs_modulus * area, rho_A=m.density * area,
                                  rho_J=m.density * 2.0 * inertia)
        rest = drod.rest_state()
        # the start: the centreline at der's node arc lengths (-h/2 ... L + h/2), from the rest shape
        if rod.rest_arc_length is not None:
            arc = np.asarray(rod.rest_arc_length, float)
        else:
            arc = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))))
        s = drod.xi_nodes
        x0 = np.stack([np.interp(s, arc, points[:, a]) for a in range(3)], axis=1)
        for k, (i, j) in ((0, (0, 1)), (len(s) - 1, (-1, -2))):
            slope = (points[i] - points[j]) / (arc[i] - arc[j])
            x0[k] = points[i] + slope * (s[k] - arc[i])
        start = drod.displaced(rest, x0 - rest.positions)
        constraints, driven = [], []
        for end in End:
            cond = rod.condition(end)
            if cond is EndCondition.CLAMPED:
                motion = rod.motion(end)
                if motion is None:
                    constraints.append(der.clamp(end.value))
                else:
                    driven.append((end, motion))
                    constraints.append(None)
            elif cond is EndCondition.PINNED:
                constraints.append(der.hinge(end.value))
        loads = [der.end_force(load.force, load.at.value) for load in rod.loads]
        return drod, start, constraints, driven, loads

    def _run_rod(self, scenario, rod, n_elements, n_frames, numerics):
        drod, start, constraints, driven, loads = self._setup(scenario, rod, n_elements)
        s = drod.xi_nodes
        x0 = start.positions
        axis = drod.rest_state().positions[-1] - drod.rest_state().positions[0]
        axis /= np.linalg.norm(axis)
        g = np.asarray(scenario.gravity, float)
        if numerics["static"]:
            if np.any(g):
                loads.append(der.distributed_force(drod.rho_A * g))
            scene = der.Scene(drod, loads=loads, constraints=[c for c in constraints if c is not None])
            result = der.solve(scene, state=start, tol=1e-10, raise_on_failure=False)
            if not result.converged:
                raise Diverged(f"der.solve: {result.status}: {result.message}")
            frames = [start] + [result.state] * (n_frames - 1)
            return self._output(drod, frames)

        centres = {end: 0.5 * (x0[0] + x0[1]) if end is End.START else 0.5 * (x0[-1] + x0[-2]) for end, _ in driven}
        for end, _ in driven:
            k_out, k_in = (0, 1) if end is End.START else (len(s) - 1, len(s) - 2)
            t_end = x0[k_in] - x0[k_out]
            if abs(abs(t_end @ axis) / np.linalg.norm(t_end) - 1) > 1e-6:
                raise NotImplementedError("a driven clamp whose end does not start along the rod's chord")

        def supports(t):
            out = [c for c in constraints if c is not None]
            for end, motion in driven:
                d, R = motion.pose(t)
                slide = () if motion.slides_along is None else tuple(float(c) for c in motion.axis)
                out.append(der.clamp(end.value, rotation=R, position=centres[end] + d, slide=slide))
            return out

        contacts, friction = self._contacts(scenario, rod, drod)
        if contacts and not driven:
            start = self._drape(drod, start, loads, g, contacts, constraints)
        scene = der.Scene(drod, loads=loads, constraints=supports(0.0), contacts=contacts)
        damping = der.Damping(rayleigh_mass=numerics["damping_rate"]) if numerics["damping_rate"] else None
        extra = {}
        if contacts:
            extra = {"friction": friction, "rho_inf": numerics["rho_inf"]}
            if friction > 0:
                extra["slip_velocity"] = 1e-4 * rod.length
        traj = der.simulate(scene, scenario.duration, dt=numerics["dt"], state=start, damping=damping,
                            gravity=g if np.any(g) else None, supports=supports if driven else None,
                            save_every=numerics["steps_per_frame"], **extra)
        if traj.status != "completed":
            raise Diverged(f"der.simulate: {traj.status}: {traj.message}", time=float(traj.times[-1]))
        if len(traj.times) != n_frames:
            raise Diverged(f"der.simulate returned {len(traj.times)} frames, expected {n_frames}")
        return self._output(drod, None, traj)

    @staticmethod
    def _contacts(scenario, rod, drod):
        """der's contact terms of the scenario (obstacles offset by the rod's radius; self-contact if the
        scenario says the rod can reach itself) and the Coulomb coefficient at the obstacles (the larger of the
        obstacle's and the rod's). Between parts of the rope der's contact is frictionless."""
        from cosseratbench.scenario import Cylinder, Plane

        r = float(rod.radius)
        contacts, mu = [], 0.0
        for ob in scenario.obstacles:
            if isinstance(ob, Cylinder):
                contacts.append(der.cylinder(ob.center, ob.axis, ob.radius, radius=r))
            elif isinstance(ob, Plane):
                contacts.append(der.plane(ob.point, ob.normal, radius=r))
            else:
                raise NotImplementedError(f"obstacle {type(ob).__name__}")
            mu = max(mu, float(ob.friction), float(rod.friction))
        if contacts and scenario.self_contact:
            contacts.append(der.self_contact(r))
        return contacts, mu

    @staticmethod
    def _drape(drod, start, loads, g, contacts, constraints):
        """A start in contact equilibrium: nodes pushed out of every cylinder (so that der's straight edges clear
        it: the suite's points sit on the surface, der's nodes between them), then the frictionless equilibrium
        with the middle node pinned (and its edge's angle held) against sliding, by der.solve: the contact forces
        and the barrier's stiffness start right, and friction takes over the pin's load in the first steps."""
        from der.terms.obstacles import CYLINDER

        x = start.positions.copy()
        h = float(drod.l_bar.max())
        moved = False
        for c in contacts:
            if getattr(c, "kind", None) != CYLINDER:
                continue
            p, a, R = c.params[:3], c.params[3:6], c.params[6]
            r = c.radius
            need = (R + r + 0.5 * 0.1 * r) / math.cos(min(0.5 * h / (R + r), 1.0))
            rel = x - p
            along = rel @ a
            radial = rel - np.outer(along, a)
            rho = np.linalg.norm(radial, axis=1)
            low = rho < need
            if low.any():
                x[low] = p + np.outer(along[low], a) + radial[low] * (need / rho[low])[:, None]
                moved = True
        touching = []
        for c in contacts:
            if getattr(c, "kind", None) == CYLINDER:
                p, a, R = c.params[:3], c.params[3:6], c.params[6]
                rel = x - p
                rho = np.linalg.norm(rel - np.outer(rel @ a, a), axis=1)
                touching += list(np.flatnonzero(rho < R + 2.0 * c.radius + h))
        if moved:
            start = drod.displaced(start, x - start.positions)
        # pin the middle of the wrap (the middle node if nothing wraps)
        mid = int(np.median(touching)) if touching else drod.n_nodes // 2
        mid = min(max(mid, 1), drod.n_nodes - 2)
        pinned = [c for c in constraints if c is not None] + [der.pin(mid), der.fix_theta(mid)]
        settle_loads = list(loads)
        if np.any(g):
            settle_loads.append(der.distributed_force(drod.rho_A * g))
        result = der.solve(der.Scene(drod, loads=settle_loads, constraints=pinned, contacts=contacts), state=start,
                           raise_on_failure=False)
        if not result.converged:
            raise Diverged(f"der.solve (the draped start): {result.status}: {result.message}")
        return result.state

    @staticmethod
    def _output(drod, states=None, traj=None):
        """(positions [T, n_el + 1, 3], directors [T, n_el, 3]): edge midpoints, and m1 at the interior nodes."""
        from der.geometry import material_frames, tangents

        if traj is not None:
            xs = traj.positions
            m1s = traj.directors
        else:
            xs = np.array([st.positions for st in states])
            m1s = np.array([material_frames(st.q, tangents(st.q, drod.edge_nodes), st.d1)[0] for st in states])
        e = drod.edge_nodes
        mid = 0.5 * (xs[:, e[:, 0]] + xs[:, e[:, 1]])                   # [T, n, 3] = the suite's nodes
        d = 0.5 * (m1s[:, :-1] + m1s[:, 1:])                              # at the interior nodes = elements
        chord = mid[:, 1:] - mid[:, :-1]
        chord /= np.linalg.norm(chord, axis=2, keepdims=True)
        d -= np.sum(d * chord, axis=2, keepdims=True) * chord
        d /= np.linalg.norm(d, axis=2, keepdims=True)
        return mid, d
