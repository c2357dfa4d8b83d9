"""Compile (or load from numba's cache) every kernel once, on tiny scenes, so that timings exclude the JIT."""
import time

_DONE = False


def warmup():
    """Run every kernel once on tiny problems; returns the seconds it took (compilation or cache loading).

    A first process compiles (tens of seconds); later processes load numba's on-disk cache (well under 1 s).
    """
    global _DONE
    t0 = time.perf_counter()
    if _DONE:
        return 0.0
    from . import clamp, distributed_force, end_force, end_torque, point_force, rod_from_shape, shapes, twisting_moment
    from . import diagnostics as dg
    from .scene import Scene
    from .solvers import solve

    rod = rod_from_shape(shapes.helix(1.0, 0.5, 0.5, 6), 1.0, 1.5)
    loads = [point_force(-1, [0, 0, 1e-3]), end_force([1e-3, 0, 0]), distributed_force([0, 1e-4, 0]),
             end_torque([0, 0, 1e-3]), end_torque(1e-3, follower=True), twisting_moment(1e-4)]
    scene = Scene(rod, loads=loads, constraints=[clamp("start")])
    for solver in ("implicit", "explicit"):
        solve(scene, solver=solver, tol=1e-6, raise_on_failure=False, stability=True, max_steps=2000,
              progress=False)
        # an unreachable tolerance ends at the round-off floor: its verdict (and the explicit solver's Newton
        # certification) compiles too
        solve(scene, solver=solver, tol=1e-300, raise_on_failure=False, stability=False, max_steps=20000,
              max_iterations=60, progress=False)
    ring = rod_from_shape(shapes.ring(1.0, 5), 1.0, 1.5, EA=100.0)
    res = solve(Scene(ring, loads=[twisting_moment(1e-3)]), tol=1e-6, raise_on_failure=False, progress=False)
    dg.profile(ring, res.state)
    dg.linking_number(ring, res.state)
    dg.profile(rod, rod.rest_state())
    _DONE = True
    return time.perf_counter() - t0


def compiled_signatures():
    """Number of compiled signatures of der's numba kernels (for diagnosing recompilation)."""
    import sys

    from numba.core.registry import CPUDispatcher

    count = 0
    for name, mod in list(sys.modules.items()):
        if not name.startswith("der"):
            continue
        for obj in vars(mod).values():
            if isinstance(obj, CPUDispatcher):
                count += len(obj.signatures)
    return count


__all__ = ["warmup", "compiled_signatures"]
