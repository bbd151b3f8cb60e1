"""Minimum-jerk segments: a smooth, time-parametrized path from one waypoint to the next.

A segment from a to b over T seconds is r(t) = a + (b − a) s(t/T) with s(u) = 10u³ − 15u⁴ + 6u⁵:
it starts and ends at rest (ṙ = r̈ = 0), and its peak speed is 15/8 ‖b − a‖ / T, at mid-time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

PEAK_SPEED_FACTOR = 15.0 / 8.0  # max_u s'(u)
UNSTIFF_SEGMENT = 1.0  # s per segment for a task without stiffness (no natural period to go by)


def minimum_jerk(u: float) -> tuple[float, float, float]:
    """s(u), s'(u), s''(u) for u in [0, 1] (clamped outside)."""
    u = min(max(u, 0.0), 1.0)
    return (u**3 * (10.0 - 15.0 * u + 6.0 * u**2),
            30.0 * u**2 * (1.0 - u) ** 2,
            60.0 * u * (1.0 - u) * (1.0 - 2.0 * u))


def segment_duration(distance: float, kp: np.ndarray, max_velocity: float | None) -> float:
    """How long a segment of `distance` (the norm of the task's error between its ends) takes.

    At least one natural period 2π/√kp of the task's PD (its smallest positive kp): a short hop
    then asks no more acceleration than the PD's own response to it. With `max_velocity`, long
    enough that the path's peak speed is max_velocity, the speed the saturated law would move at.
    """
    stiff = np.asarray(kp, dtype=float)
    stiff = stiff[stiff > 0]
    duration = 2.0 * math.pi / math.sqrt(float(stiff.min())) if stiff.size else UNSTIFF_SEGMENT
    if max_velocity is not None:
        duration = max(duration, PEAK_SPEED_FACTOR * distance / max_velocity)
    return duration


@dataclass(frozen=True)
class Segment:
    """From `start` to `end` (reference vectors) during [t0, t0 + duration]."""

    start: np.ndarray
    end: np.ndarray
    t0: float
    duration: float

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Reference, its rate and its second rate at time t (held at the ends outside)."""
        s, ds, dds = minimum_jerk((t - self.t0) / self.duration)
        delta = self.end - self.start
        return self.start + s * delta, delta * (ds / self.duration), delta * (dds / self.duration**2)

    def over(self, t: float) -> bool:
        return t >= self.t0 + self.duration
