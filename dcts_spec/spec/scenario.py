"""The `scenario` section: what `dcts simulate` runs."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from .types import DURATION, JOINT_VALUE, LENGTH, TIME, TORQUE, Integer, Number, NumberList, Range, ScalarOrVector, StrictModel, Vec3
from .robot import Payload
from .units import AngleUnit


class ForceDisturbance(StrictModel):
    """A force and/or torque (world axes) applied at a point of a body during a time window."""

    type: Literal["force"] = Field(description="force: a wrench on a body", examples=["force"])
    body: str = Field(description="link or frame the force acts on", examples=["link7"])
    point: Annotated[Vec3, LENGTH] = Field((0.0, 0.0, 0.0), description="application point in the body's frame, m",
                        examples=[[0, 0, 0.045]])
    force: Annotated[Vec3, Range(-1e6, 1e6, "N")] = Field((0.0, 0.0, 0.0), description="force in world axes, N", examples=[[10, 0, 0]])
    torque: Annotated[Vec3, TORQUE] = Field((0.0, 0.0, 0.0), description="torque in world axes, Nm", examples=[[0, 0, 1]])
    start: Annotated[Number, TIME] = Field(description="when it starts, s after the start of the run", examples=[0.5])
    duration: Annotated[Number, DURATION] = Field(description="how long it lasts, s", examples=[0.4])


class JointTorqueDisturbance(StrictModel):
    """External joint torques (e.g. a person pushing) during a time window."""

    type: Literal["joint_torque"] = Field(description="joint_torque: torques on the joints", examples=["joint_torque"])
    torque: Annotated[NumberList, TORQUE] = Field(description="one value per joint, Nm (N for a prismatic joint)",
                               examples=[[0, 5, 0, -5, 0, 0, 0]])
    start: Annotated[Number, TIME] = Field(description="when it starts, s after the start of the run", examples=[1.0])
    duration: Annotated[Number, DURATION] = Field(description="how long it lasts (ramps included), s", examples=[2.0])
    ramp: Annotated[Number, TIME] = Field(0.0, description="rise and fall time, s", examples=[0.2])


Disturbance = Annotated[ForceDisturbance | JointTorqueDisturbance, Field(discriminator="type")]


# Ranges a campaign's draws for these keys are held to as well (campaign/document.py; a payload's
# mass: robot.PAYLOAD_MASS)
NOISE_STD = Range(0, 1e6, "Nm")
MASS_SCALE = Range(0, 1e3, open=True)


class Waypoints(StrictModel):
    """A path of points fed one after the other to a task with `reference: {input: true}`."""

    task: str = Field(description="name of the task that follows the points", examples=["tool_position"])
    points: list[Annotated[NumberList, JOINT_VALUE]] = Field(min_length=1, description=(
        "the points, each the task's reference: [x, y, z] in m for a position task, roll, pitch, yaw in `unit` "
        "for an orientation task, both for a pose, joint positions in `unit` for a joint task"),
        examples=[[[0.5, 0.2, 0.5], [0.5, -0.2, 0.5]]])
    tolerance: Annotated[Number, Range(0, 1e3, open=True)] = Field(description="a point counts as reached when the norm of the task error is within "
                              "this, m (rad for orientation and joint tasks, whatever `unit`)", examples=[0.01])
    unit: AngleUnit = Field("rad", description="unit of angles in the points (orientation/joint tasks)",
                            examples=["deg"])


class ExternalTorqueSensing(StrictModel):
    """How the controller's τ_ext input is produced from the simulated external torque."""

    mode: Literal["ideal", "ignored", "noisy"] = Field(
        "ideal", description="ideal: the true external torque (Nm); ignored: zero; noisy: with noise_std and bias",
        examples=["noisy"])
    noise_std: Annotated[ScalarOrVector, NOISE_STD] = Field(0.0, description="Gaussian noise (standard deviation), Nm, one value or one "
                                      "per joint", examples=[0.5])
    bias: Annotated[ScalarOrVector, TORQUE] = Field(0.0, description="constant offset, Nm, one value or one per joint", examples=[0.2])
    seed: Annotated[Integer, Range(0, 2**32 - 1)] = Field(0, description="seed of the noise generator (unitless)", examples=[0, 42])


class ModelMismatch(StrictModel):
    """Differences between the simulated robot and the controller's model."""

    mass_scale: Annotated[Number, MASS_SCALE] = Field(1.0, description="the controller's link masses and inertias are scaled by this "
                               "factor (unitless)", examples=[1.1])


class ParameterChange(StrictModel):
    """Run-time parameters given to the controller at a time of the run (ramped in from there)."""

    time: Annotated[Number, TIME] = Field(description="when, s after the start of the run", examples=[1.0])
    values: dict[str, ScalarOrVector] = Field(
        min_length=1, description="parameter (as the bundle's header names it: tool.kp, tool.activation, "
        "joint_torque.max, ...) to its value, or one value per component; SI units (rad, not deg)",
        examples=[{"tool_position.kp": 400, "tool_position.activation": 0}])


# A run's log keeps every control step (~0.5 kB each for a 7-joint arm): 10⁷ is the longest
# duration at the default period. A 1e-5 s period with the longest duration asked for 10⁹ steps,
# and the log for 7.5 GB or more (first seen from outside).
MAX_RUN_STEPS = 10_000_000


def run_steps_problem(duration: float, period: float) -> str | None:
    """What is wrong with a run of `duration` at `period`, if it has too many steps."""
    steps = duration / period
    if steps <= MAX_RUN_STEPS:
        return None
    return (f"{duration:g} s at a period of {period:g} s is {steps:.3g} control steps, more than a run's log keeps "
            f"({MAX_RUN_STEPS:.0e}): at most {MAX_RUN_STEPS * period:g} s at this period")


class ScenarioSpec(StrictModel):
    """A simulated run: its length, start, disturbances, payloads, waypoints and sensing."""

    duration: Annotated[Number, DURATION] = Field(description="length of the run, s", examples=[2.0])
    initial_q: Annotated[NumberList, JOINT_VALUE] | None = Field(None, description="initial joint positions in `unit`, one per joint; "
                                         "default: the middle of the joint range", examples=[[0, 30, 0, -60, 0, 60, 0]])
    initial_dq: Annotated[NumberList, Range(-1e4, 1e4)] | None = Field(None, description="initial joint velocities in `unit` per s, one per "
                                          "joint; default: 0", examples=[[0, 0, 0, 10, 0, 0, 0]])
    unit: AngleUnit = Field("rad", description="unit of initial_q and initial_dq (per s)", examples=["deg"])
    disturbances: list[Disturbance] = Field(
        default_factory=list, description="pushes: forces on bodies or torques on joints, each in a time window",
        examples=[[{"type": "force", "body": "link7", "force": [10, 0, 0], "start": 0.5, "duration": 0.4}]])
    payloads: list[Payload] = Field(default_factory=list, description="masses the controller does not know about",
                                    examples=[[{"frame": "tool", "mass": 2.0}]])
    waypoints: Waypoints | None = Field(None, description="points fed one after the other to a task's reference "
                                        "input", examples=[{"task": "tool_position", "points": [[0.5, 0.2, 0.5]],
                                                            "tolerance": 0.01}])
    external_torque: ExternalTorqueSensing | Literal["ideal", "ignored", "noisy"] = Field(
        "ideal", description="how the controller's measured external torque (Nm) is produced: a mode, or the "
        "settings of the noisy sensor", examples=["ignored", {"mode": "noisy", "noise_std": 0.5}])
    model_mismatch: ModelMismatch | None = Field(None, description="differences between the simulated robot and the "
                                                 "controller's model", examples=[{"mass_scale": 1.1}])
    parameters: list[ParameterChange] = Field(
        default_factory=list, description="run-time parameter changes (the spec's `parameters` section), each "
        "over the set before it", examples=[[{"time": 1.0, "values": {"tool_position.activation": 0}}]])
    substeps: Annotated[Integer, Range(1, 1000)] = Field(1, description="simulation steps per control period (the step is period/substeps, "
                              "s)", examples=[1, 4])
    integrator: Literal["euler", "implicitfast", "implicit", "rk4"] = Field(
        "rk4",
        description="MuJoCo integrator; rk4 integrates the torque held over the period as a real robot "
        "does (the limits are shaped for x + T v + ½T²a), the Euler-type ones move x by T²a",
        examples=["rk4"],
    )

    @property
    def sensing(self) -> ExternalTorqueSensing:
        if isinstance(self.external_torque, str):
            return ExternalTorqueSensing(mode=self.external_torque)
        return self.external_torque
