"""The `limits` section: joint and Cartesian bounds."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from .types import FieldError, Number, ScalarOrVector, StrictModel
from .units import AngleUnit, AngularAccelerationUnit, AngularVelocityUnit


class JointPositionLimits(StrictModel):
    min: ScalarOrVector | None = None
    max: ScalarOrVector | None = None
    unit: AngleUnit = "rad"
    allow_outside_urdf: bool = Field(False, description="accept limits wider than the URDF's (with a warning)")

    @model_validator(mode="after")
    def _some_bound(self) -> "JointPositionLimits":
        if self.min is None and self.max is None:
            raise ValueError("give `min`, `max` or both")
        return self


class JointVelocityLimits(StrictModel):
    max: ScalarOrVector
    unit: AngularVelocityUnit = "rad/s"
    allow_outside_urdf: bool = False


class JointAccelerationLimits(StrictModel):
    max: ScalarOrVector
    unit: AngularAccelerationUnit = "rad/s^2"


class JointTorqueLimits(StrictModel):
    max: ScalarOrVector
    unit: Literal["Nm"] = "Nm"
    allow_outside_urdf: bool = False


class CartesianLimit(StrictModel):
    """Bounds on a frame's origin along a world axis (the paper's limited space) or along a plane's
    normal: min ≤ n̂ᵀp ≤ max, i.e. the origin stays between two parallel planes (a half-space with
    only one of them)."""

    frame: str
    axis: Literal["x", "y", "z"] | None = Field(None, description="a world axis; or give `normal`")
    normal: list[Number] | None = Field(
        None, min_length=3, max_length=3,
        description="the plane's normal (3 values, any length: it is normalized); min/max are distances along it, m")
    expressed_in: str | None = Field(
        None, description="a frame fixed to the world (the base, or a frame you define on it) in which normal, "
                          "min and max are given; default: world")
    min: Number | None = None
    max: Number | None = None
    max_velocity: Number | None = Field(None, gt=0, description="m/s, optional")
    max_acceleration: Number = Field(5.0, gt=0, description="braking acceleration assumed by the viability bound, m/s²")

    @model_validator(mode="after")
    def _some_bound(self) -> "CartesianLimit":
        if self.min is None and self.max is None:
            raise ValueError("give `min`, `max` or both")
        if self.min is not None and self.max is not None and self.min >= self.max:
            raise FieldError("min", f"min ({self.min}) must be smaller than max ({self.max})")
        if (self.axis is None) == (self.normal is None):
            raise ValueError("give either `axis` (x, y or z) or `normal` (3 values)")
        if self.normal is not None and not sum(v * v for v in self.normal) > 1e-12:
            raise FieldError("normal", f"the normal must not be zero, got {self.normal}")
        return self


class LimitsSpec(StrictModel):
    joint_position: JointPositionLimits | None = None
    joint_velocity: JointVelocityLimits | None = None
    joint_acceleration: JointAccelerationLimits | None = None
    joint_torque: JointTorqueLimits | None = None
    cartesian: list[CartesianLimit] = Field(default_factory=list)
