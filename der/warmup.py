"""Compile (or load from numba's cache) every kernel once, on tiny scenes, so that timings exclude the JIT.

The first ``der.solve`` of a process calls ``warmup`` before it starts its clock, so that neither compilation
(a few minutes on a cold cache, announced on stderr) nor loading the compiled kernels from numba's on-disk
cache (under a second) is counted in ``SolveResult.wall_time``; that time is ``SolveResult.compile_time``.
"""
import os
import sys
import time

_DONE = False
_RUNNING = False
COMPILE_MESSAGE = "[der] compiling der's kernels (first run only, a few minutes)"
# the modules that define numba kernels (imported by ``cache_is_cold`` to inspect their caches)
KERNEL_MODULES = ("der.geometry", "der.stencils", "der.linalg", "der.energies.stretch", "der.energies.bend",
                  "der.energies.twist", "der.loads", "der.scene", "der.diagnostics", "der.solvers.system",
                  "der.solvers.implicit", "der.solvers.explicit", "der.solvers.stability")


def is_done():
    """True once ``warmup`` has run in this process (or is running: its own solves must not start it again)."""
    return _DONE or _RUNNING


def _dispatchers():
    import importlib

    from numba.core.registry import CPUDispatcher

    for name in KERNEL_MODULES:
        mod = importlib.import_module(name)
        for obj in vars(mod).values():
            if isinstance(obj, CPUDispatcher) and obj.__module__ == name:
                yield obj


# the kernels a solve calls from Python: numba compiles (or loads) exactly these, each with the kernels it
# calls inlined into it (numba's cache index tracks only a kernel's own source file, so an inlined callee's
# stale index means nothing: it is never loaded on its own)
ENTRY_KERNELS = (("der.scene", "evaluate"), ("der.geometry", "transport_frames"), ("der.geometry", "edge_frames"),
                 ("der.geometry", "edge_array"), ("der.geometry", "add_compensated"),
                 ("der.diagnostics", "_edge_forces"), ("der.solvers.explicit", "_fire_run"))


def cache_is_cold():
    """Whether the next solve would compile der's kernels rather than load them from numba's on-disk cache.

    Cold when one of the kernels a solve calls from Python (``ENTRY_KERNELS``, the central one
    ``der.scene.evaluate`` among them) has no cached version or a stale one (its source file changed since it
    was compiled). Kernels compiled in this process count as warm. Never raises: if numba's cache cannot be
    inspected, it answers True (the message is then shown once, possibly needlessly).
    """
    import importlib

    try:
        for module, name in ENTRY_KERNELS:
            disp = getattr(importlib.import_module(module), name)
            if disp.signatures:
                continue
            cache_file = disp._cache._cache_file
            if not os.path.exists(cache_file._index_path) or not cache_file._load_index():
                return True                      # never compiled here, or the source changed
        return False
    except Exception:
        return True


def warmup():
    """Run every kernel once on tiny problems; returns the seconds it took (compilation or cache loading).

    A first process compiles (a few minutes: ``tools/compile_time.py`` measures it per kernel; it prints
    "compiling der's kernels (first run only, a few minutes)" to stderr first); later processes load numba's
    on-disk cache (well under 1 s). ``der.solve`` calls it on its first use, so you need it only to time
    something else without the JIT. Calling it again returns 0.

    Example
    -------
    >>> import der
    >>> seconds = der.warmup()          # compile or load the kernels now
    >>> der.warmup()
    0.0
    """
    global _DONE, _RUNNING
    t0 = time.perf_counter()
    if _DONE or _RUNNING:
        return 0.0
    if cache_is_cold():
        print(COMPILE_MESSAGE, file=sys.stderr, flush=True)
    _RUNNING = True
    try:
        _run_kernels()
    finally:
        _RUNNING = False
    _DONE = True
    return time.perf_counter() - t0


def _run_kernels():
    from . import clamp, distributed_force, end_force, end_torque, point_force, rod_from_shape, shapes, twisting_moment
    from . import diagnostics as dg
    from .scene import Scene
    from .solvers import solve as der_solve
    from .solvers.system import raise_if_interrupted

    def solve(*args, **kwargs):          # a Ctrl-C during the warm-up stops the process's first solve too
        return raise_if_interrupted(der_solve(*args, **kwargs))

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
    # the implicit solver's second-order correction and its Newton systems in edge coordinates (issue 17): an arc
    # under an end torque large enough that its full Newton steps are refused for their chord error
    arc = Scene(rod_from_shape(shapes.arc(1.0, 3.0, 60), 1.0, 1.5), loads=[end_torque([0.0, 0.0, 0.2])],
                constraints=[clamp("start")])
    solve(arc, tol=1e-6, raise_on_failure=False, stability=False, progress=False, second_order_correction=True,
          edge_newton=True)
    # end supports (their banded change of variables), point torques and follower forces (issue 13)
    from .constraints import hinge
    from .loads import follower_force, point_torque

    # (an extensible rod: the explicit solver's length projection does not take coupled support links)
    supported = Scene(rod.with_stiffness(EA=1e4), loads=[follower_force((1e-4, 0.0)), point_torque(2, [0, 1e-4, 0]),
                                  point_torque(3, [1e-4, 0, 0], follower=True)],
                      constraints=[clamp("start"), hinge("end")])
    for solver in ("implicit", "explicit"):
        solve(supported, solver=solver, tol=1e-6, raise_on_failure=False, stability=True, max_steps=2000,
              progress=False)
    # a rod varying along its length (issue 13): per-vertex (A1, A1') and A2 arrays are the kernels' other types
    from .rod import rod as make_rod

    varying = make_rod(rest=shapes.strains(1.0, 6, kappa1=1.0, kappa2=0.5, omega=0.3), start="straight",
                       A1=[1.0, 1.1, 1.2, 1.3, 1.4], A1prime=2.0, A2=1.5, EA=1e4)
    vscene = Scene(varying, loads=[end_force([1e-3, 0, 0])], constraints=[clamp("start")])
    for solver in ("implicit", "explicit"):
        res = solve(vscene, solver=solver, tol=1e-6, raise_on_failure=False, stability=True, max_steps=2000,
                    progress=False)
    dg.profile(varying, res.state)
    ring = rod_from_shape(shapes.ring(1.0, 5), 1.0, 1.5, EA=100.0)
    res = solve(Scene(ring, loads=[twisting_moment(1e-3)]), tol=1e-6, raise_on_failure=False, progress=False)
    dg.profile(ring, res.state)
    dg.linking_number(ring, res.state)
    dg.profile(rod, rod.rest_state())
    from .geometry import edge_lengths
    edge_lengths(rod.rest_q, rod.edge_nodes)   # (and edge_vector, no longer reached through tangents)
    # the round-off floor of the residual: compiled only when a solve comes near it (it was left to the first
    # such solve, ~1 s of compilation counted as solver time)
    from .solvers import SolverOptions
    from .solvers.system import build_system, prepare_state, residual_floor

    system = build_system(scene, SolverOptions())
    residual_floor(system, prepare_state(system, rod.rest_state()), (1.0, 1.0))


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


__all__ = ["warmup", "compiled_signatures", "cache_is_cold", "COMPILE_MESSAGE"]
