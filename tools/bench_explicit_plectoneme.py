"""The explicit solver on scenarios/plectoneme.py: what a FIRE step costs and how many steps a continuation step takes,
old paths against new, side by side in one process (CPU time, ``time.process_time``).

    python tools/bench_explicit_plectoneme.py [--n 400] [--turns 1.25] [--repeat 2000]

1. Per call, at the plectoneme's start for --turns (straight rod twisted by the implicit solve, plus the scenario's
   lateral bump) and in self-contact (a twisted ring writhed into contact, the implicit solve): the barrier over the Verlet pair list as it was (``contact.barrier.pair_barrier``, with its
   12 x 12 distance Hessian, on every candidate pair) and as it is (``explicit_contact.barrier_gradient``: bounding
   spheres first, gradient only); the no-passage check as it was (``contact.ccd.pairs_ccd`` on every step) and the
   proven step bound that now replaces it when it holds (``explicit_contact.step_bound_safe``), for a typical
   FIRE step's displacement.
2. One continuation step (from the implicit state at --turns minus 1/8 turn, plus the bump, to --turns): FIRE
   steps and CPU with the rod's inertia (``fire_mass="inertia"``, the old masses) and with the stiffness-scaled
   masses (the default), and the distance between the two equilibria and the implicit one.
"""
import argparse
import os
import sys
import time

import numpy as np
from numba import njit

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, os.path.join(HERE, "..", "scenarios"))

from der.contact.barrier import GAP, pair_barrier  # noqa: E402


@njit(cache=True)
def barrier_all_pairs(q, edges, pairs, edge_radius, dhat, kappa, grad):
    """The old per-step barrier: ``pair_barrier`` (distance Hessian included) on every listed pair."""
    x = np.empty(12)
    g = np.empty(12)
    H = np.empty((12, 12))
    energy = 0.0
    for p in range(pairs.shape[0]):
        ea, eb = pairs[p, 0], pairs[p, 1]
        nodes = (edges[ea, 0], edges[ea, 1], edges[eb, 0], edges[eb, 1])
        for k in range(4):
            for i in range(3):
                x[3 * k + i] = q[4 * nodes[k] + i]
        e, z = pair_barrier(x, edge_radius[ea] + edge_radius[eb], dhat, kappa, GAP, False, g, H)
        if e == 0.0:
            continue
        energy += e
        for k in range(4):
            for i in range(3):
                grad[4 * nodes[k] + i] += g[3 * k + i]
    return energy


def per_call(label, state, term, repeat, step):
    from der import contact as C
    from der.contact.ccd import pairs_ccd
    from der.solvers.explicit_contact import MIN_GAP_FRACTION, barrier_gradient, step_bound_safe

    q = np.ascontiguousarray(state.q)
    x = np.ascontiguousarray(q.reshape(-1, 4)[:term.n_nodes, :3])
    pairs = C.candidate_pairs(x, term.topo, term.dhat + 2.0 * term.radius)
    edges, radius = term.topo.edges, term.topo.edge_radius
    grad = np.zeros_like(q)
    barrier_all_pairs(q, edges, pairs, radius, term.dhat, term.kappa, grad)
    e_new, gap = barrier_gradient(q, edges, pairs, radius, term.dhat, term.kappa, grad)
    rng = np.random.default_rng(0)
    dx = rng.normal(size=x.shape) * step
    q_new = q.copy()
    q_new.reshape(-1, 4)[:term.n_nodes, :3] += dx
    lo = np.zeros_like(q)
    pairs_ccd(x, dx, edges, pairs, radius, MIN_GAP_FRACTION, 1e-6, 10000)
    step_bound_safe(q_new, lo, q, lo, term.n_nodes, gap, MIN_GAP_FRACTION)
    timings = {}
    for name, call in (
            ("barrier, pair_barrier on every pair (old)",
             lambda: barrier_all_pairs(q, edges, pairs, radius, term.dhat, term.kappa, grad)),
            ("barrier_gradient (new)",
             lambda: barrier_gradient(q, edges, pairs, radius, term.dhat, term.kappa, grad)),
            ("pairs_ccd (old: every step)",
             lambda: pairs_ccd(x, dx, edges, pairs, radius, MIN_GAP_FRACTION, 1e-6, 10000)),
            ("step_bound_safe (new: CCD only if it fails)",
             lambda: step_bound_safe(q_new, lo, q, lo, term.n_nodes, gap, MIN_GAP_FRACTION))):
        best = np.inf
        for _ in range(3):
            c0 = time.process_time()
            for _ in range(repeat):
                call()
            best = min(best, (time.process_time() - c0) / repeat)
        timings[name] = best
    safe = step_bound_safe(q_new, lo, q, lo, term.n_nodes, gap, MIN_GAP_FRACTION)
    print(f"\n{label}: {len(pairs)} candidate pairs, min gap {gap:.3e}, a step of {step:.1e} per coordinate "
          f"{'proven by the bound' if safe else 'left to CCD'} (us per call, best of 3 x {repeat}, Python call "
          "overhead included)")
    for name, t in timings.items():
        print(f"  {name:48s} {1e6 * t:8.1f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=400)
    ap.add_argument("--turns", type=float, default=1.25)
    ap.add_argument("--repeat", type=int, default=2000)
    ap.add_argument("--no-steps", action="store_true", help="skip part 2 (the continuation step)")
    args = ap.parse_args()
    import der
    import plectoneme as P

    L, r, F, EA = 20.0, 0.05, 1.0, 1e5
    rod = der.rod_from_shape(der.shapes.straight(L, args.n), 1.0, 1 / 0.67, EA=EA)
    contact = der.self_contact(r)
    xi = rod.rest_q.reshape(-1, 4)[:, 2] / L
    bump = np.zeros((rod.n_nodes, 3))
    bump[:, 0] = 1e-3 * L * np.sin(np.pi * np.clip(xi, 0, 1))

    def scene_of(N):
        return der.Scene(rod, loads=[der.end_force([0.0, 0.0, F])],
                         constraints=[der.clamp("start"), der.clamp("end", rotation=P.rotation_z(2 * np.pi * N),
                                                                     slide=2)], contacts=[contact])

    N0 = args.turns - 6.0 / 48
    before = der.solve(scene_of(N0), tol=1e-10, stability=False)
    start = rod.displaced(before.state, bump)
    sc = scene_of(args.turns)
    from der.solvers.options import SolverOptions
    from der.solvers.system import build_system

    term = build_system(sc, SolverOptions()).terms[0]
    per_call(f"plectoneme n = {args.n} at N = {args.turns} (straight, bumped)", start, term, args.repeat, 1e-6)
    # a touching state: a naturally straight ring twisted to twice Michell's threshold writhes into self-contact
    # (tests/test_explicit_contact.py), n = --n / 2 edges, implicit solve
    from der import closed_forms as cf

    nr = max(args.n // 2, 40)
    base = der.rod_from_shape(der.shapes.ring(1.0, nr), 1.0, 1 / 0.67)
    base = base.with_natural(kappa_bar=base.kappa_bar * 0.0)
    twist = 2.0 * cf.michell_twist(1.0, 1 / 0.67)
    ring = base.with_imposed_twist(twist)
    x0 = ring.rest_q.reshape(-1, 4)[:, :3]
    phi = np.arctan2(x0[:, 1], x0[:, 0])
    dxr = np.zeros_like(x0)
    dxr[:, 2] = 0.05 * (np.cos(2 * phi) + np.sin(3 * phi))
    rscene = der.Scene(ring, contacts=[der.self_contact(r)])
    touching = der.solve(rscene, state=ring.displaced(ring.rest_state(), dxr, twist * np.arange(nr) / nr),
                         tol=1e-8, stability=False, raise_on_failure=False)
    rterm = build_system(rscene, SolverOptions()).terms[0]
    per_call(f"twisted ring n = {nr} in self-contact ({touching.status}, {touching.contact['n_contacts']} contacts)",
             touching.state, rterm, args.repeat, 1e-7)
    if args.no_steps:
        return
    implicit = der.solve(sc, state=start, tol=1e-10, stability=False)
    print(f"\none continuation step N = {N0:g} -> {args.turns:g} from the bumped implicit state (tol 1e-4, the "
          "scenario's):")
    from der.solvers.explicit_contact import warmup
    warmup()
    for mass in ("inertia", "stiffness"):
        c0 = time.process_time()
        res = der.solve(sc, state=start, solver="explicit", tol=1e-4, stability=False, fire_mass=mass,
                        raise_on_failure=False)
        cpu = time.process_time() - c0
        dx = np.abs(res.state.positions - implicit.state.positions).max()
        print(f"  fire_mass={mass:9s} {res.status:10s} {res.iterations:8d} FIRE steps {cpu:7.2f} s CPU "
              f"({1e6 * cpu / max(res.iterations, 1):5.0f} us/step); max |x - x_implicit(tol 1e-10)| {dx:.1e}")


if __name__ == "__main__":
    main()
