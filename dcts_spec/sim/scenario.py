"""The spec's `scenario` section resolved against the robot: SI units, one value per joint."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..robot.model import Robot
from ..spec import Spec, SpecError
from ..spec.scenario import ExternalTorqueSensing, ParameterChange, Waypoints
from ..spec.units import joint_to_si
from ..validate import initial_configuration
from .mujoco_model import Payload


@dataclass(frozen=True)
class ForcePush:
    """A world-axes force and torque at a point of a frame during [start, end)."""

    frame: str
    point: np.ndarray  # in the frame, m
    force: np.ndarray  # N
    torque: np.ndarray  # Nm
    start: float
    end: float


@dataclass(frozen=True)
class TorqueProfile:
    """Joint torques during [start, end), ramped up and down linearly over `ramp` seconds."""

    torque: np.ndarray
    start: float
    end: float
    ramp: float

    def amplitude(self, t: np.ndarray) -> np.ndarray:
        """0 outside the window, 1 on the plateau, linear on the ramps (a triangle if they meet)."""
        inside = (t >= self.start) & (t < self.end)
        if self.ramp == 0:
            return inside.astype(float)
        edge = np.minimum(t - self.start, self.end - t) / self.ramp
        return np.where(inside, np.clip(edge, 0.0, 1.0), 0.0)


@dataclass(frozen=True)
class Scenario:
    """What to simulate, in SI units."""

    duration: float
    period: float  # control period
    substeps: int
    integrator: str
    q0: np.ndarray
    dq0: np.ndarray
    pushes: tuple[ForcePush, ...]
    torque_profiles: tuple[TorqueProfile, ...]
    payloads: tuple[Payload, ...]
    waypoints: Waypoints | None
    sensing: ExternalTorqueSensing
    mass_scale: float
    parameter_changes: tuple[ParameterChange, ...] = ()  # run-time parameter sets given during the run

    @property
    def steps(self) -> int:
        """Control steps in the run."""
        return max(1, int(round(self.duration / self.period)))

    @property
    def timestep(self) -> float:
        """MuJoCo's step: the control period divided by the substeps."""
        return self.period / self.substeps

    def with_duration(self, duration: float) -> Scenario:
        return dataclasses.replace(self, duration=duration)


def resolve_scenario(spec: Spec, robot: Robot) -> Scenario:
    """The scenario of a validated spec; a SpecError if the spec has none."""
    sc = spec.scenario
    if sc is None:
        raise SpecError([spec.source.diagnostic(
            (), "the spec has no `scenario` section: add one (at least `scenario: {duration: 2.0}`) to simulate it")])
    n = robot.nv
    dq0 = np.zeros(n) if sc.initial_dq is None else np.array(joint_to_si(list(sc.initial_dq), f"{sc.unit}/s",
                                                                          robot.prismatic))
    pushes, profiles = [], []
    for d in sc.disturbances:
        if d.type == "force":
            pushes.append(ForcePush(d.body, np.array(d.point), np.array(d.force), np.array(d.torque),
                                    float(d.start), float(d.start + d.duration)))
        else:
            profiles.append(TorqueProfile(np.array(d.torque, dtype=float), float(d.start),
                                          float(d.start + d.duration), float(d.ramp)))
    payloads = tuple(Payload(p.frame, float(p.mass), tuple(p.com), tuple(p.inertia)) for p in sc.payloads)
    return Scenario(
        duration=float(sc.duration),
        period=float(spec.controller.period),
        substeps=int(sc.substeps),
        integrator=sc.integrator,
        q0=initial_configuration(spec, robot),
        dq0=dq0,
        pushes=tuple(pushes),
        torque_profiles=tuple(profiles),
        payloads=payloads,
        waypoints=sc.waypoints,
        sensing=sc.sensing,
        mass_scale=1.0 if sc.model_mismatch is None else float(sc.model_mismatch.mass_scale),
        parameter_changes=tuple(sc.parameters),
    )
