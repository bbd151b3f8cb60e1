"""The check that makes status "ok" a guarantee: the joint and Cartesian acceleration bounds of the
QP data, at the answer, in their own units (rad/s², m/s²)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .stage_qp import FEASIBILITY_TOLERANCE

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


def _rows(bound_rows: range, A: np.ndarray, lba: np.ndarray, uba: np.ndarray, x: np.ndarray,
          shift: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each bound row's excess at x (< 0 inside), the QP's bound it is nearest to or beyond, and the
    check's tolerance there, in the row's units."""
    value = A[bound_rows.start : bound_rows.stop] @ x
    lo, hi = lba[bound_rows.start : bound_rows.stop], uba[bound_rows.start : bound_rows.stop]
    excess = np.maximum(lo - value, value - hi)
    nearest = np.where(lo - value > value - hi, lo, hi)
    return excess, nearest, BOUND_TOLERANCE * np.maximum(1.0, np.abs(nearest + shift))


def check_bounds(bound_rows: range, A: np.ndarray, lba: np.ndarray, uba: np.ndarray, x: np.ndarray,
                 shift: np.ndarray) -> BoundCheck:
    """Check the bound rows of the QP data at x, in their own units: a row's value and bounds in
    them are the QP's plus its constant part `shift` (the data's bound_shift), and the tolerance
    is relative to the bound there, not to the QP's (a PR2 wrist's 20 rad/s² was 274 in the QP,
    and 2.3e-5 rad/s² over it, 1.1e-6 of the bound, passed as 8e-8 of 274)."""
    excess, _, tolerance = _rows(bound_rows, A, lba, uba, x, shift)
    return BoundCheck([int(i) for i in np.flatnonzero(excess > tolerance)])


def marginal_rows(bound_rows: range, A: np.ndarray, lba: np.ndarray, uba: np.ndarray, x: np.ndarray,
                  shift: np.ndarray) -> np.ndarray:
    """The bound rows whose check at x rounding can decide either way: their excess is within what
    the cascade resolves a row to (FEASIBILITY_TOLERANCE of its bound in the QP, `Cascade._holds`)
    of the check's tolerance (in the row's units). That happens where the QP's bound dwarfs the
    row's own: a heavy load on a light wrist, whose free acceleration of 7,650 rad/s² put the QP's
    bound of a 20 rad/s² limit at 7,630, resolved to 7.6e-4 rad/s² where the check allows 2e-5;
    one runtime's answer held the limit to 1e-10, the other's crossed it by 3.3e-4."""
    excess, nearest, tolerance = _rows(bound_rows, A, lba, uba, x, shift)
    resolution = FEASIBILITY_TOLERANCE * np.maximum(1.0, np.abs(nearest))
    return np.isfinite(nearest) & (np.abs(excess - tolerance) <= resolution)
