"""Long phases say what they do on stderr (building, generating C, compiling, simulating, plotting);
`--quiet` silences them, and stdout stays the command's result."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from command_line import invoke, short_spec

from dcts_spec.phases import phase, reporting


@pytest.fixture(autouse=True)
def _private_bundle_cache(tmp_path_factory, monkeypatch):
    """No test writes into the user's bundle cache."""
    monkeypatch.setenv("DCTS_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "bundle-cache"))


def test_phases_go_to_the_installed_reporter_only() -> None:
    heard: list[str] = []
    phase("nobody listens")
    with reporting(heard.append):
        phase("one")
        with reporting(None):
            phase("silenced")
        phase("two")
    phase("after")
    assert heard == ["one", "two"]


def test_compile_says_what_it_does_on_stderr(tmp_path: Path) -> None:
    spec = short_spec(tmp_path)
    result = invoke("compile", str(spec), "--no-build", "-o", str(tmp_path / "b"))
    assert result.exit_code == 0, result.output
    assert "building the symbolic model and the dcts control law of short" in result.stderr
    assert "generating C" in result.stderr and "compiling C" not in result.stderr  # --no-build
    assert "building" not in result.stdout and result.stdout.startswith("wrote ")
    # -q silences stderr; --json prints the report alone (one compile for both: each costs ~5 s)
    as_json = invoke("compile", str(spec), "--no-build", "-o", str(tmp_path / "b"), "--json", "-q")
    assert as_json.exit_code == 0 and as_json.stderr == "" and json.loads(as_json.stdout)["name"] == "short"


@pytest.mark.skipif(shutil.which("make") is None or shutil.which("cc") is None, reason="no make or C compiler")
def test_compile_announces_the_c_build(tmp_path: Path) -> None:
    result = invoke("compile", str(short_spec(tmp_path)), "-o", str(tmp_path / "b"))
    assert result.exit_code == 0, result.output
    said = result.stderr
    assert "compiling C (and computing the golden vectors meanwhile)" in said
    assert said.index("golden vectors meanwhile") < said.index("compiling the golden-vector test and running it")


def test_simulate_announces_each_phase_and_quiet_silences_them(tmp_path: Path) -> None:
    spec = short_spec(tmp_path)
    result = invoke("simulate", str(spec), "--runtime", "python", "-o", str(tmp_path / "run"))
    assert result.exit_code == 0, result.output
    said = result.stderr.splitlines()
    assert [line.split(" ")[0] for line in said] == ["building", "simulating", "writing"], said
    assert "simulating short: dcts (python): 0.03 s in 30 control steps" in said[1]
    assert "and plots" in said[2]
    assert "wrote " in result.stdout
    # (without plots: writing them again took half of this test)
    quiet = invoke("simulate", str(spec), "--runtime", "python", "-o", str(tmp_path / "run"), "-q", "--no-plots")
    assert quiet.exit_code == 0 and quiet.output == ""


def test_compare_announces_each_run_and_the_comparison(tmp_path: Path) -> None:
    result = invoke("compare", str(short_spec(tmp_path)), "--runtime", "python", "--formulations", "dcts,osc",
                    "--no-plots", "-o", str(tmp_path / "cmp"))
    assert result.exit_code == 0, result.output
    assert result.stderr.count("simulating short:") == 2
    assert "writing the comparison …" in result.stderr  # no plots announced with --no-plots


def test_validate_check_announces_the_compilation(tmp_path: Path) -> None:
    spec = short_spec(tmp_path)
    result = invoke("validate", "--check", str(spec))
    assert result.exit_code == 0, result.output
    assert "compiling short with every formulation" in result.stderr
    assert invoke("validate", "--check", "-q", str(spec)).stderr == ""
