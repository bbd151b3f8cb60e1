"""Output folders, written all or nothing into a staging sibling, then installed (`files.py`)."""

from __future__ import annotations

import json
import secrets
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ..files import OutputFolderError, check_writable, install, mark_staging, remove_stale_staging
from .plots import write_plots
from .run import RunResult


# What every run's summary.json has held since the first dcts (a comparison.json holds one per run)
_SUMMARY_KEYS = ("spec", "formulation", "runtime")


def _is_summary(value: object) -> bool:
    return isinstance(value, dict) and all(key in value for key in _SUMMARY_KEYS)


def earlier_output(folder: Path) -> bool:
    """A run or comparison folder written by a dcts from before the OWNED file: known by its
    summary.json (or comparison.json) as dcts writes it, not by the name alone (a user's own
    summary.json there was replaced)."""
    try:
        if (folder / "summary.json").is_file():
            return _is_summary(json.loads((folder / "summary.json").read_text()))
        if (folder / "comparison.json").is_file():
            table = json.loads((folder / "comparison.json").read_text())
            return isinstance(table, dict) and bool(table) and all(_is_summary(v) for v in table.values())
    except (OSError, ValueError):
        pass
    return False


@contextmanager
def atomic_directory(path: Path, kind: str) -> Iterator[Path]:
    """Yield an empty staging folder whose entries, an output of `kind` (files.KINDS), go into
    `path` when the block succeeds (`files.install`: a user's own files in `path` stay). On an
    exception nothing is left behind and `path` is untouched. Raises OutputFolderError at once if
    `path` was not written by dcts, or holds another kind of output."""
    path = Path(path)
    check_writable(path, kind, allow_unmarked=earlier_output)
    staging = path.parent / f".{path.name}.{secrets.token_hex(6)}.partial"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_staging(path.parent, f".{path.name}.", ".partial")
        staging.mkdir()  # (mkdir, not mkdtemp: the folder gets the user's usual permissions)
        mark_staging(staging)
    except OSError as error:  # (what check_writable cannot tell beforehand: a read-only file system, /proc)
        raise OutputFolderError(f"cannot write into {path.parent}: {error.strerror}") from None
    try:
        yield staging
        install(staging, path, kind)
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)


def write_run(run: RunResult, directory: Path, plots: bool = True) -> None:
    """log.npz, summary.json and (unless `plots` is False) the PNG plots of a run."""
    directory.mkdir(parents=True, exist_ok=True)
    run.save_log(directory / "log.npz")
    run.save_summary(directory / "summary.json")
    if plots:
        write_plots(run, directory)
