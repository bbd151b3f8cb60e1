"""The check that makes status "ok" a guarantee: the joint and Cartesian acceleration bounds of the
QP data, at the answer, in their own units (rad/s², m/s²)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# A joint or Cartesian acceleration bound holds if it is crossed by at most this much, relative
# to max(1, |bound|) (rad/s² or m/s²): over a 1 ms period ~5e-13 m or rad of position.
BOUND_TOLERANCE = 1e-6


@dataclass
class BoundCheck:
    """Which joint/Cartesian acceleration bounds a solution crosses."""

    violated: list[int]  # indices into the bound rows, in row order

    @property
    def holds(self) -> bool:
        return not self.violated


def check_bounds(bound_rows: range, A: np.ndarray, lba: np.ndarray, uba: np.ndarray, x: np.ndarray,
                 shift: np.ndarray) -> BoundCheck:
    """Check the bound rows of the QP data at x, in their own units: a row's value and bounds in
    them are the QP's plus its constant part `shift` (the data's bound_shift), and the tolerance
    is relative to the bound there, not to the QP's (a PR2 wrist's 20 rad/s² was 274 in the QP,
    and 2.3e-5 rad/s² over it, 1.1e-6 of the bound, passed as 8e-8 of 274)."""
    value = A[bound_rows.start : bound_rows.stop] @ x
    lo, hi = lba[bound_rows.start : bound_rows.stop], uba[bound_rows.start : bound_rows.stop]
    excess = np.maximum(lo - value, value - hi)
    crossed = np.where(value < lo, lo, hi) + shift
    bad = np.flatnonzero(excess > BOUND_TOLERANCE * np.maximum(1.0, np.abs(crossed)))
    return BoundCheck([int(i) for i in bad])
