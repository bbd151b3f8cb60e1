"""Model mismatch: the controller's robot differs from the simulated one."""

from __future__ import annotations

import dataclasses

import pinocchio as pin

from ..robot.model import Robot


def scaled_robot(robot: Robot, mass_scale: float) -> Robot:
    """A copy of the robot whose link masses and inertias are multiplied by `mass_scale`.

    Centres of mass stay where they are, so the kinematics and the limits are unchanged.
    """
    if mass_scale == 1.0:
        return robot
    model = robot.model.copy()
    for i, inertia in enumerate(model.inertias):
        model.inertias[i] = pin.Inertia(inertia.mass * mass_scale, inertia.lever, inertia.inertia * mass_scale)
    return dataclasses.replace(robot, model=model)
