"""A URDF read into the Pinocchio model the controller drives: one angle per rotating joint.

Pinocchio models a URDF `continuous` joint by its cosine and sine (nq = 2, nv = 1), and every
part of dcts (the spec's q, the QP data's inputs, the C bundle, the simulation's state) holds one
position per joint. A continuous joint is read as what it is to the controller: a revolute joint
about the same axis without position limits; its angle is not wrapped, and a joint task on it
takes the short way round to its target (tasks/joint.py). Its effort and velocity limits stay. Mesh paths do not matter: the model holds kinematics and inertia only.
"""

from __future__ import annotations

import math
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
    links = [link.get("name", "?") for link in root.findall("link")]
    joints = [joint.get("name", "?") for joint in root.findall("joint")]
    for kind, names in (("links", links), ("joints", joints)):
        twice = sorted(name for name, count in Counter(names).items() if count > 1)
        if twice:
            raise ValueError(f"two {kind} named {twice[0]!r}: each link and each joint of a URDF has a name of its own")
    parents: dict[str, list[str]] = {}
    for joint in root.findall("joint"):
        for end in ("parent", "child"):
            element = joint.find(end)
            if element is None or element.get("link") not in links:
                named = "" if element is None else f" {element.get('link')!r}"
                raise ValueError(f"joint {joint.get('name', '?')}'s {end} link{named} is not a <link> of the URDF")
        parents.setdefault(joint.find("child").get("link"), []).append(joint.get("name", "?"))
    roots = [link for link in links if link not in parents]
    if len(roots) > 1:
        raise ValueError(f"{len(roots)} links have no parent joint ({', '.join(roots[:5])}): a URDF's links make one "
                         "tree from one root; join them with joints (fixed ones, if they do not move)")
    for link, joints in parents.items():
        if len(joints) > 1:
            raise ValueError(f"link {link} is the child of {len(joints)} joints ({', '.join(joints)}): a closed "
                             "kinematic loop, which a URDF cannot describe and dcts does not control (its joints "
                             "make a tree); keep one of these joints")


URDF_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")


def check_joints(root: ElementTree.Element) -> None:
    """Each joint's type is one of URDF's, and a moving joint's <axis> has a direction: raise naming
    the joint. urdfdom refuses an unknown type as "does not contain a valid URDF model", and reads
    an axis of 0 0 0 as given, which left a joint that moves nothing ("moves no mass", said of
    links that have mass; found from outside)."""
    for joint in root.findall("joint"):  # (not iter: a <transmission> names joints too)
        name, kind = joint.get("name", "?"), joint.get("type")
        if kind not in URDF_JOINT_TYPES:
            raise ValueError(f"joint {name} has type {kind!r}: a URDF joint is {', '.join(URDF_JOINT_TYPES[:-1])} "
                             f"or {URDF_JOINT_TYPES[-1]}")
        axis = joint.find("axis")
        if kind in ("fixed", "floating") or axis is None:  # (no <axis>: 1 0 0)
            continue
        try:
            direction = [float(v) for v in axis.get("xyz", "1 0 0").split()]
        except ValueError:
            direction = []
        if len(direction) != 3 or not all(math.isfinite(v) for v in direction) or not any(direction):
            raise ValueError(f"joint {name}'s <axis xyz=\"{axis.get('xyz')}\"> gives no direction: three finite "
                             "numbers, not all 0 (a unit vector, e.g. 0 0 1)")


def check_limit_elements(root: ElementTree.Element) -> None:
    """urdfdom refuses a revolute or prismatic joint without a <limit> giving effort and velocity, and
    says only that the file "does not contain a valid URDF model": raise naming the joint instead."""
    for joint in root.iter("joint"):
        if joint.get("type") not in ("revolute", "prismatic"):
            continue
        limit = joint.find("limit")
        for attribute in ("lower", "upper", "effort", "velocity"):
            text = None if limit is None else limit.get(attribute)
            if text is None:
                continue
            try:
                value = float(text)
            except ValueError:
                value = math.nan
            if not math.isfinite(value) or (attribute in ("effort", "velocity") and value < 0):
                allowed = "a number ≥ 0 (a magnitude; 0 for none)" if attribute in ("effort", "velocity") else "a finite number"
                raise ValueError(f"joint {joint.get('name', '?')}'s <limit {attribute}=\"{text}\">: {allowed}")
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
    check_joints(root)
    check_limit_elements(root)
    if not revolute_from_continuous(root):  # (the file as it is: urdfdom's messages name its lines)
        model = pin.buildModelFromUrdf(str(path))
    else:
        model = pin.buildModelFromXML(ElementTree.tostring(root, encoding="unicode"))
    return model, unique_frame_names(model)


def build_model(path: Path) -> pin.Model:
    """`load_model`'s model."""
    return load_model(path)[0]
