"""Shared part of the Cartesian tasks: rows of the world-aligned frame Jacobian [v; ω]."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..symbolic import SymbolicRobot
from .base import Task
from .so3 import log3, rpy_to_matrix

# Row of each axis in the world-aligned 6-D velocity [v_x v_y v_z ω_x ω_y ω_z].
AXIS_ROW = {"x": 0, "y": 1, "z": 2, "rx": 3, "ry": 4, "rz": 5}


class CartesianTask(Task):
    """A task on the selected axes of a frame, in world axes.

    The error is [p_d − p; log(R_d Rᵀ)] (world axes) and `axes` select its rows, so an
    orientation task on (rx, ry) drives the rotation about world x and y only.
    """

    def __init__(
        self,
        name: str,
        priority: int,
        frame: str,
        axes: tuple[str, ...],
        position: np.ndarray | None = None,
        rpy: np.ndarray | None = None,
        **kwargs,
    ):
        super().__init__(name, priority, **kwargs)
        self.frame = frame
        self.axes = tuple(axes)
        self.position = None if position is None else np.asarray(position, dtype=float)
        self.rpy = None if rpy is None else np.asarray(rpy, dtype=float)

    @property
    def dim(self) -> int:
        return len(self.axes)

    @property
    def rows(self) -> list[int]:
        """Rows of the 6-D frame Jacobian this task controls."""
        return [AXIS_ROW[a] for a in self.axes]

    @property
    def row_names(self) -> tuple[str, ...]:
        return tuple(f"{self.name}.{a}" for a in self.axes)

    def constant_reference(self) -> dict[str, np.ndarray]:
        out = {}
        if self.position is not None:
            out["position"] = self.position
        if self.rpy is not None:
            out["rpy"] = self.rpy
        return out

    def _terms(self, robot: SymbolicRobot, reference: dict[str, ca.SX]) -> tuple[ca.SX, ca.SX, ca.SX]:
        jacobian = robot.frame_jacobian(self.frame)[self.rows, :]
        bias = robot.frame_bias_acceleration(self.frame)[self.rows]
        position, rotation = robot.frame_placement(self.frame)
        error = ca.SX.zeros(6)
        if "position" in reference:
            error[0:3] = reference["position"] - position
        if "rpy" in reference:
            error[3:6] = log3(ca.mtimes(rpy_to_matrix(reference["rpy"]), rotation.T))
        return jacobian, bias, error[self.rows]


def _position_field() -> tuple[str, int, str, tuple[str, ...]]:
    return ("position", 3, "m", ("x", "y", "z"))


def _rpy_field() -> tuple[str, int, str, tuple[str, ...]]:
    return ("rpy", 3, "rad", ("roll", "pitch", "yaw"))


class PositionTask(CartesianTask):
    """Position of a frame's origin (a world point), any subset of x, y, z."""

    def reference_fields(self):
        return [_position_field()]


class OrientationTask(CartesianTask):
    """Orientation of a frame, any subset of the world rotation axes rx, ry, rz."""

    def reference_fields(self):
        return [_rpy_field()]


class PoseTask(CartesianTask):
    """Position and orientation of a frame, any subset of the six axes."""

    def reference_fields(self):
        return [_position_field(), _rpy_field()]
