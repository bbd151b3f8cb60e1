"""Tasks: run-time references, feed-forward, the saturated law — checked through OSC, whose top task
is met exactly, against Pinocchio's numeric kinematics."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from dcts_spec import build_controller
from dcts_spec.robot.builtin import load_builtin_model
from dcts_spec.spec import load_spec_text
from reference import OWN, orientation_terms, twist

Q = np.array([0.1, 0.6, -0.2, -1.2, 0.3, 1.0, 0.2])
DQ = np.array([0.2, -0.1, 0.3, 0.1, -0.2, 0.4, 0.1])
TARGET = np.array([0.5, 0.1, 0.55])
RPY = np.array([3.0, 0.2, -0.5])


def spec(task: str) -> str:
    return f"""version: 1
name: tasks
robot: {{model: iiwa14}}
limits: {{joint_torque: {{max: 1000, allow_outside_urdf: true}}}}
controller: {{formulation: osc}}
tasks:
  - {task}
  - {{name: rest, type: joint, priority: 2, gains: {{kp: 0, kd: 3}}}}
"""


def controller(task: str):
    return build_controller(load_spec_text(spec(task)))


def tool_state(q: np.ndarray, dq: np.ndarray):
    """Pinocchio's tool placement, world-aligned Jacobian and J̇q̇."""
    model = load_builtin_model("iiwa14")
    data = model.createData()
    pin.forwardKinematics(model, data, q, dq, np.zeros(model.nv))
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    fid = model.getFrameId("tool")
    J = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
    bias = pin.getFrameClassicalAcceleration(model, data, fid, pin.LOCAL_WORLD_ALIGNED).vector
    return data.oMf[fid], J, bias


def tool_acceleration(result, q, dq) -> np.ndarray:
    """The tool's actual 6-D acceleration J a + J̇q̇ (no τ_ext here: a = commanded q̈)."""
    _, J, bias = tool_state(q, dq)
    return J @ result.ddq + bias


def test_run_time_references_equal_constant_ones():
    constant = controller(f"{{name: reach, type: pose, frame: tool, priority: 1, gains: {{kp: 50, kd: 14}}, "
                          f"reference: {{position: {TARGET.tolist()}, rpy: {RPY.tolist()}}}}}")
    runtime = controller("{name: reach, type: pose, frame: tool, priority: 1, gains: {kp: 50, kd: 14}, reference: {input: true}}")
    layout = [(r.task, r.field, r.offset, r.size) for r in runtime.ref_layout]
    assert layout == [("reach", "position", 0, 3), ("reach", "rpy", 3, 3)]
    a = constant.step(Q, DQ)
    b = runtime.step(Q, DQ, ref=np.concatenate([TARGET, RPY]))
    np.testing.assert_allclose(a.tau, b.tau, rtol=1e-12, atol=1e-10)
    with pytest.raises(ValueError, match="reference vector of 6"):
        runtime.step(Q, DQ)


def test_feedforward_enters_the_desired_acceleration():
    c = controller("{name: reach, type: position, frame: tool, priority: 1, gains: {kp: 50, kd: 14}, "
                   "reference: {input: true, feedforward: true}}")
    assert [r.field for r in c.ref_layout] == ["position", "velocity", "acceleration"]
    v_ff, a_ff = np.array([0.1, -0.2, 0.05]), np.array([1.0, 0.5, -2.0])
    result = c.step(Q, DQ, ref=np.concatenate([TARGET, v_ff, a_ff]))
    placement, J, _ = tool_state(Q, DQ)
    desired = a_ff + 50 * (TARGET - placement.translation) + 14 * (v_ff - J[:3] @ DQ)
    np.testing.assert_allclose(tool_acceleration(result, Q, DQ)[:3], desired, rtol=1e-8, atol=1e-8)


def test_orientation_on_all_axes_is_the_world_rotation_vector():
    c = controller(f"{{name: point, type: orientation, frame: tool, axes: [rz, rx, ry], priority: 1, "
                   f"gains: {{kp: 30, kd: 8}}, reference: {{rpy: {RPY.tolist()}}}}}")
    placement, J, _ = tool_state(Q, DQ)
    error = pin.log3(pin.rpy.rpyToMatrix(*RPY) @ placement.rotation.T)
    desired = 30 * error - 8 * (J[3:] @ DQ)
    np.testing.assert_allclose(tool_acceleration(c.step(Q, DQ), Q, DQ)[[5, 3, 4]], desired[[2, 0, 1]], rtol=1e-8, atol=1e-8)


@pytest.mark.parametrize("axes", [("ry", "rx"), ("rx", "rz"), ("rz", "ry"), ("rz",), ("rx",), ("ry",)])
def test_orientation_subsets_are_the_swing_or_twist_about_the_frames_own_axes(axes):
    """Two own axes: the swing that points the free own axis like the target's; one own axis: the
    twist about it. Checked against Pinocchio's quaternions (tests/reference.orientation_terms),
    at a target 150° away about the free axis and 0.4 rad off otherwise."""
    placement, J, bias = tool_state(Q, DQ)
    free = [a for a in ("rx", "ry", "rz") if a not in axes]
    turn = np.zeros(3)
    turn[OWN[free[0]]] = np.deg2rad(150.0)
    target = placement.rotation @ pin.exp3(np.array([0.3, -0.2, 0.15])) @ pin.exp3(turn)
    rpy = pin.rpy.matrixToRpy(target)
    c = controller(f"{{name: point, type: orientation, frame: tool, axes: [{', '.join(axes)}], priority: 1, "
                   f"gains: {{kp: 30, kd: 8}}, reference: {{rpy: {rpy.tolist()}}}}}")
    ddq = c.step(Q, DQ).ddq
    if len(axes) == 2:
        B, error = orientation_terms(placement.rotation, target, axes)
        achieved = B.T @ (J[3:] @ ddq + bias[3:])
        np.testing.assert_allclose(achieved, 30 * error - 8 * (B.T @ J[3:] @ DQ), rtol=1e-8, atol=1e-8)
    else:  # the twist's own rate and acceleration, by differences of ψ along the motion
        model = load_builtin_model("iiwa14")
        fid = model.getFrameId("tool")
        h = 1e-4
        psi = [twist(model, fid, target, axes[0], Q + t * DQ + 0.5 * t**2 * ddq) for t in (-h, 0.0, h)]
        rate, acceleration = (psi[2] - psi[0]) / (2 * h), (psi[2] - 2 * psi[1] + psi[0]) / h**2
        # the error ψ is target − actual: the task acceleration is −ψ̈, its velocity −ψ̇
        np.testing.assert_allclose(-acceleration, 30 * psi[1] - 8 * -rate, rtol=1e-5, atol=1e-5)


def test_a_pointing_task_ignores_the_spin_about_its_free_axis():
    """[rx, ry]: targets that differ only by a turn about the target's own z give the same command."""
    placement, _, _ = tool_state(Q, DQ)
    base = placement.rotation @ pin.exp3(np.array([0.3, -0.2, 0.0]))
    commands = []
    for angle in (0.0, 90.0, 179.9, -179.9):
        rpy = pin.rpy.matrixToRpy(base @ pin.exp3(np.array([0.0, 0.0, np.deg2rad(angle)])))
        c = controller(f"{{name: point, type: orientation, frame: tool, axes: [rx, ry], priority: 1, "
                       f"gains: {{kp: 30, kd: 8}}, reference: {{rpy: {rpy.tolist()}}}}}")
        commands.append(c.step(Q, DQ).tau)
    for tau in commands[1:]:
        np.testing.assert_allclose(tau, commands[0], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("distance", [0.01, 0.3])
def test_saturated_law_limits_the_desired_velocity(distance: float):
    """ẍ_d = −kd(ẋ − v ẋ_d), ẋ_d = (kp/kd)Δx, v = min(1, v_sat/‖ẋ_d‖) (experiment 3's law)."""
    placement, J, _ = tool_state(Q, DQ)
    target = placement.translation + distance * np.array([0.0, 0.6, 0.8])
    c = controller(f"{{name: reach, type: position, frame: tool, priority: 1, gains: {{kp: 400, kd: 40, max_velocity: 0.4}}, "
                   f"reference: {{position: {target.tolist()}}}}}")
    result = c.step(Q, DQ)
    desired_velocity = 400 / 40 * (target - placement.translation)
    v = min(1.0, 0.4 / np.linalg.norm(desired_velocity))
    assert (v < 1.0) == (distance == 0.3)
    desired = -40 * (J[:3] @ DQ - v * desired_velocity)
    np.testing.assert_allclose(tool_acceleration(result, Q, DQ)[:3], desired, rtol=1e-8, atol=1e-8)


@pytest.mark.parametrize("axis", ["rx", "ry", "rz"])
def test_a_twist_target_half_a_turn_away_is_commanded_as_one_a_hair_off(axis):
    """The twist ψ = 2 atan2(q_k, q_w) at a half turn (q_w = 0) is read from 4 q_k² and 4 q_w q_k:
    as 4 q_w q_k / 4 q_w² it was atan2(0, 0) there, its derivative unbounded (QP rows of 1e14, a
    Panda's step fell back; found from outside). Exactly half a turn away the command is that of a
    target 1e-7 rad short of it on one side or the other (±π: the same rotation)."""
    placement, _, _ = tool_state(Q, DQ)
    k = OWN[axis]

    def command(angle: float) -> np.ndarray:
        turn = np.zeros(3)
        turn[k] = angle
        rpy = pin.rpy.matrixToRpy(placement.rotation @ pin.exp3(np.array([0.2, -0.1, 0.3]) * (turn == 0)) @ pin.exp3(turn))
        return controller(f"{{name: twist, type: orientation, frame: tool, axes: [{axis}], priority: 1, "
                          f"gains: {{kp: 30, kd: 8}}, reference: {{rpy: {rpy.tolist()}}}}}").step(Q, DQ).tau

    half = command(np.pi)
    assert np.isfinite(half).all()
    sides = [command(np.pi - 1e-7), command(-np.pi + 1e-7)]
    assert min(np.abs(half - side).max() for side in sides) < 1e-4 * np.abs(sides[0]).max(), (half, sides)
