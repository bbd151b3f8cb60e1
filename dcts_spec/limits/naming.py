"""How a bound reads in messages and summaries: `0.3 m ≤ tool.z ≤ 0.8 m`, one format everywhere.

`validate` words a Cartesian bound this way in its diagnostics, and the run summary names the
bounds that gave way the same way (their row names, `joint:<joint>` and
`cartesian:<frame>.<label>`, stay the keys of logs and summary.json).
"""

from __future__ import annotations

import numpy as np

from ..robot.collision import CollisionModel
from ..robot.model import CartesianBound, Robot, is_prismatic, unit_of_kind


def interval_text(name: str, lower: float, upper: float, unit: str, digits: int = 4) -> str:
    """`lower unit ≤ name ≤ upper unit`, leaving out a side that is infinite."""
    lo = f"{lower:.{digits}g} {unit} ≤ " if np.isfinite(lower) else ""
    hi = f" ≤ {upper:.{digits}g} {unit}" if np.isfinite(upper) else ""
    return f"{lo}{name}{hi}"


def bound_text(b: CartesianBound) -> str:
    """A Cartesian bound as an interval of the frame's coordinate, in m, then its speed limit."""
    name = f"{b.frame}.{b.label}"
    text = interval_text(name, b.c_min, b.c_max, "m")
    return text + (f", |{name}'| ≤ {b.v_max:.4g} m/s" if np.isfinite(b.v_max) else "")


def joint_bound_text(robot: Robot, j: int) -> str:
    """Joint j's row: its position interval, then its speed limit (rad, or m for a prismatic joint)."""
    name, lim = robot.joint_names[j], robot.limits
    unit = joint_unit(robot, j)
    # (a joint without position limits, as a URDF continuous joint: its speed only)
    unbounded = lim.unbounded(j) and np.isfinite(lim.v_max[j])
    parts = [] if unbounded else [interval_text(name, lim.q_min[j], lim.q_max[j], unit)]
    if np.isfinite(lim.v_max[j]):
        parts.append(f"|{name}'| ≤ {lim.v_max[j]:.4g} {unit}/s")
    return ", ".join(parts)


def joint_unit(robot: Robot, j: int) -> str:
    """"m" for a prismatic joint, "rad" for a revolute one."""
    return unit_of_kind("rad", is_prismatic(robot.model.joints[j + 1]))  # (joint 0 is the universe)


def joint_force_unit(robot: Robot, j: int) -> str:
    """Joint j's torque unit: Nm, or N for a prismatic joint."""
    return unit_of_kind("Nm", is_prismatic(robot.model.joints[j + 1]))


def joint_row_name(joint: str) -> str:
    """The name of a joint's bound row (limits/joint.py), as logs and summary.json key it."""
    return f"joint:{joint}"


def cartesian_row_name(b: CartesianBound) -> str:
    """The name of a Cartesian bound's row (limits/cartesian.py)."""
    return f"cartesian:{b.frame}.{b.label}"


def row_text(robot: Robot, row_name: str, collision: CollisionModel | None = None) -> str:
    """The bound behind a row name, as text; the name itself for a row this robot (or its
    collision model) does not have."""
    for j, joint in enumerate(robot.joint_names):
        if joint_row_name(joint) == row_name:
            return joint_bound_text(robot, j)
    for b in robot.cartesian_bounds:
        if cartesian_row_name(b) == row_name:
            return bound_text(b)
    for pair in collision.pairs if collision is not None else ():
        if pair.name == row_name:
            return f"distance({pair.a.name}, {pair.b.name}) ≥ {pair.min_distance:.4g} m"
    return row_name
