"""Where a contact Newton iteration of the implicit solver goes, on saved plectoneme steps (docs/contact.md 9.4).

    python tools/profile_contact_iteration.py --load DIR [--steps 19 20 21]

DIR holds the states of ``tools/bench_contact_steps.py --save DIR --turns 5.5 --sweep 22`` (n = 400). Each step k
is solved from state k to the scene of step k + 1 (tol 1e-4), once to load everything, once timed (CPU time,
``time.process_time``: the CPU time per Newton iteration) and once under cProfile, whose own time per function is
grouped into the phases below and scaled to that CPU time per iteration (the profiler's overhead spread evenly).
Run it with PYTHONPATH at two checkouts, side by side, to compare their code on the same iterations.

    python tools/profile_contact_iteration.py --load DIR --steps 19 20 21 --arc-list-ab [--repeat 3]

runs the same steps in one process alternating the arc trials' pair lists off (der/terms/contact.py
ARC_STEP_LIST = LONG_STEP_LIST = False, the code before) and on, --repeat times each, and prints the least CPU time per Newton
iteration of each, the broad phases per iteration, and whether the two give bitwise the same final states.
"""
import argparse
import cProfile
import json
import os
import pickle
import pstats
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))

# phase: the functions (name, or name@file suffix) whose own time it holds
GROUPS = {
    "linear solve (reordering, scatter, factorisation, refinement)": [
        "banded_solve", "cholesky_solve", "scatter", "scatter_lower", "residual", "bandwidths", "block_graph",
        "block_order", "_coo_diagonal", "_contact_solve", "new_positions", "reverse_cuthill_mckee"],
    "contact barrier (assembly, line-search energies)": [
        "assemble_pairs", "active_pairs", "pairs_energy", "evaluate@terms/contact.py", "candidates"],
    "elastic energy, forces, Hessian band": ["evaluate@scene.py", "_edge_forces"],
    "CCD and pair lists (broad phase)": [
        "pairs_ccd", "reach_pairs", "step_candidates", "hash_grid_pairs", "candidate_pairs", "max_step", "step_reach",
        "within_reach", "swept_edge_boxes", "edge_boxes"],
    "residual, scales, round-off floor": [
        "load_scales", "floor_forces", "rounding_scale", "band_matvec", "residual_norm", "residual_vector",
        "condense_forces", "max_strain"],
}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--load", required=True)
    ap.add_argument("--steps", type=int, nargs="+", default=[19, 20, 21])
    ap.add_argument("--arc-list-ab", action="store_true",
                    help="ARC_STEP_LIST and LONG_STEP_LIST off and on alternately in this process (least CPU of --repeat each)")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    import der
    from der.terms import warmup

    warmup()
    if args.arc_list_ab:
        return arc_list_ab(args)

    def run():
        it = 0
        for k in args.steps:
            with open(os.path.join(args.load, f"state_{k + 1}.pkl"), "rb") as f:
                scene, _ = pickle.load(f)
            with open(os.path.join(args.load, f"state_{k}.pkl"), "rb") as f:
                _, state = pickle.load(f)
            r = der.solve(scene, state=state, stability=False, max_iterations=5000, tol=1e-4, raise_on_failure=False)
            it += r.iterations
        return it

    run()
    c0 = time.process_time()
    iterations = run()
    cpu = time.process_time() - c0
    pr = cProfile.Profile()
    pr.enable()
    run()
    pr.disable()
    stats = pstats.Stats(pr).stats
    total = sum(v[2] for v in stats.values())
    seen, out = set(), {}
    for group, names in GROUPS.items():
        s = 0.0
        for key, v in stats.items():
            f, _, fn = key
            for name in names:
                a, _, b = name.partition("@")
                if fn == a and (not b or f.endswith(b)) and key not in seen:
                    seen.add(key)
                    s += v[2]
        out[group] = s
    out["other (the solver's loop, numpy calls, frame transport, copies)"] = total - sum(out.values())
    per = 1e3 * cpu / iterations
    print(json.dumps({"der": os.path.dirname(der.__file__), "steps": args.steps, "iterations": iterations,
                      "cpu_ms_per_iteration": round(per, 3),
                      "breakdown_ms": {g: round(per * v / total, 3) for g, v in out.items()}}, indent=1))
    return 0


def arc_list_ab(args):
    """ARC_STEP_LIST and LONG_STEP_LIST off / on alternately on the same steps: least CPU per iteration, broad phases, bitwise check."""
    import numpy as np

    import der
    import der.terms.contact as contact_term

    def run():
        it = phases = 0
        finals = []
        c0 = time.process_time()
        for k in args.steps:
            with open(os.path.join(args.load, f"state_{k + 1}.pkl"), "rb") as f:
                scene, _ = pickle.load(f)
            with open(os.path.join(args.load, f"state_{k}.pkl"), "rb") as f:
                _, state = pickle.load(f)
            count = {"n": 0}
            original = contact_term.BoundSelfContact.__init__

            def init(self, *a, _o=original, **kw):
                _o(self, *a, **kw)
                count.setdefault("terms", []).append(self)

            contact_term.BoundSelfContact.__init__ = init
            try:
                r = der.solve(scene, state=state, stability=False, max_iterations=5000, tol=1e-4,
                              raise_on_failure=False)
            finally:
                contact_term.BoundSelfContact.__init__ = original
            it += r.iterations
            phases += sum(t.broad_phases for t in count.get("terms", []))
            finals.append((r.iterations, r.status, r.state.q.copy()))
        return time.process_time() - c0, it, phases, finals

    out = {}
    for flag in (False, True) * args.repeat:
        contact_term.ARC_STEP_LIST = contact_term.LONG_STEP_LIST = flag
        cpu, it, phases, finals = run()
        o = out.setdefault(flag, {"cpu": [], "iterations": it, "broad_phases": phases, "finals": finals})
        o["cpu"].append(cpu)
    same = all(a[0] == b[0] and a[1] == b[1] and np.array_equal(a[2], b[2])
               for a, b in zip(out[False]["finals"], out[True]["finals"]))
    rows = {("after (both True)" if f else "before (ARC_STEP_LIST = LONG_STEP_LIST = False)"):
            {"iterations": o["iterations"], "steps_iterations": [x[0] for x in o["finals"]],
             "cpu_ms_per_iteration_least": round(1e3 * min(o["cpu"]) / o["iterations"], 3),
             "cpu_s_runs": [round(c, 3) for c in o["cpu"]],
             "broad_phases_per_iteration": round(o["broad_phases"] / o["iterations"], 3)}
            for f, o in out.items()}
    print(json.dumps({"der": os.path.dirname(der.__file__), "steps": args.steps, "bitwise_same_final_states": same,
                      **rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
