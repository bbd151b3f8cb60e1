"""Projector baseline: the closed-form hierarchy, joint limits by saturation in the null space,
naive torque clipping — the paper's comparison for experiment 3 (its "SCS").

Joint position and velocity limits are shaped into joint acceleration bounds exactly as for the
other formulations (`limits/viability.py`). Saturation in the null space (Flacco, De Luca,
Khatib, "Control of redundant robots under hard joint constraints: saturation in the null
space", IEEE T-RO 2015) is applied at the acceleration level to the whole hierarchy: while a
free joint exceeds its bounds, the one exceeding most is locked at its bound and the hierarchy
is recomputed with the remaining joints (at most n times, unrolled so the generated code has a
fixed cost). Locking joints keeps the dynamical consistency of the rest: the metric is the
mass matrix of the robot with those joints locked (levels that lose rank when joints lock are
damped, as at a singularity).
Unlike SNS, tasks are not scaled, and, as in the paper, each torque is finally clipped to its
limit without re-solving ("naive" saturation), which is what breaks the velocity limits.
"""

from __future__ import annotations

import casadi as ca

from ..symbolic.linalg import spd_inverse
from .hierarchy import LevelStructure, least_squares_step, level_structure, recursive_hierarchy
from .problem import ControlProblem
from .qp import Affine, ControlLaw

BIG = 1e6


def _joint_bounds(problem: ControlProblem) -> tuple[ca.SX, ca.SX]:
    """Per-joint acceleration bounds, the problem's joint rows (±BIG for joints without limits)."""
    n = problem.n
    rows = problem.acceleration_rows
    lower, upper = -BIG * ca.SX.ones(n), BIG * ca.SX.ones(n)
    for r, name in enumerate(rows.names):
        if name.startswith("joint:"):
            j = problem.robot.joint_names.index(name.removeprefix("joint:"))
            lower[j], upper[j] = rows.lower[r], rows.upper[r]
    return lower, upper


def _locked_hierarchy(
    problem: ControlProblem, structure: LevelStructure, free: ca.SX, locked_acceleration: ca.SX
) -> ca.SX:
    """The hierarchy's acceleration when joints with free_j = 0 have their acceleration fixed."""
    locked = 1.0 - free
    W = ca.diag(free)
    M = problem.mass_matrix
    fixed = locked * locked_acceleration
    # Gauss's principle with the locked joints' accelerations prescribed: the free joints see the
    # mass matrix W M W (the identity on locked joints keeps it invertible).
    metric_inverse = ca.mtimes([W, spd_inverse(ca.mtimes([W, M, W]) + ca.diag(locked)), W])
    free_acceleration = fixed + ca.mtimes(metric_inverse, problem.external_torque - problem.coriolis - ca.mtimes(M, fixed))
    exact = problem.levels[: structure.exact_levels]
    commands = [Affine(level.target, ca.SX(level.dim, 0)) for level in exact]
    hierarchy, N = recursive_hierarchy(problem, commands, 0, metric_inverse, free_acceleration, W)
    if not structure.least_squares_last:
        return hierarchy.offset
    return least_squares_step(problem.levels[-1], hierarchy.offset, N, M)


def projector(problem: ControlProblem) -> ControlLaw:
    n = problem.n
    lower, upper = _joint_bounds(problem)
    structure = level_structure(problem)
    free = ca.SX.ones(n)
    locked_acceleration = ca.SX.zeros(n)
    acceleration = _locked_hierarchy(problem, structure, free, locked_acceleration)
    for _ in range(n):
        violation = free * ca.fmax(ca.fmax(acceleration - upper, lower - acceleration), 0.0)
        # one-hot of the joint exceeding its bounds most (none if no free joint exceeds them)
        worst = ca.SX.zeros(n)
        worst[0] = 1.0
        largest = violation[0]
        for j in range(1, n):
            pick = ca.SX.zeros(n)
            pick[j] = 1.0
            worst = ca.if_else(violation[j] > largest, pick, worst)
            largest = ca.fmax(largest, violation[j])
        worst = worst * (largest > 0)
        free = free * (1.0 - worst)
        locked_acceleration = locked_acceleration + worst * (ca.fmin(ca.fmax(acceleration, lower), upper) - locked_acceleration)
        acceleration = _locked_hierarchy(problem, structure, free, locked_acceleration)
    torque = Affine.constant(problem.torque(acceleration), 0)
    scaling = Affine.constant(ca.SX.ones(len(problem.levels)), 0)
    return ControlLaw(torque, scaling, enforces_torque_limits=False)
