"""Diagnostics with file locations, and the exception that carries them."""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from typing import Literal

Severity = Literal["error", "warning", "info"]
KeyPath = tuple[str | int, ...]


def format_path(path: KeyPath) -> str:
    """`('tasks', 0, 'gains')` -> `tasks[0].gains`."""
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "<document>"


@dataclass(frozen=True)
class Diagnostic:
    """One finding about a spec, located in its file."""

    message: str
    severity: Severity = "error"
    file: str = "<spec>"
    line: int | None = None  # 1-based
    column: int | None = None  # 1-based
    path: KeyPath = ()

    def __str__(self) -> str:
        where = self.file
        if self.line is not None:
            where += f":{self.line}"
            if self.column is not None:
                where += f":{self.column}"
        key = f"{format_path(self.path)}: " if self.path else ""
        return f"{where}: {self.severity}: {key}{self.message}"

    def to_dict(self) -> dict:
        return {
            "severity": self.severity,
            "file": self.file,
            "line": self.line,
            "column": self.column,
            "path": format_path(self.path) if self.path else None,
            "message": self.message,
        }


MAX_DIAGNOSTICS = 50  # a 100,000-item list of wrong values must not print megabytes


@dataclass
class SpecError(Exception):
    """A spec that cannot be used; carries every problem found (up to MAX_DIAGNOSTICS, errors first,
    then a note of how many more there are), not just the first."""

    diagnostics: list[Diagnostic] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.diagnostics = _capped(self.diagnostics)

    def __str__(self) -> str:
        return "\n".join(str(d) for d in self.diagnostics)

    @property
    def errors(self) -> list[Diagnostic]:
        return [d for d in self.diagnostics if d.severity == "error"]


def _capped(diagnostics: list[Diagnostic]) -> list[Diagnostic]:
    """At most MAX_DIAGNOSTICS, errors before warnings, in their order; an `info` says how many were left out."""
    if len(diagnostics) <= MAX_DIAGNOSTICS:
        return diagnostics
    order = sorted(range(len(diagnostics)), key=lambda i: diagnostics[i].severity != "error")
    kept = sorted(order[:MAX_DIAGNOSTICS])
    first_left = diagnostics[order[MAX_DIAGNOSTICS]]
    left = len(diagnostics) - MAX_DIAGNOSTICS
    errors_left = sum(diagnostics[i].severity == "error" for i in order[MAX_DIAGNOSTICS:])
    note = Diagnostic(f"{left} more problems not shown ({errors_left} errors), the first of them here; "
                      f"fix these {MAX_DIAGNOSTICS} and run again", "info", first_left.file, first_left.line,
                      first_left.column)
    return [diagnostics[i] for i in kept] + [note]


YAML_LITERALS = {None: "null", True: "true", False: "false"}


def shown(value: object, limit: int = 60) -> str:
    """`repr(value)`, cut to `limit` characters: a wrong value is quoted, not printed whole. YAML's
    null, true and false are spelled as the file spells them, not as Python's None, True, False."""
    text = YAML_LITERALS[value] if value is None or isinstance(value, bool) else repr(value)
    return text if len(text) <= limit else f"{text[:limit]}… ({len(text)} characters)"


def did_you_mean(word: object, choices: list[str], n: int = 1) -> str:
    """` (did you mean 'x'?)` for the closest choices, or an empty string (always for a `word` that
    is not text: YAML's null is no misspelt 'pose')."""
    if not isinstance(word, str):
        return ""
    close = difflib.get_close_matches(word, choices, n=n, cutoff=0.5)
    return f" (did you mean {' or '.join(shown(c) for c in close)}?)" if close else ""
