"""der: discrete elastic rods with natural curvature and twist (Drozdov & Rabin), compiled with numba.

Build a rod from a rest description and a start (``rod(rest=shapes.helix(...), start="straight", A1=..., A2=...)``,
or ``rod_from_shape(shapes.helix(...), A1, A2)`` for rest = start = the shape), put it in a ``Scene`` with loads
(``point_force``, ``end_force``, ``distributed_force``, ``end_torque``, ``twisting_moment``, ``point_torque``,
``follower_force``) and constraints (``clamp``, ``hinge``, ``roller``, ``pin``, ``fix_theta``), relax it with
``solve``; read the paper's variables with ``diagnostics``.
Every public name has a docstring with units, sign conventions and an example: ``help(der.end_torque)``.

Example
-------
>>> import der
>>> rod = der.rod_from_shape(der.shapes.helix(kappa0=1.0, omega0=0.6, turns=1, n=50), A1=1.0, A2=1.5)
>>> scene = der.Scene(rod, loads=[der.end_force([0, 0, 1e-3])], constraints=[der.clamp("start")])
>>> der.solve(scene).converged
True
"""
from . import diagnostics, sections, shapes
from .constraints import clamp, fix_theta, hinge, pin, roller
from .continuation import Branch, continuation
from .loads import (
    distributed_force, end_force, end_torque, follower_force, point_force, point_torque, twisting_moment,
)
from .rod import Rod, RodState, rod, rod_from_shape   # der.rod is the constructor (the module: sys.modules)
from .scene import Scene
from .terms.contact import rod_contact, self_contact
from .terms.obstacles import cylinder, plane, sphere
from .solvers import (
    ConvergenceError, LockedRodWarning, RoundoffFloorWarning, SolveResult, SolverOptions, TightBendWarning,
    check_stability, solve,
)
from .sweep import SweepResult, sweep
from .warmup import warmup
from . import dynamics
from .dynamics import Damping, Trajectory, simulate

__all__ = [
    "shapes", "sections", "diagnostics", "solve", "check_stability", "warmup", "SolverOptions", "SolveResult",
    "ConvergenceError",
    "RoundoffFloorWarning", "LockedRodWarning", "TightBendWarning", "Rod", "RodState", "rod", "rod_from_shape", "Scene",
    "clamp", "hinge", "roller", "pin", "fix_theta", "point_force", "end_force", "distributed_force", "end_torque",
    "twisting_moment", "point_torque", "follower_force",
    "self_contact", "rod_contact", "plane", "sphere", "cylinder",
    "continuation", "Branch", "sweep", "SweepResult",
    "simulate", "Damping", "Trajectory", "dynamics",
]
