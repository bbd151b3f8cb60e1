"""Unit conversion: the one place where spec values become SI."""

from __future__ import annotations

import math
from typing import Literal, Sequence

AngleUnit = Literal["rad", "deg"]
AngularVelocityUnit = Literal["rad/s", "deg/s"]
AngularAccelerationUnit = Literal["rad/s^2", "deg/s^2"]

_FACTORS: dict[str, float] = {
    "rad": 1.0,
    "deg": math.pi / 180.0,
    "rad/s": 1.0,
    "deg/s": math.pi / 180.0,
    "rad/s^2": 1.0,
    "deg/s^2": math.pi / 180.0,
    "Nm": 1.0,
    "m": 1.0,
}


def to_si(value: float | Sequence[float] | None, unit: str) -> float | list[float] | None:
    """Convert a scalar or a list from `unit` to SI (rad, rad/s, rad/s², Nm, m)."""
    if value is None:
        return None
    factor = _FACTORS[unit]
    if isinstance(value, (int, float)):
        return float(value) * factor
    return [float(v) * factor for v in value]


def joint_to_si(values: Sequence[float], unit: str, prismatic: Sequence[bool]) -> list[float]:
    """Per-joint values (positions, or per s, per s²) from an angle `unit` to SI. A prismatic
    joint's values are in m (m/s, m/s²) whatever the unit says: `unit: deg` converted a torso
    lift's 0.2 m start to 0.0035 m, and its limits with it."""
    factor = _FACTORS[unit]
    return [float(v) * (1.0 if p else factor) for v, p in zip(values, prismatic, strict=True)]
