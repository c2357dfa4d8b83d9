"""Dynamics in physical time (issue 15): ``der.simulate`` integrates M q'' = f_ext - dE/dq - f_damping + m g.

The internal forces and their Jacobian are the ones the static solvers use (``solvers.system.evaluate_system``:
one home for the energies, loads, supports and frame transport); this module adds only what time brings:

* **Mass** (``lumped_mass``). Translational mass lumped per node by the row sums of the consistent (linear)
  mass matrix of the material that each node stands for. An open rod's material runs over [0, L], from the
  midpoint of its first edge to the midpoint of its last; the outer nodes lie half an edge outside. The inner
  half of an end edge (length l/2, between the end cross-section and the first inner node) is a linear
  element over the parameter range s in [1/2, 1] of the edge; its row sums give the outer node rho_A l/8 and
  the inner node 3 rho_A l/8. This keeps the total mass rho_A L and its first moment exact (a free end has no
  first-order inertia error), where a whole half edge on the outer node would add rho_A l/2 of mass outside
  [0, L]. Rotational inertia about the tangent: rho_J times the length of [0, L] each edge's material frame
  stands for (``Rod.edge_weights``: half the end edges).
* **Damping** (``der.Damping``), part of the model: viscous per unit length (translational c_t, rotational
  c_r), slender-body resistive-force drag with normal and tangential coefficients (f = -[xi_n (I - t t^T) +
  xi_t t t^T] v per unit length, t the node tangent), and Rayleigh damping (alpha M + beta K).
* **Body force**: ``gravity`` g, as the force m_i g on each node's lumped mass (consistent with the inertia).
* **Time-dependent loads and supports**: ``loads`` and ``supports`` may be callables of t returning the load
  (constraint) records at that time; a clamp turned at a rate is ``lambda t: [der.clamp("end",
  rotation=R(t))]``.
* **Integrators**. ``"newmark"`` (default): the generalized-alpha family with forces at the end of the step
  (Arnold & Bruls 2007); at ``rho_inf = 1`` (the default for extensible rods) it is Newmark's
  average-acceleration (trapezoidal) rule: implicit, second order, unconditionally stable and free of numerical
  dissipation for linear problems (conjugate to the implicit midpoint rule, so no secular energy drift).
  Newton's method on the banded Jacobian K + 4 M / dt^2 + 2 C / dt (at rho_inf = 1), a step whose Newton
  iteration fails being retried as two halves (up to 5 times). An inextensible rod keeps its tensions as augmented-Lagrangian multipliers,
  updated within each step until the strain is below ``strain_tol``, with a penalty of 100 times the larger of
  the edge's inertial stiffness rho_A l / dt^2 and its bending stiffness A / l^3 (the multipliers then
  converge by about two digits per update). The trapezoidal rule lets such a stiff constraint's multipliers
  ring (a period-2 oscillation that nonlinear coupling can pump: a free helix gained energy until Newton failed),
  so an inextensible rod defaults to rho_inf = 0.95, which damps only the unresolved modes.
  ``"verlet"``: explicit velocity Verlet (symplectic, second order) with the inextensibility projection
  (``solvers.projection``: positions projected and velocities made tangent, RATTLE); its stable step is
  0.9 * 2 / omega_max (a Gershgorin bound of the stiffest mode with this mass).

Units: any consistent set (SI: m, kg, s, N). rho_A mass per length, rho_J mass * length (rotational inertia per
length, rho * J for a cross-section of polar moment J).

Example
-------
>>> import der
>>> rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.0, EA=1e4, rho_A=1.0, rho_J=1e-4)
>>> scene = der.Scene(rod, constraints=[der.clamp("start")])
>>> traj = der.simulate(scene, 0.05, dt=1e-3, gravity=[1.0, 0.0, 0.0])
>>> traj.completed
True
"""
import dataclasses
import math
import sys
import time
from dataclasses import dataclass

import numpy as np
from numba import njit

from . import validate

INTEGRATORS = ("newmark", "verlet")
MAX_NEWTON = 30
MAX_MULTIPLIER_UPDATES = 40
MAX_HALVINGS = 5           # a Newmark step whose Newton fails is retried as halves, down to dt / 32
CONTACT_STEP_FRACTION = 0.25  # with self-contact active, each Verlet piece is below 0.25 x 2 / omega_max
MAX_CONTACT_HALVINGS = 20  # a Verlet step with self-contact is split into halves down to dt / 2^20
# dynamic axial penalty of an inextensible rod, in units of each edge's inertial stiffness rho_A l / dt^2
DYNAMIC_PENALTY = 100.0


@dataclass(frozen=True)
class Damping:
    """Damping of the rod's motion: viscous per length, resistive-force (slender-body) drag, Rayleigh.

    Parameters
    ----------
    translational : float >= 0
        Viscous force per unit length per unit velocity, c_t (force * time / length^2): f = -c_t v, the same
        in every direction.
    rotational : float >= 0
        Viscous moment per unit length per unit spin about the tangent, c_r (force * time): m = -c_r theta'.
    normal, tangential : float >= 0
        Resistive-force-theory drag coefficients xi_n, xi_t (force * time / length^2) of a slender filament in
        a viscous fluid: f = -[xi_n (I - t t^T) + xi_t t t^T] v per unit length (for a thin filament
        xi_n ~ 2 xi_t; Lighthill / Gray-Hancock: xi_t = 2 pi mu / (ln(2 l/a) - 1/2)).
    rayleigh_mass, rayleigh_stiffness : float >= 0
        Rayleigh damping C = alpha M + beta K (alpha in 1/time, beta in time); beta K uses the stiffness at
        the current iterate.

    Forces are lumped on the nodes with the same weights as the mass (``lumped_mass``).

    Example
    -------
    >>> import der
    >>> der.Damping(translational=0.1)
    Damping(translational=0.1, rotational=0.0, normal=0.0, tangential=0.0, rayleigh_mass=0.0, rayleigh_stiffness=0.0)
    """

    translational: float = 0.0
    rotational: float = 0.0
    normal: float = 0.0
    tangential: float = 0.0
    rayleigh_mass: float = 0.0
    rayleigh_stiffness: float = 0.0

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or \
                    not math.isfinite(v) or v < 0:
                raise ValueError(f"der.Damping: {f.name} must be a finite number >= 0; got {v!r}")
            object.__setattr__(self, f.name, float(v))

    @property
    def any(self):
        """True if any coefficient is nonzero."""
        return any(getattr(self, f.name) for f in dataclasses.fields(self))


NO_DAMPING = Damping()


def node_mass_weights(rod):
    """Length of material each node's lumped mass stands for (row sums of the consistent linear mass matrix
    on [0, L]; see the module docstring): l/8 on the outer nodes of an open rod, 3 l/8 + l'/2 on the first
    inner node, (l_{j-1} + l_j)/2 elsewhere. Sums to L.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 3), A1=1.0, A2=1.0)
    >>> der.dynamics.node_mass_weights(rod)          # l = 1/2: l/8, 3 l/8 + l/2, l/2 + 3 l/8, l/8
    array([0.0625, 0.4375, 0.4375, 0.0625])
    """
    w = np.zeros(rod.n_nodes)
    np.add.at(w, rod.edge_nodes[:, 0], 0.5 * rod.l_bar)
    np.add.at(w, rod.edge_nodes[:, 1], 0.5 * rod.l_bar)
    if not rod.closed:
        for j, (outer, inner) in ((0, (0, 1)), (rod.n_edges - 1, (rod.n_nodes - 1, rod.n_nodes - 2))):
            l = rod.l_bar[j]
            w[outer] += l / 8.0 - l / 2.0
            w[inner] += 3.0 * l / 8.0 - l / 2.0
    return w


def lumped_mass(rod, rho_J=None):
    """Mass per DOF (n_dof,): rho_A times ``node_mass_weights`` on x, y, z of each node; rho_J times the
    length each edge's frame stands for on its theta; 1 on the dummy theta of an open rod (always held).

    ``rho_J`` (mass * length) defaults to ``rod.rho_J``; if that is None too, to rho_A h^2 A2 / (4 A1) (twist
    waves at the bending wave speed on the edge scale: a numerical choice, not a physical cross-section; give
    rho_J = rho J for a physical rod, e.g. rho_A r^2 / 2 for a solid circular section).

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 10), A1=1.0, A2=1.0, rho_A=2.0, rho_J=0.1)
    >>> m = der.dynamics.lumped_mass(rod)
    >>> round(float(m.reshape(-1, 4)[:, 0].sum()), 12)     # rho_A L
    2.0
    """
    if rho_J is None:
        from .solvers.system import rotational_inertia

        rho_J = rotational_inertia(rod)
    m = np.repeat(rod.rho_A * node_mass_weights(rod), 4)
    m[3::4] = 1.0
    m[4 * np.arange(rod.n_edges) + 3] = rho_J * rod.edge_weights()
    return m


@dataclass(eq=False)
class Trajectory:
    """The result of ``der.simulate``: the rod's motion at the saved times.

    Attributes
    ----------
    times : (k,) simulated times (same unit as ``dt``).
    positions : (k, n_nodes, 3) node positions; ``thetas`` : (k, n_edges) edge angles; ``directors`` :
        (k, n_edges, 3) material directors m1 (so frames are comparable across runs).
    velocities : (k, n_dof) generalized velocities (node velocities and theta rates).
    energies : dict of (k,) arrays: "kinetic", "elastic" (stretch + bend + twist), "gravity" (-sum m g.x),
        "work" (of the applied loads and moving supports since t = 0, trapezoidal), "dissipated" (by the
        damping since t = 0) and "total" = kinetic + elastic + gravity - work + dissipated (constant up to
        the integrator's error).
    state : der.RodState at the last step; ``velocity`` : (n_dof,) there.
    status : "completed", "stopped" (by the callback), "newton_failed", "nonfinite" or "interrupted";
        ``message`` says more. ``steps``, ``newton_iterations`` (total), ``wall_time`` (s), ``dt``,
        ``integrator``, ``rho_inf`` (newmark), ``multiplier_updates``, ``compile_time`` (s, apart from the wall
        time).

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 10), A1=1.0, A2=1.0, EA=1e3, rho_J=1e-3)
    >>> traj = der.simulate(der.Scene(rod, constraints=[der.clamp("start")]), 0.01, dt=1e-3, gravity=[1, 0, 0])
    >>> traj.status, traj.positions.shape
    ('completed', (11, 11, 3))
    """

    times: np.ndarray
    positions: np.ndarray
    thetas: np.ndarray
    directors: np.ndarray
    velocities: np.ndarray
    energies: dict
    state: object
    velocity: np.ndarray
    status: str
    message: str
    steps: int
    newton_iterations: int
    wall_time: float
    dt: float
    integrator: str
    compile_time: float = 0.0
    multiplier_updates: int = 0
    rho_inf: float = float("nan")

    @property
    def completed(self):
        """True if the run reached t_end (status "completed")."""
        return self.status == "completed"

    def __repr__(self):
        return (f"Trajectory({self.status}, {self.integrator}, t = {self.times[0]:.4g} ... {self.times[-1]:.4g}, "
                f"{len(self.times)} frames, {self.steps} steps of dt = {self.dt:.3g}, "
                f"{self.newton_iterations} Newton iterations, wall time {self.wall_time:.3g} s; {self.message})")

    def save(self, path):
        """Write the trajectory to ``path`` (.npz): times, positions, thetas, directors, velocities and one
        array ``energy_<name>`` per energy, plus dt, integrator and status."""
        arrays = {"times": self.times, "positions": self.positions, "thetas": self.thetas,
                  "directors": self.directors, "velocities": self.velocities, "dt": np.array(self.dt),
                  "integrator": np.array(self.integrator), "status": np.array(self.status)}
        arrays.update({f"energy_{k}": v for k, v in self.energies.items()})
        np.savez_compressed(path, **arrays)


# ---------------------------------------------------------------------------------------------- kernels

@njit(cache=True)
def node_tangents(q, edge_nodes, n_nodes, closed):
    """Unit tangent at each node (n_nodes, 3): the normalised sum of the unit tangents of its edges."""
    out = np.zeros((n_nodes, 3))
    for j in range(edge_nodes.shape[0]):
        a = edge_nodes[j, 0]
        b = edge_nodes[j, 1]
        e = np.empty(3)
        s = 0.0
        for c in range(3):
            e[c] = q[4 * b + c] - q[4 * a + c]
            s += e[c] * e[c]
        s = np.sqrt(s)
        for c in range(3):
            out[a, c] += e[c] / s
            out[b, c] += e[c] / s
    for k in range(n_nodes):
        s = np.sqrt(out[k, 0] ** 2 + out[k, 1] ** 2 + out[k, 2] ** 2)
        if s > 0.0:
            for c in range(3):
                out[k, c] /= s
    return out


@njit(cache=True)
def add_drag(q, v, edge_nodes, weights, xi_n, xi_t, closed, f, ab, scale, kl, ku, perm):
    """Resistive-force drag: f -= w_k [xi_n (I - t t^T) + xi_t t t^T] v_k on every node k (t its tangent,
    w_k its length); with ``ab`` non-empty also adds ``scale`` times the 3x3 blocks to the band (the Jacobian
    of the drag with respect to the velocity, times dv/dq). Returns the drag power -f_drag . v >= 0."""
    n_nodes = weights.shape[0]
    t = node_tangents(q, edge_nodes, n_nodes, closed)
    power = 0.0
    off = kl + ku
    for k in range(n_nodes):
        tv = t[k, 0] * v[4 * k] + t[k, 1] * v[4 * k + 1] + t[k, 2] * v[4 * k + 2]
        for a in range(3):
            fa = weights[k] * (xi_n * (v[4 * k + a] - t[k, a] * tv) + xi_t * t[k, a] * tv)
            f[4 * k + a] -= fa
            power += fa * v[4 * k + a]
        if ab.shape[0] > 0:
            for a in range(3):
                i = 4 * k + a
                for b in range(3):
                    j = 4 * k + b
                    d = xi_n if a == b else 0.0
                    cab = weights[k] * (d + (xi_t - xi_n) * t[k, a] * t[k, b])
                    ab[off + perm[i] - perm[j], perm[j]] += scale * cab
    return power


@njit(cache=True)
def add_friction(q1, q0, normals, normal_force, mu, eps_v, dt, f, ab, kl, ku, perm):
    """Lagged smoothed Coulomb friction (IPC, Li et al. 2020, section 5) on every node k with a normal force:
    u = P_k (x1_k - x0_k) / dt the tangential velocity over the step (P_k = I - n_k n_k^T, n_k and N_k lagged
    from the start of the step), f_k = -mu N_k f1(|u|) u / |u| with f1(y) = 2 y / eps - y^2 / eps^2 below the
    slip velocity eps and 1 above it: Coulomb's law |f| <= mu N, sticking where |u| << eps. Adds f to ``f`` and,
    with ``ab`` non-empty, its exact Jacobian -df/dx1 (positive semi-definite: f1 is increasing) to the band. Returns the energy
    it dissipates over the step, -f . (x1 - x0) >= 0."""
    n_nodes = normal_force.shape[0]
    off = kl + ku
    lost = 0.0
    for k in range(n_nodes):
        N = normal_force[k]
        if N <= 0.0:
            continue
        d = np.empty(3)
        for a in range(3):
            d[a] = (q1[4 * k + a] - q0[4 * k + a]) / dt
        dn = d[0] * normals[k, 0] + d[1] * normals[k, 1] + d[2] * normals[k, 2]
        u = np.empty(3)
        for a in range(3):
            u[a] = d[a] - dn * normals[k, a]
        y = np.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
        if y < eps_v:
            ratio = 2.0 / eps_v - y / (eps_v * eps_v)        # f1(y) / y
            slope = 2.0 / eps_v - 2.0 * y / (eps_v * eps_v)  # f1'(y)
        else:
            ratio = 1.0 / y
            slope = 0.0
        c = mu * N * ratio
        for a in range(3):
            f[4 * k + a] -= c * u[a]
            lost += c * u[a] * d[a] * dt
        if ab.shape[0] > 0:
            for a in range(3):
                i = 4 * k + a
                for b in range(3):
                    j = 4 * k + b
                    p = (1.0 if a == b else 0.0) - normals[k, a] * normals[k, b]
                    uu = u[a] * u[b] / (y * y) if y > 0.0 else 0.0
                    # exact: d f / d x1 = -(mu N / dt) [ratio (P - uu) + f1'(y) uu]: PSD since f1' >= 0
                    ab[off + perm[i] - perm[j], perm[j]] += mu * N * (ratio * (p - uu) + slope * uu) / dt
    return lost


# ---------------------------------------------------------------------------------------------- driver

class _Model:
    """Everything time-dependent around one ``System``: mass, damping, gravity, loads(t), supports(t)."""

    def __init__(self, scene, system, mass, damping, gravity, loads_at, supports_at):
        self.scene, self.system, self.mass, self.damping = scene, system, mass, damping
        self.rod = scene.rod
        self.gravity = gravity
        self.loads_at, self.supports_at = loads_at, supports_at
        n = self.rod.n_dof
        self.f_gravity = np.zeros(n)
        if gravity is not None:
            self.f_gravity.reshape(-1, 4)[:, :3] = mass.reshape(-1, 4)[:, :3] * gravity[None, :]
        wn = node_mass_weights(self.rod)
        self.node_w = wn
        self.c_diag = np.zeros(n)
        if damping.translational:
            self.c_diag.reshape(-1, 4)[:, :3] += damping.translational * wn[:, None]
        if damping.rotational:
            self.c_diag[4 * np.arange(self.rod.n_edges) + 3] += damping.rotational * self.rod.edge_weights()
        if damping.rayleigh_mass:
            self.c_diag += damping.rayleigh_mass * mass
        self.drag = damping.normal > 0 or damping.tangential > 0
        self.constraints = scene.constraints
        self.support_key = support_layout(scene.constraints)
        self.rebuilds = 0

    def set_time(self, t):
        """Put the loads and supports of time t into the system (only if they depend on time).

        Supports: ``supports_at(t)``'s records become ``self.constraints`` (the targets the step applies with
        ``move_supports``); nothing is rebuilt while they keep the kinds, ends and free directions of the
        records at t = 0 -- only their rotations and positions move. A change of those (a support added,
        released or turned into another kind) rebuilds the scene and the links (``self.rebuilds``). Loads:
        ``loads_at(t)`` rebuilds the scene's load plan at every step."""
        from .scene import Scene, make_plan
        from .solvers.system import applied_scales

        sys_ = self.system
        if self.supports_at is not None:
            cons = tuple(self.supports_at(t))
            key = support_layout(cons)
            if key != self.support_key:
                sc = sys_.scene
                sys_.scene = Scene(self.rod, energies=sc.energies, loads=sc.loads, constraints=cons,
                                   contacts=sc.contacts)
                sys_.link_patterns = None           # built afresh by the next move_supports
                self.support_key = key
                self.rebuilds += 1
            self.constraints = cons
        if self.loads_at is not None:
            sc = sys_.scene
            scene_t = Scene(self.rod, energies=sc.energies, loads=tuple(self.loads_at(t)),
                            constraints=sc.constraints, contacts=sc.contacts)
            sys_.scene = scene_t
            k = sys_.plan.k_stretch
            sys_.plan = make_plan(scene_t, k)
            sys_.k_stretch = sys_.plan.k_stretch
            sys_.applied_force, sys_.applied_moment = applied_scales(scene_t)

    def forces(self, state, v, order, jac_scale=0.0):
        """Generalized force F = f_ext - dE/dq + m g - f_damping(v) (full space) and the elastic energy;
        with order 2 the band ``system.ab`` holds K and ``jac_scale`` times the damping Jacobian dF/dv is
        subtracted from it (Newmark: dv/dq = 2/dt). Returns (F, energy, damping power)."""
        from .solvers.system import evaluate_system

        sys_ = self.system
        energy = evaluate_system(sys_, state, order)
        F = sys_.fext - sys_.grad + self.f_gravity
        power = 0.0
        if self.c_diag.any():
            fd = self.c_diag * v
            F -= fd
            power += float(fd @ v)
        d = self.damping
        if d.rayleigh_stiffness:
            from .linalg import band_matvec

            Kv = np.empty_like(v)
            if order < 2:
                raise RuntimeError("Rayleigh stiffness damping needs the Jacobian (order 2)")
            band_matvec(sys_.ab, sys_.kl, sys_.ku, sys_.perm, v, Kv, False)
            F -= d.rayleigh_stiffness * Kv
            power += d.rayleigh_stiffness * float(Kv @ v)
        if self.drag:
            ab = sys_.ab if order >= 2 else np.zeros((0, 0))
            power += add_drag(state.q, v, self.rod.edge_nodes, self.node_w, d.normal, d.tangential,
                              self.rod.closed, F, ab, jac_scale, sys_.kl, sys_.ku, sys_.perm)
        return F, energy, power


def support_layout(constraints):
    """What of the support records ``constraints`` fixes the links' layout -- their kinds, ends, nodes, edges and
    free directions, not their targets (rotations, positions): two lists with the same layout differ only in
    where their supports are.

    Example
    -------
    >>> import numpy as np, der
    >>> der.dynamics.support_layout([der.clamp("end", rotation=np.eye(3))])
    (('clamp', 'end', (), None),)
    """
    from .constraints import Clamp, EndSupport, Pin

    out = []
    for c in constraints:
        if isinstance(c, Clamp):
            out.append(("clamp", c.end, c.slide, c.direction))
        elif isinstance(c, EndSupport):
            out.append((c.kind, c.end, c.free))
        elif isinstance(c, Pin):
            out.append(("pin", c.node))
        else:
            out.append((type(c).__name__, getattr(c, "edge", None)))
    return tuple(out)


def _as_velocity(rod, velocity):
    n = rod.n_dof
    if velocity is None:
        return np.zeros(n)
    v = np.asarray(velocity, dtype=float)
    if v.shape == (rod.n_nodes, 3):
        out = np.zeros(n)
        out.reshape(-1, 4)[:, :3] = v
        return out
    if v.shape != (n,):
        raise ValueError(f"der.simulate: velocity must have shape ({n},) (4 per node: vx, vy, vz, theta rate) or "
                         f"({rod.n_nodes}, 3); got {v.shape}")
    if not np.isfinite(v).all():
        raise ValueError("der.simulate: velocity must be finite")
    return v.copy()


def _gravity(gravity):
    if gravity is None:
        return None
    g = validate.vector3(gravity, "der.simulate: gravity")
    return np.asarray(g, dtype=float)


def simulate(scene, t_end, dt=None, integrator="newmark", state=None, velocity=None, damping=None, gravity=None,
             loads=None, supports=None, rho_J=None, save_every=1, callback=None, record=None, progress=None,
             newton_tol=1e-10, strain_tol=1e-9, max_steps=10_000_000, time_budget=math.inf, rho_inf=None,
             friction=0.0, slip_velocity=None):
    """Integrate the rod's motion in physical time from t = 0 to ``t_end``.

    Parameters
    ----------
    scene : der.Scene
        The rod (its ``rho_A``, ``rho_J``), energies, loads and supports. Loads and supports are those of the
        scene unless ``loads`` / ``supports`` give them as functions of time.
    t_end : float > 0
        Simulated time to reach (same time unit as dt, rho_A and the stiffnesses).
    dt : float > 0, optional
        Time step. Required for "newmark" (an implicit step is chosen for accuracy); for "verlet" the default
        is 0.9 times the stable step 2 / omega_max (larger values are refused).
    integrator : "newmark" (implicit average acceleration, default) or "verlet" (explicit velocity Verlet).
    state : der.RodState, optional (default: the rest state); velocity : (n_dof,) or (n_nodes, 3), optional.
    damping : der.Damping, optional (default: none -- energy is conserved up to the integrator's error).
    gravity : 3-vector, optional
        Acceleration of gravity (length / time^2); the body force is each node's lumped mass times it.
    loads : callable t -> sequence of load records, optional (time-dependent loads; replaces scene.loads).
    supports : callable t -> sequence of constraints, optional (prescribed support motions, e.g.
        ``lambda t: [der.clamp("start", rotation=R(t))]``; replaces scene.constraints). Its value at t = 0
        must hold the start state, and the held DOFs move as it says at every step.
    rho_J : float >= 0, optional: rotational inertia per length (default ``rod.rho_J``, see ``lumped_mass``).
        0 makes the twist quasi-static (each edge angle in balance at every step, as in Bergou et al. 2008):
        a physical rod's twist modes are L / r times faster than its bending modes, and an implicit step that
        does not resolve them gains nothing from their inertia (Newmark only).
    save_every : int >= 1: save a frame every this many steps (and the last one).
    callback : callable(t, state, velocity) -> bool, optional: called after every step; True stops the run.
    record : path of a rerun recording (.rrd), written on a ``sim_time`` timeline (at the saved frames).
    progress : True/False/None: progress lines on stderr (None: after 2 s of wall time).
    newton_tol : Newton converges when the largest node correction is below newton_tol times the edge length
        (and the largest angle correction below newton_tol radians).
    strain_tol : largest |strain| an inextensible rod may keep at the end of a step.
    friction : float >= 0
        Coulomb coefficient mu at the scene's obstacle contacts (``contacts=[der.cylinder(...)]``, "newmark"):
        lagged smoothed friction as in IPC -- the normal force and contact normal of each node from the barrier
        at the start of the step, a friction force -mu N f1(|u|) u / |u| on its tangential velocity u over the
        step, f1 rising smoothly from 0 to 1 over the slip velocity. Self-contact (``der.self_contact``) is
        frictionless; its barrier joins the implicit step's Newton system as in ``der.solve`` (rho_inf = 0 is
        advised for impacts: the trapezoidal rule can gain energy on the stiff barrier, docs/dynamics.md). With
        "verlet" its gradient is a force of the explicit step, each position update is proven non-crossing by
        CCD and the step is split into halves where it is not, or where it exceeds a quarter of the elastic +
        barrier stable step (at most 2^20 pieces, then status "contact_failed" naming the time and the pair).
    slip_velocity : float > 0, optional: the smoothing velocity eps_v (default 1e-3 edge lengths per step:
        h / (1000 dt)); a sticking contact creeps at most at about this speed.
    rho_inf : float in [0, 1], "newmark" only: the spectral radius at infinite frequency of the generalized-alpha
        method (Chung & Hulbert 1993, in the form of Arnold & Bruls 2007 with forces at the end of the step).
        1 is Newmark's average-acceleration (trapezoidal) rule: no numerical dissipation (the default for an
        extensible rod; None picks 1 there and 0.95 for an inextensible rod, see below). Below 1 the
        unresolved modes (omega dt >> 1) are damped and the resolved ones keep second-order accuracy (energy
        loss O((omega dt)^3) per step); 0.8-0.95 is the usual remedy for an inextensible rod, whose stiff
        constraint makes the trapezoidal rule's multipliers ring (period-2 oscillation, index-3 constraints).
    max_steps, time_budget : bounds (steps; seconds of wall time); reaching the time budget ends the run
        with status "stopped".

    Returns
    -------
    Trajectory (times, positions, thetas, directors, velocities, energies, final state; ``.save(path)``).

    Raises ValueError (naming the argument) for bad input, before any work.

    Conventions: t starts at 0; velocity entries follow q (x, y, z per node, theta rate per edge: the spin of
    the material frame about the tangent relative to the time-parallel reference frame).

    Example
    -------
    A cantilever released from rest under gravity (SI units: a 1 m steel-like wire would be A1 ~ 1e-2):

    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 20), A1=1.0, A2=1.0, EA=1e4, rho_A=1.0, rho_J=1e-4)
    >>> scene = der.Scene(rod, constraints=[der.clamp("start")])
    >>> traj = der.simulate(scene, t_end=0.1, dt=1e-3, gravity=[1.0, 0.0, 0.0], save_every=10)
    >>> traj.status, len(traj.times)
    ('completed', 11)
    """
    from .scene import Scene

    if not isinstance(scene, Scene):
        raise ValueError(f"der.simulate: scene must be a der.Scene; got {type(scene).__name__}")
    if getattr(scene, "scenes", None) is not None:
        raise ValueError("der.simulate: scene: a scene of several rods is not supported in dynamics yet; simulate "
                         "one rod per scene")
    rod = scene.rod
    t_end = validate.positive_number(t_end, "der.simulate: t_end", "a finite time > 0")
    if integrator not in INTEGRATORS:
        raise ValueError(f"der.simulate: integrator must be one of {INTEGRATORS}; got {integrator!r}")
    if dt is not None:
        dt = validate.positive_number(dt, "der.simulate: dt", "a finite time step > 0")
    elif integrator == "newmark":
        raise ValueError("der.simulate: dt is required with integrator='newmark' (an implicit step is a matter of "
                         "accuracy: e.g. a twentieth of the shortest period you need to resolve)")
    if damping is None:
        damping = NO_DAMPING
    if not isinstance(damping, Damping):
        raise ValueError(f"der.simulate: damping must be a der.Damping; got {type(damping).__name__}")
    g = _gravity(gravity)
    v0 = _as_velocity(rod, velocity)
    if isinstance(save_every, bool) or not isinstance(save_every, (int, np.integer)) or save_every < 1:
        raise ValueError(f"der.simulate: save_every must be an integer >= 1; got {save_every!r}")
    for name, fn in (("loads", loads), ("supports", supports), ("callback", callback)):
        if fn is not None and not callable(fn):
            raise ValueError(f"der.simulate: {name} must be a callable of t (or None); got {type(fn).__name__}")
    if rho_J is not None:
        rho_J = validate.real_number(rho_J, "der.simulate: rho_J", "a finite number >= 0")
        if not rho_J >= 0:
            raise ValueError(f"der.simulate: rho_J must be a finite number >= 0; got {rho_J!r}")
        if rho_J == 0 and integrator == "verlet":
            raise ValueError("der.simulate: rho_J = 0 (quasi-static twist) needs integrator='newmark'")
    if rho_inf is None:
        rho_inf = 0.95 if rod.inextensible else 1.0
    rho_inf = validate.real_number(rho_inf, "der.simulate: rho_inf", "a number in [0, 1]")
    if not 0.0 <= rho_inf <= 1.0:
        raise ValueError(f"der.simulate: rho_inf must be in [0, 1] (1: no numerical dissipation); got {rho_inf!r}")
    newton_tol = validate.positive_number(newton_tol, "der.simulate: newton_tol", "a finite number > 0")
    strain_tol = validate.positive_number(strain_tol, "der.simulate: strain_tol", "a finite number > 0")
    friction = validate.real_number(friction, "der.simulate: friction", "a Coulomb coefficient >= 0")
    if not friction >= 0:
        raise ValueError(f"der.simulate: friction must be a Coulomb coefficient >= 0; got {friction!r}")
    if friction > 0 and not scene.contacts:
        raise ValueError("der.simulate: friction > 0 needs obstacle contacts in the scene (contacts=[...])")
    if friction > 0 and integrator != "newmark":
        raise ValueError("der.simulate: friction needs integrator='newmark'")
    if slip_velocity is not None:
        slip_velocity = validate.positive_number(slip_velocity, "der.simulate: slip_velocity",
                                                 "a finite velocity > 0")
    if state is None:
        state = rod.rest_state()
    elif state.q.shape != (rod.n_dof,):
        raise ValueError(f"der.simulate: state does not belong to this rod (q has shape {state.q.shape})")
    if record is not None:
        from .solvers import check_record_path

        check_record_path(record, "der.simulate: record")
    if supports is not None:
        scene = Scene(rod, energies=scene.energies, loads=scene.loads, constraints=tuple(supports(0.0)),
                      contacts=scene.contacts)
    if loads is not None:
        scene = Scene(rod, energies=scene.energies, loads=tuple(loads(0.0)), constraints=scene.constraints,
                      contacts=scene.contacts)

    from .solvers import SolverOptions, _compile_first
    from .solvers.system import build_system, prepare_state, start_moving_supports, update_links

    compile_time = _compile_first()
    compile_time += _compile_dynamics()
    system = build_system(scene, SolverOptions())
    mass = lumped_mass(rod, rho_J)
    system.mass_full = mass.copy()
    work = prepare_state(system, state)       # targets of t = 0 applied; links and condensed mass from `mass`
    update_links(system, work)
    if supports is not None:
        start_moving_supports(system, work)   # laid out once: each step recomputes the links in place
    if system.terms:
        from .terms import warmup as _contact_warmup

        compile_time += _contact_warmup()
        for term in system.terms:
            term.check_start(work)
        for term in system.terms:
            term.start_stiffness(work, system)
    model = _Model(scene, system, mass, damping, g, loads, supports)
    if integrator == "newmark":
        runner = _NewmarkRun(model, work, v0, dt, newton_tol, strain_tol, rho_inf)
        runner.friction = friction
        runner.slip_velocity = slip_velocity
    else:
        runner = _VerletRun(model, work, v0, dt, strain_tol)
    dt = runner.dt
    n_steps = int(math.ceil(t_end / dt - 1e-9))
    if n_steps > max_steps:
        raise ValueError(f"der.simulate: t_end / dt = {n_steps} steps exceeds max_steps = {max_steps}")
    dt = t_end / n_steps                      # land exactly on t_end
    runner.set_dt(dt)

    recorder = None
    if record is not None:
        from .recording import Recorder

        recorder = Recorder(record, rod, scene=scene, max_overhead=None)
        recorder.log_rest()
    frames = _Frames(rod)
    t0 = time.perf_counter()
    last_print = t0
    status, message = "completed", f"reached t = {t_end:g} in {n_steps} steps"
    step = 0
    t = 0.0
    energies = runner.energies()
    frames.add(0.0, runner.state, runner.v, energies)
    if recorder is not None:
        _record(recorder, 0, 0.0, runner.state, energies, 0.0)
    try:
        while step < n_steps:
            t_next = (step + 1) * dt
            ok, why = runner.step(t_next)
            if not ok:
                status, message = why
                break
            step += 1
            t = t_next
            energies = runner.energies()
            if not np.isfinite(runner.state.q).all() or not all(np.isfinite(e) for e in energies.values()):
                status, message = "nonfinite", f"non-finite state or energy at t = {t:g} (step {step})"
                break
            if step % save_every == 0 or step == n_steps:
                frames.add(t, runner.state, runner.v, energies)
                if recorder is not None:
                    _record(recorder, step, t, runner.state, energies, time.perf_counter() - t0)
            if callback is not None and callback(t, runner.state, runner.v):
                status, message = "stopped", f"stopped by the callback at t = {t:g} (step {step})"
                break
            now = time.perf_counter()
            if now - t0 > time_budget:
                status, message = "stopped", f"time budget of {time_budget:g} s used up at t = {t:g}"
                break
            if (progress or (progress is None and now - t0 > 2.0)) and now - last_print >= 1.0:
                last_print = now
                print(f"[der] simulate ({integrator}): t = {t:.4g} of {t_end:.4g} (step {step} of {n_steps}, "
                      f"{runner.newton} Newton iterations, {now - t0:.1f} s)", file=sys.stderr, flush=True)
    except KeyboardInterrupt:
        status, message = "interrupted", f"interrupted by the user at t = {t:g}"
    finally:
        if recorder is not None:
            recorder.close()
    if frames.times[-1] != t:
        frames.add(t, runner.state, runner.v, energies)
    return frames.trajectory(runner, status, message, step, time.perf_counter() - t0, dt, integrator,
                             compile_time)


_DYNAMICS_COMPILED = False


def _compile_dynamics():
    """Compile (or load from cache) this module's kernels once per process; returns the seconds it took."""
    global _DYNAMICS_COMPILED
    if _DYNAMICS_COMPILED:
        return 0.0
    t0 = time.perf_counter()
    q = np.zeros(12)
    q[4] = 1.0
    q[8] = 2.0
    en = np.array([[0, 1], [1, 2]], dtype=np.int64)
    add_drag(q, np.zeros(12), en, np.ones(3), 1.0, 1.0, False, np.zeros(12), np.zeros((0, 0)), 0.0, 1, 1,
             np.arange(12, dtype=np.int64))
    add_friction(q, q, np.zeros((3, 3)), np.zeros(3), 0.1, 1.0, 1.0, np.zeros(12), np.zeros((0, 0)), 1, 1,
                 np.arange(12, dtype=np.int64))
    from .constraints import relink_end

    x = q.reshape(-1, 4)[:, :3]
    relink_end(x[0], x[1], np.eye(3), True, False, np.arange(5, dtype=np.int64), np.array([5], dtype=np.int64),
               np.empty((5, 2)))
    _DYNAMICS_COMPILED = True
    return time.perf_counter() - t0


def _record(recorder, step, t, state, energies, elapsed):
    recorder.rec.set_time("sim_time", duration=float(t))
    recorder._write(int(step), state, float("nan"), energies, elapsed, final=False)


class _Frames:
    def __init__(self, rod):
        self.rod = rod
        self.times, self.x, self.theta, self.m1, self.v = [], [], [], [], []
        self.energies = {}

    def add(self, t, state, v, energies):
        from .geometry import material_frames, tangents

        rod = self.rod
        self.times.append(float(t))
        self.x.append(state.positions.copy())
        self.theta.append(state.q[4 * np.arange(rod.n_edges) + 3].copy())
        m1, _ = material_frames(state.q, tangents(state.q, rod.edge_nodes), state.d1)
        self.m1.append(m1)
        self.v.append(v.copy())
        for k, e in energies.items():
            self.energies.setdefault(k, []).append(float(e))

    def trajectory(self, runner, status, message, steps, wall, dt, integrator, compile_time):
        return Trajectory(np.array(self.times), np.array(self.x), np.array(self.theta), np.array(self.m1),
                          np.array(self.v), {k: np.array(v) for k, v in self.energies.items()},
                          runner.state.copy(), runner.v.copy(), status, message, steps, runner.newton, wall, dt,
                          integrator, compile_time, runner.updates, getattr(runner, "rho_inf", float("nan")))


class _Run:
    """Shared bookkeeping of both integrators: energies, work and dissipation."""

    def __init__(self, model, state, v0):
        self.model = model
        self.system = model.system
        self.rod = model.rod
        self.state = state
        sysm = self.system
        self.held = sysm.fixed.copy()
        self.held[sysm.links.dep] = False
        v = v0.copy()
        v[self.held] = 0.0
        self._expand_consistent(v)
        self.v = v
        self.newton = 0
        self.updates = 0
        self.work = 0.0
        self.dissipated = 0.0
        self.power = 0.0

    def _expand_consistent(self, v):
        """v <- T (T^T-free part of v): dependents of the end supports follow their masters."""
        from .solvers.system import expand

        lk = self.system.links
        if lk.dep.size:
            v[lk.dep] = 0.0
            expand(self.system, v)

    def set_dt(self, dt):
        self.dt = dt

    def accel(self, F):
        """M^-1 F in the free variables (T^T M T lumped), expanded to all DOFs; zero on held DOFs."""
        from .solvers.system import condense_forces, expand

        r = condense_forces(self.system, F.copy())
        m = self.system.mass
        a = np.divide(r, m, out=np.zeros_like(r), where=m > 0)    # rho_J = 0: quasi-static twist, no rate
        a[self.system.fixed] = 0.0
        return expand(self.system, a)

    def energies(self):
        from .solvers.system import energy_terms

        e = energy_terms(self.system, self.state)
        elastic = sum(v for k, v in e.items() if k != "contact")
        contact = e.get("contact", 0.0)
        kinetic = 0.5 * float(self.model.mass @ (self.v * self.v))
        grav = -float(self.model.f_gravity @ self.state.q)
        out = {"kinetic": kinetic, "elastic": elastic, "gravity": grav, "work": self.work,
               "dissipated": self.dissipated,
               "total": kinetic + elastic + contact + grav - self.work + self.dissipated}
        if self.system.terms:
            out["contact"] = contact
        return out

    def _load_force(self):
        """The applied generalized force (loads; supports' reactions count through the held DOFs' motion)."""
        return self.system.fext.copy()


class _NewmarkRun(_Run):
    """Average-acceleration Newmark (trapezoidal rule): q1 = q0 + dt v0 + dt^2/4 (a0 + a1),
    v1 = v0 + dt/2 (a0 + a1), M a1 = F(q1, v1); Newton on q1."""

    def __init__(self, model, state, v0, dt, newton_tol, strain_tol, rho_inf=1.0):
        super().__init__(model, state, v0)
        self.dt = dt
        # generalized-alpha in the form of Arnold & Bruls (2007): forces at t_{n+1}, a pseudo-acceleration a with
        # (1 - am) a_{n+1} + am a_n = (1 - af) qdd_{n+1} + af qdd_n; rho_inf = 1 is the trapezoidal rule
        self.rho_inf = rho_inf
        self.am = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
        self.af = rho_inf / (rho_inf + 1.0)
        self.gamma = 0.5 + self.af - self.am
        self.beta = 0.25 * (self.gamma + 0.5) ** 2
        self.newton_tol = newton_tol
        self.strain_tol = strain_tol
        rod = self.rod
        self.h = float(rod.l_bar.min())
        self.xtol = newton_tol * self.h
        self.halvings = 0
        self.inext = rod.inextensible
        self.set_dt(dt)
        F, _, self.power = model.forces(state, self.v, 1)
        self.F_load = self._load_force()
        self.F_damp_power = self.power
        a = self.accel(F)
        if self.inext:
            # the tension of the start state: the acceleration tangent to the constraint manifold (M-orthogonal
            # projection of M^-1 F); without it a0 would be free fall and the trapezoidal rule keeps that error
            from .solvers.projection import project_force

            w = np.where(self.system.fixed, 0.0, 1.0 / self.system.mass)
            f = np.where(self.system.fixed, 0.0, F)
            mu = np.zeros(rod.n_edges)
            if self.system.links.dep.size == 0 and project_force(state.q, rod.edge_nodes, rod.l_bar, w, rod.closed,
                                                                 f, mu):
                a = w * f
        self.a = a
        self.acc = a.copy()           # the true acceleration qdd (a is the pseudo-acceleration)

    def set_dt(self, dt):
        self.dt = dt
        if self.inext:
            rod = self.rod
            inertial = rod.rho_A * rod.l_bar / dt ** 2
            bending = max(float(np.max(rod.A1)), float(np.max(rod.A2))) / rod.l_bar ** 3
            k = DYNAMIC_PENALTY * np.maximum(inertial, bending)
            self.system.plan.k_stretch[:] = k
            self.state.penalty = k.copy()

    def step(self, t1, depth=0):
        """One step to t1; where Newton fails, the step is retried as two half steps (at most 2^5 pieces)."""
        saved = (self.state, self.v, self.a, self.acc, self.state.lam.copy(), self.work, self.dissipated, self.power,
                 self.F_load, getattr(self, "_reaction", None))
        ok, why = self._step(t1)
        if ok or depth >= MAX_HALVINGS or why[0] != "newton_failed":
            return ok, why
        (self.state, self.v, self.a, self.acc, lam, self.work, self.dissipated, self.power, self.F_load,
         self._reaction) = saved
        self.state.lam[:] = lam
        dt = self.dt
        t0 = t1 - dt
        self.set_dt(0.5 * dt)
        self.halvings += 1
        try:
            for t in (t0 + 0.5 * dt, t1):
                ok, why = self.step(t, depth + 1)
                if not ok:
                    return ok, why
        finally:
            self.set_dt(dt)
        return True, None

    def _step(self, t1):
        from .linalg import add_diagonal, band_solve
        from .solvers.system import constrain_system, expand, move_supports, residual_vector, transport
        from .energies.stretch import elongations

        model, sysm, rod, dt = self.model, self.system, self.rod, self.dt
        s0 = self.state
        v0, a0, acc0 = self.v, self.a, self.acc
        am, af, gam, bet = self.am, self.af, self.gamma, self.beta
        model.set_time(t1)
        q_pred = s0.q + dt * v0 + 0.25 * dt * dt * a0 * 2.0      # q0 + dt v0 + dt^2/2 a0
        q_pred[self.held] = s0.q[self.held]
        if sysm.links.dep.size:
            from .constraints import enforce_links

            enforce_links(q_pred, sysm.links)
        if sysm.terms:                              # contact: the predictor may not cross an obstacle either
            step = q_pred - s0.q
            a = min([1.0] + [t.max_step(s0, step) for t in sysm.terms])
            q_pred = s0.q + 0.5 * a * step
        trial = s0.copy()
        if model.supports_at is not None:
            # supports at t1: targets applied, links recomputed in place, frames transported from s0
            moved = move_supports(sysm, s0, q_pred, trial, model.constraints)
        else:
            moved = transport(sysm, s0, q_pred, trial)
        if not moved:
            return False, ("newton_failed", f"the predictor reversed an edge at t = {t1:g}; reduce dt")
        trial.penalty = s0.penalty
        # d qdd1 / d q1 = (1 - am) / ((1 - af) beta dt^2); d v1 / d q1 = gamma / (beta dt)
        dacc = (1.0 - am) / ((1.0 - af) * bet * dt * dt)
        dvel = gam / (bet * dt)
        mdiag = model.mass * dacc + model.c_diag * dvel
        if model.damping.rayleigh_stiffness:
            kfac = 1.0 + model.damping.rayleigh_stiffness * dvel
        else:
            kfac = 1.0
        work = np.empty_like(sysm.ab)
        fric = self._lagged_contact(s0) if getattr(self, "friction", 0.0) > 0 else None
        for update in range(MAX_MULTIPLIER_UPDATES + 1):
            converged = False
            cut = 0
            for it in range(MAX_NEWTON):
                v1, a1, acc1 = self._kinematics(trial.q - s0.q, v0, a0, acc0)
                F, _, power = model.forces(trial, v1, 2, dvel)
                if fric is not None:
                    add_friction(trial.q, s0.q, fric[0], fric[1], self.friction, fric[2], dt, F, sysm.ab,
                                 sysm.kl, sysm.ku, sysm.perm)
                R_full = F - model.mass * acc1
                sysm.fext[:] = R_full            # residual_vector reads fext - grad
                sysm.grad[:] = 0.0
                R = residual_vector(sysm)
                rnorm = float(R @ R)          # before the solve (which may overwrite R)
                work[:] = sysm.ab                # K, with the drag Jacobian already subtracted... see below
                if kfac != 1.0:
                    work *= kfac
                add_diagonal(work, sysm.kl, sysm.ku, sysm.perm, mdiag, 1.0)
                constrain_system(sysm, work, 1.0)
                coo = sysm.contact_coo if sysm.terms else None
                if coo:         # self-contact pairs couple DOFs off the band: the contact solve of der.solve
                    from .solvers.implicit import _contact_solve

                    delta, info = _contact_solve(sysm, work, coo, R)
                else:
                    delta, info = band_solve(work, sysm.kl, sysm.ku, sysm.perm, R, ldlt=getattr(sysm, "ldlt", None))
                self.newton += 1
                if info != 0 or not np.all(np.isfinite(delta)):
                    return False, ("newton_failed", f"singular or non-finite Newton system at t = {t1:g}")
                expand(sysm, delta)
                big = float(np.abs(delta.reshape(-1, 4)[:, :3]).max()) / self.h
                if big > 0.25:                      # a Newton correction of more than a quarter edge: damped
                    delta *= 0.25 / big
                a = 1.0
                if sysm.terms:                      # contact: no step through an obstacle (CCD)
                    a = min([1.0] + [t.max_step(trial, delta) for t in sysm.terms])
                    if not a > 0.0:
                        return False, ("newton_failed", f"no admissible step at the obstacle at t = {t1:g}")
                    delta *= a
                    cut = cut + 1 if a < 1.0 else 0
                    if cut >= 3:
                        # Newton keeps running into the obstacle: the barrier is too soft for the contact force
                        # (IPC's remedy: double its stiffness, up to kappa_max)
                        for term in sysm.terms:
                            if term.adaptive and term.kappa < term.kappa_max:
                                term.kappa = min(2.0 * term.kappa, term.kappa_max)
                                term.kappa_updates += 1
                        cut = 0
                if fric is not None and it > 0:
                    # friction's slip law bends sharply over the slip velocity: a full Newton correction can
                    # overshoot and cycle. Backtracking on the residual norm (at most 2^-10 of the correction)
                    delta = self._backtrack(s0, trial, delta, rnorm, fric, v0, a0, acc0)
                q_new = trial.q + delta
                if not transport(sysm, s0, q_new, trial):
                    return False, ("newton_failed", f"a Newton step reversed an edge at t = {t1:g}; reduce dt")
                d = delta.reshape(-1, 4)
                dx = float(np.abs(d[:, :3]).max())
                dth = float(np.abs(d[:, 3]).max())
                for term in sysm.terms:             # near the solution: the exact (unprojected) barrier Hessian
                    term.project = dx > 1e-4 * self.h
                # converged on a full Newton correction only: a step cut short by the CCD bound is small because
                # the obstacle stopped it, not because the residual vanished
                if a == 1.0 and dx <= self.xtol and dth <= self.newton_tol:
                    converged = True
                    break
            if not converged:
                return False, ("newton_failed", f"Newton did not converge in {MAX_NEWTON} iterations at t = {t1:g} "
                               f"(last correction {dx:.2e}); reduce dt")
            if not self.inext:
                break
            gap = elongations(trial.q, rod.edge_nodes, rod.l_bar)
            if float(np.max(np.abs(gap) / rod.l_bar)) <= self.strain_tol:
                break
            if update == MAX_MULTIPLIER_UPDATES:
                return False, ("newton_failed", f"the inextensibility multipliers did not converge at t = {t1:g}")
            s0.lam += sysm.plan.k_stretch * gap
            trial.lam[:] = s0.lam
            self.updates += 1
        # final quantities at q1
        dq = trial.q - s0.q
        v1, a1, acc1 = self._kinematics(dq, v0, a0, acc0)
        v1[self.held] = dq[self.held] / dt
        a1[self.held] = 0.0
        acc1[self.held] = 0.0
        F, _, power = model.forces(trial, v1, 1)
        F_load = self._load_force()
        if fric is not None:
            self.dissipated += add_friction(trial.q, s0.q, fric[0], fric[1], self.friction, fric[2], dt,
                                            np.zeros_like(F), np.zeros((0, 0)), sysm.kl, sysm.ku, sysm.perm)
        for term in sysm.terms:
            term.after_step(trial)              # IPC's adaptive barrier stiffness
        # work of the loads (trapezoidal) and of the supports (reaction power), damping dissipation
        self.work += 0.5 * float((self.F_load + F_load) @ dq)
        if self.held.any():
            # reactions on held DOFs: what balances M a + internal forces there
            reaction_new = model.mass * acc1 - F
            self.work += 0.5 * float(((self._reaction if getattr(self, "_reaction", None) is not None else reaction_new)
                                      + reaction_new)[self.held] @ dq[self.held])
            self._reaction = reaction_new
        self.dissipated += 0.5 * dt * (self.power + power)
        self.power = power
        self.F_load = F_load
        trial.lam[:] = s0.lam
        self.state = trial
        self.v, self.a, self.acc = v1, a1, acc1
        return True, None

    def _residual(self, s0, state, fric, v0, a0, acc0):
        """The step's residual (free DOFs) at ``state``, friction included (order 1: no Jacobian)."""
        from .solvers.system import residual_vector

        sysm, model = self.system, self.model
        v1, _, acc1 = self._kinematics(state.q - s0.q, v0, a0, acc0)
        F, _, _ = model.forces(state, v1, 1)
        add_friction(state.q, s0.q, fric[0], fric[1], self.friction, fric[2], self.dt, F, np.zeros((0, 0)),
                     sysm.kl, sysm.ku, sysm.perm)
        sysm.fext[:] = F - model.mass * acc1
        sysm.grad[:] = 0.0
        return residual_vector(sysm).copy()

    def _backtrack(self, s0, trial, delta, r0, fric, v0, a0, acc0):
        """The largest delta * 2^-k (k <= 10) whose residual norm is below that of ``trial`` (R); delta itself
        if none is (r0: the squared residual norm at ``trial``)."""
        from .solvers.system import transport

        step = delta
        for _ in range(11):
            cand = trial.copy()
            if transport(self.system, s0, trial.q + step, cand):
                Rc = self._residual(s0, cand, fric, v0, a0, acc0)
                if float(Rc @ Rc) < r0:
                    return step
            step = 0.5 * step
        return delta

    def _lagged_contact(self, state):
        """(normals (n_nodes, 3), normal forces (n_nodes,), eps_v): each node's barrier force at ``state``, the
        lagged normal force and direction of the friction law."""
        from .solvers.system import evaluate_system

        sysm, rod = self.system, self.rod
        g = np.zeros(rod.n_dof)
        evaluate_system(sysm, state, 1)                 # sets each term's active set at this state
        from .terms.obstacles import BoundObstacle

        for term in sysm.terms:
            if isinstance(term, BoundObstacle):     # friction at the obstacles; self-contact is frictionless
                term.evaluate(state, 1, g, sysm.ab, [])
        f = -g.reshape(-1, 4)[:, :3]
        N = np.linalg.norm(f, axis=1)
        normals = np.divide(f, N[:, None], out=np.zeros_like(f), where=N[:, None] > 0)
        N[self.system.fixed.reshape(-1, 4)[:, :3].all(axis=1)] = 0.0
        eps = self.slip_velocity if self.slip_velocity is not None else 1e-3 * float(rod.l_bar.mean()) / self.dt
        return np.ascontiguousarray(normals), N, eps

    def _kinematics(self, dq, v0, a0, acc0):
        """(v1, a1, qdd1) of the step dq = q1 - q0 (generalized-alpha update formulas)."""
        dt, am, af, gam, bet = self.dt, self.am, self.af, self.gamma, self.beta
        a1 = (dq - dt * v0 - dt * dt * (0.5 - bet) * a0) / (bet * dt * dt)
        v1 = v0 + dt * ((1.0 - gam) * a0 + gam * a1)
        acc1 = ((1.0 - am) * a1 + am * a0 - af * acc0) / (1.0 - af)
        return v1, a1, acc1


class _VerletRun(_Run):
    """Velocity Verlet with the inextensibility projection (RATTLE) for inextensible rods; damping forces use
    the half-step velocity."""

    def __init__(self, model, state, v0, dt, strain_tol):
        super().__init__(model, state, v0)
        rod = self.rod
        self.inext = rod.inextensible
        self.strain_tol = strain_tol
        sysm = self.system
        if self.inext and sysm.links.dep.size:
            raise ValueError("der.simulate: integrator='verlet' with an inextensible rod supports pins only "
                             "(der.pin): the projection cannot yet keep the end edge of a clamp, hinge or roller "
                             "on its support; use integrator='newmark' or give the rod EA")
        if self.inext:
            sysm.plan.k_stretch[:] = 0.0           # the tension is the projection's
            state.lam[:] = 0.0
        dt_stable = self.stable_dt()
        if dt is None:
            dt = 0.9 * dt_stable
        elif dt > dt_stable:
            raise ValueError(f"der.simulate: dt = {dt:.3g} exceeds the stable explicit step {dt_stable:.3g} "
                             "(2 / omega_max with this mass); use integrator='newmark' or a smaller dt")
        self.dt = dt
        self.contact_terms = self._self_contact_terms()
        for term in self.contact_terms:
            # a fixed potential (a stiffness raised during an impact would add energy): IPC's upper bound
            if term.adaptive:
                term.kappa = term.kappa_max
        self.contact_halvings = 0
        self.w = np.where(sysm.fixed, 0.0, 1.0 / sysm.mass)
        if self.inext:
            from .solvers.projection import project_velocity

            project_velocity(state.q, rod.edge_nodes, rod.l_bar, self.w, rod.closed, self.v)
        F, _, self.power = model.forces(state, self.v, 1)
        self.F_load = self._load_force()
        self.a = self.accel(F)

    def stable_dt(self):
        from .solvers.explicit import _gershgorin, _zero_fixed
        from .solvers.system import evaluate_system

        sysm = self.system
        evaluate_system(sysm, self.state, 2)
        ab = sysm.ab.copy()
        _zero_fixed(ab, sysm)
        m = sysm.mass.copy()
        bound = float(_gershgorin(ab, sysm.kl, sysm.ku, sysm.perm, m))
        self.omega2 = max(bound, 0.0)
        if bound <= 0:
            return math.inf
        return 2.0 / math.sqrt(bound)

    def _self_contact_terms(self):
        from .terms.obstacles import BoundObstacle

        return [t for t in self.system.terms if not isinstance(t, BoundObstacle)]

    def _barrier_omega2(self):
        """A Gershgorin bound of omega^2 of the self-contact barrier at the current state: max_i sum_j |H_ij| /
        sqrt(m_i m_j) over the free DOFs of the (PSD-projected, so larger in the Loewner order) barrier Hessian H
        of the active pairs; 0 when no pair is within dhat."""
        terms = self.contact_terms
        if not any(t.n_active for t in terms):
            return 0.0
        coo = []
        g = np.zeros(self.rod.n_dof)
        for t in terms:
            t.project = True
            t.evaluate(self.state, 2, g, None, coo)
        if not coo:
            return 0.0
        rows = np.concatenate([c[0] for c in coo])
        cols = np.concatenate([c[1] for c in coo])
        vals = np.concatenate([c[2] for c in coo])
        m = self.model.mass
        free = ~self.held
        keep = free[rows] & free[cols] & (m[rows] > 0) & (m[cols] > 0)
        rows, cols, vals = rows[keep], cols[keep], vals[keep]
        if rows.size == 0:
            return 0.0
        s = np.zeros(self.rod.n_dof)
        np.add.at(s, rows, np.abs(vals) / np.sqrt(m[rows] * m[cols]))
        return float(s.max())

    def step(self, t1):
        """One step to t1. With self-contact (module docs): the step is split into halves (at most
        MAX_CONTACT_HALVINGS deep) until each piece is below the stable step of the elastic plus barrier stiffness
        at its start and its position update is proven non-crossing by CCD."""
        if not self.contact_terms:
            return self._step(t1)
        return self._contact_step(t1, 0)

    def _contact_step(self, t1, depth):
        dt = self.dt
        t0 = t1 - dt
        why = None
        omega2 = self.omega2 + self._barrier_omega2()
        if omega2 > 0 and dt > CONTACT_STEP_FRACTION * 2.0 / math.sqrt(omega2):
            why = "stiff"
        else:
            saved = (self.state, self.v, self.a, self.work, self.dissipated, self.power, self.F_load)
            ok, why = self._step(t1)
            if ok:
                # the barrier stiffens as the gap closes: the step must be stable at its end as well
                omega2 = self.omega2 + self._barrier_omega2()
                if not (omega2 > 0 and dt > CONTACT_STEP_FRACTION * 2.0 / math.sqrt(omega2)):
                    return True, None
                (self.state, self.v, self.a, self.work, self.dissipated, self.power, self.F_load) = saved
                why = "stiff"
            elif why[0] != "ccd":
                return ok, why
        if depth >= MAX_CONTACT_HALVINGS:
            if why == "stiff":
                d = self.contact_terms[0].diagnostics(self.state)
                return False, ("contact_failed", f"velocity Verlet: the self-contact barrier's stable step is below "
                               f"dt / 2^{MAX_CONTACT_HALVINGS} = {dt:.3g} at t = {t0:g} (closest pair: edges "
                               f"{d['min_distance_edges']}, centrelines {d['min_distance']:.6g} apart); reduce dt "
                               "or use integrator='newmark'")
            return False, ("contact_failed", f"velocity Verlet: no step of dt / 2^{MAX_CONTACT_HALVINGS} = {dt:.3g} "
                           f"from t = {t0:g} is proven free of crossing by CCD ({why[1]}); reduce dt or use "
                           "integrator='newmark'")
        self.contact_halvings += 1
        self.set_dt(0.5 * dt)
        try:
            for t in (t0 + 0.5 * dt, t1):
                ok, why2 = self._contact_step(t, depth + 1)
                if not ok:
                    return ok, why2
        finally:
            self.set_dt(dt)
        return True, None

    def _step(self, t1):
        from .solvers.projection import project_positions, project_velocity
        from .solvers.system import move_supports, transport
        from .constraints import enforce_links

        model, sysm, rod, dt = self.model, self.system, self.rod, self.dt
        s0 = self.state
        v_half = self.v + 0.5 * dt * self.a
        model.set_time(t1)
        q1 = s0.q + dt * v_half
        if model.supports_at is not None:
            tmp = s0.copy()
            if not move_supports(sysm, s0, q1, tmp, model.constraints):
                return False, ("nonfinite", f"an edge reversed at t = {t1:g}; reduce dt")
            q1[self.held] = tmp.q[self.held]
        if self.inext:
            for _ in range(3):
                worst = project_positions(q1, rod.edge_nodes, rod.l_bar, self.w, rod.closed, 50, self.strain_tol)
                if sysm.links.dep.size == 0:
                    break
                enforce_links(q1, sysm.links)
            if not np.isfinite(worst):
                return False, ("nonfinite", f"an edge vanished at t = {t1:g}")
        elif sysm.links.dep.size:
            enforce_links(q1, sysm.links)
        v_half = (q1 - s0.q) / dt
        for term in self.contact_terms:         # no passage: the straight path q0 -> q1 proven safe by CCD
            if term.max_step(s0, q1 - s0.q) < 1.0:
                pair = getattr(term, "ccd_pair", None)
                return False, ("ccd", f"edges {pair} at t = {t1 - dt:g}" if pair else f"at t = {t1 - dt:g}")
        trial = s0.copy()
        if not transport(sysm, s0, q1, trial):
            return False, ("nonfinite", f"an edge reversed at t = {t1:g}; reduce dt")
        F, _, power = model.forces(trial, v_half, 1)
        a1 = self.accel(F)
        v1 = v_half + 0.5 * dt * a1
        v1[self.held] = v_half[self.held]
        if self.inext:
            project_velocity(trial.q, rod.edge_nodes, rod.l_bar, self.w, rod.closed, v1)
        dq = q1 - s0.q
        F_load = self._load_force()
        self.work += 0.5 * float((self.F_load + F_load) @ dq)
        self.dissipated += 0.5 * dt * (self.power + power)
        self.power, self.F_load = power, F_load
        self.state, self.v, self.a = trial, v1, a1
        self.newton += 0
        return True, None


def natural_frequencies(scene, count=3, state=None, rho_J=None):
    """The lowest ``count`` angular frequencies (rad / time) of small vibrations about ``state`` (default: the
    rest state), with the mass ``simulate`` uses: the generalized eigenproblem K phi = omega^2 M phi on the
    DOFs the supports leave free (dense: for rods of up to a few hundred edges). Returns (omegas, modes), modes
    as (count, n_dof) arrays (expanded to all DOFs, mass-normalised).

    An inextensible rod's stretching enters with the static solvers' augmented-Lagrangian penalty, so its
    axial modes are spurious; its bending and twisting modes are those of the inextensible rod to within
    (omega^2 rho_A / penalty). Rigid-body modes of an unsupported rod come out as omega ~ 0.

    Example
    -------
    >>> import der
    >>> rod = der.rod_from_shape(der.shapes.straight(1.0, 40), A1=1.0, A2=1.0, EA=1e4, rho_A=1.0, rho_J=1e-4)
    >>> w, _ = der.dynamics.natural_frequencies(der.Scene(rod, constraints=[der.clamp("start")]), 1)
    >>> round(float(w[0]) / 1.8751 ** 2, 3)       # Euler-Bernoulli: (beta L)^2 sqrt(A1 / (rho_A L^4))
    1.0
    """
    import scipy.linalg

    from .linalg import band_to_coo
    from .solvers import SolverOptions, _compile_first
    from .solvers.system import build_system, condense_system_band, evaluate_system, prepare_state, update_links

    rod = scene.rod
    count = validate.integer(count, "der.dynamics.natural_frequencies: count", "an integer >= 1")
    if count < 1:
        raise ValueError(f"der.dynamics.natural_frequencies: count must be >= 1; got {count}")
    _compile_first()
    system = build_system(scene, SolverOptions())
    mass = lumped_mass(rod, rho_J)
    system.mass_full = mass.copy()
    work = prepare_state(system, rod.rest_state() if state is None else state)
    update_links(system, work)
    evaluate_system(system, work, 2)
    ab = system.ab.copy()
    condense_system_band(system, ab)
    r, c, v = band_to_coo(ab, system.kl, system.ku, system.perm)
    n = rod.n_dof
    K = np.zeros((n, n))
    np.add.at(K, (r, c), v)
    K = 0.5 * (K + K.T)
    free = np.flatnonzero(~system.fixed)
    if count > free.size:
        raise ValueError(f"der.dynamics.natural_frequencies: count {count} exceeds the {free.size} free DOFs")
    Kf = K[np.ix_(free, free)]
    Mf = system.mass[free]
    w2, vec = scipy.linalg.eigh(Kf, np.diag(Mf), subset_by_index=[0, count - 1])
    modes = np.zeros((count, n))
    modes[:, free] = vec.T
    from .solvers.system import expand

    for m in modes:
        expand(system, m)
    return np.sqrt(np.maximum(w2, 0.0)), modes
