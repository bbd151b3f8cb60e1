"""Joint task: a posture, or pure joint damping when kp = 0."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..symbolic import SymbolicRobot
from .base import Task, unit_text


class JointTask(Task):
    """Selected joints driven to q_d (or only damped): J is a selection matrix, J̇q̇ = 0.

    A revolute joint without position limits (a URDF continuous joint: robot/urdf.py) takes the
    short way round: its error q_d − q is wrapped into [−π, π], atan2(sin Δ, cos Δ)."""

    def __init__(self, name: str, priority: int, joint_indices: list[int], joint_names: list[str], nv: int,
                 q: np.ndarray | None = None, units: list[str] | None = None, wrapped: list[bool] | None = None,
                 **kwargs):
        super().__init__(name, priority, **kwargs)
        self.joint_indices = list(joint_indices)
        self.joint_names = list(joint_names)
        self.units = tuple(units) if units is not None else ("rad",) * len(self.joint_indices)
        self.wrapped = tuple(wrapped) if wrapped is not None else (False,) * len(self.joint_indices)
        self.nv = nv
        self.q = None if q is None else np.asarray(q, dtype=float)

    @property
    def dim(self) -> int:
        return len(self.joint_indices)

    @property
    def row_names(self) -> tuple[str, ...]:
        return tuple(f"{self.name}.{j}" for j in self.joint_names)

    @property
    def row_units(self) -> tuple[str, ...]:
        return self.units

    def reference_fields(self):
        return [("q", self.dim, unit_text(self.units), tuple(self.joint_names))]

    def constant_reference(self) -> dict[str, np.ndarray]:
        return {} if self.q is None else {"q": self.q}

    def selection_matrix(self) -> np.ndarray:
        """J: picks the task's joints out of q̇."""
        selection = np.zeros((self.dim, self.nv))
        selection[np.arange(self.dim), self.joint_indices] = 1.0
        return selection

    def _terms(self, robot: SymbolicRobot, reference: dict[str, ca.SX]) -> tuple[ca.SX, ca.SX, ca.SX]:
        jacobian = ca.SX(ca.DM(self.selection_matrix()))
        q = robot.q[self.joint_indices]
        if "q" not in reference:
            return jacobian, ca.SX.zeros(self.dim), ca.SX.zeros(self.dim)
        error = reference["q"] - q
        for i in (i for i, wrapped in enumerate(self.wrapped) if wrapped):
            error[i] = ca.atan2(ca.sin(error[i]), ca.cos(error[i]))
        return jacobian, ca.SX.zeros(self.dim), error
