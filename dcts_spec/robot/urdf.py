"""A URDF read into the Pinocchio model the controller drives: one angle per rotating joint.

Pinocchio models a URDF `continuous` joint by its cosine and sine (nq = 2, nv = 1), and every
part of dcts (the spec's q, the QP data's inputs, the C bundle, the simulation's state) holds one
position per joint. A continuous joint is read as what it is to the controller: a revolute joint
about the same axis without position limits; its angle is not wrapped, and a joint task on it
takes the short way round to its target (tasks/joint.py). Its effort and velocity limits stay. Mesh paths do not matter: the model holds kinematics and inertia only.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from xml.etree import ElementTree

import pinocchio as pin

UNLIMITED = "1e10"  # what Pinocchio (and JointLimits.of_model) read as no position limit


def revolute_from_continuous(root: ElementTree.Element) -> list[str]:
    """Make every continuous joint of a URDF tree a revolute joint without position limits (in
    place); returns their names. urdfdom wants a revolute joint's <limit> with effort and velocity:
    a missing one is 0, which Pinocchio and JointLimits read as none."""
    names = []
    for joint in root.iter("joint"):
        if joint.get("type") != "continuous":
            continue
        joint.set("type", "revolute")
        limit = joint.find("limit")
        if limit is None:
            limit = ElementTree.SubElement(joint, "limit")
        limit.set("lower", f"-{UNLIMITED}")
        limit.set("upper", UNLIMITED)
        for attribute in ("effort", "velocity"):
            limit.set(attribute, limit.get(attribute, "0"))
        names.append(joint.get("name", "?"))
    return names


def check_tree(root: ElementTree.Element) -> None:
    """A URDF's root is <robot>, and its joints make a tree: raise saying which it is not. An SDF
    (example-robot-data's Cassie) was refused for a joint's missing <limit>, and a link that is the
    child of two joints (a closed loop) as "Model does not have any body named l3"."""
    if root.tag != "robot":
        raise ValueError(f"not a URDF: its root element is <{root.tag}>, where a URDF's is <robot> (dcts reads URDF "
                         "files; convert the model to one)")
    parents: dict[str, list[str]] = {}
    for joint in root.iter("joint"):
        child = joint.find("child")
        if child is not None:
            parents.setdefault(child.get("link", "?"), []).append(joint.get("name", "?"))
    for link, joints in parents.items():
        if len(joints) > 1:
            raise ValueError(f"link {link} is the child of {len(joints)} joints ({', '.join(joints)}): a closed "
                             "kinematic loop, which a URDF cannot describe and dcts does not control (its joints "
                             "make a tree); keep one of these joints")


def check_limit_elements(root: ElementTree.Element) -> None:
    """urdfdom refuses a revolute or prismatic joint without a <limit> giving effort and velocity, and
    says only that the file "does not contain a valid URDF model": raise naming the joint instead."""
    for joint in root.iter("joint"):
        if joint.get("type") not in ("revolute", "prismatic"):
            continue
        limit = joint.find("limit")
        missing = ["<limit>"] if limit is None else [a for a in ("effort", "velocity") if limit.get(a) is None]
        if missing:
            raise ValueError(f"joint {joint.get('name', '?')} ({joint.get('type')}) has no {' or '.join(missing)}, "
                             "which the URDF format requires of a revolute or prismatic joint; give its "
                             "<limit effort=... velocity=...> (0 for none: then set limits.joint_torque or "
                             "limits.joint_velocity in the spec)")


def mimic_joints(path: Path) -> dict[str, str]:
    """The URDF's mimic joints: joint name → the joint it follows. Pinocchio reads them as joints
    of their own, which the controller would drive independently."""
    root = ElementTree.parse(path).getroot()
    return {joint.get("name", "?"): mimic.get("joint", "?") for joint in root.iter("joint")
            if (mimic := joint.find("mimic")) is not None}


def unique_frame_names(model: pin.Model) -> list[str]:
    """Give every frame its own name (in place); returns the new names. A URDF may name a joint and a
    link alike (B1-Z1's `gripperStator`), and Pinocchio's lookup by name then raises: the link keeps
    the name, the other frames get their kind as a suffix (`gripperStator_fixed_joint`)."""
    counts = Counter(frame.name for frame in model.frames)
    renamed = []
    for name in [name for name, count in counts.items() if count > 1]:
        frames = [i for i, frame in enumerate(model.frames) if frame.name == name]
        keep = next((i for i in frames if model.frames[i].type == pin.FrameType.BODY), frames[0])
        for i in frames:
            if i != keep:
                new = f"{name}_{model.frames[i].type.name.lower()}"
                while new in counts:
                    new += "_"
                counts[new] = 1
                model.frames[i].name = new
                renamed.append(new)
    return renamed


def load_model(path: Path) -> tuple[pin.Model, list[str]]:
    """Pinocchio's model of the URDF at `path`, its continuous joints made revolute and its frame
    names unique, and the frames it renamed (`unique_frame_names`). Raises what Pinocchio raises
    for a URDF it cannot read (and ElementTree's ParseError for a file that is no XML)."""
    root = ElementTree.parse(path).getroot()
    check_tree(root)
    check_limit_elements(root)
    if not revolute_from_continuous(root):  # (the file as it is: urdfdom's messages name its lines)
        model = pin.buildModelFromUrdf(str(path))
    else:
        model = pin.buildModelFromXML(ElementTree.tostring(root, encoding="unicode"))
    return model, unique_frame_names(model)


def build_model(path: Path) -> pin.Model:
    """`load_model`'s model."""
    return load_model(path)[0]
