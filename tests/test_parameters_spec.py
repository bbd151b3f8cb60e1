"""The spec's `parameters` section: what may be named, and the located errors when it is wrong."""

from __future__ import annotations

import pytest

from dcts_spec.spec import SpecError, load_spec_text
from dcts_spec.validate import validate_spec

BASE = """\
version: 1
name: p
robot: {model: iiwa14}
limits:
  joint_torque: {max: 100}
tasks:
  - {name: tool, type: position, frame: tool, priority: 1, gains: {kp: 100, kd: 20}, reference: {position: [0.5, 0, 0.6]}}
  - {name: follow, type: position, frame: link5, priority: 1, gains: {kp: 10, kd: 5}, reference: {input: true}}
  - {name: posture, type: joint, priority: 2, gains: {kp: 10, kd: 5}, reference: {q: [0, 0.5, 0, -1, 0, 1, 0]}}
"""


def _errors(parameters: str) -> list[str]:
    with pytest.raises(SpecError) as info:
        validate_spec(load_spec_text(BASE + parameters, "p.yaml"))
    return [str(d) for d in info.value.diagnostics]


def test_a_valid_section_validates_and_keeps_the_ramp_default():
    spec = load_spec_text(BASE + "parameters:\n  tasks: {tool: [activation, kp, reference]}\n  limits: [joint_torque]\n", "p.yaml")
    validate_spec(spec)
    assert spec.parameters.task_fields("tool") == ("kp", "reference", "activation")  # vector order
    assert spec.parameters.ramp(0.001) == pytest.approx(0.005)
    assert spec.parameters.limit_groups() == ("joint_torque",)


@pytest.mark.parametrize(("ramp_time", "warned"), [(0.0001, True), (0.0009, True), (0.001, True), (0.0, False),
                                                   (0.0011, False), (0.005, False)])
def test_a_ramp_shorter_than_a_period_is_a_warning(ramp_time, warned):
    """A ramp_time of at most one period takes a new set at once (one step), as 0 does, but reads as
    a ramp: a gain change then stepped the torque by 100 Nm at 250 Hz (found from outside). 0 is the
    way to ask for no ramp, and is not warned about."""
    spec = load_spec_text(BASE + f"parameters:\n  ramp_time: {ramp_time}\n  tasks: {{tool: [kp]}}\n", "p.yaml")
    warnings = [str(d) for d in validate_spec(spec).diagnostics if d.severity == "warning" and "ramp" in str(d)]
    assert bool(warnings) == warned, warnings
    assert all("p.yaml:11:" in w and "at most one control period" in w for w in warnings)


@pytest.mark.parametrize(("parameters", "line", "words"), [
    ("parameters:\n  tasks: {tool: [stiffness]}\n", 11, "'stiffness' is not allowed"),
    ("parameters:\n  tasks: {tol: [kp]}\n", 11, "did you mean 'tool'"),
    ("parameters:\n  tasks: {tool: [max_velocity]}\n", 11, "no gains.max_velocity"),
    ("parameters:\n  tasks: {follow: [reference]}\n", 11, "already a run-time input"),
    ("parameters:\n  tasks: {tool: [kp, kp]}\n", 11, "named twice"),
    ("parameters:\n  limits: [joint_acceleration]\n", 11, "no joint acceleration limit"),
    ("parameters:\n  limits: [cartesian]\n", 11, "no cartesian limit"),
    ("parameters:\n  ramp_time: -1\n", 11, "≥ 0"),
])
def test_a_wrong_section_is_refused_with_its_line(parameters, line, words):
    errors = _errors(parameters)
    assert any(f"p.yaml:{line}:" in e and words in e for e in errors), errors
