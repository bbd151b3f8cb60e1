"""The corpus of broken specs: every problem is reported at the right line, with a helpful message.

Each file of `tests/broken_specs/` has exactly one problem and starts with the comment
`# expect: LINE: TEXT`: an error must be reported at the 1-based LINE, and its message must
contain TEXT (case-insensitive).
"""

from __future__ import annotations

import functools
import json
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

import command_line
from command_line import ROOT
from dcts_spec.spec import SpecError
from dcts_spec.validate import validate_file

dcts = functools.partial(command_line.dcts, timeout=120)
CORPUS = ROOT / "tests" / "broken_specs"
EXPECT = re.compile(r"#\s*expect:\s*(\d+):\s*(.+?)\s*$")


@dataclass(frozen=True)
class Expected:
    path: Path
    line: int
    text: str

    @property
    def relative(self) -> str:
        return self.path.relative_to(ROOT).as_posix()


def _expected(path: Path) -> Expected:
    first = path.read_text(encoding="utf-8").split("\n", 1)[0]
    match = EXPECT.fullmatch(first)
    assert match, f"{path.name}: the first line must be `# expect: LINE: TEXT`, got {first!r}"
    return Expected(path, int(match[1]), match[2])


CASES = [_expected(p) for p in sorted(CORPUS.glob("*.yaml"))]


def _errors(path: Path) -> list:
    with pytest.raises(SpecError) as caught:
        validate_file(path)
    return caught.value.errors


def test_corpus_is_large_enough() -> None:
    assert len(CASES) >= 30


@pytest.mark.parametrize("case", CASES, ids=[c.path.stem for c in CASES])
def test_reported_at_line_with_message(case: Expected) -> None:
    errors = _errors(case.path)
    assert errors, "a SpecError without any error-level diagnostic"
    listing = "\n".join(str(d) for d in errors)
    at_line = [d for d in errors if d.line == case.line]
    assert at_line, f"no error at line {case.line}; got:\n{listing}"
    assert any(case.text.lower() in d.message.lower() for d in at_line), (
        f"no error at line {case.line} mentions {case.text!r}; got:\n{listing}"
    )
    for d in errors:
        assert d.file == str(case.path)
        assert d.line is not None and d.column is not None, f"unlocated diagnostic: {d}"


def test_truly_empty_file(tmp_path: Path) -> None:
    path = tmp_path / "empty.yaml"
    path.write_bytes(b"")
    (error,) = _errors(path)
    assert error.line == 1 and "empty" in error.message


def test_missing_file(tmp_path: Path) -> None:
    (error,) = _errors(tmp_path / "nowhere.yaml")
    assert "no such file" in error.message


SEVERAL_STRUCTURAL = """\
version: 1
name: several
robot:
  modle: iiwa14
controller:
  formulation: qp
tasks:
  - name: tool_position
    type: position
    frame: tool
    priority: 1
    gains: {kp: 100, kd: -20}
    reference: {position: [0.5, 0.0, 0.6]}
scenario:
  duration: 2.0
  unit: degrees
"""

SEVERAL_SEMANTIC = """\
version: 1
name: several
robot:
  model: iiwa14
tasks:
  - name: tool_position
    type: position
    frame: tool0
    priority: 1
    gains: {kp: 100, kd: 20}
    reference: {position: [0.5, 0.0, 0.6]}
  - name: elbow
    type: joint
    joints: [joint1, joint9]
    priority: 2
    gains: {kp: 0, kd: 5}
scenario:
  duration: 2.0
  initial_q: [0, 0, 0]
  payloads:
    - {frame: gripper, mass: 1.0}
"""


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (SEVERAL_STRUCTURAL, {4: "did you mean 'model'", 6: "'qp' is not allowed", 12: "must be ≥ 0 and ≤ 1e5 1/s, got -20", 16: "'degrees'"}),
        (SEVERAL_SEMANTIC, {8: "no frame 'tool0'", 14: "no joint 'joint9'", 19: "3 values for 7 joints", 21: "no frame 'gripper'"}),
    ],
    ids=["structural", "semantic"],
)
def test_several_problems_are_all_reported(tmp_path: Path, text: str, expected: dict[int, str]) -> None:
    path = tmp_path / "several.yaml"
    path.write_text(text, encoding="utf-8")
    errors = _errors(path)
    for line, message in expected.items():
        assert any(d.line == line and message in d.message for d in errors), (
            f"line {line}: {message!r} not reported; got:\n" + "\n".join(map(str, errors))
        )
    assert [d.line for d in errors] == sorted(d.line for d in errors), "diagnostics are not in file order"


REPRESENTATIVE = ["bad_indentation", "key_typo_gains", "unknown_joint"]  # YAML syntax, structure, robot


@pytest.mark.parametrize("stem", REPRESENTATIVE)
def test_cli_reports_one_file(stem: str) -> None:
    case = next(c for c in CASES if c.path.stem == stem)
    result = dcts("validate", case.relative)
    assert result.returncode == 1
    assert "Traceback" not in result.stdout + result.stderr
    assert f"{case.relative}:{case.line}:" in result.stderr
    assert case.text.lower() in result.stderr.lower()


def test_cli_reports_every_file_in_one_run() -> None:
    result = dcts("validate", *(c.relative for c in CASES))
    assert result.returncode == 1
    assert "Traceback" not in result.stdout + result.stderr
    missing = [f"{c.relative}:{c.line}" for c in CASES if f"{c.relative}:{c.line}:" not in result.stderr]
    assert not missing, "not reported by the CLI:\n" + "\n".join(missing)


def test_cli_json_of_broken_file() -> None:
    case = next(c for c in CASES if c.path.stem == "unknown_task_frame")
    result = dcts("validate", "--json", case.relative)
    assert result.returncode == 1
    assert "Traceback" not in result.stdout + result.stderr
    [report] = json.loads(result.stdout)  # a list, even for one file
    assert report["valid"] is False
    assert any(d["line"] == case.line and d["severity"] == "error" for d in report["diagnostics"])
