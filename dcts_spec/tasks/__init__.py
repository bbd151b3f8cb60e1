"""Tasks: one module per type, built from the spec's task entries."""

from __future__ import annotations

import numpy as np

from ..robot.model import Robot
from ..spec.tasks import TaskSpec
from ..spec.types import as_list
from ..limits.naming import joint_unit
from ..spec.units import joint_to_si, to_si
from .base import ReferenceInput, Task, TaskTerms
from .cartesian import CartesianTask, OrientationTask, PoseTask, PositionTask
from .joint import JointTask

CARTESIAN_TYPES: dict[str, type[CartesianTask]] = {
    "position": PositionTask,
    "orientation": OrientationTask,
    "pose": PoseTask,
}


def task_joints(spec: TaskSpec, robot: Robot) -> list[str]:
    """Joints of a joint task (all joints by default)."""
    return list(spec.joints) if spec.joints is not None else robot.joint_names


def task_dimension(spec: TaskSpec, robot: Robot) -> int:
    return spec.cartesian_dimension or len(task_joints(spec, robot))


def make_task(spec: TaskSpec, robot: Robot) -> Task:
    """The task object of a validated spec entry (references converted to SI)."""
    dim = task_dimension(spec, robot)
    ref = spec.reference
    common = dict(
        kp=np.array(as_list(spec.gains.kp, dim)),
        kd=np.array(as_list(spec.gains.kd, dim)),
        max_velocity=spec.gains.max_velocity,
        reference_is_input=bool(ref and ref.input),
        feedforward=bool(ref and ref.feedforward),
    )
    if spec.type == "joint":
        names = task_joints(spec, robot)
        indices = [robot.joint_names.index(j) for j in names]
        q = None if ref is None or ref.q is None else np.array(joint_to_si(list(ref.q), ref.unit,
                                                                           robot.prismatic[indices]))
        units = [joint_unit(robot, j) for j in indices]
        wrapped = [unit == "rad" and robot.limits.unbounded(j) for unit, j in zip(units, indices, strict=True)]
        return JointTask(spec.name, spec.priority, indices, names, robot.nv, q=q, units=units, wrapped=wrapped,
                         **common)
    position = None if ref is None or ref.position is None else np.array(ref.position)
    rpy = None if ref is None or ref.rpy is None else np.array(to_si(list(ref.rpy), ref.unit))
    return CARTESIAN_TYPES[spec.type](
        spec.name, spec.priority, spec.frame or "", spec.axis_names, position=position, rpy=rpy, **common
    )


__all__ = [
    "CartesianTask",
    "JointTask",
    "OrientationTask",
    "PoseTask",
    "PositionTask",
    "ReferenceInput",
    "Task",
    "TaskTerms",
    "make_task",
    "task_dimension",
    "task_joints",
]
