"""Which robot model a bundle was generated from: a digest of everything the controller uses.

The spec's SHA-256 says which spec a bundle implements; the model digest says which robot
model it was compiled for. They differ in meaning when the controller is compiled for a
modified model (model mismatch: `scenario.model_mismatch.mass_scale` scales the controller's
masses and inertias while the simulated robot keeps the spec's).
"""

from __future__ import annotations

import hashlib
import json
import struct

import numpy as np

from ..robot.model import Robot

# Model arrays that take part in the controller (dynamics, limits, friction-like terms).
_MODEL_VECTORS = ("armature", "friction", "damping", "rotorInertia", "rotorGearRatio", "effortLimit",
                  "velocityLimit", "lowerPositionLimit", "upperPositionLimit")


def _floats(h: "hashlib._Hash", values) -> None:
    array = np.ascontiguousarray(np.asarray(values, dtype=np.float64))
    h.update(struct.pack("<q", array.size))
    h.update(array.astype("<f8", copy=False).tobytes())


def _text(h: "hashlib._Hash", text: str) -> None:
    data = text.encode()
    h.update(struct.pack("<q", len(data)))
    h.update(data)


def model_digest(robot: Robot) -> str:
    """SHA-256 of the robot as the controller sees it: kinematic tree, joint placements,
    inertias, frames, gravity, the model's vectors and the merged limits (bit-exact)."""
    model = robot.model
    h = hashlib.sha256(b"dcts-model-1")
    _text(h, robot.name)
    for i in range(model.njoints):
        _text(h, model.names[i])
        _text(h, model.joints[i].shortname())
        h.update(struct.pack("<q", int(model.parents[i])))
        _floats(h, model.jointPlacements[i].homogeneous)
        inertia = model.inertias[i]
        _floats(h, [inertia.mass, *np.asarray(inertia.lever).ravel(), *np.asarray(inertia.inertia).ravel()])
    for frame in model.frames:
        _text(h, frame.name)
        _text(h, str(frame.type))
        h.update(struct.pack("<q", int(frame.parentJoint)))
        _floats(h, frame.placement.homogeneous)
    _floats(h, model.gravity.linear)
    for name in _MODEL_VECTORS:
        _text(h, name)
        _floats(h, getattr(model, name, np.zeros(0)))
    for limits in (robot.limits, robot.urdf_limits):
        for name in ("q_min", "q_max", "v_max", "tau_max", "a_max"):
            _floats(h, getattr(limits, name))
    for bound in robot.cartesian_bounds:
        _text(h, bound.frame)
        _floats(h, [*bound.direction, bound.c_min, bound.c_max, bound.v_max, bound.a_max])
    return h.hexdigest()


def total_mass(robot: Robot) -> float:
    return float(sum(robot.model.inertias[i].mass for i in range(robot.model.njoints)))


def model_record(robot: Robot, spec_robot: Robot, changes: dict | None = None) -> dict:
    """The manifest's `model` entry: the model's digest, whether it is the spec's own robot,
    and what was changed (e.g. {"mass_scale": 1.2}) when it is not."""
    digest, spec_model_digest = model_digest(robot), model_digest(spec_robot)
    modified = digest != spec_model_digest
    record = {
        "sha256": digest,
        "modified": modified,
        "spec_model_sha256": spec_model_digest,
        "total_mass": total_mass(robot),
    }
    if modified:  # (changes given for the spec's own model, e.g. mass_scale 1, change nothing)
        record["changes"] = dict(changes or {})
        record["spec_total_mass"] = total_mass(spec_robot)
    return record


def describe_changes(changes: dict) -> str:
    """One line for people: `mass_scale = 1.2 (link masses and inertias)`."""
    if not changes:
        return "unspecified changes"
    parts = []
    for key, value in changes.items():
        text = f"{key} = {value:g}" if isinstance(value, (int, float)) else f"{key} = {json.dumps(value)}"
        if key == "mass_scale":
            text += " (link masses and inertias)"
        parts.append(text)
    return ", ".join(parts)
