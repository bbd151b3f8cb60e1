"""A URDF's continuous joints are driven as revolute joints without position limits (robot/urdf.py)."""

from __future__ import annotations

from pathlib import Path
from xml.etree import ElementTree

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from dcts_spec.controller import build_controller
from dcts_spec.limits.naming import joint_bound_text
from dcts_spec.robot.describe import describe
from dcts_spec.robot.model import JointLimits
from dcts_spec.robot.urdf import build_model, revolute_from_continuous
from dcts_spec.sim.runner import prepare_simulation
from dcts_spec.spec import SpecError, load_spec
from dcts_spec.validate import validate_spec
from formulation_cases import numeric_tasks, relative
from reference import closed_form_hierarchy

INERTIAL = """<inertial><origin xyz="0.05 0.01 0.2"/><mass value="{m}"/>
      <inertia ixx="0.03" iyy="0.02" izz="0.01" ixy="0.001" ixz="0" iyz="0.002"/></inertial>"""
# A revolute shoulder, a continuous forearm roll (effort and velocity given) and a continuous
# wrist without a <limit> element, about three different axes.
URDF = f"""<robot name="roll_arm">
  <link name="base"/>
  <link name="upper">{INERTIAL.format(m=2.0)}</link>
  <link name="forearm">{INERTIAL.format(m=1.5)}</link>
  <link name="hand">{INERTIAL.format(m=0.5)}</link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="80" velocity="2"/></joint>
  <joint name="forearm_roll" type="continuous"><parent link="upper"/><child link="forearm"/>
    <origin xyz="0 0 0.4" rpy="0.2 0 0"/><axis xyz="0 0 1"/><limit effort="30" velocity="3"/></joint>
  <joint name="wrist_roll" type="continuous"><parent link="forearm"/><child link="hand"/>
    <origin xyz="0 0 0.3"/><axis xyz="1 0 0"/></joint>
  <link name="tool"/>
  <joint name="tool_joint" type="fixed"><parent link="hand"/><child link="tool"/><origin xyz="0.1 0 0.05"/></joint>
</robot>
"""


def _urdf(tmp_path: Path) -> Path:
    path = tmp_path / "roll_arm.urdf"
    path.write_text(URDF)
    return path


def _pinocchio_configuration(angles: np.ndarray) -> np.ndarray:
    """The same configuration in Pinocchio's own model of the URDF: (cos, sin) per continuous joint."""
    return np.array([angles[0], np.cos(angles[1]), np.sin(angles[1]), np.cos(angles[2]), np.sin(angles[2])])


def test_a_continuous_joint_is_a_revolute_one_with_the_same_dynamics(tmp_path: Path) -> None:
    """One angle per joint (nq = nv), no position limits, the URDF's effort and velocity kept; and
    the mass matrix, the inverse dynamics and the tool's placement of Pinocchio's own model of the
    file (cosine and sine per continuous joint) at the same angles."""
    path = _urdf(tmp_path)
    assert revolute_from_continuous(ElementTree.parse(path).getroot()) == ["forearm_roll", "wrist_roll"]
    model = build_model(path)
    assert model.nq == model.nv == 3
    limits = JointLimits.of_model(model)
    assert np.isneginf(limits.q_min[1:]).all() and np.isposinf(limits.q_max[1:]).all()
    assert limits.q_min[0] == -2 and limits.tau_max.tolist() == [80, 30, np.inf] and limits.v_max[1] == 3

    original = pin.buildModelFromUrdf(str(path))
    assert original.nq == 5
    rng = np.random.default_rng(3)
    for _ in range(5):
        angles, v, a = rng.uniform(-4, 4, 3), rng.normal(size=3), rng.normal(size=3)
        q = _pinocchio_configuration(angles)
        ours, theirs = model.createData(), original.createData()
        assert np.allclose(pin.crba(model, ours, angles), pin.crba(original, theirs, q), atol=1e-12)
        assert np.allclose(pin.rnea(model, ours, angles, v, a), pin.rnea(original, theirs, q, v, a), atol=1e-12)
        pin.framesForwardKinematics(model, ours, angles)
        pin.framesForwardKinematics(original, theirs, q)
        tool = ours.oMf[model.getFrameId("tool")], theirs.oMf[original.getFrameId("tool")]
        assert np.allclose(tool[0].homogeneous, tool[1].homogeneous, atol=1e-12)


ROLL_ARM_SPEC = """version: 1
name: roll_arm
robot:
  urdf: roll_arm.urdf
  locked_joints: {wrist_roll: 0.7}
tasks:
  - name: tool
    type: position
    frame: tool
    axes: [x]
    priority: 1
    gains: {kp: 100, kd: 20}
    reference: {position: [0.1, 0.0, 0.0]}
  - name: posture
    type: joint
    priority: 2
    gains: {kp: 10, kd: 6}
    reference: {q: [0.3, 4.0]}
"""


def _roll_arm_spec(tmp_path: Path):
    """The roll arm with its wrist locked: a position task on the tool, a posture whose target for
    the continuous forearm roll (4.0 rad) is the long way round from where the tests put it."""
    _urdf(tmp_path)
    spec_file = tmp_path / "roll_arm.yaml"
    spec_file.write_text(ROLL_ARM_SPEC)
    return load_spec(spec_file)


def test_a_spec_drives_a_continuous_joint_and_locks_one_at_its_angle(tmp_path: Path) -> None:
    """A spec on that URDF validates (the joint was refused before), locks the wrist at 0.7 rad
    where the tool is where Pinocchio's own model puts it, and its controller steps with status ok.
    `dcts describe` calls the forearm roll continuous."""
    path = _urdf(tmp_path)
    spec = _roll_arm_spec(tmp_path)
    robot = validate_spec(spec).robot
    assert robot.joint_names == ["shoulder", "forearm_roll"]
    assert joint_bound_text(robot, 1) == "|forearm_roll'| ≤ 3 rad/s"  # (what summary.json names a relaxed bound by)
    angles = np.array([0.4, -2.5])
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, angles)
    original = pin.buildModelFromUrdf(str(path))
    theirs = original.createData()
    pin.framesForwardKinematics(original, theirs, _pinocchio_configuration(np.array([*angles, 0.7])))
    assert np.allclose(data.oMf[robot.model.getFrameId("tool")].homogeneous,
                       theirs.oMf[original.getFrameId("tool")].homogeneous, atol=1e-12)

    controller = build_controller(spec)
    result = controller.step(angles, np.array([0.1, 2.0]), np.zeros(2))
    assert result.status == 0 and np.isfinite(result.tau).all()
    # the posture (targets 0.3 and 4.0 rad) takes the short way round on the continuous joint only
    problem = controller.problem
    posture_error = ca.Function("e", [problem.q, problem.param], [problem.levels[-1].error])
    error = np.array(posture_error([-3.7, 4.0 - 2 * np.pi + 0.1], problem.param_layout.defaults)).ravel()
    assert np.allclose(error, [4.0, -0.1], atol=1e-12)
    kinds = {joint.name: joint.type for joint in describe(str(path)).joints}
    assert kinds == {"shoulder": "revolute", "forearm_roll": "continuous", "wrist_roll": "continuous"}


PENDULUM = """version: 1
name: pendulum
robot:
  urdf: {urdf}
{limits}tasks:
  - {{name: posture, type: joint, priority: 1, gains: {{kp: 10, kd: 6}}, reference: {{q: [0.5, -0.5]}}}}
"""


def test_a_joint_whose_urdf_range_is_empty_has_no_position_limits(tmp_path):
    """example-robot-data's double pendulum gives its revolute joints <limit lower="0" upper="0">
    (and effort and velocity 0): meant as no limits, as an effort of 0 is. Read as [0, 0] they were
    held still by their own position bounds, silently. They are now driven without position
    limits, with a warning naming them, unless the spec gives limits.joint_position."""
    from dcts_spec.robot.builtin import example_robot_data_dir

    urdf = example_robot_data_dir() / "double_pendulum_description" / "urdf" / "double_pendulum.urdf"
    spec = tmp_path / "pendulum.yaml"
    spec.write_text(PENDULUM.format(urdf=urdf, limits=""))
    report = validate_spec(load_spec(spec))
    assert np.all(np.isneginf(report.robot.limits.q_min)) and np.all(np.isposinf(report.robot.limits.q_max))
    (warning,) = [d for d in report.diagnostics if "no position range" in d.message]
    assert "joint1, joint2" in warning.message and "limits.joint_position" in warning.message
    assert "q ∈ [-∞, -∞] .. [∞, ∞] deg" in report.summary()
    spec.write_text(PENDULUM.format(urdf=urdf, limits="limits:\n  joint_position: {min: -1, max: 1}\n"))
    report = validate_spec(load_spec(spec))
    assert np.array_equal(report.robot.limits.q_max, [1.0, 1.0])
    assert not [d for d in report.diagnostics if "no position range" in d.message]


def test_a_joint_whose_urdf_limits_are_inverted_is_an_error(tmp_path):
    """<limit lower="1" upper="-1"> validated (the summary read q ∈ [57.3, -57.3] deg), and building
    the controller then failed with "high - low < 0" (first seen from outside)."""
    from dcts_spec.robot.builtin import example_robot_data_dir

    source = example_robot_data_dir() / "double_pendulum_description" / "urdf" / "double_pendulum.urdf"
    text = source.read_text()
    old = 'lower="0"\n      upper="0"'
    assert old in text, "example-robot-data's double pendulum changed: update this test"
    urdf = tmp_path / "pendulum.urdf"
    urdf.write_text(text.replace(old, 'lower="1"\n      upper="-1"', 1))
    spec = tmp_path / "pendulum.yaml"
    spec.write_text(PENDULUM.format(urdf=urdf, limits=""))
    with pytest.raises(SpecError) as caught:
        validate_spec(load_spec(spec))
    assert "the URDF gives joint1 (1 > -1) a lower position limit above its upper one" in str(caught.value)


def test_a_joint_and_a_link_named_alike_are_two_frames_and_the_link_keeps_the_name(tmp_path):
    """A URDF may name a fixed joint and a link alike (example-robot-data's B1-Z1: `gripperStator`):
    Pinocchio's lookup by that name raised, and every command exited with an internal error (3).
    The link keeps the name, the joint's frame is `<name>_fixed_joint`; the spec's task, Cartesian
    bound and push on that name validate and run."""
    path = tmp_path / "roll_arm.urdf"
    # (and a link already called what the joint's frame would become: that name stays the link's)
    path.write_text(URDF.replace('<joint name="tool_joint"', '<joint name="tool"').replace(
        '<link name="tool"/>', '<link name="tool"/>\n  <link name="tool_fixed_joint"/>\n  <joint name="tip" type="fixed">'
        '<parent link="tool"/><child link="tool_fixed_joint"/></joint>'))
    model = build_model(path)
    names = [frame.name for frame in model.frames]
    assert names.count("tool") == names.count("tool_fixed_joint") == names.count("tool_fixed_joint_") == 1
    assert model.frames[model.getFrameId("tool")].type == pin.FrameType.BODY
    assert model.frames[model.getFrameId("tool_fixed_joint")].type == pin.FrameType.BODY
    spec_file = tmp_path / "named_alike.yaml"
    spec_file.write_text(f"""version: 1
name: named_alike
robot:
  urdf: {path.name}
limits:
  cartesian:
    - {{frame: tool, axis: z, min: -1.0}}
tasks:
  - {{name: tool, type: position, frame: tool, axes: [x], priority: 1, gains: {{kp: 100, kd: 20}},
     reference: {{position: [0.1, 0.0, 0.0]}}}}
  - {{name: posture, type: joint, priority: 2, gains: {{kp: 10, kd: 6}}, reference: {{q: [0.3, 0.2, 0.1]}}}}
scenario:
  duration: 0.05
  disturbances:
    - {{type: force, body: tool, force: [0, 0, -5], start: 0.01, duration: 0.02}}
""")
    spec = load_spec(spec_file)
    warnings = [d.message for d in validate_spec(spec).diagnostics if d.severity == "warning"]
    assert any("the link keeps the name, the other is tool_fixed_joint_" in w for w in warnings), warnings
    result = build_controller(spec).step(np.zeros(3), np.zeros(3), np.zeros(3))
    assert result.status == 0
    log = prepare_simulation(spec, "python").run()
    assert np.isfinite(log.tau).all() and np.abs(log.tau_ext_true).max() > 0  # (the push reached the tool)


def test_a_locked_joint_named_as_a_link_is_locked(tmp_path):
    """A joint named as a link, locked (the SO-100's `gripper`, found from outside): Pinocchio's
    reduction looks the joint's frame up by its name, which was the link's too, and `dcts validate`
    exited with an internal error (3). Locked, the model is the one whose joint has a name of its
    own, locked at the same angle; the link keeps the name."""
    def spec_with(urdf: str, joint: str, name: str) -> Path:
        path = tmp_path / f"{name}.urdf"
        path.write_text(urdf)
        spec = tmp_path / f"{name}.yaml"
        spec.write_text(f"""version: 1
name: {name}
robot:
  urdf: {path.name}
  locked_joints: {{{joint}: 0.3}}
tasks:
  - {{name: tool, type: position, frame: hand, axes: [x], priority: 1, gains: {{kp: 100, kd: 20}},
     reference: {{position: [0.1, 0.0, 0.0]}}}}
""")
        return spec

    alike = validate_spec(load_spec(spec_with(URDF.replace('joint name="wrist_roll"', 'joint name="hand"'), "hand", "alike")))
    own = validate_spec(load_spec(spec_with(URDF, "wrist_roll", "own")))
    model, reference = alike.robot.model, own.robot.model
    assert model.nv == reference.nv == 2
    assert model.frames[model.getFrameId("hand")].type == pin.FrameType.BODY
    q = np.array([0.4, -0.7])
    assert np.array_equal(pin.crba(model, model.createData(), q), pin.crba(reference, reference.createData(), q))
    assert build_controller(alike.spec).step(q, np.zeros(2), np.zeros(2)).status == 0


@pytest.mark.parametrize(("limit", "severity", "words"), [
    ('<limit lower="-2" upper="2" velocity="2"/>', "error", "joint shoulder (revolute) has no effort"),
    ('<limit lower="-2" upper="2"/>', "error", "joint shoulder (revolute) has no effort or velocity"),
    ('<limit lower="-2" upper="2" effort="0" velocity="2"/>', "warning", "gives shoulder, wrist_roll no effort limit"),
])
def test_a_urdf_joint_without_its_limits_is_named(tmp_path, limit, severity, words):
    """urdfdom refuses a revolute joint whose <limit> lacks effort or velocity with "does not contain
    a valid URDF model", naming nothing: the error names the joint and what is missing. An effort of
    0 reads as no limit, which was silent (iCub-like URDFs, found from outside): a warning."""
    path = tmp_path / "roll_arm.urdf"
    urdf = URDF.replace('<limit lower="-2" upper="2" effort="80" velocity="2"/>', limit)
    assert urdf != URDF
    path.write_text(urdf)
    spec_file = tmp_path / "arm.yaml"
    spec_file.write_text(f"version: 1\nname: arm\nrobot:\n  urdf: {path.name}\ntasks:\n"
                         "  - {name: posture, type: joint, priority: 1, gains: {kp: 10, kd: 6}, reference: {q: [0.3, 0.2, 0.1]}}\n")
    if severity == "error":
        with pytest.raises(SpecError) as raised:
            validate_spec(load_spec(spec_file))
        assert words in str(raised.value)
    else:
        messages = [d.message for d in validate_spec(load_spec(spec_file)).diagnostics if d.severity == severity]
        assert any(words in m for m in messages), messages


@pytest.mark.parametrize(("edit", "words"), [
    (lambda urdf: urdf.replace('<robot name="roll_arm">', '<sdf version="1.6"><model name="roll_arm">')
     .replace("</robot>", "</model></sdf>"), "not a URDF: its root element is <sdf>, where a URDF's is <robot>"),
    (lambda urdf: urdf.replace('<joint name="tool_joint" type="fixed"><parent link="hand"/>',
                               '<joint name="strut" type="fixed"><parent link="base"/><child link="hand"/></joint>\n'
                               '  <joint name="tool_joint" type="fixed"><parent link="hand"/>'),
     "link hand is the child of 2 joints (wrist_roll, strut): a closed kinematic loop"),
    (lambda urdf: urdf.replace('name="shoulder" type="revolute"', 'name="shoulder" type="spherical"'),
     "joint shoulder has type 'spherical': a URDF joint is revolute, continuous, prismatic, fixed, floating or planar"),
    (lambda urdf: urdf.replace('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>'),
     "joint shoulder's <axis xyz=\"0 0 0\"> gives no direction"),
    (lambda urdf: urdf.replace('effort="80"', 'effort="-80"'), "joint shoulder's <limit effort=\"-80\">: a number ≥ 0"),
    (lambda urdf: urdf.replace('<child link="hand"/>', '<child link="palm"/>'),
     "joint wrist_roll's child link 'palm' is not a <link> of the URDF"),
    (lambda urdf: urdf.replace('name="forearm_roll"', 'name="shoulder"'), "two joints named 'shoulder'"),
    (lambda urdf: urdf.replace('<link name="tool"/>', '<link name="tool"/>\n  <link name="stray"/>'),
     "2 links have no parent joint (base, stray)"),
    (lambda urdf: urdf.replace('name="shoulder" type="revolute"', 'name="shoulder" type="floating"'),
     "joint shoulder is a floating joint (6 DOF): dcts drives fixed-base robots"),
    (lambda urdf: urdf.replace('<mass value="2.0"/>', '<mass value="1e30"/>'),
     "the URDF's masses span too many orders of magnitude to be computed with (the link moved by shoulder has 1e+30 kg)"),
])
def test_a_file_that_is_no_urdf_or_no_tree_says_so(tmp_path, edit, words):
    """An SDF (example-robot-data's Cassie) was refused for a joint's missing <limit>, and a link with
    two parents as "Model does not have any body named …" (both found from outside). Joints and links
    urdfdom refuses only as "does not contain a valid URDF model", or reads without complaint (an
    axis of 0 0 0, a negative effort), and a floating joint (an internal error, exit 3) are named
    (found from outside by a mutation fuzz of specs and URDFs)."""
    path = tmp_path / "roll_arm.urdf"
    path.write_text(edit(URDF))
    spec_file = tmp_path / "arm.yaml"
    spec_file.write_text(f"version: 1\nname: arm\nrobot:\n  urdf: {path.name}\ntasks:\n"
                         "  - {name: posture, type: joint, priority: 1, gains: {kp: 10, kd: 6}, reference: {q: [0.3, 0.2, 0.1]}}\n")
    with pytest.raises(SpecError) as raised:
        validate_spec(load_spec(spec_file))
    assert [d.line for d in raised.value.errors] == [4] and words in str(raised.value), str(raised.value)


@pytest.mark.parametrize("given", [False, True])
def test_placeholder_velocity_limits_of_a_urdf_are_named(tmp_path, given):
    """A URDF velocity limit of 1000 rad/s (Bolt's, Solo's) is no motor's: a warning names the joints
    and says what takes it as it is, unless the spec gives limits.joint_velocity (found from outside:
    Bolt's golden vectors drew random states at 360 rad/s)."""
    path = tmp_path / "roll_arm.urdf"
    path.write_text(URDF.replace('effort="80" velocity="2"', 'effort="80" velocity="1000"'))
    limits = "limits:\n  joint_velocity: {max: [2, 3, 3]}\n" if given else ""
    spec_file = tmp_path / "arm.yaml"
    spec_file.write_text(f"version: 1\nname: arm\nrobot:\n  urdf: {path.name}\n{limits}tasks:\n"
                         "  - {name: posture, type: joint, priority: 1, gains: {kp: 10, kd: 6}, reference: {q: [0.3, 0.2, 0.1]}}\n")
    warned = [d.message for d in validate_spec(load_spec(spec_file)).diagnostics if "placeholders" in d.message]
    assert warned == ([] if given else [warned[0]])
    if not given:
        assert "(shoulder 1000 rad/s;" in warned[0] and "limits.joint_velocity" in warned[0]


PAYLOAD_SPEC = """version: 1
name: carrying
robot:
  model: iiwa14
  payloads:
    - {{frame: {frame}, mass: 2.5, com: [0.01, -0.02, 0.05], inertia: [0.004, 0.003, 0.002]}}
tasks:
  - {{name: hold, type: position, frame: tool, priority: 1, gains: {{kp: 50, kd: 14}}, reference: {{position: [0.5, 0, 0.5]}}}}
"""


def test_a_payload_the_robot_carries_is_in_the_controllers_model_and_the_plants(tmp_path):
    """`robot.payloads`: the controller's model is the URDF with the mass (and its inertia) as a link of
    its own at the frame (Pinocchio's own model of that edited file, the reference: mass matrix,
    inverse dynamics), moments no rigid body has are a located error,
    and the MuJoCo plant carries it too, so the controller is not surprised by it (a 6 kg tool known
    only through τ_ext, one step late, made a UR10's shoulder oscillate: docs/formulations.md)."""
    from dcts_spec.robot.builtin import builtin_urdf_path
    from dcts_spec.sim.mujoco_model import build_mujoco_model

    spec = tmp_path / "carrying.yaml"
    spec.write_text(PAYLOAD_SPEC.format(frame="tool"))
    model = validate_spec(load_spec(spec)).robot.model
    text = builtin_urdf_path("iiwa14").read_text()
    edited = text.replace("</robot>", """  <link name="payload"><inertial><origin xyz="0.01 -0.02 0.05"/><mass value="2.5"/>
    <inertia ixx="0.004" ixy="0" ixz="0" iyy="0.003" iyz="0" izz="0.002"/></inertial></link>
  <joint name="payload_joint" type="fixed"><parent link="tool"/><child link="payload"/></joint>
</robot>""")
    reference, plain = pin.buildModelFromXML(edited), pin.buildModelFromXML(text)
    assert pin.computeTotalMass(model) == pytest.approx(pin.computeTotalMass(plain) + 2.5, abs=1e-12)
    rng = np.random.default_rng(7)
    for _ in range(5):
        q, v, a = rng.uniform(-2, 2, 7), rng.normal(size=7), rng.normal(size=7)
        ours, theirs = model.createData(), reference.createData()
        assert np.allclose(pin.crba(model, ours, q), pin.crba(reference, theirs, q), atol=1e-12)
        assert np.allclose(pin.rnea(model, ours, q, v, a), pin.rnea(reference, theirs, q, v, a), atol=1e-12)
    plant = build_mujoco_model(model)
    assert float(plant.body_mass.sum()) == pytest.approx(pin.computeTotalMass(model), abs=1e-9)

    spec.write_text(PAYLOAD_SPEC.format(frame="tol"))
    with pytest.raises(SpecError) as caught:
        validate_spec(load_spec(spec))
    assert f"{spec}:6:" in str(caught.value) and "robot.payloads[0].frame: no link, joint or frame named 'tol'" in str(caught.value)
    spec.write_text(PAYLOAD_SPEC.format(frame="tool").replace("[0.004, 0.003, 0.002]", "[0.01, 0.003, 0.002]"))
    with pytest.raises(SpecError) as caught:
        load_spec(spec)
    assert f"{spec}:6:" in str(caught.value) and "no rigid body has these principal moments" in str(caught.value)


def test_the_reference_takes_a_continuous_joint_the_short_way_as_dcts_does(tmp_path: Path) -> None:
    """The independent reference (tests/reference.py) wraps a joint task's error on a joint without
    position limits as dcts does: at this state the forearm roll's target is 6.5 rad the long way
    round and 0.22 rad the short way, and the reference's torque equals dcts's only with the wrap."""
    spec = _roll_arm_spec(tmp_path)
    controller = build_controller(spec)
    model, names = controller.robot.model, controller.robot.joint_names
    q, dq, tau_ext = np.array([0.4, -2.5]), np.array([0.1, 0.5]), np.zeros(2)
    result = controller.step(q, dq, tau_ext)
    assert result.status == 0 and np.allclose(result.scaling, 1.0)
    wrapped, _, _ = closed_form_hierarchy(model, numeric_tasks(spec, names, model), q, dq, tau_ext)
    unwrapped, _, _ = closed_form_hierarchy(model, numeric_tasks(spec, names), q, dq, tau_ext)
    assert relative(result.tau, wrapped) < 1e-9, (result.tau, wrapped)
    assert relative(result.tau, unwrapped) > 1e-2  # (the state tells the two apart)
