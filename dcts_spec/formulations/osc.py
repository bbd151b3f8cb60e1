"""OSC — the closed-form dynamically consistent hierarchy, no limits (the paper's eq. 1, by levels).

Each level's desired acceleration is met in the null space of the levels above
(`hierarchy.py`); the remaining null space moves passively (minimum acceleration energy);
a lowest level that is over-constrained is met in least squares. The torque is
τ = M a + ν + g − τ_ext: gravity is compensated separately, as in the paper. OSC knows no
limits: its torque is clipped to the torque limits after the fact.
"""

from __future__ import annotations

import casadi as ca

from .hierarchy import least_squares_step, level_structure, recursive_hierarchy
from .problem import ControlProblem
from .qp import Affine, ControlLaw


def osc(problem: ControlProblem) -> ControlLaw:
    structure = level_structure(problem)
    exact = problem.levels[: structure.exact_levels]
    commands = [Affine(level.target, ca.SX(level.dim, 0)) for level in exact]
    hierarchy, N = recursive_hierarchy(problem, commands, 0)
    acceleration = hierarchy.offset
    if structure.least_squares_last:
        acceleration = least_squares_step(problem.levels[-1], acceleration, N, problem.mass_matrix)
    torque = Affine.constant(problem.torque(acceleration), 0)
    scaling = Affine.constant(ca.SX.ones(len(problem.levels)), 0)
    return ControlLaw(torque, scaling, enforces_torque_limits=False)
