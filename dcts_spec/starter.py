"""`dcts init`: a commented spec to start from, for a built-in robot or a URDF, that validates and
simulates as written."""

from __future__ import annotations

import os
import re
from importlib import resources
from pathlib import Path

import numpy as np
import pinocchio as pin

from .codegen.bundle import render
from .robot.builtin import BUILTIN_ROBOTS
from .robot.describe import RobotDescription, describe
from .robot.model import Robot
from .robot.resolve import resolve_robot
from .spec import load_spec_text
from .validate import initial_configuration

# Ready postures (deg): elbow and wrist bent, away from the joint limits and from singularities
# (a stretched arm loses a Cartesian direction). A URDF starts in the middle of its joint ranges
# if the tool can move along every axis there, else at the best-conditioned of some draws around it
# (the middle of the iiwa14's ranges is the arm straight up: singular, and the tool was not held).
READY_POSTURES = {
    "iiwa14": [0, 30, 0, -60, 0, 60, 0],
    "panda": [0, -45, 0, -135, 0, 90, 45],
}
TARGET_OFFSET = np.array([0.0, 0.1, 0.0])  # m: the tool's target, from where it starts
WELL_CONDITIONED = 0.2  # smallest / largest singular value of the tool's position Jacobian
POSTURE_DRAWS = 256  # seeded: the same URDF always gives the same spec
POSTURE_SPREAD = 0.35  # draws within ± this fraction of each joint's range (± 2 rad without one)


class InitError(Exception):
    """The spec cannot be written (message for the user)."""


def write_starter(file: Path, robot: str) -> str:
    """Write the starter spec for `robot` (a built-in name or a URDF file) to `file`, which must not
    exist; return the spec's name. Raises InitError, DescribeError or SpecError."""
    if file.exists() or file.is_symlink():
        raise InitError(f"{file} exists: dcts init never overwrites a file; choose another name")
    text = starter_text(file, robot)
    try:
        with open(file, "x", encoding="utf-8") as out:  # "x": a file that appeared meanwhile stays
            out.write(text)
    except OSError as error:
        raise InitError(f"cannot write {file}: {error.strerror}") from None
    return spec_name(file)


def spec_name(file: Path) -> str:
    """The file's stem as a spec name (an identifier: letters, digits, _)."""
    name = re.sub(r"\W", "_", file.stem, flags=re.ASCII)[:64] or "spec"
    return f"spec_{name}"[:64] if name[0].isdigit() else name


def starter_text(file: Path, robot: str) -> str:
    """The starter spec's YAML; the target is computed from the robot's forward kinematics."""
    builtin = robot in BUILTIN_ROBOTS
    if not builtin and Path(robot).suffix.lower() != ".urdf":
        raise InitError(f"--robot takes a built-in robot ({', '.join(BUILTIN_ROBOTS)}) or a URDF file, not {robot!r}")
    description = describe(robot)
    if builtin:
        robot_key, q0, unit = f"model: {robot}", READY_POSTURES.get(robot), "deg"
    else:
        robot_key, q0, unit = f"urdf: {_urdf_path(Path(robot), file.parent)}", None, "rad"
    if q0 is None:
        q0 = [round(_middle(j.position.min, j.position.max), 3) for j in description.joints]
    values = {
        "FILE": file.name,
        "NAME": spec_name(file),
        "ROBOT": description.name,
        "ROBOT_ARG": robot,
        "ROBOT_KEY": robot_key,
        "TORQUE_LIMITS": _torque_limits(description),
        "FRAME": description.tool_frame,
        "INITIAL_Q": _flow(q0),
        "UNIT": unit,
        "JOINTS": ", ".join(j.name for j in description.joints),
        "TARGET": "[0, 0, 0]",
    }
    template = resources.files(__package__).joinpath("templates", "spec.yaml.in").read_text(encoding="utf-8")
    spec = load_spec_text(render(template, values), str(file))
    robot, _ = resolve_robot(spec)
    if robot.nv < 3:
        raise InitError(f"the starter spec holds the tool at a point, which takes at least 3 joints; {description.name} "
                        f"has {robot.nv}: write the tasks by hand (docs/tasks.md)")
    frame = robot.model.getFrameId(description.tool_frame)
    q = initial_configuration(spec, robot)
    if not builtin:
        q = np.round(_well_conditioned(robot, frame, q), 3)
        values["INITIAL_Q"] = _flow(q)
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    values["TARGET"] = _flow(np.round(data.oMf[frame].translation + TARGET_OFFSET, 3))
    return render(template, values)


def _well_conditioned(robot: Robot, frame: int, q: np.ndarray) -> np.ndarray:
    """`q` if the tool can move along every axis there (its position Jacobian's singular values
    within WELL_CONDITIONED of each other), else the best-conditioned of POSTURE_DRAWS seeded draws
    around it within the joint limits."""
    model, data = robot.model, robot.model.createData()

    def conditioning(q: np.ndarray) -> float:
        J = pin.computeFrameJacobian(model, data, q, frame, pin.LOCAL_WORLD_ALIGNED)[:3]
        sigma = np.linalg.svd(J, compute_uv=False)
        return float(sigma[-1] / sigma[0]) if sigma[0] > 0 else 0.0

    if conditioning(q) >= WELL_CONDITIONED:
        return q
    lim = robot.limits
    reach = np.where(np.isfinite(lim.q_max - lim.q_min), POSTURE_SPREAD * (lim.q_max - lim.q_min), 2.0)
    low, high = np.maximum(q - reach, lim.q_min), np.minimum(q + reach, lim.q_max)
    draws = np.random.default_rng(0).uniform(low, high, (POSTURE_DRAWS, q.size))
    return max(draws, key=conditioning)


def _torque_limits(description: RobotDescription) -> str:
    efforts = [j.effort.max for j in description.joints]
    if any(e is None for e in efforts):
        return "joint_torque: {max: 50}  # the URDF gives none: put your drives' limits here"
    return f"joint_torque: {{max: {_flow(efforts)}}}  # the URDF's"


def _middle(low: float | None, high: float | None) -> float:
    if low is None or high is None:
        return 0.0
    return 0.5 * (low + high)


def _flow(values) -> str:
    """A YAML flow list of numbers, without trailing zeros."""
    return "[" + ", ".join(f"{float(v) + 0.0:g}" for v in values) + "]"  # (+ 0.0: no -0)


def _urdf_path(path: Path, start: Path) -> str:
    """`path` as the spec file will name it: as given if absolute (`../../work/...` broke when the
    spec moved; found from outside), else relative to the spec's folder when it can be."""
    if path.is_absolute():
        return path.as_posix()
    try:
        return Path(os.path.relpath(path.resolve(), start.resolve())).as_posix()
    except ValueError:  # another drive (Windows)
        return str(path.resolve())
