"""A progress bar on the terminal for runs long enough to need one."""

from __future__ import annotations

import sys
import time

from rich.console import Console
from rich.progress import BarColumn, Progress, TaskProgressColumn, TextColumn, TimeRemainingColumn

from .runner import Hook

MIN_SECONDS = 1.0  # runs expected to be shorter get no bar
UPDATES = 200


class ProgressBar:
    """Shows the simulated time on stderr once the run is seen to take more than a second.

    Off when stderr is not a terminal or when `enabled` is False (--quiet).
    """

    def __init__(self, steps: int, period: float, description: str, enabled: bool = True):
        self._steps, self._period, self._description = steps, period, description
        self._enabled = enabled and sys.stderr.isatty()
        self._progress: Progress | None = None
        self._task = None
        self._start = time.perf_counter()
        self.every = max(1, steps // UPDATES)

    def hook(self) -> Hook:
        return Hook(self.every, self._update)

    def _update(self, k: int) -> None:
        if not self._enabled:
            return
        done = k + 1
        if self._progress is None:
            elapsed = time.perf_counter() - self._start
            if elapsed * self._steps / done < MIN_SECONDS:
                return
            self._progress = Progress(
                TextColumn("{task.description}"), BarColumn(), TaskProgressColumn(),
                TextColumn("{task.fields[sim]}"), TimeRemainingColumn(),
                console=Console(stderr=True), transient=True,
            )
            self._progress.start()
            self._task = self._progress.add_task(self._description, total=self._steps, sim="")
        total = self._steps * self._period
        self._progress.update(self._task, completed=done, sim=f"{done * self._period:.2f}/{total:.2f} s")

    def close(self) -> None:
        if self._progress is not None:
            self._progress.stop()
            self._progress = None
