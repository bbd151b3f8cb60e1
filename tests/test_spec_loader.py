"""The located YAML reader and the spec loader: positions, units, scalar-or-list fields, defaults."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest

from dcts_spec.spec import Diagnostic, SpecError, load_spec, load_spec_text
from dcts_spec.spec.errors import MAX_DIAGNOSTICS, did_you_mean, format_path
from dcts_spec.spec.source import MAX_BYTES, read_yaml, read_yaml_file
from dcts_spec.spec.types import as_list, size_of
from dcts_spec.spec.units import to_si

ROOT = Path(__file__).resolve().parents[1]

SPEC = """\
version: 1
name: reach
robot:
  model: iiwa14
  frames:
    camera: {parent: link7, xyz: [0, 0.05, 0.08]}
limits:
  joint_torque: {max: 100}
  joint_position:
    min: [-160, -110, -160, -110, -160, -110, -170]
    max: 160
    unit: deg
tasks:
  - name: tool_position
    type: position
    frame: tool
    priority: 1
    gains: {kp: [100, 100, 200], kd: 20}
    reference: {position: [0.5, 0.0, 0.6]}
  - name: damping
    type: joint
    priority: 2
    gains:
      kp: 0
      kd: 5
"""


def _errors(text: str) -> list[Diagnostic]:
    with pytest.raises(SpecError) as caught:
        load_spec_text(text, "spec.yaml")
    return caught.value.errors


# --- the YAML reader -------------------------------------------------------------------------------------


def test_positions_of_nested_keys_and_list_items() -> None:
    data, source = read_yaml(SPEC, "spec.yaml")
    assert data["tasks"][1]["gains"] == {"kp": 0, "kd": 5}
    pos = source.positions
    assert pos[()] == (1, 1)
    assert pos[("robot",)] == (3, 1)
    assert pos[("robot", "model")] == (4, 3)
    assert pos[("robot", "frames", "camera", "parent")] == (6, 14)  # a key inside a flow mapping
    assert pos[("limits", "joint_position", "min")] == (10, 5)
    assert pos[("limits", "joint_position", "min", 3)] == (10, 29)  # an item of a flow list
    assert pos[("tasks", 0)] == (14, 5)  # a block list item: where its mapping starts
    assert pos[("tasks", 1, "name")] == (20, 5)
    assert pos[("tasks", 1, "gains", "kd")] == (25, 7)
    assert pos[("tasks", 0, "reference", "position", 2)] == (19, 38)


def test_locate_falls_back_to_the_longest_existing_prefix() -> None:
    _, source = read_yaml(SPEC, "spec.yaml")
    assert source.locate(("tasks", 1, "gains", "max_velocity")) == (23, 5)
    assert source.locate(("tasks", 7, "frame")) == (13, 1)
    assert source.locate(("nothing", "here")) == (1, 1)
    d = source.diagnostic(("tasks", 1, "priority"), "too low", "warning")
    assert (d.file, d.line, d.column, d.severity) == ("spec.yaml", 22, 5, "warning")
    assert str(d) == "spec.yaml:22:5: warning: tasks[1].priority: too low"


def test_duplicate_and_non_text_keys_are_all_reported() -> None:
    with pytest.raises(SpecError) as caught:
        read_yaml("a: 1\nb: {x: 1, x: 2}\n3: c\na: 4\n", "f.yaml")
    found = [(d.line, d.column, d.message) for d in caught.value.diagnostics]
    assert found == [
        (2, 11, "duplicate key 'x'"),
        (3, 1, "keys must be text, got 3"),
        (4, 1, "duplicate key 'a'"),
    ]


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        ("a:\n  b: 1\n   c: 2\n", 3, "indentation"),
        ("a:\n\tb: 1\n", 2, "tabs"),
        ("a: [1, 2\nb: 3\n", 2, "invalid YAML"),
        ("a: 1\n---\nb: 2\n", 2, "single document"),
        ("a: !!python/object:os.system x\n", 1, "invalid YAML value"),
        ("base: &b {kp: 1}\ngains: {<<: *b, kd: 2}\n", 2, "merge keys"),
        ("", 1, "empty"),
        ("# only a comment\n", 1, "empty"),
        ("\n\n- 1\n- 2\n", 3, "holds a list"),
        ("just text\n", 1, "holds the value 'just text'"),
    ],
    ids=["indentation", "tab", "unclosed", "two-documents", "python-tag", "merge-key", "empty", "comment", "list", "scalar"],
)
def test_unreadable_yaml_is_one_located_error(text: str, line: int, message: str) -> None:
    with pytest.raises(SpecError) as caught:
        read_yaml(text, "f.yaml")
    (d,) = caught.value.diagnostics
    assert (d.file, d.line, d.severity) == ("f.yaml", line, "error")
    assert message.lower() in d.message.lower()


def test_yaml_scalars() -> None:
    data, _ = read_yaml("a: [1e6, 1.0e-3, -2.5E+2, 1.5, 10, 0.5]\nb: yes\nc: '1e6'\nd: 1e\ne: ~\n"
                        "f: [true, False, on, off, no]\ng: 2001-12-14\n", "f.yaml")
    assert data["a"] == [1e6, 1e-3, -250.0, 1.5, 10, 0.5]
    assert isinstance(data["a"][0], float) and isinstance(data["a"][4], int)
    assert data["b"] == "yes"  # YAML 1.2: only true and false are booleans
    assert data["f"] == [True, False, "on", "off", "no"]
    assert data["g"] == "2001-12-14"  # no dates: a spec has none
    assert data["c"] == "1e6" and data["d"] == "1e" and data["e"] is None


def test_aliases_are_read() -> None:
    data, _ = read_yaml("g: &g {kp: 1, kd: 2}\nh: *g\n", "f.yaml")
    assert data["h"] == {"kp": 1, "kd": 2}


def test_read_yaml_file(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("a: 1\n", encoding="utf-8")
    data, source = read_yaml_file(path)
    assert data == {"a": 1} and source.file == str(path)
    with pytest.raises(SpecError, match="no such file"):
        read_yaml_file(tmp_path / "missing.yaml")
    path.write_bytes(b"a: \xff\xfe\n")
    with pytest.raises(SpecError, match="cannot read"):
        read_yaml_file(path)


# --- input that must not hang, crash or flood: one located error, fast ---------------------------------

HANG_SECONDS = 10.0  # far below a hang, far above the ~0.1 s these take on a loaded machine


def _one_error(text: str) -> Diagnostic:
    """The single error of reading `text`, which must come without a hang (an alias bomb expanded
    takes minutes; the bound is loose, so that a loaded CI machine does not fail it)."""
    start = time.perf_counter()
    with pytest.raises(SpecError) as caught:
        load_spec_text(text, "f.yaml")
    assert time.perf_counter() - start < HANG_SECONDS, "bad input must be refused, not expanded"
    (d,) = caught.value.errors
    assert d.file == "f.yaml" and d.line is not None and d.column is not None
    return d


@pytest.mark.parametrize(
    ("text", "line", "column", "message"),
    [
        ("a: &a [1, *a]\n", 1, 11, "alias *a refers to a value that contains it"),
        ("a: &a {b: {c: *a}}\n", 1, 15, "recursive alias"),
        ("a: *nowhere\n", 1, 4, "names no anchor"),
        ("a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(f"{c}: &{c} [{', '.join(['*' + p] * 10)}]\n"
                                                       for p, c in zip("abcd", "bcde")), 4, 36, "alias *c is expanded"),
        ("a: " + "[" * 500 + "]" * 500 + "\n", 1, 35, "nested deeper than 32 levels"),  # at the 32nd [
        ("a:\n" + "".join("  " * i + f"k{i}:\n" for i in range(1, 40)), 32, 63, "nested deeper than 32 levels"),
        ("a: [" + ", ".join(["0"] * 100_000) + "]\n", 1, 29_996, "more than 10000 values"),  # at the 9,999th 0
        ("version: " + "9" * 400 + "\n", 1, 10, "a whole number of 400 characters"),
        ("version: " + "9" * 5000 + "\n", 1, 10, "a whole number of 5000 characters"),
        ("version: !!timestamp 2001-13-45\n", 1, 10, "invalid YAML value: month must be in 1..12"),
        ("version: !!int x\n", 1, 10, "invalid YAML value"),
        ("a: 1\n? [1, 2]\n: 3\n", 2, 3, "keys must be text, got a sequence"),
        ("a: 1\nb: 'x\0y'\n", 2, 6, "U+0000 is not allowed"),
        ("a: 1\nb:\n  - c\x07\n", 3, 6, "U+0007 is not allowed"),
    ],
    ids=["recursive-alias", "recursive-alias-deep", "undefined-alias", "alias-bomb", "500-deep", "40-deep-mapping",
         "100k-list", "400-digits", "5000-digits", "bad-date", "bad-int-tag", "list-key", "nul", "bell"],
)
def test_hostile_yaml_is_one_located_error(text: str, line: int, column: int, message: str) -> None:
    d = _one_error(text)
    assert (d.line, d.column) == (line, column) and message in d.message, str(d)


@pytest.mark.parametrize(("value", "message"), [
    ("yes", "'yes' is not allowed; allowed: 1"), ("true", "expected the number 1, got true"),
    ("2001-13-45", "'2001-13-45' is not allowed"), ("'1'", "remove the quotes"),
])
def test_version_is_the_number_1(value: str, message: str) -> None:
    d = _one_error(SPEC.replace("version: 1", f"version: {value}"))
    assert d.path == ("version",) and message in d.message


def test_a_long_wrong_value_is_quoted_not_printed() -> None:
    d = _one_error(SPEC.replace("name: reach", "name: " + "é" * 5000))
    assert d.message == "at most 64 characters, got 5000"
    d = _one_error(SPEC.replace("joint_torque: {max: 100}", "joint_torque: {max: 100, unit: " + "N" * 5000 + "}"))
    assert len(d.message) < 200 and "(5002 characters)" in d.message


def test_many_errors_are_capped_with_a_count(tmp_path: Path) -> None:
    text = SPEC.split("tasks:")[0] + "tasks: [" + ", ".join(["1"] * 5000) + "]\n"
    with pytest.raises(SpecError) as caught:
        load_spec_text(text, "f.yaml")
    shown = caught.value.diagnostics
    assert len(shown) == MAX_DIAGNOSTICS + 1 and len(caught.value.errors) == MAX_DIAGNOSTICS
    note = shown[-1]
    assert note.severity == "info" and f"{5000 - MAX_DIAGNOSTICS} more problems not shown" in note.message
    assert note.line == 13 and note.column is not None  # where the first one left out is
    assert len(str(caught.value)) < 10_000


def test_errors_come_before_warnings_when_capped() -> None:
    warnings = [Diagnostic(f"w{i}", "warning", "f.yaml", i + 1, 1) for i in range(MAX_DIAGNOSTICS)]
    error = Diagnostic("e", "error", "f.yaml", 99, 1)
    kept = SpecError([*warnings, error]).diagnostics
    assert error in kept and kept[-1].message.startswith("1 more problems not shown (0 errors)")


def test_big_and_endless_files_are_refused(tmp_path: Path) -> None:
    big = tmp_path / "big.yaml"
    big.write_bytes(b"# padding\n" * (MAX_BYTES // 10 + 1))
    for path in (big, Path("/dev/zero")):
        if not path.exists():
            continue
        start = time.perf_counter()
        with pytest.raises(SpecError) as caught:
            read_yaml_file(path)
        assert time.perf_counter() - start < HANG_SECONDS  # (/dev/zero: refused, not read to the end)
        (d,) = caught.value.diagnostics
        assert (d.line, d.column) == (1, 1) and "larger than 1000 kB" in d.message


def test_bytes_that_are_not_utf8_are_located(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_bytes(b"a: 1\nb: \xff\n")
    with pytest.raises(SpecError) as caught:
        read_yaml_file(path)
    (d,) = caught.value.diagnostics
    assert (d.line, d.column) == (2, 4) and "0xff is not UTF-8" in d.message


# --- numeric ranges: what validation accepts, the compiler builds ------------------------------------


@pytest.mark.parametrize(("old", "new", "path", "message"), [
    ("joint_torque: {max: 100}", "joint_torque: {max: 1e308, allow_outside_urdf: true}", ("limits", "joint_torque", "max"),
     "must be > 0 and ≤ 1e6 Nm (N for a prismatic joint), got 1e308"),
    ("joint_torque: {max: 100}", "joint_torque: {max: 100}\n  joint_velocity: {max: [1, 1, 1, 1, 1, 1, 1e308]}",
     ("limits", "joint_velocity", "max"), "item 6: must be > 0 and ≤ 1e4, got 1e308"),
    ("kp: [100, 100, 200]", "kp: 1e200", ("tasks", 0, "gains", "kp"), "must be ≥ 0 and ≤ 1e8 1/s², got 1e200"),
    ("priority: 2", "priority: 1001", ("tasks", 1, "priority"), "must be ≥ 1 and ≤ 1000, got 1001"),
    ("model: iiwa14", "model: iiwa14\n  locked_joints: {joint7: 1e300}", ("robot", "locked_joints", "joint7"),
     "must be ≥ -1e4 and ≤ 1e4, got 1e300"),
])
def test_numbers_out_of_range_name_the_range(old: str, new: str, path: tuple, message: str) -> None:
    d = _one_error(SPEC.replace(old, new))
    assert d.path == path and message in d.message, str(d)


@pytest.mark.parametrize("weights", ["[0, 1]", "[1, -1]", "[1e21, 1]"])
def test_priority_weights_out_of_range(weights: str) -> None:
    d = _one_error(SPEC + f"controller: {{formulation: qp_mt, priority_weights: {weights}}}\n")
    assert d.path == ("controller", "priority_weights") and "must be ≥ 1e-10 and ≤ 1e20" in d.message


EXTREMES = SPEC.replace("""  joint_position:
    min: [-160, -110, -160, -110, -160, -110, -170]
    max: 160
    unit: deg
""", "").replace("joint_torque: {max: 100}", (
    "joint_torque: {max: 1e6, allow_outside_urdf: true}\n"
    "  joint_velocity: {max: 1e4, allow_outside_urdf: true}\n"
    "  joint_acceleration: {max: 1e7}\n"
    "  cartesian: [{frame: tool, axis: z, min: -1e3, max: 1e3, max_velocity: 1e3, max_acceleration: 1e5}]"
)).replace("kp: [100, 100, 200], kd: 20", "kp: 1e8, kd: 1e5, max_velocity: 1e3")


@pytest.mark.parametrize(("formulation", "settings"), [
    ("dcts", "fallback_damping: 1e5"),
    ("qp_md", "priority_weights: [1e20, 1e-10], regularization_weight: 1e6, joint_damping: 1e4"),
])
def test_the_extremes_of_every_range_build_a_controller(formulation: str, settings: str) -> None:
    """Validation's ranges are ones the compiler builds: the limits of the ranges at once give a
    controller whose step is finite (a torque limit of 1e308 or a weight of 0 did not)."""
    from dcts_spec.controller import build_controller
    from dcts_spec.validate import validate_spec

    spec = load_spec_text(EXTREMES + f"controller: {{formulation: {formulation}, period: 1e-5, {settings}}}\n", "f.yaml")
    report = validate_spec(spec)
    controller = build_controller(spec)
    result = controller.step(report.initial_q, np.zeros(7))
    assert np.all(np.isfinite(result.tau))


# --- units, scalar-or-list fields --------------------------------------------------------------------------


def test_to_si() -> None:
    assert to_si(180, "deg") == pytest.approx(math.pi)
    assert to_si([90, -45], "deg") == pytest.approx([math.pi / 2, -math.pi / 4])
    assert to_si((30,), "deg/s") == pytest.approx([math.pi / 6])
    assert to_si(360, "deg/s^2") == pytest.approx(2 * math.pi)
    assert to_si(1.5, "rad") == 1.5 and to_si(2, "rad/s^2") == 2.0
    assert to_si([10, 20], "Nm") == [10.0, 20.0]
    assert to_si(0.3, "m") == 0.3
    assert to_si(None, "deg") is None
    assert isinstance(to_si(2, "rad"), float)
    assert all(isinstance(v, float) for v in to_si([1, 2], "rad"))  # type: ignore[union-attr]
    with pytest.raises(KeyError):
        to_si(1.0, "furlong")


def test_scalar_or_list_fields() -> None:
    spec = load_spec_text(SPEC)
    jp = spec.limits.joint_position
    assert jp is not None
    assert jp.min == (-160.0, -110.0, -160.0, -110.0, -160.0, -110.0, -170.0) and jp.max == 160.0
    assert size_of(jp.min) == 7 and size_of(jp.max) is None and size_of(None) is None
    assert as_list(jp.max, 3) == [160.0, 160.0, 160.0]
    assert as_list(jp.min, 7) == list(jp.min)
    assert spec.limits.joint_torque is not None and spec.limits.joint_torque.max == 100.0
    gains = spec.tasks[0].gains
    assert gains.kp == (100.0, 100.0, 200.0) and gains.kd == 20.0
    assert all(isinstance(v, float) for v in gains.kp)  # type: ignore[union-attr]


@pytest.mark.parametrize(
    ("value", "message"),
    [("[]", "empty list"), ("true", "got true"), ("fast", "got 'fast'"), ("[1, two]", "item 1"), (".nan", "got nan")],
)
def test_scalar_or_list_rejects(value: str, message: str) -> None:
    (d,) = _errors(SPEC.replace("joint_torque: {max: 100}", f"joint_torque: {{max: {value}}}"))
    assert (d.line, d.path) == (8, ("limits", "joint_torque", "max"))
    assert message in d.message


def test_number_constraints_are_enforced() -> None:
    (d,) = _errors(SPEC + "controller: {period: 0}\n")
    assert (d.line, d.path) == (26, ("controller", "period")) and "must be ≥ 1e-5 and ≤ 0.1 s, got 0" in d.message
    (d,) = _errors(SPEC + "controller: {period: 1}\n")
    assert "must be ≥ 1e-5 and ≤ 0.1 s, got 1" in d.message
    (d,) = _errors(SPEC + "scenario: {duration: -1}\n")
    assert d.path == ("scenario", "duration") and "must be > 0 and ≤ 1e4 s" in d.message
    (d,) = _errors(SPEC.replace("priority: 2", "priority: true"))
    assert d.path == ("tasks", 1, "priority") and "whole number" in d.message


# --- defaults ----------------------------------------------------------------------------------------------


def test_defaults() -> None:
    spec = load_spec_text(SPEC)
    assert spec.version == 1 and spec.name == "reach"
    ctl = spec.controller
    assert (ctl.formulation, ctl.solver, ctl.period, ctl.external_torque) == ("dcts", "daqp", 0.001, "measured")
    assert ctl.priority_weights is None and ctl.joint_damping == 5.0 and ctl.regularization_weight == 1e-4
    assert spec.limits.joint_velocity is None and spec.limits.cartesian == []
    assert spec.limits.joint_position is not None and spec.limits.joint_position.allow_outside_urdf is False
    assert spec.robot.locked_joints == {} and spec.robot.urdf is None
    camera = spec.robot.frames["camera"]
    assert camera.rpy == (0.0, 0.0, 0.0) and camera.unit == "rad" and camera.xyz == (0.0, 0.05, 0.08)
    assert spec.scenario is None
    tool, damping = spec.tasks
    assert tool.axes is None and tool.axis_names == ("x", "y", "z") and tool.cartesian_dimension == 3
    assert tool.reference is not None and tool.reference.unit == "rad" and not tool.reference.input
    assert tool.gains.max_velocity is None
    assert damping.joints is None and damping.reference is None and damping.cartesian_dimension is None
    assert spec.priority_levels == [1, 2] and spec.tasks_at(2) == [damping]


def test_scenario_defaults_and_short_forms() -> None:
    spec = load_spec_text(SPEC + "scenario: {duration: 2, external_torque: noisy}\n")
    sc = spec.scenario
    assert sc is not None
    assert (sc.unit, sc.substeps, sc.integrator, sc.initial_q) == ("rad", 1, "rk4", None)
    assert sc.disturbances == [] and sc.payloads == [] and sc.waypoints is None
    assert sc.sensing.mode == "noisy" and sc.sensing.noise_std == 0.0 and sc.sensing.seed == 0
    spec = load_spec_text(SPEC + "scenario: {duration: 2, external_torque: {mode: noisy, noise_std: 0.5}}\n")
    assert spec.scenario is not None and spec.scenario.sensing.noise_std == 0.5


def test_axes_define_the_cartesian_dimension() -> None:
    spec = load_spec_text(SPEC.replace("frame: tool\n", "frame: tool\n    axes: [z, x]\n").replace("[100, 100, 200]", "[1, 2]"))
    assert spec.tasks[0].axis_names == ("z", "x") and spec.tasks[0].cartesian_dimension == 2


def test_source_and_base_dir(tmp_path: Path) -> None:
    path = tmp_path / "reach.yaml"
    path.write_text(SPEC, encoding="utf-8")
    spec = load_spec(path)
    assert spec.source.file == str(path) and spec.base_dir == tmp_path
    assert spec.source.locate(("tasks", 1, "gains", "kd")) == (25, 7)


# --- messages ----------------------------------------------------------------------------------------------


def test_unknown_key_suggests_and_lists_allowed_keys() -> None:
    errors = _errors(SPEC.replace("      kd: 5", "      kd: 5\n      max_vel: 1"))
    (d,) = [d for d in errors if "max_vel" in d.message]
    assert (d.line, d.column, d.path) == (26, 7, ("tasks", 1, "gains", "max_vel"))
    assert "did you mean 'max_velocity'" in d.message and "allowed keys: kp, kd, max_velocity" in d.message


def test_discriminated_union_entry_with_a_key_named_like_its_type() -> None:
    scenario = "scenario:\n  duration: 2\n  disturbances:\n    - {type: force, body: link7, force: [0, 0, 1], strat: 1, duration: 1}\n"
    errors = _errors(SPEC + scenario)
    (typo,) = [d for d in errors if "strat" in d.message]
    assert typo.path == ("scenario", "disturbances", 0, "strat") and typo.line == 29
    assert "did you mean 'start'" in typo.message


def test_union_reports_the_specific_alternative_only() -> None:
    (d,) = _errors(SPEC + "scenario: {duration: 2, external_torque: {mode: noisey}}\n")
    assert d.path == ("scenario", "external_torque", "mode") and "did you mean 'noisy'" in d.message


def test_literal_messages() -> None:
    (d,) = _errors(SPEC.replace("version: 1", "version: 2"))
    assert d.message == "2 is not allowed; allowed: 1"
    (d,) = _errors(SPEC.replace("version: 1", "version: '1'"))
    assert "remove the quotes" in d.message
    (d,) = _errors(SPEC.replace("type: joint", "type: joints"))
    assert d.line == 21 and "did you mean 'joint'" in d.message


@pytest.mark.parametrize("old, new, message", [
    ("type: joint", "type: null", "tasks[1].type: null is not allowed; allowed: position, orientation, pose, joint"),
    ("type: joint", "type: true", "tasks[1].type: true is not allowed; allowed:"),
    ("frame: tool", "frame: false", "tasks[0].frame: expected text, got false"),
])
def test_yaml_literals_are_spelled_as_yaml_spells_them(old: str, new: str, message: str) -> None:
    """A user wrote null/true/false, not Python's None/True/False; and null is no misspelt 'pose'."""
    (d,) = _errors(SPEC.replace(old, new))
    assert message in str(d) and "None" not in d.message and "did you mean" not in d.message


def test_field_errors_point_at_the_blamed_key() -> None:
    (d,) = _errors(SPEC.replace("kd: 20}", "kd: [20, 20]}"))
    assert d.path == ("tasks", 0, "gains") and "kd has 2 values but the task has 3 axes" in d.message
    (d,) = _errors(SPEC.replace("      kp: 0\n      kd: 5", "      kp: 0\n      kd: -5"))
    assert (d.line, d.path) == (25, ("tasks", 1, "gains", "kd"))


def test_helpers() -> None:
    assert format_path(("tasks", 0, "gains", "kp")) == "tasks[0].gains.kp"
    assert format_path(()) == "<document>"
    assert did_you_mean("prority", ["priority", "gains"]) == " (did you mean 'priority'?)"
    assert did_you_mean("zzz", ["priority", "gains"]) == ""
    d = Diagnostic("bad", "error", "f.yaml", 3, 5, ("a", 1))
    assert d.to_dict() == {"severity": "error", "file": "f.yaml", "line": 3, "column": 5, "path": "a[1]", "message": "bad"}
    assert str(SpecError([d, Diagnostic("meh", "warning")])) == "f.yaml:3:5: error: a[1]: bad\n<spec>: warning: meh"
    assert SpecError([d, Diagnostic("meh", "warning")]).errors == [d]


def test_closed_sets_match_what_the_compiler_offers():
    """The spec's allowed formulations and built-in robots are the ones the compiler has."""
    import typing

    from dcts_spec.formulations import FORMULATIONS
    from dcts_spec.robot.builtin import BUILTIN_ROBOTS
    from dcts_spec.spec.controller import Formulation
    from dcts_spec.spec.robot import RobotSpec

    assert set(typing.get_args(Formulation)) == set(FORMULATIONS)
    robots = typing.get_args(RobotSpec.model_fields["model"].annotation)
    assert {r for arg in robots for r in typing.get_args(arg)} == set(BUILTIN_ROBOTS)


@pytest.mark.parametrize("name", ["api", "daqp", "Utils", "types"])
def test_a_spec_named_like_a_daqp_file_is_refused(name: str) -> None:
    """`name: api` validated, and the bundle's api.h then shadowed DAQP's: the C did not compile
    (first seen from outside)."""
    text = (Path(__file__).resolve().parents[1] / "specs" / "minimal.yaml").read_text()
    with pytest.raises(SpecError) as caught:
        load_spec_text(text.replace("name: minimal", f"name: {name}"))
    assert "is the name of one of DAQP's C files" in str(caught.value) and ":4:" in str(caught.value)
    load_spec_text(text.replace("name: minimal", "name: api_arm"))


@pytest.mark.parametrize("name", ["math", "time", "String"])
def test_a_spec_named_like_a_c_standard_header_is_refused(name: str) -> None:
    """`name: math` validated, and its math.h then shadowed the system's where CMake put the
    bundle's folder on the include path: the bundle's own CMake build did not compile (found from
    outside)."""
    text = (Path(__file__).resolve().parents[1] / "specs" / "minimal.yaml").read_text()
    with pytest.raises(SpecError) as caught:
        load_spec_text(text.replace("name: minimal", f"name: {name}"))
    assert "is the name of a C standard header" in str(caught.value) and ":4:" in str(caught.value)
    load_spec_text(text.replace("name: minimal", "name: math_arm"))
