"""The bundle's header reads like a datasheet: units of the references, compiled gains and limits,
sign conventions; the README's integration example compiles against the bundle."""

from __future__ import annotations

from pathlib import Path

from dcts_spec.controller import Controller
from dcts_spec.spec import load_spec
from dcts_spec.validate import validate_spec

# A revolute and a prismatic joint: units differ per joint (rad, m).
SLIDER_URDF = """\
<robot name="slider">
  <link name="base"/>
  <link name="arm"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="hand"><inertial><mass value="0.5"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" velocity="1.5" effort="20"/></joint>
  <joint name="slide" type="prismatic"><parent link="arm"/><child link="hand"/><origin xyz="0.3 0 0"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.4" velocity="0.25" effort="50"/></joint>
</robot>
"""

SLIDER_SPEC = """\
version: 1
name: slider
robot: {urdf: slider.urdf}
tasks:
  - {name: reach, type: pose, frame: hand, axes: [x, rz], priority: 1, gains: {kp: 40, kd: 12},
     reference: {input: true, feedforward: true}}
  - {name: posture, type: joint, priority: 2, gains: {kp: 5, kd: 4}, reference: {input: true, feedforward: true}}
"""


def slider_controller(tmp_path: Path) -> Controller:
    (tmp_path / "slider.urdf").write_text(SLIDER_URDF)
    (tmp_path / "slider.yaml").write_text(SLIDER_SPEC)
    spec = load_spec(tmp_path / "slider.yaml")
    return Controller(spec, validate_spec(spec).robot)


def test_reference_units_are_real_units(tmp_path):
    """Feed-forward velocities and accelerations carry their axes' units (no 'SI/s'); a prismatic
    joint's reference is in m."""
    layout = {(r.task, r.field): r.unit for r in slider_controller(tmp_path).ref_layout}
    assert layout == {
        ("reach", "position"): "m", ("reach", "rpy"): "rad",
        ("reach", "velocity"): "m/s, rad/s", ("reach", "acceleration"): "m/s², rad/s²",
        ("posture", "q"): "rad, m", ("posture", "velocity"): "rad/s, m/s", ("posture", "acceleration"): "rad/s², m/s²",
    }
