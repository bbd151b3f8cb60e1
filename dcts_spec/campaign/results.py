"""A campaign's output folder: the samples streamed to samples.jsonl as they finish, and what
makes resuming safe.

campaign.json records the SHA-256 of the spec and campaign files (and the optimization's
settings); running the same command again skips the samples already in samples.jsonl, and a
changed file is refused at its line. The folder follows dcts' output rules (`files.py`): it is
written only if absent, empty, or a campaign's folder (its OWNED file lists what dcts wrote
there); a report replaces only the report files dcts wrote, and only once it is complete.
"""

from __future__ import annotations

import hashlib
import json
import secrets
import shutil
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ..files import (OutputFolderError, check_writable, claim, install_files, lists_paths, mark_staging,
                     owned_names, remove_stale_staging)
from ..spec.errors import Diagnostic, SpecError, shown

STATE = "campaign.json"
SAMPLES = "samples.jsonl"
REPORT_NAMES = ("report.json", "report.html", "plots")
REPLAYS = "replays"  # the worst cases' specs (and the runs a user replays into it)
JOURNAL = "optuna.journal"  # an optimization's study
TRIALS = "trials.jsonl"  # an optimization's trials, one line each
NAMES = (STATE, SAMPLES, *REPORT_NAMES, REPLAYS, JOURNAL, TRIALS)


def file_digest(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


class ResultsFolder:
    """DIR of `dcts sweep --out DIR`."""

    def __init__(self, folder: Path, spec_file: Path, campaign_file: Path, settings: dict[str, Any]):
        self.folder = Path(folder)
        self.state = {"spec": str(spec_file), "spec_sha256": file_digest(spec_file), "campaign": str(campaign_file),
                      "campaign_sha256": file_digest(campaign_file), "settings": settings}
        self._files = {"spec": Path(spec_file), "campaign": Path(campaign_file)}

    @property
    def samples_file(self) -> Path:
        return self.folder / SAMPLES

    def check(self) -> None:
        """Raise if the campaign cannot go into the folder (a folder dcts did not write, another
        output, another campaign): writes nothing, so that the inputs' own checks come first."""
        check_writable(self.folder, "campaign")
        state_file = self.folder / STATE
        if state_file.is_file():
            # a campaign that stopped before any result (a crash at its start) has nothing the
            # changed files' samples would be compared with: it starts again
            if any((self.folder / name).is_file() and (self.folder / name).stat().st_size
                   for name in (SAMPLES, JOURNAL, TRIALS)):
                self._check_same(json.loads(state_file.read_text()))
        elif owned_names(self.folder):
            raise OutputFolderError(f"{self.folder} holds another dcts output (no {STATE}): choose another output "
                                    "folder for the campaign")

    def open(self, samples: int) -> dict[int, dict[str, Any]]:
        """Check the folder, record the campaign (or check it is the recorded one) and return
        the rows already finished, by sample index (of the campaign's `samples`)."""
        self.check()
        state_file = self.folder / STATE
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as error:  # (what check_writable cannot tell beforehand: a read-only file system)
            raise OutputFolderError(f"cannot create {self.folder}: {error.strerror}") from None
        claim(self.folder, "campaign", NAMES)  # (an older dcts's OWNED lists no report files: _earlier_report)
        state_file.write_text(json.dumps(self.state, indent=2) + "\n")
        return self._finished(samples)

    def _check_same(self, recorded: dict[str, Any]) -> None:
        for what in ("spec", "campaign"):
            if recorded.get(f"{what}_sha256") != self.state[f"{what}_sha256"]:
                raise SpecError([Diagnostic(
                    f"this {what} file changed since {self.folder} was started with it ({STATE} records SHA-256 "
                    f"{str(recorded.get(f'{what}_sha256'))[:12]}…, the file has {self.state[f'{what}_sha256'][:12]}…): "
                    "its samples would not be comparable; give another --out folder, or remove that one to start "
                    "again", file=str(self._files[what]), line=1, column=1)])
        if recorded.get("settings") != self.state["settings"]:
            raise SpecError([Diagnostic(
                f"{self.folder} was started with other settings ({recorded.get('settings')}, now "
                f"{self.state['settings']}): give another --out folder, or the same options",
                file=str(self._files["campaign"]), line=1, column=1)])

    def _finished(self, samples: int) -> dict[int, dict[str, Any]]:
        """The rows of samples.jsonl; a last line cut short by a kill is dropped (and cut off). A
        line that is no row of this campaign (edited, or added from elsewhere) is an error at it."""
        rows: dict[int, dict[str, Any]] = {}
        path = self.samples_file
        if not path.is_file():
            return rows
        data = path.read_bytes()
        complete = data[: data.rfind(b"\n") + 1]
        if len(complete) != len(data):
            with path.open("r+b") as f:
                f.truncate(len(complete))
        for number, line in enumerate(complete.decode(errors="replace").splitlines(), 1):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
            except ValueError:
                row = None
            problem = _row_problem(row, samples)
            if problem:
                raise SpecError([Diagnostic(
                    f"{problem}: not a row dcts wrote for this campaign; remove the line (its sample runs again) or "
                    "give another --out folder", file=str(path), line=number, column=1)])
            rows[row["index"]] = row
        return rows

    def append(self, rows: Iterable[dict[str, Any]]) -> None:
        """Add finished rows: one line each, flushed at once (an interrupted campaign keeps them)."""
        with self.samples_file.open("a", encoding="utf-8") as f:
            for row in rows:
                f.write(json.dumps(row) + "\n")
                f.flush()

    @contextmanager
    def report_staging(self) -> Iterator[Path]:
        """Yield an empty folder to write the report into; when the block succeeds, its files
        replace the report files dcts wrote before (`files.install_files`): the old report stays
        until the new one is complete, and a user's file in plots/ or replays/ (a replay's run
        folder, their notes) stays."""
        parent = self.folder.parent
        remove_stale_staging(parent, f".{self.folder.name}.", ".report")
        staging = parent / f".{self.folder.name}.{secrets.token_hex(6)}.report"
        staging.mkdir()
        mark_staging(staging)
        try:
            yield staging
            install_files(staging, self.folder, self._earlier_report())
        finally:
            shutil.rmtree(staging, ignore_errors=True)

    def _earlier_report(self) -> set[str]:
        """The report files of a campaign folder whose OWNED file predates the list of paths."""
        if lists_paths(self.folder):
            return set()
        plots = self.folder / "plots"
        return {"report.json", "report.html", *(f"plots/{p.name}" for p in plots.glob("*.png")),
                *(f"{REPLAYS}/{p.name}" for p in (self.folder / REPLAYS).glob("sample_*.yaml"))}


def _row_problem(row: Any, samples: int) -> str:
    """What makes a samples.jsonl line no sample row of a campaign of `samples` ('' if nothing)."""
    if not isinstance(row, dict):
        return "not a JSON object"
    index = row.get("index")
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < samples:
        return f"its index {shown(index)} is not a sample of this campaign (0 to {samples - 1})"
    if row.get("status") not in ("ok", "invalid", "error"):
        return f"its status {shown(row.get('status'))} is none of ok, invalid, error"
    return ""

