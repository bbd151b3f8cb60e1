"""The `robot` section: which robot, extra frames, locked joints."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from .types import Number, StrictModel, Vec3
from .units import AngleUnit


class FrameSpec(StrictModel):
    """An extra frame fixed to a link (or to another frame) of the robot."""

    parent: str = Field(description="link, joint or frame the new frame is attached to", examples=["link7"])
    xyz: Vec3 = Field((0.0, 0.0, 0.0), description="position of the frame in its parent, m", examples=[[0, 0.05, 0.08]])
    rpy: Vec3 = Field((0.0, 0.0, 0.0), description="roll, pitch, yaw of the frame in its parent, in `unit`",
                      examples=[[0, 90, 0]])
    unit: AngleUnit = Field("rad", description="unit of rpy", examples=["deg"])


class RobotSpec(StrictModel):
    """A built-in robot (`model`) or any URDF (`urdf`, relative to the spec file)."""

    model: Literal["iiwa14", "panda"] | None = Field(None, description="built-in robot", examples=["iiwa14", "panda"])
    urdf: str | None = Field(None, description="path to a URDF file, relative to the spec file",
                             examples=["robots/my_arm.urdf"])
    frames: dict[str, FrameSpec] = Field(
        default_factory=dict, description="extra frames by name (tool tips, cameras), usable wherever a frame is named",
        examples=[{"camera": {"parent": "link7", "xyz": [0, 0.05, 0.08]}}])
    locked_joints: dict[str, Number] = Field(
        default_factory=dict, description="joints fixed at a value (rad, or m for a prismatic joint), e.g. gripper fingers",
        examples=[{"panda_finger_joint1": 0.02}],
    )

    @model_validator(mode="after")
    def _one_source(self) -> "RobotSpec":
        if (self.model is None) == (self.urdf is None):
            raise ValueError("give exactly one of `model` (iiwa14, panda) or `urdf` (a path)")
        return self
