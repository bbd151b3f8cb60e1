"""Bumpless parameter changes: a new set is reached linearly over the ramp time, one step at a time.

The C runtime (codegen/templates/controller.c.in: ctl_ramp_advance) does exactly the same, so
both runtimes apply the same values at every step.
"""

from __future__ import annotations

import math

import numpy as np


TWO_PI = 2.0 * math.pi


def ramp_steps(ramp_time: float, period: float) -> int:
    """Control steps a change takes: the ramp time in periods, at least 1 (the next step)."""
    return max(1, math.ceil(ramp_time / period - 1e-9))


class ParameterRamp:
    """The parameter values applied at each step while moving from one set to the next.

    `set(target)` starts a ramp from the values the last step applied; each `advance()` (once per
    control step, before the step uses them) moves 1/steps of the way, and the steps-th one lands
    on the target exactly. A set given during a ramp starts a new ramp from where it is.
    `periodic`: the values that are angles of period 2π (an orientation reference's roll, pitch
    and yaw): their target is taken as the equivalent angle within π of where the ramp is, so a
    ramp turns the short way round (yaw 3.1 → -3.1 swept the target through 0, and a reference
    of [π, 0, 0] set to the same orientation as [-π, 0, 0] turned it a full turn: torque steps of
    65 and 149 Nm, found from outside).
    """

    def __init__(self, defaults: np.ndarray, steps: int, periodic: np.ndarray | None = None):
        self.steps = int(steps)
        self.start = np.array(defaults, dtype=float)
        self.target = self.start.copy()
        self.now = self.start.copy()
        self.k = self.steps
        self.periodic = np.zeros(self.start.size, dtype=bool) if periodic is None else np.asarray(periodic, dtype=bool)

    def set(self, target: np.ndarray) -> None:
        self.start = self.now.copy()
        self.target = np.array(target, dtype=float)
        turn = self.target[self.periodic] - self.now[self.periodic]
        # (the same operations, in the same order, as the C set_params)
        self.target[self.periodic] = self.now[self.periodic] + (turn - TWO_PI * np.floor(turn / TWO_PI + 0.5))
        self.k = 0

    def advance(self) -> np.ndarray:
        """The values of this step."""
        if self.k < self.steps:
            self.k += 1
            if self.k >= self.steps:
                self.now = self.target.copy()
            else:
                self.now = self.start + (self.target - self.start) * (self.k / self.steps)
        return self.now
