"""The `tasks` list: what the robot should do, by priority."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from .types import IDENTIFIER, JOINT_VALUE, LENGTH, FieldError, Flag, Integer, Number, NumberList, Range, ScalarOrVector, StrictModel, Vec3, size_of
from .units import AngleUnit

TaskType = Literal["position", "orientation", "pose", "joint"]
Axis = Literal["x", "y", "z", "rx", "ry", "rz"]

TRANSLATION_AXES: tuple[str, ...] = ("x", "y", "z")
ROTATION_AXES: tuple[str, ...] = ("rx", "ry", "rz")
ALLOWED_AXES: dict[str, tuple[str, ...]] = {
    "position": TRANSLATION_AXES,
    "orientation": ROTATION_AXES,
    "pose": TRANSLATION_AXES + ROTATION_AXES,
}
REFERENCE_FIELDS: dict[str, tuple[str, ...]] = {
    "position": ("position",),
    "orientation": ("rpy",),
    "pose": ("position", "rpy"),
    "joint": ("q",),
}


class Gains(StrictModel):
    """PD gains of the task's error dynamics ẍ_d = kp Δx − kd ẋ (+ feed-forward)."""

    kp: Annotated[ScalarOrVector, Range(0, 1e8, "1/s²")] = Field(description="stiffness in 1/s², one value or one per task axis (0: a pure damping task)",
                               examples=[100, [100, 100, 200]])
    kd: Annotated[ScalarOrVector, Range(0, 1e5, "1/s")] = Field(description="damping in 1/s, one value or one per task axis", examples=[20, [20, 20, 28]])
    max_velocity: Annotated[Number, Range(0, 1e3, open=True)] | None = Field(
        None, description="saturate the desired velocity (kp/kd)Δx to this norm (m/s, rad/s for orientation "
        "and joint tasks)", examples=[0.25]
    )

    @model_validator(mode="after")
    def _saturation_needs_stiffness(self) -> "Gains":
        if self.max_velocity is not None and not self.has_stiffness():
            raise FieldError("max_velocity", "max_velocity needs kp > 0 (it saturates the velocity (kp/kd)Δx)")
        if self.max_velocity is not None and any(p > 0 and d == 0 for p, d in self.axes()):
            # (the saturated law ẍ_d = kd (v ẋ_d − ẋ) asks for nothing where kd = 0: the task sat still)
            raise FieldError("kd", "max_velocity needs kd > 0 where kp > 0: the velocity-saturated law is "
                             "ẍ_d = kd (v (kp/kd)Δx − ẋ), so an axis with kd = 0 asks for no acceleration")
        return self

    def axes(self) -> list[tuple[float, float]]:
        """(kp, kd) per axis, a scalar standing for every axis; none where their sizes differ (an
        error of validate's, at the task)."""
        kp = self.kp if isinstance(self.kp, tuple) else (self.kp,)
        kd = self.kd if isinstance(self.kd, tuple) else (self.kd,)
        if len(kp) != len(kd) and 1 not in (len(kp), len(kd)):
            return []
        size = max(len(kp), len(kd))
        return list(zip(kp * (size // len(kp)), kd * (size // len(kd))))

    def has_stiffness(self) -> bool:
        values = self.kp if isinstance(self.kp, tuple) else (self.kp,)
        return any(v != 0 for v in values)


class Reference(StrictModel):
    """Target of a task: constant (world frame) or a run-time input of the compiled controller."""

    position: Annotated[Vec3, LENGTH] | None = Field(None, description="target point [x, y, z] of the frame's origin in the world, m",
                                  examples=[[0.5, 0.0, 0.6]])
    rpy: Annotated[Vec3, JOINT_VALUE] | None = Field(None, description="target orientation as roll, pitch, yaw (world), in `unit`",
                             examples=[[180, 0, 0]])
    q: Annotated[NumberList, JOINT_VALUE] | None = Field(None, description="target joint positions in `unit` (m for a prismatic joint), "
                                 "one per joint of the task", examples=[[0, 30, 0, -60, 0, 60, 0]])
    unit: AngleUnit = Field("rad", description="unit of rpy or q", examples=["deg"])
    input: Flag = Field(False, description="the reference is an input of the controller at run time (waypoints "
                        "in simulation)", examples=[True])
    feedforward: Flag = Field(
        False, description="with input: also take a velocity (m/s, rad/s) and an acceleration (m/s², rad/s²) "
        "feed-forward per task axis", examples=[True]
    )

    def given_fields(self) -> tuple[str, ...]:
        return tuple(f for f in ("position", "rpy", "q") if getattr(self, f) is not None)


class TaskSpec(StrictModel):
    """One task: a frame's position and/or orientation, or joint positions, with PD gains and a priority."""

    name: str = Field(pattern=IDENTIFIER, description="identifier (letters, digits, _), unique "
                      "in the spec", examples=["tool_position", "posture"])
    type: TaskType = Field(description="position (3 translation axes), orientation (3 rotation axes), pose (both) "
                           "or joint (joint positions)", examples=["position", "joint"])
    frame: str | None = Field(None, description="frame of a Cartesian task (link, joint or spec frame)",
                              examples=["tool"])
    axes: list[Axis] | None = Field(None, description=(
        "controlled axes; their number is the task dimension. x, y, z: world axes; rx, ry, rz: all three are the "
        "world rotation, one or two are the frame's own axes ([rx, ry]: point the frame's z, its spin free; "
        "[rz]: only the spin about the frame's z); see docs/tasks.md"), examples=[["x", "y"], ["rx", "ry"]])
    joints: list[str] | None = Field(None, description="joints of a joint task (default: all)",
                                     examples=[["joint1", "joint3"]])
    priority: Annotated[Integer, Range(1, 1000)] = Field(description="1 is the highest; tasks may share a level", examples=[1, 2])
    gains: Gains = Field(description="PD gains of the task", examples=[{"kp": 100, "kd": 20}])
    reference: Reference | None = Field(
        None, description="the target; a task with kp ≠ 0 needs one", examples=[{"position": [0.5, 0.0, 0.6]},
                                                                               {"input": True}])

    @model_validator(mode="after")
    def _consistent(self) -> "TaskSpec":
        cartesian = self.type != "joint"
        if cartesian and self.frame is None and "frame" in self.model_fields_set:  # (`frame:` left empty)
            raise FieldError("frame", f"an empty value: a {self.type} task needs the name of a frame")
        if cartesian and self.frame is None:
            raise FieldError("type", f"a {self.type} task needs `frame`")
        if not cartesian and self.frame is not None:
            raise FieldError("frame", "a joint task has no `frame`; use `joints` to choose joints")
        if cartesian and self.joints is not None:
            raise FieldError("joints", f"`joints` is for joint tasks; a {self.type} task uses `frame` and `axes`")
        if not cartesian and self.axes is not None:
            raise FieldError("axes", "`axes` is for Cartesian tasks; a joint task uses `joints`")
        if self.axes is not None:
            allowed = ALLOWED_AXES[self.type]
            wrong = [a for a in self.axes if a not in allowed]
            if wrong:
                raise FieldError("axes", f"axes {wrong} not allowed for a {self.type} task; allowed: {list(allowed)}")
            if len(set(self.axes)) != len(self.axes) or not self.axes:
                raise FieldError("axes", f"axes must be a non-empty list without repeats, got {self.axes}")
        if self.joints is not None and (not self.joints or len(set(self.joints)) != len(self.joints)):
            raise FieldError("joints", f"joints must be a non-empty list without repeats, got {self.joints}")
        self._check_reference()
        self._check_gain_sizes()
        return self

    def _check_reference(self) -> None:
        needs = REFERENCE_FIELDS[self.type]
        if self.reference is None:
            if self.gains.has_stiffness():
                raise FieldError(
                    "gains",
                    f"a task with kp ≠ 0 needs a `reference` ({' and '.join(needs)}, or `input: true`); "
                    "set kp: 0 for a pure damping task"
                )
            return
        given = self.reference.given_fields()
        if self.reference.feedforward and not self.reference.input:
            raise FieldError("reference", "feedforward needs `input: true` (it is read at run time)")
        if self.reference.input:
            if given:
                raise FieldError("reference", f"give either `input: true` or constant values, not both ({', '.join(given)})")
            return
        extra = [f for f in given if f not in needs]
        if extra:
            raise FieldError("reference", f"field {extra[0]!r} does not fit a {self.type} task; it takes {list(needs)}")
        missing = [f for f in needs if f not in given]
        if missing:
            raise FieldError("reference", f"the reference of a {self.type} task needs {missing} (or `input: true`)")

    def _check_gain_sizes(self) -> None:
        dim = self.cartesian_dimension
        if dim is None:
            return
        for name in ("kp", "kd"):
            size = size_of(getattr(self.gains, name))
            if size is not None and size != dim:
                raise FieldError("gains", f"{name} has {size} values but the task has {dim} axes {list(self.axis_names)}")

    @property
    def axis_names(self) -> tuple[str, ...]:
        """Controlled Cartesian axes in the order written (all axes of the type by default)."""
        return ALLOWED_AXES[self.type] if self.axes is None else tuple(self.axes)

    @property
    def cartesian_dimension(self) -> int | None:
        """Task dimension of a Cartesian task; None for joint tasks (it depends on the robot)."""
        return None if self.type == "joint" else len(self.axis_names)
