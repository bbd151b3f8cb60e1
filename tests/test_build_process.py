"""Build steps (codegen/process.py): a time-out ends make and every process it started, the
time-out is configurable, a long step says what it compiles and how long it has run, and DAQP's
sources are fetched once, whole."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from dcts_spec.codegen import CodegenError
from dcts_spec.codegen import process as process_module
from dcts_spec.codegen.build import make
from dcts_spec.codegen.bundle import DAQP_VERSION
from dcts_spec.codegen.process import build_timeout, run, start
from dcts_spec.phases import reporting

# A "compiler" that starts a child which outlives it unless its group is ended, then hangs. The
# child's pid is written under another name and renamed, so child.pid never exists empty (CI once
# read it between the shell's open and its echo).
HANGING_MAKEFILE = """all:
\tsleep 300 & echo $$! > child.tmp && mv child.tmp child.pid; sleep 300
"""


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except OSError:
        return False
    return state != "Z"  # a zombie is dead, waiting for init to reap it


def _wait_dead(pid: int, seconds: float = 5.0) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if not _alive(pid):
            return True
        time.sleep(0.05)
    return False


def test_timeout_ends_the_whole_process_group(tmp_path: Path) -> None:
    (tmp_path / "Makefile").write_text(HANGING_MAKEFILE)
    start = time.monotonic()
    with pytest.raises(CodegenError, match=r"host build: timed out after 1 s; its processes were ended"):
        make(tmp_path, ["all"], "host build", timeout=1)
    assert time.monotonic() - start < 10
    child = int((tmp_path / "child.pid").read_text())
    assert _wait_dead(child), f"the build's child {child} survived the time-out"


def test_timeout_from_the_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DCTS_BUILD_TIMEOUT", "0.5")
    assert build_timeout() == 0.5
    assert build_timeout(7) == 7  # an explicit time-out (--build-timeout) wins
    with pytest.raises(CodegenError, match=r"timed out after 0\.5 s"):  # (as given, not rounded to 0 s)
        run(["sleep", "30"], tmp_path, "sleeping")
    monkeypatch.delenv("DCTS_BUILD_TIMEOUT")
    assert build_timeout() == process_module.DEFAULT_TIMEOUT_S


@pytest.mark.parametrize("value", ["ten", "0", "-3", "nan"])
def test_bad_timeout_in_the_environment(value: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DCTS_BUILD_TIMEOUT", value)
    with pytest.raises(CodegenError, match=f"DCTS_BUILD_TIMEOUT='{value}': not a time-out"):
        build_timeout()


def test_failure_keeps_the_end_of_the_output(tmp_path: Path) -> None:
    with pytest.raises(CodegenError, match=r"(?s)failing step failed \(exit code 3\):\nout\nerr"):
        run(["sh", "-c", "echo out; echo err >&2; exit 3"], tmp_path, "failing step")


def test_progress_names_large_sources_and_the_time_so_far(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(process_module, "HEARTBEAT_S", 0.2)
    (tmp_path / "big_casadi.c").write_text("/* */\n" * 50_000)  # 0.35 MB
    (tmp_path / "small.c").write_text("int x;\n")
    script = "echo cc -O2 -c small.c -o small.o; echo cc -O2 -c big_casadi.c -o big.o; sleep 0.7"
    said: list[str] = []
    with reporting(said.append):
        run(["sh", "-c", script], tmp_path, "host build")
    assert said[0] == "host build: compiling big_casadi.c (0.3 MB of C)", said
    assert all(line.startswith("host build: still running after ") for line in said[1:]) and len(said) >= 2, said


def test_interrupt_ends_the_group(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C (or SIGTERM, which dcts turns into an exit) while waiting: the group goes too."""
    (tmp_path / "Makefile").write_text(HANGING_MAKEFILE)
    interrupted = False

    def interrupted_wait(self, timeout=None):  # once the child runs, one wait is interrupted
        nonlocal interrupted
        if not interrupted and (tmp_path / "child.pid").is_file():
            interrupted = True
            raise KeyboardInterrupt
        return original_wait(self, timeout=timeout)

    original_wait = process_module.subprocess.Popen.wait
    monkeypatch.setattr(process_module, "HEARTBEAT_S", 0.3)
    monkeypatch.setattr(process_module.subprocess.Popen, "wait", interrupted_wait)
    with pytest.raises(KeyboardInterrupt):
        make(tmp_path, ["all"], "host build", timeout=20)
    monkeypatch.undo()
    child = int((tmp_path / "child.pid").read_text())
    assert _wait_dead(child), f"the build's child {child} survived the interrupt"


def test_a_step_given_up_on_ends_its_group(tmp_path: Path) -> None:
    """A step started in the background (compile_bundle builds the library while it computes the
    golden vectors) and given up on: `end` takes its whole group."""
    (tmp_path / "Makefile").write_text(HANGING_MAKEFILE)
    step = start(["make", "-C", str(tmp_path), "all"], tmp_path, "host build")
    deadline = time.monotonic() + 10
    while not (tmp_path / "child.pid").is_file() and time.monotonic() < deadline:
        time.sleep(0.05)
    step.end()
    child = int((tmp_path / "child.pid").read_text())
    assert _wait_dead(child) and step.process.poll() is not None


def test_a_failure_while_the_library_builds_ends_its_build(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An error in the golden vectors, computed while `make lib` runs (here a compiler that hangs):
    the error, the compiler ended, no staging folder left."""
    from dcts_spec.codegen import bundle as bundle_module
    from dcts_spec.codegen.build import compile_bundle

    compiler = tmp_path / "hanging-cc"
    compiler.write_text(f'#!/bin/sh\n[ "$1" = --version ] && {{ echo hanging 1; exit 0; }}\n'
                        f'echo $$ >> {tmp_path}/cc.pids; sleep 300\n')
    compiler.chmod(0o755)

    def failing(controller, states):
        deadline = time.monotonic() + 10
        while not (tmp_path / "cc.pids").is_file() and time.monotonic() < deadline:
            time.sleep(0.05)
        raise RuntimeError("the golden vectors failed")

    monkeypatch.setenv("DCTS_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(bundle_module, "compute_golden", failing)
    spec = Path(__file__).resolve().parent.parent / "specs" / "minimal.yaml"
    with pytest.raises(RuntimeError, match="the golden vectors failed"):
        compile_bundle(spec, tmp_path / "out" / "bundle", cc=str(compiler))
    pids = [int(line) for line in (tmp_path / "cc.pids").read_text().split()]
    assert pids and all(_wait_dead(pid) for pid in pids), "a compiler of the library's build survived"
    assert not (tmp_path / "out").exists()


def test_parallel_first_downloads_of_daqp_each_get_the_complete_sources(tmp_path, monkeypatch):
    # on a fresh machine pytest-xdist's workers all fetch DAQP at once; one must never compile
    # another's half-unpacked copy. pip is stood in for by a copy of the real source archive's
    # contents (the cached sources), slow enough that the two fetches overlap.
    import tarfile
    import types
    from concurrent.futures import ThreadPoolExecutor

    from dcts_spec.codegen import build, daqp_sources

    try:
        cached = daqp_sources()
    except CodegenError as error:
        pytest.skip(f"DAQP sources unavailable: {error}")
    archive = tmp_path / f"daqp-{DAQP_VERSION}.tar.gz"
    with tarfile.open(archive, "w:gz") as tar:
        tar.add(cached, arcname=f"daqp-{DAQP_VERSION}/csrc")

    def pip_download(command, **_):
        time.sleep(0.3)
        (Path(command[command.index("-d") + 1]) / archive.name).write_bytes(archive.read_bytes())
        return types.SimpleNamespace(returncode=0, stdout="", stderr="")

    monkeypatch.setattr(build, "subprocess", types.SimpleNamespace(run=pip_download))
    cache = tmp_path / "cache"
    with ThreadPoolExecutor(2) as pool:
        futures = [pool.submit(daqp_sources, cache) for _ in range(2)]
    found = {future.result() for future in futures}
    assert found == {cache / "daqp" / f"daqp-{DAQP_VERSION}" / "csrc"}
    csrc = found.pop()
    assert sorted(p.name for p in (csrc / "src").iterdir()) == sorted(p.name for p in (cached / "src").iterdir())
    assert [p.name for p in (cache / "daqp").iterdir()] == [f"daqp-{DAQP_VERSION}"]  # no private folder left
