"""Cartesian bounds: a frame's origin along a world axis or a plane normal (rows of J_c)."""

from __future__ import annotations

import casadi as ca

from ..robot.model import CartesianBound
from ..symbolic import SymbolicRobot
from .base import AccelerationRows
from .naming import cartesian_row_name
from .viability import acceleration_bounds, state_excess


def cartesian_rows(bounds: tuple[CartesianBound, ...], robot: SymbolicRobot, dt: float,
                   offsets: list[tuple] | None = None) -> AccelerationRows:
    """c̈_min ≤ J_c a + J̇_c q̇ ≤ c̈_max with c̈ bounds shaped from c, ċ as for joints. `offsets`:
    (c_min, c_max) per bound where they are run-time parameters."""
    parts = []
    for i, b in enumerate(bounds):
        c_min, c_max = offsets[i] if offsets else (b.c_min, b.c_max)
        position, _ = robot.frame_placement(b.frame)
        d = ca.DM(b.direction)
        jacobian = ca.mtimes(d.T, robot.frame_jacobian(b.frame)[0:3, :])
        bias = ca.dot(d, robot.frame_bias_acceleration(b.frame)[0:3])
        c, c_dot = ca.dot(d, position), ca.mtimes(jacobian, robot.dq)
        lo, hi = acceleration_bounds(c, c_dot, c_min, c_max, b.v_max, float("inf"), b.a_max, dt)
        parts.append(AccelerationRows(jacobian, bias, lo, hi, [cartesian_row_name(b)],
                                      state_excess(c, c_dot, c_min, c_max, b.v_max, lo, hi, dt)))
    return AccelerationRows.stack(parts, robot.nv)
