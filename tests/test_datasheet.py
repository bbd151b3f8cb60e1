"""The bundle's header reads like a datasheet: units of the references, compiled gains and limits,
sign conventions; the README's integration example compiles against the bundle."""

from __future__ import annotations

import math
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from dcts_spec.codegen import compile_bundle
from dcts_spec.controller import Controller
from dcts_spec.spec import load_spec
from dcts_spec.validate import validate_spec

MINIMAL = Path(__file__).resolve().parents[1] / "specs" / "minimal.yaml"

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


# -- the header of a compiled spec -----------------------------------------------------------------

SHEET_SPEC = """\
version: 1
name: sheet
robot:
  model: iiwa14
  frames:
    table: {parent: base, xyz: [0, 0, 0.2]}
limits:
  joint_position: {min: [-165, -115, -165, -115, -165, -115, -170], max: [165, 115, 165, 115, 165, 115, 170], unit: deg}
  joint_velocity: {max: [100, 110, 100, 130, 130, 180, 180], unit: deg/s}
  joint_acceleration: {max: 1000, unit: deg/s^2}
  joint_torque: {max: [100, 100, 80, 80, 60, 40, 40]}
  cartesian:
    - {frame: tool, axis: z, min: 0.1}
    - {frame: tool, normal: [0, 0, 2], expressed_in: table, min: -0.15, max: 1.3, max_velocity: 0.5, max_acceleration: 4}
tasks:
  - {name: reach, type: pose, frame: tool, axes: [x, y, z, rz], priority: 1,
     gains: {kp: [100, 100, 120, 30], kd: 20, max_velocity: 0.3}, reference: {input: true, feedforward: true}}
  - {name: point, type: orientation, frame: tool, axes: [rx, ry], priority: 2, gains: {kp: 50, kd: [14, 15]},
     reference: {rpy: [180, 0, 0], unit: deg}}
  - {name: posture, type: joint, priority: 3, gains: {kp: 10, kd: 6}, reference: {q: [0, 0.5, 0, -1, 0, 1, 0]}}
"""
JOINTS = [f"joint{k}" for k in range(1, 8)]
# What the spec above says, in SI, written out here (not taken from the compiler).
EXPECTED_GAINS = {  # task: (kp per axis, kd per axis, max_velocity text)
    "reach": ([100, 100, 120, 30], [20] * 4, "0.3 (the norm of (kp/kd) dx over axes in m/s and rad/s)"),
    "point": ([50, 50], [14, 15], "none"),
    "posture": ([10] * 7, [6] * 7, "none"),
}
EXPECTED_JOINTS = {  # joint: (q min, q max, |dq| max, |ddq| max, |tau| max)
    name: (-math.radians(p), math.radians(p), math.radians(v), math.radians(1000), t)
    for name, p, v, t in zip(JOINTS, [165, 115, 165, 115, 165, 115, 170], [100, 110, 100, 130, 130, 180, 180],
                             [100, 100, 80, 80, 60, 40, 40])
}
JOINT_UNITS = ("rad", "rad", "rad/s", "rad/s²", "Nm")


@pytest.fixture(scope="module")
def sheet(tmp_path_factory) -> tuple[Path, str]:
    """The spec above compiled without building: (bundle directory, header text)."""
    folder = tmp_path_factory.mktemp("sheet")
    (folder / "sheet.yaml").write_text(SHEET_SPEC)
    compile_bundle(folder / "sheet.yaml", folder / "bundle", build=False)
    return folder / "bundle", (folder / "bundle" / "sheet.h").read_text()


def parse_values(text: str) -> list[float]:
    """"100" or "[50, 60]" as floats."""
    return [float(v) for v in text.strip("[]").split(",")]


def test_header_lists_every_task_gain_with_units(sheet):
    _, header = sheet
    blocks = re.findall(r"^ \*   (\w+): priority (\d+), .*\n \*     kp = (\S+|\[[^\]]*\]) 1/s², kd = (\S+|\[[^\]]*\]) 1/s, "
                        r"max_velocity = (.*)\n \*     reference: (.*)$", header, re.M)
    assert [b[0] for b in blocks] == list(EXPECTED_GAINS)
    for name, priority, kp, kd, saturation, _ in blocks:
        want_kp, want_kd, want_saturation = EXPECTED_GAINS[name]
        for got, want in ((parse_values(kp), want_kp), (parse_values(kd), want_kd)):
            assert np.allclose(np.broadcast_to(got, len(want)), want), (name, got, want)
        assert saturation == want_saturation
    references = {b[0]: b[5] for b in blocks}
    assert references["reach"] == "run time, ref[0..13], with velocity and acceleration feed-forward"
    assert references["point"] == "compiled, rpy = [3.14159, 0, 0] rad (world)"
    assert references["posture"] == "compiled, q = [0, 0.5, 0, -1, 0, 1, 0] rad"


def test_header_lists_every_joint_limit_with_units(sheet):
    _, header = sheet
    rows = {}
    for line in header.splitlines():
        cells = re.fullmatch(r" \*   (joint\d)\s+" + r"\s+".join([r"(-?[\d.e+-]+) (\S+)"] * 5), line)
        if cells:
            rows[cells.group(1)] = cells.groups()[1:]
    assert list(rows) == JOINTS
    for name, cells in rows.items():
        values, units = [float(v) for v in cells[::2]], cells[1::2]
        assert units == JOINT_UNITS, name
        assert np.allclose(values, EXPECTED_JOINTS[name], rtol=1e-5), (name, values)
    # what |ddq| max does not bound (limits/viability.py): the way back after a push
    assert " *   |ddq| max bounds the command; a joint beyond its compiled position or velocity limit" in header


def test_header_lists_cartesian_bounds_with_frame_direction_and_offsets(sheet):
    _, header = sheet
    bounds = re.findall(r"^ \*   (\S+): frame (\w+), d = \[([^\]]*)\].*\n \*     (.*)$", header, re.M)
    assert [(b[0], b[1]) for b in bounds] == [("tool.z", "tool"), ("tool.plane1", "tool")]
    assert np.allclose(parse_values(bounds[0][2]), [0, 0, 1]) and np.allclose(parse_values(bounds[1][2]), [0, 0, 1])
    assert bounds[0][3] == "0.1 m ≤ d.p; speed: no limit; braking at 5 m/s²"
    # the plane given in `table` (0.2 m above the world's origin): its offsets in the world
    assert bounds[1][3] == "0.05 m ≤ d.p ≤ 1.5 m; |d.v| ≤ 0.5 m/s; braking at 4 m/s²"
    assert "normal [0, 0, 2] in frame table" in header


def test_an_axis_given_in_a_frame_is_that_frames_axis(tmp_path):
    """`axis: z, expressed_in: table` ignored the frame (the bound held z ≥ 0.1 in the world, not
    above the table), and the header's note on it crashed `dcts compile` (exit 3)."""
    text = SHEET_SPEC.replace("    - {frame: tool, axis: z, min: 0.1}\n", "    - {frame: tool, axis: z, expressed_in: table, min: 0.1}\n")
    (tmp_path / "sheet.yaml").write_text(text)
    robot = validate_spec(load_spec(tmp_path / "sheet.yaml")).robot
    assert robot.cartesian_bounds[0].label == "z" and robot.cartesian_bounds[0].c_min == pytest.approx(0.3)
    compile_bundle(tmp_path / "sheet.yaml", tmp_path / "bundle", build=False)
    header = (tmp_path / "bundle" / "sheet.h").read_text()
    assert "0.3 m ≤ d.p; speed: no limit" in header and "axis z in frame table" in header


def test_header_reference_layout_has_real_units(sheet):
    _, header = sheet
    layout = dict(re.findall(r"^ \*   (ref\[[\d.]+\])\s+task reach, (.*)$", header, re.M))
    assert layout == {
        "ref[0..2]": "position (m): x, y, z",
        "ref[3..5]": "rpy (rad): roll, pitch, yaw",
        "ref[6..9]": "velocity (m/s: reach.x, reach.y, reach.z; rad/s: reach.rz)",
        "ref[10..13]": "acceleration (m/s²: reach.x, reach.y, reach.z; rad/s²: reach.rz)",
    }
    assert "SI/s" not in header


def test_header_states_units_signs_and_timing(sheet):
    _, header = sheet
    assert re.search(r"tau\[7\]\s+output: joint torques to apply \(Nm, gravity included\)", header)
    assert re.search(r"within \|tau\| <= tau_max = \[100, 100, 80, 80, 60, 40, 40\] Nm$", header, re.M)
    assert re.search(r"q\[7\]\s+joint positions \(rad\)", header) and re.search(r"dq\[7\]\s+joint velocities \(rad/s\)", header)
    assert "the torque the environment applies on the joints" in header
    assert "M(q) ddq + nu(q, dq) + g(q) = tau + tau_ext" in header
    assert "`dcts bench sheet.yaml` (or spec.yaml, its copy in" in header
    assert re.search(r"Sizes +NQ 7, NREF 14, NX \d+, NA \d+, NLEVELS 3, NR \d+, NP \d+; workspace \d+ bytes", header)


def test_tau_ext_sign_is_the_headers(tmp_path):
    """M ddq + nu + g = tau + tau_ext: with the accelerations unchanged (osc: no limits, the same
    task accelerations), a measured tau_ext the environment applies is taken off the torque."""
    (tmp_path / "sheet.yaml").write_text(SHEET_SPEC.replace("limits:", "controller: {formulation: osc}\nlimits:", 1))
    spec = load_spec(tmp_path / "sheet.yaml")
    controller = Controller(spec, validate_spec(spec).robot)
    q, dq = np.array([0.1, 0.5, -0.2, -1.2, 0.3, 0.9, 0.1]), np.full(7, 0.05)
    ref, tau_ext = np.concatenate([[0.5, 0.0, 0.6, 0, 0, 0], np.zeros(8)]), np.array([3.0, -2.0, 1.0, 0.5, -0.5, 0.2, 0.1])
    free, pushed = controller.step(q, dq, np.zeros(7), ref), controller.step(q, dq, tau_ext, ref)
    np.testing.assert_allclose(pushed.tau - free.tau, -tau_ext, atol=1e-9)


# -- the README's integration example --------------------------------------------------------------


def integration_example(readme: str) -> str:
    return re.search(r"## Integration\n.*?```c\n(.*?)```", readme, re.S).group(1)


@pytest.mark.parametrize("formulation", ["dcts", "osc"])
def test_readme_integration_example_compiles(sheet, tmp_path, formulation):
    """The README's loop compiles against the bundle's header (a QP spec with references, and a closed
    form); the platform functions it declares are the integrator's."""
    if formulation == "dcts":
        bundle = sheet[0]
    else:
        (tmp_path / "minimal.yaml").write_text(MINIMAL.read_text())
        bundle = tmp_path / "bundle"
        compile_bundle(tmp_path / "minimal.yaml", bundle, formulation=formulation, build=False)
    example = integration_example((bundle / "README.md").read_text())
    assert 15 <= len(example.strip().splitlines()) <= 35
    source = tmp_path / "example.c"
    source.write_text(example)
    compiler = shutil.which("gcc") or shutil.which("cc")
    done = subprocess.run([compiler, "-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Werror", "-fsyntax-only",
                           f"-I{bundle}", str(source)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_a_closed_forms_header_does_not_promise_the_bounds(sheet, tmp_path):
    """osc has no joint or Cartesian bound rows and clips its torque: its header said status 0
    meant every bound held (status 0 came with a joint 0.5 rad beyond its limit) and that ddq was
    the acceleration of the applied torque (it is that of the torque before the clip)."""
    (tmp_path / "minimal.yaml").write_text(MINIMAL.read_text())
    compile_bundle(tmp_path / "minimal.yaml", tmp_path / "osc", formulation="osc", build=False)
    closed = (tmp_path / "osc" / "minimal.h").read_text()
    assert "no joint or Cartesian bound rows: those limits are neither" in " ".join(closed.split())
    assert "joint/Cartesian bound holds" not in closed
    assert "M^-1 (tau - nu - g) before the torque clip" in closed
    header = sheet[1]  # (a dcts QP with bounds: as before)
    assert "every torque limit and joint/Cartesian bound holds" in header and "before the torque clip" not in header


def test_prismatic_joint_in_m_and_n(tmp_path):
    """A prismatic joint's row, inputs and references are in m, m/s and N, a revolute one's in rad."""
    slider_controller(tmp_path)  # writes the URDF and the spec
    compile_bundle(tmp_path / "slider.yaml", tmp_path / "bundle", build=False)
    header = (tmp_path / "bundle" / "slider.h").read_text()
    assert re.search(r"^ \*   shoulder\s+-2 rad\s+2 rad\s+1\.5 rad/s\s+none\s+20 Nm$", header, re.M)
    assert re.search(r"^ \*   slide\s+0 m\s+0\.4 m\s+0\.25 m/s\s+none\s+50 N$", header, re.M)
    assert re.search(r"q\[2\]\s+joint positions \(rad, m for a prismatic joint\)", header)
    assert re.search(r"task posture, velocity \(rad/s: posture\.shoulder; m/s: posture\.slide\)", header)
    assert re.search(r"within \|tau\| <= tau_max = \[20, 50\] \(Nm, N for a prismatic joint\)", header)


def test_header_lists_the_locked_joints_the_firmware_holds(sheet, tmp_path):
    """A locked joint is not in q: the header says which, and where the model has them (a Baxter
    bundle's head and fingers appeared only in its spec.yaml). None for a robot with none."""
    spec = tmp_path / "locked.yaml"
    spec.write_text("version: 1\nname: locked\nrobot:\n  model: iiwa14\n  locked_joints: {joint7: 0.3, joint5: -0.2}\n"
                    "tasks:\n  - {name: reach, type: position, frame: tool, priority: 1, gains: {kp: 10, kd: 6}, "
                    "reference: {position: [0.5, 0, 0.5]}}\n")
    compile_bundle(spec, tmp_path / "bundle", build=False)
    header = re.sub(r"\n \* +", " ", (tmp_path / "bundle" / "locked.h").read_text())  # (wrapped lines joined)
    assert re.search(r"Locked +not in q: hold them there yourself .*: joint7 at 0\.3, joint5 at -0\.2\.", header)
    assert "Locked " not in sheet[1]


@pytest.mark.parametrize(("ramp_time", "words"), [
    (0.0025, "over 3 step(s) (0.003 s; ramp_time 0.0025 s in whole periods)"),
    (0.004, "over 4 step(s) (0.004 s)"),
])
def test_the_ramp_is_stated_in_the_steps_it_takes(tmp_path, ramp_time, words):
    """A ramp_time of 2.5 periods takes 3 steps: the header gave 0.0025 s for them."""
    from dcts_spec.codegen.datasheet import parameters_doc_text

    text = MINIMAL.read_text() + f"parameters: {{ramp_time: {ramp_time}, tasks: {{tool_position: [kp]}}}}\n"
    (tmp_path / "ramp.yaml").write_text(text)
    spec = load_spec(tmp_path / "ramp.yaml")
    doc = " ".join(parameters_doc_text(Controller(spec, validate_spec(spec).robot), "ramp").replace("*", " ").split())
    assert words in doc


LOOP_PLATFORM = r"""
/* A platform for the README's loop: an invalid reading, a valid one, five invalid ones, then the
 * robot is stopped; every torque written is printed. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
static int reads = 0;
int read_joints(double q[], double dq[], double tau_ext[])
{
    static const double start[7] = {0, 0.5236, 0, -1.0472, 0, 1.0472, 0};
    int i;
    for (i = 0; i < 7; ++i) { q[i] = start[i]; dq[i] = 0.0; tau_ext[i] = 0.0; }
    ++reads;
    return reads == 2 ? 0 : 1;
}
void read_references(double ref[]) { (void)ref; }
void write_torques(const double tau[]) { printf("%.6f\n", tau[1]); if (reads > 8) exit(0); }
void wait_for_period(void) {}
void stop_robot(const char *why) { printf("stop %s\n", why); exit(0); }
void control_loop(void);
int main(void) { control_loop(); return 0; }
"""


def test_readme_integration_loop_steps_on_its_first_valid_reading(tmp_path):
    """The loop waited for a valid reading and then stepped only on the next one: if that one
    failed, the fallback had no finite q and wrote 0 Nm with the brakes off (found from outside).
    Now every torque written holds the arm against gravity (joint 2: ~-52 Nm at this q)."""
    (tmp_path / "minimal.yaml").write_text(MINIMAL.read_text())
    bundle = tmp_path / "bundle"
    compile_bundle(tmp_path / "minimal.yaml", bundle, build=False)
    (tmp_path / "loop.c").write_text(integration_example((bundle / "README.md").read_text()))
    (tmp_path / "platform.c").write_text(LOOP_PLATFORM)
    compiler = shutil.which("gcc") or shutil.which("cc")
    sources = [str(tmp_path / "loop.c"), str(tmp_path / "platform.c"), str(bundle / "minimal.c"),
               str(bundle / "minimal_casadi.c"), *map(str, sorted((bundle / "daqp" / "src").glob("*.c")))]
    # (-O0: the loop's few steps need no speed, and -O1 took 12-16 s of this test)
    done = subprocess.run([compiler, "-std=gnu99", "-O0", "-w", f"-I{bundle}", f"-I{bundle / 'daqp' / 'include'}",
                           *sources, "-lm", "-o", str(tmp_path / "loop")], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    written = subprocess.run([str(tmp_path / "loop")], capture_output=True, text=True, timeout=60).stdout.split()
    torques = [float(t) for t in written if not t.startswith("stop")]
    assert len(torques) >= 6 and all(t < -40.0 for t in torques), written
