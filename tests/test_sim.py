"""Closed-loop simulation: disturbances and τ_ext sensing with real physics, scenarios, the CLI."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest
from command_line import dcts
from reference import dynamics
from typer.testing import CliRunner

from dcts_spec.analysis.run import analyze
from dcts_spec.cli import app
from dcts_spec.codegen import model_digest
from dcts_spec.codegen.bundle import spec_digest
from dcts_spec.controller import StepResult
from dcts_spec.files import OWNED, OutputFolderError
from dcts_spec.robot.builtin import load_builtin_model
from dcts_spec.sim_commands import RunOptions, simulate_command
from dcts_spec.sim.mismatch import scaled_robot
from dcts_spec.sim.mujoco_model import mass_matrix
from dcts_spec.sim.runner import Simulation, prepare_simulation
from dcts_spec.sim.runtime import RuntimeUnavailable, make_runtime
from dcts_spec.sim.scenario import TorqueProfile
from dcts_spec.sim.sensing import TorqueSensor
from dcts_spec.spec import SpecError, load_spec_text
from dcts_spec.spec.scenario import ExternalTorqueSensing
from dcts_spec.validate import validate_spec

HOME = "[0, 0.6, 0, -1.2, 0, 0.8, 0]"


@pytest.fixture(autouse=True)
def _private_bundle_cache(tmp_path_factory, monkeypatch):
    """No test writes into the user's bundle cache (the C runtime loads its bundles from there)."""
    monkeypatch.setenv("DCTS_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "bundle-cache"))


def spec_text(scenario: str, tasks: str = "", limits: str = "joint_torque: {max: 300, allow_outside_urdf: true}") -> str:
    """An iiwa14 holding its tool at a point over a damped null space; `scenario` is indented YAML."""
    tasks = tasks or """
  - {name: hold, type: position, frame: tool, priority: 1, gains: {kp: 100, kd: 20}, reference: {position: [0.69, 0.0, 0.51]}}
  - {name: damping, type: joint, priority: 2, gains: {kp: 0, kd: 5}}"""
    return f"""
version: 1
name: sim_case
robot: {{model: iiwa14}}
limits:
  {limits}
tasks:{tasks}
scenario:
  initial_q: {HOME}
{scenario}"""


def simulate(text: str, formulation: str | None = None, runtime=None) -> tuple[Simulation, object]:
    sim = prepare_simulation(load_spec_text(text), "python", formulation)
    if runtime is not None:
        sim = Simulation(sim.spec, sim.robot, sim.scenario, runtime)
    return sim, sim.run()


def point_jacobian(model: pin.Model, q: np.ndarray, frame: str, point: np.ndarray) -> np.ndarray:
    """(6, n): rows [velocity of `point` (in the frame); angular velocity], world axes."""
    data = model.createData()
    fid = model.getFrameId(frame)
    J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
    lever = data.oMf[fid].rotation @ point
    return np.vstack([J[:3] - pin.skew(lever) @ J[3:], J[3:]])


PUSH = """
  duration: 0.2
  disturbances:
    - {type: force, body: tool, point: [0.02, -0.01, 0.05], force: [10, -5, 20], torque: [0.5, 1.0, -0.3], start: 0.05, duration: 0.1}
"""


def test_push_at_a_point_is_measured_as_jacobian_transpose_wrench() -> None:
    # With an Euler-type integrator the motion-based estimate of τ_ext is exact (with rk4, the
    # default, the period's mean acceleration is used: see the next test).
    sim, log = simulate(spec_text(PUSH + "  integrator: implicitfast\n"))
    wrench = np.array([10, -5, 20, 0.5, 1.0, -0.3])
    window = range(51, 150)
    for k in window:
        expected = point_jacobian(sim.robot.model, log.q[k], "tool", np.array([0.02, -0.01, 0.05])).T @ wrench
        np.testing.assert_allclose(log.tau_ext_true[k], expected, atol=1e-10)
        # Ideal sensing sees the previous step's torque, reconstructed from the motion alone:
        # this checks the moment (p − c) × f MuJoCo needs for a force away from the CoM.
        np.testing.assert_allclose(log.tau_ext_measured[k + 1], expected, atol=1e-9)
    outside = np.r_[0:50, 152:log.steps]
    assert np.abs(log.tau_ext_true[outside]).max() == 0.0
    assert np.abs(log.tau_ext_measured[outside]).max() < 1e-9


@pytest.mark.parametrize(("push", "substeps", "words"), [
    ("{type: force, body: link7, force: [2000, 0, 0], start: 0.1002, duration: 0.0004}", 1, "0 s of force for its 0.0004 s"),
    ("{type: force, body: link7, force: [2000, 0, 0], start: 0.1, duration: 0.0004}", 1, "0.001 s of force for its 0.0004 s"),
    ("{type: force, body: link7, force: [2000, 0, 0], start: 0.1, duration: 0.0004}", 10, None),  # (4 substeps)
    ("{type: force, body: base, force: [20, 0, 0], start: 0.1, duration: 0.1}", 1, "fixed to the world"),
])
def test_a_push_the_simulation_cannot_apply_as_written_is_warned_about(push: str, substeps: int, words: str | None) -> None:
    """A push shorter than a simulation step acted for a whole step or not at all, and one on a
    frame fixed to the world not at all, without a word."""
    text = spec_text(f"  duration: 0.2\n  substeps: {substeps}\n  disturbances:\n    - {push}\n")
    warnings = [d.message for d in validate_spec(load_spec_text(text)).diagnostics
                if d.severity == "warning" and d.path[:2] == ("scenario", "disturbances")]
    assert (any(words in w for w in warnings) if words else not warnings), warnings


@pytest.mark.parametrize(("scenario", "words"), [
    ("  payloads: [{frame: base, mass: 2}]\n", "base is fixed to the world: the robot does not carry this payload"),
    ("  external_torque: {mode: ideal, noise_std: 0.5}\n", "acts only with mode: noisy (the mode is ideal)"),
])
def test_a_scenario_entry_without_effect_is_warned_about(scenario: str, words: str) -> None:
    warnings = [d.message for d in validate_spec(load_spec_text(spec_text("  duration: 0.2\n" + scenario))).diagnostics
                if d.severity == "warning"]
    assert any(words in w for w in warnings), warnings


def test_a_cartesian_speed_limit_crossed_by_a_push_is_in_the_summary() -> None:
    """A bound's max_velocity had no metric: a push took the tool 0.009 m/s past its 0.05 m/s and
    the summary said Cartesian 0 m. The excess is checked against Pinocchio's frame velocity."""
    limits = ("joint_torque: {max: 100}\n  joint_acceleration: {max: 20}\n"
              "  cartesian: [{frame: tool, axis: z, min: 0.1, max_velocity: 0.05}]")
    sim, log = simulate(spec_text("  duration: 0.25\n  disturbances:\n    - {type: force, body: link7, "
                                  "force: [0, 0, -300], start: 0.05, duration: 0.1}\n", limits=limits))
    summary = analyze(sim, log).summary
    model = sim.robot.model
    data, frame = model.createData(), model.getFrameId("tool")
    speeds = [abs(pin.getFrameVelocity(model, data, frame, pin.LOCAL_WORLD_ALIGNED).linear[2])
              for q, dq in zip(log.q, log.dq) if pin.forwardKinematics(model, data, q, dq) is None]
    assert max(speeds) > 0.05 + 1e-3  # (the premise: the push beats the bound's braking)
    assert summary["max_cartesian_velocity_violation"] == pytest.approx(max(speeds) - 0.05, rel=1e-9)
    assert summary["units"]["max_cartesian_velocity_violation"] == "m/s"


@pytest.mark.parametrize(("integrator", "substeps"), [("rk4", 1), ("implicitfast", 4), ("euler", 2)])
def test_push_with_other_integrators_is_measured_closely(integrator: str, substeps: int) -> None:
    sim, log = simulate(spec_text(PUSH + f"  integrator: {integrator}\n  substeps: {substeps}\n"))
    assert sim.mj_model.opt.timestep == pytest.approx(0.001 / substeps)
    # One sensing step behind; not exact any more (the acceleration varies within a period).
    error = np.abs(log.tau_ext_measured[52:150] - log.tau_ext_true[51:149]).max()
    assert error < 0.01 * np.abs(log.tau_ext_true).max()


def test_a_push_within_a_control_period_is_logged_as_the_periods_mean_torque() -> None:
    """With substeps, τ_ext was logged at each period's first substep only: a push of 2 of the 4
    substeps of a period (from 0.1005 s for 0.5 ms) acted (q̇ jumped) but logged 0 Nm, and so did
    max_disturbance_torque. A period's τ_ext is now the mean of its substeps', what the motion and
    the motion-based estimate see."""
    force = np.array([0.0, 100.0, 0.0])
    push = "{type: force, body: link7, point: [0, 0, 0.045], force: [0, 100, 0], start: 0.1005, duration: 0.0005}"
    sim, log = simulate(spec_text(f"  duration: 0.15\n  substeps: 4\n  integrator: implicitfast\n"
                                  f"  disturbances:\n    - {push}\n"))
    full = point_jacobian(sim.robot.model, log.q[100], "link7", np.array([0, 0, 0.045]))[:3].T @ force
    np.testing.assert_allclose(log.tau_ext_true[100], 0.5 * full, atol=1e-3 * np.abs(full).max())
    assert np.abs(np.delete(log.tau_ext_true, 100, axis=0)).max() == 0.0
    np.testing.assert_allclose(log.tau_ext_measured[101], log.tau_ext_true[100], atol=1e-2 * np.abs(full).max())
    assert analyze(sim, log).summary["max_disturbance_torque"] == pytest.approx(np.abs(log.tau_ext_true[100]).max())


def test_the_controllers_acceleration_is_the_one_its_limit_bounds() -> None:
    """With external_torque: measured, limits.joint_acceleration bounds a = M_c⁻¹(τ + τ̂_ext − ν_c − g_c);
    the summary held the runtime's q̈_cmd = M_c⁻¹(τ − ν_c − g_c) against it (1304 rad/s² where a stayed
    within 250, a person pushing joints). With a model mismatch a is the controller's model's."""
    limits = "joint_torque: {max: 300, allow_outside_urdf: true}\n  joint_acceleration: {max: 30}"
    scenario = ("  duration: 0.3\n  model_mismatch: {mass_scale: 1.2}\n  disturbances:\n    - {type: joint_torque, "
                "torque: [0, 20, 0, 0, -10, 0, 0], start: 0.05, duration: 0.2, ramp: 0.05}\n")
    sim, log = simulate(spec_text(scenario, limits=limits))
    model = sim.controller_robot.model
    data = model.createData()
    a = np.array([pin.aba(model, data, q, dq, tau + tau_ext)
                  for q, dq, tau, tau_ext in zip(log.q, log.dq, log.tau, log.tau_ext_measured)])
    assert np.abs(log.ddq_commanded).max() > 60.0  # (the premise: q̈_cmd alone is far beyond the limit)
    assert np.all(log.status == 0)
    assert np.abs(a).max() < 30.0 + 1e-6
    assert analyze(sim, log).summary["max_controller_acceleration"] == pytest.approx(np.abs(a).max(), rel=1e-6)


def test_unmodelled_payload_shows_up_in_measured_torque() -> None:
    scenario = "  duration: 1.0\n  payloads:\n    - {frame: tool, mass: 3.0, com: [0, 0, 0.05]}\n"
    sim, log = simulate(spec_text(scenario))
    assert np.all(log.tau_ext_true == 0.0)  # a payload is part of the robot, not a disturbance
    k = log.steps - 1
    weight = np.array([0, 0, -9.81 * 3.0, 0, 0, 0])
    static = point_jacobian(sim.robot.model, log.q[k - 1], "tool", np.array([0, 0, 0.05])).T @ weight
    assert np.abs(log.dq[-1]).max() < 0.01  # nearly at rest again: the weight is what is left
    np.testing.assert_allclose(log.tau_ext_measured[k], static, atol=0.02 * np.abs(static).max())
    # The analysis counts the payload as a disturbance: what the controller measured, one step later.
    run = analyze(sim, log)
    payload = run.series.payload_torque
    np.testing.assert_allclose(log.tau_ext_measured[1:], payload[:-1], atol=1e-3 * np.abs(static).max())
    assert run.summary["max_disturbance_torque"] == pytest.approx(np.abs(payload).max())
    assert run.summary["max_disturbance_torque"] > 0.9 * np.abs(static).max()
    assert run.summary["max_external_torque_estimate_error"] < 1e-3 * np.abs(static).max()


def test_joint_torque_profile_with_ramps() -> None:
    profile = TorqueProfile(np.array([1.0, -2.0]), start=0.1, end=0.5, ramp=0.1)
    t = np.array([0.0, 0.1, 0.15, 0.2, 0.3, 0.45, 0.5, 0.6])
    np.testing.assert_allclose(profile.amplitude(t), [0, 0, 0.5, 1, 1, 0.5, 0, 0], atol=1e-12)
    triangle = TorqueProfile(np.ones(1), start=0.0, end=0.1, ramp=0.1)
    assert triangle.amplitude(np.array([0.05]))[0] == pytest.approx(0.5)
    scenario = """  duration: 0.3
  integrator: implicitfast
  disturbances:
    - {type: joint_torque, torque: [0, 0, 0, 0, 0, 0, 3], start: 0.1, duration: 0.1, ramp: 0.02}
"""
    _, log = simulate(spec_text(scenario))  # Euler-type integration: exact ideal sensing
    k = round(0.11 / 0.001)  # half-way up the ramp
    assert log.tau_ext_true[k, 6] == pytest.approx(1.5)
    assert log.tau_ext_true[150, 6] == pytest.approx(3.0)
    np.testing.assert_allclose(log.tau_ext_measured[151], log.tau_ext_true[150], atol=1e-9)


def _rk4_period(model: pin.Model, q: np.ndarray, dq: np.ndarray, tau: np.ndarray, period: float):
    """One period of the torque tau held, integrated by classic Runge–Kutta in Pinocchio (ABA):
    what MuJoCo's rk4 does with no contact, independently of it."""
    data = model.createData()

    def derivative(state):
        x, v = state
        return v, pin.aba(model, data, x, v, tau)

    def moved(state, slope, h):
        return state[0] + h * slope[0], state[1] + h * slope[1]

    k1 = derivative((q, dq))
    k2 = derivative(moved((q, dq), k1, period / 2))
    k3 = derivative(moved((q, dq), k2, period / 2))
    k4 = derivative(moved((q, dq), k3, period))
    return tuple(s + period / 6 * (a + 2 * b + 2 * c + d) for s, a, b, c, d in zip((q, dq), k1, k2, k3, k4))


def test_ideal_sensing_sees_no_torque_where_there_is_none_in_a_fast_period() -> None:
    """With rk4, ideal sensing took the period's mean acceleration at the state of its start, and
    made up torques where the motion was fast: 4.7 Nm on a Centauro's torso with nothing pushing
    (found from outside). At the period's midpoint it is second-order in the period: a torque
    that takes the iiwa14's joints up to 2.5 rad/s faster in 1 ms is seen as 3e-4 Nm of τ_ext,
    where the period's start saw 0.64 Nm."""
    model = load_builtin_model("iiwa14")
    q, dq = np.array([0.3, 0.8, -0.4, -1.2, 0.6, 1.0, -0.5]), np.array([0.5, -1.0, 0.8, 1.5, -2.0, 2.5, -3.0])
    tau = np.array([60.0, -60.0, 30.0, 40.0, -10.0, 5.0, 2.0])
    period = 0.001
    q_next, dq_next = _rk4_period(model, q, dq, tau, period)
    ddq = (dq_next - dq) / period
    assert np.abs(dq_next - dq).max() > 2.0  # (the premise: a fast period)
    seen = {}
    for at_start in (True, False):
        sensor = TorqueSensor(ExternalTorqueSensing(mode="ideal"), model, 2, at_start=at_start)
        seen[at_start] = np.zeros(7)
        sensor.measure(1, q, dq, q_next, dq_next, ddq, tau, seen[at_start])
    assert np.abs(seen[False]).max() < 1e-5 * np.abs(tau).max()
    assert np.abs(seen[True]).max() > 100 * np.abs(seen[False]).max()


def test_noisy_sensing_is_seeded_and_ignored_sensing_is_zero() -> None:
    noisy = "  duration: 0.05\n  external_torque: {mode: noisy, noise_std: 0.5, bias: 1.0, seed: %d}\n"
    _, a = simulate(spec_text(noisy % 7))
    _, b = simulate(spec_text(noisy % 7))
    _, c = simulate(spec_text(noisy % 8))
    np.testing.assert_array_equal(a.tau_ext_measured, b.tau_ext_measured)
    assert not np.array_equal(a.tau_ext_measured, c.tau_ext_measured)
    assert np.mean(a.tau_ext_measured) == pytest.approx(1.0, abs=0.1)
    _, ignored = simulate(spec_text(PUSH + "  external_torque: ignored\n"))
    assert np.all(ignored.tau_ext_measured == 0.0)
    assert np.abs(ignored.tau_ext_true).max() > 1.0


def test_model_mismatch_scales_the_controllers_masses_only() -> None:
    sim = prepare_simulation(load_spec_text(spec_text("  duration: 0.05\n  model_mismatch: {mass_scale: 1.3}\n")))
    q = np.array([0.1, 0.6, 0.0, -1.2, 0.2, 0.8, 0.0])
    true, controller = sim.robot.model, sim.controller_robot.model
    g_true = pin.computeGeneralizedGravity(true, true.createData(), q)
    g_ctrl = pin.computeGeneralizedGravity(controller, controller.createData(), q)
    np.testing.assert_allclose(g_ctrl, 1.3 * g_true, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(mass_matrix(sim.mj_model, mujoco.MjData(sim.mj_model), q),
                               dynamics(true, q, np.zeros(7))[0], atol=1e-12)
    assert sim.runtime.robot.model is controller
    assert scaled_robot(sim.robot, 1.0) is sim.robot
    # At rest under gravity compensation by a heavier model, the estimator sees the excess.
    log = sim.run()
    midpoint = pin.interpolate(controller, log.q[0], log.q[1], 0.5), 0.5 * (log.dq[0] + log.dq[1])  # (rk4: TorqueSensor)
    np.testing.assert_allclose(log.tau_ext_measured[1], pin.rnea(controller, controller.createData(), *midpoint,
                               log.ddq[0]) - log.tau[0], atol=1e-9)


def test_mass_matrices_agree_along_a_simulated_trajectory() -> None:
    sim, log = simulate(spec_text(PUSH))
    data = mujoco.MjData(sim.mj_model)
    for q in log.q[::20]:
        M = dynamics(sim.robot.model, q, np.zeros(7))[0]
        assert np.abs(mass_matrix(sim.mj_model, data, q) - M).max() < 1e-12 * np.abs(M).max()


def test_actual_acceleration_is_the_commanded_one_without_disturbance() -> None:
    # Euler-type integration: the logged acceleration (q̇ₖ₊₁ − q̇ₖ)/T is the one at the step's start
    _, log = simulate(spec_text("  duration: 0.2\n  integrator: implicitfast\n"))
    assert np.all(log.status >= 0)
    np.testing.assert_allclose(log.ddq, log.ddq_commanded, atol=1e-8 * np.abs(log.ddq).max())


def test_dcts_keeps_a_cartesian_bound() -> None:
    tasks = """
  - {name: reach, type: position, frame: tool, priority: 1, gains: {kp: 25, kd: 10}, reference: {position: [0.5, 0.0, 0.3]}}
  - {name: damping, type: joint, priority: 2, gains: {kp: 0, kd: 5}}"""
    limits = "cartesian:\n    - {frame: tool, axis: z, min: 0.45, max_acceleration: 2}"
    for formulation, crosses in (("dcts", False), ("osc", True)):
        sim, log = simulate(spec_text("  duration: 0.6\n", tasks, limits), formulation)
        run = analyze(sim, log)
        z = run.series.frame_positions["tool"][:, 2]
        assert run.summary["solver_failures"] == 0
        if crosses:  # OSC has no limits: the same task goes through the bound
            assert z.min() < 0.4
        else:
            assert z.min() > 0.45 - 1e-4
            assert run.summary["max_cartesian_violation"] < 1e-4


def test_waypoints_are_fed_in_turn_and_their_times_recorded() -> None:
    tasks = """
  - {name: reach, type: position, frame: tool, priority: 1, gains: {kp: 400, kd: 40, max_velocity: 0.4}, reference: {input: true}}
  - {name: damping, type: joint, priority: 2, gains: {kp: 0, kd: 5}}"""
    points = [[0.68, 0.0, 0.51], [0.68, 0.02, 0.51], [0.66, 0.02, 0.52]]
    scenario = f"  duration: 0.5\n  waypoints: {{task: reach, tolerance: 0.003, points: {points}}}\n"
    sim, log = simulate(spec_text(scenario, tasks))
    times = log.waypoint_times
    assert np.all(np.isfinite(times)) and np.all(np.diff(times) > 0)
    tool_path = analyze(sim, log).series.frame_positions["tool"]
    for i, t in enumerate(times):
        k = round(t / 0.001)
        tool = tool_path[k]
        assert np.linalg.norm(tool - points[i]) <= 0.003
        np.testing.assert_allclose(log.ref[k - 1], points[i])  # fed until reached ...
        np.testing.assert_allclose(log.ref[k], points[min(i + 1, 2)])  # ... then at once the next one
    # The run goes on for its whole duration, holding the last point.
    assert log.steps == 500
    np.testing.assert_allclose(log.ref[-1], points[-1])


def _feedforward_case() -> Simulation:
    """A tool path to a point 0.1 m away at up to 0.4 m/s, then 2 cm on, fed with feed-forward."""
    tasks = """
  - {name: reach, type: position, frame: tool, priority: 1, gains: {kp: 400, kd: 40, max_velocity: 0.4}, reference: {input: true, feedforward: true}}
  - {name: damping, type: joint, priority: 2, gains: {kp: 0, kd: 5}}"""
    points = [[0.69, 0.1, 0.51], [0.67, 0.1, 0.5]]
    scenario = f"  duration: 0.85\n  waypoints: {{task: reach, tolerance: 0.002, points: {points}}}\n"
    return prepare_simulation(load_spec_text(spec_text(scenario, tasks)), "python")


def _ref_field(sim: Simulation, log, task: str, field: str) -> np.ndarray:
    entry = next(r for r in sim.runtime.ref_layout if r.task == task and r.field == field)
    return log.ref[:, entry.offset: entry.offset + entry.size]


class _WithoutFeedForward:
    """The same runtime with the velocity and acceleration inputs zeroed: the path alone."""

    def __init__(self, inner):
        self.inner, self.n, self.ref_layout, self.priorities = inner, inner.n, inner.ref_layout, inner.priorities
        self.nx = inner.nx
        self.cut = np.concatenate([np.arange(r.offset, r.offset + r.size) for r in inner.ref_layout
                                   if r.field in ("velocity", "acceleration")])

    def step(self, q, dq, tau_ext=None, ref=None) -> StepResult:
        ref = ref.copy()
        ref[self.cut] = 0.0
        return self.inner.step(q, dq, tau_ext, ref)


def test_feedforward_waypoints_are_a_smooth_timed_path_tracked_closely() -> None:
    sim = _feedforward_case()
    log = sim.run()
    p, v, a = (_ref_field(sim, log, "reach", f) for f in ("position", "velocity", "acceleration"))
    period = sim.scenario.period
    # The fed velocity and acceleration are the time derivatives of the fed position (central
    # differences; the acceleration's jerk jumps where a segment starts or ends).
    np.testing.assert_allclose(v, np.gradient(p, period, axis=0), atol=1e-4)
    np.testing.assert_allclose(a, np.gradient(v, period, axis=0), atol=0.02 * np.abs(a).max())
    speed = np.linalg.norm(v, axis=1)
    assert 0.99 * 0.4 < speed.max() <= 0.4 + 1e-9  # max_velocity sets the segments' durations
    np.testing.assert_allclose(p[0], analyze(sim, log).series.frame_positions["tool"][0], atol=1e-12)  # from where it is
    times = log.waypoint_times
    assert np.all(np.isfinite(times))
    assert times[0] == pytest.approx(15 / 8 * np.linalg.norm(np.array([0.69, 0.1, 0.51]) - p[0]) / 0.4, abs=0.003)
    assert times[1] - times[0] == pytest.approx(2 * np.pi / np.sqrt(400), abs=0.003)  # a short hop: the PD's period
    assert speed[round(times[0] / period)] < 1e-3 and np.all(speed[round(times[1] / period):] == 0.0)  # at rest there

    # The same path with the velocity and acceleration inputs zeroed lags far behind it (first
    # segment: 0.47 s).
    without = Simulation(sim.spec, sim.robot, sim.scenario.with_duration(0.47), _WithoutFeedForward(sim.runtime))
    lag = np.linalg.norm(analyze(without, without.run()).series.task_errors["reach"], axis=1)
    error = np.linalg.norm(analyze(sim, log).series.task_errors["reach"][:lag.size], axis=1)
    assert np.sqrt(np.mean(error**2)) < 0.01 * np.sqrt(np.mean(lag**2)) and lag.max() > 0.02  # m


def test_a_paths_speed_follows_a_run_time_max_velocity() -> None:
    """Segments were timed with the compiled max_velocity: set to 0.2 m/s at t = 0, the path
    still peaked at the compiled 0.4."""
    tasks = """
  - {name: reach, type: position, frame: tool, priority: 1, gains: {kp: 400, kd: 40, max_velocity: 0.4}, reference: {input: true, feedforward: true}}
  - {name: damping, type: joint, priority: 2, gains: {kp: 0, kd: 5}}"""
    scenario = ("  duration: 0.6\n  waypoints: {task: reach, tolerance: 0.002, points: [[0.69, 0.1, 0.51]]}\n"
                "  parameters: [{time: 0, values: {reach.max_velocity: 0.2}}]\n")
    text = spec_text(scenario, tasks) + "parameters:\n  tasks: {reach: [max_velocity]}\n"
    sim = prepare_simulation(load_spec_text(text), "python")
    log = sim.run()
    speed = np.linalg.norm(_ref_field(sim, log, "reach", "velocity"), axis=1)
    assert 0.99 * 0.2 < speed.max() <= 0.2 + 1e-9


def test_feedforward_of_an_orientation_path_is_in_the_tasks_own_rows() -> None:
    """A swing task ([rx, ry]: the frame's own axes): the fed rates are the time derivatives of
    the task's error towards the fed rpy, at a fixed configuration."""
    tasks = """
  - {name: turn, type: orientation, frame: tool, axes: [rx, ry], priority: 1, gains: {kp: 400, kd: 40}, reference: {input: true, feedforward: true}}"""
    scenario = "  duration: 1.0\n  waypoints: {task: turn, tolerance: 0.001, points: [[2.9, 0.2, -2.8]]}\n"
    sim = prepare_simulation(load_spec_text(spec_text(scenario, tasks)), "python")
    follower, q = sim.waypoints, sim.scenario.q0
    ref = sim.initial_ref.copy()
    follower.restart(ref)
    task, period = follower.task, 1e-3
    model, data = sim.robot.model, sim.robot.model.createData()
    pin.framesForwardKinematics(model, data, q)
    placement = data.oMf[model.getFrameId("tool")]
    layout = {r.field: r for r in sim.runtime.ref_layout}

    def fed(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        follower.update(t, q, ref)
        return tuple(ref[layout[f].offset: layout[f].offset + layout[f].size].copy()
                     for f in ("rpy", "velocity", "acceleration"))

    def error(rpy: np.ndarray) -> np.ndarray:
        return task.numeric_error(placement.translation, placement.rotation, {"rpy": rpy})

    for t in (0.05, 0.12, 0.2):
        _, velocity, acceleration = fed(t)
        before, after, now = error(fed(t - period)[0]), error(fed(t + period)[0]), error(fed(t)[0])
        np.testing.assert_allclose(velocity, (after - before) / (2 * period), rtol=1e-3, atol=1e-6)
        np.testing.assert_allclose(acceleration, (after - 2 * now + before) / period**2, rtol=1e-2, atol=1e-3)
        assert np.linalg.norm(velocity) > 0.1


def test_input_references_without_waypoints_hold_their_initial_value() -> None:
    tasks = """
  - {name: reach, type: pose, frame: tool, axes: [x, y, z, rx], priority: 1, gains: {kp: 100, kd: 20}, reference: {input: true}}
  - {name: posture, type: joint, priority: 2, gains: {kp: 10, kd: 5}, reference: {input: true, feedforward: true}}"""
    sim, log = simulate(spec_text("  duration: 0.1\n", tasks))
    assert sim.initial_ref.size == 3 + 3 + 7 * 3
    assert np.abs(log.q - log.q[0]).max() < 1e-6  # nothing to do: the robot stays put


class _Exploding:
    """A runtime that commands absurd torques: MuJoCo gives up."""

    n, nx, ref_layout, priorities = 7, 0, [], [1, 2]

    def step(self, q, dq, tau_ext=None, ref=None) -> StepResult:
        return StepResult(np.full(7, 1e15), np.zeros(7), np.ones(2), 0, np.zeros(0))


def test_unstable_simulation_stops_and_is_reported() -> None:
    sim, log = simulate(spec_text("  duration: 0.1\n"), runtime=_Exploding())
    assert log.diverged_at is not None and log.steps < 100
    run = analyze(sim, log)
    assert run.summary["completed"] is False


def test_missing_scenario_and_unavailable_runtime() -> None:
    text = spec_text("  duration: 0.1\n").split("scenario:")[0]
    with pytest.raises(SpecError, match="no `scenario` section"):
        prepare_simulation(load_spec_text(text))
    with pytest.raises(ValueError, match="unknown runtime"):
        make_runtime(load_spec_text(text), "fortran")


def run_c_like_python(text: str, **c_options) -> tuple[Simulation, object]:
    """The spec run with the C runtime (skipped where it cannot be built) and with the Python
    runtime: the same closed loop. Returns the C simulation and its log."""
    try:
        c = prepare_simulation(load_spec_text(text), "c", **c_options)
    except RuntimeUnavailable as error:
        pytest.skip(str(error))
    python = prepare_simulation(load_spec_text(text), "python")
    c_log, python_log = c.run(), python.run()
    np.testing.assert_allclose(c_log.tau, python_log.tau, atol=1e-6)
    np.testing.assert_allclose(c_log.q, python_log.q, atol=1e-9)
    return c, c_log


@pytest.mark.slow  # (the default tier: test_c_runtime_simulates_model_mismatch_like_python)
def test_c_runtime_runs_the_same_closed_loop_as_python(tmp_path: Path) -> None:
    run_c_like_python(spec_text(PUSH), work_dir=tmp_path, cache=False)


def test_c_runtime_simulates_model_mismatch_like_python(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The C bundle is generated for the controller's (scaled) model, says so, runs the same
    closed loop as the Python runtime, and the next run loads it from the cache."""
    monkeypatch.setenv("DCTS_CACHE_DIR", str(tmp_path / "cache"))
    text = spec_text(PUSH + "  model_mismatch: {mass_scale: 1.2}\n")
    c, c_log = run_c_like_python(text)
    matched = prepare_simulation(load_spec_text(spec_text(PUSH)), "python").run()
    assert np.max(np.abs(matched.tau - c_log.tau)) > 0.1  # the mismatch shows

    manifest = c.runtime.manifest
    assert manifest["model"]["modified"] and manifest["model"]["changes"] == {"mass_scale": 1.2}
    assert manifest["model_sha256"] == model_digest(c.controller_robot) != model_digest(c.robot)
    assert manifest["spec_sha256"] == spec_digest(load_spec_text(text))
    header = (c.runtime.directory / "sim_case.h").read_text()
    assert "#define SIM_CASE_MODEL_MODIFIED 1" in header and "mass_scale = 1.2" in header
    assert analyze(c, c_log).summary["mass_scale"] == 1.2

    again = prepare_simulation(load_spec_text(text), "c")
    assert again.runtime.directory == c.runtime.directory
    assert [p.name for p in (tmp_path / "cache").iterdir() if not p.name.startswith(".")] == [c.runtime.directory.name]


def test_no_cache_option_builds_in_a_temporary_directory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []

    def prepare(spec, runtime, formulation, duration, work_dir=None, cache=True):
        calls.append((runtime, work_dir, cache))
        raise RuntimeUnavailable("stop here")

    monkeypatch.setattr("dcts_spec.sim_commands.prepare_simulation", prepare)
    spec = tmp_path / "s.yaml"
    spec.write_text(spec_text("  duration: 0.02\n"))
    runner = CliRunner()
    for command in ("simulate", "compare"):
        for flag, cached in (("--no-cache", False), ("--cache", True)):
            result = runner.invoke(app, [command, str(spec), flag, "--out", str(tmp_path / "out"), "-q"])
            assert result.exit_code == 1 and "stop here" in result.output
            runtime, work_dir, cache = calls[-1]
            assert runtime == "c" and cache is cached
            if not cached:
                assert work_dir is not None and not Path(work_dir).exists()  # removed after the run


# -- the command line ---------------------------------------------------------------------------


def test_simulate_never_deletes_a_users_file(tmp_path: Path) -> None:
    spec = tmp_path / "push.yaml"
    spec.write_text(spec_text(PUSH))
    users = tmp_path / "mine"
    (users / "sub").mkdir(parents=True)
    (users / "important.txt").write_text("keep")
    result = dcts("simulate", str(spec), "--runtime", "python", "--out", str(users), "--duration", "0.05", "--no-plots")
    assert result.returncode == 1 and "refusing" in result.stderr and "Traceback" not in result.stderr
    assert sorted(p.name for p in users.iterdir()) == ["important.txt", "sub"]
    out = tmp_path / "out"
    for _ in range(2):  # a note added to a run folder survives the next run into it
        assert simulate_command(spec, out, RunOptions(runtime="python", quiet=True, duration=0.05), plots=False) == 0
        (out / "notes.txt").write_text("my notes")
    assert (out / "notes.txt").read_text() == "my notes" and (out / "summary.json").is_file()


def test_simulate_writes_a_complete_output_directory(tmp_path: Path) -> None:
    spec = tmp_path / "push.yaml"
    spec.write_text(spec_text(PUSH))
    out = tmp_path / "out"
    result = dcts("simulate", str(spec), "--runtime", "python", "--out", str(out), "--duration", "0.2")
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    names = {p.name for p in out.iterdir()}
    assert {"log.npz", "summary.json", "joint_positions.png", "joint_velocities.png", "torques.png",
            "task_errors.png", "scalings.png", "energies.png", "end_effector_path.png"} <= names
    summary = json.loads((out / "summary.json").read_text())
    from dcts_spec.analysis.metrics import SUMMARY_KEYS

    for key in SUMMARY_KEYS:
        value = summary[key]
        values = value.values() if isinstance(value, dict) else [value]
        assert all(isinstance(v, (int, float)) and np.isfinite(v) for v in values), key
    assert summary["runtime"] == "python" and summary["formulation"] == "dcts"
    log = np.load(out / "log.npz")
    assert log["q"].shape == (200, 7) and log["position_tool"].shape == (200, 3)
    assert {"tau_ext_true", "tau_ext_measured", "error_hold", "scaling", "status"} <= set(log.files)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_simulate_from_python_runs_and_writes_what_the_command_does(tmp_path: Path) -> None:
    """`dcts_spec.simulate` (the README's Python API): the run the command runs, its folder the
    command's files; a folder dcts may not write is refused before the run."""
    import dcts_spec

    spec = tmp_path / "push.yaml"
    spec.write_text(spec_text(PUSH))
    run = dcts_spec.simulate(spec, runtime="python", duration=0.05, out=tmp_path / "out", plots=False)
    assert run.summary["steps"] == 50 and run.log.q.shape == (50, 7)
    assert json.loads((tmp_path / "out" / "summary.json").read_text()) == json.loads(json.dumps(run.summary))
    assert np.array_equal(np.load(tmp_path / "out" / "log.npz")["tau"], run.log.tau)
    again = dcts_spec.simulate(spec, runtime="python", duration=0.05)  # (no folder: nothing written)
    assert np.array_equal(again.log.tau, run.log.tau)
    users = tmp_path / "users"
    users.mkdir()
    (users / "notes.txt").write_text("mine")
    with pytest.raises(OutputFolderError, match="not written by dcts"):
        dcts_spec.simulate(spec, runtime="python", out=users)
    assert [p.name for p in users.iterdir()] == ["notes.txt"]


def test_failed_run_leaves_no_output_directory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    spec = tmp_path / "push.yaml"
    spec.write_text(spec_text("  duration: 0.02\n"))
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.txt").write_text("previous run")
    (out / OWNED).write_text('["old.txt"]')  # a previous dcts run

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr("dcts_spec.analysis.outputs.write_plots", broken)
    with pytest.raises(OSError):
        simulate_command(spec, out, RunOptions(runtime="python", quiet=True))
    assert sorted(p.name for p in out.iterdir()) == [OWNED, "old.txt"]  # the previous output is untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "push.yaml"]


@pytest.mark.parametrize(
    ("options", "formulation", "message"),
    [
        (RunOptions(runtime="python"), None, "no `scenario` section"),
        (RunOptions(runtime="fortran"), None, "unknown runtime"),
        (RunOptions(runtime="python"), "magic", "unknown formulation"),
        (RunOptions(runtime="python", duration=-1.0), None, "--duration must be positive"),
    ],
)
def test_bad_input_is_one_message_and_exit_1(tmp_path: Path, capsys: pytest.CaptureFixture, options: RunOptions,
                                             formulation: str | None, message: str) -> None:
    spec = tmp_path / "no_scenario.yaml"
    spec.write_text(spec_text("  duration: 0.1\n").split("scenario:")[0])
    out = tmp_path / "out"
    assert simulate_command(spec, out, options, formulation) == 1
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_output_path_that_is_a_file_is_refused_before_running(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    spec = tmp_path / "s.yaml"
    spec.write_text(spec_text("  duration: 0.02\n"))
    (tmp_path / "taken").write_text("")
    assert simulate_command(spec, tmp_path / "taken", RunOptions(runtime="python")) == 1
    assert "exists and is not a directory" in capsys.readouterr().err


def test_broken_spec_exits_1_with_its_location(tmp_path: Path) -> None:
    spec = tmp_path / "broken.yaml"
    spec.write_text(spec_text("  duration: -1\n"))
    result = dcts("compare", str(spec), "--runtime", "python", "--out", str(tmp_path / "out"))
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert "broken.yaml:" in result.stderr and "duration" in result.stderr


def test_viewer_without_display_warns_and_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    spec = tmp_path / "s.yaml"
    spec.write_text(spec_text("  duration: 0.02\n"))
    code = simulate_command(spec, tmp_path / "out", RunOptions(runtime="python", quiet=True), plots=False, viewer=True)
    assert code == 0
    assert "--viewer needs a display" in capsys.readouterr().err
    assert (tmp_path / "out" / "summary.json").is_file()


def test_video_without_encoder_says_so(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                       capsys: pytest.CaptureFixture) -> None:
    monkeypatch.setattr("shutil.which", lambda name: None)
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # makes the import fail
    spec = tmp_path / "s.yaml"
    spec.write_text(spec_text("  duration: 0.02\n"))
    code = simulate_command(spec, tmp_path / "out", RunOptions(runtime="python", quiet=True),
                            video=tmp_path / "run.mp4")
    assert code == 1
    assert "no MP4 encoder" in capsys.readouterr().err
    assert not (tmp_path / "out").exists() and not (tmp_path / "run.mp4").exists()


@pytest.mark.parametrize("target", ["spec", "video"])
def test_a_video_is_never_written_over_a_file(tmp_path: Path, capsys: pytest.CaptureFixture, target: str) -> None:
    """--video moved the finished video over whatever was at its path: a user's holiday.mp4, the
    spec itself (first seen from outside). Refused before the run, nothing written."""
    spec = tmp_path / "s.yaml"
    spec.write_text(spec_text("  duration: 0.02\n"))
    video = spec if target == "spec" else tmp_path / "holiday.mp4"
    if target == "video":
        video.write_bytes(b"the user's")
    before = video.read_bytes()
    code = simulate_command(spec, tmp_path / "out", RunOptions(runtime="python", quiet=True), video=video)
    assert code == 1
    assert f"{video} exists: the video is not written over it" in capsys.readouterr().err
    assert video.read_bytes() == before and not (tmp_path / "out").exists()


@pytest.mark.slow
def test_video_is_rendered_where_possible(tmp_path: Path) -> None:
    spec = tmp_path / "s.yaml"
    spec.write_text(spec_text("  duration: 0.3\n"))
    video = tmp_path / "run.mp4"
    result = dcts("simulate", str(spec), "--runtime", "python", "--out", str(tmp_path / "out"),
                  "--no-plots", "--video", str(video))
    if result.returncode != 0:
        assert "no MP4 encoder" in result.stderr or "no OpenGL backend" in result.stderr, result.stderr
        pytest.skip(result.stderr.strip())
    assert video.stat().st_size > 1000


def test_compare_writes_tables_and_overlays(tmp_path: Path) -> None:
    spec = tmp_path / "push.yaml"
    spec.write_text(spec_text(PUSH))
    out = tmp_path / "cmp"
    result = dcts("compare", str(spec), "--runtime", "python", "--formulations", "dcts,osc", "--out", str(out),
                  "--duration", "0.1", "--quiet")
    assert result.returncode == 0, result.stderr
    assert result.stdout == ""
    table = json.loads((out / "comparison.json").read_text())
    assert set(table) == {"dcts", "osc"}
    markdown = (out / "comparison.md").read_text()
    assert "| metric | unit | dcts | osc |" in markdown and "| task_rms_error[hold] | m |" in markdown
    for name in ("compare_task_errors", "compare_scalings", "compare_energies", "compare_joint_velocities",
                 "compare_end_effector_path"):
        assert (out / f"{name}.png").is_file()
    assert (out / "dcts" / "log.npz").is_file() and (out / "osc" / "summary.json").is_file()


def test_version_names_dcts_and_its_solvers() -> None:
    from importlib.metadata import version

    result = CliRunner().invoke(app, ["--version"])
    assert result.exit_code == 0, result.output
    assert result.output.startswith(f"dcts {version('dcts-spec')} (casadi {version('casadi')}, daqp {version('daqp')}, ")


# A UR10's tool pulled toward a target below its floor bound, its orientation and posture below
# (format templates: the doubled braces are YAML's)
UR10_FLOOR_TASKS = """tasks:
  - {{name: tool_pos, type: position, frame: tool0, priority: 1, gains: {{kp: 100, kd: 20}}, reference: {{position: [0.75, 0.35, 0.10]}}}}
  - {{name: tool_point, type: orientation, frame: tool0, axes: [rx, ry], priority: 2, gains: {{kp: 200, kd: 28}}, reference: {{rpy: [180, 0, 0], unit: deg}}}}
  - {{name: posture, type: joint, priority: 3, gains: {{kp: 10, kd: 6}}, reference: {{q: [0, -1.2, 1.5, -1.9, -1.57, 0]}}}}
"""

UR10_TOOL_ON_FLOOR = """version: 1
name: ur10_tool_on_floor
robot:
  urdf: {urdf}/ur_description/urdf/ur10_robot.urdf
{robot_payload}limits:
  joint_acceleration: {{max: 15}}
  cartesian:
    - {{frame: tool0, axis: z, min: 0.30}}
""" + UR10_FLOOR_TASKS + """scenario:
  duration: 2.5
  initial_q: [0, -1.2, 1.5, -1.9, -1.57, 0]
{scenario_payload}"""


def test_a_payload_the_controller_models_does_not_make_the_loop_oscillate():
    """A UR10 holding its tool on a floor bound its target lies below, with a 6 kg tool. Unknown to
    the controller (a scenario payload), it reaches it only through τ_ext, one step late, and that
    carries the payload's reaction to the previous step's acceleration: the torque oscillates with a
    period of a few steps (72 steps with a jump above 10 % of a limit in 2.5 s, the floor crossed by
    3e-6 m with status "ok"; 29 and 1.4e-6 m since the answers are polished on their active face,
    224 and 56 relaxed steps just before). Declared in `robot.payloads`, it is in the controller's
    model and the plant alike: 2 such steps (the start), the floor held to 4e-9 m."""
    from dcts_spec.robot.builtin import example_robot_data_dir

    tool = "{frame: tool0, mass: 6.0, com: [0, 0, 0.05]}"
    summaries = {}
    for known in (False, True):
        text = UR10_TOOL_ON_FLOOR.format(urdf=example_robot_data_dir(),
                                         robot_payload=f"  payloads: [{tool}]\n" if known else "",
                                         scenario_payload="" if known else f"  payloads: [{tool}]\n")
        sim, log = simulate(text)
        summaries[known] = analyze(sim, log).summary
    assert summaries[False]["torque_jump_steps"] >= 20  # (the premise: unknown, it oscillates)
    assert summaries[True]["torque_jump_steps"] <= 5 and summaries[True]["max_cartesian_violation"] < 1e-7
    assert summaries[True]["limits_relaxed"] == 0 and summaries[True]["crossed_after_ok_steps"] == 0


UR10_SHOULDER_TOWARD_ITS_LIMIT = """version: 1
name: ur10_shoulder_toward_its_limit
robot:
  urdf: {urdf}/ur_description/urdf/ur10_robot.urdf
  payloads: [{{frame: tool0, mass: 6.0, com: [0, 0, 0.05]}}]
limits:
  joint_position: {{min: [-180, -180, -160, -270, -270, -270], max: [180, 0, 160, 90, 90, 270], unit: deg}}
  joint_velocity: {{max: [100, 100, 150, 150, 150, 150], unit: deg/s}}
  joint_acceleration: {{max: 15}}
  joint_torque: {{max: [330, 330, 150, 54, 54, 54]}}
  joint_braking: {braking}
  cartesian:
    - {{frame: tool0, axis: z, min: 0.30}}
controller: {{formulation: dcts, external_torque: measured}}
""" + UR10_FLOOR_TASKS + """scenario:
  duration: 0.6
  initial_q: [1.37, -0.435, 0.433, -1.621, -1.516, 0]
  initial_dq: [0.288, 1.462, -2.618, -0.04, 1.276, 0]
"""


def test_a_crossing_from_the_held_torque_is_said_and_an_acceleration_limit_removes_it():
    """The plant holds the torque over a period (MuJoCo's rk4), the controller's model the
    acceleration, and the velocity bounds aim VELOCITY_MARGIN below the limits for the difference.
    A Panda reaching very hard at 500 Hz with no acceleration limit (~1300 rad/s² in a step) parts
    from its model by more than that: a velocity bound the model holds is crossed after an "ok"
    step (9e-4 rad/s; 3e-3 before the simulated τ_ext sensor took the period's midpoint), and the
    summary says so and what keeps it small. With 20 rad/s² nothing is crossed."""
    from dcts_spec.analysis.report import describe

    text = """version: 1
name: panda_reaching_hard
robot: {{model: panda}}
limits:
{acceleration}  cartesian:
    - {{frame: panda_hand_tcp, axis: z, min: 0.25}}
controller: {{period: 0.002}}
tasks:
  - {{name: reach, type: position, frame: panda_hand_tcp, priority: 1, gains: {{kp: 2000, kd: 90}}, reference: {{position: [0.5, 0.0, 0.0]}}}}
  - {{name: posture, type: joint, priority: 2, gains: {{kp: 10, kd: 6}}, reference: {{q: [0, -0.3, 0, -2.0, 0, 1.8, 0.8]}}}}
scenario: {{duration: 0.1, initial_q: [0, -0.3, 0, -2.0, 0, 1.8, 0.8]}}
"""
    sim, log = simulate(text.format(acceleration=""))
    run = analyze(sim, log)
    assert run.summary["crossed_after_ok_steps"] >= 1 and run.summary["max_joint_velocity_violation"] > 5e-4
    assert "the torque held over a period, not the acceleration" in describe(run)
    sim, log = simulate(text.format(acceleration="  joint_acceleration: {max: 20}\n"))
    run = analyze(sim, log)
    assert run.summary["crossed_after_ok_steps"] == 0 and run.summary["max_joint_velocity_violation"] < 1e-5


def test_a_joint_gravity_pulls_toward_its_limit_brakes_as_its_torque_allows_and_stops_inside():
    """A UR10 with a 6 kg tool swings its shoulder lift up toward its limit (0 rad) at 1.46 rad/s;
    gravity and the payload pull it that way, and its 330 Nm leave ~6 rad/s² of braking where its
    acceleration limit says 15. Bounds that count on 15 (`joint_braking: acceleration_limit`, the
    default and the paper's) start braking too late: the joint crosses its limit by 2 mrad, 117
    steps relaxed, the torque jumps 294 Nm. Counting on what the torque gives (`torque_limited`),
    it stops inside, no step relaxed."""
    from dcts_spec.robot.builtin import example_robot_data_dir

    summaries = {}
    for braking in ("torque_limited", "acceleration_limit"):
        sim, log = simulate(UR10_SHOULDER_TOWARD_ITS_LIMIT.format(urdf=example_robot_data_dir(), braking=braking))
        summaries[braking] = analyze(sim, log).summary
    torque, constant = summaries["torque_limited"], summaries["acceleration_limit"]
    assert constant["limits_relaxed"] >= 50 and constant["max_joint_position_violation"] > 1e-3
    assert torque["limits_relaxed"] == 0 and torque["max_joint_position_violation"] < 1e-5
    assert torque["max_joint_velocity_violation"] < 1e-5 and torque["torque_jump_steps"] <= 3


def test_a_panda_leaning_with_its_payload_to_its_shoulder_limit_stops_inside():
    """A Panda with a 3 kg payload at its hand leans forward to its shoulder's limit (a posture
    target beyond it): the further it leans, the harder gravity pulls it on. Counting on its
    15 rad/s² acceleration limit it crossed the limit by 0.066 rad (406 relaxed steps, 19 torque
    steps above 10 % of a limit); counting on its torque's braking it stops inside."""
    text = """version: 1
name: panda_lean
robot:
  model: panda
  payloads: [{{frame: panda_hand_tcp, mass: 3.0}}]
limits:
  joint_acceleration: {{max: 15}}
  joint_braking: {braking}
tasks:
  - {{name: posture, type: joint, priority: 1, gains: {{kp: 60, kd: 4}}, reference: {{q: [0, 2.5, 0, -0.5, 0, 1.8, 0.8]}}}}
scenario: {{duration: 1.3, initial_q: [0, 0.0, 0, -0.5, 0, 1.8, 0.8]}}
"""
    summaries = {}
    for braking in ("torque_limited", "acceleration_limit"):
        sim, log = simulate(text.format(braking=braking))
        summaries[braking] = analyze(sim, log).summary
    assert summaries["acceleration_limit"]["max_joint_position_violation"] > 0.03
    torque = summaries["torque_limited"]
    assert torque["max_joint_position_violation"] < 1e-5 and torque["limits_relaxed"] == 0


def _compiled_upper_bound(c, joint: str, q: np.ndarray, dq: np.ndarray) -> float:
    """The upper acceleration bound the controller compiles for `joint`'s row, at (q, dq)."""
    import casadi as ca

    from dcts_spec.limits.naming import joint_row_name

    p, rows = c.problem, c.problem.acceleration_rows
    row = rows.names.index(joint_row_name(joint))
    return float(ca.Function("upper", [p.sym.q, p.sym.dq, p.param], [rows.upper[row]])(q, dq, c.param_layout.defaults))


def test_the_braking_the_bounds_assume_is_the_torque_limit_s_in_the_state():
    """The shoulder lift's upper acceleration bound in the compiled controller equals the one the
    shaping gives with the braking computed independently (Pinocchio's CRBA and RNEA: (τ_max + h)/M_jj,
    the other joints still), which is below the acceleration limit in this state; with
    `joint_braking: acceleration_limit` it is the one with 15 rad/s²."""
    from formulation_cases import joint_acceleration_bounds, joint_braking

    from dcts_spec import build_controller
    from dcts_spec.robot.builtin import example_robot_data_dir

    q = np.array([1.386, -0.064, -0.157, -2.004, -1.001, 0.0])
    dq = np.array([-0.14, 1.373, -1.958, -2.616, 1.688, 0.0])
    upper = {}
    for braking in ("torque_limited", "acceleration_limit"):
        c = build_controller(load_spec_text(UR10_SHOULDER_TOWARD_ITS_LIMIT.format(urdf=example_robot_data_dir(),
                                                                                  braking=braking)))
        compiled = _compiled_upper_bound(c, "shoulder_lift_joint", q, dq)
        assert compiled == pytest.approx(joint_acceleration_bounds(c.robot, q, dq, c.problem.period)[1][1], abs=1e-9)
        upper[braking] = compiled
        if braking == "torque_limited":
            toward_max, _ = joint_braking(c.robot, q, dq, 1)
            assert 3.0 < toward_max < 10.0  # (its torque gives less than the 15 rad/s² limit here)
    assert upper["torque_limited"] < upper["acceleration_limit"] - 1.0


def test_a_joint_gravity_pulls_less_and_less_toward_its_bound_counts_on_the_braking_it_will_have():
    """`joint_braking: torque_limited`. Baxter's left shoulder (50 Nm) swinging down at its velocity
    limit, 1.43 rad from its bound:
    here gravity pulls it down almost as hard as its torque limit can hold, so braking counted on
    this state alone (0.09 rad/s²) would call its bound unkeepable, the status "limits relaxed" for
    ~100 steps of a motion that ends inside it. The gravity torque falls as the arm swings toward hanging:
    on average over the way it leaves ~6 rad/s² of braking, more than the 0.8 rad/s² that stopping
    at the bound needs. The bound the controller compiles counts on that mean, and agrees with the
    independent one (Pinocchio's gravity and its derivative) and with the mean of Pinocchio's
    gravity sampled along the way."""
    from formulation_cases import BAXTER_TWO_HANDS, joint_acceleration_bounds, joint_braking

    from dcts_spec import build_controller
    from dcts_spec.robot.builtin import example_robot_data_dir

    text = BAXTER_TWO_HANDS.format(urdf=example_robot_data_dir())
    c = build_controller(load_spec_text(text.replace("joint_acceleration: {max: 15}",
                                                     "joint_acceleration: {max: 15}\n  joint_braking: torque_limited")))
    q = np.array([0.0539, -0.3809, -0.0616, 1.3171, -0.0621, 0.1136, -0.0663, 0.18, -0.6263, -0.1393, 1.464,
                  -0.2145, 0.202, -0.2167])
    dq = np.array([0.6917, 1.5, -1.3594, -0.3287, -1.3766, -1.9554, -1.4094, 1.5, -0.7352, -0.8801, 1.5, -2.251,
                   0.258, -2.55])
    j, model, lim = 1, c.robot.model, c.robot.limits
    data = model.createData()
    gap = lim.q_max[j] - q[j]
    way = np.linspace(0.0, gap, 2001)
    gravity = [pin.computeGeneralizedGravity(model, data, q + s * np.eye(14)[j])[j] for s in way]
    coriolis = pin.rnea(model, data, q, dq, np.zeros(14))[j] - gravity[0]
    inertia = pin.crba(model, data, q)[j, j]
    now = (lim.tau_max[j] + coriolis + gravity[0]) / inertia
    sampled = (lim.tau_max[j] + coriolis + np.trapezoid(gravity, way) / gap) / inertia
    toward_max, _ = joint_braking(c.robot, q, dq, j)
    need = dq[j] ** 2 / (2 * gap)
    assert now < 0.2 * need and toward_max == pytest.approx(sampled, rel=1e-5) and toward_max > 5 * need
    compiled = _compiled_upper_bound(c, "left_s1", q, dq)
    assert compiled == pytest.approx(joint_acceleration_bounds(c.robot, q, dq, c.problem.period)[1][j], abs=1e-9)
    assert compiled > -dq[j] / c.problem.period  # (no demand to stop within the step: the state is viable)


def test_a_bound_crossed_after_an_ok_step_is_counted_and_said():
    """A push the controller cannot foresee (τ_ext is measured one step late) moves the tool further
    through the floor bound it holds in the step the push starts, a step whose status was "ok": the
    summary counts such steps (the plant is not the model the status vouched for) and the printed
    summary says where to look."""
    from dcts_spec.analysis.report import describe
    from dcts_spec.robot.builtin import example_robot_data_dir

    push = "  disturbances:\n    - {type: force, body: tool0, force: [0, 0, -100], start: 0.5, duration: 0.1}\n"
    text = UR10_TOOL_ON_FLOOR.format(urdf=example_robot_data_dir(), robot_payload="", scenario_payload=push)
    sim, log = simulate(text.replace("duration: 2.5", "duration: 0.6"))
    run = analyze(sim, log)
    assert run.summary["crossed_after_ok_steps"] >= 1 and run.summary["crossed_after_ok_first"] == pytest.approx(0.5)
    assert '"ok" steps left a bound crossed further (the first at t = 0.5 s)' in describe(run)
