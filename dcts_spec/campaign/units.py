"""The units of a campaign report's columns: each swept value, by where the campaign file puts it,
and each metric, as summary.json's `units` gives it. The plots' axes and report.json say them."""

from __future__ import annotations

from typing import Any

from ..analysis.units import combine, level_units, run_units, task_error_units, torque_unit
from ..formulations.problem import ControlProblem
from ..limits.naming import joint_force_unit, joint_unit
from ..robot.model import Robot
from ..spec.errors import KeyPath
from .document import Campaign
from .sampling import Variable

# pushes[i].<field> and payloads[i].<field>
PUSH_UNITS = {"force": "N", "point": "m", "start": "s", "duration": "s"}
PAYLOAD_UNITS = {"mass": "kg", "com": "m"}


def variable_unit(path: KeyPath, robot: Robot, campaign: Campaign, parameter_units: dict[str, str]) -> str:
    """The unit of the swept value at `path` in the campaign file (a per-joint entry's: its joint's;
    a value drawn for every joint: theirs, combined)."""
    section = path[0]
    if section == "pushes":
        return PUSH_UNITS[str(path[2])]
    if section == "payloads":
        return PAYLOAD_UNITS[str(path[2])]
    joint = path[-1] if isinstance(path[-1], int) else None  # (a per-joint entry)
    joints = range(robot.nv) if joint is None else [joint]
    if section == "model_mismatch":
        return "1"
    if section == "external_torque":
        return torque_unit(robot) if joint is None else joint_force_unit(robot, joint)
    if section == "initial_state":
        if path[1] == "within_limits":
            return "1"  # where in its range each joint starts
        state = campaign.initial_state
        angle = state.unit if state is not None else "rad"
        # (a prismatic joint's offset is in m whatever the angle unit)
        return combine(angle if joint_unit(robot, j) == "rad" else "m" for j in joints)
    return parameter_units[str(path[2])]


def column_units(variables: list[Variable], metrics: list[str], robot: Robot, campaign: Campaign,
                 problem: ControlProblem, parameter_units: dict[str, str], primary_task: str) -> dict[str, str]:
    """Column → unit, for the swept values' columns (a per-joint value's components and norm) and the
    report's metrics (name, or name.task for a per-task one; primary_rms_error)."""
    out: dict[str, str] = {}
    for v in variables:
        unit = variable_unit(v.path, robot, campaign, parameter_units)
        out[v.name] = unit
        if v.size > 1:
            out[f"{v.name}.norm"] = unit
            out |= {f"{v.name}[{j}]": variable_unit(v.path + (j,), robot, campaign, parameter_units)
                    for j in range(v.size)}
    units = run_units(task_error_units(problem.levels, robot), level_units(problem.levels, robot), robot)
    for metric in metrics:
        key, _, part = metric.partition(".")
        unit: Any = units["task_rms_error"].get(primary_task) if metric == "primary_rms_error" else units.get(key)
        if isinstance(unit, dict):
            unit = unit.get(part)
        if isinstance(unit, str):
            out[metric] = unit
    return out


def shown(unit: str | None) -> bool:
    """A unit worth writing: not a ratio's "1", not unknown."""
    return bool(unit) and unit != "1"


def labelled(column: str, units: dict[str, str]) -> str:
    """An axis label: `pushes[0].force.magnitude [N]`."""
    unit = units.get(column)
    return f"{column} [{unit}]" if shown(unit) else column


def with_unit(value: str, column: str, units: dict[str, str]) -> str:
    """A value as text with its column's unit: `0.0123 rad/s`."""
    unit = units.get(column)
    return f"{value} {unit}" if shown(unit) else value
