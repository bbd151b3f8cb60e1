"""Metrics of a run: their definitions on hand-made logs, the energy split, tables, atomic outputs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from reference import dynamics
from test_validate import LIFT_URDF

from dcts_spec import load_spec

from dcts_spec.analysis.compare import markdown_table, scaling_overlay, table_rows
from dcts_spec.analysis.metrics import SUMMARY_KEYS, json_ready, summarize, summary_units
from dcts_spec.analysis.report import describe
from dcts_spec.files import OWNED, OutputFolderError
from dcts_spec.limits.naming import row_text
from dcts_spec.analysis.outputs import atomic_directory
from dcts_spec.analysis.plots import external_torque_figure, joint_figure, task_error_figure
from dcts_spec.analysis.run import RunResult
from dcts_spec.analysis.series import TimeSeries, _kinetic_energies, evaluate
from dcts_spec.sim.log import SimulationLog
from dcts_spec.spec import load_spec_text
from dcts_spec.tasks import make_task
from dcts_spec.validate import validate_spec

SPEC = """
version: 1
name: metrics
robot: {model: iiwa14}
limits:
  joint_velocity: {max: 1.0}
  joint_torque: {max: 50}
  cartesian:
    - {frame: tool, axis: z, min: 0.3}
tasks:
  - {name: reach, type: position, frame: tool, priority: 1, gains: {kp: 100, kd: 20}, reference: {input: true}}
  - {name: tilt, type: orientation, frame: tool, axes: [rx, ry], priority: 2, gains: {kp: 50, kd: 10}, reference: {rpy: [3.1, 0, 0]}}
  - {name: posture, type: joint, priority: 3, gains: {kp: 10, kd: 5}, reference: {q: [0, 0.5, 0, -1, 0, 1, 0]}}
  - {name: rest, type: joint, joints: [joint6, joint7], priority: 3, gains: {kp: 0, kd: 2}}
scenario: {duration: 0.01}
"""


@pytest.fixture(scope="module")
def case():
    spec = load_spec_text(SPEC)
    robot = validate_spec(spec).robot
    rng = np.random.default_rng(4)
    log = SimulationLog.allocate(40, 7, 3, 3, 0.002)
    lo, hi = robot.limits.q_min, robot.limits.q_max
    log.q[:] = rng.uniform(lo + 0.2, hi - 0.2, (40, 7))
    log.dq[:] = rng.uniform(-0.5, 0.5, (40, 7))
    log.ddq[:] = rng.uniform(-3, 3, (40, 7))
    log.tau[:] = rng.uniform(-40, 40, (40, 7))
    log.ref[:] = rng.uniform(0.2, 0.6, (40, 3))
    log.scaling[:] = 1.0
    return spec, robot, log, evaluate(spec, robot, log)


def _numeric(robot, q, dq, frame="tool"):
    model = robot.model
    data = model.createData()
    M, _, g = dynamics(model, q, dq)
    fid = model.getFrameId(frame)
    J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
    pin.forwardKinematics(model, data, q, dq, np.zeros(model.nv))
    bias = pin.getFrameClassicalAcceleration(model, data, fid, pin.LOCAL_WORLD_ALIGNED).vector
    pin.updateFramePlacements(model, data)
    return M, g, J, bias, data.oMf[fid]


def test_series_match_pinocchio(case) -> None:
    spec, robot, log, series = case
    for k in (0, 17, 39):
        q, dq, a, tau = log.q[k], log.dq[k], log.ddq[k], log.tau[k]
        M, g, J, bias, placement = _numeric(robot, q, dq)
        np.testing.assert_allclose(series.frame_positions["tool"][k], placement.translation, atol=1e-12)
        np.testing.assert_allclose(series.task_errors["reach"][k], log.ref[k] - placement.translation, atol=1e-12)
        np.testing.assert_allclose(series.task_errors["posture"][k], np.array([0, 0.5, 0, -1, 0, 1, 0]) - q, atol=1e-12)
        # J a + J̇q̇ − ẍ_d of the first level, ẍ_d = kp Δx − kd ẋ
        target = 100 * (log.ref[k] - placement.translation) - 20 * J[:3] @ dq
        np.testing.assert_allclose(series.acceleration_errors[1][k], J[:3] @ a + bias[:3] - target, atol=1e-9)
        assert series.kinetic_energy[k] == pytest.approx(0.5 * dq @ M @ dq, rel=1e-12)
        assert series.acceleration_energy[k] == pytest.approx(0.5 * (tau - g) @ np.linalg.solve(M, tau - g), rel=1e-10)


def test_kinetic_energy_split_is_m_orthogonal() -> None:
    rng = np.random.default_rng(0)
    n, m, samples = 7, 5, 6
    A = rng.normal(size=(samples, n, n))
    M = A @ A.transpose(0, 2, 1) + n * np.eye(n)
    J = rng.normal(size=(samples, m, n))
    J[0, 4] = J[0, 3]  # a rank-deficient stack: the pseudo-inverse handles it
    dq = rng.normal(size=(samples, n))
    total, task = _kinetic_energies(M, J, dq)
    for k in range(samples):
        Minv = np.linalg.inv(M[k])
        Lambda = np.linalg.pinv(J[k] @ Minv @ J[k].T)
        # the task-consistent part of q̇ and its M-orthogonal complement
        dq_task = Minv @ J[k].T @ Lambda @ J[k] @ dq[k]
        dq_null = dq[k] - dq_task
        assert dq_task @ M[k] @ dq_null == pytest.approx(0.0, abs=1e-9)
        assert task[k] == pytest.approx(0.5 * dq_task @ M[k] @ dq_task, rel=1e-9)
        assert total[k] - task[k] == pytest.approx(0.5 * dq_null @ M[k] @ dq_null, rel=1e-8, abs=1e-12)
    # A full-rank square stack leaves no null space.
    square = rng.normal(size=(1, n, n))
    total, task = _kinetic_energies(M[:1], square, dq[:1])
    assert task[0] == pytest.approx(total[0], rel=1e-9)


def test_summary_definitions(case) -> None:
    spec, robot, log, series = case
    log = SimulationLog(**{**log.__dict__})
    log.q = log.q.copy()
    log.dq = np.zeros_like(log.dq)
    log.tau = np.zeros_like(log.tau)
    log.scaling = np.ones_like(log.scaling)
    log.status = np.zeros_like(log.status)
    log.q[3, 1] = robot.limits.q_max[1] + 0.1
    log.q[5, 2] = robot.limits.q_min[2] - 0.25
    log.dq[7, 4] = -1.5  # v_max = 1
    log.tau[9, 0] = 52.0  # τ_max = 50
    log.tau[20, 3] = 4.0  # a step of 4 Nm twice, below 10 % of 50 Nm
    log.ddq_commanded = np.zeros_like(log.ddq_commanded)
    log.ddq_commanded[15, 6] = -321.0
    log.scaling[11] = [1.0, 0.4, 0.0]
    log.status[[12, 13]] = [-2, 1]
    log.optimal[:] = 1
    log.optimal[[12, 13]] = -1  # (not checked: a fallback and a relaxed step)
    log.optimal[[17, 18]] = 0  # two "ok" answers off the lowest level's optimum
    log.wall_time = 0.04
    series = evaluate(spec, robot, log)
    summary = summarize(log, series, robot, [1, 2, 3])
    assert summary["lowest_level_off_optimum_steps"] == 2
    assert summary["max_joint_position_violation"] == pytest.approx(0.25)
    assert summary["max_joint_velocity_violation"] == pytest.approx(0.5)
    assert summary["max_joint_velocity_violation_ratio"] == pytest.approx(0.5)
    assert summary["max_torque_violation"] == pytest.approx(2.0)
    assert summary["max_torque_jump"] == pytest.approx(52.0) and summary["max_torque_jump_ratio"] == pytest.approx(1.04)
    assert summary["torque_jump_steps"] == 2  # up at 9 and down at 10; not the 4 Nm ones
    assert summary["max_controller_acceleration"] == pytest.approx(321.0)  # (no τ_ext: a = q̈_cmd)
    assert summary["joint_acceleration_limits"] is bool(np.isfinite(robot.limits.a_max).any())
    assert summary["solver_failures"] == 1 and summary["limits_relaxed"] == 1
    assert summary["min_scaling"] == 0.0
    assert summary["min_scaling_by_priority"] == {"1": 1.0, "2": 0.4, "3": 0.0}
    assert summary["realtime_factor"] == pytest.approx(0.08 / 0.04)
    errors = series.task_errors["reach"]
    assert summary["task_rms_error"]["reach"] == pytest.approx(np.sqrt(np.mean(np.sum(errors**2, axis=1))))
    tail = errors[-max(1, round(0.1 * len(errors))):]
    assert summary["task_final_error"]["reach"] == pytest.approx(np.max(np.linalg.norm(tail, axis=1)))
    assert summary["primary_mean_acceleration_error"] == pytest.approx(
        np.mean(np.linalg.norm(series.acceleration_errors[1], axis=1)))
    assert summary["acceleration_energy_integral"] == pytest.approx(np.sum(series.acceleration_energy) * 0.002)
    z = series.frame_positions["tool"][:, 2]
    assert summary["max_cartesian_violation"] == pytest.approx(max(0.0, 0.3 - z.min()))
    assert set(SUMMARY_KEYS) <= set(summary)
    json.dumps(json_ready(summary))


def test_json_ready_and_tables(case) -> None:
    assert json_ready({"a": float("nan"), "b": [np.float64(1.5), float("inf")], 3: np.int64(2)}) == \
        {"a": None, "b": [1.5, None], "3": 2}
    spec, robot, log, series = case
    units = {"min_scaling": "1", "task_rms_error": {"reach": "m"}}
    runs = [RunResult(label, robot, log, series, {"min_scaling": value, "task_rms_error": {"reach": 0.5}, "units": units},
                      [1, 2, 3], {}) for label, value in (("dcts", 0.25), ("osc", None))]
    rows = {name: (unit, values) for name, unit, values in table_rows(runs)}
    assert rows["min_scaling"] == ("1", [0.25, None]) and rows["task_rms_error[reach]"] == ("m", [0.5, 0.5])
    table = markdown_table(runs)
    assert table.splitlines()[0] == "| metric | unit | dcts | osc |"
    assert "| min_scaling | 1 | 0.25 | – |" in table
    assert "| task_rms_error[reach] | m | 0.5 | 0.5 |" in table


def test_atomic_directory_replaces_its_own_files_and_keeps_the_users(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with atomic_directory(out, "run") as staging:
        (staging / "a.txt").write_text("first")
        assert not out.exists()
    assert (out / "a.txt").read_text() == "first"
    with pytest.raises(RuntimeError):
        with atomic_directory(out, "run") as staging:
            (staging / "a.txt").write_text("second")
            raise RuntimeError("boom")
    assert (out / "a.txt").read_text() == "first"
    (out / "notes.txt").write_text("mine")  # the user's
    (out / "mine").mkdir()
    with atomic_directory(out, "run") as staging:
        (staging / "b.txt").write_text("third")
    assert sorted(p.name for p in out.iterdir()) == [OWNED, "b.txt", "mine", "notes.txt"]  # a.txt was dcts'
    assert (out / "notes.txt").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    (tmp_path / "file").write_text("")
    with pytest.raises(OutputFolderError):
        with atomic_directory(tmp_path / "file", "run"):
            pass
    users = tmp_path / "users"
    users.mkdir()
    (users / "important.txt").write_text("keep")
    with pytest.raises(OutputFolderError, match="not written by dcts"):
        with atomic_directory(users, "run"):
            pass
    assert [p.name for p in users.iterdir()] == ["important.txt"]


def test_atomic_directory_never_overwrites_a_users_file_where_its_output_goes(tmp_path: Path) -> None:
    """A user's file with the name of a new entry, or added inside a folder dcts wrote: refused,
    and the folder is left as it was (both were overwritten or deleted: another command's
    summary.json, a main.c added to a bundle's firmware/)."""
    out = tmp_path / "out"
    with atomic_directory(out, "run") as staging:
        (staging / "firmware").mkdir()
        (staging / "firmware" / "startup.c").write_text("dcts")
    (out / "firmware" / "my_main.c").write_text("mine")
    with pytest.raises(OutputFolderError, match="firmware/my_main.c"):
        with atomic_directory(out, "run") as staging:
            (staging / "firmware").mkdir()
    assert (out / "firmware" / "my_main.c").read_text() == "mine" and (out / "firmware" / "startup.c").is_file()
    (out / "firmware" / "my_main.c").unlink()
    (out / "summary.json").write_text("mine")
    with pytest.raises(OutputFolderError, match="summary.json"):
        with atomic_directory(out, "run") as staging:
            (staging / "summary.json").write_text("dcts")
    assert (out / "summary.json").read_text() == "mine" and (out / "firmware" / "startup.c").is_file()
    with atomic_directory(out, "run") as staging:  # its own files (all of firmware/) it replaces
        (staging / "log.npz").write_text("dcts")
    assert sorted(p.name for p in out.iterdir()) == [OWNED, "log.npz", "summary.json"]
    (out / OWNED).write_text('["log.npz"]')  # an OWNED file from before the paths were listed
    (out / "log.npz").unlink()
    (out / "log.npz").mkdir()
    (out / "log.npz" / "inside").write_text("")
    with atomic_directory(out, "run") as staging:  # (its folders count as dcts's, as they did)
        (staging / "log.npz").write_text("dcts")
    assert (out / "log.npz").read_text() == "dcts"


def test_empty_log_has_a_summary(case) -> None:
    spec, robot, _, _ = case
    log = SimulationLog.allocate(0, 7, 3, 3, 0.001)
    series = evaluate(spec, robot, log)
    assert isinstance(series, TimeSeries)
    summary = summarize(log, series, robot, [1, 2, 3])
    assert summary["steps"] == 0 and summary["min_scaling"] == 1.0


def test_a_run_folder_from_before_the_owned_list_is_still_written(tmp_path: Path) -> None:
    """runs/minimal from an older dcts (summary.json, no .dcts-owned): the README's first command
    must still run into it; a user's file there stays."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "summary.json").write_text('{"spec": "minimal", "formulation": "dcts", "runtime": "c", "steps": 10}')
    (out / "mine.txt").write_text("keep")
    with atomic_directory(out, "run") as staging:
        (staging / "summary.json").write_text('{"new": 1}')
    assert (out / "summary.json").read_text() == '{"new": 1}' and (out / "mine.txt").read_text() == "keep"


@pytest.mark.parametrize("name, text", [("summary.json", '{"my": "results"}'), ("summary.json", "not json"),
                                        ("comparison.json", '{"a": {"spec": "x"}}'), ("comparison.json", "{}")])
def test_a_users_summary_in_a_folder_dcts_did_not_write_is_not_taken_for_an_older_run(tmp_path: Path, name,
                                                                                      text) -> None:
    """A folder with no OWNED file whose summary.json (comparison.json) is not a dcts run's: the
    user's, refused before any work and left as it was (found from outside: `dcts simulate -o`
    replaced the user's summary.json and log.npz there)."""
    out = tmp_path / "results"
    out.mkdir()
    (out / name).write_text(text)
    (out / "log.npz").write_text("mine")
    with pytest.raises(OutputFolderError, match="not written by dcts"):
        with atomic_directory(out, "run") as staging:
            (staging / name).write_text("dcts")
    assert (out / name).read_text() == text and sorted(p.name for p in out.iterdir()) == sorted([name, "log.npz"])


def _summary(case, **changes):
    """summarize() of the case's log with `changes` to its arrays, and the run around it."""
    spec, robot, log, _ = case
    log = SimulationLog(**{**log.__dict__, **changes})
    series = evaluate(spec, robot, log)
    summary = summarize(log, series, robot, [1, 2, 3])
    summary |= {"spec": "metrics", "formulation": "dcts", "runtime": "python", "period": 0.002}
    summary["units"] = summary_units(summary, series, robot)
    rows = {t.name: make_task(t, robot).row_names for t in spec.tasks}
    return RunResult("dcts", robot, log, series, summary, [1, 2, 3], rows), series


def _numbers(value) -> bool:
    """A number, or a map/list holding only numbers (what needs a unit)."""
    if isinstance(value, dict):
        return bool(value) and all(_numbers(v) for v in value.values())
    if isinstance(value, list):
        return all(_numbers(v) for v in value)
    return isinstance(value, (int, float)) and not isinstance(value, bool)



def test_a_crossing_after_an_ok_step_counts_collision_pairs_and_not_a_narrowed_limit(case) -> None:
    """crossed_after_ok_steps compares each bound's excess at k+1 with the one at k under the limits
    step k held. Found from outside: a Kinova's end effector crossed its 0.02 m from a box by
    4.45e-5 m after the "ok" step at a push's onset, uncounted (collision pairs were left out), and
    a velocity limit a run-time parameter lowered below the speed was counted as the plant's doing."""
    from types import SimpleNamespace

    spec, robot, log, _ = case
    steps = len(log.status)
    log = SimulationLog(**{**log.__dict__, "q": np.tile(log.q[0], (steps, 1)), "dq": np.zeros_like(log.dq),
                           "status": np.zeros_like(log.status)})
    log.dq[:, 0] = 0.5
    series = evaluate(spec, robot, log)
    series.limits.joint.v_max[12:, 0] = 0.3  # narrowed at sample 12, under the joint's 0.5 rad/s
    pairs = SimpleNamespace(pairs=[SimpleNamespace(min_distance=0.02)])
    distances = np.full((steps, 1), 0.05)
    assert summarize(log, series, robot, [1, 2, 3], pairs, distances)["crossed_after_ok_steps"] == 0
    distances[21, 0] = 0.02 - 4.45e-5  # the step at sample 20 let the pair cross
    log.dq[31:, 0] = 0.6  # the step at sample 30 sped the joint up beyond its narrowed limit
    summary = summarize(log, series, robot, [1, 2, 3], pairs, distances)
    assert summary["crossed_after_ok_steps"] == 2 and summary["crossed_after_ok_first"] == pytest.approx(log.time[20])
    log.status[20] = 1  # a relaxed step vouches for nothing
    assert summarize(log, series, robot, [1, 2, 3], pairs, distances)["crossed_after_ok_steps"] == 1

def test_every_number_in_the_summary_has_a_unit(case) -> None:
    run, series = _summary(case)
    s, units = run.summary, run.summary["units"]
    missing = [k for k, v in s.items() if k != "units" and _numbers(v) and k not in units]
    assert not missing
    assert units["max_joint_position_violation"] == "rad" and units["max_joint_velocity_violation"] == "rad/s"
    assert units["max_torque_violation"] == "Nm" and units["min_scaling"] == "1" and units["period"] == "s"
    assert units["task_rms_error"] == {"reach": "m", "tilt": "rad", "posture": "rad", "rest": "rad/s"}
    assert units["mean_acceleration_error"] == {"1": "m/s²", "2": "rad/s²", "3": "rad/s²"}
    assert units["primary_mean_acceleration_error"] == "m/s²"
    json.dumps(json_ready(s))


def test_a_damping_task_reports_its_velocity_error(case) -> None:
    spec, robot, log, series = case
    joints = [5, 6]  # joint6, joint7
    np.testing.assert_allclose(series.task_errors["rest"], -log.dq[:, joints], atol=1e-12)
    assert series.damping == ("rest",)
    run, _ = _summary(case)
    s = run.summary
    assert s["task_error_quantity"] == {"reach": "tracking error", "tilt": "tracking error",
                                        "posture": "tracking error", "rest": "damping (velocity error)"}
    assert s["task_rms_error"]["rest"] == pytest.approx(np.sqrt(np.mean(np.sum(log.dq[:, joints] ** 2, axis=1))))
    assert s["task_rms_error"]["rest"] > 0.1  # not the 0 of an error it does not have


def test_min_scaling_says_which_level_and_when(case) -> None:
    scaling = np.ones((40, 3))
    scaling[11] = [1.0, 0.4, 0.3]
    scaling[20] = [1.0, 0.3, 1.0]  # the same minimum later at a higher level: the first time counts
    run, _ = _summary(case, scaling=scaling)
    assert run.summary["min_scaling"] == pytest.approx(0.3)
    assert run.summary["min_scaling_at"] == {"priority": 3, "tasks": ["posture", "rest"], "time": pytest.approx(0.022)}
    assert "min scaling 0.3 (priority 3: posture, rest, at t = 0.022 s)" in describe(run)
    run, _ = _summary(case, scaling=np.ones((40, 3)))
    assert run.summary["min_scaling_at"] is None and "min scaling 1 (never scaled)" in describe(run)


IGNORED = SPEC.replace("scenario:", "controller: {external_torque: ignored}\nscenario:")


@pytest.mark.parametrize(("text", "used"), [(SPEC, True), (IGNORED, False)])
def test_the_tau_ext_metrics_are_of_the_input_the_controller_used(case, text: str, used: bool) -> None:
    """With controller.external_torque: ignored the controller takes τ_ext = 0 whatever the sensor
    gives. The estimate error and the plot's input line were of the sensor's value (exp5_payload:
    0.243 Nm where the input was off by 28.8 Nm), and max_commanded_acceleration was of q̈_cmd =
    M⁻¹(τ − ν − g), not of a = q̈_cmd + M⁻¹τ_ext,used, which joint_acceleration bounds."""
    _, robot, log, _ = case
    spec = load_spec_text(text)
    push = np.zeros_like(log.tau)
    push[10:20, 3] = 12.0
    ddq_commanded = np.random.default_rng(2).uniform(-5, 5, log.tau.shape)
    # a perfect one-step-late estimate
    log = SimulationLog(**{**log.__dict__, "tau_ext_true": push, "tau_ext_measured": np.roll(push, 1, axis=0),
                           "ddq_commanded": ddq_commanded})
    series = evaluate(spec, robot, log)
    summary = summarize(log, series, robot, [1, 2, 3])
    input_torque = log.tau_ext_measured if used else np.zeros_like(push)
    assert summary["max_external_torque_estimate_error"] == pytest.approx(0.0 if used else 12.0)
    a = ddq_commanded + np.array([np.linalg.solve(dynamics(robot.model, q, dq)[0], t)
                                  for q, dq, t in zip(log.q, log.dq, input_torque)])
    assert summary["max_controller_acceleration"] == pytest.approx(np.abs(a).max(), rel=1e-9)
    summary["units"] = summary_units(summary, series, robot)
    run = RunResult("dcts", robot, log, series, summary, [1, 2, 3], {})
    axes = external_torque_figure(run).axes[3]
    line = next(line for line in axes.lines if line.get_label() == "controller input (τ_ext used)")
    np.testing.assert_array_equal(line.get_ydata(), input_torque[:, 3])
    assert axes.get_title() == f"joint4 (input off by ≤ {0.0 if used else 12.0:.2g} Nm)"


def test_a_peak_over_joints_is_printed_in_the_unit_of_its_joint(tmp_path: Path) -> None:
    """On a lift (prismatic) with two revolute joints the run's line read "torque 0 N, Nm" and
    "velocity 0.1 m/s, rad/s (…)": a peak over the joints is in the unit of the joint where it is
    reached (summary worst_joints), and a 0 is reached at none. The share of its limit is that of
    the joint where the largest share is reached, named where it is another."""
    (tmp_path / "lift.urdf").write_text(LIFT_URDF)
    (tmp_path / "lift.yaml").write_text("version: 1\nname: lift\nrobot: {urdf: lift.urdf}\ntasks:\n  - {name: posture, "
                                        "type: joint, priority: 1, gains: {kp: 10, kd: 6}, reference: {q: [0.2, 0, 0]}}\n")
    spec = load_spec(tmp_path / "lift.yaml")
    robot = validate_spec(spec).robot
    log = SimulationLog.allocate(10, 3, 0, 1, 0.001)
    log.q[:] = [0.2, 0.0, 0.0]
    log.scaling[:] = 1.0
    log.dq[4] = [0.4, 0.0, 0.0]  # the lift 0.1 m/s beyond its 0.3 m/s

    def line() -> str:
        series = evaluate(spec, robot, log)
        summary = summarize(log, series, robot, [1]) | {"spec": "lift", "formulation": "dcts", "runtime": "python"}
        summary["units"] = summary_units(summary, series, robot)
        assert summary["units"]["max_torque_violation"] == "N, Nm"  # (summary.json: the unit of every joint's)
        return next(text for text in describe(RunResult("dcts", robot, log, series, summary, [1], {})).splitlines()
                    if "worst excess" in text)

    assert "velocity 0.1 m/s (33.3% of its limit), torque 0, " in line()
    log.dq[6] = [0.0, 2.5, 0.0]  # the shoulder 0.5 rad/s beyond its 2 rad/s: 25 %, the lift's 33 %
    # (summarize's worst_joints: the largest excess and the largest share at different joints)
    assert "velocity 0.5 rad/s (on shoulder; as a share of a joint's limit, up to 33.3% on lift), " in line()


def test_printed_summary_carries_units(case) -> None:
    relaxed = np.zeros((40, 2), dtype=bool)
    relaxed[[5, 6, 9], 1] = True
    run, _ = _summary(case, bound_names=["joint:joint1", "cartesian:tool.z"], relaxed=relaxed)
    text = describe(run)
    s = run.summary
    assert f"torque {s['max_torque_violation']:.3g} Nm" in text
    assert f"reach {s['task_rms_error']['reach']:.3g} m (" in text
    assert f"rest [damping, velocity] {s['task_rms_error']['rest']:.3g} rad/s" in text
    assert f"position {s['max_joint_position_violation']:.3g} rad," in text
    assert (f"smoothness torque steps between periods up to {s['max_torque_jump']:.3g} Nm "
            f"({100 * s['max_torque_jump_ratio']:.3g}% of its limit; {s['torque_jump_steps']} above 10%)") in text
    # the hint where it helps: jumps, and no acceleration limits to bound them
    s.update(torque_jump_steps=3, joint_acceleration_limits=False)
    assert "3 above 10%), the controller's joint accelerations up to" in describe(run)
    assert "(no limits.joint_acceleration: the velocity limits alone allow 2 q̇_max/T a step)" in describe(run)
    s.update(joint_acceleration_limits=True)
    assert "no limits.joint_acceleration" not in describe(run)
    # The relaxed bound reads as validate words it: the same helper, the same text.
    assert s["relaxed_bounds"]["cartesian:tool.z"] == {"bound": "0.3 m ≤ tool.z", "steps": 3,
                                                      "first": pytest.approx(0.01), "last": pytest.approx(0.018)}
    assert "relaxed    0.3 m ≤ tool.z: 3 steps between t = 0.01 s and 0.018 s" in text


def test_ok_steps_off_the_lowest_levels_optimum_are_said(case) -> None:
    """The printed summary says how many "ok" answers the optimality check found off the lowest
    level's optimum (StepResult.optimal), and says nothing when there are none."""
    _, _, log, _ = case
    optimal = np.ones(log.steps, dtype=np.int8)
    run, _ = _summary(case, optimal=optimal)
    assert run.summary["lowest_level_off_optimum_steps"] == 0 and "optimum" not in describe(run)
    optimal[[3, 4, 9]] = 0
    run, _ = _summary(case, optimal=optimal)
    assert ('optimum    3 "ok" steps whose answer does not minimize the lowest level\'s objective given the '
            "levels above") in describe(run)


def test_a_scaling_just_below_one_is_not_printed_as_one(case) -> None:
    """A level scaled to 0.99996 read "min scaling 1 (priority 1: …)" (a 27-joint Romeo)."""
    _, _, log, _ = case
    scaling = np.ones_like(log.scaling)
    scaling[7, 0] = 0.99996
    run, _ = _summary(case, scaling=scaling)
    assert "min scaling 1 − 4e-05 (priority 1: reach, at t = 0.014 s)" in describe(run)


def test_a_relaxed_joint_says_which_of_its_limits_its_state_was_beyond(case) -> None:
    """One row holds a joint's position and velocity limits: the summary says which one the state
    crossed in the relaxed steps (a user could not tell), or that it crossed neither."""
    _, robot, log, _ = case
    lim = robot.limits
    relaxed = np.zeros((40, 2), dtype=bool)
    relaxed[[5, 6], 0] = True
    dq = log.dq.copy()
    dq[6, 0] = -(lim.v_max[0] + 0.25)
    run, _ = _summary(case, bound_names=["joint:joint1", "cartesian:tool.z"], relaxed=relaxed, dq=dq)
    assert run.summary["relaxed_bounds"]["joint:joint1"]["beyond"] == "its velocity limit by up to 0.25 rad/s"
    assert "2 steps between t = 0.01 s and 0.012 s; beyond its velocity limit by up to 0.25 rad/s" in describe(run)
    q = log.q.copy()
    q[5, 0] = lim.q_max[0] + 0.125
    run, _ = _summary(case, bound_names=["joint:joint1", "cartesian:tool.z"], relaxed=relaxed, dq=dq, q=q)
    assert run.summary["relaxed_bounds"]["joint:joint1"]["beyond"] == (
        "its position limit by up to 0.125 rad and its velocity limit by up to 0.25 rad/s")
    run, _ = _summary(case, bound_names=["joint:joint1", "cartesian:tool.z"], relaxed=relaxed)
    assert run.summary["relaxed_bounds"]["joint:joint1"]["beyond"].startswith("none of its limits")
    assert "beyond" not in run.summary["relaxed_bounds"].get("cartesian:tool.z", {})


def test_the_printed_summary_gives_the_collision_excess_where_pairs_are_watched(case) -> None:
    run, _ = _summary(case)
    assert "collision" not in describe(run).split("\n")[1]  # (no collision section)
    run.summary |= {"max_collision_violation": 0.038}
    run.summary["units"]["max_collision_violation"] = "m"
    assert "collision 0.038 m" in describe(run).split("\n")[1], describe(run).split("\n")[1]


def test_relaxed_bounds_are_worded_as_validate_words_them() -> None:
    spec = load_spec_text(SPEC.replace("reference: {input: true}", "reference: {position: [0.5, 0, 0.1]}"))
    report = validate_spec(spec)
    warning = next(str(d) for d in report.diagnostics if "tool.z" in str(d))
    assert f"outside its bound {row_text(report.robot, 'cartesian:tool.z')} " in warning
    lim = report.robot.limits
    assert row_text(report.robot, "joint:joint2") == (
        f"{lim.q_min[1]:.4g} rad ≤ joint2 ≤ {lim.q_max[1]:.4g} rad, |joint2'| ≤ 1 rad/s")
    assert row_text(report.robot, "joint:nope") == "joint:nope"


def test_plots_label_their_axes_and_keep_honest_scales(case) -> None:
    steps = 40
    rng = np.random.default_rng(1)
    relaxed = np.zeros((steps, 2), dtype=bool)
    relaxed[[5, 6], 0] = True
    status = np.zeros(steps, dtype=np.int8)
    status[[5, 6]] = 1
    residual = 0.03 * rng.standard_normal((steps, 7))  # a model residual, no push
    scaling = np.ones((steps, 3))
    scaling[8:12, 1] = 0.5
    run, _ = _summary(case, bound_names=["joint:joint1", "cartesian:tool.z"], relaxed=relaxed, status=status,
                      tau_ext_measured=residual, scaling=scaling)

    errors = task_error_figure(run).axes
    assert [ax.get_ylabel() for ax in errors] == ["Δx [m]", "Δx [rad]", "Δx [rad]", "−ẋ [rad/s]"]
    assert errors[3].get_title() == "rest — damping (velocity error)"
    assert all("limits relaxed" in ax.get_legend_handles_labels()[1] for ax in errors)

    positions = joint_figure(run, run.log.q, run.series.limits.joint.q_min, run.series.limits.joint.q_max, "q", "")
    labels = [ax.get_legend_handles_labels()[1] for ax in positions.axes if ax.get_visible()]
    assert labels[0] == ["bound relaxed"] and not any(labels[1:])  # joint1 only
    assert positions.axes[1].get_ylabel() == "q [rad]"

    torques = external_torque_figure(run).axes
    low, high = torques[0].get_ylim()
    assert low <= -1.0 and high >= 1.0  # 0.03 Nm stays small on the page
    assert torques[0].get_title() == f"joint1 (input off by ≤ {np.abs(residual[1:, 0]).max():.2g} Nm)"

    flat, _ = _summary(case, scaling=np.ones((steps, 3)))
    flat.label = "osc"
    overlay = scaling_overlay([run, flat]).axes
    # Level 2 of the first run scaled: a line; the second run never did: a legend entry, no line.
    assert [line.get_label() for line in overlay[1].lines if len(line.get_xdata())] == ["dcts"]
    assert "osc: never scaled" in overlay[1].get_legend_handles_labels()[1]
    assert overlay[0].get_legend_handles_labels()[1] == ["dcts: never scaled", "osc: never scaled"]


def test_a_closed_form_reports_its_bounds_unchecked_not_held():
    """osc and the projector have no bound rows, so their status is 0 whatever the bounds: a run of
    osc that crossed a Cartesian bound by 0.07 m and a joint limit by 0.1 rad said "0 steps with
    relaxed limits", next to dcts's count in `dcts compare` (found from outside)."""
    from dcts_spec.analysis.run import analyze
    from dcts_spec.sim.runner import prepare_simulation

    spec = load_spec(Path(__file__).resolve().parents[1] / "specs" / "minimal.yaml")
    for formulation, checked in (("osc", False), ("dcts", True)):
        sim = prepare_simulation(spec, "python", formulation, duration=0.05)
        run = analyze(sim, sim.run())
        assert run.summary["bounds_checked"] is checked
        assert (run.summary["limits_relaxed"] is None) is not checked
        assert ("bounds not checked (osc is a closed form" in describe(run)) is not checked


def test_the_share_of_a_limit_names_its_joint_where_it_is_not_the_largest_values():
    """A PR2's largest torque step was its prismatic lift's 1,132 N (11 % of its limit) and the
    largest share of a limit its shoulder's 188 %: the line said "1.13e+03 N (188% of its limit)"
    (found from outside). Now it names both joints where they differ."""
    from types import SimpleNamespace

    from dcts_spec.analysis.report import share_of_limit

    summary = {"max_torque_jump": 1132.0, "max_torque_jump_ratio": 1.88,
               "worst_joints": {"max_torque_jump": "torso_lift", "max_torque_jump_ratio": "r_shoulder_pan"}}
    assert share_of_limit(SimpleNamespace(summary=summary), "max_torque_jump") == \
        "on torso_lift; as a share of a joint's limit, up to 188% on r_shoulder_pan"
    summary["worst_joints"]["max_torque_jump_ratio"] = "torso_lift"
    summary["max_torque_jump_ratio"] = 0.113
    assert share_of_limit(SimpleNamespace(summary=summary), "max_torque_jump") == "11.3% of its limit"
