"""Built-in robots: the project's own iiwa14 URDF and the Panda of example-robot-data."""

from __future__ import annotations

import sysconfig
from importlib import resources
from pathlib import Path

import numpy as np
import pinocchio as pin

from .urdf import build_model

BUILTIN_ROBOTS = ("iiwa14", "panda")

PANDA_FINGER_JOINTS = ("panda_finger_joint1", "panda_finger_joint2")


def iiwa14_urdf_path() -> Path:
    """The iiwa14 URDF shipped with this package (written from shared/robots/iiwa14.md)."""
    return Path(str(resources.files("dcts_spec.robot") / "data" / "iiwa14.urdf"))


def example_robot_data_dir() -> Path:
    """Root of example-robot-data's `robots/` folder, installed by the cmeel wheel."""
    prefix = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix"
    path = prefix / "share" / "example-robot-data" / "robots"
    if not path.is_dir():
        raise FileNotFoundError(
            f"example-robot-data is not installed (looked in {path}); run `pip install example-robot-data`"
        )
    return path


def builtin_urdf_path(name: str) -> Path:
    """URDF file of a built-in robot."""
    if name == "iiwa14":
        return iiwa14_urdf_path()
    if name == "panda":
        return example_robot_data_dir() / "panda_description" / "urdf" / "panda.urdf"
    raise KeyError(f"unknown built-in robot {name!r}; built-in robots are {', '.join(BUILTIN_ROBOTS)}")


def builtin_locked_joints(name: str) -> dict[str, float]:
    """Joints a built-in robot locks by default (the Panda's fingers), with their values."""
    return {j: 0.0 for j in PANDA_FINGER_JOINTS} if name == "panda" else {}


def lock_joints(model: pin.Model, locked: dict[str, float]) -> pin.Model:
    """Reduced model with the given joints fixed at the given positions."""
    if not locked:
        return model
    q_ref = pin.neutral(model)
    ids = []
    for name, value in locked.items():
        jid = model.getJointId(name)
        if jid >= model.njoints:
            raise KeyError(f"joint {name!r} to lock is not in the model")
        q_ref[model.joints[jid].idx_q] = value
        ids.append(jid)
    # Pinocchio's reduction finds each locked joint's frame by the joint's name, and raises where
    # another frame has it too (SO-100: a link and a joint `gripper`; `unique_frame_names` renamed
    # the joint's frame): for the while, that frame gets the joint's name and the others another
    model = pin.Model(model)
    original: dict[str, str] = {}
    for jid in ids:
        name = model.names[jid]
        for i, frame in enumerate(model.frames):
            own = frame.type == pin.FrameType.JOINT and frame.parentJoint == jid
            if own == (frame.name == name):
                continue
            temporary = name if own else f"{frame.name}#{i}"
            original[temporary] = frame.name
            model.frames[i].name = temporary
    reduced = pin.buildReducedModel(model, ids, q_ref)
    for i, frame in enumerate(reduced.frames):
        if frame.name in original:
            reduced.frames[i].name = original[frame.name]
    return reduced


def load_builtin_model(name: str) -> pin.Model:
    """Pinocchio model of a built-in robot, with its default joints locked."""
    model = build_model(builtin_urdf_path(name))
    return lock_joints(model, builtin_locked_joints(name))


def random_configuration(model: pin.Model, rng: np.random.Generator, margin: float = 0.1) -> np.ndarray:
    """A configuration drawn uniformly inside the joint limits (shrunk by `margin` rad)."""
    lo = model.lowerPositionLimit + margin
    hi = model.upperPositionLimit - margin
    return rng.uniform(lo, hi)
