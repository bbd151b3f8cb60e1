"""Helpers of test_formulations.py: specs, random states, and independent numeric checks.

Everything that *checks* a controller here is computed from Pinocchio and NumPy (tests/reference.py
and the functions below), never from dcts_spec's symbolic layer or formulations. The only piece of
dcts_spec reused is `limits.viability.acceleration_bounds`, evaluated on numbers, which defines what
the shaped joint/Cartesian acceleration bounds *are*.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import pytest

import dcts_spec
from dcts_spec.limits.joint import BRAKING_FLOOR, DEFAULT_BRAKING
from dcts_spec.limits.viability import acceleration_bounds
from dcts_spec.robot.builtin import example_robot_data_dir
from dcts_spec.spec import Spec, load_spec_text
from dcts_spec.spec.units import to_si
from reference import NumericTask, closed_form_hierarchy

# Campaigns of 1,000 states per robot take minutes each: run them with DCTS_CAMPAIGN=1.
CAMPAIGN = pytest.mark.skipif(not os.environ.get("DCTS_CAMPAIGN"), reason="1,000-state campaign: set DCTS_CAMPAIGN=1 to run it")

# Tool frame used for the Cartesian tasks of each built-in robot.
TOOL = {"iiwa14": "tool", "panda": "panda_hand_tcp"}
# A comfortable configuration of each robot (tool in front of the base, pointing down-ish).
HOME = {
    "iiwa14": np.array([0.0, 0.6, 0.0, -1.2, 0.0, 0.8, 0.0]),
    "panda": np.array([0.0, -0.3, 0.0, -2.0, 0.0, 1.8, 0.8]),
}

# Large limits so that the "no bound active" properties see no active bound (checked anyway).
WIDE_LIMITS = """
  joint_torque: {max: 10000, allow_outside_urdf: true}
  joint_velocity: {max: 20, allow_outside_urdf: true}
"""


def spec_text(robot: str, tasks: str, limits: str = "", controller: str = "", name: str = "case") -> str:
    """A YAML spec; `tasks`, `limits` and `controller` are YAML bodies indented by two spaces."""
    text = f"version: 1\nname: {name}\nrobot: {{model: {robot}}}\n"
    if limits.strip():
        text += "limits:\n" + limits.strip("\n") + "\n"
    if controller.strip():
        text += "controller:\n" + controller.strip("\n") + "\n"
    return text + "tasks:\n" + tasks.strip("\n") + "\n"


def case_tasks(case: str, robot: str) -> str:
    """Task lists of the property cases (constant references near the robot's workspace).

    a: position(3) @1 + orientation(rx, ry) @2 + posture @3 (the posture is over-constrained: least squares)
    b: pose 6-D @1 + posture @2
    c: orientation(rx, ry) @1 + joint damping (kp = 0) @2
    d: position(3) and orientation(rx, ry) sharing level 1 + damping of the first joint @2 (1-D null space left)
    e: position(3) @1 + orientation(rx, ry) @2 (2-D null space left)
    """
    tool = TOOL[robot]
    posture = ", ".join(f"{v:.3f}" for v in HOME[robot])
    first_joint = "joint1" if robot == "iiwa14" else "panda_joint1"
    position = f"{{name: reach, type: position, frame: {tool}, priority: 1, gains: {{kp: 40, kd: 12}}, reference: {{position: [0.5, 0.1, 0.55]}}}}"
    orientation = (
        f"{{name: point, type: orientation, frame: {tool}, axes: [rx, ry], priority: {{p}}, gains: {{kp: 30, kd: 10}}, "
        "reference: {rpy: [3.0, 0.2, 0.0]}}"
    )
    cases = {
        "a": [position, orientation.replace("{p}", "2"),
              f"{{name: posture, type: joint, priority: 3, gains: {{kp: 10, kd: 6}}, reference: {{q: [{posture}]}}}}"],
        "b": [f"{{name: pose, type: pose, frame: {tool}, priority: 1, gains: {{kp: 40, kd: 12}}, "
              "reference: {position: [0.5, -0.1, 0.5], rpy: [3.0, 0.3, 0.5]}}",
              f"{{name: posture, type: joint, priority: 2, gains: {{kp: 10, kd: 6}}, reference: {{q: [{posture}]}}}}"],
        "c": [orientation.replace("{p}", "1"),
              "{name: damping, type: joint, priority: 2, gains: {kp: 0, kd: 5}}"],
        "d": [position, orientation.replace("{p}", "1"),
              f"{{name: base_damping, type: joint, joints: [{first_joint}], priority: 2, gains: {{kp: 0, kd: 5}}}}"],
        "e": [position, orientation.replace("{p}", "2")],
    }
    return "\n".join(f"  - {t}" for t in cases[case])


def case_spec(case: str, robot: str, limits: str = WIDE_LIMITS, controller: str = "") -> Spec:
    return load_spec_text(spec_text(robot, case_tasks(case, robot), limits, controller, name=f"case_{case}"))


# -- random states ---------------------------------------------------------------------------------


@dataclass
class State:
    q: np.ndarray
    dq: np.ndarray
    tau_ext: np.ndarray


def random_states(model: pin.Model, count: int, seed: int, margin: float = 0.3, tau_ext: bool = True) -> list[State]:
    """q uniform inside the joint limits shrunk by `margin`, q̇ ~ N(0, 0.5), τ_ext ~ N(0, 5) (or 0)."""
    rng = np.random.default_rng(seed)
    lo, hi = model.lowerPositionLimit + margin, model.upperPositionLimit - margin
    n = model.nv
    return [
        State(rng.uniform(lo, hi), rng.normal(0.0, 0.5, n), rng.normal(0.0, 5.0, n) if tau_ext else np.zeros(n))
        for _ in range(count)
    ]


# -- the spec's tasks as the reference sees them ---------------------------------------------------


def numeric_tasks(spec: Spec, joint_names: list[str], model: pin.Model | None = None) -> list[NumericTask]:
    """The spec's tasks read directly from the spec entries (not through dcts_spec.tasks). With the
    robot's `model`, a joint task's joints without position limits (Pinocchio's ±1e10 or beyond:
    a URDF continuous joint) take the short way round."""
    out = []
    for t in spec.tasks:
        ref = t.reference
        if t.type == "joint":
            joints = list(t.joints) if t.joints is not None else list(joint_names)
            dim = len(joints)
        else:
            dim = len(t.axis_names)
        kp = np.broadcast_to(np.asarray(t.gains.kp, dtype=float), (dim,)).copy()
        kd = np.broadcast_to(np.asarray(t.gains.kd, dtype=float), (dim,)).copy()
        if t.type == "joint":
            q = None if ref is None or ref.q is None else np.array(to_si(list(ref.q), ref.unit))
            indices = [joint_names.index(j) for j in joints]
            wrapped = None if model is None else tuple(
                bool(model.lowerPositionLimit[i] <= -1e10 and model.upperPositionLimit[i] >= 1e10) for i in indices)
            out.append(NumericTask(t.priority, "joint", kp, kd, joints=indices, q=q, wrapped=wrapped))
        else:
            position = None if ref is None or ref.position is None else np.array(ref.position, dtype=float)
            rotation = None if ref is None or ref.rpy is None else pin.rpy.rpyToMatrix(*to_si(list(ref.rpy), ref.unit))
            out.append(NumericTask(t.priority, t.type, kp, kd, frame=t.frame, axes=tuple(t.axis_names), position=position, rotation=rotation))
    return out


# -- numeric dynamics and checks -------------------------------------------------------------------


def actual_acceleration(model: pin.Model, q, dq, tau, tau_ext) -> np.ndarray:
    """Forward dynamics: a = M⁻¹(τ + τ_ext − ν − g), from Pinocchio (ABA)."""
    return pin.aba(model, model.createData(), q, dq, tau + tau_ext)


def level_residuals(levels, a: np.ndarray) -> list[np.ndarray]:
    """J_i a + J̇_i q̇ − ẍ_d,i for every level (levels as returned by closed_form_hierarchy)."""
    return [J @ a + bias - target for J, bias, target in levels]


def span_residual(levels, vector: np.ndarray) -> float:
    """Relative residual of the least-squares projection of `vector` onto span([J_1ᵀ … J_kᵀ])."""
    JT = np.hstack([J.T for J, _, _ in levels])
    coefficients, *_ = np.linalg.lstsq(JT, vector, rcond=None)
    return float(np.linalg.norm(vector - JT @ coefficients) / max(np.linalg.norm(vector), 1e-12))


def null_space_dimension(levels) -> int:
    J = np.vstack([J for J, _, _ in levels])
    return J.shape[1] - np.linalg.matrix_rank(J, 1e-8)


def joint_braking(robot, q, dq, j: int) -> tuple[float, float]:
    """The deceleration joint j's bounds assume (toward its upper bound, toward its lower one): its
    acceleration limit (DEFAULT_BRAKING without one), or (limits.joint_braking "torque_limited")
    less where its own torque limit gives less on the way to the bound with the other joints
    still: (τ_max ∓ (ν_j + ḡ_j)) / M_jj, ν from Pinocchio's RNEA, ḡ_j the mean of the gravity torque
    over the way, which turning a revolute joint makes g_j cos θ + (∂g_j/∂q_j) sin θ
    (Pinocchio's gravity derivatives); at least BRAKING_FLOOR of the limit."""
    lim, model = robot.limits, robot.model
    data = model.createData()
    nominal = lim.a_max[j] if np.isfinite(lim.a_max[j]) else DEFAULT_BRAKING
    if not lim.torque_limited_braking:
        return nominal, nominal
    q, dq = np.asarray(q, dtype=float), np.asarray(dq, dtype=float)
    inertia = pin.crba(model, data, q)[j, j]
    gravity = pin.computeGeneralizedGravity(model, data, q)[j]
    coriolis = pin.rnea(model, data, q, dq, np.zeros(model.nv))[j] - gravity
    rate = np.diag(pin.computeGeneralizedGravityDerivatives(model, data, q))[j]
    revolute = model.joints[_joint_of(model, j)].shortname().startswith("JointModelR")

    def mean(g1: float, gap: float) -> float:
        if not revolute or not np.isfinite(gap):
            return gravity
        gap = max(gap, 0.0)
        if gap <= 1e-4:
            return gravity + 0.5 * g1 * gap
        return (gravity * np.sin(gap) + g1 * (1.0 - np.cos(gap))) / gap

    sides = (lim.tau_max[j] + coriolis + mean(rate, lim.q_max[j] - q[j]),
             lim.tau_max[j] - coriolis - mean(-rate, q[j] - lim.q_min[j]))
    return tuple(float(min(max(value / inertia, BRAKING_FLOOR * nominal), nominal)) for value in sides)


def _joint_of(model, v: int) -> int:
    """The Pinocchio joint index whose velocity is v."""
    return next(i for i in range(1, model.njoints) if model.joints[i].idx_v == v)


def joint_acceleration_bounds(robot, q, dq, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The shaped bounds on each joint's acceleration (±inf where a joint has no bound)."""
    lim = robot.limits
    lower, upper = np.full(len(q), -np.inf), np.full(len(q), np.inf)
    for j in range(len(q)):
        if not np.isfinite([lim.q_min[j], lim.q_max[j], lim.v_max[j], lim.a_max[j]]).any():
            continue
        braking = joint_braking(robot, q, dq, j)
        lo, hi = acceleration_bounds(float(q[j]), float(dq[j]), lim.q_min[j], lim.q_max[j], lim.v_max[j], lim.a_max[j], braking, dt)
        lower[j], upper[j] = float(lo), float(hi)
    return lower, upper


def cartesian_accelerations(robot, q, dq, a, dt: float) -> list[tuple[str, float, float, float]]:
    """(name, lower, c̈, upper) for each Cartesian bound: c̈ = J_c a + J̇_c q̇ from Pinocchio."""
    model = robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, q, dq, np.zeros(model.nv))
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    out = []
    for b in robot.cartesian_bounds:
        fid = model.getFrameId(b.frame)
        J = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)[b.axis]
        bias = pin.getFrameClassicalAcceleration(model, data, fid, pin.LOCAL_WORLD_ALIGNED).vector[b.axis]
        c, c_dot = data.oMf[fid].translation[b.axis], J @ dq
        lo, hi = acceleration_bounds(float(c), float(c_dot), b.c_min, b.c_max, b.v_max, np.inf, b.a_max, dt)
        out.append((f"{b.frame}.{'xyz'[b.axis]}", float(lo), float(J @ a + bias), float(hi)))
    return out


def _side_margins(lower, value, upper) -> np.ndarray:
    """min over both sides of (distance inside the bound) / max(1, |bound|): < 0 means violated."""
    lower, value, upper = (np.asarray(v, dtype=float) for v in (lower, value, upper))
    with np.errstate(invalid="ignore"):
        low = np.where(np.isfinite(lower), (value - lower) / np.maximum(1.0, np.abs(lower)), np.inf)
        high = np.where(np.isfinite(upper), (upper - value) / np.maximum(1.0, np.abs(upper)), np.inf)
    return np.minimum(low, high)


@dataclass
class BoundCheck:
    """Relative margins of a step's torque and accelerations to every bound: > 0 inside, < 0 beyond.

    Each margin is the distance to the bound divided by max(1, |bound|) (τ_max for torques).
    """

    torque: np.ndarray  # per joint
    joint: np.ndarray  # per joint (inf for joints without any bound)
    cartesian: np.ndarray  # per Cartesian bound

    def violation(self) -> float:
        """Largest relative violation of any bound (0 if none)."""
        margins = np.concatenate([self.torque, self.joint, self.cartesian])
        return float(max(0.0, -margins.min())) if margins.size else 0.0

    def active(self, tol: float = 1e-6) -> dict[str, np.ndarray]:
        return {name: np.flatnonzero(getattr(self, name) <= tol) for name in ("torque", "joint", "cartesian")}

    def any_active(self, tol: float = 1e-6) -> bool:
        return any(v.size for v in self.active(tol).values())


def check_bounds(robot, q, dq, tau, a, dt: float) -> BoundCheck:
    """Margins of τ to the torque limits and of the acceleration a to the shaped joint/Cartesian bounds."""
    lower, upper = joint_acceleration_bounds(robot, q, dq, dt)
    cart = cartesian_accelerations(robot, q, dq, a, dt)
    tau_max = robot.limits.tau_max
    return BoundCheck(
        torque=_side_margins(-tau_max, tau, tau_max),
        joint=_side_margins(lower, a, upper),
        cartesian=np.array([_side_margins(lo, c, hi) for _, lo, c, hi in cart], dtype=float).reshape(-1),
    )


def reference_solution(model, tasks, state: State, measured: bool = True):
    """(τ, a, levels) of the independent closed-form hierarchy at a state."""
    return closed_form_hierarchy(model, tasks, state.q, state.dq, state.tau_ext if measured else None)


def relative(x: np.ndarray, y: np.ndarray) -> float:
    return float(np.abs(x - y).max() / max(np.abs(y).max(), 1.0))


def approach_speed(distance: float, v_max: float, braking: float, dt: float, upper: float) -> float:
    """The speed toward a position bound `distance` away at which the shaped upper acceleration bound
    equals `upper` (bisection: the bound falls as the speed grows)."""

    def bound(v: float) -> float:
        return float(acceleration_bounds(0.0, v, -np.inf, distance, v_max, np.inf, braking, dt)[1])

    lo, hi = 0.0, 50.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if bound(mid) > upper else (lo, mid)
    return 0.5 * (lo + hi)


# Baxter, both hands at priorities 1 and 2 above a posture (first tried from outside): the top
# level is scaled in most states ({urdf}: example-robot-data's robots/ folder)
BAXTER_TWO_HANDS = """version: 1
name: baxter_two_hands
robot:
  urdf: {urdf}/baxter_description/urdf/baxter.urdf
  locked_joints: {{head_pan: 0, l_gripper_l_finger_joint: 0, l_gripper_r_finger_joint: 0, r_gripper_l_finger_joint: 0, r_gripper_r_finger_joint: 0}}
limits:
  joint_acceleration: {{max: 15}}
  cartesian:
    - {{frame: left_gripper, axis: z, min: -0.20}}
    - {{frame: right_gripper, axis: y, max: -0.75}}
controller:
  formulation: dcts
  external_torque: measured
tasks:
  - {{name: left_pos, type: position, frame: left_gripper, priority: 1, gains: {{kp: 100, kd: 20}}, reference: {{position: [0.55, 0.75, -0.35]}}}}
  - {{name: right_pos, type: position, frame: right_gripper, priority: 2, gains: {{kp: 100, kd: 20}}, reference: {{position: [0.55, -0.55, -0.05]}}}}
  - {{name: posture, type: joint, priority: 3, gains: {{kp: 5, kd: 5}}, reference: {{q: [0.3, -0.5, 0, 1.2, 0, 0.9, 0, -0.3, -0.5, 0, 1.2, 0, 0.9, 0]}}}}
"""


# A Tiago's torso lift and arm (example-robot-data; its head and wheels locked), as a spec's robot
# section: two specs found from outside use it (a push, and a top level's scaling stage)
TIAGO_ROBOT = f"""robot:
  urdf: {example_robot_data_dir() / "tiago_description" / "robots" / "tiago_no_hand.urdf"}
  locked_joints: {{head_1_joint: 0, head_2_joint: 0, wheel_left_joint: 0, wheel_right_joint: 0}}
"""


def kinova_spec(posture: bool = False) -> str:
    """A Kinova arm (example-robot-data, 6 joints) found from outside: a position target beyond two
    Cartesian bounds at priority 1, an orientation [rx, ry] at 2, a wrist joint at 3, and with
    `posture` a posture at 4, which the levels above leave no direction."""
    lowest = ("  - {name: posture, type: joint, priority: 4, gains: {kp: 2, kd: 3}, "
              "reference: {q: [0, 2.9, 1.0, -2.0, 1.4, 1.3]}}\n") if posture else ""
    return f"""
version: 1
name: kinova
robot: {{urdf: {example_robot_data_dir() / "kinova_description" / "robots" / "kinova.urdf"}}}
limits:
  joint_acceleration: {{max: 30}}
  joint_torque: {{max: [30, 60, 30, 15, 15, 15]}}
  cartesian:
    - {{frame: j2s6s200_end_effector, axis: z, min: 0.35}}
    - {{frame: j2s6s200_end_effector, axis: x, max: -0.05}}
controller: {{formulation: dcts, external_torque: measured}}
tasks:
  - {{name: reach, type: position, frame: j2s6s200_end_effector, priority: 1, gains: {{kp: 80, kd: 18}},
     reference: {{position: [0.10, -0.35, 0.20]}}}}
  - {{name: point, type: orientation, frame: j2s6s200_end_effector, axes: [rx, ry], priority: 2,
     gains: {{kp: 60, kd: 15}}, reference: {{rpy: [180, 0, 0], unit: deg}}}}
  - {{name: wrist, type: joint, joints: [j2s6s200_joint_6], priority: 3, gains: {{kp: 10, kd: 6}}, reference: {{q: [0.5]}}}}
{lowest}scenario: {{duration: 1.0, initial_q: [0, 2.9, 1.0, -2.0, 1.4, 1.3]}}
"""


def same_step_in_c(spec_text: str, states, tmp_path, monkeypatch, status: int) -> None:
    """The spec's C bundle at each state (q, q̇, τ_ext), both runtimes from a reset: the status
    `status` in both, and the same scalings and torques."""
    monkeypatch.setenv("DCTS_CACHE_DIR", str(tmp_path / "cache"))
    spec = load_spec_text(spec_text, "spec.yaml")
    python, compiled = dcts_spec.build_controller(spec), dcts_spec.compile_c(spec, tmp_path / "bundle")
    for q, dq, tau_ext in states:
        python.reset()
        compiled.reset()
        expected, got = python.step(q, dq, tau_ext), compiled.step(q, dq, tau_ext)
        assert got.status == expected.status == status
        np.testing.assert_allclose(got.scaling, expected.scaling, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(got.tau, expected.tau, rtol=1e-6, atol=1e-8)
