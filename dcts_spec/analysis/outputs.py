"""Output directories, written all or nothing: files go to a temporary sibling renamed at the end."""

from __future__ import annotations

import secrets
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from .plots import write_plots
from .run import RunResult


@contextmanager
def atomic_directory(path: Path) -> Iterator[Path]:
    """Yield an empty directory that becomes `path` when the block succeeds.

    On an exception nothing is left behind and an existing `path` is untouched; on success an
    existing `path` is replaced.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise FileExistsError(f"{path} exists and is not a directory")
    path.parent.mkdir(parents=True, exist_ok=True)
    # mkdir, not mkdtemp: the directory gets the user's usual permissions.
    staging = path.parent / f".{path.name}.{secrets.token_hex(6)}.partial"
    staging.mkdir()
    try:
        yield staging
        if path.exists():
            # A directory cannot be renamed onto a non-empty one: move the old one aside first.
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=path.parent))
            path.rename(old / path.name)
            try:
                staging.rename(path)
            except OSError:
                (old / path.name).rename(path)
                raise
            finally:
                shutil.rmtree(old, ignore_errors=True)
        else:
            staging.rename(path)
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
