"""Discovery from the command line: `dcts robots`, `dcts describe`, `dcts init`."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from command_line import MINIMAL, invoke

from dcts_spec.robot.builtin import BUILTIN_ROBOTS, builtin_urdf_path, example_robot_data_dir, load_builtin_model


@pytest.fixture(autouse=True)
def _private_bundle_cache(tmp_path_factory, monkeypatch):
    """No test writes into the user's bundle cache."""
    monkeypatch.setenv("DCTS_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "bundle-cache"))


def described(*targets: str) -> list[dict]:
    result = invoke("describe", "--json", *targets)
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def test_robots_lists_the_builtins() -> None:
    result = invoke("robots")
    assert result.exit_code == 0, result.output
    for name in BUILTIN_ROBOTS:
        assert f"{name} " in result.stdout
    listed = json.loads(invoke("robots", "--json").stdout)
    assert [r["name"] for r in listed] == list(BUILTIN_ROBOTS)
    assert [r["dof"] for r in listed] == [load_builtin_model(name).nv for name in BUILTIN_ROBOTS]


@pytest.mark.parametrize("name", BUILTIN_ROBOTS)
def test_describe_a_builtin_robot_matches_its_model(name: str) -> None:
    [robot] = described(name)
    model = load_builtin_model(name)
    assert [j["name"] for j in robot["joints"]] == list(model.names)[1:]
    assert np.allclose([j["position"]["max"] for j in robot["joints"]], model.upperPositionLimit)
    assert np.allclose([j["velocity"]["max"] for j in robot["joints"]], model.velocityLimit)
    assert np.allclose([j["effort"]["max"] for j in robot["joints"]], model.effortLimit)
    assert {j["effort"]["unit"] for j in robot["joints"]} == {"Nm"}
    assert {j["position"]["unit"] for j in robot["joints"]} == {"rad"}
    # every link of the URDF (Pinocchio merges fixed and locked links into their joint's body)
    assert robot["mass"] == pytest.approx(sum(inertia.mass for inertia in model.inertias))
    assert {f["name"] for f in robot["frames"]} == {f.name for f in model.frames} - {"universe"}
    assert robot["urdf"] == str(builtin_urdf_path(name))
    text = invoke("describe", name).stdout
    assert f"tool: {robot['tool_frame']}" in text and " deg " in text and " Nm" in text and "links (kg)" in text


def test_describe_a_spec_shows_its_limits_and_frames(tmp_path: Path) -> None:
    spec = tmp_path / "narrow.yaml"
    spec.write_text(MINIMAL.read_text().replace("joint_torque: {max: 100}", "joint_torque: {max: 42}")
                    .replace("robot:\n  model: iiwa14", "robot:\n  model: iiwa14\n  frames:\n"
                             "    tip: {parent: tool, xyz: [0, 0, 0.1]}"))
    [robot] = described(str(spec))
    assert {j["effort"]["max"] for j in robot["joints"]} == {42.0}
    assert {"name": "tip", "kind": "frame", "joint": "joint7"} in robot["frames"]


def test_describe_a_urdf_and_several_targets(tmp_path: Path) -> None:
    ur5 = example_robot_data_dir() / "ur_description" / "urdf" / "ur5_robot.urdf"
    robots = described("iiwa14", str(ur5))
    assert [r["dof"] for r in robots] == [7, 6]
    assert robots[1]["tool_frame"] == "tool0"


def test_describe_what_is_not_a_robot_exits_1(tmp_path: Path) -> None:
    result = invoke("describe", "no_such_robot")
    assert result.exit_code == 1 and "neither a built-in robot (iiwa14, panda) nor a file" in result.output
    broken = tmp_path / "broken.urdf"
    broken.write_text("<robot name='x'><link name='a'/>")
    result = invoke("describe", str(broken))
    assert result.exit_code == 1 and "cannot load the URDF" in result.output and "Traceback" not in result.output
    spec = tmp_path / "broken.yaml"
    spec.write_text("version: 1\nname: b\nrobot: {model: iiwa14}\ntasks: []\nbogus: 1\n")
    result = invoke("describe", str(spec))
    assert result.exit_code == 1 and "broken.yaml:5" in result.output


@pytest.mark.parametrize("name", BUILTIN_ROBOTS)
def test_init_validate_simulate_for_each_builtin_robot(name: str, tmp_path: Path) -> None:
    spec = tmp_path / f"my {name}.yaml"
    result = invoke("init", str(spec), "--robot", name)
    assert result.exit_code == 0, result.output
    text = spec.read_text()
    assert text.startswith("# ") and f"model: {name}" in text and "name: my_" in text
    validated = invoke("validate", "--json", str(spec))
    assert validated.exit_code == 0, validated.output
    [report] = json.loads(validated.stdout)
    assert report["valid"] and not [d for d in report["diagnostics"] if d["severity"] != "info"], report
    out = tmp_path / "run"
    result = invoke("simulate", str(spec), "--runtime", "python", "--duration", "0.05", "--no-plots", "-q",
                    "-o", str(out))
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] and summary["solver_failures"] == 0
    # The target is 10 cm from where the tool starts, and the tool heads for it.
    assert 0.08 < summary["task_final_error"]["tool_position"] < 0.1
    compiled = invoke("compile", str(spec), "--no-build", "-q", "-o", str(tmp_path / "bundle"))
    assert compiled.exit_code == 0, compiled.output


def test_init_from_a_urdf_names_it_relative_to_the_spec(tmp_path: Path) -> None:
    (tmp_path / "robots").mkdir()
    urdf = tmp_path / "robots" / "arm.urdf"
    urdf.write_text(builtin_urdf_path("iiwa14").read_text())
    spec = tmp_path / "specs" / "arm.yaml"
    spec.parent.mkdir()
    assert invoke("init", str(spec), "--robot", str(urdf)).exit_code == 0
    assert f"urdf: {urdf.as_posix()}" in spec.read_text()  # (absolute as given: the spec may move)
    spec.unlink()
    assert invoke("init", str(spec), "--robot", os.path.relpath(urdf)).exit_code == 0
    assert "urdf: ../robots/arm.urdf" in spec.read_text()  # (relative: to the spec's folder)
    # It starts where the tool moves along every axis: the middle of the iiwa14's ranges is the arm
    # straight up, singular, and that spec was validated with warnings and never held the tool.
    validated = invoke("validate", "--json", str(spec))
    assert validated.exit_code == 0, validated.output
    [report] = json.loads(validated.stdout)
    assert not [d for d in report["diagnostics"] if d["severity"] != "info"], report["diagnostics"]


def test_init_refuses_a_robot_that_cannot_hold_a_point(tmp_path: Path) -> None:
    urdf = tmp_path / "pendulum.urdf"
    link = '<inertial><mass value="1"/><origin xyz="0 0 -0.5"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>'
    urdf.write_text(f'''<robot name="pendulum"><link name="base"/><link name="a">{link}</link><link name="b">{link}</link>
<joint name="j1" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" velocity="5" effort="50"/></joint>
<joint name="j2" type="revolute"><parent link="a"/><child link="b"/><origin xyz="0 0 -1"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" velocity="5" effort="50"/></joint>
</robot>''')
    result = invoke("init", str(tmp_path / "p.yaml"), "--robot", str(urdf))
    assert result.exit_code == 1 and "takes at least 3 joints; pendulum has 2" in result.output, result.output
    assert not (tmp_path / "p.yaml").exists()


def test_init_never_overwrites_a_file(tmp_path: Path) -> None:
    spec = tmp_path / "mine.yaml"
    spec.write_text("my own spec\n")
    result = invoke("init", str(spec))
    assert result.exit_code == 1 and "never overwrites" in result.output
    assert spec.read_text() == "my own spec\n"


@pytest.mark.parametrize("robot", ["no_such_robot", str(MINIMAL)])
def test_init_wants_a_robot(robot: str, tmp_path: Path) -> None:
    result = invoke("init", str(tmp_path / "x.yaml"), "--robot", robot)
    assert result.exit_code == 1 and "built-in robot" in result.output and "Traceback" not in result.output
    assert not (tmp_path / "x.yaml").exists()
