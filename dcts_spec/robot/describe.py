"""What a robot offers a spec: its joints with their limits and units, its frames, its links and
masses (`dcts describe`, `dcts robots`).

A robot is named three ways: a built-in name, a URDF file, or a spec file (then it is the spec's
robot: its locked joints, extra frames and merged limits).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ElementTree
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..spec import load_spec
from .builtin import BUILTIN_ROBOTS, builtin_locked_joints, builtin_urdf_path, load_builtin_model
from .model import JointLimits, is_prismatic, multi_dof_kind, unit_of_kind
from .resolve import captured_stderr, locked_joints, resolve_robot
from .urdf import build_model

FRAME_KINDS = {pin.FrameType.BODY: "link", pin.FrameType.JOINT: "joint", pin.FrameType.FIXED_JOINT: "fixed joint",
               pin.FrameType.OP_FRAME: "frame", pin.FrameType.SENSOR: "sensor"}


class DescribeError(Exception):
    """The robot cannot be loaded (message for the user)."""


@dataclass(frozen=True)
class Limit:
    """A bound in SI units (None where the URDF gives none) and its unit."""

    min: float | None
    max: float | None
    unit: str


@dataclass(frozen=True)
class Joint:
    name: str
    type: str  # revolute, continuous or prismatic (what the URDF says, read from Pinocchio)
    position: Limit
    velocity: Limit
    effort: Limit


@dataclass(frozen=True)
class Frame:
    name: str
    kind: str  # link, joint, fixed joint, frame (added by a spec)
    joint: str  # the joint that moves it ("universe": fixed to the base)


@dataclass(frozen=True)
class Link:
    name: str
    mass: float  # kg


@dataclass(frozen=True)
class RobotDescription:
    name: str
    source: str  # "built-in", or the URDF or spec file
    urdf: str
    joints: list[Joint]
    locked_joints: dict[str, float]
    frames: list[Frame]
    links: list[Link]

    @property
    def mass(self) -> float:
        return sum(link.mass for link in self.links)

    @property
    def tool_frame(self) -> str:
        """The last link moved by the last joint: where a tool task usually goes."""
        last = self.joints[-1].name
        return [f.name for f in self.frames if f.joint == last and f.kind == "link"][-1]

    def to_dict(self) -> dict:
        return {**asdict(self), "dof": len(self.joints), "mass": self.mass, "mass_unit": "kg",
                "tool_frame": self.tool_frame}

    def text(self) -> str:
        """The description for the terminal: a joint table, then frames and links."""
        lines = [f"{self.name}: {len(self.joints)} joints, {self.mass:.4g} kg in {len(self.links)} links "
                 f"({self.source}; URDF {self.urdf})", ""]
        rows = [("joint", "type", "position", "velocity", "effort")]
        rows += [(j.name, j.type, _position_text(j.position), _bound_text(j.velocity), _bound_text(j.effort))
                 for j in self.joints]
        widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
        lines += ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]
        if self.locked_joints:
            lines += ["", "locked joints (not controlled): "
                      + ", ".join(f"{name} = {value:g}" for name, value in self.locked_joints.items())]
        lines += ["", f"frames (any can be a task's, bound's or payload's `frame:`; tool: {self.tool_frame}):"]
        for joint in dict.fromkeys(f.joint for f in self.frames):
            names = ", ".join(f.name if f.kind == "link" else f"{f.name} ({f.kind})"
                              for f in self.frames if f.joint == joint)
            lines.append(f"  moved by {joint}: {names}" if joint != "universe" else f"  fixed: {names}")
        lines += ["", "links (kg): " + ", ".join(f"{link.name} {link.mass:.4g}" for link in self.links)]
        return "\n".join(lines)


def _number(value: float, unit: str) -> str:
    if unit.startswith("rad"):
        return f"{math.degrees(value):.4g} {unit.replace('rad', 'deg')} ({value:.4g} {unit})"
    return f"{value:.4g} {unit}"


def _position_text(limit: Limit) -> str:
    if limit.min is None and limit.max is None:
        return "unbounded"
    if limit.unit == "rad":
        low, high = (f"{math.degrees(v):.4g}" if v is not None else "-inf" for v in (limit.min, limit.max))
        rad = ", ".join(f"{v:.4g}" if v is not None else "inf" for v in (limit.min, limit.max))
        return f"[{low}, {high}] deg ([{rad}] rad)"
    return f"[{limit.min:.4g}, {limit.max:.4g}] {limit.unit}"


def _bound_text(limit: Limit) -> str:
    return "none" if limit.max is None else _number(limit.max, limit.unit)


def describe(target: str) -> RobotDescription:
    """The robot a built-in name, a URDF file or a spec file names (SpecError for a broken spec)."""
    if target in BUILTIN_ROBOTS:
        try:
            urdf = builtin_urdf_path(target)
            model = load_builtin_model(target)
        except FileNotFoundError as error:
            raise DescribeError(str(error)) from None
        return _description(target, "built-in robot", urdf, model, JointLimits.of_model(model),
                            builtin_locked_joints(target))
    path = Path(target)
    if not path.is_file():
        raise DescribeError(f"{target} is neither a built-in robot ({', '.join(BUILTIN_ROBOTS)}) nor a file")
    if path.suffix.lower() == ".urdf":
        model = _load_urdf(path)
        return _description(path.stem, "URDF file", path, model, JointLimits.of_model(model), {})
    spec = load_spec(path)
    robot, _ = resolve_robot(spec)
    return _description(robot.name, f"the robot of {path}", robot.urdf_path, robot.model, robot.limits,
                        locked_joints(spec))


def _load_urdf(path: Path) -> pin.Model:
    try:
        with captured_stderr():  # urdfdom prints its complaint itself; the message below says it
            model = build_model(path)
    except Exception as error:  # Pinocchio raises plain RuntimeErrors for bad URDFs
        raise DescribeError(f"cannot load the URDF {path}: {error}") from None
    if model.nv == 0:
        raise DescribeError(f"the URDF {path} has no movable joint")
    return model


def _description(name: str, source: str, urdf: Path, model: pin.Model, limits: JointLimits,
                 locked: dict[str, float]) -> RobotDescription:
    joints = []
    for jid in range(1, model.njoints):
        joint = model.joints[jid]
        kind = "prismatic" if is_prismatic(joint) else "revolute"
        unit = unit_of_kind("rad", is_prismatic(joint))
        q, v = joint.idx_q, joint.idx_v
        if joint.nv != 1:  # (a floating base: validation asks to lock it)
            none = Limit(None, None, "")
            joints.append(Joint(model.names[jid], f"{multi_dof_kind(joint)} ({joint.nv} DOF)", none, none, none))
            continue
        if kind == "revolute" and limits.unbounded(q):
            kind = "continuous"  # (a URDF continuous joint, read as a revolute one: robot/urdf.py)
        position = Limit(_finite(limits.q_min[q]), _finite(limits.q_max[q]), unit)
        joints.append(Joint(model.names[jid], kind, position, Limit(None, _finite(limits.v_max[v]), f"{unit}/s"),
                            Limit(None, _finite(limits.tau_max[v]), unit_of_kind("Nm", is_prismatic(joint)))))
    frames = [Frame(f.name, FRAME_KINDS.get(f.type, str(f.type)), model.names[f.parentJoint])
              for f in model.frames if f.name != "universe"]
    return RobotDescription(name, source, str(urdf), joints, dict(locked), frames, _links(urdf))


def _finite(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _links(urdf: Path) -> list[Link]:
    """Every link of the URDF with its mass (0 for a link without <inertial>)."""
    root = ElementTree.parse(urdf).getroot()
    links = []
    for link in root.iter("link"):
        mass = link.find("inertial/mass")
        links.append(Link(link.get("name", "?"), float(mass.get("value", 0.0)) if mass is not None else 0.0))
    return links
