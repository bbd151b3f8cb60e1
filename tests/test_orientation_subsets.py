"""Orientation subsets in closed loop: pointing tasks ([rx, ry]: the tool's own z free) and a
twist task ([rz]: only the spin about the tool's own z) settle as their PD gains say, whatever
the offset about the free axes, up to 179.9°.

The loop integrates the controller's own q̈ (semi-implicit Euler at the control period), so it
checks the task's error and Jacobian, not a simulator. kp = 100, kd = 20 is critically damped
(ω = 10 rad/s): each run is compared with that linear response, (1 + ωt) e^(−ωt), which falls to
0.05 % of the start in 1 s."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from dcts_spec import build_controller
from dcts_spec.spec import load_spec_text
from reference import orientation_terms

DT = 0.001
HOME = {"iiwa14": [0.0, 0.5, 0.0, -1.3, 0.0, 1.2, 0.0], "panda": [0.0, -0.3, 0.0, -2.0, 0.0, 1.8, 0.8]}
TOOL = {"iiwa14": "tool", "panda": "panda_hand_tcp"}


def _spec(robot: str, axes: tuple[str, ...], rpy: np.ndarray) -> str:
    return f"""version: 1
name: subsets
robot: {{model: {robot}}}
controller: {{formulation: dcts}}
tasks:
  - {{name: point, type: orientation, frame: {TOOL[robot]}, axes: [{", ".join(axes)}], priority: 1, gains: {{kp: 100, kd: 20}}, reference: {{rpy: {rpy.tolist()}}}}}
  - {{name: posture, type: joint, priority: 2, gains: {{kp: 5, kd: 5}}, reference: {{q: {HOME[robot]}}}}}
limits: {{joint_torque: {{max: 1000, allow_outside_urdf: true}}, joint_velocity: {{max: 10, allow_outside_urdf: true}}}}
"""


def _errors(robot: str, axes: tuple[str, ...], free_angle_deg: float, seconds: float = 1.0) -> np.ndarray:
    """‖error‖ over a run whose target is 0.3 rad off in the controlled axes and `free_angle_deg`
    about the (first) free own axis, by Pinocchio's computation of the error."""
    q = np.array(HOME[robot])
    c = build_controller(load_spec_text(_spec(robot, axes, np.zeros(3))))  # for the model only
    model = c.robot.model
    data = model.createData()
    fid = model.getFrameId(TOOL[robot])
    pin.framesForwardKinematics(model, data, q)
    R0 = data.oMf[fid].rotation
    free = [k for k, a in enumerate(("rx", "ry", "rz")) if a not in axes][0]
    turn, tilt = np.zeros(3), np.zeros(3)
    turn[free] = np.deg2rad(free_angle_deg)
    for k, a in enumerate(("rx", "ry", "rz")):
        if a in axes:
            tilt[k] = 0.3 / np.sqrt(len(axes))
    target = R0 @ pin.exp3(tilt) @ pin.exp3(turn)
    c = build_controller(load_spec_text(_spec(robot, axes, pin.rpy.matrixToRpy(target))))
    dq = np.zeros(model.nv)
    out = []
    for _ in range(int(seconds / DT)):
        pin.framesForwardKinematics(model, data, q)
        out.append(np.linalg.norm(orientation_terms(data.oMf[fid].rotation, target, axes)[1]))
        r = c.step(q, dq)
        assert r.status == 0
        dq = dq + DT * r.ddq
        q = pin.integrate(model, q, DT * dq)
    return np.array(out)


@pytest.mark.parametrize(("robot", "axes", "free_angles"), [
    ("iiwa14", ("rx", "ry"), (-179.9,)),
    ("panda", ("ry", "rz"), (179.9,)),
    ("panda", ("rz",), (179.9,)),
])
def test_subset_settles_whatever_the_free_offset(robot, axes, free_angles):
    runs = {angle: _errors(robot, axes, angle) for angle in free_angles}
    t = DT * np.arange(len(next(iter(runs.values()))))
    response = (1.0 + 10.0 * t) * np.exp(-10.0 * t)  # a linear PD's error, ω = 10 rad/s, from rest
    for angle, e in runs.items():
        assert e[0] > 0.25, (angle, e[0])  # the premise: 0.3 rad to go
        assert e[-1] < 1e-3 * e[0], f"free offset {angle}°: {e[-1]:.3g} rad left after 1 s (started at {e[0]:.3g})"
        assert np.all(np.diff(e) <= 1e-9), f"free offset {angle}°: the error grows at t = {np.argmax(np.diff(e) > 1e-9) * DT:.3f} s"
        np.testing.assert_allclose(e / e[0], response, rtol=0, atol=5e-3)  # (the loop's 1 ms Euler steps: ~2e-3)
