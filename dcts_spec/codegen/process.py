"""Run one build step (make, a compiler, a harness): its own process group, a time-out, progress.

A step runs in a new session, so that on a time-out, Ctrl-C or SIGTERM the whole group (make
and the compilers it started) is ended, not make alone: a 48-joint compile left gcc running as
an orphan with 5.8 GB. While it runs, the step reports the C files make starts compiling and,
every `HEARTBEAT_S`, how long it has been running (compiling a 28-joint controller takes a minute).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import threading
import time
from pathlib import Path

from ..phases import phase
from .bundle import CodegenError

TIMEOUT_VARIABLE = "DCTS_BUILD_TIMEOUT"
DEFAULT_TIMEOUT_S = 600.0
HEARTBEAT_S = 15.0
# A compiler command as make echoes it: `cc ... -c foo_casadi.c -o build/…/foo_casadi.o`
_COMPILING = re.compile(r"\s-c\s+(\S+\.c)\b")


def build_timeout(seconds: float | None = None) -> float:
    """The time-out of each build step: `seconds` if given, else $DCTS_BUILD_TIMEOUT, else 600 s."""
    if seconds is not None:
        if not seconds > 0:
            raise CodegenError(f"the build time-out must be positive, got {seconds:g} s")
        return float(seconds)
    text = os.environ.get(TIMEOUT_VARIABLE, "").strip()
    if not text:
        return DEFAULT_TIMEOUT_S
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value > 0:
        raise CodegenError(f"{TIMEOUT_VARIABLE}={text!r}: not a time-out; give a positive number of seconds")
    return value


def tail(text: str, lines: int = 40) -> str:
    return "\n".join(text.strip().splitlines()[-lines:])


def _describe_compile(line: str, cwd: Path) -> str | None:
    """'compiling foo_casadi.c (2.9 MB)' for a compiler command make echoed, else None."""
    found = _COMPILING.search(line)
    if found is None:
        return None
    source = Path(found.group(1))
    path = source if source.is_absolute() else cwd / source
    try:
        size = path.stat().st_size
    except OSError:
        return None
    if size < 100_000:  # the small files take a second or two: not worth a line each
        return None
    return f"compiling {source.name} ({size / 1e6:.1f} MB of C)"


def _end_group(process: subprocess.Popen) -> None:
    """End the step's whole process group (make, the compilers it started, their children)."""
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    process.wait()


class Step:
    """A build step started in the background (`start`): `wait` finishes it as `run` does, `end`
    ends its process group (a caller that gives up on it: an error, Ctrl-C, SIGTERM)."""

    def __init__(self, command: list[str], cwd: Path, what: str, env: dict | None, timeout: float | None) -> None:
        self.what, self.cwd, self.limit = what, Path(cwd), build_timeout(timeout)
        try:
            self.process = subprocess.Popen(command, cwd=cwd, env=env, stdout=subprocess.PIPE,
                                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True,
                                            errors="replace", start_new_session=True)
        except FileNotFoundError as exc:
            raise CodegenError(f"{what}: {exc.filename} not found") from None
        self.start = time.monotonic()
        self.lines: list[str] = []
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.lines.append(line)
            started = _describe_compile(line, self.cwd)
            if started:
                phase(f"{self.what}: {started}")

    def end(self) -> None:
        """End the step's process group, if it still runs."""
        if self.process.poll() is None:
            _end_group(self.process)
        self.reader.join(timeout=5)

    def wait(self) -> str:
        """Its output (stdout and stderr); a failure or a time-out (counted from its start) raises
        CodegenError with the end of it."""
        process, limit, timed_out = self.process, self.limit, False
        try:
            while process.poll() is None:
                elapsed = time.monotonic() - self.start
                if elapsed >= limit:
                    timed_out = True
                    break
                try:
                    process.wait(timeout=min(HEARTBEAT_S, limit - elapsed))
                except subprocess.TimeoutExpired:
                    if time.monotonic() - self.start < limit:
                        phase(f"{self.what}: still running after {time.monotonic() - self.start:.0f} s "
                              f"(time-out {limit:.3g} s)")
        except BaseException:
            _end_group(process)  # Ctrl-C, SIGTERM: the new session does not get the terminal's signal
            raise
        finally:
            if timed_out:
                _end_group(process)
            self.reader.join(timeout=5)
        if timed_out:
            raise CodegenError(f"{self.what}: timed out after {limit:.3g} s; its processes were ended (allow "
                               f"more with --build-timeout SECONDS or {TIMEOUT_VARIABLE})")
        output = "".join(self.lines)
        if process.returncode != 0:
            raise CodegenError(f"{self.what} failed (exit code {process.returncode}):\n{tail(output)}")
        return output


def start(command: list[str], cwd: Path, what: str, env: dict | None = None, timeout: float | None = None) -> Step:
    """Start a build step in its own process group; `Step.wait` finishes it."""
    return Step(command, cwd, what, env, timeout)


def run(command: list[str], cwd: Path, what: str, env: dict | None = None, timeout: float | None = None) -> str:
    """Run a build step; its output (stdout and stderr) is returned, a failure or a time-out
    (`build_timeout(timeout)`) raises CodegenError with the end of it."""
    return start(command, cwd, what, env, timeout).wait()
