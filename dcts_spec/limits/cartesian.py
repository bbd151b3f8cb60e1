"""Cartesian bounds on one world axis of a frame (the paper's limited space, rows of J_c)."""

from __future__ import annotations

import casadi as ca

from ..robot.model import CartesianBound
from ..symbolic import SymbolicRobot
from .base import AccelerationRows
from .viability import acceleration_bounds


def cartesian_rows(bounds: tuple[CartesianBound, ...], robot: SymbolicRobot, dt: float) -> AccelerationRows:
    """c̈_min ≤ J_c a + J̇_c q̇ ≤ c̈_max with c̈ bounds shaped from c, ċ as for joints."""
    parts = []
    for b in bounds:
        position, _ = robot.frame_placement(b.frame)
        jacobian = robot.frame_jacobian(b.frame)[b.axis, :]
        bias = robot.frame_bias_acceleration(b.frame)[b.axis]
        c, c_dot = position[b.axis], ca.mtimes(jacobian, robot.dq)
        lo, hi = acceleration_bounds(c, c_dot, b.c_min, b.c_max, b.v_max, float("inf"), b.a_max, dt)
        parts.append(AccelerationRows(jacobian, bias, lo, hi, [f"cartesian:{b.frame}.{'xyz'[b.axis]}"]))
    return AccelerationRows.stack(parts, robot.nv)
