"""Start-up: `import dcts_spec`, `dcts --help`, `--version` and rejecting a broken spec load no
solver or simulator (CasADi, Pinocchio, MuJoCo take ~0.7 s to import), and the public API still
resolves its lazily imported names."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

import dcts_spec

HEAVY = ("casadi", "pinocchio", "mujoco")

# Runs the command line in a fresh interpreter, then prints which heavy modules it imported.
_RUN_CLI = """
import json, sys
from dcts_spec.cli import main
sys.argv = ["dcts", *json.loads(sys.argv[1])]
try:
    main()
except SystemExit:
    pass
print(json.dumps([m for m in {heavy!r} if m in sys.modules]))
"""


def _python(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=120)


def test_import_loads_no_solver() -> None:
    check = f"import dcts_spec, sys; loaded = [m for m in {HEAVY!r} if m in sys.modules]; assert not loaded, loaded"
    result = _python("-c", check)
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize("content", [
    "version: 1\nname: x\nrobot: {model: iiwa14\n",  # YAML error
    "version: 1\nname: x\nrobot: {model: iiwa14}\ntasks:\n  - {name: a, type: positon, frame: tool}\n",  # schema
], ids=["yaml", "schema"])
def test_validate_rejects_a_broken_spec_without_solvers(tmp_path: Path, content: str) -> None:
    spec = tmp_path / "broken.yaml"
    spec.write_text(content)
    result = _python("-c", _RUN_CLI.format(heavy=HEAVY), json.dumps(["validate", str(spec)]))
    assert f"{spec}:" in result.stderr  # the located error was printed
    assert json.loads(result.stdout.splitlines()[-1]) == []


@pytest.mark.parametrize("args", [["--help"], ["--version"], ["validate", "--help"]])
def test_help_and_version_load_no_solver(args: list[str]) -> None:
    result = _python("-c", _RUN_CLI.format(heavy=HEAVY), json.dumps(args))
    assert result.stdout.strip(), result.stderr
    assert json.loads(result.stdout.splitlines()[-1]) == []


def test_version_names_the_libraries() -> None:
    result = _python("-c", _RUN_CLI.format(heavy=HEAVY), json.dumps(["--version"]))
    assert result.stdout.startswith("dcts ") and "casadi " in result.stdout and "pinocchio " in result.stdout


def test_public_api_resolves_every_name() -> None:
    from dcts_spec import codegen, controller, spec, validate
    from dcts_spec.analysis import simulate

    homes = {"compile_c": codegen, "compiled_controller": codegen, "Controller": controller, "StepResult": controller,
             "build_controller": controller, "Spec": spec, "SpecError": spec, "load_spec": spec,
             "simulate": simulate, "validate_spec": validate}
    assert set(dcts_spec.__all__) == set(homes)
    for name, module in homes.items():
        assert getattr(dcts_spec, name) is getattr(module, name), name
    assert set(dcts_spec.__all__) <= set(dir(dcts_spec))
    with pytest.raises(AttributeError, match="no_such_name"):
        dcts_spec.no_such_name  # noqa: B018
