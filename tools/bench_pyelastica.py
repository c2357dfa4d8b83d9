"""der against PyElastica: time to static equilibrium and the error reached, on the same problems.

    python tools/bench_pyelastica.py [--json] [--repeat 3] [--n 50 100 200] [--quick] [--cap 300]

Problems (A1 = 1, A2 = 1/0.67 throughout; both codes clamp at xi = 0 and load the end cross-section at xi = L):
  straight_twist  straight rod, L = 1, dead end torque T = 0.5 about its axis; error of the end rotation vector
                  against the closed form T L / A2 (both discretisations are exact here: the error is that of the
                  stopping test);
  ring_torsion    arc of radius 1, length 3, dead end torque 1e-3 t0(L); error of the end rotation vector
                  against der.closed_forms.ring_end_rotation (linear in T; the O(T) floor is ~6e-6);
  helix_force     3-turn helix, kappa0 = 1, omega0 = 0.6, dead end force 1e-3 e3 (along the axis); error of the
                  end displacement against der's own answer at n = 1600 and 3200, Richardson-extrapolated (its
                  estimated error is printed; ~1e-5).
Errors are |q - q_ref| / |q_ref| for the 3-vector q (rotation components in the rest end frame (t0, m1, m2);
displacement in the lab frame).

Fairness choices
* Same geometry, same material points. PyElastica gets der's nodes and rest frames (positions=, directors= of
  CosseratRod.straight_rod), so its n elements are der's n edges and the centres of its end elements are der's
  rod ends (der puts the end cross-sections at the midpoints of the end edges). PyElastica's clamp is element 0:
  FixedConstraint on nodes 0 and 1 and on the directors of element 0 (OneEndFixedBC fixes node 0 only; the
  centre of element 0 would then move with the shear of element 0). The end torque acts on the last element
  (external_torques are in the element frame: Q T), the end force as F/2 on each of the last two nodes (the
  element centre, as der's end_force). The end rotation is that of the last element's directors, the end
  position the centre of the last element. (With PyElastica's "natural" geometry -- nodes 0..n spanning
  [0, L], OneEndFixedBC -- the clamped frame sits at h/2 and the loaded one at L - h/2: the twist comes out as
  T (L - h) / A2, an error of exactly 1/n, e.g. 2 % at n = 50; measured.)
* Stiffness. PyElastica's own constructor with radius r = L/50, density 1, E = A1/I and G = A2/(2I), I = pi r^4/4,
  so that its bend_matrix is exactly diag(A1, A1, A2) (voronoi-averaged, uniform). Rest curvature and strain
  are PyElastica's own kappa and sigma of the initial shape (rest_kappa, rest_sigma), so the rest state is
  force-free in its own discretisation, as der's is in der's. PyElastica is shearable and extensible: its
  shear_matrix (alpha_c G A, alpha_c G A, E A) is multiplied by ``shear``: 1 for the torque problems, whose
  exact solution carries no force; 100 for the helix, where the extension F L / EA alone moves the end (with
  shear = 10 the answer moved by 1.1e-3 |q_ref| at every n, 12 % of PyElastica's error at n = 200, for a 3.2x
  longer time step). The column "10x" is the measured change of the answer, |q(shear) - q(10 shear)| / |q_ref|,
  when that stiffness is raised 10x: it must be well below the error. r only sets the inertia (r >= h keeps the
  rotational modes from limiting the time step) and, with shear = 1, the physical EA = 4 A1 / r^2.
* Time step. PositionVerlet (PyElastica's default). For each problem and n the largest stable dt is found by
  trying (doubling, then 5 bisections to 2 %; stable = 2000 steps from rest under the load stay finite and
  slow); runs use 0.9 of it. A run that blows up anyway is retried at half the step.
* Damping: elastica.AnalyticalLinearDamper(uniform_damping_constant=gamma, time_step=dt) (all velocities decay
  at rate gamma); gamma per problem was tuned by scanning at n = 50 (steps to the stopping test; near critical
  damping of the slowest mode): straight_twist 7000 (2500, 3500, 5000, 10000: 2.6x, 1.7x, 1.2x, 2.0x the
  steps), ring_torsion 8 (4, 6, 10, 13: 1.7x, 1.2x, 1.06x, 1.6x), helix_force 0.08 (0.05, 0.065, 0.1, 0.13:
  1.6x, 1.2x, 1.02x, 1.6x). The slowest mode does not depend on n (same rod: r is fixed).
* Stopping test (checked every ~W/(10 dt) steps): the end quantity changed by less than 1e-7 of its size over
  the last window W = 4/gamma of simulated time, and the largest nodal speed (|v| and |omega|) has fallen
  below 1e-5 of its peak during the run (it floors at ~1e-6 of the peak from round-off at n = 200). Both are far
  below the errors compared, except in straight_twist, where both codes' errors are those of their stopping
  tests. A run stops "not converged" after ``--cap`` seconds.
* der: der.solve(scene) (implicit, default tol 1e-8), stability analysis off; time = result.wall_time. PyElastica:
  time of the stepping loop with its checks. Setup (building the rod and the system: 1-9 ms for either code
  here) is excluded for both, as are the dt search and the shear check. JIT: a warm-up run of every problem
  with both codes comes first (numba cache loads or compiles) and is reported apart. Median of --repeat runs,
  same process, one thread of work at a time.

Result on a 2-core AMD EPYC (PyElastica 1.0.0, n = 50/100/200): PyElastica takes 40-190x der's time on
straight_twist (a 1-D wave problem: 665-2511 steps), 1200-2000x on ring_torsion and 7500-11800x on helix_force;
its error is 0.8x der's on the ring and 2.9x der's on the helix (both second order, same limit).
"""
import argparse
import importlib.metadata
import json
import os
import platform
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import der  # noqa: E402
from der import closed_forms as cf  # noqa: E402
from der import diagnostics as dg  # noqa: E402

try:
    import elastica as ea
    from elastica.external_forces import NoForces
except ImportError:
    sys.exit("bench_pyelastica.py: needs PyElastica, which der does not depend on: pip install -e '.[bench]'")

A1, A2 = 1.0, 1.0 / 0.67
# per problem: PyElastica damping gamma, shear/stretch factor, load
PROBLEMS = {
    "straight_twist": {"gamma": 7000.0, "shear": 1.0},
    "ring_torsion": {"gamma": 8.0, "shear": 1.0},
    "helix_force": {"gamma": 0.08, "shear": 100.0},
}
TOL_Q, TOL_RATE = 1e-7, 1e-5
HELIX = {"kappa0": 1.0, "omega0": 0.6, "turns": 3.0, "F": 1e-3}


class Problem:
    """A der rod with its end load (lab frame), the quantity compared ('rot' or 'disp') and its reference."""

    def __init__(self, name, n):
        self.name, self.n = name, n
        self.force, self.torque = np.zeros(3), np.zeros(3)
        if name == "straight_twist":
            shape, T = der.shapes.straight(1.0, n, axis=(0, 0, 1)), 0.5
            self.torque, self.kind = np.array([0.0, 0.0, T]), "rot"
            self.ref = np.array([T * 1.0 / A2, 0.0, 0.0])
        elif name == "ring_torsion":
            shape, T = der.shapes.arc(1.0, 3.0, n), 1e-3
            self.torque, self.kind = T * cf.ring_end_basis(1.0, 3.0)[0], "rot"
            self.ref = cf.ring_end_rotation(A1, A2, 1.0, 3.0, T)
        else:
            h = HELIX
            shape = der.shapes.helix(h["kappa0"], h["omega0"], h["turns"], n)
            self.force, self.kind, self.ref = np.array([0.0, 0.0, h["F"]]), "disp", None
        self.rod = der.rod_from_shape(shape, A1, A2)

    def scene(self):
        loads = []
        if self.torque.any():
            loads.append(der.end_torque(self.torque))
        if self.force.any():
            loads.append(der.end_force(self.force))
        return der.Scene(self.rod, loads=loads, constraints=[der.clamp("start")])

    def der_quantity(self, state):
        if self.kind == "rot":
            return dg.end_motion(self.rod, state)[1]
        return dg.end_frame(self.rod, state)[0] - dg.end_frame(self.rod, self.rod.rest_state())[0]

    def error(self, q):
        return float(np.linalg.norm(q - self.ref) / np.linalg.norm(self.ref))


def helix_reference():
    """der's converged end displacement (n = 1600, 3200; Richardson) and its estimated relative error."""
    d = {}
    for n in (1600, 3200):
        p = Problem("helix_force", n)
        d[n] = p.der_quantity(der.solve(p.scene(), stability=False).state)
    ref = d[3200] + (d[3200] - d[1600]) / 3.0
    return ref, float(np.linalg.norm(d[3200] - d[1600]) / 3.0 / np.linalg.norm(ref))


def der_run(p):
    res = der.solve(p.scene(), stability=False, raise_on_failure=False)
    return {"time": res.wall_time, "q": p.der_quantity(res.state), "converged": bool(res.converged),
            "iterations": res.iterations}


# ------------------------------------------------------------------------------------------------------------
# PyElastica
# ------------------------------------------------------------------------------------------------------------


class EndLoad(NoForces):
    """Dead end force (lab) at the centre of the last element and dead end torque (lab) on the last element."""

    def __init__(self, force, torque):
        super().__init__()
        self.force, self.torque = np.asarray(force, float), np.asarray(torque, float)

    def apply_forces(self, system, time=0.0):
        system.external_forces[:, -2:] += 0.5 * self.force[:, None]

    def apply_torques(self, system, time=0.0):
        system.external_torques[:, -1] += system.director_collection[:, :, -1] @ self.torque


class Sim(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
    pass


def pe_build(p, dt, gamma, shear):
    """PyElastica rod on der's nodes and rest frames; returns (simulator, rod, rest end frame, rest end point)."""
    x = p.rod.rest_q.reshape(-1, 4)[:, :3].T.copy()
    e = np.diff(x, axis=1)
    t = e / np.linalg.norm(e, axis=0)
    d1 = p.rod.rest_d1.T.copy()
    Q = np.stack([d1, np.cross(t.T, d1.T).T, t])                 # rows d1, d2, d3 = (m1, m2, t) per element
    r = p.rod.length / 50.0
    inertia = np.pi * r ** 4 / 4.0
    rod = ea.CosseratRod.straight_rod(p.n, x[:, 0], t[:, 0], d1[:, 0], float(np.linalg.norm(e, axis=0).sum()), r,
                                      1.0, youngs_modulus=A1 / inertia, shear_modulus=A2 / (2.0 * inertia),
                                      position=x, directors=Q)
    rod.rest_kappa[:] = rod.kappa
    rod.rest_sigma[:] = rod.sigma
    rod.shear_matrix *= shear
    sim = Sim()
    sim.append(rod)
    sim.constrain(rod).using(ea.FixedConstraint, constrained_position_idx=(0, 1), constrained_director_idx=(0,))
    sim.add_forcing_to(rod).using(EndLoad, force=p.force, torque=p.torque)
    sim.dampen(rod).using(ea.AnalyticalLinearDamper, uniform_damping_constant=gamma, time_step=dt)
    sim.finalize()
    return sim, rod, np.array([Q[2, :, -1], Q[0, :, -1], Q[1, :, -1]]), 0.5 * (x[:, -1] + x[:, -2])


def pe_quantity(p, rod, F0, x0):
    if p.kind == "disp":
        return 0.5 * (rod.position_collection[:, -1] + rod.position_collection[:, -2]) - x0
    Q = rod.director_collection[:, :, -1]
    F = np.array([Q[2], Q[0], Q[1]])                             # rows t, m1, m2 as der's end_frame
    return F0 @ dg.rotation_vector(F.T @ F0)


def pe_relax(p, dt, gamma, shear, cap):
    """Damped PositionVerlet from rest to the stopping test; timed loop only."""
    sim, rod, F0, x0 = pe_build(p, dt, gamma, shear)
    stepper = ea.PositionVerlet()
    W = 4.0 / gamma
    every = max(1, min(200, int(W / dt / 10)))
    hist, peak, t, steps, status = [], 0.0, 0.0, 0, "not converged (cap)"
    t0 = time.perf_counter()
    while True:
        for _ in range(every):
            t = stepper.step(sim, t, dt)
        steps += every
        q = pe_quantity(p, rod, F0, x0)
        rate = max(np.abs(rod.velocity_collection).max(), np.abs(rod.omega_collection).max())
        if not (np.isfinite(q).all() and np.isfinite(rate)):
            status = "nonfinite"
            break
        peak = max(peak, rate)
        hist.append((t, q))
        while len(hist) > 1 and hist[1][0] <= t - W:
            hist.pop(0)
        size = np.linalg.norm(q)
        if (hist[0][0] <= t - W * (1 - 1e-9) and np.linalg.norm(q - hist[0][1]) <= TOL_Q * size
                and rate <= TOL_RATE * peak):
            status = "converged"
            break
        if time.perf_counter() - t0 > cap:
            break
    wall = time.perf_counter() - t0
    return {"time": wall, "q": q, "converged": status == "converged", "status": status, "steps": steps, "t_sim": t}


def pe_stable(p, dt, gamma, shear, steps=2000):
    sim, rod, _, _ = pe_build(p, dt, gamma, shear)
    stepper, t = ea.PositionVerlet(), 0.0
    for _ in range(steps):
        t = stepper.step(sim, t, dt)
    v, w = np.abs(rod.velocity_collection).max(), np.abs(rod.omega_collection).max()
    return bool(np.isfinite(v) and np.isfinite(w) and v * dt < 0.01 * p.rod.l_bar.mean() and w * dt < 0.01)


def pe_largest_dt(p, gamma, shear, dt=1e-3, bisections=5):
    """Largest stable time step, by trying: double/halve to bracket, then bisect (geometric) 5 times."""
    if pe_stable(p, dt, gamma, shear):
        while pe_stable(p, 2 * dt, gamma, shear):
            dt *= 2
    else:
        while not pe_stable(p, dt, gamma, shear):
            dt /= 2
    lo, hi = dt, 2 * dt
    for _ in range(bisections):
        mid = np.sqrt(lo * hi)
        lo, hi = (mid, hi) if pe_stable(p, mid, gamma, shear) else (lo, mid)
    return lo


# ------------------------------------------------------------------------------------------------------------
# the benchmark
# ------------------------------------------------------------------------------------------------------------


def warmup():
    """Compile or load every kernel of both codes; returns (der seconds, PyElastica seconds)."""
    t0 = time.perf_counter()
    der.warmup()
    for name in PROBLEMS:
        der_run(Problem(name, 8))
    t1 = time.perf_counter()
    for name, cfg in PROBLEMS.items():
        p = Problem(name, 8)
        sim, rod, F0, x0 = pe_build(p, 1e-6, cfg["gamma"], cfg["shear"])
        stepper, t = ea.PositionVerlet(), 0.0
        for _ in range(20):
            t = stepper.step(sim, t, 1e-6)
        pe_quantity(p, rod, F0, x0)
    return t1 - t0, time.perf_counter() - t1


def bench(name, n, repeat, cap, ref=None, log=print):
    cfg = PROBLEMS[name]
    p = Problem(name, n)
    if ref is not None:
        p.ref = ref
    gamma, shear = cfg["gamma"], cfg["shear"]
    ds = [der_run(p) for _ in range(repeat)]
    t0 = time.perf_counter()
    dt_max = pe_largest_dt(p, gamma, shear)
    search = time.perf_counter() - t0
    dt = 0.9 * dt_max
    runs = []
    for _ in range(repeat):
        r = pe_relax(p, dt, gamma, shear, cap)
        while r["status"] == "nonfinite" and dt > dt_max / 64:
            dt /= 2
            log(f"  {name} n={n}: PyElastica blew up, retrying at dt = {dt:.3g}")
            r = pe_relax(p, dt, gamma, shear, cap)
        runs.append(r)
        if not r["converged"]:
            break                                   # one capped run is enough to know
    pe = runs[-1]
    # the shear/stretch check: the same run with 10x the shear and stretch stiffness (its own stable step)
    dt10 = 0.9 * pe_largest_dt(p, gamma, 10 * shear)
    r10 = pe_relax(p, dt10, gamma, 10 * shear, cap)
    effect = float(np.linalg.norm(pe["q"] - r10["q"]) / np.linalg.norm(p.ref)) if r10["converged"] else None
    d_time = statistics.median(d["time"] for d in ds)
    pe_time = statistics.median(r["time"] for r in runs) if all(r["converged"] for r in runs) else None
    row = {
        "problem": name, "n": n,
        "der_time_s": d_time, "der_error": p.error(ds[-1]["q"]), "der_converged": all(d["converged"] for d in ds),
        "der_iterations": ds[-1]["iterations"],
        "pe_time_s": pe_time, "pe_error": p.error(pe["q"]), "pe_status": pe["status"], "pe_steps": pe["steps"],
        "pe_sim_time": pe["t_sim"], "pe_dt_max": dt_max, "pe_dt": dt, "pe_dt_search_s": search,
        "pe_gamma": gamma, "pe_shear_factor": shear, "pe_shear_10x_change": effect, "pe_dt_10x": dt10,
        "ratio": pe_time / d_time if pe_time is not None else None,
        "der_times_s": [d["time"] for d in ds], "pe_times_s": [r["time"] for r in runs],
    }
    log(f"  {name} n={n}: der {d_time:.3g} s, err {row['der_error']:.2e}; PyElastica {row['pe_status']} "
        f"{_fmt_t(pe_time)}, err {row['pe_error']:.2e}, dt {dt:.3g}, {pe['steps']} steps; 10x shear: {_fmt_e(effect)}")
    return row


def _fmt_t(t):
    return "n/c" if t is None else (f"{t * 1e3:.3g} ms" if t < 1 else f"{t:.3g} s")


def _fmt_e(e):
    return "n/c" if e is None else f"{e:.1e}"


def machine():
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "machine": platform.machine(), "python": platform.python_version(),
            "numba": importlib.metadata.version("numba"), "numpy": np.__version__}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object as the last line")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per code (median reported)")
    ap.add_argument("--n", type=int, nargs="+", default=[50, 100, 200], help="edges (= PyElastica elements)")
    ap.add_argument("--quick", action="store_true", help="smoke test: n = 50, problems 1-2, one run")
    ap.add_argument("--cap", type=float, default=300.0, help="wall-clock cap per PyElastica run [s]")
    args = ap.parse_args(argv)
    names = list(PROBLEMS)
    if args.quick:
        args.n, args.repeat, names = [50], 1, names[:2]
    if args.repeat < 1 or min(args.n) < 4:
        ap.error("--repeat must be >= 1 and every --n >= 4")
    log = (lambda s: print(s, file=sys.stderr, flush=True)) if args.json else (lambda s: print(s, flush=True))
    info = {"pyelastica": importlib.metadata.version("pyelastica"), "der": importlib.metadata.version("der"),
            "machine": machine()}
    log(f"PyElastica {info['pyelastica']}, der {info['der']}; {info['machine']['cpu']}, {info['machine']['cores']} "
        f"cores, Python {info['machine']['python']}, numba {info['machine']['numba']}")
    der_warm, pe_warm = warmup()
    log(f"warm-up (JIT compile or cache load, excluded from the timings): der {der_warm:.2f} s, "
        f"PyElastica {pe_warm:.2f} s")
    ref = None
    if "helix_force" in names:
        t0 = time.perf_counter()
        ref, ref_err = helix_reference()
        info["helix_reference"] = {"displacement": ref.tolist(), "estimated_error": ref_err,
                                   "seconds": time.perf_counter() - t0}
        log(f"helix reference (der, n = 1600 and 3200, Richardson): {np.array2string(ref, precision=6)}, "
            f"estimated error {ref_err:.1e}")
    rows = [bench(name, n, args.repeat, args.cap, ref if name == "helix_force" else None, log)
            for name in names for n in args.n]
    print()
    print(f"median of {args.repeat}; errors |q - q_ref|/|q_ref|; ratio = PyElastica time / der time; "
          f"10x = change of PyElastica's answer when its shear/stretch stiffness is raised 10x (relative to |q_ref|)")
    head = ("problem", "n", "der time", "der error", "PyEl. time", "PyEl. error", "ratio", "PyEl. dt (max)",
            "steps", "10x")
    lines = [head] + [(r["problem"], str(r["n"]), _fmt_t(r["der_time_s"]), f"{r['der_error']:.1e}",
                       _fmt_t(r["pe_time_s"]), f"{r['pe_error']:.1e}",
                       "n/c" if r["ratio"] is None else f"{r['ratio']:.3g}",
                       f"{r['pe_dt']:.2e} ({r['pe_dt_max']:.2e})", str(r["pe_steps"]),
                       _fmt_e(r["pe_shear_10x_change"])) for r in rows]
    widths = [max(len(l[i]) for l in lines) for i in range(len(head))]
    for k, line in enumerate(lines):
        print("| " + " | ".join(c.ljust(w) for c, w in zip(line, widths)) + " |")
        if k == 0:
            print("|" + "|".join("-" * (w + 2) for w in widths) + "|")
    gammas = ", ".join(f"{k} {v['gamma']:g}" for k, v in PROBLEMS.items())
    shears = ", ".join(f"{k} {v['shear']:g}" for k, v in PROBLEMS.items())
    print(f"PyElastica: PositionVerlet at 0.9 x the largest stable dt; AnalyticalLinearDamper, uniform_damping_constant"
          f" {gammas}; radius L/50, shear factor {shears}; stop: change < {TOL_Q:g} over 4/gamma and speeds < "
          f"{TOL_RATE:g} of peak. der: implicit, tol 1e-8.")
    if args.json:
        print(json.dumps({"tool": "bench_pyelastica", **info, "repeat": args.repeat, "n": args.n,
                          "warmup_s": {"der": der_warm, "pyelastica": pe_warm}, "tol_q": TOL_Q, "tol_rate": TOL_RATE,
                          "problems": PROBLEMS, "rows": rows}))
    return 0 if all(r["pe_time_s"] is not None and r["der_converged"] for r in rows) else 3


if __name__ == "__main__":
    sys.exit(main())
