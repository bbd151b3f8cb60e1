"""`dcts validate` on the specs of the repository, its JSON output, and the warnings it gives."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from command_line import ROOT, dcts
from dcts_spec.robot.builtin import example_robot_data_dir, iiwa14_urdf_path
from dcts_spec.validate import validate_file

SPECS = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "specs").glob("**/*.yaml"))


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
