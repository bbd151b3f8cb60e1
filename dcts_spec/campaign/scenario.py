"""A sample applied to the spec: the spec's YAML data with the sample's scenario and controller.

The result is a whole spec (data for `spec_from_data`, or YAML for a file): the sample is run
from it, and the same data written to a file replays the sample with `dcts simulate`.
"""

from __future__ import annotations

import copy
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..spec.errors import format_path
from ..spec.units import joint_to_si
from .document import Campaign, ForceMagnitude
from .sampling import Sample


@dataclass(frozen=True)
class JointRange:
    """The robot's joint position limits and the spec's start (SI), for initial states."""

    q0: np.ndarray
    q_min: np.ndarray
    q_max: np.ndarray
    prismatic: np.ndarray  # per joint: its values are in m whatever the angle unit

    def to_si(self, values: list[float], unit: str) -> list[float]:
        """Per-joint values in an angle `unit` (or per s) in SI."""
        return joint_to_si(values, unit, self.prismatic)


def sample_spec_data(base: dict[str, Any], campaign: Campaign, sample: Sample, joints: JointRange) -> dict[str, Any]:
    """The spec data of `base` (a spec's YAML data, untouched) with the sample applied: its
    pushes and payloads added to the scenario's, its duration, mismatch, sensing, start state,
    formulation and run-time parameters (set at t = 0) in place of the spec's."""
    data = copy.deepcopy(base)
    scenario = data.setdefault("scenario", {}) or {}
    data["scenario"] = scenario
    if campaign.duration is not None:
        scenario["duration"] = campaign.duration
    for i, push in enumerate(campaign.pushes):
        force = _force(campaign, sample, i)
        scenario.setdefault("disturbances", []).append({
            "type": "force", "body": push.body, "force": force,
            "point": [sample.value("pushes", i, "point", a) for a in "xyz"],
            "start": sample.value("pushes", i, "start"), "duration": sample.value("pushes", i, "duration")})
    for i, payload in enumerate(campaign.payloads):
        scenario.setdefault("payloads", []).append({
            "frame": payload.frame, "mass": sample.value("payloads", i, "mass"),
            "com": [sample.value("payloads", i, "com", a) for a in "xyz"]})
    if campaign.model_mismatch is not None:
        scenario["model_mismatch"] = {"mass_scale": sample.value("model_mismatch", "mass_scale")}
    if campaign.external_torque is not None:
        scenario["external_torque"] = {
            "mode": "noisy", "noise_std": sample.value("external_torque", "noise_std"),
            "bias": _per_joint(sample, ("external_torque", "bias"), len(joints.q0)), "seed": sample.seed}
    if campaign.initial_state is not None:
        _initial_state(scenario, campaign, sample, joints)
    if sample.formulation is not None:
        data.setdefault("controller", {})["formulation"] = sample.formulation
    controller = campaign.controller
    if controller is not None and controller.parameters:
        values = {name: sample.value("controller", "parameters", name) if not isinstance(value, list)
                  else [sample.value("controller", "parameters", name, j) for j in range(len(value))]
                  for name, value in controller.parameters.items()}
        # after the spec's own changes: the run applies those of one time in list order, and the
        # sample's values must win over a set the spec gives at t = 0 (before, it overrode them)
        scenario["parameters"] = [*scenario.get("parameters", []), {"time": 0.0, "values": values}]
    return data


def _force(campaign: Campaign, sample: Sample, i: int) -> list[float]:
    if isinstance(campaign.pushes[i].force, ForceMagnitude):
        magnitude = float(sample.value("pushes", i, "force", "magnitude"))
        return [magnitude * d for d in sample.directions[f"pushes[{i}].force"]]
    return [float(sample.value("pushes", i, "force", a)) for a in "xyz"]


def _per_joint(sample: Sample, path: tuple, joints: int) -> list[float]:
    """A per-joint value: its draws, or the entries of its list (one per joint)."""
    name = format_path(path)
    if name in sample.values:
        value = sample.values[name]
        return list(value) if isinstance(value, list) else [float(value)] * joints
    return [float(sample.values[f"{name}[{j}]"]) for j in range(joints)]


def _initial_state(scenario: dict, campaign: Campaign, sample: Sample, joints: JointRange) -> None:
    """initial_q in rad (initial_dq converted along if it was in degrees)."""
    state = campaign.initial_state
    assert state is not None
    if state.within_limits is not None:
        # The sample drew where in the shrunk range each joint starts (0: its low end, 1: its high end).
        span = joints.q_max - joints.q_min
        low = joints.q_min + state.within_limits * span
        q = low + np.array(_per_joint(sample, ("initial_state", "within_limits"), len(joints.q0))) * (1 - 2 * state.within_limits) * span
    else:
        offset = np.array(joints.to_si(_per_joint(sample, ("initial_state", "offset"), len(joints.q0)), state.unit))
        q = np.clip(joints.q0 + offset, joints.q_min, joints.q_max)
    if scenario.get("unit", "rad") != "rad" and scenario.get("initial_dq") is not None:
        scenario["initial_dq"] = joints.to_si(list(scenario["initial_dq"]), f"{scenario['unit']}/s")
    scenario["unit"] = "rad"
    scenario["initial_q"] = [float(v) for v in q]


def replay_yaml(data: dict[str, Any], spec_file: Path, replay_file: Path, comment: str) -> str:
    """The sample's spec as a file next to `replay_file`: a relative URDF path made relative to
    the replay's folder (it was relative to the spec's)."""
    data = copy.deepcopy(data)
    urdf = (data.get("robot") or {}).get("urdf")
    if isinstance(urdf, str) and not os.path.isabs(urdf):
        target = (spec_file.parent / urdf).resolve()
        data["robot"]["urdf"] = os.path.relpath(target, replay_file.parent.resolve())
    header = "".join(f"# {line}\n" for line in comment.splitlines())
    return header + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, allow_unicode=True)
