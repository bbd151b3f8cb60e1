"""The command line's conventions: one output option and default rule, choices in the help, no
`<bool>` metavars, exit 2 for usage errors and 1 for bad specs, `--json` always a list."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from command_line import MINIMAL, invoke, short_spec
from typer.testing import CliRunner

from dcts_spec import cli
from dcts_spec.cli import app
from dcts_spec.formulations import FORMULATIONS
COMMANDS = ("validate", "schema", "simulate", "compare", "sweep", "compile", "bench", "robots", "describe", "init")
WRITERS = ("schema", "simulate", "compare", "compile")

runner = CliRunner()


@pytest.fixture(autouse=True)
def _private_bundle_cache(tmp_path_factory, monkeypatch):
    """No test writes into the user's bundle cache."""
    monkeypatch.setenv("DCTS_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "bundle-cache"))


@pytest.mark.parametrize("command", COMMANDS)
def test_help_shows_no_bool_metavar(command: str) -> None:
    result = invoke(command, "--help")
    assert result.exit_code == 0, result.output
    assert "<bool>" not in result.output


def test_root_help_states_the_output_rule_and_exit_codes() -> None:
    result = invoke("--help")
    assert result.exit_code == 0 and "<bool>" not in result.output
    text = " ".join(result.output.split())
    for phrase in ("build/<name>", "runs/<name>", "runs/<name>-compare", "2 a usage error", "1 a bad spec"):
        assert phrase in text


@pytest.mark.parametrize("command", WRITERS)
def test_every_writer_takes_out_and_o(command: str) -> None:
    output = invoke(command, "--help").output
    assert re.search(r"--out\s+-o", output), output
    assert "--output" not in output  # the old spelling works but is not advertised


@pytest.mark.parametrize("command", ("simulate", "compile", "bench"))
def test_formulation_help_lists_the_choices(command: str) -> None:
    output = invoke(command, "--help").output
    assert "|".join(FORMULATIONS) in output


def test_compare_help_lists_the_choices() -> None:
    assert ", ".join(FORMULATIONS) in " ".join(invoke("compare", "--help").output.split())


@pytest.mark.parametrize("args", [
    ("simulate", str(MINIMAL), "--runtime", "fortran"),
    ("simulate", str(MINIMAL), "--formulation", "nope"),
    ("simulate", str(MINIMAL), "--duration", "-1"),
    ("simulate", str(MINIMAL), "--duration", "0"),
    ("simulate", str(MINIMAL), "--duration", "inf"),  # (a MemoryError or OverflowError, exit 3, before)
    ("compare", str(MINIMAL), "--duration", "1e9"),
    ("simulate", str(MINIMAL), "--no-such-option"),
    ("compare", str(MINIMAL), "--formulations", "dcts,nope"),
    ("compare", str(MINIMAL), "--formulations", ","),
    ("compare", str(MINIMAL), "--formulations", "dcts,osc,dcts"),
    ("compare", str(MINIMAL), "--runtime", "fortran"),
    ("compile", str(MINIMAL), "--target", "z80"),
    ("compile", str(MINIMAL), "--formulation", "nope"),
    ("bench", str(MINIMAL), "--states", "0"),
    ("validate",),
    ("nosuchcommand",),
])
def test_usage_errors_exit_2(args: tuple[str, ...], tmp_path: Path) -> None:
    result = runner.invoke(app, [*args, "--out", str(tmp_path / "out")] if args[0] in ("simulate", "compare")
                           else list(args))
    assert result.exit_code == 2, result.output
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("args", [
    ("simulate", str(MINIMAL), "--out"), ("simulate", str(MINIMAL), "-o"), ("simulate", str(MINIMAL), "--video"),
    ("compare", str(MINIMAL), "--out"), ("compile", str(MINIMAL), "--out"), ("schema", "--out"),
    ("sweep", str(MINIMAL), "--campaign", "c.yaml", "--out"),
])
def test_an_empty_output_path_is_a_usage_error(args: tuple[str, ...], tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """`-o "$OUT"` with OUT unset: not the current folder."""
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(app, [*args, ""])
    assert result.exit_code == 2, result.output
    assert "an empty path" in result.output
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("command", ("validate", "compile", "simulate", "compare", "bench"))
def test_bad_specs_exit_1(command: str, tmp_path: Path) -> None:
    broken = tmp_path / "broken.yaml"
    broken.write_text("version: 1\nname: broken\nrobot: {model: iiwa14}\ntasks: []\nbogus: 1\n")
    args = [command, str(broken)] + (["--out", str(tmp_path / "out")] if command in WRITERS else [])
    result = invoke(*args)
    assert result.exit_code == 1, result.output
    assert "broken.yaml:5" in result.output and "Traceback" not in result.output
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("debug", [False, True])
def test_an_internal_error_exits_3_not_2(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture,
                                         debug: bool) -> None:
    """Exit 3 with DCTS_DEBUG too (it exited 1, "bad spec", with the traceback: found from outside)."""
    def broken_app() -> None:
        raise RuntimeError("a bug")

    monkeypatch.setattr(cli, "app", broken_app)
    if debug:
        monkeypatch.setenv("DCTS_DEBUG", "1")
    else:
        monkeypatch.delenv("DCTS_DEBUG", raising=False)
    with pytest.raises(SystemExit) as exited:
        cli.main()
    assert exited.value.code == 3
    err = capsys.readouterr().err
    assert "RuntimeError: a bug" in err and ("Traceback" in err) == debug


def test_ctrl_c_inside_casadi_exits_130(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    """A Ctrl-C during CasADi's C code surfaces as a SystemError raised while handling the
    KeyboardInterrupt (`DM.__array__ returned a result with an exception set`): an interrupt, 130,
    not an internal error (it was 3, with that message)."""
    def interrupted_app() -> None:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise SystemError("<function DM.__array__> returned a result with an exception set")

    monkeypatch.setattr(cli, "app", interrupted_app)
    monkeypatch.delenv("DCTS_DEBUG", raising=False)
    with pytest.raises(SystemExit) as exited:
        cli.main()
    assert exited.value.code == 130 and "SystemError" not in capsys.readouterr().err


def test_validate_json_is_a_list_for_one_file() -> None:
    result = invoke("validate", "--json", str(MINIMAL))
    assert result.exit_code == 0, result.output
    reports = json.loads(result.stdout)
    assert isinstance(reports, list) and [r["name"] for r in reports] == ["minimal"]


def test_an_unreadable_spec_is_a_report_of_its_own_not_a_usage_error(tmp_path: Path, monkeypatch) -> None:
    """An unreadable spec among others was Click's usage error (exit 2, no JSON, the other reports
    lost; found from outside). The command no longer checks readability itself: the spec loader
    says why it cannot read the file. (As root every file is readable: a refused open stands in.)"""
    import os

    unreadable = tmp_path / "locked.yaml"
    unreadable.write_text(MINIMAL.read_text())
    monkeypatch.setattr(os, "access", lambda path, mode, **_: Path(path) != unreadable)
    real_open = Path.open

    def refusing_open(self, *args, **kwargs):
        if self == unreadable:
            raise PermissionError(13, "Permission denied")
        return real_open(self, *args, **kwargs)

    monkeypatch.setattr(Path, "open", refusing_open)
    result = invoke("validate", "--json", str(MINIMAL), str(unreadable))
    assert result.exit_code == 1, result.output
    reports = json.loads(result.stdout)
    assert [r["valid"] for r in reports] == [True, False]
    assert reports[1]["diagnostics"][0]["message"] == "cannot read the file: Permission denied"


@pytest.mark.parametrize("command", [("validate", str(MINIMAL), str(MINIMAL), str(MINIMAL)), ("describe", "iiwa14")])
def test_a_printing_command_ends_like_a_filter_when_its_reader_stops(command) -> None:
    """`dcts validate a.yaml b.yaml | head -1` exited 1, "a bad spec", for valid specs: Click's
    answer to the closed pipe (found from outside). It ends as `cat` does, by SIGPIPE."""
    import signal
    import sys

    script = Path(sys.executable).with_name("dcts")
    process = subprocess.Popen([str(script), *command], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    process.stdout.close()  # (the reader gone before the first line)
    assert process.wait(timeout=120) == -signal.SIGPIPE


def test_a_named_pipe_is_refused_not_waited_on(tmp_path: Path) -> None:
    """`dcts validate` on a named pipe waited forever for a writer (found from outside)."""
    import os

    pipe = tmp_path / "spec.yaml"
    os.mkfifo(pipe)
    result = invoke("validate", str(pipe))
    assert result.exit_code == 1 and "a named pipe, not a file" in result.output, result.output


def test_schema_out_and_its_old_spelling(tmp_path: Path) -> None:
    for option in ("-o", "--out", "--output"):
        path = tmp_path / f"schema{option}.json"
        result = invoke("schema", option, str(path))
        assert result.exit_code == 0, result.output
        assert json.loads(path.read_text())["title"]


def test_schema_replaces_a_schema_and_no_other_file(tmp_path: Path) -> None:
    """`schema -o` over an older schema rewrites it; over a spec (or any other file), it refuses
    with exit 1 and the file keeps its content (a spec was overwritten)."""
    schema = tmp_path / "schema.json"
    schema.write_text(json.dumps({"$id": "https://dcts.dev/schemas/dcts-spec.schema.json", "title": "old"}))
    assert invoke("schema", "-o", str(schema)).exit_code == 0
    assert json.loads(schema.read_text())["title"] != "old"
    for other, text in (("spec.yaml", "version: 1\nname: mine\n"), ("notes.json", '{"mine": 1}')):
        path = tmp_path / other
        path.write_text(text)
        result = invoke("schema", "-o", str(path))
        assert result.exit_code == 1 and "refusing to overwrite" in result.stderr, result.output
        assert path.read_text() == text


def test_compile_defaults_to_build_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    spec = short_spec(tmp_path)
    monkeypatch.chdir(tmp_path)
    result = invoke("compile", str(spec), "--no-build")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "build" / "short" / "short.h").is_file()
    result = invoke("compile", str(spec), "--no-build", "--output", "old")  # the old spelling
    assert result.exit_code == 0, result.output
    assert (tmp_path / "old" / "short.h").is_file()


def test_the_headers_regenerate_hint_is_a_command_that_works(tmp_path: Path) -> None:
    spec = short_spec(tmp_path)
    bundle = tmp_path / "bundle"
    assert invoke("compile", str(spec), "--no-build", "--formulation", "osc", "-o", str(bundle)).exit_code == 0
    header = (bundle / "short.h").read_text()
    hint = re.search(r"regenerate with `dcts ([^`]*)`", header)
    assert hint, header[:400]
    args = hint.group(1).replace("<this folder>", str(bundle)).split()
    assert args[:2] == ["compile", spec.name]
    (bundle / "short.h").write_text("stale")
    result = runner.invoke(app, [args[0], str(spec), *args[2:], "--no-build"])
    assert result.exit_code == 0, result.output
    assert (bundle / "short.h").read_text().startswith("/*")
    assert json.loads((bundle / "manifest.json").read_text())["formulation"] == "osc"


def test_simulate_and_compare_default_to_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    spec = short_spec(tmp_path)
    monkeypatch.chdir(tmp_path)
    result = invoke("simulate", str(spec), "--runtime", "python", "--no-plots", "-q")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "runs" / "short" / "summary.json").is_file()
    result = invoke("compare", str(spec), "--runtime", "python", "--formulations", "dcts,osc", "--no-plots", "-q")
    assert result.exit_code == 0, result.output
    compared = tmp_path / "runs" / "short-compare"
    assert (compared / "comparison.json").is_file() and (compared / "osc" / "summary.json").is_file()
    assert not list(compared.glob("*.png"))  # --no-plots


@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash to load the completion script into")
def test_shell_completion_is_offered() -> None:
    # the script `--show-completion` prints for bash (that option detects the shell it runs in:
    # under sh it refuses), asked for by name through Click's completion variable
    result = CliRunner().invoke(app, [], env={"_DCTS_COMPLETE": "source_bash"}, prog_name="dcts")
    assert result.exit_code == 0, result.output
    assert "_DCTS_COMPLETE" in result.output
    script = subprocess.run(["bash", "-n"], input=result.output, capture_output=True, text=True)
    assert script.returncode == 0, script.stderr
    assert "--install-completion" in invoke("--help").output



@pytest.mark.parametrize("command", ("validate --check", "compile", "simulate --runtime python"))
def test_a_level_above_the_lowest_over_constrained_everywhere_is_a_located_error(command: str, tmp_path: Path) -> None:
    """The same tool position at priorities 1 and 2 above a damping (3 + 3 directions of 7 joints:
    the count does not show it, every configuration does). Each command says where, and exits 1: validate --check
    said "valid", compile gave no line and simulate --runtime python an internal error (exit 3)."""
    text = MINIMAL.read_text().replace("name: minimal", "name: twice")
    tasks = "".join(f"  - {{name: tool_{p}, type: position, frame: tool, priority: {p}, gains: {{kp: 100, kd: 20}}, "
                    "reference: {position: [0.5, 0.0, 0.5]}}\n" for p in (1, 2))
    tasks += "  - {name: damping, type: joint, priority: 3, gains: {kp: 0, kd: 5}}\n"
    spec = tmp_path / "twice.yaml"
    spec.write_text(text[:text.index("tasks:")] + "tasks:\n" + tasks + text[text.index("scenario:"):])
    args = command.split()
    result = invoke(args[0], str(spec), *args[1:], *(["--out", str(tmp_path / "out")] if args[0] in WRITERS else []))
    assert result.exit_code == 1, result.output
    assert "twice.yaml:" in result.output and "priority 2 is over-constrained" in result.output
    assert "Traceback" not in result.output
    assert not (tmp_path / "out").exists()
