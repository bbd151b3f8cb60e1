"""Running the `dcts` command line of this environment from the tests."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def dcts(*args: str, cwd: Path = ROOT, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run `dcts ARGS` (the installed script, or the module when there is none) and capture its output."""
    script = Path(sys.executable).with_name("dcts")
    command = [str(script)] if script.is_file() else [sys.executable, "-c", "from dcts_spec.cli import main; main()"]
    return subprocess.run([*command, *args], cwd=cwd, capture_output=True, text=True, timeout=timeout)
