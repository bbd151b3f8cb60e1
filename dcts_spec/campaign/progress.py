"""The campaign's progress bar on stderr: samples done of the campaign, samples/s, time left."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn


@contextmanager
def sample_progress(total: int, done: int, description: str, enabled: bool = True) -> Iterator[Callable[[], None]]:
    """Yield `advance()`, called once per finished sample; no bar unless stderr is a terminal."""
    if not (enabled and sys.stderr.isatty()):
        yield lambda: None
        return
    progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                        TextColumn("{task.fields[rate]}"),
                        TimeRemainingColumn(), console=Console(stderr=True), transient=True)
    task = progress.add_task(description, total=total, completed=done, rate="")
    with progress:
        def advance() -> None:
            progress.advance(task)
            speed = progress.tasks[0].speed
            progress.update(task, rate=f"{speed:.2f} samples/s" if speed else "")
        yield advance
