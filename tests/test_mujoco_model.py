"""The MuJoCo model built from a Pinocchio model has the same dynamics, sites and payloads."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from dcts_spec.robot.builtin import example_robot_data_dir, load_builtin_model, random_configuration
from dcts_spec.sim.mujoco_model import Payload, bias_forces, build_mujoco_model, mass_matrix


def _ur5() -> pin.Model:
    return pin.buildModelFromUrdf(str(example_robot_data_dir() / "ur_description/urdf/ur5_robot.urdf"))


def _synthetic() -> pin.Model:
    """Unaligned and prismatic joints, a massless link and a point mass."""
    rng = np.random.default_rng(3)

    def placement() -> pin.SE3:
        return pin.SE3(pin.exp3(rng.normal(size=3)), 0.2 * rng.normal(size=3))

    def body() -> pin.Inertia:
        rotation = pin.exp3(rng.normal(size=3))
        return pin.Inertia(1.5, 0.1 * rng.normal(size=3), rotation @ np.diag([0.02, 0.03, 0.04]) @ rotation.T)

    point_mass = pin.Inertia(0.7, np.array([0.1, 0.0, 0.2]), np.zeros((3, 3)))
    links = [
        (pin.JointModelRevoluteUnaligned(0.48, -0.6, 0.64), body()),
        (pin.JointModelPY(), pin.Inertia.Zero()),
        (pin.JointModelPrismaticUnaligned(0.6, 0.0, 0.8), point_mass),
        (pin.JointModelRX(), body()),
    ]
    model = pin.Model()
    joint_id = 0
    for k, (joint, inertia) in enumerate(links):
        joint_id = model.addJoint(joint_id, joint, placement(), f"j{k}")
        model.appendBodyToJoint(joint_id, inertia, pin.SE3.Identity())
    model.lowerPositionLimit[:] = -1.0
    model.upperPositionLimit[:] = 1.0
    return model


MODELS = {
    "iiwa14": lambda: load_builtin_model("iiwa14"),
    "panda": lambda: load_builtin_model("panda"),
    "ur5": _ur5,
    "synthetic": _synthetic,
}


@pytest.mark.parametrize("name", MODELS)
def test_dynamics_match_pinocchio(name: str) -> None:
    model = MODELS[name]()
    data = model.createData()
    mj_model = build_mujoco_model(model)
    mj_data = mujoco.MjData(mj_model)
    rng = np.random.default_rng(0)
    mass_error = bias_error = 0.0
    for _ in range(20):
        q = random_configuration(model, rng)
        dq = rng.uniform(-2.0, 2.0, model.nv)
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        mass_error = max(mass_error, np.abs(mass_matrix(mj_model, mj_data, q) - M).max() / np.abs(M).max())
        bias = pin.rnea(model, data, q, dq, np.zeros(model.nv))
        bias_error = max(bias_error, np.abs(bias_forces(mj_model, mj_data, q, dq) - bias).max())
    assert mass_error < 1e-12
    assert bias_error < 1e-10


def test_actuators_are_unclamped_joint_motors() -> None:
    model = load_builtin_model("iiwa14")
    mj_model = build_mujoco_model(model, timestep=0.002, integrator="rk4")
    assert mj_model.opt.timestep == 0.002
    assert mj_model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
    assert mj_model.nu == model.nv
    assert not mj_model.jnt_limited.any()
    assert not mj_model.actuator_ctrllimited.any()
    mj_data = mujoco.MjData(mj_model)
    mj_data.ctrl[:] = np.arange(1.0, 8.0)
    mujoco.mj_forward(mj_model, mj_data)
    np.testing.assert_array_equal(mj_data.qfrc_actuator, mj_data.ctrl)


@pytest.mark.parametrize(
    ("name", "frames"), [("iiwa14", ["tool", "link7"]), ("panda", ["panda_hand_tcp", "panda_hand"])]
)
def test_sites_follow_frames(name: str, frames: list[str]) -> None:
    model = load_builtin_model(name)
    data = model.createData()
    mj_model = build_mujoco_model(model)
    mj_data = mujoco.MjData(mj_model)
    q = random_configuration(model, np.random.default_rng(1))
    pin.framesForwardKinematics(model, data, q)
    mj_data.qpos[:] = q
    mujoco.mj_kinematics(mj_model, mj_data)
    for frame in frames:
        placement = data.oMf[model.getFrameId(frame)]
        site = mj_data.site(frame)
        np.testing.assert_allclose(site.xpos, placement.translation, atol=1e-14)
        np.testing.assert_allclose(site.xmat.reshape(3, 3), placement.rotation, atol=1e-14)


@pytest.mark.parametrize("inertia", [None, (0.01, 0.02, 0.015)])
def test_payload_adds_its_gravity_torque(inertia: tuple[float, float, float] | None) -> None:
    model = load_builtin_model("iiwa14")
    data = model.createData()
    payload = Payload("tool", mass=2.5, com=(0.02, -0.01, 0.05), inertia=inertia)
    bare = build_mujoco_model(model)
    loaded = build_mujoco_model(model, payloads=[payload])
    bare_data, loaded_data = mujoco.MjData(bare), mujoco.MjData(loaded)
    rng = np.random.default_rng(2)
    frame_id = model.getFrameId("tool")
    for _ in range(5):
        q = random_configuration(model, rng)
        dq = np.zeros(model.nv)
        delta = bias_forces(loaded, loaded_data, q, dq) - bias_forces(bare, bare_data, q, dq)
        J = pin.computeFrameJacobian(model, data, q, frame_id, pin.LOCAL_WORLD_ALIGNED)
        lever = data.oMf[frame_id].rotation @ np.array(payload.com)
        J_point = J[:3] - pin.skew(lever) @ J[3:]
        np.testing.assert_allclose(delta, -J_point.T @ (payload.mass * model.gravity.linear), atol=1e-12)


def test_geometry_meshes_and_primitives() -> None:
    package_dir = example_robot_data_dir().parent.parent
    urdf = example_robot_data_dir() / "panda_description/urdf/panda.urdf"
    model, collision, visual = pin.buildModelsFromUrdf(str(urdf), package_dirs=[str(package_dir)])
    mj_model = build_mujoco_model(model, geometry=collision)
    assert mj_model.ngeom == collision.ngeoms
    assert mj_model.nmesh > 0
    assert not mj_model.geom_contype.any() and not mj_model.geom_conaffinity.any()
    # Collada meshes are skipped: MuJoCo cannot read them.
    assert build_mujoco_model(model, geometry=visual).ngeom == 0


def test_rejects_floating_base_and_unknown_integrator() -> None:
    model = pin.Model()
    model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "root")
    with pytest.raises(ValueError, match="JointModelFreeFlyer"):
        build_mujoco_model(model)
    with pytest.raises(ValueError, match="integrator"):
        build_mujoco_model(load_builtin_model("iiwa14"), integrator="verlet")
    with pytest.raises(ValueError, match="payload frame"):
        build_mujoco_model(load_builtin_model("iiwa14"), payloads=[Payload("nowhere", 1.0)])
