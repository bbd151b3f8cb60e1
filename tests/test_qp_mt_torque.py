"""QP-MT's two readings (controller.minimized_torque): r = ‖τ‖² or r = ‖τ − g‖².

At rest with a task that asks for nothing (a damping task on joint 7, q̇ = 0), QP-MT minimizes its
regularization alone: without gravity ‖M q̈‖² is smallest at q̈ = 0, so τ = g (Pinocchio's); with
gravity included, the torque is smallest when the arm is let fall: ‖τ‖ < ‖g‖.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from dcts_spec.controller import build_controller
from dcts_spec.robot.builtin import load_builtin_model
from dcts_spec.spec import load_spec_text

Q = np.array([-0.78, 2.05, 2.07, -1.65, -2.08, 2.03, 0.0])  # the paper's q_ini, gravity loads the arm


def _torque(minimized: str | None) -> np.ndarray:
    option = f"\n  minimized_torque: {minimized}" if minimized else ""
    spec = load_spec_text(f"""
version: 1
name: qp_mt_reading
robot: {{model: iiwa14}}
controller:
  formulation: qp_mt{option}
tasks:
  - {{name: wrist, type: joint, joints: [joint7], priority: 1, gains: {{kp: 0, kd: 1}}}}
""", "qp_mt_reading.yaml")
    controller = build_controller(spec)
    return controller.step(Q, np.zeros(7)).tau


def test_without_gravity_holds_the_arm_still():
    model = load_builtin_model("iiwa14")
    g = pin.computeGeneralizedGravity(model, model.createData(), Q)
    assert _torque("without_gravity") == pytest.approx(g, abs=1e-4 * np.abs(g).max())


def test_full_torque_lets_the_arm_fall_and_is_the_default():
    model = load_builtin_model("iiwa14")
    g = pin.computeGeneralizedGravity(model, model.createData(), Q)
    full = _torque("full")
    assert np.linalg.norm(full) < 0.9 * np.linalg.norm(g)
    assert _torque(None) == pytest.approx(full)
