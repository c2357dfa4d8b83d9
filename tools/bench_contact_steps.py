"""Before/after of contact solves on the same plectoneme continuation steps (docs/contact.md section 8.3).

    python tools/bench_contact_steps.py --save DIR [--turns 5 --sweep 20 --n 400]   # write the steps' states
    python tools/bench_contact_steps.py --load DIR --steps 17 18 [--json] [--set NAME=VALUE]   # step k -> k + 1

--save runs scenarios/plectoneme.py's continuation (tol 1e-4) and pickles (scene, state) after every step as
DIR/state_<k>.pkl (k from 0). --load solves, for each k of --steps, the scene of step k + 1 from the state of step
k and reports iterations, CPU time of the solve, the solver's phase timers and its linear solves. Run it with
PYTHONPATH pointing at two checkouts in one command to compare their code on identical inputs, e.g.

    (cd /tmp/main && PYTHONPATH=$PWD python $OLDPWD/tools/bench_contact_steps.py --load DIR --steps 17 18) &
    PYTHONPATH=$PWD python tools/bench_contact_steps.py --load DIR --steps 17 18; wait
"""
import argparse
import json
import os
import pickle
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def save(directory, turns, sweep, n):
    import der

    sys.path.insert(0, os.path.join(HERE, "..", "scenarios"))
    import plectoneme as P

    os.makedirs(directory, exist_ok=True)
    p = argparse.Namespace(A1=1.0, A2=1 / 0.67, L=20.0, EA=1e5, radius=0.05, force=1.0, turns=turns, sweep=sweep,
                           perturb=1e-3, png=None, n=n, samples=None, predictor="last")
    count = []

    class Saver:
        args = argparse.Namespace(tol=1e-4)

        def solve(self, scene, **kw):
            kw.setdefault("tol", 1e-4)
            r = der.solve(scene, **kw)
            with open(os.path.join(directory, f"state_{len(count)}.pkl"), "wb") as f:
                pickle.dump((scene, r.state), f)
            count.append(1)
            return r

    P.run(p, Saver())
    return len(count)


def load(directory, steps):
    import der
    from der.terms import warmup

    warmup()
    out = []
    for k in steps:
        with open(os.path.join(directory, f"state_{k + 1}.pkl"), "rb") as f:
            scene, _ = pickle.load(f)
        with open(os.path.join(directory, f"state_{k}.pkl"), "rb") as f:
            _, state = pickle.load(f)
        c0 = time.process_time()
        r = der.solve(scene, state=state, stability=False, max_iterations=5000, tol=1e-4, raise_on_failure=False)
        out.append({"step": k + 1, "iterations": r.iterations, "cpu_s": time.process_time() - c0,
                    "wall_s": r.wall_time, "status": r.status, "linear_solves": r.linear_solves,
                    "timings": r.timings, "contacts": (r.contact or {}).get("n_contacts")})
    return {"der": os.path.dirname(der.__file__), "steps": out}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--save", default=None)
    ap.add_argument("--load", default=None)
    ap.add_argument("--steps", type=int, nargs="+", default=[17, 18])
    ap.add_argument("--turns", type=float, default=5.0)
    ap.add_argument("--sweep", type=int, default=20)
    ap.add_argument("--n", type=int, default=400)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="a solver switch for --load (tools/plectoneme_with_switches.py), e.g. "
                         "CONTACT_ARC_EVERY_FRACTION=0")
    args = ap.parse_args(argv)
    if args.set:
        sys.path.insert(0, HERE)
        from plectoneme_with_switches import apply_switches

        apply_switches(args.set)
    if args.save:
        print(f"{save(args.save, args.turns, args.sweep, args.n)} states written to {args.save}")
    if args.load:
        res = load(args.load, args.steps)
        if args.json:
            print(json.dumps(res))
        else:
            for s in res["steps"]:
                print(f"{res['der']}: step {s['step']}: {s['iterations']} iterations, {s['cpu_s']:.2f} s CPU "
                      f"({1e3 * s['cpu_s'] / max(s['iterations'], 1):.1f} ms per iteration), {s['status']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
