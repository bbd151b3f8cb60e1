"""A scenario schedules run-time parameter changes: validated where they are written, given to the
runtime at their time, ramped, and logged as applied."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from dcts_spec.analysis.run import analyze
from dcts_spec.sim.runner import prepare_simulation
from dcts_spec.spec import SpecError, load_spec_text
from dcts_spec.validate import validate_spec

from test_parameters import SPEC


def _spec(changes: list[dict], ramp_time: float | None = None, formulation: str = "osc"):
    data = yaml.safe_load(yaml.safe_dump(SPEC))
    data["controller"] = {"formulation": formulation}
    data["parameters"] = {"tasks": {"tool": ["kp", "activation"]}, "limits": ["joint_torque"]}
    if ramp_time is not None:
        data["parameters"]["ramp_time"] = ramp_time
    data["scenario"].update(duration=0.12, parameters=changes)
    return load_spec_text(yaml.safe_dump(data), "schedule.yaml")


@pytest.mark.parametrize(("values", "words"), [
    ({"tool.stiffness": 1}, "no such run-time parameter"),
    ({"joint_torque.max": 500}, "compiled envelope"),
    ({"tool.activation": -0.5}, "outside [0, 1]"),
])
def test_a_bad_change_is_refused_where_it_is_written(values, words):
    with pytest.raises(SpecError) as info:
        validate_spec(_spec([{"time": 0.02, "values": {"tool.kp": 50}}, {"time": 0.05, "values": values}]))
    text = str(info.value)
    assert "schedule.yaml:" in text and "scenario.parameters[1].values" in text and words in text


def _largest_jump_after(ramp_time: float) -> tuple[float, np.ndarray]:
    simulation = prepare_simulation(_spec([{"time": 0.05, "values": {"tool.activation": 0}}], ramp_time))
    log = simulation.run()
    k = int(round(0.05 / log.period))
    return float(np.abs(np.diff(log.tau[k - 1: k + 12], axis=0)).max()), log.param


def test_a_scheduled_mode_switch_is_ramped_and_logged():
    immediate, _ = _largest_jump_after(0.0)
    ramped, param = _largest_jump_after(0.005)
    assert immediate > 5.0  # switching the task off at once kicks the torque
    assert ramped < 0.5 * immediate
    activation = param[:, 3]  # tool.kp (3 values), then tool.activation
    np.testing.assert_allclose(activation[49:56], [1, 0.8, 0.6, 0.4, 0.2, 0, 0], atol=1e-12)


def test_the_summary_and_plots_hold_a_run_to_the_limits_in_force():
    """Limits narrowed at run time are what the metrics measure against: a joint braking down to a
    lowered velocity limit, and a tool below a raised Cartesian minimum, are beyond them."""
    data = yaml.safe_load(yaml.safe_dump(SPEC))
    data["controller"] = {"formulation": "dcts"}
    data["parameters"] = {"ramp_time": 0.002, "limits": ["joint_velocity", "cartesian"]}
    data["scenario"].update(duration=0.2, parameters=[
        {"time": 0.08, "values": {"joint_velocity.max": 0.05, "cartesian.tool.z.min": 0.7}}])
    simulation = prepare_simulation(load_spec_text(yaml.safe_dump(data), "narrowed.yaml"))
    log = simulation.run()
    run = analyze(simulation, log)
    layout = simulation.param_layout
    v_max = log.param[:, layout.entry("joint_velocity.max").slice]
    z_min = log.param[:, layout.entry("cartesian.tool.z.min").slice][:, 0]
    velocity_excess = np.maximum(np.abs(log.dq) - v_max, 0.0).max()
    z = run.series.frame_positions["tool"][:, 2]
    summary = run.summary
    assert np.abs(log.dq[79]).max() > 0.1  # (the premise: the arm moves faster than the lowered limit)
    assert z[79] < 0.7  # (and the tool is below the raised minimum)
    assert summary["max_joint_velocity_violation"] == pytest.approx(velocity_excess, rel=1e-12)
    assert summary["max_joint_velocity_violation"] > 0.05
    assert summary["max_cartesian_violation"] == pytest.approx(np.maximum(z_min - z, 0.0).max(), rel=1e-12)
    assert summary["max_cartesian_violation"] > 0.01
    texts = [b["bound"] for b in summary["relaxed_bounds"].values()]
    assert any("narrowed at run time in those steps: max velocity 0.05" in t for t in texts), texts
    assert any("narrowed at run time in those steps: min 0.7 m" in t for t in texts), texts
    # (the plots shade the same limits, step by step)
    assert np.array_equal(run.series.limits.joint.v_max, v_max)
