"""Independent check of the supercoiled ring's contact states (issue 14, scenarios/twisted_ring.py --radius).

    python tools/ring_contact_check.py [--twists 10 12 14] [--n 60] [--radius 0.05] [--modes 12] [--samples 160]
                                       [--json]

der: the naturally straight ring of scenarios/twisted_ring.py (A1 = 1, A2 = 1/0.67, a0 = 1, kappa0 = 0), welded
with the extra twist, kicked out of plane (--perturb 0.01) and continued in --sweep steps to each twist, with
self-contact of radius r (the kick only while the ring has no contact). Reported: its elastic energy (bending + twist + stretching, without the barrier's
own energy, which is reported apart) and its writhe (der.diagnostics).

Independent calculation (no der code, only numpy, numba and scipy): the same ring as a smooth closed curve
x(u) = sum_{k=1..K} a_k cos(k u) + b_k sin(k u), u in [0, 2 pi), sampled at M points, rescaled to the length
L = 2 pi a0, with the energy of an isotropic naturally straight inextensible rod whose twist has relaxed to
uniform (Kirchhoff; Calugareanu-White: Tw = Lk - Wr),

    E = A1/2 int kappa^2 ds + A2 (2 pi)^2 (Lk - Wr)^2 / (2 L),

the writhe by our own quadrature of the Gauss double integral (trapezoidal rule on the samples, the integrand's
diagonal limit 0), plus a penalty W sum max(0, 2r - |x_i - x_j|)^2 du^2 over sample pairs farther apart along the
ring than pi r (the same exclusion arc as der), raised in steps (W = 1e3 ... 1e7) so that the overlap left is a
small fraction of r, and a weak penalty on non-uniform speed |x'| (a gauge: keeps the samples spread evenly).
Minimised by L-BFGS (scipy) with central finite-difference gradients, from the Fourier fit of der's state at the
same twist (a local minimum next to der's); the energy reported is E without the penalties.
"""
import argparse
import json
import os
import sys
import time

import numpy as np
from numba import njit

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))

A1, A2, A0 = 1.0, 1.0 / 0.67, 1.0
L = 2 * np.pi * A0


@njit(cache=True)
def _gauss_writhe(x, dx, du):
    """Writhe of the closed sampled curve: (1/4 pi) sum_{i != j} (x'_i x x'_j) . (x_i - x_j) / |x_i - x_j|^3 du^2."""
    m = x.shape[0]
    w = 0.0
    for i in range(m):
        for j in range(i + 1, m):
            rx = x[i, 0] - x[j, 0]
            ry = x[i, 1] - x[j, 1]
            rz = x[i, 2] - x[j, 2]
            cx = dx[i, 1] * dx[j, 2] - dx[i, 2] * dx[j, 1]
            cy = dx[i, 2] * dx[j, 0] - dx[i, 0] * dx[j, 2]
            cz = dx[i, 0] * dx[j, 1] - dx[i, 1] * dx[j, 0]
            d2 = rx * rx + ry * ry + rz * rz
            w += 2.0 * (cx * rx + cy * ry + cz * rz) / (d2 * np.sqrt(d2))
    return w * du * du / (4.0 * np.pi)


@njit(cache=True)
def _overlap(x, du, excl, two_r):
    """sum over sample pairs more than ``excl`` samples apart (cyclic) of max(0, 2r - d)^2 du^2, and min d."""
    m = x.shape[0]
    s = 0.0
    dmin = 1e300
    for i in range(m):
        for j in range(i + 1, m):
            k = j - i
            if k > m - k:
                k = m - k
            if k <= excl:
                continue
            d = np.sqrt((x[i, 0] - x[j, 0]) ** 2 + (x[i, 1] - x[j, 1]) ** 2 + (x[i, 2] - x[j, 2]) ** 2)
            if d < dmin:
                dmin = d
            if d < two_r:
                s += (two_r - d) ** 2
    return s * du * du, dmin


@njit(cache=True)
def _writhe_grad(x, dx, du, gx, gd):
    """Adds d Wr / d x_i and d Wr / d x'_i to gx, gd (from f = (a x b) . r / |r|^3, a = x'_i, b = x'_j,
    r = x_i - x_j: df/da = (b x r) / |r|^3, df/db = (r x a) / |r|^3, df/dr = (a x b) / |r|^3 - 3 f r / |r|^2)."""
    m = x.shape[0]
    c = 2.0 * du * du / (4.0 * np.pi)
    for i in range(m):
        for j in range(i + 1, m):
            r = x[i] - x[j]
            a = dx[i]
            b = dx[j]
            d2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
            i3 = 1.0 / (d2 * np.sqrt(d2))
            axb = np.cross(a, b)
            f = (axb[0] * r[0] + axb[1] * r[1] + axb[2] * r[2]) * i3
            dr = c * (axb * i3 - 3.0 * f * r / d2)
            gx[i] += dr
            gx[j] -= dr
            gd[i] += c * np.cross(b, r) * i3
            gd[j] += c * np.cross(r, a) * i3


@njit(cache=True)
def _overlap_grad(x, du, excl, two_r, gx, w):
    m = x.shape[0]
    for i in range(m):
        for j in range(i + 1, m):
            k = j - i
            if k > m - k:
                k = m - k
            if k <= excl:
                continue
            r = x[i] - x[j]
            d = np.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
            if d < two_r:
                g = -2.0 * w * (two_r - d) * du * du / d * r
                gx[i] += g
                gx[j] -= g


class Ring:
    def __init__(self, K, M, radius, lk):
        self.K, self.M, self.r, self.lk = K, M, radius, lk
        u = 2 * np.pi * np.arange(M) / M
        self.du = 2 * np.pi / M
        k = np.arange(1, K + 1)
        ku = np.outer(u, k)
        c, s = np.cos(ku), np.sin(ku)
        self.B0 = np.hstack([c, s])                       # x = B0 @ coef (coef (2K, 3))
        self.B1 = np.hstack([-s * k, c * k])              # x'
        self.B2 = np.hstack([-c * k * k, -s * k * k])     # x''
        # pairs closer than pi r along the ring (in samples; ds = L / M) are not contacts
        self.excl = int(np.ceil(np.pi * radius / (L / M)))

    def parts(self, coef):
        C = coef.reshape(2 * self.K, 3)
        x, d1, d2 = self.B0 @ C, self.B1 @ C, self.B2 @ C
        speed = np.linalg.norm(d1, axis=1)
        length = speed.sum() * self.du
        lam = L / length                                   # rescale to the ring's length
        x, d1, d2, speed = lam * x, lam * d1, lam * d2, lam * speed
        kappa2 = np.sum(np.cross(d1, d2) ** 2, axis=1) / speed ** 6
        bend = 0.5 * A1 * np.sum(kappa2 * speed) * self.du
        wr = _gauss_writhe(np.ascontiguousarray(x), np.ascontiguousarray(d1), self.du)
        twist = A2 * (2 * np.pi) ** 2 * (self.lk - wr) ** 2 / (2 * L)
        gauge = np.sum((speed / (L / (2 * np.pi)) - 1.0) ** 2) * self.du
        over, dmin = _overlap(np.ascontiguousarray(x), self.du, self.excl, 2 * self.r)
        return {"bend": bend, "twist": twist, "writhe": wr, "gauge": gauge, "overlap": over, "dmin": dmin, "x": x}

    def objective(self, coef, W):
        p = self.parts(coef)
        return p["bend"] + p["twist"] + 1e-2 * p["gauge"] + W * p["overlap"]

    def grad(self, coef, W):
        """Analytic gradient of ``objective`` (checked against central differences in tests)."""
        C = coef.reshape(2 * self.K, 3)
        x0, e1, e2 = self.B0 @ C, self.B1 @ C, self.B2 @ C
        sp0 = np.linalg.norm(e1, axis=1)
        length = sp0.sum() * self.du
        lam = L / length
        x, d1, d2, sp = lam * x0, lam * e1, lam * e2, lam * sp0
        du = self.du
        cr = np.cross(d1, d2)
        c2 = np.sum(cr ** 2, axis=1)
        # bend = A1/2 du sum |d1 x d2|^2 / |d1|^5
        g1 = 0.5 * A1 * du * (2 * np.cross(d2, cr) / sp[:, None] ** 5 - 5 * (c2 / sp ** 7)[:, None] * d1)
        g2 = 0.5 * A1 * du * 2 * np.cross(cr, d1) / sp[:, None] ** 5
        gx = np.zeros_like(x)
        gw_x, gw_d = np.zeros_like(x), np.zeros_like(x)
        wr = _gauss_writhe(np.ascontiguousarray(x), np.ascontiguousarray(d1), du)
        _writhe_grad(np.ascontiguousarray(x), np.ascontiguousarray(d1), du, gw_x, gw_d)
        dtw = -A2 * (2 * np.pi) ** 2 * (self.lk - wr) / L
        gx += dtw * gw_x
        g1 += dtw * gw_d
        a0 = L / (2 * np.pi)
        g1 += 1e-2 * du * (2 * (sp / a0 - 1) / a0 / sp)[:, None] * d1
        _overlap_grad(np.ascontiguousarray(x), du, self.excl, 2 * self.r, gx, W)
        gC = lam * (self.B0.T @ gx + self.B1.T @ g1 + self.B2.T @ g2)
        dE_dlam = np.sum(gx * x0) + np.sum(g1 * e1) + np.sum(g2 * e2)
        dlam_dC = -lam * lam / L * du * (self.B1.T @ (e1 / sp0[:, None]))
        return (gC + dE_dlam * dlam_dC).ravel()

    def grad_fd(self, coef, W, h=1e-6):
        g = np.empty_like(coef)
        for i in range(coef.size):
            c1 = coef.copy()
            c1[i] += h
            c2 = coef.copy()
            c2[i] -= h
            g[i] = (self.objective(c1, W) - self.objective(c2, W)) / (2 * h)
        return g

    def fit(self, pts):
        """Least-squares Fourier coefficients of the closed polyline pts (m, 3) resampled uniformly in arc length."""
        P = np.vstack([pts, pts[:1]])
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
        u = 2 * np.pi * np.arange(self.M) / self.M
        t = u / (2 * np.pi) * s[-1]
        X = np.stack([np.interp(t, s, P[:, d]) for d in range(3)], axis=1)
        X -= X.mean(axis=0)
        C, *_ = np.linalg.lstsq(self.B0, X, rcond=None)
        return C.ravel()


def minimise(ring, coef0, weights=(1e3, 1e4, 1e5, 1e6, 1e7), maxiter=400):
    from scipy.optimize import minimize

    coef = coef0.copy()
    for W in weights:
        res = minimize(ring.objective, coef, args=(W,), jac=lambda c, W=W: ring.grad(c, W), method="L-BFGS-B",
                       options={"maxiter": maxiter, "gtol": 1e-9, "ftol": 1e-14})
        coef = res.x
    p = ring.parts(coef)
    return coef, p, res


def der_states(twists, n, radius, sweep_per_twist=2, perturb=0.01):
    """der's contact states of the naturally straight ring at each twist (a continuation through all of them)."""
    import der
    from der import diagnostics as dg
    from scenarios.twisted_ring import make_rod, start_state

    p = argparse.Namespace(a0=A0, n=n, A1=A1, A2=A2, kappa0=0.0)
    base, _ = make_rod(p)
    steps = np.linspace(0.0, max(twists), int(np.ceil(max(twists) / 2.0)) * sweep_per_twist + 1)[1:]
    steps = np.unique(np.concatenate([steps, twists]))
    state, welded, out, touching = base.rest_state(), 0.0, {}, False
    t0 = time.perf_counter()
    for tw in steps:
        rod = base.with_imposed_twist(tw)
        scene = der.Scene(rod, contacts=[der.self_contact(radius)])
        # the out-of-plane kick only while the ring has no contact (a kick could push strands in contact together)
        kick = perturb if not touching else 0.0
        res = der.solve(scene, state=start_state(rod, state, welded, tw, kick, A0), stability=False)
        state, welded = res.state, float(tw)
        touching = bool(res.contact.get("n_contacts", 0) or any(t.get("n_contacts", 0)
                                                               for t in res.contact.get("terms", [])))
        if any(abs(tw - t) < 1e-12 for t in twists):
            lk, twt, wr = dg.linking_number(rod, res.state)
            elastic = float(sum(v for k, v in res.energy.items() if k != "contact"))
            out[float(tw)] = {"energy": elastic, "barrier_energy": float(res.energy.get("contact", 0.0)),
                              "energy_terms": dict(res.energy), "writhe": float(wr), "twist": float(twt),
                              "linking_number": float(lk), "min_distance": res.contact.get("min_distance"),
                              "contacts": int(sum(t.get("n_contacts", 0) for t in res.contact.get("terms", []))),
                              "positions": res.state.positions.copy(), "iterations": res.iterations}
    return out, time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--twists", type=float, nargs="+", default=[10.0, 12.0, 14.0])
    ap.add_argument("--n", type=int, default=60)
    ap.add_argument("--radius", type=float, default=0.05)
    ap.add_argument("--modes", type=int, default=12)
    ap.add_argument("--samples", type=int, default=160)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    ders, der_time = der_states(args.twists, args.n, args.radius)
    rows = []
    for tw in args.twists:
        d = ders[float(tw)]
        ring = Ring(args.modes, args.samples, args.radius, tw / (2 * np.pi))
        t0 = time.perf_counter()
        coef, p, res = minimise(ring, ring.fit(d["positions"]))
        e = p["bend"] + p["twist"]
        rows.append({"twist": tw, "Lk": tw / (2 * np.pi),
                     "der": {k: d[k] for k in ("energy", "barrier_energy", "energy_terms", "writhe", "min_distance", "contacts",
                                               "iterations")},
                     "independent": {"energy": e, "bend": p["bend"], "twist_energy": p["twist"], "writhe": p["writhe"],
                                     "min_distance": p["dmin"], "gauge": p["gauge"], "lbfgs": res.message
                                     if isinstance(res.message, str) else str(res.message),
                                     "seconds": time.perf_counter() - t0},
                     "energy_rel_diff": (d["energy"] - e) / e, "writhe_diff": d["writhe"] - p["writhe"]})
    out = {"tool": "ring_contact_check", "n": args.n, "radius": args.radius, "modes": args.modes,
           "samples": args.samples, "der_seconds": der_time, "rows": rows}
    if args.json:
        print(json.dumps(out, indent=1, default=float))
    else:
        print(f"naturally straight ring, A1 = 1, A2 = 1/0.67, a0 = 1, r = {args.radius}; der n = {args.n}; "
              f"independent: K = {args.modes} modes, M = {args.samples} samples")
        print("| twist | Lk | E der | E indep. | rel. diff | Wr der | Wr indep. | diff | d_min/2r der | indep. |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r['twist']:g} | {r['Lk']:.4f} | {r['der']['energy']:.5f} | {r['independent']['energy']:.5f} | "
                  f"{r['energy_rel_diff']:+.2e} | {r['der']['writhe']:.4f} | {r['independent']['writhe']:.4f} | "
                  f"{r['writhe_diff']:+.1e} | {r['der']['min_distance'] / (2 * args.radius):.4f} | "
                  f"{r['independent']['min_distance'] / (2 * args.radius):.4f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
