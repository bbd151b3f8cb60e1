"""Units of what a run reports: per joint set, per task, and of every entry of summary.json.

A unit is a string: "rad", "m/s", "Nm", "1" for ratios and factors, "steps" for counts of control
steps. A set of joints or task rows mixing units reads "m, rad" (a norm over both is taken as is).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

from ..limits.naming import joint_force_unit, joint_unit
from ..robot.model import Robot
from ..formulations.problem import Level
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
    "crossed_after_ok_steps": "steps",
    "lowest_level_off_optimum_steps": "steps",
    "crossed_after_ok_first": "s",
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


def torque_unit(robot: Robot) -> str:
    """Nm for revolute joints, N for prismatic ones."""
    return combine(joint_force_unit(robot, j) for j in range(robot.nv))


def joint_peak_units(robot: Robot, joints: Sequence[int] | None = None) -> dict[str, str]:
    """The unit of each summary entry that is a peak over joints (metrics.summarize's per_joint),
    over `joints` (all by default): "Nm", "N" or "N, Nm" for a torque."""
    joints = range(robot.nv) if joints is None else joints
    position = joints_unit(robot, joints)
    force = combine(joint_force_unit(robot, j) for j in joints)
    return {
        "max_joint_position_violation": position,
        "max_joint_velocity_violation": per(position, "s"),
        "max_torque_violation": force,
        "max_torque_jump": force,
        "max_controller_acceleration": per(position, "s²"),
        "max_disturbance_torque": force,
        "max_external_torque_estimate_error": force,
    }


def task_unit(task: Task, robot: Robot) -> str:
    """The unit of a task's rows: "m" (translation axes), "rad" (rotation axes, joints), or both."""
    if isinstance(task, JointTask):
        return joints_unit(robot, task.joint_indices)
    assert isinstance(task, CartesianTask)
    return combine("m" if a in TRANSLATION else "rad" for a in task.axes)


def pure_damping(task: Task) -> bool:
    """No reference at all: the task only damps its velocity (kd), its Δx is 0 by construction;
    its error is reported as a velocity error."""
    return not task.reference_is_input and not task.constant_reference()


def task_error_units(levels: Sequence[Level], robot: Robot) -> dict[str, str]:
    """Task → the unit of its reported error rows: its rows' unit, per s for a pure damping task."""
    return {t.name: per(task_unit(t, robot), "s") if pure_damping(t) else task_unit(t, robot)
            for lv in levels for t in lv.tasks}


def level_units(levels: Sequence[Level], robot: Robot) -> dict[int, str]:
    """Priority → the unit of its rows' positions (its accelerations: per s²)."""
    return {lv.priority: combine(task_unit(t, robot) for t in lv.tasks) for lv in levels}


def run_units(task_units: dict[str, str], levels: dict[int, str], robot: Robot) -> dict[str, Any]:
    """The unit of every numeric entry a run's summary can have (per task or level for the nested
    ones); `summary_units` keeps those of one summary, a campaign's report those of its columns."""
    level_accelerations = {str(p): per(u, "s²") for p, u in levels.items()}
    return {
        **FIXED_UNITS,
        **joint_peak_units(robot),
        "relaxed_bounds": {"steps": "steps", "first": "s", "last": "s"},
        "min_distances": "m",
        "collision_violations": {"min_distance": "m", "by": "m", "steps": "steps", "first": "s", "last": "s"},
        "max_collision_violation": "m",
        "min_scaling_at": {"time": "s"},
        "min_scaling_by_priority": {str(p): "1" for p in levels},
        "primary_mean_acceleration_error": next(iter(level_accelerations.values()), "1"),
        "mean_acceleration_error": level_accelerations,
        **{key: dict(task_units) for key in ("task_rms_error", "task_mean_error", "task_final_error")},
    }
