"""der: discrete elastic rods with natural curvature and twist (Drozdov & Rabin), compiled with numba."""
from . import shapes
from .constraints import clamp, fix_theta, pin
from .loads import distributed_force, end_force, end_torque, point_force, twisting_moment
from .rod import Rod, RodState, rod_from_shape
from .scene import Scene
from .solvers import (
    ConvergenceError, LockedRodWarning, RoundoffFloorWarning, SolveResult, SolverOptions, check_stability, solve,
)
from .warmup import warmup

__all__ = [
    "shapes", "solve", "check_stability", "warmup", "SolverOptions", "SolveResult", "ConvergenceError", "RoundoffFloorWarning", "LockedRodWarning",
    "Rod", "RodState", "rod_from_shape", "Scene",
    "clamp", "pin", "fix_theta", "point_force", "end_force", "distributed_force", "end_torque", "twisting_moment",
]
