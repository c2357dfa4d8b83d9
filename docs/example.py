"""The README's example, as printed there: `python docs/example.py` (after der.warmup(), so that the printed
times hold no compilation)."""
import numpy as np
import der   # from the repository root, or anywhere once installed (see "Where to run Python" above)

der.warmup()

# rest state and start apart; here the start is the rest (the same rod as der.rod_from_shape(helix, 1.0, 1.5))
rod = der.rod(rest=der.shapes.helix(kappa0=1.0, omega0=0.6, turns=1, n=200), start="rest", A1=1.0, A2=1.5)
scene = der.Scene(rod,
                  loads=[der.end_force([0, 0, 1e-3]), der.end_torque(2e-3, follower=True)],
                  constraints=[der.clamp("start")])
result = der.solve(scene, record="helix.rrd")          # implicit by default; solver="explicit" for FIRE
print(result)                                          # status, residual vs tol, iterations, times, stability
profile = der.diagnostics.profile(rod, result.state)   # xi, kappa, omega, alpha, Mn, Mb, Mt, Ft, Fn, Fb

# a rod curved one way then the other at rest (a perversion), straight at start, elliptical section (A1' = A1/4)
rest = der.shapes.strains(length=2.0, n=81, kappa1=lambda s: np.where(s < 1.0, 1.5, -1.5))
section = der.sections.ellipse(0.1, 0.05, E=1e4, nu=0.5)          # semi-axes 0.1 along m1, 0.05 along m2
strip = der.rod(rest=rest, start="straight", **section.stiffness(extensible=False))
print(strip)
result = der.solve(der.Scene(strip, loads=[der.end_force([0, 0, 1.0])],
                             constraints=[der.clamp("start"), der.clamp("end", slide=(0, 0, 1))]))
print(result.status, result.reactions[0]["force"].round(4), result.reactions[0]["moment"].round(4))
