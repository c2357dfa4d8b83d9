"""Would der's symmetric banded LDL^T (der/linalg.py) replace dgbsv on the reordered contact band? Side by side.

    python tools/bench_contact_ldlt.py [--turns 6] [--sweep 24] [--max 400]

Runs scenarios/plectoneme.py (n = 400) and keeps the first ``--max`` contact Newton matrices that
``der.contact.reorder.banded_solve`` sent to dgbsv (its banded Cholesky refused, or skipped after a refusal). On
each, in the same run: the solve as it is (scatter into a fresh general band, dgbsv) against the LDL^T path
(same scatter, ``band_ldlt_compact`` with L in the band's spare rows, refined against the whole band and
accepted at LDLT_BACKWARD_ERROR, else dgbsv on the same band), CPU per solve (``time.process_time``, best of
``--repeat``); how many the LDL^T accepts, split by whether the lower triangle is positive definite (dpbtrf) and
whether the Cholesky path (``cholesky_solve``) would have accepted it; the allocation of the fresh band alone;
and the relative skew part of the band (elastic) and of the contact triplets.
"""
import argparse
import contextlib
import io
import os
import runpy
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))


def capture(turns, sweep, limit):
    import der.contact.reorder as R

    orig, caps = R.banded_solve, []

    def keeping(ab, kl, ku, perm, rows, cols, vals, rhs, newpos, kl2, ku2, chol=None, keep=None):
        before = chol.counts["dgbsv"] if chol is not None else None
        out = orig(ab, kl, ku, perm, rows, cols, vals, rhs, newpos, kl2, ku2, chol, keep)
        if chol is not None and chol.counts["dgbsv"] > before and len(caps) < limit:
            caps.append((ab.copy(order="F"), kl, ku, perm.copy(), rows.copy(), cols.copy(), vals.copy(),
                         rhs.copy(), newpos.copy(), kl2, ku2))
        return out

    R.banded_solve = keeping
    argv = sys.argv
    sys.argv = ["plectoneme.py", "--turns", str(turns), "--sweep", str(sweep), "--json"]
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            try:
                runpy.run_path(os.path.join(HERE, "..", "scenarios", "plectoneme.py"), run_name="__main__")
            except SystemExit as e:      # the scenario's exit code (0: converged and checked)
                if e.code not in (0, None):
                    raise
    finally:
        R.banded_solve, sys.argv = orig, argv
    return caps


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--turns", type=float, default=6.0)
    ap.add_argument("--sweep", type=int, default=24)
    ap.add_argument("--max", type=int, default=400)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    import scipy.sparse as sp
    from scipy.linalg.lapack import dgbsv, dpbtrf

    from der.contact.reorder import BandCholesky, cholesky_solve, scatter, scatter_lower
    from der.linalg import (LDLT_BACKWARD_ERROR, LDLT_REFINEMENTS, _ldlt_solve_refined, band_ldlt_compact,
                            band_to_coo)

    caps = capture(args.turns, args.sweep, args.max)

    def fresh(c):
        ab, kl, ku, perm, rows, cols, vals, rhs, newpos, kl2, ku2 = c
        out = np.zeros((2 * kl2 + ku2 + 1, rhs.shape[0]), order="F")
        scatter(ab, kl, ku, perm, rows, cols, vals, newpos, kl2, ku2, out)
        b = np.empty(rhs.shape[0])
        b[newpos] = rhs
        return out, b

    def old(c):
        out, b = fresh(c)
        x = dgbsv(c[9], c[10], out, b, overwrite_ab=True, overwrite_b=True)[2]
        return x[c[8]], None

    def new(c):
        out, b = fresh(c)
        kl2, ku2, n = c[9], c[10], b.shape[0]
        L, D, x, r = out[:kl2, :].T, np.empty(n), np.empty(n), np.empty(n)
        err = np.inf
        if band_ldlt_compact(out, kl2, ku2, L, D) >= 0:
            err = _ldlt_solve_refined(out, kl2, ku2, L, D, b, x, r, LDLT_BACKWARD_ERROR, LDLT_REFINEMENTS)
            if err <= LDLT_BACKWARD_ERROR:
                return x[c[8]], err
        x = dgbsv(kl2, ku2, out, b, overwrite_ab=True, overwrite_b=True)[2]
        return x[c[8]], err

    for c in caps[:3]:
        old(c), new(c)
    best = {"dgbsv": np.inf, "ldlt_then_dgbsv": np.inf, "alloc": np.inf}
    for _ in range(args.repeat):
        t0 = time.process_time()
        for c in caps:
            old(c)
        t1 = time.process_time()
        for c in caps:
            new(c)
        t2 = time.process_time()
        for c in caps:
            np.zeros((2 * c[9] + c[10] + 1, c[7].shape[0]), order="F")
        t3 = time.process_time()
        best = {"dgbsv": min(best["dgbsv"], t1 - t0), "ldlt_then_dgbsv": min(best["ldlt_then_dgbsv"], t2 - t1),
                "alloc": min(best["alloc"], t3 - t2)}
    table, errs, skew_band, skew_pairs = {}, [], [], []
    for c in caps:
        ab, kl, ku, perm, rows, cols, vals, rhs, newpos, kl2, ku2 = c
        n = rhs.shape[0]
        low = np.zeros((kl2 + 1, n), order="F")
        scatter_lower(ab, kl, ku, perm, rows, cols, vals, newpos, kl2, low)
        spd = dpbtrf(low, lower=1)[1] == 0
        chol = cholesky_solve(ab, kl, ku, perm, rows, cols, vals, rhs, newpos, kl2, BandCholesky(),
                              LDLT_BACKWARD_ERROR) is not None
        _, err = new(c)
        errs.append(err)
        key = (("lower triangle positive definite" if spd else "lower triangle indefinite")
               + (", Cholesky would accept" if chol else ", Cholesky refuses")
               + (", LDL^T accepts" if err <= LDLT_BACKWARD_ERROR else ", LDL^T refuses"))
        table[key] = table.get(key, 0) + 1
        r, cc, v = band_to_coo(ab, kl, ku, perm)
        B = sp.csr_matrix((v, (r, cc)), shape=(n, n))
        T = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
        m = abs(B + T).max()
        skew_band.append(abs(B - B.T).max() / m)
        skew_pairs.append(abs(T - T.T).max() / m)
    k = len(caps)
    print(f"{k} contact matrices sent to dgbsv, {caps[0][7].shape[0]} unknowns, "
          f"reordered half-bandwidth {min(c[9] for c in caps)}-{max(c[9] for c in caps)}")
    print(f"CPU per solve: dgbsv {1e3 * best['dgbsv'] / k:.3f} ms, LDL^T then dgbsv "
          f"{1e3 * best['ldlt_then_dgbsv'] / k:.3f} ms (ratio {best['ldlt_then_dgbsv'] / best['dgbsv']:.2f}); "
          f"the fresh band's allocation alone {1e3 * best['alloc'] / k:.3f} ms")
    for key, v in sorted(table.items()):
        print(f"  {v:4d}  {key}")
    e = np.array(errs)
    refused = e[~(e <= LDLT_BACKWARD_ERROR)]
    if refused.size:
        print(f"LDL^T backward error reached on the refused: median {np.median(refused):.1e}, "
              f"min {refused.min():.1e} (accept at {LDLT_BACKWARD_ERROR:.0e})")
    print(f"skew part / max|A|: elastic band median {np.median(skew_band):.1e} max {max(skew_band):.1e}; "
          f"contact triplets max {max(skew_pairs):.1e}")


if __name__ == "__main__":
    main()
