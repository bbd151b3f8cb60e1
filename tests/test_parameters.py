"""Run-time parameters in the Python runtime: defaults are the compiled controller, a set means
what recompiling with it would, activation 0 removes a task, and a change is ramped."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from dcts_spec.controller import Controller, build_controller
from dcts_spec.formulations.parameters import ParameterError
from dcts_spec.spec import load_spec_text
from dcts_spec.validate import validate_spec

SPEC = {
    "version": 1,
    "name": "params",
    "robot": {"model": "iiwa14"},
    "limits": {"joint_torque": {"max": 100}, "joint_acceleration": {"max": 30},
               "cartesian": [{"frame": "tool", "axis": "z", "min": 0.1, "max": 1.2}]},
    "tasks": [
        {"name": "tool", "type": "position", "frame": "tool", "priority": 1,
         "gains": {"kp": 100, "kd": 20, "max_velocity": 0.5}, "reference": {"position": [0.5, 0.1, 0.6]}},
        {"name": "posture", "type": "joint", "priority": 2, "gains": {"kp": 10, "kd": 5},
         "reference": {"q": [0, 30, 0, -60, 0, 60, 0], "unit": "deg"}},
    ],
    "scenario": {"duration": 0.5, "initial_q": [0, 30, 0, -60, 0, 60, 0], "unit": "deg"},
}
ALL = {"tasks": {"tool": ["kp", "kd", "max_velocity", "reference", "activation"], "posture": ["kp", "kd"]},
       "limits": ["joint_position", "joint_velocity", "joint_acceleration", "joint_torque", "cartesian"]}
Q = np.radians([10, 35, -5, -70, 8, 55, 3])
DQ = np.array([0.1, -0.05, 0.2, 0.1, -0.1, 0.05, 0.3])


def _controller(formulation: str, parameters: dict | None = None, **changes) -> Controller:
    data = yaml.safe_load(yaml.safe_dump(SPEC))
    for path, value in changes.items():
        *keys, last = path.split("__")
        node = data
        for key in keys:
            node = node[int(key)] if key.isdigit() else node[key]
        node[last] = value
    if parameters is not None:
        data["parameters"] = parameters
    return build_controller(load_spec_text(yaml.safe_dump(data), "params.yaml"), formulation)


def _settled(c: Controller, values: dict) -> None:
    c.set_params(values)
    for _ in range(50):
        c.step(Q, DQ)


@pytest.mark.parametrize("kd", [1e-310, 0.0])
def test_a_vanishing_kd_of_a_velocity_saturated_task_keeps_the_controller_running(kd):
    """kd = 1e-310 passed the range check (0, 1e5] and kp/kd overflowed: every step fell back,
    in both runtimes. kd may now be 0 (the law divides by at least SATURATION_KD_FLOOR)."""
    c = _controller("dcts", {"tasks": {"tool": ["kd"]}})
    c.set_params({"tool.kd": kd})
    for _ in range(20):
        result = c.step(Q, DQ)
    assert result.status >= 0 and np.all(np.isfinite(result.tau)), result


@pytest.mark.parametrize("formulation", ["dcts", "osc", "qp_mt"])
def test_the_defaults_are_the_compiled_controller(formulation):
    plain, param = _controller(formulation), _controller(formulation, ALL)
    assert param.param_size == 3 + 3 + 1 + 3 + 1 + 7 + 7 + 7 + 7 + 7 + 7 + 7 + 2
    for k in range(4):
        q, dq = Q + 0.1 * k, DQ * (1 - 0.3 * k)
        a, b = plain.step(q, dq), param.step(q, dq)
        assert a.status == b.status
        np.testing.assert_allclose(b.tau, a.tau, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("formulation", ["dcts", "osc"])
def test_a_parameter_set_means_what_compiling_it_would(formulation):
    param = _controller(formulation, ALL)
    _settled(param, {"tool.kp": [60, 80, 100], "tool.kd": 15, "tool.max_velocity": 0.3, "tool.position": [0.45, 0, 0.7],
                     "posture.kp": 20, "joint_torque.max": 90, "joint_velocity.max": 1.2,
                     "cartesian.tool.z.max": 1.0})
    compiled = _controller(formulation, None, tasks__0__gains={"kp": [60, 80, 100], "kd": 15, "max_velocity": 0.3},
                           tasks__0__reference={"position": [0.45, 0, 0.7]},
                           tasks__1__gains={"kp": 20, "kd": 5},
                           limits={"joint_torque": {"max": 90}, "joint_velocity": {"max": 1.2}, "joint_acceleration": {"max": 30},
                                   "cartesian": [{"frame": "tool", "axis": "z", "min": 0.1, "max": 1.0}]})
    for k in range(3):
        q, dq = Q - 0.05 * k, DQ * (1 + k)
        a, b = compiled.step(q, dq), param.step(q, dq)
        assert a.status == b.status
        np.testing.assert_allclose(b.tau, a.tau, rtol=1e-6, atol=1e-6)
        assert np.all(np.abs(b.tau) <= 90 + 1e-9)


@pytest.mark.parametrize("formulation", ["dcts", "osc", "qp_mt"])
def test_activation_zero_is_the_spec_without_the_task(formulation):
    param = _controller(formulation, {"tasks": {"tool": ["activation"]}})
    _settled(param, {"tool.activation": 0.0})
    data = yaml.safe_load(yaml.safe_dump(SPEC))
    data["tasks"] = data["tasks"][1:]
    alone = build_controller(load_spec_text(yaml.safe_dump(data), "alone.yaml"), formulation)
    for k in range(3):
        q, dq = Q + 0.07 * k, DQ * (1 - 0.4 * k)
        a, b = alone.step(q, dq), param.step(q, dq)
        assert b.status == a.status == 0
        # the posture gets exactly the acceleration it gets alone (qp_mt: up to its regularization)
        np.testing.assert_allclose(b.ddq, a.ddq, rtol=1e-5, atol=1e-5 if formulation != "qp_mt" else 1e-3)


def test_activation_fades_the_task():
    """From 1 to 0 the acceleration moves steadily from the task's to the one without it."""
    param = _controller("osc", {"tasks": {"tool": ["activation"]}})
    ddq = {}
    for a in (1.0, 0.75, 0.5, 0.25, 0.0):
        param.reset_params()
        param.set_params({"tool.activation": a})
        ddq[a] = param.step(Q, DQ).ddq
    away = [np.linalg.norm(ddq[a] - ddq[0.0]) for a in (1.0, 0.75, 0.5, 0.25)]
    assert all(x > y for x, y in zip(away, away[1:])) and away[-1] > 0



BLEND = """version: 1
name: blend
robot: {model: iiwa14}
limits: {joint_torque: {max: 300, allow_outside_urdf: true}}
tasks:
  - {name: tilt, type: orientation, frame: tool, priority: 1, gains: {kp: 50, kd: 10}, reference: {rpy: [150, 20, 30], unit: deg}}
  - {name: elbow, type: joint, joints: [joint1, joint2, joint4], priority: 2, gains: {kp: 20, kd: 8}, reference: {q: [0.4, 0.3, -1.0]}}
parameters: {tasks: {tilt: [activation]}}
"""


@pytest.mark.parametrize("formulation", ["dcts", "osc"])
@pytest.mark.parametrize("activation", [0.7, 0.3, 1e-3])
def test_a_level_below_a_partly_active_one_is_exact(formulation, activation):
    """A partly active level leaves the rest of its directions to the levels below, so its blend of
    projectors is no projector. The level below took its J̄ from J N M⁻¹ Nᵀ Jᵀ and missed its own
    task where the two share directions (here by up to 2 %, at scaling 1 and status "ok"; on an
    iiwa14 with a bound active, a position level read s = 0.77 below an orientation at activation
    1e-3 and 0 at 0, and the torque jumped 55 Nm, found from outside). From J M⁻¹ Nᵀ Jᵀ it is exact."""
    c = build_controller(load_spec_text(BLEND), formulation)
    q, dq = np.radians([0, 30, 0, -60, 0, 60, 0]), np.array([0.1, -0.2, 0.1, 0.3, 0.0, 0.1, -0.1])
    c.set_params({"tilt.activation": activation})
    for _ in range(50):  # (through the ramp)
        result = c.step(q, dq)
    assert result.status == 0 and np.allclose(result.scaling, 1.0)
    desired = 20 * (np.array([0.4, 0.3, -1.0]) - q[[0, 1, 3]]) - 8 * dq[[0, 1, 3]]
    np.testing.assert_allclose(result.ddq[[0, 1, 3]], desired, rtol=1e-9, atol=1e-9)

def test_a_gain_step_is_ramped_linearly():
    param = _controller("osc", {"tasks": {"tool": ["kp"]}, "ramp_time": 0.01}, tasks__0__gains={"kp": 100, "kd": 20})
    steps = 10

    def step() -> tuple[np.ndarray, np.ndarray]:
        tau = param.step(Q, DQ).tau
        return tau, param.evaluate_data(Q, DQ)["tau0"].ravel()  # osc: the torque before clipping

    before, raw_before = step()
    param.set_params({"tool.kp": 400})
    taus, raws = zip(*[step() for _ in range(steps + 2)])
    # osc's torque is affine in kp: each step moves a tenth of the way, the last lands on it
    for k, raw in enumerate(raws[:steps], start=1):
        np.testing.assert_allclose(raw, raw_before + k / steps * (raws[-1] - raw_before), rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(raws[steps - 1], raws[-1])
    jumps = np.abs(np.diff(np.vstack([before, *taus]), axis=0)).max(axis=1)
    assert jumps.max() <= np.abs(raws[-1] - raw_before).max() / steps * (1 + 1e-9) + 1e-12
    assert np.abs(taus[-1] - before).max() > 5.0  # a step worth ramping


def test_a_new_set_during_a_ramp_starts_from_where_it_is():
    param = _controller("osc", {"tasks": {"tool": ["kp"]}, "ramp_time": 0.004})
    param.set_params({"tool.kp": 200})
    param.step(Q, DQ)
    param.step(Q, DQ)  # half way: 150
    param.set_params({"tool.kp": 100})
    assert param._ramp.now[0] == pytest.approx(150)
    values = [param.step(Q, DQ) and param._ramp.now[0] for _ in range(4)]
    np.testing.assert_allclose(values, [137.5, 125, 112.5, 100])


@pytest.mark.parametrize(("values", "field", "words"), [
    ({"tool.kp": np.nan}, "tool.kp", "not finite"),
    ({"tool.kd": -1}, "tool.kd", "outside"),
    ({"joint_torque.max": 101}, "joint_torque.max", "compiled envelope"),
    ({"joint_acceleration.max": 0}, "joint_acceleration.max", "outside"),
    ({"joint_position.min": -3, "joint_position.max": 3}, "joint_position.min", "compiled envelope"),
    ({"joint_position.min": 0.5, "joint_position.max": 0.4}, "joint_position.max", "above the matching min"),
    ({"cartesian.tool.z.min": 1.3}, "cartesian.tool.z.min", "compiled envelope"),
    ({"tool.activation": 1.5}, "tool.activation", "outside [0, 1]"),
    # (the value as given, not rounded by %g to the bound it exceeds)
    ({"tool.activation": 1 + 1e-15}, "tool.activation", "1.000000000000001 is outside [0, 1]"),
    ({"joint_torque.max": 100.0000001}, "joint_torque.max", "100.0000001 Nm (joint1) is outside"),
    ({"tool.stiffness": 1}, "tool.stiffness", "no such run-time parameter"),
    ({"posture.kp": [1, 2]}, "posture.kp", "takes 7"),
    ({"tool.kp": True}, "tool.kp", "True is not a number"),  # (it was taken as 1.0)
])
def test_an_invalid_set_is_refused_and_the_old_one_kept(values, field, words):
    param = _controller("osc", ALL)
    param.set_params({"tool.kp": 50})
    kept = param.params()
    with pytest.raises(ParameterError) as info:
        param.set_params(values)
    assert info.value.field == field and words in str(info.value)
    assert param.params() == kept


def test_evaluate_data_names_a_parameter_vector_of_the_wrong_size():
    param = _controller("osc", ALL)
    with pytest.raises(ValueError, match=f"param must have {param.param_size} values .* got 3"):
        param.evaluate_data(Q, DQ, param=[1.0, 2.0, 3.0])  # (a numpy broadcast error in a buffer, before)


def test_limits_keep_their_compiled_structure():
    """A run-time limit replaces a finite compiled one; the rows and terms stay the compiled ones."""
    plain, param = _controller("dcts"), _controller("dcts", ALL)
    assert param.bound_names == plain.bound_names and param.na == plain.na
    # (the tool's activation frees its 3 directions for the posture below: 3 more null-space variables)
    assert param.nx == plain.nx + 3
    validate_spec(param.spec)


ORIENTED = {**SPEC, "tasks": [
    {"name": "tool", "type": "position", "frame": "tool", "priority": 1, "gains": {"kp": 100, "kd": 20},
     "reference": {"position": [0.5, 0.1, 0.6]}},
    {"name": "grip", "type": "orientation", "frame": "tool", "priority": 1, "gains": {"kp": 400, "kd": 40},
     "reference": {"rpy": [3.1, 0.0, 3.1]}},
    {"name": "posture", "type": "joint", "priority": 2, "gains": {"kp": 0, "kd": 5}},
]}


@pytest.mark.parametrize(("rpy", "largest_step"), [
    ([3.1 - 2 * np.pi, 0.0, 3.1], 1e-9),  # the same orientation as [3.1, 0, 3.1]
    ([3.1, 0.0, -3.1], 5.0),  # a turn of 0.083 rad about z
])
def test_an_orientation_reference_is_ramped_the_short_way_round(rpy, largest_step):
    """A roll, pitch or yaw ramped angle by angle swept the target through far orientations: the
    same orientation written as -π + 0.04 instead of 3.1 turned it a full turn (torque steps of up
    to 149 Nm), yaw 3.1 → -3.1, a 0.083 rad turn, stepped the torque by 65 Nm (found from outside).
    Each angle's target is now taken within π of where the ramp is."""
    data = yaml.safe_load(yaml.safe_dump(ORIENTED))
    data["parameters"] = {"tasks": {"grip": ["reference"]}}
    c = build_controller(load_spec_text(yaml.safe_dump(data), "oriented.yaml"))
    before = c.step(Q, DQ).tau
    c.set_params({"grip.rpy": rpy})
    torques = np.array([before] + [c.step(Q, DQ).tau for _ in range(8)])
    assert np.abs(np.diff(torques, axis=0)).max() <= largest_step
    target = np.array(c.params()["grip.rpy"])
    assert np.allclose(np.mod(target - np.array(rpy) + np.pi, 2 * np.pi) - np.pi, 0.0, atol=1e-12)  # (equivalent)
    assert np.abs(target - [3.1, 0.0, 3.1]).max() <= np.pi


# An xArm7 whose orientation @1 and elbow height @3 can be switched at run time, its reach @2
# between them (found from outside, the states saved in tests/data/half_active_levels.npz: a to d).
HALF_ACTIVE = """version: 1
name: xarm_half_active
robot:
  urdf: {urdf}/xarm_description/urdf/xarm7.urdf
  frames:
    tool: {{parent: link_eef, xyz: [0, 0, 0.1]}}
  payloads: [{{frame: tool, mass: 1.5}}]
limits:
  joint_position: {{min: [-170, -110, -170, -5, -170, -90, -170], max: [170, 115, 170, 215, 170, 175, 170], unit: deg}}
  joint_velocity: {{max: [100, 100, 100, 100, 140, 140, 140], unit: deg/s}}
  joint_acceleration: {{max: [10, 10, 12, 12, 20, 20, 20]}}
  joint_torque: {{max: [40, 40, 24, 24, 24, 16, 16]}}
  cartesian:
    - {{frame: tool, axis: x, max: 0.55}}
    - {{frame: tool, normal: [0, 0.34, 0.94], min: 0.15}}
controller: {{formulation: dcts, external_torque: measured}}
tasks:
  - {{name: aim, type: orientation, frame: tool, axes: [ry, rz], priority: 1, gains: {{kp: 100, kd: 20}}, reference: {{rpy: [180, 10, 0], unit: deg}}}}
  - {{name: reach, type: position, frame: tool, axes: [x, y, z], priority: 2, gains: {{kp: 150, kd: 25}}, reference: {{position: [0.65, 0.05, 0.1]}}}}
  - {{name: elbow_z, type: position, frame: link4, axes: [z], priority: 3, gains: {{kp: 40, kd: 13}}, reference: {{position: [0.1, 0, 0.55]}}}}
  - {{name: rest, type: joint, priority: 4, gains: {{kp: 5, kd: 4}}, reference: {{q: [0, 0.3, 0, 1.2, 0, 0.9, 0]}}}}
parameters:
  tasks:
    aim: [activation, kp]
    elbow_z: [activation, reference]
  limits: [joint_position, joint_acceleration, cartesian, joint_torque]
scenario: {{duration: 2.0, initial_q: [0, 0.3, 0, 1.2, 0, 0.9, 0]}}
"""


def half_active_states():
    """The saved states (q, dq, tau_ext, the parameter set, how many steps the ramp has taken)."""
    from pathlib import Path

    data = np.load(Path(__file__).parent / "data" / "half_active_levels.npz")
    return {k: tuple(data[f"{k}_{f}"] for f in ("q", "dq", "tau_ext", "param")) + (int(data[f"{k}_steps"]),)
            for k in "abcd"}


def step_at(runtime, state):
    """The runtime's answer at a saved state: its parameter set applied, the state stepped as often
    as the ramp had taken (each step from a fresh cascade)."""
    q, dq, tau_ext, param, steps = state
    runtime.reset_params()
    runtime.set_params(param)
    for _ in range(steps):
        runtime.reset()
        result = runtime.step(q, dq, tau_ext)
    return result


def test_levels_below_a_half_active_level_get_no_unbounded_freedom():
    """Below a half-active or damped level N_k is no projector, and the freedom N_k z leaks into
    that level's directions with a gain as small as 1e-7. At state a (aim and elbow_z between 0
    and 1) the cascade grew z to 1e9 along such a leak: reach reported s = 1 with status "ok" while
    the torque gave the tool an acceleration 94 % of ẍ_d away from s ẍ_d. With z bounded
    (formulations/dcts.py, RELEASED_REACH), s = 0.148 and the task acceleration the torque gives
    (Pinocchio) is within the blend a half-active level above allows (11 %)."""
    import pinocchio as pin
    from dcts_spec.robot.builtin import example_robot_data_dir

    controller = build_controller(load_spec_text(HALF_ACTIVE.format(urdf=example_robot_data_dir())))
    q, dq, tau_ext, _, _ = state = half_active_states()["a"]
    result = step_at(controller, state)
    model = controller.robot.model
    data = model.createData()
    ddq = pin.aba(model, data, q, dq, result.tau + tau_ext)
    pin.forwardKinematics(model, data, q, dq, ddq)
    pin.updateFramePlacements(model, data)
    tool = model.getFrameId("tool")
    achieved = pin.getFrameClassicalAcceleration(model, data, tool, pin.LOCAL_WORLD_ALIGNED).linear
    velocity = pin.getFrameVelocity(model, data, tool, pin.LOCAL_WORLD_ALIGNED).linear
    desired = 150 * (np.array([0.65, 0.05, 0.1]) - data.oMf[tool].translation) - 25 * velocity
    s = result.scaling[1]
    assert result.status == 0 and s < 0.5, (result.status, s)
    assert np.linalg.norm(achieved - s * desired) < 0.2 * np.linalg.norm(desired)


def test_a_scaling_stage_daqp_calls_infeasible_is_tried_at_gentler_steps():
    """At state d, below two partly active levels, the Python runtime's DAQP called elbow_z's
    scaling stage infeasible at its first step (ρ = 1e-8), and the level was bent to s = 0.26
    where HiGHS, on the same stage, and the C runtime reach s = 1 (found from outside: the torques
    0.85 Nm apart, both status "ok"). The stage is now tried at SCALE_RETRY_STEPS first."""
    from dcts_spec.robot.builtin import example_robot_data_dir

    controller = build_controller(load_spec_text(HALF_ACTIVE.format(urdf=example_robot_data_dir())))
    result = step_at(controller, half_active_states()["d"])
    assert result.status == 0 and result.scaling[2] == pytest.approx(1.0, abs=1e-9), result.scaling

