"""Cartesian bounds on any plane, checked at the start and against constant targets, and the
numbers every limit message carries (issue: tasks and bounds that mean what the user wrote)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from dcts_spec import build_controller
from dcts_spec.spec import SpecError, load_spec_text
from dcts_spec.validate import validate_spec

TILT = np.deg2rad(20.0)
NORMAL = [0.0, float(np.sin(TILT)), float(np.cos(TILT))]  # a table tilted 20° about world x


def _spec(cartesian: str, target=(0.5, 0.0, 0.6), initial="[0, 30, 0, -60, 0, 60, 0]") -> str:
    return f"""version: 1
name: plane
robot: {{model: iiwa14}}
limits:
  joint_torque: {{max: 100}}
  cartesian:
    - {cartesian}
tasks:
  - {{name: reach, type: position, frame: tool, priority: 1, gains: {{kp: 60, kd: 16}}, reference: {{position: {list(target)}}}}}
  - {{name: damping, type: joint, priority: 2, gains: {{kp: 0, kd: 5}}}}
scenario: {{duration: 1.0, initial_q: {initial}, unit: deg}}
"""


def test_a_bound_crossed_at_the_start_is_a_located_error_with_numbers():
    with pytest.raises(SpecError) as e:
        validate_spec(load_spec_text(_spec("{frame: tool, axis: z, min: 0.7}"), "s.yaml"))
    message = str(e.value)
    assert "s.yaml:7:7: error: limits.cartesian[0]" in message and "0.6146 m" in message and "0.7 m ≤ tool.z" in message


def test_a_target_beyond_a_bound_is_a_warning_with_numbers():
    report = validate_spec(load_spec_text(_spec("{frame: tool, axis: z, min: 0.3}", target=(0.5, 0.0, 0.2)), "s.yaml"))
    warnings = [str(d) for d in report.diagnostics if d.severity == "warning"]
    assert any("s.yaml:9:" in w and "tool.z at 0.2 m" in w and "0.3 m ≤ tool.z" in w for w in warnings), warnings


def test_initial_q_outside_its_limits_names_values_and_limits():
    with pytest.raises(SpecError, match=r"joint 2 \(joint2\) at 130, 10 deg beyond its limits \[-120, 120\] deg"):
        validate_spec(load_spec_text(_spec("{frame: tool, axis: z, min: 0.1}", initial="[0, 130, 0, -60, 0, 60, 0]")))


@pytest.mark.parametrize("text", ["{frame: tool, axis: z, normal: [0, 0, 1], min: 0.1}",
                                  "{frame: tool, normal: [0, 0, 0], min: 0.1}",
                                  "{frame: tool, normal: [0, 0, 1], min: 0.1, expressed_in: link3}"])
def test_bad_planes_are_located_errors(text):
    with pytest.raises(SpecError, match=r"limits\.cartesian\[0\]"):
        validate_spec(load_spec_text(_spec(text)))


def test_a_tilted_plane_holds_in_closed_loop_while_the_target_lies_beyond_it():
    """n̂ᵀp ≥ 0.45 on a plane tilted 20°; the target is 0.2 m below it. The loop integrates the
    controller's own q̈ (semi-implicit Euler) and a 0.2 s external push (15 and 10 Nm on joints 2
    and 4, measured) half way; the tool must stay on its side (1e-5 m) and end on the plane."""
    text = _spec(f"{{frame: tool, normal: {NORMAL}, min: 0.45}}", target=(0.5, -0.1, 0.3))
    c = build_controller(load_spec_text(text))
    model = c.robot.model
    data = model.createData()
    fid = model.getFrameId("tool")
    n = np.array(NORMAL)
    q, dq, dt = np.deg2rad([0, 30, 0, -60, 0, 60, 0]), np.zeros(7), 0.001
    lowest = np.inf
    for k in range(1500):
        push = np.array([0, 15, 0, 10, 0, 0, 0]) if 500 <= k < 700 else np.zeros(7)
        r = c.step(q, dq, tau_ext=push)
        assert r.status == 0, (k, r.status, r.relaxed)
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        dq = dq + dt * (r.ddq + np.linalg.solve(M, push))
        q = q + dt * dq
        pin.framesForwardKinematics(model, data, q)
        lowest = min(lowest, n @ data.oMf[fid].translation)
    assert lowest >= 0.45 - 1e-5, lowest
    assert abs(n @ data.oMf[fid].translation - 0.45) < 2e-3  # the task pulled it onto the plane


def test_a_plane_given_in_a_fixed_frame_is_that_plane_in_the_world():
    world = validate_spec(load_spec_text(_spec(f"{{frame: tool, normal: {NORMAL}, min: 0.45}}"))).robot
    base = validate_spec(load_spec_text(_spec(f"{{frame: tool, normal: {NORMAL}, min: 0.45, expressed_in: universe}}"))).robot
    assert world.cartesian_bounds[0].direction == pytest.approx(base.cartesian_bounds[0].direction)
    assert world.cartesian_bounds[0].c_min == pytest.approx(base.cartesian_bounds[0].c_min)


def test_a_urdf_without_movable_joints_is_a_located_error(tmp_path):
    (tmp_path / "fixed.urdf").write_text('<robot name="fixed"><link name="base"/><link name="a"/>'
                                          '<joint name="j" type="fixed"><parent link="base"/><child link="a"/></joint></robot>')
    spec = tmp_path / "s.yaml"
    spec.write_text("version: 1\nname: t\nrobot: {urdf: fixed.urdf}\n"
                    "tasks:\n  - {name: d, type: joint, priority: 1, gains: {kp: 0, kd: 5}}\n")
    from dcts_spec.spec import load_spec

    with pytest.raises(SpecError, match=r"s\.yaml:3:9: error: robot\.urdf: the URDF fixed\.urdf has no movable joint"):
        validate_spec(load_spec(spec))


def test_a_waypoint_beyond_a_bound_is_a_warning():
    text = _spec("{frame: tool, axis: z, min: 0.3}").replace(
        "reference: {position: [0.5, 0.0, 0.6]}", "reference: {input: true}").replace(
        "scenario: {duration: 1.0,", "scenario: {waypoints: {task: reach, tolerance: 0.01, points: [[0.5, 0, 0.5], [0.5, 0, 0.25]]}, duration: 1.0,")
    report = validate_spec(load_spec_text(text, "s.yaml"))
    warnings = [str(d) for d in report.diagnostics if d.severity == "warning"]
    assert len(warnings) == 1 and "scenario.waypoints.points[1]" in warnings[0] and "tool.z at 0.25 m" in warnings[0], warnings


def test_limits_wider_than_the_urdf_name_the_values():
    text = _spec("{frame: tool, axis: z, min: 0.1}").replace("joint_torque: {max: 100}", "joint_torque: {max: [100, 200, 100, 100, 100, 100, 100]}")
    with pytest.raises(SpecError, match=r"limits\.joint_torque\.max: above the URDF's effort limit \(joint 2, joint2: 200 vs 100 Nm\)"):
        validate_spec(load_spec_text(text))
