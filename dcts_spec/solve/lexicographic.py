"""The lexicographic solve of a QP's row levels with DAQP's hierarchical mode, and its check.

DAQP (≥ 0.11) takes the levels as `break_points`: the first level is hard; each level below
minimizes the squared violation of its rows without increasing that of any level above, with
proximal iterations that remove the bias of its soft-constraint penalty, so each level is
optimal given the levels above (not approximately, through weights); what freedom is left
minimizes ½xᵀHx + fᵀx. The generated C calls the same DAQP sources the same way.

A solver's exit flag is not evidence: `check_bounds` verifies the joint and Cartesian bounds on
the unscaled data, in their own units (rad/s², m/s²), after every solve.
"""

from __future__ import annotations

from dataclasses import dataclass

import daqp
import numpy as np

from ..formulations.qp import BOUNDS, QP

# Both runtimes: a primal tolerance tighter than DAQP's 1e-6, so that bounds hold to ~1e-8 in
# the scaled problem, and a bounded iteration count (all levels and proximal steps together).
DAQP_SETTINGS = {"primal_tol": 1e-8, "iter_limit": 1000}
DAQP_INF = 1e30  # DAQP's "no bound"
# A joint or Cartesian acceleration bound holds if it is crossed by at most this much, relative
# to max(1, |bound|) (rad/s² or m/s²): over a 1 ms period ~5e-13 m or rad of position.
BOUND_TOLERANCE = 1e-6


def solve_lexicographic(
    H: np.ndarray, f: np.ndarray, A: np.ndarray, lower: np.ndarray, upper: np.ndarray, break_points: list[int]
) -> tuple[np.ndarray | None, int, int]:
    """x of the lexicographic QP (None if DAQP failed), DAQP's exit flag and iteration count.

    `lower` and `upper` are DAQP's: the nx variable bounds, then the rows of A."""
    lower = np.clip(lower, -DAQP_INF, DAQP_INF)
    upper = np.clip(upper, -DAQP_INF, DAQP_INF)
    sense = np.zeros(lower.size, dtype=np.intc)
    x, _, exitflag, info = daqp.solve(
        np.ascontiguousarray(H), np.ascontiguousarray(f), np.ascontiguousarray(A), upper, lower, sense,
        break_points=np.asarray(break_points, dtype=np.intc), **DAQP_SETTINGS,
    )
    if exitflag < 1 or not np.all(np.isfinite(x)):
        return None, int(exitflag), int(info["iterations"])
    return np.asarray(x, dtype=float), int(exitflag), int(info["iterations"])


@dataclass
class BoundCheck:
    """Which joint/Cartesian acceleration bounds a solution crosses, worst first, and by how much."""

    violated: list[int]  # indices into the bound rows
    violation: list[float]  # in the bound's own unit (rad/s² or m/s²)

    @property
    def holds(self) -> bool:
        return not self.violated


def check_bounds(qp: QP, A: np.ndarray, lba: np.ndarray, uba: np.ndarray, x: np.ndarray) -> BoundCheck:
    """Check the bound rows of the (unscaled) QP data at x."""
    rows = qp.rows_of(BOUNDS)
    value = A[rows.start : rows.stop] @ x
    lo, hi = lba[rows.start : rows.stop], uba[rows.start : rows.stop]
    excess = np.maximum(lo - value, value - hi)
    crossed = np.where(value < lo, lo, hi)
    tolerance = BOUND_TOLERANCE * np.maximum(1.0, np.abs(crossed))
    bad = np.flatnonzero(excess > tolerance)
    order = bad[np.argsort(-excess[bad])]
    return BoundCheck([int(i) for i in order], [float(excess[i]) for i in order])
