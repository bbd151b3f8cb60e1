"""The `parameters` section: which compiled values the firmware may change at run time.

    parameters:
      ramp_time: 0.005            # s; a new set is reached linearly over this time (default 5 periods)
      tasks:
        tool_position: [kp, kd, reference, activation]
        posture: [kp]
      limits: [joint_velocity, joint_torque, cartesian]

The compiled values are the defaults. Gains and references take any value in their range; the
limits only narrow: a run-time limit stays within what was compiled (the envelope).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from .types import Number, Range, StrictModel

TaskParameter = Literal["kp", "kd", "max_velocity", "reference", "activation"]
LimitGroup = Literal["joint_position", "joint_velocity", "joint_acceleration", "joint_torque", "cartesian"]
# A task's fields in the order they sit in the parameter vector.
TASK_PARAMETER_ORDER: tuple[str, ...] = ("kp", "kd", "max_velocity", "reference", "activation")
LIMIT_GROUP_ORDER: tuple[str, ...] = ("joint_position", "joint_velocity", "joint_acceleration", "joint_torque",
                                      "cartesian")
DEFAULT_RAMP_PERIODS = 5


class ParametersSpec(StrictModel):
    """Values of the compiled controller that can be changed at run time, without a bump."""

    ramp_time: Annotated[Number, Range(0, 1e3, "s")] | None = Field(
        None, description="a new parameter set is reached linearly over this time, s (0: at the next step); "
        f"default: {DEFAULT_RAMP_PERIODS} control periods", examples=[0.005, 0.05])
    tasks: dict[str, list[TaskParameter]] = Field(
        default_factory=dict, description=(
            "per task name, its run-time values: kp, kd, max_velocity (gains), reference (a constant reference), "
            "activation (0 to 1: how much of the task acts; 0 frees its directions for the levels below)"),
        examples=[{"tool_position": ["kp", "kd", "activation"], "posture": ["kp"]}])
    limits: list[LimitGroup] = Field(
        default_factory=list, description=(
            "limit groups whose values are run-time parameters, narrowing only: joint_position (min, max), "
            "joint_velocity, joint_acceleration, joint_torque (max), cartesian (each bound's min and max)"),
        examples=[["joint_velocity", "joint_torque"]])

    def ramp(self, period: float) -> float:
        """The ramp time in s (the default: a few control periods)."""
        return DEFAULT_RAMP_PERIODS * period if self.ramp_time is None else float(self.ramp_time)

    def task_fields(self, task: str) -> tuple[str, ...]:
        """A task's run-time fields in vector order (none if it has none)."""
        given = set(self.tasks.get(task, ()))
        return tuple(f for f in TASK_PARAMETER_ORDER if f in given)

    def limit_groups(self) -> tuple[str, ...]:
        given = set(self.limits)
        return tuple(g for g in LIMIT_GROUP_ORDER if g in given)
