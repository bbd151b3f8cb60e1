"""`dcts sweep`: campaign files with located errors, reproducible samples, the same numbers on
Ray and in a serial loop, resuming, replaying a worst case with `dcts simulate`, tuning.

Small campaigns (4-8 samples of a 0.3 s run of specs/minimal.yaml) and one Ray session for the
module (2 CPUs, no dashboard), to stay within the suite's time."""

from __future__ import annotations

import json
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from command_line import MINIMAL, ROOT, invoke

from dcts_spec.campaign import SweepOptions, load_campaign_text, sweep, tune
from dcts_spec.campaign.engine import RayPool
from dcts_spec.campaign.report import save_json, summary_lines, worst_cases
from dcts_spec.campaign.results import NAMES, ResultsFolder
from dcts_spec.files import OWNED
from dcts_spec.campaign.runner import CampaignInputs, SampleRunner, metric_columns
from dcts_spec.campaign.sampling import Sampler
from dcts_spec.campaign.scenario import JointRange, sample_spec_data
from dcts_spec.campaign.schema import campaign_json_schema_text
from dcts_spec.campaign.units import labelled
from dcts_spec.campaign.sweep import CampaignSession, check_campaign
from dcts_spec.spec import SpecError

ray = pytest.importorskip("ray")

CAMPAIGN = """\
version: 1
samples: 6
seed: 11
duration: 0.3
pushes:
  - body: link7
    force: {magnitude: {uniform: [0, 60]}, direction: horizontal}
    point: [0, 0, {uniform: [0, 0.05]}]
    start: {uniform: [0.05, 0.15]}
    duration: {choice: [0.05, 0.1]}
payloads:
  - frame: tool
    mass: {uniform: [0.5, 2.5]}
external_torque: {noise_std: {uniform: [0, 0.5]}, bias: {normal: [0, 0.2]}}
initial_state: {offset: {uniform: [-3, 3]}, unit: deg}
controller:
  parameters:
    tool_position.kp: {loguniform: [50, 400]}
report:
  worst: 2
  metrics: [primary_rms_error, max_torque_violation, max_joint_velocity_violation]
"""
EXAMPLE = ROOT / "specs" / "campaigns" / "pushes_payloads.yaml"
# Metrics that measure the machine, not the controller.
TIMING = {"wall_time"}


@pytest.fixture(scope="module", autouse=True)
def _private_bundle_cache(tmp_path_factory):
    """No test writes into the user's bundle cache (the driver gives its cache to the workers)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("DCTS_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "bundle-cache"))
        yield


@pytest.fixture(scope="module")
def ray_session():
    """One local Ray session for the module."""
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def spec_file(tmp_path_factory) -> Path:
    """specs/minimal.yaml with the position task's kp as a run-time parameter, a 0.3 s run."""
    folder = tmp_path_factory.mktemp("spec")
    text = MINIMAL.read_text().replace("name: minimal", "name: sweep_minimal").replace("duration: 2.0", "duration: 0.3")
    path = folder / "sweep_minimal.yaml"
    path.write_text(text + "parameters:\n  tasks: {tool_position: [kp]}\n")
    return path


@pytest.fixture(scope="module")
def campaign_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("campaign") / "campaign.yaml"
    path.write_text(CAMPAIGN)
    return path


@pytest.fixture(scope="module")
def serial_run(ray_session, spec_file, campaign_file, tmp_path_factory):
    """The whole campaign in a plain loop: the reference for the other runs."""
    out = tmp_path_factory.mktemp("serial") / "out"
    return sweep(spec_file, campaign_file, out, SweepOptions(engine="serial", progress=False, plots=False))


def _rows(folder: Path) -> dict[int, dict]:
    rows = [json.loads(line) for line in (folder / "samples.jsonl").read_text().splitlines()]
    assert len({r["index"] for r in rows}) == len(rows), "a sample was run twice"
    return {r["index"]: r for r in rows}


def _without_timing(row: dict) -> dict:
    return {k: v for k, v in row.items() if k not in TIMING}


# -- the campaign file --------------------------------------------------------------------------------------


def test_campaign_errors_are_located_and_say_what_is_allowed() -> None:
    text = CAMPAIGN.replace("{uniform: [0, 60]}", "{unifrom: [0, 60]}").replace("mass: {uniform: [0.5, 2.5]}",
                                                                               "mass: heavy")
    text += "model_mismatch: {mass_scale: {uniform: [0.9, 1.1]}}\n"
    with pytest.raises(SpecError) as caught:
        load_campaign_text(text, "c.yaml")
    messages = [str(d) for d in caught.value.diagnostics]
    assert any(m.startswith("c.yaml:7:") and "'unifrom'" in m and "did you mean 'uniform'" in m for m in messages)
    assert any(m.startswith("c.yaml:13:") and "expected a number or a distribution" in m for m in messages)
    assert any(m.startswith("c.yaml:22:") and "its own C bundle" in m for m in messages), messages


@pytest.mark.parametrize(("old", "new", "line", "words"), [
    ("noise_std: {uniform: [0, 0.5]}", "noise_std: {uniform: [-1, 0.5]}", 14, "values from -1 to 0.5: must be ≥ 0"),
    ("noise_std: {uniform: [0, 0.5]}", "noise_std: {normal: [0.5, 0.1]}", 14, "values from -0.1 to 1.1 (mean ± 6 σ)"),
    ("mass: {uniform: [0.5, 2.5]}", "mass: {choice: [0, 1]}", 13, "values from 0 to 1: must be > 0 and ≤ 1e4 kg"),
    ("duration: {choice: [0.05, 0.1]}", "duration: -0.1", 10, "values -0.1: must be > 0"),
])
def test_a_draw_the_spec_would_refuse_is_an_error_in_the_campaign(old, new, line, words) -> None:
    """Every sample was invalid, with the error blamed on the spec's scenario line."""
    assert old in CAMPAIGN
    with pytest.raises(SpecError) as caught:
        load_campaign_text(CAMPAIGN.replace(old, new), "c.yaml")
    messages = [str(d) for d in caught.value.diagnostics]
    assert any(m.startswith(f"c.yaml:{line}:") and words in m for m in messages), messages


def test_a_normal_draw_well_within_the_range_is_taken() -> None:
    """A payload of normal(2, 0.2) kg ran before the ranges were checked, and still does."""
    campaign = load_campaign_text(CAMPAIGN.replace("mass: {uniform: [0.5, 2.5]}", "mass: {normal: [2, 0.2]}"))
    assert campaign.payloads[0].mass.normal == (2, 0.2)


def test_an_empty_campaign_file_is_called_one() -> None:
    for text, words in (("", "a campaign file is a mapping with at least `version` and `samples`"),
                        ("- 1\n", "a campaign file must be a mapping of keys (version, samples, ...)")):
        with pytest.raises(SpecError) as caught:
            load_campaign_text(text, "c.yaml")
        assert words in str(caught.value), str(caught.value)


def test_a_violation_within_the_tolerance_is_no_worst_case() -> None:
    rows = [{"index": i, "status": "ok", "max_torque_violation": v} for i, v in enumerate((0.0, 1.5e-9, 2e-6))]
    assert [r["index"] for r in worst_cases(rows, "max_torque_violation", 3, 1e-6)] == [2]
    assert [r["index"] for r in worst_cases(rows, "max_torque_violation", 3, 0.0)] == [2, 1]


def test_campaign_names_checked_against_the_spec(spec_file, tmp_path) -> None:
    campaign = tmp_path / "c.yaml"
    campaign.write_text(CAMPAIGN.replace("body: link7", "body: link77").replace("primary_rms_error,", "primary_rms,"))
    result = invoke("sweep", str(spec_file), "--campaign", str(campaign), "-o", str(tmp_path / "out"), "--serial",
                    "--no-plots")
    assert result.exit_code == 1
    assert f"{campaign}:6:5: error: pushes[0].body: no frame 'link77' in the robot (did you mean 'link7'?)" in result.stderr
    assert f"{campaign}:21:" in result.stderr and "unknown metric 'primary_rms'" in result.stderr
    campaign.write_text(CAMPAIGN.replace("bias: {normal: [0, 0.2]}", "bias: [0, 0.1, 0.2]"))
    result = invoke("sweep", str(spec_file), "--campaign", str(campaign), "-o", str(tmp_path / "out"), "--serial")
    assert result.exit_code == 1 and f"{campaign}:14:" in result.stderr and "3 values for 7 joints" in result.stderr
    # run-time parameters are checked on the compiled controller, which knows their names and ranges
    campaign.write_text(CAMPAIGN.replace("tool_position.kp: {loguniform: [50, 400]}", "tool_position.kq: 100\n    "
                                         "tool_position.kp: {uniform: [-5, 400]}"))
    result = invoke("sweep", str(spec_file), "--campaign", str(campaign), "-o", str(tmp_path / "out"), "--serial",
                    "--no-plots")
    assert result.exit_code == 1
    assert f"{campaign}:18:" in result.stderr and "'tool_position.kq' is not a run-time parameter" in result.stderr
    assert f"{campaign}:19:" in result.stderr and "leave the allowed range [0, 1e+08]" in result.stderr
    assert not (tmp_path / "out").exists()  # (it held campaign.json, and the fixed campaign was refused there)


def test_one_range_for_every_joint_is_checked_against_each_joints_limit(spec_file, tmp_path) -> None:
    """A velocity limit drawn from [2, 3] rad/s for all joints passed (it was checked against
    the largest joint's envelope) and every sample was invalid."""
    spec = tmp_path / "spec.yaml"
    spec.write_text(spec_file.read_text().replace("parameters:\n  tasks: {tool_position: [kp]}",
                                                  "parameters:\n  tasks: {tool_position: [kp]}\n  limits: [joint_velocity]"))
    campaign = tmp_path / "c.yaml"
    campaign.write_text(CAMPAIGN.replace("tool_position.kp: {loguniform: [50, 400]}",
                                         "joint_velocity.max: {uniform: [2, 3]}"))
    result = invoke("sweep", str(spec), "--campaign", str(campaign), "-o", str(tmp_path / "out"), "--serial", "-q")
    assert result.exit_code == 1 and f"{campaign}:18:" in result.stderr, result.output
    assert "leave the allowed range (0, 1.74533] rad/s" in result.stderr and "what all its components allow" in result.stderr
    assert not (tmp_path / "out").exists()


def test_a_campaign_too_large_to_list_is_refused(spec_file, tmp_path) -> None:
    """10⁷ samples at each of 100 grid points passed (only `samples` was capped) and the run took
    24 GB listing them before it ran one."""
    campaign = tmp_path / "c.yaml"
    campaign.write_text(CAMPAIGN.replace("samples: 6", "samples: 10000000").replace(
        "duration: {choice: [0.05, 0.1]}", "duration: {grid: [0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07, 0.08, 0.09, 0.1]}")
        .replace("mass: {uniform: [0.5, 2.5]}", "mass: {grid: [0.5, 1, 1.5, 2, 2.5, 3, 3.5, 4, 4.5, 5]}"))
    result = invoke("sweep", str(spec_file), "--campaign", str(campaign), "-o", str(tmp_path / "out"), "--serial", "-q",
                    "--max-samples", "2")
    assert result.exit_code == 1 and f"{campaign}:2:" in result.stderr, result.output
    assert "at each of the 100 grid points are 1,000,000,000 samples" in result.stderr
    assert not (tmp_path / "out").exists()


def test_samples_are_drawn_from_seed_and_index_alone() -> None:
    campaign = load_campaign_text(CAMPAIGN + "model_mismatch: {mass_scale: {grid: [0.9, 1.1]}}\n")
    sampler = Sampler(campaign, 7)
    assert sampler.count == 12  # 6 draws at each of 2 grid points
    forward = [sampler.sample(i) for i in range(sampler.count)]
    assert [sampler.sample(i) for i in reversed(range(sampler.count))][::-1] == forward
    assert [s.value("model_mismatch", "mass_scale") for s in forward] == [0.9] * 6 + [1.1] * 6
    masses = [s.value("payloads", 0, "mass") for s in forward]
    assert all(0.5 <= m <= 2.5 for m in masses) and len(set(masses)) == 12
    assert Sampler(load_campaign_text(CAMPAIGN.replace("seed: 11", "seed: 12")), 7).sample(0) != forward[0]


def test_grids_cross_and_start_states_stay_within_the_limits() -> None:
    campaign = load_campaign_text("version: 1\nsamples: 3\nduration: 0.3\ninitial_state: {within_limits: 0.2}\n"
                                  "controller: {formulation: {grid: [dcts, osc]}}\n"
                                  "payloads: [{frame: tool, mass: {grid: [1, 2]}}]\n")
    sampler = Sampler(campaign, 7)
    samples = [sampler.sample(i) for i in range(sampler.count)]
    assert [(s.value("payloads", 0, "mass"), s.formulation) for s in samples] == [
        (m, f) for m in (1.0, 2.0) for f in ("dcts", "osc") for _ in range(3)]
    joints = JointRange(np.zeros(7), -np.arange(1.0, 8.0), np.arange(1.0, 8.0), np.zeros(7, dtype=bool))
    for sample in samples:
        data = sample_spec_data({"scenario": {"duration": 2.0, "unit": "deg"}}, campaign, sample, joints)
        q = np.array(data["scenario"]["initial_q"])
        span = joints.q_max - joints.q_min
        assert np.all(q >= joints.q_min + 0.2 * span - 1e-12) and np.all(q <= joints.q_max - 0.2 * span + 1e-12)
        assert data["scenario"]["unit"] == "rad" and data["controller"]["formulation"] == sample.formulation
        assert data["scenario"]["payloads"] == [{"frame": "tool", "mass": sample.value("payloads", 0, "mass"),
                                                 "com": [0.0, 0.0, 0.0]}]


def test_a_swept_parameter_wins_over_the_specs_own_set_at_t0() -> None:
    """The spec sets kp at t = 0 itself: the sample's kp is what runs from t = 0 (it ran the spec's,
    and every sample had the same metrics), and the spec's later changes still come."""
    campaign = load_campaign_text("version: 1\nsamples: 2\nduration: 0.3\n"
                                  "controller: {parameters: {tool_position.kp: {grid: [20, 3000]}}}\n")
    spec_changes = [{"time": 0.1, "values": {"joint_torque.max": 80}}, {"time": 0.0, "values": {"tool_position.kp": 400}}]
    joints = JointRange(np.zeros(7), -np.ones(7), np.ones(7), np.zeros(7, dtype=bool))
    sampler = Sampler(campaign, 7)
    for sample in (sampler.sample(i) for i in range(sampler.count)):
        data = sample_spec_data({"scenario": {"parameters": spec_changes}}, campaign, sample, joints)
        changes = sorted(data["scenario"]["parameters"], key=lambda c: c["time"])  # (as the run orders them)
        at_start = [c["values"]["tool_position.kp"] for c in changes if c["time"] == 0.0]
        assert at_start[-1] == sample.value("controller", "parameters", "tool_position.kp") != 400
        assert changes[-1] == spec_changes[0]


def test_the_committed_campaign_schema_is_up_to_date_and_takes_the_example() -> None:
    jsonschema = pytest.importorskip("jsonschema")
    committed = ROOT / "schemas" / "dcts-campaign.schema.json"
    assert committed.read_text() == campaign_json_schema_text(), (
        "regenerate it: python -m dcts_spec.campaign.schema schemas/dcts-campaign.schema.json")
    schema = json.loads(committed.read_text())
    jsonschema.validate(yaml.safe_load(EXAMPLE.read_text()), schema)
    jsonschema.validate(yaml.safe_load(CAMPAIGN), schema)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(yaml.safe_load(CAMPAIGN.replace("{uniform: [0.5, 2.5]}", "{unifrom: [0.5, 2.5]}")), schema)


def test_the_example_campaign_fits_the_benchmark_spec() -> None:
    spec = ROOT / "specs" / "bench_iiwa14.yaml"
    runner = SampleRunner(CampaignInputs(str(spec), spec.read_text(), str(EXAMPLE), EXAMPLE.read_text(), "unused"))
    check_campaign(runner)  # its bodies, frames and metrics exist in the spec
    assert runner.sampler.count == 1000 and "pushes[0].force.magnitude" in runner.sampler.swept()


# -- engines, resuming, replaying ----------------------------------------------------------------------------


def test_ray_gives_the_serial_loops_numbers(ray_session, spec_file, campaign_file, serial_run, tmp_path) -> None:
    result = sweep(spec_file, campaign_file, tmp_path / "out", SweepOptions(progress=False))
    assert result.complete and result.report["throughput"]["engine"] == "ray"
    assert result.report["throughput"]["workers"] == 2
    serial, parallel = _rows(serial_run.folder), _rows(result.folder)
    assert sorted(serial) == list(range(6))
    assert all(r["status"] == "ok" for r in serial.values())
    for i in serial:
        assert _without_timing(parallel[i]) == _without_timing(serial[i])
    # the samples differ (the campaign sweeps something) and the kp reached the controller's log
    assert len({r["primary_rms_error"] for r in serial.values()}) == 6
    assert (result.folder / "report.html").is_file() and result.report["plots"]
    assert all((result.folder / p).is_file() for p in result.report["plots"])
    assert "plots/controller.parameters.tool_position.kp.png" in result.report["plots"]
    assert "plots/initial_state.offset.norm.png" in result.report["plots"]  # a per-joint value: by its norm


@pytest.mark.slow  # (Ray's own session: test_ray_gives_the_serial_loops_numbers)
def test_a_cluster_address_runs_the_campaign_there(ray_session, spec_file, campaign_file, serial_run,
                                                   tmp_path) -> None:
    """`--address`: another process (here the module's Ray session stands for a cluster) runs the
    samples; the command connects to it instead of starting its own."""
    out = tmp_path / "out"
    address = ray.get_runtime_context().gcs_address
    args = ["sweep", str(spec_file), "--campaign", str(campaign_file), "-o", str(out), "--address", address,
            "--no-plots", "-q"]
    finished = subprocess.run([str(Path(sys.executable).with_name("dcts")), *args], capture_output=True, text=True,
                              timeout=300)
    assert finished.returncode == 0, finished.stderr
    report = json.loads((out / "report.json").read_text())
    assert report["throughput"]["engine"] == "ray" and report["throughput"]["workers"] == 2
    rows, reference = _rows(out), _rows(serial_run.folder)
    assert sorted(rows) == list(range(6))
    assert all(_without_timing(rows[i]) == _without_timing(reference[i]) for i in rows)


@pytest.mark.slow
def test_a_dead_worker_is_replaced_and_its_samples_run_again(ray_session, spec_file, campaign_file,
                                                             serial_run) -> None:
    session = CampaignSession(spec_file, campaign_file, serial_run.folder, {"mode": "sweep"},
                              SweepOptions(progress=False))
    pool = RayPool(session.inputs)
    try:
        rows = []
        for row in pool.map(list(range(6))):
            if not rows:
                ray.kill(pool._actors[0])  # as a segfault in the C code would end it
            rows.append(row)
    finally:
        pool.close()
    reference = _rows(serial_run.folder)
    assert sorted(r["index"] for r in rows) == list(range(6))
    assert all(_without_timing(r) == _without_timing(reference[r["index"]]) for r in rows)


def test_an_interrupted_campaign_resumes_where_it_stopped(spec_file, campaign_file, serial_run, tmp_path) -> None:
    out = tmp_path / "out"  # (serial: resuming is the folder's business, whatever the engine)
    first = sweep(spec_file, campaign_file, out,
                  SweepOptions(engine="serial", progress=False, max_samples=3, plots=False))
    assert not first.complete and len(_rows(out)) == 3
    # killed while writing the fourth line: a line cut short
    with (out / "samples.jsonl").open("a") as f:
        f.write('{"index": 3, "seed": 1')
    second = sweep(spec_file, campaign_file, out, SweepOptions(engine="serial", progress=False, plots=False))
    assert second.complete and second.report["throughput"]["samples"] == 3  # only the 3 missing ones ran
    rows, reference = _rows(out), _rows(serial_run.folder)
    assert sorted(rows) == list(range(6))
    assert all(_without_timing(rows[i]) == _without_timing(reference[i]) for i in rows)


@pytest.mark.slow  # (the default tier resumes an interrupted one: test_an_interrupted_campaign_resumes_where_it_stopped)
@pytest.mark.parametrize("engine", ["serial", "ray"])
def test_a_killed_campaign_resumes(spec_file, tmp_path, engine) -> None:
    """SIGTERM in the middle of a campaign (a cluster job's end): the finished samples stay, the
    command exits with 143, and the same command runs the others only. (With Ray, its core
    worker's own handler dumped a stack trace and exited with 15.)"""
    campaign_file = tmp_path / "campaign.yaml"
    campaign_file.write_text(CAMPAIGN.replace("samples: 6", "samples: 30"))
    out = tmp_path / "out"
    args = ["sweep", str(spec_file), "--campaign", str(campaign_file), "-o", str(out), "--no-plots", "-q"]
    args += ["--serial"] if engine == "serial" else ["--workers", "1"]
    script = Path(sys.executable).with_name("dcts")
    process = subprocess.Popen([str(script), *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    samples = out / "samples.jsonl"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        if samples.is_file() and samples.read_text().count("\n") >= 2:
            break
        time.sleep(0.05)
    process.send_signal(signal.SIGTERM)
    code = process.wait(60)
    errors = process.stderr.read() if process.stderr else ""
    assert code == 128 + signal.SIGTERM, errors
    assert "Token authentication" not in errors  # (Ray's start-up notice, printed under -q)
    stopped = _rows(out)
    assert 2 <= len(stopped) < 30
    result = sweep(spec_file, campaign_file, out, SweepOptions(engine="serial", progress=False, plots=False))
    assert result.complete and result.report["throughput"]["samples"] == 30 - len(stopped)
    rows = _rows(out)
    assert sorted(rows) == list(range(30))
    assert all(_without_timing(rows[i]) == _without_timing(stopped[i]) for i in stopped)


def test_a_stop_that_lands_in_casadi_ends_the_campaign_not_the_sample(spec_file, campaign_file, monkeypatch) -> None:
    """SIGTERM's SystemExit, raised while CasADi's C code runs, reaches the sample as a SystemError:
    it was recorded as that sample's error and the campaign ran on to its end (exit 0: the killed
    campaign test above failed now and then under load). Now the stop ends the campaign."""
    from dcts_spec import files
    from dcts_spec.campaign import runner as runner_module

    class Closable:
        def __init__(self, _bundle) -> None:
            pass

        def close(self) -> None:
            pass

    def simulation_interrupted_in_casadi(*_args) -> None:
        files.request_stop(signal.SIGTERM)  # (what the CLI's handler records before its SystemExit)
        try:
            raise SystemExit(128 + signal.SIGTERM)
        except SystemExit:
            raise SystemError("<function DM.__array__> returned a result with an exception set") from None

    monkeypatch.setattr(files, "_stop_signal", None)
    monkeypatch.setattr(runner_module, "CompiledController", Closable)
    monkeypatch.setattr(runner_module, "Simulation", simulation_interrupted_in_casadi)
    monkeypatch.setattr(SampleRunner, "bundle", lambda self, *args: None)
    runner = SampleRunner(CampaignInputs(str(spec_file), spec_file.read_text(), str(campaign_file),
                                         campaign_file.read_text(), "unused"))
    with pytest.raises(SystemExit) as stopped:
        runner.run(0)
    assert stopped.value.code == 128 + signal.SIGTERM


def test_a_changed_campaign_is_refused_at_its_file(spec_file, campaign_file, serial_run, tmp_path) -> None:
    changed = tmp_path / "campaign.yaml"
    changed.write_text(CAMPAIGN.replace("seed: 11", "seed: 12"))
    result = invoke("sweep", str(spec_file), "--campaign", str(changed), "-o", str(serial_run.folder), "--serial")
    assert result.exit_code == 1
    assert result.stderr.startswith(f"{changed}:1:1: error: this campaign file changed since")
    assert len(_rows(serial_run.folder)) == 6  # nothing written


def test_a_campaign_that_stopped_before_any_sample_starts_again_with_the_changed_file(spec_file, campaign_file,
                                                                                      tmp_path) -> None:
    """A campaign that crashed at its start (an overflowing range, since refused) left campaign.json
    alone, and the corrected file was refused as "changed since": the folder had to be removed by
    hand (first seen from outside). With no sample, nothing is lost by starting again."""
    out = tmp_path / "out"
    folder = ResultsFolder(out, spec_file, campaign_file, {"mode": "sweep"})
    folder.open(6)  # (what a run records before its first sample)
    changed = tmp_path / "campaign.yaml"
    changed.write_text(CAMPAIGN.replace("samples: 6", "samples: 1"))
    result = invoke("sweep", str(spec_file), "--campaign", str(changed), "-o", str(out), "--serial", "--no-plots", "-q")
    assert result.exit_code == 0, result.output
    assert len(_rows(out)) == 1 and json.loads((out / "campaign.json").read_text())["campaign"] == str(changed)


@pytest.mark.parametrize(("line", "words"), [
    ('{"index": 2, "seed": 1, "status": "ok"', "not a JSON object"),  # (garbled in the middle)
    ('{"index": 99, "seed": 1, "status": "ok"}', "its index 99 is not a sample of this campaign (0 to 5)"),
    ('{"index": 1, "seed": 1}', "its status null is none of ok, invalid, error"),
])
def test_a_foreign_line_in_the_samples_is_an_error_at_it(spec_file, campaign_file, serial_run, tmp_path,
                                                         line, words) -> None:
    """A garbled or foreign line gave an internal error (exit 3: JSONDecodeError, KeyError)."""
    out = tmp_path / "out"
    shutil.copytree(serial_run.folder, out)
    rows = (out / "samples.jsonl").read_text().splitlines()
    (out / "samples.jsonl").write_text("\n".join([*rows[:3], line, *rows[3:]]) + "\n")
    result = invoke("sweep", str(spec_file), "--campaign", str(campaign_file), "-o", str(out), "--serial", "-q")
    assert result.exit_code == 1, result.output
    assert result.stderr.startswith(f"{out / 'samples.jsonl'}:4:1: error: {words}"), result.stderr


def test_a_report_is_json_without_infinity(tmp_path) -> None:
    """A trial scored worst possible (∞) made report.json and trials.jsonl invalid JSON."""
    save_json({"best": {"value": float("inf")}, "history": [float("nan"), 1.0]}, tmp_path / "r.json")
    def refuse(constant):
        raise ValueError(constant)
    assert json.loads((tmp_path / "r.json").read_text(), parse_constant=refuse) == {
        "best": {"value": None}, "history": [None, 1.0]}


def test_an_unreachable_cluster_is_an_error_at_once(spec_file, campaign_file, tmp_path) -> None:
    """Ray retried for minutes, printing only its own log lines, and left the folder behind."""
    result = invoke("sweep", str(spec_file), "--campaign", str(campaign_file), "-o", str(tmp_path / "out"),
                    "--address", "127.0.0.1:1", "-q")
    assert result.exit_code == 1 and "--address 127.0.0.1:1: no Ray cluster answers there" in result.stderr
    assert not (tmp_path / "out").exists()


def test_a_folder_dcts_did_not_write_is_refused(spec_file, campaign_file, tmp_path) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    result = invoke("sweep", str(spec_file), "--campaign", str(campaign_file), "-o", str(tmp_path), "--serial")
    assert result.exit_code == 1 and "not written by dcts" in result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_a_campaigns_folder_keeps_its_samples_and_the_users_files(spec_file, campaign_file, tmp_path) -> None:
    """Another command's output never replaces a campaign (`dcts simulate -o` into one deleted it),
    and a campaign's report replaces only the report files dcts wrote (a rerun deleted the user's
    files in plots/ and replays/)."""
    out = tmp_path / "out"
    options = SweepOptions(engine="serial", progress=False, max_samples=2)
    sweep(spec_file, campaign_file, out, options)
    (out / "plots" / "notes.txt").write_text("mine")
    (out / "replays" / "sample_mine.yaml").write_text("mine")
    for command in (("simulate", "--no-plots"), ("compare", "--no-plots"), ("compile", "--no-build")):
        result = invoke(command[0], str(spec_file), *command[1:], "-o", str(out), "-q")
        assert result.exit_code == 1 and "holds the output of `dcts sweep`" in result.stderr, result.output
    assert len(_rows(out)) == 2
    old_plots = {p.name for p in (out / "plots").glob("*.png")}
    resumed = sweep(spec_file, campaign_file, out, options)
    assert len(_rows(out)) == 4 and (out / "report.json").is_file() and old_plots
    assert (out / "plots" / "notes.txt").read_text() == "mine"
    assert (out / "replays" / "sample_mine.yaml").read_text() == "mine"
    assert {p.name for p in (out / "replays").glob("sample_0*.yaml")} == {
        Path(w["replay"]).name for w in resumed.report["worst_cases"]}  # (the earlier worst cases' replaced)


@pytest.mark.slow  # (an older dcts's folder; the default tier resumes the current one's)
def test_a_campaign_folder_of_an_older_dcts_resumes(spec_file, campaign_file, tmp_path) -> None:
    """Its .dcts-owned is a plain list of names: its report files count as dcts's (the first
    version of the report's staging refused them as a user's, and the campaign never finished)."""
    out = tmp_path / "out"
    options = SweepOptions(engine="serial", progress=False, max_samples=2)
    sweep(spec_file, campaign_file, out, options)
    (out / OWNED).write_text(json.dumps(sorted(NAMES)) + "\n")  # (as an older dcts wrote it)
    resumed = sweep(spec_file, campaign_file, out, SweepOptions(engine="serial", progress=False))
    assert resumed.complete and json.loads((out / "report.json").read_text())["finished"] == 6


def test_a_worst_case_replays_with_dcts_simulate(spec_file, campaign_file, serial_run) -> None:
    worst = serial_run.report["worst_cases"][0]
    assert worst["metric"] == "primary_rms_error"
    row = _rows(serial_run.folder)[worst["index"]]
    assert worst["value"] == max(r["primary_rms_error"] for r in _rows(serial_run.folder).values())
    replay = serial_run.folder / worst["replay"]
    scenario = yaml.safe_load(replay.read_text())["scenario"]
    assert scenario["parameters"][0]["values"]["tool_position.kp"] == row["controller.parameters.tool_position.kp"]
    command = shlex.split(worst["command"])  # the report's command line, as given
    assert command[:3] == ["dcts", "simulate", str(replay)]
    result = invoke(*command[1:], "--no-plots", "-q")
    assert result.exit_code == 0, result.output
    replayed_folder = Path(command[command.index("-o") + 1])
    summary = json.loads((replayed_folder / "summary.json").read_text())
    replayed = metric_columns(summary, "tool_position")
    assert {k: v for k, v in replayed.items() if k not in TIMING} == {k: row[k] for k in replayed if k not in TIMING}
    # the campaign's next report rewrites its replay specs, and leaves the replayed run alone
    sweep(spec_file, campaign_file, serial_run.folder, SweepOptions(engine="serial", progress=False, plots=False))
    assert replay.is_file() and (replayed_folder / "summary.json").is_file()


@pytest.mark.slow  # (the default tier resumes a serial study: test_an_interrupted_optimization_resumes_with_new_values)
def test_optimize_tunes_the_gain_and_resumes(ray_session, spec_file, tmp_path) -> None:
    campaign_file = tmp_path / "campaign.yaml"
    campaign_file.write_text(CAMPAIGN.replace("samples: 6", "samples: 3"))
    out = tmp_path / "out"
    options = SweepOptions(progress=False, plots=False)
    first = tune(spec_file, campaign_file, out, "primary_rms_error", "worst", trials=3, options=options)
    record = first.report["optimize"]
    assert record["trials"] == 3 and len((out / "trials.jsonl").read_text().splitlines()) == 3
    assert len({t["values"]["tool_position.kp"] for t in record["history"]}) == 3
    assert record["best"]["value"] == min(t["value"] for t in record["history"])
    assert 50 <= record["best"]["values"]["tool_position.kp"] <= 400
    # the campaign's rows ran with the best gain: their worst is the best trial's objective
    rows = _rows(out)
    assert {r["controller.parameters.tool_position.kp"] for r in rows.values()} == {record["best"]["values"]["tool_position.kp"]}
    assert max(r["primary_rms_error"] for r in rows.values()) == pytest.approx(record["best"]["value"], rel=1e-12)
    second = tune(spec_file, campaign_file, out, "primary_rms_error", "worst", trials=4, options=options)
    assert second.report["optimize"]["trials"] == 4  # the three finished trials kept, one more run
    assert len((out / "trials.jsonl").read_text().splitlines()) == 4
    assert "Best of 4 trials" in (out / "report.html").read_text()
    best = second.report["optimize"]["best"]  # the rows are the best trial's, whichever run found it
    assert max(r["primary_rms_error"] for r in _rows(out).values()) == pytest.approx(best["value"], rel=1e-12)


def test_an_interrupted_optimization_resumes_with_new_values(spec_file, tmp_path) -> None:
    """The trial an interrupted run was in is closed, and the resumed study draws new values (its
    sampler, seeded as at the start, proposed the first trials' values again)."""
    import optuna
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    campaign_file = tmp_path / "campaign.yaml"
    campaign_file.write_text(CAMPAIGN.replace("samples: 6", "samples: 1"))
    out, options = tmp_path / "out", SweepOptions(engine="serial", progress=False, plots=False)
    tune(spec_file, campaign_file, out, "primary_rms_error", "worst", trials=2, options=options)
    storage = JournalStorage(JournalFileBackend(str(out / "optuna.journal")))
    optuna.load_study(study_name="dcts-sweep", storage=storage).ask()  # (the trial a kill left running)
    record = tune(spec_file, campaign_file, out, "primary_rms_error", "worst", trials=4, options=options).report["optimize"]
    assert record["trials"] == 4
    assert len({t["values"]["tool_position.kp"] for t in record["history"]}) == 4, record["history"]
    states = [t.state for t in optuna.load_study(study_name="dcts-sweep", storage=storage).trials]
    assert optuna.trial.TrialState.RUNNING not in states


def test_optimize_tunes_the_varying_components_of_a_reference(tmp_path) -> None:
    """A parameter of several components (a position) with a range or a set per component: each
    varying component is a dimension of the search, the fixed ones stay (it was refused: "give one
    range for all its components")."""
    spec = tmp_path / "reference.yaml"
    spec.write_text(MINIMAL.read_text().replace("name: minimal", "name: sweep_reference").replace(
        "duration: 2.0", "duration: 0.1") + "parameters:\n  tasks: {tool_position: [reference]}\n")
    campaign_file = tmp_path / "campaign.yaml"
    campaign_file.write_text("version: 1\nsamples: 1\nseed: 3\nduration: 0.1\ncontroller:\n  parameters:\n"
                             "    tool_position.position: [0.5, {uniform: [-0.1, 0.1]}, {choice: [0.55, 0.6]}]\n")
    out, options = tmp_path / "out", SweepOptions(engine="serial", progress=False, plots=False)
    record = tune(spec, campaign_file, out, "primary_rms_error", "worst", trials=3, options=options).report["optimize"]
    positions = [t["values"]["tool_position.position"] for t in record["history"]]
    assert len(positions) == 3 and all(p[0] == 0.5 and -0.1 <= p[1] <= 0.1 and p[2] in (0.55, 0.6) for p in positions)
    assert len({p[1] for p in positions}) == 3  # (drawn, not the first value again)
    best = record["best"]["values"]["tool_position.position"]
    [row] = _rows(out).values()  # the campaign's row ran with the best trial's position
    assert [row[f"controller.parameters.tool_position.position[{j}]"] for j in range(3)] == best


def test_an_optimization_refused_leaves_no_folder(spec_file, tmp_path) -> None:
    campaign_file = tmp_path / "campaign.yaml"
    campaign_file.write_text(CAMPAIGN.split("controller:")[0] + "report:" + CAMPAIGN.split("report:")[1])
    result = invoke("sweep", str(spec_file), "--campaign", str(campaign_file), "-o", str(tmp_path / "o"), "--serial",
                    "--optimize", "primary_rms_error")
    assert result.exit_code == 1 and "needs controller values to tune" in result.stderr, result.output
    assert not (tmp_path / "o").exists()


def test_sweep_help_and_an_unknown_optimize_metric(spec_file, campaign_file, tmp_path) -> None:
    help_ = invoke("sweep", "--help")
    assert help_.exit_code == 0 and "<bool>" not in help_.output
    result = invoke("sweep", str(spec_file), "--campaign", str(campaign_file), "-o", str(tmp_path / "o"), "--serial",
                    "--optimize", "primary_rms_eror")
    assert result.exit_code == 2 and "did you mean 'primary_rms_error'" in result.stderr
    assert not (tmp_path / "o").exists()  # refused before anything was written
    result = invoke("sweep", str(tmp_path / "missing.yaml"), "--campaign", str(campaign_file), "-o", str(tmp_path / "o"))
    assert result.exit_code == 1 and str(tmp_path / "missing.yaml") in result.stderr and "Traceback" not in result.output


def test_a_campaign_where_no_sample_ran_exits_1_with_the_first_reason(spec_file, campaign_file, tmp_path,
                                                                      monkeypatch) -> None:
    """Every sample invalid (here: a spec the draws make invalid) printed its report and exited 0."""
    spec_data = SampleRunner.spec_data

    def broken(self, sample):
        data = spec_data(self, sample)
        data["limits"]["joint_torque"]["max"] = -1.0  # no draw does this: refused by the spec's own check
        return data

    monkeypatch.setattr(SampleRunner, "spec_data", broken)
    out = tmp_path / "out"
    result = invoke("sweep", str(spec_file), "--campaign", str(campaign_file), "-o", str(out), "--serial",
                    "--no-plots")
    assert result.exit_code == 1, result.output
    assert "(0 ran, 6 invalid, 0 errors)" in result.stdout
    assert "first invalid sample (0): " in result.stdout and "limits.joint_torque.max" in result.stdout, result.stdout
    assert f"error: no sample ran (6 invalid, 0 errors); each sample's reason is in {out / 'samples.jsonl'}" \
        in result.stderr
    report = json.loads((out / "report.json").read_text())
    assert report["first_not_run"]["invalid"]["index"] == 0
    assert "First invalid sample (0):" in (out / "report.html").read_text()


def test_the_report_gives_each_column_its_unit(serial_run) -> None:
    """The report's plots, metrics and worst cases had no units (a push in N against a violation in
    rad/s read as two bare numbers)."""
    units = serial_run.report["units"]
    swept = {"pushes[0].force.magnitude": "N", "pushes[0].point.z": "m", "pushes[0].start": "s",
             "pushes[0].duration": "s", "payloads[0].mass": "kg", "external_torque.noise_std": "Nm",
             "external_torque.bias.norm": "Nm", "external_torque.bias[6]": "Nm", "initial_state.offset.norm": "deg",
             "initial_state.offset[0]": "deg", "controller.parameters.tool_position.kp": "1/s²"}
    assert {k: units.get(k) for k in swept} == swept
    # the metrics' (the primary task is a position, every joint revolute)
    expected = {"primary_rms_error": "m", "max_torque_violation": "Nm", "max_joint_velocity_violation": "rad/s"}
    assert {k: units[k] for k in expected} == expected
    lines = summary_lines(serial_run.report)
    assert any(line.startswith("  worst primary_rms_error = ") and " m (sample " in line for line in lines), lines
    assert labelled("pushes[0].force.magnitude", units) == "pushes[0].force.magnitude [N]"
    assert labelled("model_mismatch.mass_scale", {"model_mismatch.mass_scale": "1"}) == "model_mismatch.mass_scale"


def test_a_range_wider_than_a_double_is_an_error_at_it() -> None:
    """{uniform: [-1e308, 1e308]} crashed the campaign with an OverflowError (first seen from outside)."""
    text = CAMPAIGN.replace("offset: {uniform: [-3, 3]}", "offset: {uniform: [-1e308, 1e308]}")
    with pytest.raises(SpecError) as caught:
        load_campaign_text(text, "c.yaml")
    assert any(str(d).startswith("c.yaml:") and "is wider than a double can hold" in str(d)
               for d in caught.value.diagnostics), str(caught.value)
