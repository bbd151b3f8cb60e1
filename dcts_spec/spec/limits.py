"""The `limits` section: joint and Cartesian bounds."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from .collision import CollisionSpec
from .types import JOINT_VALUE, LENGTH, FieldError, Flag, Number, Range, ScalarOrVector, StrictModel
from .units import AngleUnit, AngularAccelerationUnit, AngularVelocityUnit

_ALLOW_OUTSIDE_URDF = "accept limits wider than the URDF's (with a warning) instead of refusing them"


class JointPositionLimits(StrictModel):
    """Joint position bounds min ≤ q ≤ max, replacing the URDF's (narrower unless allowed)."""

    min: Annotated[ScalarOrVector, JOINT_VALUE] | None = Field(None, description="lower bound in `unit` (rad or deg; m for a prismatic "
                                       "joint), one value or one per joint; default: the URDF's",
                                       examples=[-160, [-165, -115, -165, -115, -165, -115, -170]])
    max: Annotated[ScalarOrVector, JOINT_VALUE] | None = Field(None, description="upper bound in `unit` (rad or deg; m for a prismatic "
                                       "joint), one value or one per joint; default: the URDF's",
                                       examples=[160, [165, 115, 165, 115, 165, 115, 170]])
    unit: AngleUnit = Field("rad", description="unit of min and max", examples=["deg"])
    allow_outside_urdf: Flag = Field(False, description=_ALLOW_OUTSIDE_URDF, examples=[False])

    @model_validator(mode="after")
    def _some_bound(self) -> "JointPositionLimits":
        if self.min is None and self.max is None:
            raise ValueError("give `min`, `max` or both")
        return self


class JointVelocityLimits(StrictModel):
    """Joint velocity bounds |q̇| ≤ max."""

    max: Annotated[ScalarOrVector, Range(0, 1e4, open=True)] = Field(description="in `unit` (rad/s or deg/s; m/s for a prismatic joint), one value or "
                                "one per joint", examples=[1.5, [100, 110, 100, 130, 130, 180, 180]])
    unit: AngularVelocityUnit = Field("rad/s", description="unit of max", examples=["deg/s"])
    allow_outside_urdf: Flag = Field(False, description=_ALLOW_OUTSIDE_URDF, examples=[False])


class JointAccelerationLimits(StrictModel):
    """Joint acceleration bounds |q̈| ≤ max (the URDF has none)."""

    max: Annotated[ScalarOrVector, Range(0, 1e7, open=True)] = Field(description="in `unit` (rad/s² or deg/s²; m/s² for a prismatic joint), one value "
                                "or one per joint", examples=[20, [500, 500, 600, 600, 800, 800, 1000]])
    unit: AngularAccelerationUnit = Field("rad/s^2", description="unit of max", examples=["deg/s^2"])


class JointTorqueLimits(StrictModel):
    """Joint torque bounds |τ| ≤ max."""

    max: Annotated[ScalarOrVector, Range(0, 1e6, "Nm (N for a prismatic joint)", open=True)] = Field(description="in Nm (N for a prismatic joint), one value or one per joint",
                                examples=[100, [176, 176, 110, 110, 110, 40, 40]])
    unit: Literal["Nm"] = Field("Nm", description="unit of max: Nm", examples=["Nm"])
    allow_outside_urdf: Flag = Field(False, description=_ALLOW_OUTSIDE_URDF, examples=[False])


class CartesianLimit(StrictModel):
    """Bounds on a frame's origin along a world axis (the paper's limited space) or along a plane's
    normal: min ≤ n̂ᵀp ≤ max, i.e. the origin stays between two parallel planes (a half-space with
    only one of them)."""

    frame: str = Field(description="the robot frame (link, joint or spec frame) whose origin is bounded",
                       examples=["tool", "link7"])
    axis: Literal["x", "y", "z"] | None = Field(None, description="a world axis; or give `normal`", examples=["z"])
    normal: list[Annotated[Number, Range(-1e6, 1e6)]] | None = Field(
        None, min_length=3, max_length=3,
        description="the plane's normal (3 values, unitless, any length: it is normalized); min/max are distances "
                    "along it, m",
        examples=[[1, 1, 0]])
    expressed_in: str | None = Field(
        None, description="a frame fixed to the world (the base, or a frame you define on it) in which normal, "
                          "min and max are given; default: world", examples=["table"])
    min: Annotated[Number, LENGTH] | None = Field(None, description="lower bound of the coordinate along the axis or normal, m",
                               examples=[0.1])
    max: Annotated[Number, LENGTH] | None = Field(None, description="upper bound of the coordinate along the axis or normal, m",
                               examples=[0.8])
    max_velocity: Annotated[Number, Range(0, 1e3, "m/s", open=True)] | None = Field(None, description="bound on the frame's speed along the axis or "
                                        "normal, m/s; optional", examples=[0.5])
    max_acceleration: Annotated[Number, Range(0, 1e5, "m/s²", open=True)] = Field(5.0, description="braking acceleration assumed by the viability bound, m/s²",
                                     examples=[5.0])

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
    """Bounds the controller keeps (joint bounds default to the URDF's)."""

    joint_position: JointPositionLimits | None = Field(
        None, description="joint position bounds; default: the URDF's", examples=[{"min": -160, "max": 160, "unit": "deg"}])
    joint_velocity: JointVelocityLimits | None = Field(
        None, description="joint velocity bounds; default: the URDF's", examples=[{"max": 90, "unit": "deg/s"}])
    joint_acceleration: JointAccelerationLimits | None = Field(
        None, description="joint acceleration bounds; default: none", examples=[{"max": 20}])
    joint_torque: JointTorqueLimits | None = Field(
        None, description="joint torque bounds; default: the URDF's effort limits", examples=[{"max": 100}])
    joint_braking: Literal["acceleration_limit", "torque_limited"] = Field(
        "acceleration_limit", description="the deceleration the joint position bounds count on to stop a joint in "
        "time: `acceleration_limit`, its acceleration limit (10 rad/s² without one; Del Prete 2018, as the paper), "
        "which near a bound gravity pulls the joint toward can ask for more braking than the torques give (the "
        "bound then gives way, status \"limits relaxed\"); `torque_limited`, less where the joint's own torque "
        "limit gives less on the way to the bound, the other joints still, so such a joint slows down earlier: it "
        "stops a loaded arm inside its joint limits, but where the other joints must move it can ask for braking "
        "the arm does not have, and another bound gives way instead (docs/formulations.md)",
        examples=["torque_limited"])
    cartesian: list[CartesianLimit] = Field(
        default_factory=list, description="bounds on frame origins (planes the frames stay between)",
        examples=[[{"frame": "tool", "axis": "z", "min": 0.1}]])
    collision: CollisionSpec | None = Field(
        None, description="links kept apart from each other and from obstacles (hard distance bounds); default: none",
        examples=[{"obstacles": {"table": {"type": "plane", "normal": [0, 0, 1], "point": [0, 0, 0.1]}}}])
