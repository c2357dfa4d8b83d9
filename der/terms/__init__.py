"""Terms of a Scene beyond the rod's elastic energy and loads: contact and obstacles (issue 14).

A term is a small frozen record (``der.self_contact(radius)``, ``der.plane(point, normal)``, ...) given to
``der.Scene(rod, ..., contacts=[...])``. Each term class lives in one module and registers itself here with
``@register``; the Scene and the solvers only use the interface below, summed over the terms (composition by
addition, no chain of isinstance tests). Importing this package imports no contact kernel: a term's ``bind``
imports ``der.contact`` when a solve starts, so a scene without terms never loads it.

Interface of a term record:

- ``check_scene(scene)``: ValueError for what needs the rod (e.g. a radius the rod's curvature forbids);
- ``bind(system)`` -> a bound term for one solve, with
  - ``check_start(state, tight_bend="refuse")``: ValueError if the starting state already violates the term
    (naming edges/gaps); a start bent tighter than the contact radius is refused ("refuse", a user's start) or
    warned about ("warn": SolverOptions.tight_bend, a continuation step starting from the model's own equilibrium);
  - ``evaluate(state, order, grad, ab, coo)`` -> energy: adds dE/dq into ``grad`` (order >= 1); with order 2
    adds band-local Hessian blocks into the band ``ab`` and appends off-band COO triplets (rows, cols, vals)
    to the list ``coo`` (only terms with ``couples_dofs``); +inf for an inadmissible state;
  - ``max_step(state, delta)`` -> the largest safe fraction in [0, 1] of the step ``delta`` (CCD);
  - ``after_step(state)`` -> True if the term changed its own parameters (the adaptive barrier stiffness);
  - ``force_scale`` (after evaluate): the largest contact force on a node, for the residual's load scale;
  - ``diagnostics(state)`` -> dict (pairs, forces, minimal distance).
"""
TERMS = {}


def register(cls):
    """Class decorator: make ``cls`` a term the Scene accepts (one line per term module)."""
    TERMS[cls.__name__] = cls
    return cls


def check_term(term, scene):
    """TypeError unless ``term`` is a registered term record; then its own checks against the scene."""
    if type(term) not in TERMS.values():
        raise TypeError(f"der.Scene: contacts: {term!r} is not a contact term; use "
                        f"{', '.join('der.' + c.constructor for c in TERMS.values())}")
    term.check_scene(scene)


_WARM = []


def warmup():
    """Compile (or load from numba's cache) the contact kernels once per process, on a small ring with every
    term, so that a solve's wall time holds no compilation. Returns the seconds it took (0 afterwards)."""
    if _WARM:
        return 0.0
    import time

    import numpy as np

    from ..rod import rod_from_shape   # der.rod is the constructor function (issue 13), not this module
    from .. import shapes
    from ..scene import Scene
    from ..solvers.options import SolverOptions
    from ..solvers.system import build_system, prepare_state

    t0 = time.perf_counter()
    for closed in (True, False):
        shape = shapes.ring(1.0, 24) if closed else shapes.straight(1.0, 24)
        r = rod_from_shape(shape, 1.0, 1.5)
        terms = [contact.self_contact(0.02), obstacles.plane([0, 0, -1], [0, 0, 1]),
                 obstacles.sphere([0, 0, -3], 1.0), obstacles.cylinder([0, 5, 0], [1, 0, 0], 1.0)]
        system = build_system(Scene(r, contacts=terms), SolverOptions())
        state = prepare_state(system, r.rest_state())
        delta = np.zeros(r.n_dof)
        delta[2::4] = -0.1
        for t in system.terms:
            t.check_start(state)
            t.start_stiffness(state, system)
            for order in (0, 1, 2):
                t.evaluate(state, order, system.grad, system.ab, [])
            t.max_step(state, delta)
            t.diagnostics(state)
    # a pair inside the barrier range (the rest states above have none): the pair assembly compiles here too
    from .. import contact as C

    topo = C.topology([(1, False, 0.02, 1.0), (1, False, 0.02, 1.0)], 0.002)
    pos = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, -0.5, 0.041], [0.5, 0.5, 0.041]])
    C.barrier_system(pos, topo, np.array([[0, 1]], dtype=np.int64), 0.002, 1.0, 4 * np.arange(4), 16)
    _WARM.append(time.perf_counter() - t0)
    return _WARM[0]


from . import contact, obstacles  # noqa: E402,F401  (registration)
