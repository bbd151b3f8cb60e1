"""`dcts validate` on the specs of the repository, its JSON output, and the warnings it gives."""

from __future__ import annotations

import difflib
import json
import math
import re
from pathlib import Path

import pytest

from command_line import ROOT, dcts
from dcts_spec.robot.builtin import example_robot_data_dir, iiwa14_urdf_path
from dcts_spec.robot.describe import describe
from dcts_spec.robot.resolve import LISTED_FRAMES
from dcts_spec.spec import SpecError
from dcts_spec.validate import validate_file

# every spec file (campaign files are not specs: tests/test_sweep.py loads them)
SPECS = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "specs").glob("**/*.yaml") if "campaigns" not in p.parts)


@pytest.fixture(scope="module")
def specs_json() -> dict[str, dict]:
    """`dcts validate --json` over every spec of `specs/`, in one run: file -> report."""
    result = dcts("validate", "--json", *SPECS)
    assert "Traceback" not in result.stdout + result.stderr, result.stderr
    assert result.returncode == 0, result.stdout + result.stderr
    return {r["file"]: r for r in json.loads(result.stdout)}


def test_there_are_specs() -> None:
    assert "specs/minimal.yaml" in SPECS


def test_every_spec_is_valid(specs_json: dict[str, dict]) -> None:
    assert sorted(specs_json) == SPECS
    invalid = {f: r["diagnostics"] for f, r in specs_json.items() if r["valid"] is not True}
    assert not invalid


def test_every_spec_validates_with_the_human_output() -> None:
    result = dcts("validate", *SPECS)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stdout + result.stderr
    for spec in SPECS:
        assert f"{spec}: ok" in result.stdout


def test_minimal_json(specs_json: dict[str, dict]) -> None:
    report = specs_json["specs/minimal.yaml"]
    assert report["valid"] is True and report["name"] == "minimal"
    assert report["robot"]["name"] == "iiwa14" and report["robot"]["dof"] == 7
    assert report["formulation"] == "dcts"
    levels = [
        (lv["priority"], lv["dimension"], lv["rank"], lv["free_before"], [(t["name"], t["type"], t["dimension"]) for t in lv["tasks"]])
        for lv in report["levels"]
    ]
    assert levels == [
        (1, 3, 3, 7, [("tool_position", "position", 3)]),
        (2, 7, 4, 4, [("damping", "joint", 7)]),
    ]
    assert report["limits"]["tau_max"] == [100.0] * 7
    assert not [d for d in report["diagnostics"] if d["severity"] == "error"]


WIDENED = """\
version: 1
name: widened
robot:
  model: iiwa14
limits:
  joint_position:
    min: -175
    max: 175
    unit: deg
    allow_outside_urdf: true
tasks:
  - name: tool_position
    type: position
    frame: tool
    priority: 1
    gains: {kp: 100, kd: 20}
    reference: {position: [0.5, 0.0, 0.6]}
scenario:
  duration: 1.0
  initial_q: [0, 30, 0, -60, 0, 60, 0]
  unit: deg
"""

# No initial_q: the arm starts in the middle of its joint range, straight up, where the tool cannot move up.
SINGULAR = """\
version: 1
name: singular
robot:
  model: iiwa14
tasks:
  - name: tool_position
    type: position
    frame: tool
    priority: 1
    gains: {kp: 100, kd: 20}
    reference: {position: [0.5, 0.0, 0.6]}
"""


@pytest.fixture()
def warning_specs(tmp_path: Path) -> tuple[Path, Path]:
    widened, singular = tmp_path / "widened.yaml", tmp_path / "singular.yaml"
    widened.write_text(WIDENED, encoding="utf-8")
    singular.write_text(SINGULAR, encoding="utf-8")
    return widened, singular


def _warnings(path: Path) -> list[tuple[int | None, str]]:
    report = validate_file(path)
    assert not [d for d in report.diagnostics if d.severity == "error"]
    return [(d.line, d.message) for d in report.diagnostics if d.severity == "warning"]


def test_limit_widened_on_purpose_is_a_warning(warning_specs: tuple[Path, Path]) -> None:
    warnings = _warnings(warning_specs[0])
    assert any(line == 7 and "below the URDF's lower limit" in m and "allow_outside_urdf" in m for line, m in warnings)
    assert any(line == 8 and "above the URDF's upper limit" in m for line, m in warnings)
    report = validate_file(warning_specs[0])
    assert report.robot.limits.q_max[0] == pytest.approx(math.radians(175))


def test_singular_task_at_initial_configuration_is_a_warning(warning_specs: tuple[Path, Path]) -> None:
    warnings = _warnings(warning_specs[1])
    assert any(line == 6 and "'tool_position' is singular at the initial configuration" in m for line, m in warnings)


def test_a_lowest_priority_left_no_freedom_is_a_warning(tmp_path: Path) -> None:
    """A posture over every joint at priority 1 leaves a lower tool task nothing: it would be
    compiled and have no effect. A warning at that priority; none where freedom is left."""
    spec = tmp_path / "no_freedom.yaml"
    tasks = ("  - {name: posture, type: joint, priority: 1, gains: {kp: 10, kd: 6}, reference: {q: [0, 0, 0, 0, 0, 0, 0]}}\n"
             "  - {name: reach, type: position, frame: tool, priority: 2, gains: {kp: 10, kd: 6}, "
             "reference: {position: [0.4, 0.1, 0.4]}}\n")
    spec.write_text(f"version: 1\nname: no_freedom\nrobot: {{model: iiwa14}}\ntasks:\n{tasks}", encoding="utf-8")
    assert any(line == 6 and "priority 2 gets no freedom" in m and "all 7" in m for line, m in _warnings(spec))
    swapped = tasks.replace("priority: 1", "priority: 3").replace("priority: 2", "priority: 1")
    spec.write_text(f"version: 1\nname: no_freedom\nrobot: {{model: iiwa14}}\ntasks:\n{swapped}", encoding="utf-8")
    assert not any("gets no freedom" in m for _, m in _warnings(spec))


@pytest.mark.parametrize(("period", "kp", "kd", "expected"), [
    (0.004, 100000, 632, "kd × controller.period = 632 × 0.004 s = 2.53 ≥ 2"),  # critically damped, too fast for 250 Hz
    (0.001, 100, 2100, "= 2.1 ≥ 2"),
    (0.004, 100000, 100, "kd = 100 1/s is at most kp × controller.period / 2 = 200"),
    (0.004, [100, 100000, 100], [20, 100, 20], "kd = 100 1/s is at most"),  # one axis
    (0.001, 100000, 632, None),  # the same gains at 1 kHz: stable
    (0.004, 10000, 200, None),
    (0.001, 100, 0, "(undamped)"),  # kd = 0 with kp > 0: held over T the oscillation grows, slowly
    (0.001, 0, 0, None),  # nothing asked for
])
def test_gains_unstable_at_the_period_are_a_warning(tmp_path: Path, period, kp, kd, expected) -> None:
    """Each level gets its commanded acceleration exactly, so a task axis is a double integrator held
    over the period: its PD is stable only for kp T/2 < kd < 2/T. Outside, validate warns at the
    task's kd (a critically damped kp 1e5 at 250 Hz validated, then swung its torques between the
    limits at every period in simulation; found from outside)."""
    spec = tmp_path / "gains.yaml"
    spec.write_text(f"version: 1\nname: gains\nrobot: {{model: iiwa14}}\ncontroller: {{period: {period}}}\ntasks:\n"
                    f"  - {{name: reach, type: position, frame: tool, priority: 1, gains: {{kp: {kp}, kd: {kd}}},\n"
                    f"     reference: {{position: [0.5, 0.0, 0.6]}}}}\n", encoding="utf-8")
    found = [(line, m) for line, m in _warnings(spec) if "controller.period" in m]
    if expected is None:
        assert not found
    else:
        assert len(found) == 1 and found[0][0] == 6 and expected in found[0][1], found


def test_max_velocity_needs_damping_only_where_there_is_stiffness(tmp_path: Path) -> None:
    """With max_velocity, an axis with kp > 0 and kd = 0 asks for nothing (the saturated law is
    kd (v (kp/kd)Δx − ẋ)): an error at its kd (tests/broken_specs). An axis with neither asks for
    nothing either way and stays valid, as it was."""
    spec = tmp_path / "mv.yaml"
    spec.write_text("version: 1\nname: mv\nrobot: {model: iiwa14}\ntasks:\n"
                    "  - {name: tool_position, type: position, frame: tool, priority: 1, gains: {kp: [100, 100, 0], "
                    "kd: [20, 20, 0], max_velocity: 0.5}, reference: {position: [0.5, 0.0, 0.6]}}\n", encoding="utf-8")
    validate_file(spec)
    spec.write_text(spec.read_text().replace("kp: [100, 100, 0]", "kp: [100, 100, 1]"))
    assert any("max_velocity needs kd > 0 where kp > 0" in m for m in _errors(spec).values())


def test_warnings_through_the_cli(warning_specs: tuple[Path, Path]) -> None:
    widened, singular = warning_specs
    result = dcts("validate", str(widened), str(singular))
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stdout + result.stderr
    assert f"{widened}:7:5: warning:" in result.stdout
    assert f"{singular}:6:5: warning:" in result.stdout
    result = dcts("validate", "--json", str(singular))
    assert result.returncode == 0
    [report] = json.loads(result.stdout)  # a list, even for one file
    assert report["valid"] is True
    assert 6 in [d["line"] for d in report["diagnostics"] if d["severity"] == "warning"]


def test_any_urdf_by_path(tmp_path: Path) -> None:
    """A URDF given by a path relative to the spec file, and one by an absolute path (UR5)."""
    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "arm.urdf").write_text(iiwa14_urdf_path().read_text())
    ur5 = example_robot_data_dir() / "ur_description" / "urdf" / "ur5_robot.urdf"
    for urdf, frame, n in (("robots/arm.urdf", "tool", 7), (str(ur5), "tool0", 6)):
        spec = tmp_path / "spec.yaml"
        spec.write_text(
            "version: 1\nname: by_path\n"
            f"robot: {{urdf: {urdf}}}\n"
            "tasks:\n"
            f"  - {{name: reach, type: position, frame: {frame}, priority: 1, gains: {{kp: 10, kd: 6}}, "
            "reference: {position: [0.4, 0.1, 0.4]}}\n"
        )
        report = validate_file(spec)
        assert report.robot.nv == n
        assert report.levels[0].dimension == 3


def _errors(path: Path) -> dict[int | None, str]:
    with pytest.raises(SpecError) as caught:
        validate_file(path)
    return {d.line: d.message for d in caught.value.errors}


def _similarity(a: str, b: str) -> float:
    return difflib.SequenceMatcher(None, a, b).ratio()


@pytest.mark.parametrize("section, name, line", [
    ("limits:\n  cartesian:\n    - {frame: FRAME, axis: z, min: 0.05}\n", "lnk7", 6),
    ("", "gripper", 5),
], ids=["cartesian_bound", "task"])
def test_unknown_frame_lists_the_closest_frames_and_where_to_see_all(tmp_path: Path, section: str, name: str,
                                                                      line: int) -> None:
    """iiwa14 has 17 frames: an unknown frame's message names the closest few, nearest first,
    and the command that lists them all."""
    spec = tmp_path / "frames.yaml"
    task_frame = "tool" if section else name
    spec.write_text("version: 1\nname: frames\nrobot: {model: iiwa14}\n" + section.replace("FRAME", name)
                    + f"tasks:\n  - {{name: reach, type: position, frame: {task_frame}, priority: 1, "
                    "gains: {kp: 10, kd: 6}, reference: {position: [0.5, 0, 0.6]}}\n")
    message = _errors(spec)[line]
    frames = [f.name for f in describe("iiwa14").frames]
    assert message.startswith(f"no frame {name!r}")
    assert message.endswith("(`dcts describe iiwa14` lists them all)")
    listed = message.split(f"closest of its {len(frames)} frames: ")[1].split(" (")[0].split(", ")
    assert len(listed) == LISTED_FRAMES and set(listed) <= set(frames)
    scores = [_similarity(name, f) for f in listed]
    assert scores == sorted(scores, reverse=True)  # nearest first
    assert min(scores) >= max(_similarity(name, f) for f in frames if f not in listed)  # the closest, not any


def test_unknown_joint_lists_every_joint(tmp_path: Path) -> None:
    spec = tmp_path / "joints.yaml"
    spec.write_text("version: 1\nname: joints\nrobot: {model: iiwa14}\ntasks:\n"
                    "  - {name: hold, type: joint, joints: [joint9], priority: 1, gains: {kp: 0, kd: 6}}\n")
    assert _errors(spec)[5].endswith("; joints: joint1, joint2, joint3, joint4, joint5, joint6, joint7")


SMALL_URDF = """\
<robot name="small">
  <link name="base"/>
  <link name="arm"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" velocity="1" effort="10"/></joint>
</robot>
"""


def test_unknown_frame_of_a_small_robot_lists_them_all(tmp_path: Path) -> None:
    (tmp_path / "small.urdf").write_text(SMALL_URDF)
    spec = tmp_path / "small.yaml"
    for bound_frame, task_frame, line, wording in (("hand", "arm", 6, "no frame 'hand'"),
                                                    ("arm", "hand", 8, "no frame 'hand' in the robot")):
        spec.write_text(
            "version: 1\nname: small\nrobot: {urdf: small.urdf}\n"
            f"limits:\n  cartesian:\n    - {{frame: {bound_frame}, axis: z, min: -1}}\n"
            f"tasks:\n  - {{name: reach, type: position, frame: {task_frame}, priority: 1, gains: {{kp: 10, kd: 6}}, "
            "reference: {position: [0.5, 0, 0.6]}}\n"
        )
        assert _errors(spec)[line] == f"{wording}; frames: base, shoulder, arm"


def test_a_joint_target_beyond_the_joints_range_is_a_warning_at_its_value(tmp_path: Path) -> None:
    """A posture beyond a joint limit (PR2's head pan at 3.5 rad, first tried from outside) was
    accepted silently; its level can only give way at the limit. Written in the spec's unit."""
    spec = tmp_path / "posture.yaml"
    spec.write_text(
        "version: 1\nname: posture\nrobot: {model: iiwa14}\n"
        "tasks:\n  - name: posture\n    type: joint\n    priority: 1\n    gains: {kp: 10, kd: 6}\n"
        "    reference: {unit: deg, q: [0, 30, 0, -140, 0, 60, 0]}\n"
    )
    warnings = [w for w in _warnings(spec) if "outside" in w[1]]
    assert warnings == [(9, "-140 deg is outside joint4's range [-120, 120] deg: the "
                             "joint stops at its limit and this priority level gives way there")]


def test_summary_gives_a_prismatic_joint_in_metres(tmp_path: Path) -> None:
    """TIAGo Pro's torso lift (prismatic, 0 to 0.35 m at 0.035 m/s) was shown as 0 to 20.05 deg at
    2.005 deg/s (first tried from outside); the revolute joints stay in degrees."""
    spec = tmp_path / "tiago.yaml"
    urdf = example_robot_data_dir() / "tiago_pro_description" / "robots" / "tiago_pro.urdf"
    wheels = ", ".join(f"wheel_{side}_joint: 0" for side in ("front_left", "front_right", "rear_left", "rear_right"))
    spec.write_text(
        f"version: 1\nname: lift\nrobot:\n  urdf: {urdf}\n  locked_joints: {{{wheels}}}\n"
        "tasks:\n  - {name: reach, type: position, frame: arm_left_tool_link, priority: 1, gains: {kp: 10, kd: 6}, "
        "reference: {position: [0.5, 0.3, 0.9]}}\n"
    )
    lines = validate_file(spec).summary().splitlines()
    position = next(line for line in lines if "q ∈" in line)
    assert position.split("q ∈ [")[1].startswith("0, -30,") and ".. [0.35, 270," in position, position
    assert "|q̇| ≤ [0.035, 143.2," in next(line for line in lines if "|q̇|" in line)
    assert "(m, m/s, N, m/s² for the prismatic torso_lift_joint" in "\n".join(lines)


LIFT_URDF = """<robot name="lift">
  <link name="base"/>
  <link name="carriage"><inertial><mass value="5"/><origin xyz="0 0 0"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="upper"><inertial><mass value="2"/><origin xyz="0.2 0 0"/><inertia ixx="0.02" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="fore"><inertial><mass value="1"/><origin xyz="0.15 0 0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="lift" type="prismatic"><parent link="base"/><child link="carriage"/><axis xyz="0 0 1"/><limit lower="0" upper="0.5" velocity="0.3" effort="500"/></joint>
  <joint name="shoulder" type="revolute"><parent link="carriage"/><child link="upper"/><axis xyz="0 0 1"/><limit lower="-2" upper="2" velocity="2" effort="50"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/><origin xyz="0.4 0 0"/><axis xyz="0 0 1"/><limit lower="-2" upper="2" velocity="2" effort="50"/></joint>
</robot>
"""


def test_a_prismatic_joints_values_stay_in_metres_under_an_angle_unit(tmp_path: Path) -> None:
    """`unit: deg` converts the revolute joints' values only, as the schema says: a torso lift's
    0.2 m start became 0.0035 m, its limits and its posture target with it."""
    from dcts_spec.sim.scenario import resolve_scenario
    from dcts_spec.tasks import make_task

    (tmp_path / "lift.urdf").write_text(LIFT_URDF)
    spec = tmp_path / "lift.yaml"
    spec.write_text(
        "version: 1\nname: lift\nrobot: {urdf: lift.urdf}\nlimits:\n"
        "  joint_position: {min: [0.05, -90, -90], max: [0.4, 90, 90], unit: deg}\n"
        "  joint_velocity: {max: [0.25, 90, 90], unit: deg/s}\n"
        "tasks:\n  - {name: posture, type: joint, priority: 1, gains: {kp: 10, kd: 6}, "
        "reference: {q: [0.2, 10, 20], unit: deg}}\n"
        "scenario: {duration: 0.1, initial_q: [0.3, 10, 20], initial_dq: [0.1, 5, 0], unit: deg}\n")
    report = validate_file(spec)
    assert not [d for d in report.diagnostics if d.severity == "error"], report.diagnostics
    robot, limits = report.robot, report.robot.limits
    assert list(robot.prismatic) == [True, False, False]
    assert (limits.q_min[0], limits.q_max[0], limits.v_max[0]) == (0.05, 0.4, 0.25)
    assert limits.q_max[1] == pytest.approx(math.pi / 2) and limits.v_max[2] == pytest.approx(math.pi / 2)
    assert report.initial_q[:2] == pytest.approx([0.3, math.radians(10)])
    assert make_task(report.spec.tasks[0], robot).q == pytest.approx([0.2, math.radians(10), math.radians(20)])
    assert resolve_scenario(report.spec, robot).dq0[:2] == pytest.approx([0.1, math.radians(5)])


def test_the_gravity_warning_names_the_joint_and_a_prismatic_joints_force_in_n(tmp_path: Path) -> None:
    """The torque limits too weak for gravity: the warning said "joint 1 needs 78.5 Nm" of a lift
    (found from outside, on a PR2's torso): now the joint's name, and N for a prismatic joint."""
    (tmp_path / "lift.urdf").write_text(LIFT_URDF)
    spec = tmp_path / "lift.yaml"
    spec.write_text("version: 1\nname: lift\nrobot: {urdf: lift.urdf}\nlimits:\n  joint_torque: {max: [50, 50, 50]}\n"
                    "tasks:\n  - {name: posture, type: joint, priority: 1, gains: {kp: 10, kd: 6}, "
                    "reference: {q: [0.2, 0.1, 0.2]}}\n")
    warnings = [d.message for d in validate_file(spec).diagnostics if d.severity == "warning"]
    assert any("(joint 1, lift, needs 78.5 N, limit 50.0 N)" in w for w in warnings), warnings


def test_limit_messages_name_the_joint_and_a_prismatic_joints_unit(tmp_path: Path) -> None:
    """Limits beyond the URDF's said "joint 1: 2e+04 vs 1e+04 Nm" of a PR2's torso lift (found from
    outside): now the joint's name, and m/s and N for a prismatic joint."""
    (tmp_path / "lift.urdf").write_text(LIFT_URDF)
    spec = tmp_path / "lift.yaml"
    spec.write_text("version: 1\nname: lift\nrobot: {urdf: lift.urdf}\nlimits:\n"
                    "  joint_torque: {max: [600, 60, 50]}\n  joint_velocity: {max: [0.5, 2, 2]}\n"
                    "tasks:\n  - {name: posture, type: joint, priority: 1, gains: {kp: 10, kd: 6}, "
                    "reference: {q: [0.2, 0.1, 0.2]}}\n")
    with pytest.raises(SpecError) as raised:
        validate_file(spec)
    messages = [d.message for d in raised.value.diagnostics]
    assert any("above the URDF's effort limit (joint 1, lift: 600 vs 500 N, joint 2, shoulder: 60 vs 50 Nm)" in m
               for m in messages), messages
    assert any("above the URDF's velocity limit (joint 1, lift: 0.5 vs 0.3 m/s)" in m for m in messages), messages


@pytest.mark.parametrize(("inertia", "severity", "words"), [
    ('ixx="0.02" iyy="0.02" izz="0.05" ixy="0" ixz="0" iyz="0"', "warning", "break A + B ≥ C"),  # (CAD rounding)
    ('ixx="0.02" iyy="0.02" izz="0.02" ixy="0.05" ixz="0" iyz="0"', "error", "not positive definite"),
    ('ixx="0.02" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0" mass="-2"', "error", "negative mass (-2 kg)"),
    # a point mass written with rounding (iCub's r_hip_2): no diagnostic, and MuJoCo takes it
    ('ixx="-5.4e-20" iyy="-5.4e-20" izz="0" ixy="0" ixz="0" iyz="0"', None, ""),
])
def test_an_unphysical_inertia_is_named_at_validation(tmp_path: Path, inertia: str, severity: str, words: str) -> None:
    """MuJoCo refused such a body and the simulation ended in an internal error (exit 3); a body
    that only breaks A + B ≥ C is simulated balanced."""
    upper = '<mass value="2"/><origin xyz="0.2 0 0"/><inertia ixx="0.02" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/>'
    mass = re.search(r'mass="(-?[0-9.]+)"', inertia)
    changed = f'<mass value="{mass.group(1) if mass else 2}"/><origin xyz="0.2 0 0"/><inertia ' + \
        re.sub(r' ?mass="-?[0-9.]+"', "", inertia) + "/>"
    assert upper in LIFT_URDF
    (tmp_path / "lift.urdf").write_text(LIFT_URDF.replace(upper, changed))
    spec = tmp_path / "lift.yaml"
    spec.write_text("version: 1\nname: lift\nrobot: {urdf: lift.urdf}\ntasks:\n  - {name: posture, type: joint, "
                    "priority: 1, gains: {kp: 10, kd: 6}, reference: {q: [0.2, 0.1, 0.2]}}\nscenario: {duration: 0.05}\n")
    if severity == "error":
        with pytest.raises(SpecError) as info:
            validate_file(spec)
        assert "link upper (moved by joint shoulder)" in str(info.value) and words in str(info.value)
        return
    report = validate_file(spec)
    found = [d for d in report.diagnostics if "link upper" in d.message]
    assert (found and found[0].severity == "warning" and words in found[0].message) if severity else not found, found
    result = dcts("simulate", str(spec), "--runtime", "python", "--no-plots", "-q", "-o", str(tmp_path / "run"))
    assert result.returncode == 0, result.stderr


def test_a_mimic_joint_and_an_unreadable_inertial_are_warned_about(tmp_path: Path) -> None:
    """Pinocchio drives a mimic joint as one of its own, and urdfdom reads an <inertial> it cannot
    parse as none (its complaint went to a silenced stderr): both passed without a word."""
    urdf = LIFT_URDF.replace('<limit lower="-2" upper="2" velocity="2" effort="50"/></joint>\n</robot>',
                             '<limit lower="-2" upper="2" velocity="2" effort="50"/><mimic joint="shoulder"/>'
                             '</joint>\n</robot>')
    upper = 'izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial></link>\n  <link name="fore">'
    assert urdf != LIFT_URDF and upper in urdf
    (tmp_path / "lift.urdf").write_text(urdf.replace(upper, upper.replace(' ixz="0"', "")))
    spec = tmp_path / "lift.yaml"
    spec.write_text("version: 1\nname: lift\nrobot: {urdf: lift.urdf}\ntasks:\n  - {name: posture, type: joint, "
                    "priority: 1, gains: {kp: 10, kd: 6}, reference: {q: [0.2, 0.1, 0.2]}}\n")
    warnings = [d.message for d in validate_file(spec).diagnostics if d.severity == "warning"]
    assert any("joint elbow mimics shoulder" in m and "robot.locked_joints" in m for m in warnings), warnings
    assert any("could not read" in m and "missing ixz" in m and "Link [upper]" in m for m in warnings), warnings
    spec.write_text(spec.read_text().replace("robot: {urdf: lift.urdf}", "robot: {urdf: lift.urdf, locked_joints: {elbow: 0}}")
                    .replace("[0.2, 0.1, 0.2]", "[0.2, 0.1]"))
    assert not any("mimics" in d.message for d in validate_file(spec).diagnostics)


def test_a_floating_root_is_described_as_one_and_locked_only_at_its_neutral(tmp_path: Path) -> None:
    """describe called it a continuous joint, and a lock at 0.5 moved the base 0.5 m along x."""
    urdf = LIFT_URDF.replace('<link name="base"/>', '<link name="world"/>\n  <link name="base"/>\n  <joint name="root" '
                             'type="floating"><parent link="world"/><child link="base"/></joint>')
    (tmp_path / "lift.urdf").write_text(urdf)
    rows = {j.name: j.type for j in describe(str(tmp_path / "lift.urdf")).joints}
    assert rows["root"] == "floating (6 DOF)" and rows["lift"] == "prismatic"
    spec = tmp_path / "lift.yaml"
    text = ("version: 1\nname: lift\nrobot: {urdf: lift.urdf, locked_joints: {root: 0.5}}\ntasks:\n  - {name: posture, "
            "type: joint, priority: 1, gains: {kp: 10, kd: 6}, reference: {q: [0.2, 0.1, 0.2]}}\n")
    spec.write_text(text)
    with pytest.raises(SpecError) as info:
        validate_file(spec)
    assert "lift.yaml:3:" in str(info.value) and "root is a floating joint" in str(info.value)
    spec.write_text(text.replace("root: 0.5", "root: 0"))
    assert validate_file(spec).robot.nv == 3


def test_summary_words_cartesian_bounds_like_the_run_summary(tmp_path: Path) -> None:
    """One-sided bounds leave out the infinite side, with the unit on each number."""
    spec = tmp_path / "bounded.yaml"
    spec.write_text(
        "version: 1\nname: bounded\nrobot: {model: iiwa14}\n"
        "limits:\n  cartesian:\n    - {frame: tool, axis: z, min: 0.05}\n    - {frame: tool, axis: x, max: 0.9}\n"
        "    - {frame: tool, axis: y, min: -0.5, max: 0.5}\n"
        "tasks:\n  - {name: reach, type: position, frame: tool, priority: 1, gains: {kp: 10, kd: 6}, "
        "reference: {position: [0.5, 0, 0.6]}}\n"
    )
    summary = validate_file(spec).summary()
    bounds = [line.strip() for line in summary.splitlines() if "tool." in line]
    assert bounds == ["0.05 m ≤ tool.z", "tool.x ≤ 0.9 m", "-0.5 m ≤ tool.y ≤ 0.5 m"]


def test_a_cartesian_bound_braking_beyond_what_the_joint_acceleration_limits_allow_is_a_warning(tmp_path: Path) -> None:
    """With joint acceleration limits of 1 rad/s², the tool's z moves at ~1.3 m/s² at most at the
    initial configuration, less than the 5 m/s² a Cartesian bound's viability brakes with by
    default: near the bound it can be crossed (an xArm7 crossed one by 0.66 mm, reported as
    relaxed, with no warning). Its own max_acceleration within that reach: no warning."""
    spec = tmp_path / "ceiling.yaml"
    text = ("version: 1\nname: ceiling\nrobot: {model: iiwa14}\nlimits:\n  joint_acceleration: {max: 1}\n"
            "  cartesian:\n    - {frame: tool, axis: z, max: 0.9}\n"
            "tasks:\n  - {name: reach, type: position, frame: tool, priority: 1, gains: {kp: 10, kd: 6}, "
            "reference: {position: [0.5, 0, 0.6]}}\nscenario: {duration: 1, initial_q: [0, 30, 0, -60, 0, 60, 0], unit: deg}\n")
    spec.write_text(text)
    warned = [(line, m) for line, m in _warnings(spec) if "acceleration limits move tool.z" in m]
    assert len(warned) == 1 and warned[0][0] == 7, _warnings(spec)
    reach = float(re.search(r"at ([0-9.]+) m/s² at most", warned[0][1]).group(1))
    suggested = float(re.search(r"max_acceleration: ([0-9.]+) or less", warned[0][1]).group(1))
    assert 0.1 < reach < 5 and 0.9 * reach <= suggested <= reach
    spec.write_text(text.replace("max: 0.9}", "max: 0.9, max_acceleration: 0.1}"))
    assert not any("acceleration limits move" in m for _, m in _warnings(spec))
    spec.write_text(text.replace("  joint_acceleration: {max: 1}\n", ""))
    assert not any("acceleration limits move" in m for _, m in _warnings(spec))


@pytest.mark.parametrize("priority", [1, 2])
def test_a_task_on_a_frame_no_joint_moves_is_said_to_be_one_at_any_priority(tmp_path: Path, priority: int) -> None:
    """Below another level, a task on the base was said to "conflict with the higher priorities"
    (found from outside on a 29-joint human's fixed pelvis at priority 3); it conflicts with nothing.
    At any priority it is now said at its frame that no joint moves that frame."""
    spec = tmp_path / "fixed.yaml"
    reach = "{name: reach, type: position, frame: tool, priority: 1, gains: {kp: 10, kd: 6}, reference: {position: [0.5, 0, 0.6]}}"
    base = (f"{{name: base, type: position, frame: base, priority: {priority}, gains: {{kp: 10, kd: 6}}, "
            "reference: {position: [0, 0, 0]}}")
    spec.write_text("version: 1\nname: fixed\nrobot: {model: iiwa14}\ntasks:\n"
                    f"  - {reach if priority == 2 else base}\n  - {base if priority == 2 else reach.replace('priority: 1', 'priority: 2')}\n"
                    "  - {name: damping, type: joint, priority: 3, gains: {kp: 0, kd: 6}}\n")
    with pytest.raises(SpecError) as raised:
        validate_file(spec)
    errors = [(d.line, d.message) for d in raised.value.errors]
    line = 6 if priority == 2 else 5
    assert len(errors) == 1 and errors[0][0] == line, errors
    assert "frame 'base' is fixed to the world (no joint moves it)" in errors[0][1]
    assert "conflict" not in errors[0][1]


def test_a_cartesian_bound_on_a_frame_fixed_to_the_world_is_a_warning(tmp_path: Path) -> None:
    """No joint moves the base: a bound on it constrains nothing (found from outside: accepted with
    no word, or with advice to lower its braking to 0 m/s² where joint acceleration limits exist)."""
    spec = tmp_path / "base_bound.yaml"
    spec.write_text("version: 1\nname: base_bound\nrobot: {model: iiwa14}\nlimits:\n  joint_acceleration: {max: 10}\n"
                    "  cartesian:\n    - {frame: base, axis: z, min: -0.2}\n"
                    "tasks:\n  - {name: reach, type: position, frame: tool, priority: 1, gains: {kp: 10, kd: 6}, "
                    "reference: {position: [0.5, 0, 0.6]}}\n")
    warned = [(line, m) for line, m in _warnings(spec) if "base" in m]
    assert warned == [(7, "base is fixed to the world: no joint moves it, so this bound constrains nothing (it holds, "
                          "or is crossed, whatever the controller does); bound a frame the robot moves")], _warnings(spec)


@pytest.mark.parametrize("formulation", ["osc", "projector", "dcts"])
def test_a_formulation_that_does_not_hold_cartesian_or_collision_limits_says_so(tmp_path: Path, formulation: str) -> None:
    """osc holds no limit and the projector the joint ones only: their steps read "ok" inside an
    obstacle (found from outside, with no warning anywhere)."""
    spec = tmp_path / "unkept.yaml"
    spec.write_text(f"""version: 1
name: unkept
robot: {{model: iiwa14}}
controller: {{formulation: {formulation}}}
limits:
  cartesian:
    - {{frame: tool, axis: z, min: 0.05}}
  collision:
    obstacles: {{ball: {{type: sphere, center: [0.673, 0.0, 0.40], radius: 0.05}}}}
tasks:
  - {{name: reach, type: position, frame: tool, priority: 1, gains: {{kp: 10, kd: 6}}, reference: {{position: [0.5, 0, 0.6]}}}}
scenario: {{duration: 1, initial_q: [0, 30, 0, -60, 0, 60, 0], unit: deg}}
""")
    warned = {line for line, m in _warnings(spec) if f"formulation {formulation}" in m and "not held" in m}
    assert warned == (set() if formulation == "dcts" else {6, 8})


def test_a_push_or_parameter_change_after_the_run_ends_is_a_warning(tmp_path: Path) -> None:
    """A push starting at 5 s of a 1 s run, and a parameter change at 5 s, had no effect and
    validated silently."""
    spec = tmp_path / "late.yaml"
    spec.write_text("""version: 1
name: late
robot: {model: iiwa14}
tasks:
  - {name: posture, type: joint, priority: 1, gains: {kp: 10, kd: 6}, reference: {q: [0, 0, 0, 0, 0, 0, 0]}}
parameters:
  tasks: {posture: [kp]}
scenario:
  duration: 1.0
  disturbances:
    - {type: force, body: link7, force: [10, 0, 0], start: 5.0, duration: 0.2}
    - {type: force, body: link7, force: [10, 0, 0], start: 0.5, duration: 0.2}
  parameters:
    - {time: 5.0, values: {posture.kp: 20}}
""", encoding="utf-8")
    warnings = _warnings(spec)
    assert any(line == 11 and "push starts at 5 s, not before the run ends" in m for line, m in warnings), warnings
    assert any(line == 14 and "parameter change comes at 5 s" in m for line, m in warnings), warnings
    assert not any(line == 12 for line, _ in warnings)


def test_a_run_with_more_steps_than_a_log_keeps_is_an_error(tmp_path: Path) -> None:
    """A 1e-5 s period and a 10,000 s run, each allowed, validated: the log then asked for 7.5 GB or
    more (first seen from outside). The spec's duration and --duration are held to 10⁷ steps."""
    text = (ROOT / "specs" / "minimal.yaml").read_text().replace("duration: 2.0", "duration: 10000")
    spec = tmp_path / "long.yaml"
    spec.write_text(text + "controller: {period: 1.0e-5}\n")
    result = dcts("validate", str(spec))
    assert result.returncode == 1
    assert "scenario.duration: 10000 s at a period of 1e-05 s is 1e+09 control steps" in result.stderr
    spec.write_text(text.replace("duration: 10000", "duration: 0.1") + "controller: {period: 1.0e-5}\n")
    result = dcts("simulate", str(spec), "--duration", "200", "-o", str(tmp_path / "out"))
    assert result.returncode == 1 and "--duration 200 s at a period of 1e-05 s" in result.stderr
    assert not (tmp_path / "out").exists()
    spec.write_text(text)  # the longest run at the default period
    assert dcts("validate", str(spec)).returncode == 0


def _nan_torque_limit(spec):
    limits = spec.limits
    torque = limits.joint_torque.model_copy(update={"max": float("nan")})
    return spec.model_copy(update={"limits": limits.model_copy(update={"joint_torque": torque})})


def _negative_period(spec):
    return spec.model_copy(update={"controller": spec.controller.model_copy(update={"period": -1.0})})


@pytest.mark.parametrize(("edit", "path"), [(_nan_torque_limit, "limits.joint_torque.max"),
                                            (_negative_period, "controller.period")])
def test_a_spec_edited_in_python_is_checked_again(edit, path):
    """model_copy(update=...) does not validate: a NaN torque limit built a controller whose every
    torque was NaN (status -2), and a negative period built and stepped (found from outside)."""
    from dcts_spec import build_controller, load_spec
    from dcts_spec.spec.errors import format_path

    with pytest.raises(SpecError) as caught:
        build_controller(edit(load_spec(ROOT / "specs" / "minimal.yaml")))
    (error,) = caught.value.errors
    assert error.line is None and "as edited in Python" in error.file and format_path(error.path) == path


def test_a_bundle_of_a_spec_edited_in_python_records_the_edited_spec(tmp_path):
    """spec.yaml and SPEC_SHA256 of the bundle are the compiled spec's: a spec edited to a 40 Nm
    torque limit recorded its file's 100 Nm and the file's digest (found from outside)."""
    from dcts_spec import load_spec
    from dcts_spec.codegen import compile_bundle

    spec = load_spec(ROOT / "specs" / "minimal.yaml")
    limits = spec.limits
    torque = limits.joint_torque.model_copy(update={"max": 40.0})
    edited = spec.model_copy(update={"limits": limits.model_copy(update={"joint_torque": torque})})
    for which, out in ((spec, tmp_path / "as_file"), (edited, tmp_path / "edited")):
        compile_bundle(which, out, build=False)
    manifests = [json.loads((tmp_path / d / "manifest.json").read_text()) for d in ("as_file", "edited")]
    assert manifests[0]["spec_sha256"] != manifests[1]["spec_sha256"]
    assert b"The smallest useful spec" in (tmp_path / "as_file" / "spec.yaml").read_bytes()  # (the file, comments too)
    assert load_spec(tmp_path / "edited" / "spec.yaml").limits.joint_torque.max == 40.0


def test_a_target_beyond_a_bound_names_the_tasks_that_share_its_scaling(tmp_path: Path) -> None:
    """A level's tasks share one scaling: a foot pulled into its bound stopped the other feet of
    its level (8 cm of drift, found from outside), and the warning named only the bounded task."""
    spec = tmp_path / "shared.yaml"
    spec.write_text(
        "version: 1\nname: shared\nrobot: {model: iiwa14}\n"
        "limits:\n  cartesian:\n    - {frame: tool, axis: z, min: 0.3}\n"
        "tasks:\n"
        "  - {name: reach, type: position, frame: tool, axes: [x, z], priority: 1, gains: {kp: 100, kd: 20},\n"
        "     reference: {position: [0.5, 0.0, 0.1]}}\n"
        "  - {name: wrist, type: joint, joints: [joint7], priority: 1, gains: {kp: 10, kd: 6}, reference: {q: [0.2]}}\n"
        "  - {name: posture, type: joint, priority: 2, gains: {kp: 0, kd: 6}}\n")
    warning = next(d.message for d in validate_file(spec).diagnostics if "outside its bound" in d.message)
    assert "wrist, at the same priority, shares that scaling and is no longer driven either: give it a " \
        "priority of its own" in warning and "posture" not in warning
    # (two of them: the plural, as a 17-joint G1's two hands at one priority read "left_hand ... share")
    spec.write_text(spec.read_text().replace(
        "  - {name: posture",
        "  - {name: elbow, type: joint, joints: [joint4], priority: 1, gains: {kp: 10, kd: 6}, reference: {q: [-1]}}\n"
        "  - {name: posture"))
    warning = next(d.message for d in validate_file(spec).diagnostics if "outside its bound" in d.message)
    assert "wrist, elbow, at the same priority, share that scaling and are no longer driven either: give them" in warning
