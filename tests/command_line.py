"""Running the `dcts` command line of this environment from the tests."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from typer.testing import CliRunner

from dcts_spec.cli import app

ROOT = Path(__file__).resolve().parents[1]
MINIMAL = ROOT / "specs" / "minimal.yaml"


def dcts(*args: str, cwd: Path = ROOT, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run `dcts ARGS` (the installed script, or the module when there is none) and capture its output."""
    script = Path(sys.executable).with_name("dcts")
    command = [str(script)] if script.is_file() else [sys.executable, "-c", "from dcts_spec.cli import main; main()"]
    return subprocess.run([*command, *args], cwd=cwd, capture_output=True, text=True, timeout=timeout)


def invoke(*args: str):
    """Run `dcts ARGS` in this process (faster than `dcts`; stdout and stderr kept apart)."""
    return CliRunner().invoke(app, list(args), env={"COLUMNS": "200"})


def short_spec(folder: Path, name: str = "short") -> Path:
    """specs/minimal.yaml under another name, with a 0.03 s scenario, written into `folder`."""
    text = MINIMAL.read_text().replace("name: minimal", f"name: {name}").replace("duration: 2.0", "duration: 0.03")
    path = folder / f"{name}.yaml"
    path.write_text(text)
    return path
