"""Capstan: a rope over a fixed cylinder, loaded at both ends, holds below and slips above T2/T1 = exp(mu theta).

The rope (no gravity, radius r, extensible) lies over a rigid cylinder of radius R through a wrap angle theta; its
light end is pulled with T1 along its leg, its heavy end with T2 = ratio * T1 * exp(mu theta). Start: the
frictionless contact equilibrium under T1 at both ends (der.solve, one node pinned and one angle held against the
free slide and spin; their reactions vanish at equilibrium), so the run starts with the right contact forces. Then
der.simulate (Newmark, lagged smoothed Coulomb friction mu) while T2 is ramped from T1 to its value over
``ramp`` and held; light viscous damping removes the ramp's transient. Measured: how far the light end moved
(``slide``) and its speed at the end (``speed``). Holding: the speed stays at the creep of the smoothed friction
(below the slip velocity); slipping: the rope accelerates towards the heavy side.

    python tools/capstan.py --json                  # ratios 0.8 and 1.25 at theta = pi/2 and pi
    python tools/capstan.py --ratios 0.5 0.8 0.95 1.05 1.25 --angles 1.5708 3.1416 --json
"""
import argparse
import json
import math
import sys
import time

import numpy as np

import der

MU = 0.3


def draped_rope(theta, R=1.0, r=0.02, h=0.1, leg=0.6, A1=1e-4, EA=1e3, rho_A=1.0):
    """(rod, start positions (n_nodes, 3), wrap angle, unit tangents of the two legs pointing away from the cylinder).

    The cylinder's axis is y through the origin; the rope comes up on the -x side, lies over the top through an angle
    theta (rounded to whole edges of length h on the polygon that circumscribes the circle of radius R + r +
    dhat/2) and leaves along the tangent there."""
    dhat = 0.1 * r
    Rw = R + r + 0.5 * dhat
    dphi = 2.0 * math.atan(h / (2.0 * Rw))
    n_arc = max(1, int(round(theta / dphi)))
    theta = n_arc * dphi
    bulge = Rw / math.cos(0.5 * dphi)
    n_leg = max(2, int(round(leg / h)))
    up = np.array([0.0, 0.0, 1.0])
    pts = [np.array([-Rw, 0.0, 0.0]) - (k - 0.5) * h * up for k in range(n_leg, 0, -1)]
    pts += [np.array([-bulge * math.cos((k + 0.5) * dphi), 0.0, bulge * math.sin((k + 0.5) * dphi)])
            for k in range(n_arc)]
    end = np.array([-Rw * math.cos(theta), 0.0, Rw * math.sin(theta)])
    t_end = np.array([math.sin(theta), 0.0, math.cos(theta)])
    pts += [end + (k - 0.5) * h * t_end for k in range(1, n_leg + 1)]
    pts = np.array(pts)
    n = len(pts) - 1
    rod = der.rod_from_shape(der.shapes.straight(n * h, n, axis=(0, 0, 1), director=(0, 1, 0)), A1=A1, A2=A1,
                             EA=EA, rho_A=rho_A, rho_J=1e-5)
    return rod, pts, theta, -up, t_end


def run(theta, ratio, mu=MU, t_end=1.0, dt=2e-3, ramp=0.2, damping=5.0, slip_velocity=1e-3, T1=1.0, rho_inf=0.5,
        **rope):
    """One capstan run: a dict with the wrap angle, T2/T1, the capstan ratio exp(mu theta), the light end's slide
    and final speed, the verdict ("holds" if the final speed is below the slip velocity), steps and CPU time."""
    rod, pts, theta, t_light, t_heavy = draped_rope(theta, **rope)
    r = rope.get("r", 0.02)
    R = rope.get("R", 1.0)
    cyl = der.cylinder([0, 0, 0], [0, 1, 0], R, radius=r)
    start = rod.displaced(rod.rest_state(), pts - rod.rest_state().positions)
    mid = rod.n_nodes // 2
    c0 = time.process_time()
    settle = der.solve(der.Scene(rod, loads=[der.end_force(T1 * t_light, "start"), der.end_force(T1 * t_heavy, "end")],
                                 constraints=[der.pin(mid), der.fix_theta(mid)], contacts=[cyl]),
                       state=start, raise_on_failure=False)
    if not settle.converged:
        raise RuntimeError(f"capstan: the draped start did not converge: {settle.status}: {settle.message}")
    T2 = ratio * T1 * math.exp(mu * theta)

    def loads(t):
        s = min(t / ramp, 1.0) if ramp > 0 else 1.0
        s = s * s * (3.0 - 2.0 * s)            # smooth ramp
        return [der.end_force(T1 * t_light, "start"), der.end_force((T1 + s * (T2 - T1)) * t_heavy, "end")]

    scene = der.Scene(rod, loads=loads(0.0), contacts=[cyl])
    traj = der.simulate(scene, t_end, dt=dt, state=settle.state, loads=loads, friction=mu,
                        slip_velocity=slip_velocity, damping=der.Damping(translational=damping) if damping else None,
                        rho_inf=rho_inf, save_every=5, progress=False)
    cpu = time.process_time() - c0
    x = traj.positions[:, 0, :]
    slide = float((x[-1] - x[0]) @ (-t_light))          # the light end moving up = towards the heavy side
    late = int(np.searchsorted(traj.times, traj.times[-1] - 0.2 * t_end))
    speed = float((x[-1] - x[late]) @ (-t_light)) / float(traj.times[-1] - traj.times[late])
    out = {"theta": theta, "ratio": ratio, "T2_over_T1": ratio * math.exp(mu * theta),
           "capstan": math.exp(mu * theta), "mu": mu, "status": traj.status, "slide": slide, "speed": speed,
           "slip_velocity": slip_velocity,
           "verdict": ("holds" if abs(speed) < slip_velocity else "slips") if traj.completed else traj.status,
           "n_edges": rod.n_edges, "steps": traj.steps, "newton_iterations": traj.newton_iterations,
           "cpu_s": round(cpu, 2)}
    return out, traj


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ratios", type=float, nargs="+", default=[0.8, 1.25],
                    help="T2 / (T1 exp(mu theta)) values to run")
    ap.add_argument("--angles", type=float, nargs="+", default=[math.pi / 2, math.pi], help="wrap angles (rad)")
    ap.add_argument("--mu", type=float, default=MU)
    ap.add_argument("--t-end", type=float, default=1.0)
    ap.add_argument("--dt", type=float, default=2e-3)
    ap.add_argument("--json", action="store_true", help="print one JSON document")
    a = ap.parse_args(argv)
    rows = []
    for theta in a.angles:
        for ratio in a.ratios:
            out, _ = run(theta, ratio, mu=a.mu, t_end=a.t_end, dt=a.dt)
            rows.append(out)
            if not a.json:
                print(f"theta {out['theta']:.4f}  T2/T1 = {out['ratio']:.3g} exp(mu theta) = {out['T2_over_T1']:.4g}: "
                      f"{out['verdict']:6s} slide {out['slide']:.3e}  speed {out['speed']:.3e}  ({out['steps']} steps, "
                      f"{out['newton_iterations']} Newton, {out['cpu_s']} s CPU)", flush=True)
    if a.json:
        print(json.dumps({"mu": a.mu, "runs": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
