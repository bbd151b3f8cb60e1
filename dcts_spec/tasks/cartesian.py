"""Shared part of the Cartesian tasks: rows of the world-aligned frame Jacobian [v; ω]."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..symbolic import SymbolicRobot
from .base import Task
from .so3 import orientation_error, orientation_rows, rpy_to_matrix

# Row of each axis in the world-aligned 6-D velocity [v_x v_y v_z ω_x ω_y ω_z].
AXIS_ROW = {"x": 0, "y": 1, "z": 2, "rx": 3, "ry": 4, "rz": 5}
TRANSLATION = ("x", "y", "z")


class CartesianTask(Task):
    """A task on the selected axes of a frame.

    Position axes x, y, z are the world's: the error is p_d − p on the selected ones. Rotation
    axes are the world's when all three are selected (log(R_d Rᵀ)), and otherwise the frame's
    own: [rx, ry] points the frame's z axis like the target's and leaves the spin about it free
    (the swing), [rz] controls only that spin (the twist); see `so3.orientation_error`.
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
        self._error_functions: dict[tuple[str, ...], ca.Function] = {}

    @property
    def dim(self) -> int:
        return len(self.axes)

    @property
    def row_names(self) -> tuple[str, ...]:
        return tuple(f"{self.name}.{a}" for a in self.axes)

    @property
    def row_units(self) -> tuple[str, ...]:
        return tuple("m" if a in TRANSLATION else "rad" for a in self.axes)

    def constant_reference(self) -> dict[str, np.ndarray]:
        out = {}
        if self.position is not None:
            out["position"] = self.position
        if self.rpy is not None:
            out["rpy"] = self.rpy
        return out

    @property
    def _linear(self) -> list[int]:
        return [AXIS_ROW[a] for a in self.axes if a in TRANSLATION]

    @property
    def _angular(self) -> tuple[str, ...]:
        return tuple(a for a in self.axes if a not in TRANSLATION)

    @property
    def _written_order(self) -> list[int]:
        """Where each axis as written sits in [translation rows; rotation rows]."""
        linear, angular = [a for a in self.axes if a in TRANSLATION], list(self._angular)
        return [linear.index(a) if a in TRANSLATION else len(linear) + angular.index(a) for a in self.axes]

    def _rows(self, J6, bias6, rotation):
        """The task Jacobian and bias from the world-aligned frame Jacobian and bias [v; ω]."""
        jacobian, bias = [J6[self._linear, :]], [bias6[self._linear]]
        if self._angular:
            # d/dt (Bᵀω) = Bᵀω̇ + (ω × B)ᵀω = Bᵀω̇: the bias is Bᵀ(J̇q̇)_ω
            B = orientation_rows(rotation, self._angular)
            jacobian.append(ca.mtimes(B.T, J6[3:6, :]))
            bias.append(ca.mtimes(B.T, bias6[3:6]))
        order = self._written_order
        return ca.vertcat(*jacobian)[order, :], ca.vertcat(*bias)[order]

    def _error(self, position, rotation, reference):
        error = [ca.SX.zeros(len(self._linear))]
        if "position" in reference:
            error[0] = (reference["position"] - position)[self._linear]
        if self._angular:
            error.append(orientation_error(rotation, rpy_to_matrix(reference["rpy"]), self._angular)
                         if "rpy" in reference else ca.SX.zeros(len(self._angular)))
        return ca.vertcat(*error)[self._written_order]

    def _terms(self, robot: SymbolicRobot, reference: dict[str, ca.SX]) -> tuple[ca.SX, ca.SX, ca.SX]:
        position, rotation = robot.frame_placement(self.frame)
        jacobian, bias = self._rows(robot.frame_jacobian(self.frame), robot.frame_bias_acceleration(self.frame), rotation)
        error = self._error(position, rotation, reference)
        if len(self._angular) == 1 and "rpy" in reference:
            # A twist ψ changes at ω_k only while the free swing is small: its own gradient makes
            # ψ̈ = J a + J̇q̇ exact, so the PD settles as its gains say at any swing (with ω_k the
            # twist of a 150° swing still had 13 % of its error left after 1 s at kp = 100).
            row = self._written_order.index(len(self._linear))
            gradient = -ca.jacobian(error[row], robot.q)  # the error is target − actual
            jacobian[row, :] = gradient
            bias[row] = ca.jtimes(ca.mtimes(gradient, robot.dq), robot.q, robot.dq)
        return jacobian, bias, error

    def numeric_jacobian(self, J6: np.ndarray, rotation: np.ndarray) -> np.ndarray:
        """The task Jacobian from a numeric world-aligned frame Jacobian (Pinocchio's
        LOCAL_WORLD_ALIGNED) and the frame's rotation."""
        J, _ = self._rows(ca.DM(J6), ca.DM.zeros(6), ca.DM(rotation))
        return np.array(ca.evalf(J))

    def numeric_error(self, position: np.ndarray, rotation: np.ndarray, reference: dict[str, np.ndarray]) -> np.ndarray:
        """The task error Δx at a numeric frame placement, toward `reference` (position, rpy)."""
        fields = tuple(sorted(reference))
        if fields not in self._error_functions:  # built once per field set: a waypoint runner calls this every step
            p, R = ca.SX.sym("p", 3), ca.SX.sym("R", 3, 3)
            symbols = {k: ca.SX.sym(k, 3) for k in fields}
            self._error_functions[fields] = ca.Function("error", [p, R, *symbols.values()], [self._error(p, R, symbols)])
        values = [reference[k] for k in fields]
        return np.array(self._error_functions[fields](position, rotation, *values)).ravel()


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
