"""Staging folders: a killed command leaves none behind (SIGTERM), and the next run removes what a
SIGKILL left (issue 12: `.out.tmp-*` folders of ~800 KB that no later run removed)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dcts_spec import cli, files
from dcts_spec.files import (STALE_STAGING_SECONDS, OutputFolderError, check_writable, install, mark_staging,
                             remove_stale_staging)

ROOT = Path(__file__).resolve().parents[1]


def test_sigterm_during_compile_leaves_no_staging_folder(tmp_path):
    out = tmp_path / "bundle"
    env = {**os.environ, "DCTS_CACHE_DIR": str(tmp_path / "cache")}
    command = ["compile", str(ROOT / "specs" / "minimal.yaml"), "-o", str(out), "-q"]
    process = subprocess.Popen([sys.executable, "-c", f"import sys; sys.argv = ['dcts', *{command!r}]; "
                                "from dcts_spec.cli import main; main()"], cwd=ROOT, env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while not list(tmp_path.glob(".bundle.tmp-*")) and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert process.poll() is None, "the compile ended before its staging folder could be seen"
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 128 + signal.SIGTERM, stderr.decode(errors="replace")[-3000:]
    assert not list(tmp_path.glob(".bundle.tmp-*")) and not out.exists()


def test_after_a_stop_request_nothing_is_installed_and_the_command_exits_with_the_signal(tmp_path, monkeypatch):
    # Python drops a signal handler's SystemExit raised while a finalizer runs (CI saw a SIGTERMed
    # compile exit 0); the recorded request must still keep the output out and the exit code right
    staging, out = tmp_path / ".out.tmp-1", tmp_path / "out"
    staging.mkdir()
    (staging / "file").write_text("x")
    monkeypatch.setattr(files, "_stop_signal", None)
    install(staging, out, "run")
    assert (out / "file").is_file()
    staging.mkdir()
    monkeypatch.setattr(files, "_stop_signal", signal.SIGTERM)
    with pytest.raises(SystemExit) as stopped:
        install(staging, tmp_path / "other", "run")
    assert stopped.value.code == 128 + signal.SIGTERM and not (tmp_path / "other").exists()
    monkeypatch.setattr(cli, "app", lambda: None)  # a command that finished as if never signalled
    with pytest.raises(SystemExit) as exited:
        cli.main()
    assert exited.value.code == 128 + signal.SIGTERM


def test_the_next_run_removes_only_old_staging_folders_of_its_output(tmp_path):
    """Only dcts's own (marked) staging folders: a user's old `.bundle.tmp-backup` with their
    thesis in it matched the name and was deleted by the next `dcts compile -o bundle` (first
    seen from outside)."""
    old, young = tmp_path / ".bundle.tmp-old", tmp_path / ".bundle.tmp-young"
    other, user = tmp_path / ".other.tmp-old", tmp_path / "bundle.tmp-notes"
    backup = tmp_path / ".bundle.tmp-backup"  # the name of a staging folder, a user's folder
    for folder in (old, young, other, user, backup):
        folder.mkdir()
        (folder / "file").write_text("x")
        if folder is not backup:
            mark_staging(folder)
    past = time.time() - 2 * STALE_STAGING_SECONDS
    for folder in (old, other, user, backup):
        os.utime(folder, (past, past))
    remove_stale_staging(tmp_path, ".bundle.tmp-")
    assert not old.exists()
    assert young.exists() and other.exists() and user.exists()  # a live run's, another output's, a user's
    assert (backup / "file").read_text() == "x"


def test_an_installed_output_has_no_staging_mark(tmp_path):
    staging = tmp_path / ".out.tmp-1"
    staging.mkdir()
    mark_staging(staging)
    (staging / "file").write_text("x")
    install(staging, tmp_path / "out", "run")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [".dcts-owned", "file"]


def test_an_output_folder_that_cannot_be_made_is_refused_before_the_run(tmp_path):
    """-o below a file, or a link to nothing, failed with an internal error (exit 3) after the
    whole simulation (first seen from outside); now check_writable, which every command runs
    before its work, says why."""
    (tmp_path / "notes.txt").write_text("x")
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    for folder, words in ((tmp_path / "notes.txt" / "run", "notes.txt is not a directory"),
                          (tmp_path / "notes.txt" / "a" / "b", "notes.txt is not a directory"),
                          (tmp_path / "dangling", "is a link to nothing")):
        with pytest.raises(OutputFolderError, match=words):
            check_writable(folder, "run")
    check_writable(tmp_path / "new" / "run", "run")  # made later, in a folder that can be made
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dangling", "notes.txt"]
