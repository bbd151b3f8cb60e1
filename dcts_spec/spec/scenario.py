"""The `scenario` section: what `dcts simulate` runs."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from .types import Integer, Number, NumberList, ScalarOrVector, StrictModel, Vec3
from .units import AngleUnit


class ForceDisturbance(StrictModel):
    """A force and/or torque (world axes) applied at a point of a body during a time window."""

    type: Literal["force"]
    body: str = Field(description="link or frame the force acts on")
    point: Vec3 = Field((0.0, 0.0, 0.0), description="application point in the body's frame, m")
    force: Vec3 = Field((0.0, 0.0, 0.0), description="force in world axes, N")
    torque: Vec3 = Field((0.0, 0.0, 0.0), description="torque in world axes, Nm")
    start: Number = Field(ge=0, description="s")
    duration: Number = Field(gt=0, description="s")


class JointTorqueDisturbance(StrictModel):
    """External joint torques (e.g. a person pushing) during a time window."""

    type: Literal["joint_torque"]
    torque: NumberList = Field(description="one value per joint, Nm")
    start: Number = Field(ge=0)
    duration: Number = Field(gt=0)
    ramp: Number = Field(0.0, ge=0, description="rise and fall time, s")


Disturbance = Annotated[ForceDisturbance | JointTorqueDisturbance, Field(discriminator="type")]


class Payload(StrictModel):
    """A mass the controller does not know about, rigidly attached at a frame (simulation only)."""

    frame: str
    mass: Number = Field(gt=0, description="kg")
    com: Vec3 = Field((0.0, 0.0, 0.0), description="centre of mass in the frame, m")


class Waypoints(StrictModel):
    """A path of points fed one after the other to a task with `reference: {input: true}`."""

    task: str
    points: list[NumberList] = Field(min_length=1)
    tolerance: Number = Field(gt=0, description="a point counts as reached within this distance")
    unit: AngleUnit = Field("rad", description="unit of angles in the points (orientation/joint tasks)")


class ExternalTorqueSensing(StrictModel):
    """How the controller's τ_ext input is produced from the simulated external torque."""

    mode: Literal["ideal", "ignored", "noisy"] = "ideal"
    noise_std: ScalarOrVector = Field(0.0, description="Gaussian noise, Nm")
    bias: ScalarOrVector = Field(0.0, description="constant offset, Nm")
    seed: Integer = 0


class ModelMismatch(StrictModel):
    """Differences between the simulated robot and the controller's model."""

    mass_scale: Number = Field(1.0, gt=0, description="the controller's link masses and inertias are scaled by this")


class ScenarioSpec(StrictModel):
    duration: Number = Field(gt=0, description="s")
    initial_q: NumberList | None = Field(None, description="default: the middle of the joint range")
    initial_dq: NumberList | None = None
    unit: AngleUnit = Field("rad", description="unit of initial_q and initial_dq (per s)")
    disturbances: list[Disturbance] = Field(default_factory=list)
    payloads: list[Payload] = Field(default_factory=list)
    waypoints: Waypoints | None = None
    external_torque: ExternalTorqueSensing | Literal["ideal", "ignored", "noisy"] = "ideal"
    model_mismatch: ModelMismatch | None = None
    substeps: Integer = Field(1, ge=1, description="simulation steps per control period (the step is period/substeps)")
    integrator: Literal["euler", "implicitfast", "implicit", "rk4"] = Field(
        "rk4",
        description="MuJoCo integrator; rk4 integrates the torque held over the period as a real robot "
        "does (the limits are shaped for x + T v + ½T²a), the Euler-type ones move x by T²a",
    )

    @property
    def sensing(self) -> ExternalTorqueSensing:
        if isinstance(self.external_torque, str):
            return ExternalTorqueSensing(mode=self.external_torque)
        return self.external_torque
