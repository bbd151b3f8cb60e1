"""Task base class: a Jacobian, a bias J̇q̇, an error, and the desired acceleration from the gains."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..symbolic import SymbolicRobot

# The smallest kd (1/s) the velocity-saturated law divides kp by (`Task._feedback`)
SATURATION_KD_FLOOR = 1e-9


def unit_text(units: tuple[str, ...], suffix: str = "") -> str:
    """The distinct units of some rows, in order: "m/s", or "m/s, rad/s" for a mix."""
    return ", ".join(dict.fromkeys(u + suffix for u in units))


@dataclass(frozen=True)
class ReferenceInput:
    """A slice of the controller's run-time reference vector `ref`."""

    task: str
    field: str  # position | rpy | q | velocity | acceleration
    offset: int
    size: int
    unit: str
    components: tuple[str, ...]

    def to_dict(self) -> dict:
        return {
            "task": self.task,
            "field": self.field,
            "offset": self.offset,
            "size": self.size,
            "unit": self.unit,
            "components": list(self.components),
        }


@dataclass
class TaskParameters:
    """Run-time values (symbols of the controller's `param` input) replacing compiled ones; None:
    the compiled value."""

    kp: ca.SX | None = None
    kd: ca.SX | None = None
    max_velocity: ca.SX | None = None
    reference: dict[str, ca.SX] = field(default_factory=dict)  # constant reference fields


@dataclass
class TaskTerms:
    """Symbolic quantities of one task at the current state."""

    jacobian: ca.SX  # J (m × n)
    bias: ca.SX  # J̇ q̇ (m)
    error: ca.SX  # Δx = x_d − x (m), on SO(3) for rotations
    target: ca.SX  # ẍ_d (m), from the gains


class Task(ABC):
    """One task of the hierarchy; subclasses define its Jacobian, bias and error."""

    def __init__(
        self,
        name: str,
        priority: int,
        kp: np.ndarray,
        kd: np.ndarray,
        max_velocity: float | None = None,
        reference_is_input: bool = False,
        feedforward: bool = False,
    ):
        self.name = name
        self.priority = priority
        self.kp = np.asarray(kp, dtype=float)
        self.kd = np.asarray(kd, dtype=float)
        self.max_velocity = max_velocity
        self.reference_is_input = reference_is_input
        self.feedforward = feedforward

    @property
    @abstractmethod
    def dim(self) -> int:
        """Task dimension m."""

    @abstractmethod
    def reference_fields(self) -> list[tuple[str, int, str, tuple[str, ...]]]:
        """(field, size, unit, component names) of the full reference when it is a run-time input."""

    @abstractmethod
    def _terms(self, robot: SymbolicRobot, reference: dict[str, ca.SX]) -> tuple[ca.SX, ca.SX, ca.SX]:
        """Jacobian, bias J̇q̇ and error Δx, given the reference fields (constants or inputs)."""

    @abstractmethod
    def constant_reference(self) -> dict[str, np.ndarray]:
        """The reference baked into the controller (empty for a pure damping task)."""

    @property
    @abstractmethod
    def row_names(self) -> tuple[str, ...]:
        """Names of the task's rows (axes or joints), for logs and layouts."""

    @property
    @abstractmethod
    def row_units(self) -> tuple[str, ...]:
        """SI unit of each row's coordinate (m or rad), in the order of row_names."""

    def reference_inputs(self, offset: int) -> list[ReferenceInput]:
        """The slices of `ref` this task reads, starting at `offset`."""
        if not self.reference_is_input:
            return []
        fields = list(self.reference_fields())
        if self.feedforward:
            fields += [("velocity", self.dim, unit_text(self.row_units, "/s"), self.row_names),
                       ("acceleration", self.dim, unit_text(self.row_units, "/s²"), self.row_names)]
        out = []
        for field, size, unit, components in fields:
            out.append(ReferenceInput(self.name, field, offset, size, unit, components))
            offset += size
        return out

    def build(self, robot: SymbolicRobot, ref: ca.SX, offset: int, params: TaskParameters | None = None) -> TaskTerms:
        """Symbolic terms of the task; run-time references are read from `ref` at `offset`, run-time
        parameters (gains, a constant reference) from `params`."""
        params = params or TaskParameters()
        if self.reference_is_input:
            reference = {r.field: ref[r.offset : r.offset + r.size] for r in self.reference_inputs(offset)}
        else:
            reference = {k: params.reference.get(k, ca.SX(ca.DM(v))) for k, v in self.constant_reference().items()}
        jacobian, bias, error = self._terms(robot, reference)
        velocity = ca.mtimes(jacobian, robot.dq)
        velocity_ff = reference.get("velocity", ca.SX.zeros(self.dim))
        acceleration_ff = reference.get("acceleration", ca.SX.zeros(self.dim))
        target = acceleration_ff + self._feedback(error, velocity - velocity_ff, params)
        return TaskTerms(jacobian, bias, error, target)

    def _feedback(self, error: ca.SX, velocity_error: ca.SX, params: TaskParameters) -> ca.SX:
        """ẍ_d = kp Δx − kd ẋ, or with `max_velocity` the velocity-saturated law of the paper's
        experiment 3: ẍ_d = −kd (ẋ − v ẋ_d), ẋ_d = (kp/kd) Δx, v = min(1, v_sat/‖ẋ_d‖).

        The paper prints v_sat/‖ẋ_d‖²; that is not a velocity bound (its units are wrong), so the
        usual saturation ‖v ẋ_d‖ ≤ v_sat is used.
        """
        kp = ca.DM(self.kp) if params.kp is None else params.kp
        kd = ca.DM(self.kd) if params.kd is None else params.kd
        if self.max_velocity is None:
            return kp * error - kd * velocity_error
        max_velocity = self.max_velocity if params.max_velocity is None else params.max_velocity
        # (kd floored where it divides: a kd of 0, or a denormal one set at run time, made kp/kd
        # infinite and every step fall back; below the floor the law is ẍ_d ≈ 0 either way)
        desired_velocity = (kp / ca.fmax(kd, SATURATION_KD_FLOOR)) * error
        speed = ca.norm_2(desired_velocity)
        v = ca.fmin(1.0, max_velocity / ca.fmax(speed, 1e-12))
        return -kd * (velocity_error - v * desired_velocity)
