"""Units of what a run reports: per joint set, per task, and of every entry of summary.json.

A unit is a string: "rad", "m/s", "Nm", "1" for ratios and factors, "steps" for counts of control
steps. A set of joints or task rows mixing units reads "m, rad" (a norm over both is taken as is).
"""

from __future__ import annotations

from collections.abc import Iterable

from ..limits.naming import joint_unit
from ..robot.model import Robot
from ..tasks import CartesianTask, JointTask, Task

TRANSLATION = ("x", "y", "z")

# summary.json entries whose unit does not depend on the robot or the tasks.
FIXED_UNITS: dict[str, str] = {
    "period": "s",
    "substeps": "1",
    "mass_scale": "1",
    "duration": "s",
    "steps": "steps",
    "diverged_at": "s",
    "max_joint_velocity_violation_ratio": "1",
    "max_cartesian_violation": "m",
    "max_cartesian_velocity_violation": "m/s",
    "max_torque_jump_ratio": "1",
    "torque_jump_steps": "steps",
    "solver_failures": "steps",
    "limits_relaxed": "steps",
    "min_scaling": "1",
    "acceleration_energy_integral": "J/s",  # ∫ ½(τ−g)ᵀM⁻¹(τ−g) dt, ½(τ−g)ᵀM⁻¹(τ−g) in J/s²
    "kinetic_energy_peak": "J",
    "task_space_kinetic_energy_peak": "J",
    "null_space_kinetic_energy_peak": "J",
    "waypoints_total": "1",
    "waypoints_reached": "1",
    "waypoint_times": "s",
    "wall_time": "s",
    "realtime_factor": "1",
}


def combine(units: Iterable[str]) -> str:
    """Distinct units in order of appearance, e.g. "m, rad"."""
    return ", ".join(dict.fromkeys(u for text in units for u in text.split(", ")))


def per(unit: str, denominator: str) -> str:
    """Each unit of a combination divided: per("m, rad", "s²") == "m/s², rad/s²"."""
    return combine(f"{u}/{denominator}" for u in unit.split(", "))


def joints_unit(robot: Robot, joints: Iterable[int] | None = None) -> str:
    """The unit of joint positions: "rad", "m" (prismatic) or "rad, m"."""
    return combine(joint_unit(robot, j) for j in (range(robot.nv) if joints is None else joints))


def joint_force_unit(robot: Robot, j: int) -> str:
    """Joint j's torque unit: Nm, or N for a prismatic joint."""
    return "Nm" if joint_unit(robot, j) == "rad" else "N"


def torque_unit(robot: Robot) -> str:
    """Nm for revolute joints, N for prismatic ones."""
    return combine(joint_force_unit(robot, j) for j in range(robot.nv))


def task_unit(task: Task, robot: Robot) -> str:
    """The unit of a task's rows: "m" (translation axes), "rad" (rotation axes, joints), or both."""
    if isinstance(task, JointTask):
        return joints_unit(robot, task.joint_indices)
    assert isinstance(task, CartesianTask)
    return combine("m" if a in TRANSLATION else "rad" for a in task.axes)
