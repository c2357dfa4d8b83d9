"""Figure 1 of helix_winding: CPU seconds of its continuation in eta (scenarios/helix_winding.py
displacement_path) against six independent solves from the uniform helix, in the same process, per curve.

    python tools/bench_helix_continuation.py [repetitions]
"""
import json
import os
import sys
import time

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, os.path.join(ROOT, "scenarios"))
sys.path.insert(0, ROOT)
import numpy as np, der
import helix_winding as hw
from der import closed_forms as cf
der.warmup()
class P: pass
class S:
    def solve(self, scene, state=None):
        return der.solve(scene, state=state, stability=False)
solver = S()
res = {}
for rep in range(int(sys.argv[1]) if len(sys.argv) > 1 else 1):
    for lam in (0.5, 0.6, 0.7):
        p = P(); p.A1 = 0.67; p.lam = lam; p.turns = 1.0; p.n = 200; p.EA = None
        rod = hw.rest_rod(p)
        etas = list(np.linspace(0.6, 0.9 * float(cf.winding_eta_max(lam)), 6))
        c0 = time.process_time()
        old = [hw.solve_at(p, solver, rod, e, 0.0)[1]["P0"] for e in etas]
        c1 = time.process_time()
        new = [m["P0"] for e, m, r in hw.displacement_path(p, solver, rod, etas, 0.0)]
        c2 = time.process_time()
        res.setdefault("old", []).append(c1 - c0); res.setdefault("new", []).append(c2 - c1)
        print(f"lam {lam}: independent solves {c1-c0:.3f} s CPU, continuation {c2-c1:.3f} s CPU, ratio {(c2-c1)/(c1-c0):.2f}; "
              f"max rel diff {max(abs(a-b)/max(abs(a),1e-2) for a,b in zip(old,new)):.2e}", flush=True)
        print("  P0:", json.dumps([float(x) for x in new]))
print(f"total: independent {sum(res['old']):.3f} s, continuation {sum(res['new']):.3f} s, ratio {sum(res['new'])/sum(res['old']):.2f}")
