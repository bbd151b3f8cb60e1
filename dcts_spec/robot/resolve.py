"""Resolve the `robot` and `limits` sections of a spec into a `Robot`, with located diagnostics."""

from __future__ import annotations

import contextlib
import difflib
import os
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..spec import Diagnostic, Spec, SpecError
from ..spec.errors import KeyPath, did_you_mean
from ..spec.limits import JointAccelerationLimits, JointTorqueLimits, JointVelocityLimits
from ..spec.source import SourceMap
from ..spec.types import as_list, size_of
from ..spec.units import joint_to_si, to_si
from .builtin import builtin_locked_joints, builtin_urdf_path, lock_joints
from .model import (CartesianBound, JointLimits, Robot, is_prismatic, multi_dof_kind, no_position_range, prismatic_joints,
                    unit_of_kind)
from .urdf import load_model, mimic_joints

AXIS_INDEX = {"x": 0, "y": 1, "z": 2}
# A joint moving less inertia than this, relative to the largest joint's (kg·m² or kg), moves
# none: the URDF's massless links (exactly 0 in Pinocchio's mass matrix)
MOVED_INERTIA = 1e-12
LISTED_FRAMES = 8  # an unknown frame's message lists this many candidates, the closest first


def resolve_robot(spec: Spec) -> tuple[Robot, list[Diagnostic]]:
    """Build the robot of a spec; raises SpecError with every problem, returns the warnings."""
    diags: list[Diagnostic] = []
    src = spec.source
    model, urdf_path = _load_model(spec, diags)
    if model is None:
        raise SpecError(diags)
    _check_inertias(spec, model, diags)
    _check_moved_inertia(spec, model, diags)
    _add_frames(spec, model, diags)
    _add_payloads(spec, model, diags)
    urdf_limits = JointLimits.of_model(model)
    inverted = [f"{model.names[j]} ({lo:.6g} > {hi:.6g})" for j in range(1, model.njoints)
                for lo, hi in [(model.lowerPositionLimit[model.joints[j].idx_q], model.upperPositionLimit[model.joints[j].idx_q])]
                if lo > hi]
    if inverted:  # (validate said ok, and building the controller failed with "high - low < 0")
        diags.append(src.diagnostic(("robot",), f"the URDF gives {', '.join(inverted)} a lower position limit above "
                                                "its upper one; correct its <limit lower=... upper=...>"))
    empty = no_position_range(model)
    rangeless = [model.names[j] for j in range(1, model.njoints) if empty[model.joints[j].idx_q]]
    if rangeless and not spec.limits.joint_position:
        diags.append(src.diagnostic(
            ("robot",), f"the URDF gives {', '.join(rangeless)} no position range (lower = upper): driven without "
                        f"position limits; give limits.joint_position to bound them", "warning"))
    for key, attribute, values in (("joint_velocity", "velocity", urdf_limits.v_max),
                                   ("joint_torque", "effort", urdf_limits.tau_max)):
        unlimited = [model.names[j] for j in range(1, model.njoints) if not np.isfinite(values[model.joints[j].idx_v])]
        if unlimited and getattr(spec.limits, key) is None:  # (0 in a URDF is read as none, silently before)
            diags.append(src.diagnostic(
                ("robot",), f"the URDF gives {', '.join(unlimited)} no {attribute} limit ({attribute}=\"0\" or none): "
                            f"driven without one; give limits.{key} to bound them", "warning"))
    names = [model.names[j] for j in range(1, model.njoints)]  # (one velocity each: revolute or prismatic)
    prismatic = prismatic_joints(model)
    if spec.limits.joint_velocity is None:
        diags += _placeholder_velocities(src, names, urdf_limits.v_max, prismatic)
    limits = _merge_limits(spec, urdf_limits, _JointUnits(names, prismatic), diags)
    bounds = _cartesian_bounds(spec, model, diags)
    if any(d.severity == "error" for d in diags):
        raise SpecError(diags)
    model.lowerPositionLimit = np.where(np.isfinite(limits.q_min), limits.q_min, -1e10)
    model.upperPositionLimit = np.where(np.isfinite(limits.q_max), limits.q_max, 1e10)
    name = spec.robot.model or Path(spec.robot.urdf or "robot").stem
    robot = Robot(name, model, urdf_path, limits, urdf_limits, bounds)
    return robot, diags


def frame_candidates(name: str, frames: list[str], spec: Spec) -> str:
    """What follows `no frame 'x'`: a near-typo's correction, then the robot's frames; a long
    list is cut to the closest few and says which command lists them all."""
    frames = [f for f in frames if f != "universe"]  # Pinocchio's world frame: no task's or bound's
    hint = did_you_mean(name, frames, n=3)
    if len(frames) <= LISTED_FRAMES:
        return f"{hint}; frames: {', '.join(frames)}"
    closest = sorted(frames, key=lambda f: -difflib.SequenceMatcher(None, name, f).ratio())[:LISTED_FRAMES]
    target = spec.robot.model or str(_urdf_path(spec))
    return (f"{hint}; closest of its {len(frames)} frames: {', '.join(closest)} "
            f"(`dcts describe {target}` lists them all)")


# A URDF velocity limit above these is a placeholder (Bolt's and Solo's 1000 rad/s, iCub's 100), not a
# motor's: the fastest joints of legged robots turn at ~30 rad/s, and of example-robot-data's URDFs
# none gives one between 60 (Romeo's) and 100.
PLACEHOLDER_SPEED = {False: 90.0, True: 10.0}  # rad/s (revolute), m/s (prismatic)


def _placeholder_velocities(src: SourceMap, names: list[str], v_max: np.ndarray, prismatic: np.ndarray) -> list[Diagnostic]:
    """A warning naming the joints whose URDF velocity limit is a placeholder: the velocity bounds,
    the fallback's gate on implausible readings (formulations/fallback.py) and the golden vectors'
    limit states are drawn from it."""
    fast = [(name, v, slides) for name, v, slides in zip(names, v_max, prismatic, strict=True)
            if np.isfinite(v) and v > PLACEHOLDER_SPEED[slides]]
    if not fast:
        return []
    shown = ", ".join(f"{name} {v:g} {'m/s' if slides else 'rad/s'}" for name, v, slides in fast[:4])
    more = f" and {len(fast) - 4} more" if len(fast) > 4 else ""
    return [src.diagnostic(("robot",), f"the URDF's velocity limits look like placeholders ({shown}{more}; above "
                                       f"{PLACEHOLDER_SPEED[False]:g} rad/s or {PLACEHOLDER_SPEED[True]:g} m/s): the velocity "
                                       f"bounds and the fallback torque's gate on implausible readings (10 × the limit) "
                                       f"take them as they are; give limits.joint_velocity the joints' real limits",
                                "warning")]


def _urdf_path(spec: Spec) -> Path:
    """The spec's URDF file (a relative path is the spec file's)."""
    path = Path(spec.robot.urdf or "")
    return path if path.is_absolute() else spec.base_dir / path


def _robot_key(spec: Spec) -> KeyPath:
    """Where the spec names its robot: `robot.model` (built-in) or `robot.urdf`."""
    return ("robot", "model") if spec.robot.model is not None else ("robot", "urdf")


def locked_joints(spec: Spec) -> dict[str, float]:
    """The joints the spec's robot has locked, at their positions (rad or m): a built-in robot's
    own (the Panda's fingers), then the spec's `robot.locked_joints`."""
    builtin = builtin_locked_joints(spec.robot.model) if spec.robot.model is not None else {}
    return {**builtin, **spec.robot.locked_joints}


def _load_model(spec: Spec, diags: list[Diagnostic]) -> tuple[pin.Model | None, Path]:
    src = spec.source
    where = _robot_key(spec)
    locked = locked_joints(spec)
    if spec.robot.model is not None:
        path = builtin_urdf_path(spec.robot.model)
    else:
        path = _urdf_path(spec)
        if not path.is_file():
            message = (f"{path} is a folder, not a URDF file" if path.is_dir() else
                       f"{path} is not a regular file (a pipe or a device), not a URDF file" if path.exists() else
                       f"URDF file not found: {path}")
            diags.append(src.diagnostic(where, message))
            return None, path
    try:
        with captured_stderr() as parser_messages:  # (urdfdom prints its complaints itself)
            full, renamed = load_model(path)
    except Exception as exc:  # Pinocchio raises plain RuntimeErrors for bad URDFs
        diags.append(src.diagnostic(where, f"cannot load the URDF {path}: {exc}"))
        return None, path
    if renamed:  # (a spec's frame of that name is now the link's, which may not be where the joint is)
        diags.append(src.diagnostic(where, f"the URDF names a link and another frame alike: the link keeps the "
                                           f"name, the other is {', '.join(renamed)}", "warning"))
    skipped = [line.removeprefix("Error:").strip() for line in parser_messages if line.startswith("Error:")]
    if skipped:  # (urdfdom goes on without an element it cannot parse: a link's inertial read as none)
        diags.append(src.diagnostic(where, f"the URDF parser skipped what it could not read ({'; '.join(skipped)}): "
                                           "that part counts as absent (an <inertial> as no mass); correct the URDF",
                                    "warning"))
    for joint, leader in mimic_joints(path).items():
        if joint in full.names and joint not in locked:
            diags.append(src.diagnostic(where, (
                f"joint {joint} mimics {leader} in the URDF, which dcts does not model: it is driven as a joint "
                f"of its own; lock it with robot.locked_joints (and {leader} if they must move together)"),
                "warning"))
    known = set(full.names)
    unknown = [j for j in locked if j not in known]
    for j in unknown:
        hint = did_you_mean(j, list(full.names)[1:], n=3)
        diags.append(src.diagnostic(("robot", "locked_joints", j), f"no joint {j!r} to lock{hint}"))
    if unknown:
        return None, path
    outside = False
    for name, value in locked.items():
        joint = full.joints[full.getJointId(name)]
        if joint.nq != 1 and value != 0:  # (the value went into the first coordinate: a floating base's x)
            diags.append(src.diagnostic(("robot", "locked_joints", name), (
                f"{name} is a {multi_dof_kind(joint)} joint ({joint.nq} position coordinates), which one value "
                f"cannot place: lock it at 0, its neutral position (the URDF's placement of its child link)")))
            outside = True
            continue
        lo, hi = full.lowerPositionLimit[joint.idx_q], full.upperPositionLimit[joint.idx_q]
        if joint.nq == 1 and lo < hi and not lo - 1e-9 <= value <= hi + 1e-9:
            unit = unit_of_kind("rad", is_prismatic(joint))
            diags.append(src.diagnostic(("robot", "locked_joints", name),
                                        f"{value:g} {unit} is outside {name}'s range [{lo:.6g}, {hi:.6g}] {unit} "
                                        f"(a locked joint's position is in {unit})"))
            outside = True
    if outside:
        return None, path
    model = lock_joints(full, locked)
    several = [(model.names[j], joint) for j, joint in enumerate(model.joints) if j and (joint.nq != 1 or joint.nv != 1)]
    for name, joint in several:  # (the limits, the QP data and the C hold one coordinate per joint)
        diags.append(src.diagnostic(where, (
            f"joint {name} is a {multi_dof_kind(joint)} joint ({joint.nv} DOF): dcts drives fixed-base robots whose "
            f"joints have one coordinate each (revolute, continuous, prismatic); lock it at its neutral position "
            f"with robot.locked_joints: {{{name}: 0}}, or make it fixed in the URDF")))
    if several:
        return None, path
    if model.nv == 0:
        movable = "" if not locked else f" once {', '.join(locked)} are locked"
        diags.append(src.diagnostic(where, f"the URDF {path.name} has no movable joint{movable}: nothing to control"))
        return None, path
    return model, path


@contextlib.contextmanager
def captured_stderr() -> Iterator[list[str]]:
    """Capture the process's stderr (file descriptor 2, which C++ libraries write to directly):
    the yielded list holds its lines once the block ends."""
    lines: list[str] = []
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with tempfile.TemporaryFile(mode="w+", encoding="utf-8", errors="replace") as capture:
            os.dup2(capture.fileno(), 2)
            try:
                yield lines
            finally:
                os.dup2(saved, 2)
                capture.seek(0)
                lines.extend(capture.read().splitlines())
    finally:
        os.close(saved)


# kg·m²: a principal moment this close to 0 is rounding (iCub's URDF writes ixx = -5.4e-20 for a
# link with no rotational inertia), not an inertia that is not positive definite
INERTIA_ROUNDING = 1e-12


def _check_inertias(spec: Spec, model: pin.Model, diags: list[Diagnostic]) -> None:
    """Each body's mass and rotational inertia (a joint's child link with the links fixed to it)
    must be physical. A negative mass, or an inertia that is not positive semi-definite, is an
    error: M(q) may lose definiteness and MuJoCo refuses the body (the simulation ended in an
    internal error). Principal moments that break A + B ≥ C (a common rounding of CAD exports) are
    a warning: MuJoCo balances them (`balanceinertia`), the controller keeps the URDF's."""
    for j in range(1, model.njoints):
        inertia = model.inertias[j]
        moments = np.linalg.eigvalsh(inertia.inertia)
        link = _child_link(model, j)
        tolerance = max(1e-9 * float(np.abs(moments).max()), INERTIA_ROUNDING)
        if inertia.mass < 0:
            problem = f"has a negative mass ({inertia.mass:.4g} kg)"
        elif moments[0] < -tolerance:
            problem = f"has an inertia that is not positive definite (principal moments {_moments(moments)} kg·m²)"
        elif moments[0] + moments[1] < moments[2] - tolerance:
            diags.append(spec.source.diagnostic(_robot_key(spec), (
                f"link {link}'s principal moments of inertia {_moments(moments)} kg·m² break A + B ≥ C, which every "
                "rigid body's satisfy: the simulation (MuJoCo) balances them, the controller uses the URDF's"),
                "warning"))
            continue
        else:
            continue
        diags.append(spec.source.diagnostic(_robot_key(spec), (
            f"link {link} (moved by joint {model.names[j]}) {problem} in the URDF: no rigid body has one; "
            "correct its <inertial>")))


def _child_link(model: pin.Model, joint: int) -> str:
    """The link a joint moves (its first body frame)."""
    return next((f.name for f in model.frames if f.parentJoint == joint and f.type == pin.FrameType.BODY),
                model.names[joint])


def _moments(moments: np.ndarray) -> str:
    return "[" + ", ".join(f"{m:.4g}" for m in moments) + "]"


def _check_moved_inertia(spec: Spec, model: pin.Model, diags: list[Diagnostic]) -> None:
    """Every joint must move some inertia: a joint whose links, and every link beyond it, have no
    mass (massless fingers in some URDFs) makes the mass matrix singular, and no dynamics-based
    controller exists for it (M(q)'s diagonal entry is that inertia about the joint's axis)."""
    data = model.createData()  # (every joint has one coordinate: _load_model refused the others)
    diagonal = np.diag(pin.crba(model, data, pin.neutral(model))) + model.armature
    largest = float(diagonal.max())
    empty = diagonal <= MOVED_INERTIA * max(1.0, largest)
    carried = _subtree_masses(model)
    dwarfed = [j for j in range(1, model.njoints) if empty[model.joints[j].idx_v] and carried[j] > 0.0]
    if dwarfed:  # (links with mass, beside one of a mass that makes theirs rounding: 1e30 kg, found from outside)
        heaviest = max(range(1, model.njoints), key=lambda j: model.inertias[j].mass)
        names = ", ".join(model.names[j] for j in dwarfed)
        diags.append(spec.source.diagnostic(_robot_key(spec), (
            f"the inertia that {names} move{'s' if len(dwarfed) == 1 else ''} is below {MOVED_INERTIA:g} of the largest "
            f"joint's ({largest:.3g}): the URDF's masses span too many orders of magnitude to be computed with "
            f"(the link moved by {model.names[heaviest]} has {model.inertias[heaviest].mass:.3g} kg); correct its masses")))
        empty[[model.joints[j].idx_v for j in dwarfed]] = False
    if empty.any():
        names = [model.names[j] for j in range(1, model.njoints) if empty[model.joints[j].idx_v]]
        joints, them = (f"joints {', '.join(names)} move", "them") if len(names) > 1 else (f"joint {names[0]} moves", "it")
        diags.append(spec.source.diagnostic(
            _robot_key(spec), f"{joints} no mass or inertia (every link beyond {them} is massless in the URDF), so the "
                   f"mass matrix is singular and no torque controller exists: lock {them} with "
                   f"robot.locked_joints, or give those links inertia"))


def _subtree_masses(model: pin.Model) -> list[float]:
    """The mass each joint moves: its child link's and every link's beyond it (kg)."""
    mass = [model.inertias[j].mass for j in range(model.njoints)]
    for j in range(model.njoints - 1, 0, -1):  # (a parent's index is below its children's)
        mass[model.parents[j]] += mass[j]
    return mass


def _add_frames(spec: Spec, model: pin.Model, diags: list[Diagnostic]) -> None:
    """`robot.frames` into the model, each after its parent whatever their order in the file (a
    frame on a frame written below it was "no frame named" it, found from outside)."""
    src = spec.source
    pending = {}
    for name, frame in spec.robot.frames.items():
        if model.existFrame(name):
            diags.append(src.diagnostic(("robot", "frames", name),
                                        f"the robot already has a frame named {name!r}; choose another name"))
        else:
            pending[name] = frame
    while pending:
        ready = [name for name, frame in pending.items() if model.existFrame(frame.parent)]
        if not ready:
            break
        for name in ready:
            frame = pending.pop(name)
            parent = model.frames[model.getFrameId(frame.parent)]
            rpy = to_si(list(frame.rpy), frame.unit)
            local = pin.SE3(pin.rpy.rpyToMatrix(*rpy), np.array(frame.xyz))
            model.addFrame(pin.Frame(name, parent.parentJoint, model.getFrameId(frame.parent), parent.placement * local,
                                     pin.FrameType.OP_FRAME))
    for name, frame in pending.items():
        path = ("robot", "frames", name, "parent")
        if frame.parent in pending:  # (a frame left waits on another one left: a cycle, or a missing parent)
            chain = [name]
            while pending[chain[-1]].parent in pending and pending[chain[-1]].parent not in chain:
                chain.append(pending[chain[-1]].parent)
            last = pending[chain[-1]].parent
            message = (f"frames attached to each other in a cycle ({' → '.join(chain + [last])}): attach one of them "
                       "to a link" if last in chain else
                       f"attached to frame {frame.parent!r}, which is not placed either (see its error)")
            diags.append(src.diagnostic(path, message))
        else:
            hint = frame_candidates(frame.parent, [f.name for f in model.frames], spec)
            diags.append(src.diagnostic(path, f"no link, joint or frame named {frame.parent!r}{hint}"))


def _add_payloads(spec: Spec, model: pin.Model, diags: list[Diagnostic]) -> None:
    """`robot.payloads` into the model: each mass, at its centre of mass in its frame, added
    to the inertia of the joint that frame moves with. Everything built from the model (the
    controller's dynamics, the C code, the MuJoCo plant) then carries it."""
    for k, payload in enumerate(spec.robot.payloads):
        if not model.existFrame(payload.frame):
            hint = frame_candidates(payload.frame, [f.name for f in model.frames], spec)
            diags.append(spec.source.diagnostic(("robot", "payloads", k, "frame"),
                                                f"no link, joint or frame named {payload.frame!r}{hint}"))
            continue
        frame = model.frames[model.getFrameId(payload.frame)]
        mass = pin.Inertia(float(payload.mass), np.array(payload.com, dtype=float), np.diag(payload.inertia))
        model.inertias[frame.parentJoint] = model.inertias[frame.parentJoint] + frame.placement.act(mass)


@dataclass(frozen=True)
class _JointUnits:
    """The joints as limit messages name them, and which are prismatic (their limits in m, m/s,
    m/s² and N where a revolute joint's are in rad, rad/s, rad/s² and Nm)."""

    names: list[str]
    prismatic: np.ndarray

    def value(self, j: int, text: str, unit: str) -> str:
        """`joint 3, <name>: <text> <unit>`, in the unit of the joint's kind (as the gravity warning)."""
        return f"joint {j + 1}, {self.names[j]}: {text} {unit_of_kind(unit, self.prismatic[j])}"


def _vector(
    value: float | tuple[float, ...], unit: str, joints: _JointUnits, path: KeyPath, src: SourceMap,
    diags: list[Diagnostic], what: str
) -> np.ndarray | None:
    """A scalar-or-vector joint limit in SI (a prismatic joint's in m), or None (with a diagnostic)
    if its size is wrong."""
    n = joints.prismatic.size
    size = size_of(value)
    if size is not None and size != n:
        diags.append(src.diagnostic(path, f"{what} has {size} values but the robot has {n} joints"))
        return None
    return np.array(joint_to_si(as_list(value, n), unit, joints.prismatic), dtype=float)


def _merge_limits(spec: Spec, urdf: JointLimits, joints: _JointUnits, diags: list[Diagnostic]) -> JointLimits:
    """Spec limits override the URDF's; wider than the URDF only when explicitly allowed."""
    src = spec.source
    lim = spec.limits
    q_min, q_max = urdf.q_min, urdf.q_max
    if (jp := lim.joint_position) is not None:
        base = ("limits", "joint_position")
        lo = _vector(jp.min, jp.unit, joints, base + ("min",), src, diags, "min") if jp.min is not None else q_min
        hi = _vector(jp.max, jp.unit, joints, base + ("max",), src, diags, "max") if jp.max is not None else q_max
        if lo is not None and hi is not None:
            bad = np.flatnonzero(lo >= hi)
            if bad.size:
                j = bad[0]
                diags.append(src.diagnostic(
                    base + ("min",), f"min must be smaller than max ({joints.value(j, f'{lo[j]:.4g} ≥ {hi[j]:.4g}', 'rad')})"))
            _outside(lo, urdf.q_min, lo < urdf.q_min - 1e-9, "rad", base + ("min",), "below the URDF's lower limit",
                     jp.allow_outside_urdf, joints, src, diags)
            _outside(hi, urdf.q_max, hi > urdf.q_max + 1e-9, "rad", base + ("max",), "above the URDF's upper limit",
                     jp.allow_outside_urdf, joints, src, diags)
            q_min, q_max = lo, hi
    v_max = _symmetric(lim.joint_velocity, "joint_velocity", urdf.v_max, "velocity", "rad/s", joints, src, diags)
    a_max = _symmetric(lim.joint_acceleration, "joint_acceleration", urdf.a_max, None, "rad/s²", joints, src, diags)
    tau_max = _symmetric(lim.joint_torque, "joint_torque", urdf.tau_max, "effort", "Nm", joints, src, diags)
    return JointLimits(q_min=q_min, q_max=q_max, v_max=v_max, tau_max=tau_max, a_max=a_max,
                       torque_limited_braking=lim.joint_braking == "torque_limited")


def _symmetric(
    section: JointVelocityLimits | JointAccelerationLimits | JointTorqueLimits | None,
    key: str,
    urdf: np.ndarray,
    urdf_name: str | None,
    unit: str,
    joints: _JointUnits,
    src: SourceMap,
    diags: list[Diagnostic],
) -> np.ndarray:
    """A symmetric bound |x| ≤ max from the spec (checked), or the URDF's where the spec has none.

    `urdf_name` is None for bounds the URDF does not declare (accelerations): no comparison then.
    """
    if section is None:
        return urdf
    path = ("limits", key, "max")
    values = _vector(section.max, section.unit, joints, path, src, diags, "max")
    if values is None:
        return urdf
    if urdf_name is not None:
        _outside(values, urdf, values > urdf + 1e-9, unit, path, f"above the URDF's {urdf_name} limit",
                 section.allow_outside_urdf, joints, src, diags)
    return values


def _outside(values: np.ndarray, urdf: np.ndarray, mask: np.ndarray, unit: str, path: KeyPath, what: str, allowed: bool,
             joints: _JointUnits, src: SourceMap, diags: list[Diagnostic]) -> None:
    """Joints whose spec limit is beyond the URDF's, with both values (in SI units)."""
    beyond = np.flatnonzero(mask)
    if not beyond.size:
        return
    listed = ", ".join(joints.value(j, f"{values[j]:.4g} vs {urdf[j]:.4g}", unit) for j in beyond)
    if allowed:
        diags.append(src.diagnostic(path, f"{what} ({listed}), widened on purpose: allow_outside_urdf", "warning"))
    else:
        diags.append(
            src.diagnostic(path, f"{what} ({listed}); narrow it, or set allow_outside_urdf: true in "
                                 f"{'.'.join(map(str, path[:-1]))} to widen on purpose")
        )


def _cartesian_bounds(spec: Spec, model: pin.Model, diags: list[Diagnostic]) -> tuple[CartesianBound, ...]:
    out = []
    names = [f.name for f in model.frames]
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    for i, c in enumerate(spec.limits.cartesian):
        at = ("limits", "cartesian", i)
        if not model.existFrame(c.frame):
            diags.append(spec.source.diagnostic(at + ("frame",), f"no frame {c.frame!r}{frame_candidates(c.frame, names, spec)}"))
            continue
        if c.axis is not None:
            direction, shift = np.eye(3)[AXIS_INDEX[c.axis]], 0.0
        else:
            direction, shift = np.asarray(c.normal, dtype=float) / np.linalg.norm(c.normal), 0.0
        given = direction
        if c.expressed_in not in (None, "world"):  # (an axis too: it was ignored, and the C header crashed)
            if not model.existFrame(c.expressed_in):
                hint = frame_candidates(c.expressed_in, names, spec)
                diags.append(spec.source.diagnostic(at + ("expressed_in",), f"no frame {c.expressed_in!r}{hint}"))
                continue
            frame = model.frames[model.getFrameId(c.expressed_in)]
            if frame.parentJoint != 0:
                diags.append(spec.source.diagnostic(
                    at + ("expressed_in",), f"frame {c.expressed_in!r} moves with joint {model.names[frame.parentJoint]!r}; "
                    "a plane must be given in the world or in a frame fixed to it"))
                continue
            # n̂ᵀ(Rᵀ(p − p_f)) = (R n̂)ᵀp − (R n̂)ᵀp_f: the same bounds on the world normal, shifted
            placement = data.oMf[model.getFrameId(c.expressed_in)]
            direction = placement.rotation @ direction
            shift = float(direction @ placement.translation)
        # an axis keeps its name while it is a world axis (a frame that only moves the origin)
        world_axis = c.axis is not None and np.allclose(direction, given, rtol=0.0, atol=1e-12)
        out.append(
            CartesianBound(
                frame=c.frame,
                direction=tuple(float(v) for v in direction),
                label=c.axis if world_axis else f"plane{i}",
                c_min=-np.inf if c.min is None else c.min + shift,
                c_max=np.inf if c.max is None else c.max + shift,
                v_max=np.inf if c.max_velocity is None else c.max_velocity,
                a_max=c.max_acceleration,
            )
        )
    return tuple(out)
