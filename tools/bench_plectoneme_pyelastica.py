"""PyElastica's plectoneme example side by side with der (issue 14, scenario 4).

    python tools/bench_plectoneme_pyelastica.py [--json] [--pyelastica-json FILE] [--der-only] [--sweep 40]
    /work/venv-bench/bin/python tools/bench_plectoneme_pyelastica.py --pyelastica-only --out FILE  (the long run)

With --pyelastica-json FILE (the long run's --out): if FILE says "complete": true, the side-by-side table of the
end quantities and the ratio PyElastica's wall time to t = 100 / der's wall time to its 10-turn equilibrium;
otherwise (a snapshot of a run still going) its state labelled INCOMPLETE, beside der's step at the same turns,
and no ratio.

The rod and twist of PyElastica 1.0's self-contact plectoneme case (parameters in the issue's anchor; this is our
own run of them, not PyElastica's example code): 150 elements, L = 1, r = 0.025, E = 1e6, G = E / 1.5, total
mass 1, along +y from the origin; the start clamped; the far end's x and z held at 0, y free (no force), its
directors turned about the axis at a constant rate for 50 time units to 10 turns, then held; relaxation to
t = 100 (dt = 0.0025 L / 150: ~6.0 million PositionVerlet steps); AnalyticalLinearDamper with
damping_constant nu = 2 / density / (pi r^2) (= 2); SelfContact(k = 1e4, nu = 10); a kick of -1e-4 added to the
z velocity of the middle node at the start and at every step of the twisting phase (our reading of "a kick
during the twisting").

der: the same rod (A1 = E pi r^4 / 4, A2 = G pi r^4 / 2, EA = E pi r^2, extensible, n = 150 edges), the same
supports (der.clamp at the start; der.clamp("end", rotation, slide=1): the end cross-section turned about y and
free to slide along y, no force), self-contact of radius r, twisted by der.continuation (natural parameter,
--sweep fixed steps to 10 turns, each a static equilibrium of the implicit solver, warm-started from the last).
With F = 0 the rod folds into a plectoneme of its whole length whose writhe is capped near L sin 2 theta / (4 pi r)
~ 3 turns: the rest stays twist, the torque M = 2 pi A2 Tw / L grows, and the end loop closes to a radius of
curvature below r from N ~ 6.5 (Tw ~ 3.4). PyElastica's run bends the same way at the same twist (its tightest
bend 0.999 r at Tw = 3.21, der's 1.029 r at Tw = 3.20; 0.956 r and 0.946 r at Tw = 3.97 and 4.05): the tight end
loop is the thin-rod model's, in both codes (point contact, neighbours within pi r + dhat excluded), not an
artefact. der's continuation steps therefore solve on with a TightBendWarning (a user's start so bent is still
refused). Per step (--json, der.steps): Tw, Wr, extension, contacts, the tightest bend, and the tightest bend
times M / A1 (not constant: 0.29 at N = 1.25 to 1.21 at N = 10, the loop is shaped by the strands' contact). PyElastica resolves a damped dynamics in time; der
solves for equilibria, so the comparison is PyElastica's time to its final state against der's time to the
equilibrium, both judged by the same end quantities computed by the same code here (one difference of setup:
der's rod has its end cross-sections, the midpoints of its end edges, L apart, so its polygon is 150 L / 149 long
node to node, PyElastica's L; the extension below is node to node): Lk = Tw + Wr, Wr (der's
Gauss integral of the centreline closed by the extended closure of scenarios/plectoneme.py, axis y), Tw (sum
of the twist angles between consecutive cross-section frames), the extension (end-to-end along y) and the
smallest centreline distance of non-neighbour elements (over 2r it says whether the strands stay apart).
"""
import argparse
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))

N_ELEM, L, R, E = 150, 1.0, 0.025, 1e6
G = E / 1.5
TURNS = 10
DENSITY = 1.0 / (np.pi * R * R * L)
NU = 2.0 / DENSITY / (np.pi * R * R)
DT = 0.0025 * L / N_ELEM
TWIST_TIME = 5.0 * TURNS
K_CONTACT, NU_CONTACT = 1e4, 10.0
KICK = -1e-4
A1 = E * np.pi * R ** 4 / 4
A2 = G * np.pi * R ** 4 / 2
EA = E * np.pi * R ** 2
VENV = "/work/venv-bench/bin/python"


# ---- PyElastica (run in the venv that has it) ------------------------------------------------------------

def pyelastica_run(final_time, out, every=20000):
    import elastica as ea

    class Sim(ea.BaseSystemCollection, ea.Constraints, ea.Damping, ea.Contact, ea.CallBacks):
        pass

    class TurnEnd(ea.ConstraintBase):
        """Start: node 0 and element 0 fixed. End: node -1 held at x = z = 0 (y free), element -1's directors
        turned about +y at a constant rate until TURNS turns, then held; the middle node kicked in z."""

        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            rod = self._system
            self.x0 = rod.position_collection[:, 0].copy()
            self.Q0 = rod.director_collection[..., 0].copy()
            self.Qend = rod.director_collection[..., -1].copy()
            self.omega = 2 * np.pi * TURNS / TWIST_TIME
            self.mid = N_ELEM // 2

        def constrain_values(self, system, time):
            rod = system
            rod.position_collection[:, 0] = self.x0
            rod.director_collection[..., 0] = self.Q0
            rod.position_collection[0, -1] = 0.0
            rod.position_collection[2, -1] = 0.0
            phi = self.omega * min(time, TWIST_TIME)
            c, s = np.cos(phi), np.sin(phi)
            Ry = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])     # rotation by phi about +y
            rod.director_collection[..., -1] = self.Qend @ Ry.T                # rows d_i -> R d_i

        def constrain_rates(self, system, time):
            rod = system
            rod.velocity_collection[:, 0] = 0.0
            rod.omega_collection[:, 0] = 0.0
            rod.velocity_collection[0, -1] = 0.0
            rod.velocity_collection[2, -1] = 0.0
            rod.omega_collection[:, -1] = 0.0
            if time < TWIST_TIME:
                rod.omega_collection[2, -1] = self.omega      # material frame: d3 is the rod axis
                rod.velocity_collection[2, self.mid] += KICK

    sim = Sim()
    rod = ea.CosseratRod.straight_rod(N_ELEM, np.zeros(3), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]),
                                      L, R, DENSITY, youngs_modulus=E, shear_modulus=G)
    sim.append(rod)
    sim.constrain(rod).using(TurnEnd, constrained_position_idx=(0, -1), constrained_director_idx=(0, -1))
    sim.dampen(rod).using(ea.AnalyticalLinearDamper, damping_constant=NU, time_step=DT)
    sim.detect_contact_between(rod, rod).using(ea.RodSelfContact, k=K_CONTACT, nu=NU_CONTACT)
    sim.finalize()
    rod.velocity_collection[2, N_ELEM // 2] += KICK
    stepper = ea.PositionVerlet()
    steps = int(round(final_time / DT))
    t, log = 0.0, []
    t0 = time.perf_counter()
    for k in range(steps):
        t = stepper.step(sim, t, DT)
        if (k + 1) % every == 0:
            log.append({"t": t, "wall": time.perf_counter() - t0,
                        "speed": float(np.abs(rod.velocity_collection).max()),
                        "extension": float(rod.position_collection[1, -1] - rod.position_collection[1, 0])})
            if not np.isfinite(rod.position_collection).all():
                break
            print(json.dumps(log[-1]), file=sys.stderr, flush=True)
            _snapshot(out, rod, t, k + 1, time.perf_counter() - t0, log, complete=False)
    return _snapshot(out, rod, t, k + 1, time.perf_counter() - t0, log, complete=(k + 1 == steps))


def _snapshot(out, rod, t, steps, wall, log, complete):
    """Write the state reached (a long run may be stopped before its final time: the snapshot says so)."""
    import importlib.metadata

    res = {"final_time": t, "steps": steps, "dt": DT, "wall_s": wall, "log": log, "complete": complete,
           "positions": rod.position_collection.T.tolist(), "directors": rod.director_collection.tolist(),
           "pyelastica": importlib.metadata.version("pyelastica")}
    with open(out + ".tmp", "w") as f:
        json.dump(res, f)
    os.replace(out + ".tmp", out)
    return res


# ---- the end quantities, the same code for both --------------------------------------------------------

def _rotation_angle_about(Qa, Qb):
    """Twist angle from frame Qa to frame Qb (rows d1, d2, d3) about their mean axis: the d3 component of the
    rotation vector of Qb Qa^T expressed in the material frame."""
    from der import diagnostics as dg

    Rm = Qb @ Qa.T                       # maps Qa's rows (in lab coordinates) ... in the material frame of a
    v = dg.rotation_vector(Rm.T)
    return float(v[2])


def end_quantities(x, frames):
    """x (n_nodes, 3) centreline, frames (n_edges, 3, 3) rows d1, d2, d3 (d3 along the edge). Axis y."""
    from der.contact import topology, exclusion_k  # noqa: F401
    from scenarios.plectoneme import closed_writhe

    # rotate the lab frame so that the axis y becomes z (cyclic permutation, det +1): (x, y, z) -> (z, x, y)
    xr = np.ascontiguousarray(x[:, [2, 0, 1]])
    wr = closed_writhe(xr, L)
    # twist: sum over consecutive frames of the angle about the tangent after parallel transport
    tw = 0.0
    for k in range(len(frames) - 1):
        a, b = frames[k], frames[k + 1]
        t0, t1 = a[2], b[2]
        # parallel transport of a's d1 onto b's tangent
        axis = np.cross(t0, t1)
        s, c = np.linalg.norm(axis), float(t0 @ t1)
        d1 = a[0]
        if s > 1e-15:
            k_ = axis / s
            ang = np.arctan2(s, c)
            d1 = d1 * np.cos(ang) + np.cross(k_, d1) * np.sin(ang) + k_ * (k_ @ d1) * (1 - np.cos(ang))
        tw += np.arctan2(float(np.cross(d1, b[0]) @ t1), float(d1 @ b[0]))
    tw /= 2 * np.pi
    # the smallest centreline distance of non-neighbour edges (brute force, 150 edges)
    from der.contact.distance import segment_distance2

    ne = x.shape[0] - 1
    kx = int(np.ceil((np.pi * R + 0.1 * R) / (L / N_ELEM)))
    dmin = np.inf
    for i in range(ne):
        for j in range(i + kx + 1, ne):
            d = np.sqrt(segment_distance2(np.concatenate([x[i], x[i + 1], x[j], x[j + 1]])))
            dmin = min(dmin, d)
    # the tightest bend: kappa_i = 2 tan(phi_i / 2) / D_i (phi the turning angle at node i, D the mean length of
    # its two edges), the discrete curvature both codes bend with
    e = np.diff(x, axis=0)
    le = np.linalg.norm(e, axis=1)
    t = e / le[:, None]
    cosphi = np.clip(np.einsum("ij,ij->i", t[:-1], t[1:]), -1.0, 1.0)
    kappa = 2.0 * np.tan(0.5 * np.arccos(cosphi)) / (0.5 * (le[:-1] + le[1:]))
    rmin = 1.0 / kappa.max() if kappa.max() > 0 else np.inf
    return {"twist": tw, "writhe": wr, "linking_number": tw + wr, "extension": float(x[-1, 1] - x[0, 1]),
            "min_distance": float(dmin), "min_distance_over_2r": float(dmin / (2 * R)),
            "min_curvature_radius": float(rmin), "min_curvature_radius_over_r": float(rmin / R),
            "tightest_bend_node": int(np.argmax(kappa)) + 1}


# ---- der ---------------------------------------------------------------------------------------------------

def der_run(sweep, tol, force=0.0, max_iterations=5000):
    """der's continuation of the case to TURNS turns (der.continuation, natural parameter N, fixed steps of
    TURNS / sweep, each a der.solve warm-started from the last; the 1e-3 L lateral imperfection added to the
    start of each step until the first contact). Each step's start is the model's own equilibrium: a bend
    tighter than r there is solved on with a TightBendWarning (counted here), not refused."""
    import warnings

    import der
    from der.terms.contact import min_curvature_radius
    from scenarios.plectoneme import closed_writhe, rotation_z

    rod = der.rod_from_shape(der.shapes.straight(L, N_ELEM), A1, A2, EA=EA)
    contact = der.self_contact(R)
    xi = rod.rest_q.reshape(-1, 4)[:, 2] / L
    bump = np.zeros((rod.n_nodes, 3))
    bump[:, 0] = 1e-3 * L * np.sin(np.pi * np.clip(xi, 0, 1))
    # not on the nodes the clamps hold (each clamp holds its end edge where the start state has it: a nudged node 1
    # tilted the bottom clamp, as in scenarios/plectoneme.py before stop 27)
    bump[:2] = 0.0
    bump[-2:] = 0.0

    def scene_of(N):
        loads = [der.end_force([0.0, 0.0, force])] if force else []
        return der.Scene(rod, loads=loads, constraints=[der.clamp("start"),
                                                        der.clamp("end", rotation=rotation_z(2 * np.pi * N), slide=2)],
                         contacts=[contact])

    last = {"contacts": 0}

    def contacts(scene, state):
        last["contacts"] = der.diagnostics.contact_forces(scene, state)["n_contacts"]
        return last["contacts"]

    def twist(scene, state):
        return der.diagnostics.total_twist(rod, state) / (2 * np.pi)

    def writhe(scene, state):
        return closed_writhe(state.positions, L)

    def extension(scene, state):
        return float(state.positions[-1, 2] - state.positions[0, 2])     # node to node, as end_quantities

    def bend_radius(scene, state):
        return min_curvature_radius(rod, state)[0]

    def perturb(N, state):
        return None if last["contacts"] else rod.displaced(state, bump)

    options = der.SolverOptions(max_iterations=max_iterations)
    c0, t0 = time.process_time(), time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", der.TightBendWarning)
        branch = der.continuation(scene_of, 0.0, float(TURNS), parameter="turns", method="natural",
                                  dp=TURNS / sweep, predictor="last", perturb=perturb, stability=False, leave_unstable=1e-3,
                                  tol=tol, options=options, summaries={"contacts": contacts, "twist": twist, "writhe": writhe,
                                                                  "extension": extension,
                                                                  "min_curvature_radius": bend_radius},
                                  max_steps=4 * sweep, progress=False)
    cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    tight = [str(w.message) for w in caught if issubclass(w.category, der.TightBendWarning)]
    pts = branch.points[1:]
    state = branch.states[-1]
    radii = [pt["min_curvature_radius"] for pt in pts]
    first_tight = next((pt["turns"] for pt, rr in zip(pts, radii) if rr <= R), None)
    # F = 0: the only length of a loop's statics is A1 / M, M = A2 2 pi Tw / L the torque the twist carries; the
    # tightest bend against it (constant along the branch if the tight end loop is set by the torque)
    loop = [rr * A2 * 2 * np.pi * pt["twist"] / L / A1 for pt, rr in zip(pts, radii)]
    xs = state.positions                   # along z
    frames = np.stack([np.stack([d1, d2, t]) for d1, d2, t in zip(*_der_frames(rod, state))])
    # (x, y, z)_der -> the PyElastica lab: der's z is PyElastica's y; der's x -> PyElastica's z, der's y -> x
    # x_pe = y_d, y_pe = z_d, z_pe = x_d (a cyclic permutation, det +1): rows of P are der's axes in PyElastica's
    P = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]], float)
    return {"wall_s": wall, "cpu_s": cpu, "solve_wall_s": float(sum(pt["step_time"] for pt in pts)),
            "iterations": int(sum(pt["newton_iterations"] for pt in pts)),
            "converged": branch.status == "completed" and abs(pts[-1]["turns"] - TURNS) < 1e-9,
            "status": branch.status, "message": branch.message, "turns_reached": float(pts[-1]["turns"]),
            "points": len(pts), "sweep": sweep, "tol": tol, "force": force,
            "first_turns_bent_tighter_than_r": first_tight,
            "tight_bend_warnings": len(tight),
            "steps": [{k: pt[k] for k in ("turns", "twist", "writhe", "extension", "contacts", "min_curvature_radius",
                                          "newton_iterations", "step_time")} | {"min_curvature_radius_M_over_A1": lp}
                      for pt, lp in zip(pts, loop)],
            "positions": xs @ P, "frames": frames @ P}


def _der_frames(rod, state):
    from der import diagnostics as dg

    from der.geometry import material_frames

    e = np.diff(state.positions, axis=0)
    t = np.ascontiguousarray(e / np.linalg.norm(e, axis=1, keepdims=True))
    d1, d2 = material_frames(state.q, t, state.d1)
    return d1, d2, t


def pyelastica_side(path):
    """PyElastica's run (the --out of --pyelastica-only, complete or a snapshot of a run still going): its state's
    end quantities, its cost, and whether it reached its final time."""
    with open(path) as f:
        pe = json.load(f)
    x = np.array(pe["positions"])
    Q = np.array(pe["directors"])                       # (3, 3, n_elem): rows d1, d2, d3
    frames = np.transpose(Q, (2, 0, 1))
    out = {k: pe[k] for k in ("final_time", "steps", "dt", "wall_s", "pyelastica")}
    out["complete"] = bool(pe.get("complete"))
    out["turns_applied"] = float(min(pe["final_time"], TWIST_TIME) / TWIST_TIME * TURNS)
    out["end"] = end_quantities(x, frames)
    log = pe.get("log") or []
    if log:
        # when its extension settled: the first snapshot after the twisting phase from which the extension
        # stays within 1e-3 L of its last value (a diagnostic; the ratio uses the wall time to t = 100)
        ext = np.array([e["extension"] for e in log])
        tt = np.array([e["t"] for e in log])
        ok = (np.abs(ext - ext[-1]) <= 1e-3 * L) & (tt >= TWIST_TIME)
        bad = np.flatnonzero(~ok)
        k = 0 if not bad.size else int(bad[-1]) + 1
        out["settled_t"] = float(tt[k]) if k < len(log) and ok[k:].all() and ok.any() else None
        out["settled_wall_s"] = float(log[k]["wall"]) if out["settled_t"] is not None else None
        out["last_speed"] = float(log[-1]["speed"])
    return out


ROWS = (("linking_number", "Lk"), ("writhe", "Wr"), ("twist", "Tw"), ("extension", "extension (L)"),
        ("min_distance_over_2r", "min distance / 2r"), ("min_curvature_radius_over_r", "min curvature radius / r"))


def table(der_end, pe_end, pe_complete, pe_turns):
    head = "PyElastica" if pe_complete else f"PyElastica INCOMPLETE (t < 100, {pe_turns:.3g} turns applied)"
    lines = [f"{'quantity':26s} {'der':>12s}   {head}"]
    for key, name in ROWS:
        lines.append(f"{name:26s} {der_end[key]:12.5g}   {pe_end[key]:.5g}")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pyelastica-only", action="store_true", help="run PyElastica (needs it) and write --out")
    ap.add_argument("--der-only", action="store_true", help="der's run only (no PyElastica comparison)")
    ap.add_argument("--out", default="/tmp/pyelastica_plectoneme.json")
    ap.add_argument("--final-time", type=float, default=100.0)
    ap.add_argument("--pyelastica-json", default=None,
                    help="PyElastica's run (--out of --pyelastica-only): complete (\"complete\": true) gives the "
                         "side-by-side table and the ratio; a snapshot of a run still going is reported as incomplete")
    ap.add_argument("--sweep", type=int, default=40)
    ap.add_argument("--tol", type=float, default=1e-4)
    ap.add_argument("--force", type=float, default=0.0,
                    help="der only: a pulling force on the sliding end (PyElastica's case has none)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if args.pyelastica_only:
        pyelastica_run(args.final_time, args.out)
        return 0
    if args.sweep < 4 * TURNS:
        raise ValueError(f"--sweep must be >= {4 * TURNS} (at most 1/4 turn per step); got {args.sweep}")
    import der

    der.warmup()
    dr = der_run(args.sweep, args.tol, args.force)
    out = {"tool": "bench_plectoneme_pyelastica", "load": os.getloadavg()[0],
           "der": {k: v for k, v in dr.items() if k not in ("positions", "frames")}}
    out["der"]["end"] = end_quantities(dr["positions"], dr["frames"])
    print(json.dumps({k: v for k, v in out["der"].items() if k != "steps"}, default=float), file=sys.stderr)
    if args.pyelastica_json and not args.der_only:
        pe = pyelastica_side(args.pyelastica_json)
        out["pyelastica"] = pe
        if pe["complete"] and dr["converged"]:
            # PyElastica's wall time to its final state (t = 100) over der's to its equilibrium at 10 turns
            out["ratio_pyelastica_over_der"] = pe["wall_s"] / dr["wall_s"]
        else:
            out["ratio_pyelastica_over_der"] = None
            out["no_ratio_because"] = (f"PyElastica's run is INCOMPLETE: t = {pe['final_time']:.4g} of 100 "
                                       f"({pe['turns_applied']:.3g} of {TURNS} turns applied), its snapshot below"
                                       if not pe["complete"] else f"der did not reach {TURNS} turns ({dr['message']})")
    if args.json:
        print(json.dumps(out, indent=1, default=float))
        return 0
    d = out["der"]
    print(f"der: {d['status']} ({d['message']}), {d['turns_reached']:g} turns in {d['points']} steps, "
          f"{d['iterations']} Newton iterations, {d['wall_s']:.2f} s wall ({d['solve_wall_s']:.2f} s in the solves), "
          f"{d['cpu_s']:.2f} s CPU, load {out['load']:.1f}; bent tighter than r from N = "
          f"{d['first_turns_bent_tighter_than_r']} on ({d['tight_bend_warnings']} TightBendWarnings)")
    if "pyelastica" in out:
        pe = out["pyelastica"]
        print(f"PyElastica {pe['pyelastica']}: t = {pe['final_time']:.4g} of 100, {pe['steps']} steps, "
              f"{pe['wall_s']:.0f} s wall" + ("" if pe["complete"] else "  ** INCOMPLETE: a snapshot of a run still "
                                              "going, not its final state **"))
        print(table(d["end"], pe["end"], pe["complete"], pe["turns_applied"]))
        if not pe["complete"]:
            k = int(np.argmin([abs(st["turns"] - pe["turns_applied"]) for st in d["steps"]]))
            st = d["steps"][k]
            print(f"(der at {st['turns']:g} turns, the step nearest PyElastica's snapshot: Tw {st['twist']:.4g}, Wr "
                  f"{st['writhe']:.4g}, extension {st['extension']:.4g}, min curvature radius / r (rest Voronoi lengths) "
                  f"{st['min_curvature_radius'] / R:.4g}; PyElastica's is a damped dynamics still twisting)")
        if out["ratio_pyelastica_over_der"]:
            print(f"PyElastica wall time to t = 100 / der wall time to the 10-turn equilibrium: "
                  f"{pe['wall_s']:.0f} s / {d['wall_s']:.2f} s = {out['ratio_pyelastica_over_der']:.0f}")
        else:
            print(f"no ratio: {out['no_ratio_because']}")
    else:
        print(table(d["end"], {k: float("nan") for k, _ in ROWS}, False, float("nan")))
    return 0


if __name__ == "__main__":
    sys.exit(main())
