"""MuJoCo's passive viewer following a run at real-time speed."""

from __future__ import annotations

import threading
import time

from .camera import aim_at_robot
from .display import display_problem
from .runner import Hook, Simulation

REFRESH = 60.0  # viewer updates per simulated second


class ViewerUnavailable(RuntimeError):
    """No window can be opened here."""


class LiveViewer:
    """Shows the simulation while it runs, slowed down to real time so it can be watched.

    Closing the window lets the run finish at full speed.
    """

    def __init__(self, sim: Simulation):
        problem = display_problem()
        if problem is not None:
            raise ViewerUnavailable(f"--viewer needs a display: {problem}")
        import mujoco.viewer

        before = set(threading.enumerate())
        try:
            self._handle = mujoco.viewer.launch_passive(sim.mj_model, sim.mj_data)
        except Exception as error:  # GLFW reports a missing or refused display in several ways
            raise ViewerUnavailable(f"cannot open MuJoCo's viewer: {error}") from None
        self._threads = set(threading.enumerate()) - before
        sim.reset()
        with self._handle.lock():
            aim_at_robot(self._handle.cam, sim.mj_model, sim.mj_data)
        self._period = sim.scenario.period
        self.every = max(1, round(1.0 / (REFRESH * self._period)))
        self._start = time.perf_counter()

    def hook(self) -> Hook:
        return Hook(self.every, self._update)

    def _update(self, k: int) -> None:
        if not self._handle.is_running():
            return
        ahead = (k + 1) * self._period - (time.perf_counter() - self._start)
        if ahead > 0:
            time.sleep(ahead)
        self._handle.sync()

    def close(self) -> None:
        self._handle.close()
        # The viewer's daemon thread tears down OpenGL after close(): exiting the process
        # before it is done can crash.
        for thread in self._threads:
            thread.join(timeout=5.0)
