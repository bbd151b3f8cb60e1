"""The iiwa14 URDF against its parameter table (shared/robots/iiwa14.md)."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from dcts_spec.robot.builtin import iiwa14_urdf_path

# link: (pos in parent, quat wxyz not normalized, mass, com, principal inertia, range)
TABLE = {
    "link1": ((0, 0, 0.1575), (1, 0, 0, 0), 5.76, (0, -0.03, 0.12), (0.0333, 0.033, 0.0123), 2.96706),
    "link2": ((0, 0, 0.2025), (0, 0, 1, 1), 6.35, (0.0003, 0.059, 0.042), (0.0305, 0.0304, 0.011), 2.0944),
    "link3": ((0, 0.2045, 0), (0, 0, 1, 1), 3.5, (0, 0.03, 0.13), (0.025, 0.0238, 0.0076), 2.96706),
    "link4": ((0, 0, 0.2155), (1, 1, 0, 0), 3.5, (0, 0.067, 0.034), (0.017, 0.0164, 0.006), 2.0944),
    "link5": ((0, 0.1845, 0), (0, 0, 1, 1), 3.5, (0.0001, 0.021, 0.076), (0.01, 0.0087, 0.00449), 2.96706),
    "link6": ((0, 0, 0.2155), (1, 1, 0, 0), 1.8, (0, 0.0006, 0.0004), (0.0049, 0.0047, 0.0036), 2.0944),
    "link7": ((0, 0.081, 0), (0, 0, 1, 1), 1.2, (0, 0, 0.02), (0.001, 0.001, 0.001), 3.05433),
}
VMAX_DEG = (100, 110, 100, 130, 130, 180, 180)


@pytest.fixture(scope="module")
def model() -> pin.Model:
    return pin.buildModelFromUrdf(str(iiwa14_urdf_path()))


def test_structure(model: pin.Model) -> None:
    assert model.name == "iiwa14"
    assert model.nq == model.nv == 7
    assert list(model.names)[1:] == [f"joint{i}" for i in range(1, 8)]
    assert all(model.joints[i].shortname() == "JointModelRZ" for i in range(1, 8))
    for i, link in enumerate(TABLE, start=1):
        frame = model.frames[model.getFrameId(link, pin.FrameType.BODY)]
        assert frame.parentJoint == i
        assert frame.placement.isIdentity()


def test_placements_and_inertias(model: pin.Model) -> None:
    for i, (pos, quat, mass, com, diag, _) in enumerate(TABLE.values(), start=1):
        w, x, y, z = quat
        rotation = pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()
        np.testing.assert_allclose(model.jointPlacements[i].translation, pos, atol=1e-15)
        np.testing.assert_allclose(model.jointPlacements[i].rotation, rotation, atol=1e-15)
        inertia = model.inertias[i]
        assert inertia.mass == pytest.approx(mass, abs=1e-15)
        np.testing.assert_allclose(inertia.lever, com, atol=1e-15)
        np.testing.assert_allclose(inertia.inertia, np.diag(diag), atol=1e-15)


def test_limits(model: pin.Model) -> None:
    ranges = np.array([row[-1] for row in TABLE.values()])
    np.testing.assert_array_equal(model.upperPositionLimit, ranges)
    np.testing.assert_array_equal(model.lowerPositionLimit, -ranges)
    np.testing.assert_allclose(model.velocityLimit, np.deg2rad(VMAX_DEG), rtol=1e-15)
    np.testing.assert_array_equal(model.effortLimit, np.full(7, 100.0))


def test_tool_frame(model: pin.Model) -> None:
    assert model.existFrame("tool")
    tool = model.frames[model.getFrameId("tool")]
    assert tool.parentJoint == model.getJointId("joint7")
    assert tool.placement.isApprox(pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.045])), 1e-15)


def test_mujoco_keeps_tool_body() -> None:
    mj_model = mujoco.MjModel.from_xml_path(str(iiwa14_urdf_path()))
    assert mj_model.nv == 7
    assert mj_model.body("tool").parentid[0] == mj_model.body("link7").id
