"""The `robot` section: which robot, extra frames, locked joints, payloads it carries."""

from __future__ import annotations

import re
from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from .types import IDENTIFIER, IDENTIFIER_RULE, JOINT_VALUE, LENGTH, Number, Range, StrictModel, Vec3
from .units import AngleUnit


_NAME_MAX, _PATH_MAX = 255, 4096  # Linux's NAME_MAX and PATH_MAX, the smallest usual limits
# (also the range a campaign's draws of a scenario payload's mass are held to: campaign/document.py)
PAYLOAD_MASS = Range(0, 1e4, "kg", open=True)
PAYLOAD_INERTIA = Range(0, 1e4, "kg·m²")


class Payload(StrictModel):
    """A rigid mass attached at a frame: a tool, a gripper, a part held (`robot.payloads`, which the
    controller models), or one the controller does not know (`scenario.payloads`)."""

    frame: str = Field(description="link or frame the payload is attached to", examples=["tool"])
    mass: Annotated[Number, PAYLOAD_MASS] = Field(description="mass, kg", examples=[2.0])
    com: Annotated[Vec3, LENGTH] = Field((0.0, 0.0, 0.0), description="centre of mass in the frame, m", examples=[[0, 0, 0.05]])
    inertia: tuple[Annotated[Number, PAYLOAD_INERTIA], Annotated[Number, PAYLOAD_INERTIA],
                   Annotated[Number, PAYLOAD_INERTIA]] = Field(
        (0.0, 0.0, 0.0), description=("principal moments of inertia about the centre of mass, along the frame's "
                                      "axes, kg·m² (0: a point mass)"), examples=[[0.004, 0.004, 0.001]])

    @field_validator("inertia")
    @classmethod
    def _a_body_can_have_them(cls, moments: tuple[float, float, float]) -> tuple[float, float, float]:
        """Each moment at most the sum of the other two (the triangle inequality of a rigid body's
        principal moments: MuJoCo refuses others)."""
        a, b, c = moments
        if a > b + c or b > a + c or c > a + b:
            raise ValueError(f"no rigid body has these principal moments: each must be at most the sum of the "
                             f"other two, got {list(moments)}")
        return moments


class FrameSpec(StrictModel):
    """An extra frame fixed to a link (or to another frame) of the robot."""

    parent: str = Field(description="link, joint or frame the new frame is attached to", examples=["link7"])
    xyz: Annotated[Vec3, LENGTH] = Field((0.0, 0.0, 0.0), description="position of the frame in its parent, m", examples=[[0, 0.05, 0.08]])
    rpy: Annotated[Vec3, JOINT_VALUE] = Field((0.0, 0.0, 0.0), description="roll, pitch, yaw of the frame in its parent, in `unit`",
                      examples=[[0, 90, 0]])
    unit: AngleUnit = Field("rad", description="unit of rpy", examples=["deg"])


class RobotSpec(StrictModel):
    """A built-in robot (`model`) or any URDF (`urdf`, relative to the spec file)."""

    model: Literal["iiwa14", "panda"] | None = Field(None, description="built-in robot", examples=["iiwa14", "panda"])
    urdf: str | None = Field(None, description=("path to a URDF file, relative to the spec file; its continuous joints "
                                                "are driven as revolute joints without position limits (one angle each)"),
                             examples=["robots/my_arm.urdf"])
    frames: dict[str, FrameSpec] = Field(
        default_factory=dict, description=("extra frames by name (tool tips, cameras; names as task names: letters, digits, "
                                           "_), usable wherever a frame is named; a parent may be another of them"),
        examples=[{"camera": {"parent": "link7", "xyz": [0, 0.05, 0.08]}}])
    locked_joints: dict[str, Annotated[Number, JOINT_VALUE]] = Field(
        default_factory=dict, description="joints fixed at a value (rad, or m for a prismatic joint), e.g. gripper fingers",
        examples=[{"panda_finger_joint1": 0.02}],
    )
    payloads: list[Payload] = Field(
        default_factory=list, description=(
            "masses the robot carries and the controller models (a tool, a gripper, a part held), each added to "
            "the link its frame is on; the simulation carries them too. A mass it does not know about is a "
            "scenario's payload"),
        examples=[[{"frame": "tool", "mass": 1.2, "com": [0, 0, 0.04]}]])

    @field_validator("urdf")
    @classmethod
    def _a_possible_path(cls, path: str | None) -> str | None:
        """A path the file system can look up (a longer one is an OSError, not 'not found')."""
        if path is None:
            return path
        if not path.strip():
            raise ValueError("an empty path: give the path of a URDF file, relative to the spec file")
        longest = max(len(part.encode()) for part in path.split("/"))
        if longest > _NAME_MAX or len(path.encode()) > _PATH_MAX:
            raise ValueError(f"not a possible file path: a name of at most {_NAME_MAX} bytes, a path of at most "
                             f"{_PATH_MAX}; got a name of {longest} bytes in a path of {len(path.encode())}")
        return path

    @field_validator("frames")
    @classmethod
    def _identifiers(cls, frames: dict[str, FrameSpec]) -> dict[str, FrameSpec]:
        """A frame the spec adds is named as a task is: its name goes into the generated C (comments,
        run-time parameter names), where `*/` ended a comment and broke the build (found from
        outside)."""
        for name in frames:
            if not re.fullmatch(IDENTIFIER, name):
                raise ValueError(f"frame name {name!r} is not an identifier ({IDENTIFIER_RULE})")
        return frames

    @model_validator(mode="after")
    def _one_source(self) -> "RobotSpec":
        if (self.model is None) == (self.urdf is None):
            raise ValueError("give exactly one of `model` (iiwa14, panda) or `urdf` (a path)")
        return self
