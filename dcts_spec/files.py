"""Output folders that never lose a user's file.

A command builds its output in a staging folder, then `install` moves it into place: entries the
new output has replace their namesakes, entries the previous dcts output had (listed in its
OWNED file) and the new one lacks go, and everything else in the folder (a user's notes, their
main.c) stays. A folder that exists, is not empty and has no OWNED file was not made by dcts:
`check_writable` refuses it before any work is done. OWNED lists every path dcts wrote, to the
files inside its subfolders, so `install` also refuses (and leaves the folder as it was) where
the new output would replace a user's file: one with the name of a new entry (a summary.json
of their own in a bundle folder), or one added inside a folder dcts wrote (firmware/my_main.c).

A folder holds one kind of output (OWNED records which): a command refuses a folder that holds
another kind, as a newer output of its own would replace it (`dcts simulate -o` into a campaign's
folder deleted the campaign). A campaign adds to its folder over several runs: it replaces its
report with `install_files`, which keeps its samples and whatever else is there.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import time
from collections.abc import Iterable
from fnmatch import fnmatch
from pathlib import Path

OWNED = ".dcts-owned"  # JSON: {"kind", "entries": top-level names, "paths": every path below them} dcts wrote
# The kinds of output, by the command that writes them
KINDS = {"bundle": "dcts compile", "run": "dcts simulate", "comparison": "dcts compare", "campaign": "dcts sweep"}
# An output from before OWNED recorded its kind, known by a file only that kind writes (in this order)
_KIND_MARKERS = (("campaign.json", "campaign"), ("manifest.json", "bundle"), ("comparison.json", "comparison"),
                 ("summary.json", "run"))
# A staging folder this old was left by a run that was killed (SIGKILL, a power cut): a live run
# finishes its staging in minutes, and a younger one may belong to a run still going.
STALE_STAGING_SECONDS = 3600.0
# In every staging folder from its creation until it is installed: what lets a later run remove
# one a killed run left behind (a folder of the same name without it is someone else's)
STAGING_MARK = ".dcts-staging"
# The signal that asked this process to stop (see `request_stop`), or None
_stop_signal: int | None = None


class OutputFolderError(Exception):
    """The output folder cannot be written without touching files dcts did not write."""


def _owned(folder: Path) -> dict | list | None:
    try:
        return json.loads((folder / OWNED).read_text())
    except (OSError, ValueError):
        return None


def _names(owned: dict | list | None) -> set[str]:
    """The top-level names of an OWNED file's contents."""
    if isinstance(owned, dict):
        return set(owned.get("entries", []))
    return set(owned) if isinstance(owned, list) else set()


def _paths_of(owned: dict | list | None) -> set[str] | None:
    """Every path (relative, '/'-separated) of an OWNED file's contents; None where the file
    predates this list (a plain list of top-level names: their subfolders count as dcts's)."""
    return set(owned.get("paths", [])) if isinstance(owned, dict) else None


def owned_names(folder: Path) -> set[str]:
    """The top-level names dcts wrote into `folder`."""
    return _names(_owned(folder))


def output_kind(folder: Path) -> str | None:
    """The kind of dcts output `folder` holds (a KINDS key), None if it shows none."""
    owned = _owned(folder)
    if isinstance(owned, dict) and owned.get("kind"):
        return str(owned["kind"])
    return next((kind for marker, kind in _KIND_MARKERS if (folder / marker).is_file()), None)


def _check_kind(folder: Path, kind: str) -> None:
    held = output_kind(folder) if folder.is_dir() else None
    if held is not None and held != kind:
        raise OutputFolderError(f"{folder} holds the output of `{KINDS.get(held, held)}`, not of `{KINDS[kind]}`: "
                                "refusing to replace it; choose another output folder")


def _paths(root: Path) -> list[str]:
    """The paths of every file and folder below `root`, relative to it."""
    return sorted(p.relative_to(root).as_posix() for p in root.rglob("*"))


def _users_files(folder: Path, owned: dict | list | None, names: set[str], regenerated: tuple[str, ...]) -> list[str]:
    """The paths among `folder`'s entries `names` (and below them) that dcts did not write (`owned`:
    its OWNED file's contents), other than those matching a `regenerated` pattern (fnmatch). None
    in a folder with no OWNED file (an output of a dcts from before it, which the command
    recognized): its entries count as dcts's, as they did then."""
    if owned is None:
        return []
    entries, paths = _names(owned), _paths_of(owned)
    candidates = []
    for name in sorted(names):
        path = folder / name
        if not (path.exists() or path.is_symlink()):
            continue
        if name not in entries:
            candidates.append(name)
        elif paths is not None and path.is_dir() and not path.is_symlink():
            candidates += [f"{name}/{p}" for p in _paths(path) if f"{name}/{p}" not in paths]
    return [p for p in candidates if not any(fnmatch(p, pattern) for pattern in regenerated)]


def check_writable(folder: Path, kind: str, allow_unmarked=lambda folder: False) -> None:
    """Raise OutputFolderError unless `folder` is absent, empty, or holds an output of this `kind`
    (a KINDS key) dcts wrote before (`allow_unmarked`: other evidence of that, e.g. a bundle's
    manifest from before OWNED)."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise OutputFolderError(f"{folder} exists and is not a directory")
    if folder.is_symlink() and not folder.exists():
        raise OutputFolderError(f"{folder} is a link to nothing ({os.readlink(folder)}): choose another output folder")
    ancestor = next(p for p in folder.absolute().parents if p.exists())  # (the first folder that would be made in)
    if not folder.exists() and not ancestor.is_dir():
        raise OutputFolderError(f"cannot create {folder}: {ancestor} is not a directory")
    if not folder.exists() and not os.access(ancestor, os.W_OK | os.X_OK):
        raise OutputFolderError(f"cannot create {folder}: {ancestor} is not writable")
    if folder.is_dir() and any(folder.iterdir()) and not (folder / OWNED).is_file() and not allow_unmarked(folder):
        raise OutputFolderError(f"{folder} is not empty and was not written by dcts (it has no {OWNED}): refusing "
                                "to write into it; choose another output folder (dcts never deletes files it did not write)")
    _check_kind(folder, kind)


def request_stop(signum: int) -> None:
    """Record that a signal (SIGTERM) asked this process to stop: from now on `install` refuses.
    The signal handler's exception alone is not enough: Python drops one raised while a finalizer
    (`__del__`, a weakref callback) runs, and the command would then finish and install its output."""
    global _stop_signal
    _stop_signal = signum


def stop_signal() -> int | None:
    """The signal `request_stop` recorded, or None."""
    return _stop_signal


def install(staging: Path, folder: Path, kind: str, regenerated: tuple[str, ...] = ()) -> None:
    """Move the finished `staging` folder's entries, an output of `kind`, into `folder` (see the
    module docstring); after `request_stop`, raise SystemExit instead (the caller removes its
    staging folder). `regenerated`: patterns (fnmatch, relative paths) of what the output's own
    tools make and remake, which it may replace though dcts did not write them (a bundle's `make`
    products)."""
    if _stop_signal is not None:
        raise SystemExit(128 + _stop_signal)
    staging, folder = Path(staging), Path(folder)
    (staging / STAGING_MARK).unlink(missing_ok=True)  # (an output now, not a leftover)
    new = sorted(p.name for p in staging.iterdir() if p.name != OWNED)
    paths = [p for p in _paths(staging) if p != OWNED]
    (staging / OWNED).write_text(json.dumps({"kind": kind, "entries": new, "paths": paths}) + "\n")
    if not folder.exists():
        staging.rename(folder)
        return
    _check_kind(folder, kind)  # (again: the folder may have changed while the output was made)
    owned = _owned(folder)
    old = _names(owned)
    users = _users_files(folder, owned, old | set(new), regenerated)
    if users:
        shown = ", ".join(users[:5]) + (f" and {len(users) - 5} more" if len(users) > 5 else "")
        raise OutputFolderError(f"{folder} has files dcts did not write where this output goes ({shown}): nothing "
                                "was changed; move them, or choose another output folder (dcts never deletes or "
                                "overwrites files it did not write)")
    trash = folder.parent / f".{folder.name}.{secrets.token_hex(6)}.old"
    trash.mkdir()
    moved: list[str] = []
    try:
        for name in sorted((old | set(new) | {OWNED}) & {p.name for p in folder.iterdir()}):
            (folder / name).rename(trash / name)
            moved.append(name)
        for name in [*new, OWNED]:
            (staging / name).rename(folder / name)
    except OSError:
        for name in moved:  # put the previous output back
            if not (folder / name).exists():
                (trash / name).rename(folder / name)
        raise
    finally:
        shutil.rmtree(trash, ignore_errors=True)
    staging.rmdir()


def claim(folder: Path, kind: str, entries: Iterable[str]) -> None:
    """Record in `folder`'s OWNED file that it holds an output of `kind` with these top-level
    `entries`, for an output dcts adds to in place (a campaign): the paths OWNED lists stay listed,
    and an OWNED file from before paths were listed stays without them (`lists_paths`)."""
    owned = _owned(folder)
    state: dict = {"kind": kind, "entries": sorted(entries)}
    if not isinstance(owned, list):
        state["paths"] = owned.get("paths", []) if isinstance(owned, dict) else []
    (folder / OWNED).write_text(json.dumps(state) + "\n")


def lists_paths(folder: Path) -> bool:
    """Does `folder`'s OWNED file list the paths dcts wrote (not one from before they were)?"""
    owned = _owned(folder)
    return isinstance(owned, dict) and "paths" in owned


def install_files(staging: Path, folder: Path, previous: set[str]) -> None:
    """Move the files below `staging` into `folder`, an output dcts is adding to (a campaign's
    report next to its samples): the files dcts wrote there before (OWNED's paths, and `previous`
    for an OWNED file from before they were listed) that the new set lacks go, every other file
    stays. A user's file where a new one goes refuses, and nothing changes. While the files move,
    OWNED lists the old and the new ones, so an interruption leaves none of them unlisted."""
    if _stop_signal is not None:
        raise SystemExit(128 + _stop_signal)
    staging, folder = Path(staging), Path(folder)
    owned = _owned(folder)
    state = owned if isinstance(owned, dict) else {"entries": sorted(_names(owned))}
    old = set(state.get("paths", [])) | previous
    new = [p for p in _paths(staging) if (staging / p).is_file() and p != STAGING_MARK]
    users = [p for p in new if (folder / p).exists() and p not in old]
    if users:
        shown = ", ".join(users[:5]) + (f" and {len(users) - 5} more" if len(users) > 5 else "")
        raise OutputFolderError(f"{folder} has files dcts did not write where this output goes ({shown}): nothing "
                                "was changed; move them (dcts never deletes or overwrites files it did not write)")
    folders = {p for f in new for p in _parents(f)}
    (folder / OWNED).write_text(json.dumps({**state, "paths": sorted(old | set(new) | folders)}) + "\n")
    for path in new:
        (folder / path).parent.mkdir(parents=True, exist_ok=True)
        (staging / path).replace(folder / path)
    for path in sorted(old - set(new), reverse=True):  # (files before their folders)
        target = folder / path
        if target.is_file() or target.is_symlink():
            target.unlink()
        elif target.is_dir() and path not in folders and not any(target.iterdir()):
            target.rmdir()
    kept = {p for p in old - set(new) if (folder / p).exists()}  # (an owned folder a user's file keeps)
    (folder / OWNED).write_text(json.dumps({**state, "paths": sorted(set(new) | folders | kept)}) + "\n")


def _parents(path: str) -> list[str]:
    """The folders of a relative path, outermost first: 'a/b/c.png' → ['a', 'a/b']."""
    parts = path.split("/")[:-1]
    return ["/".join(parts[: i + 1]) for i in range(len(parts))]


def check_new_file(path: Path, what: str) -> None:
    """A single file dcts is to write (`what`: "the video"): refused if anything is at `path`
    already, the user's or an earlier run's alike (dcts cannot tell them apart)."""
    if path.exists() or path.is_symlink():
        raise OutputFolderError(f"{path} exists: {what} is not written over it (dcts never deletes or overwrites "
                                "files); remove it, or choose another name")


def mark_staging(folder: Path) -> None:
    """Mark `folder`, just made to stage an output in, as dcts's (STAGING_MARK)."""
    (folder / STAGING_MARK).touch()


def remove_stale_staging(parent: Path, prefix: str, suffix: str = "") -> None:
    """Remove the staging folders `parent/<prefix>*<suffix>` older than STALE_STAGING_SECONDS that
    dcts marked as its own (`mark_staging`), next to an output it is about to write, left by a
    killed run. A folder of such a name without the mark is a user's, and stays."""
    if not parent.is_dir():
        return
    now = time.time()
    for path in parent.glob(f"{prefix}*{suffix}"):
        try:
            if (path.is_dir() and not path.is_symlink() and (path / STAGING_MARK).is_file()
                    and now - path.stat().st_mtime > STALE_STAGING_SECONDS):
                shutil.rmtree(path, ignore_errors=True)
        except OSError:
            pass
