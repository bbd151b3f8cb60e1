"""What a formulation produces: τ, a and s as affine maps of the QP variable x, and the QP itself.

Every QP here is *lexicographic*: its rows come in levels, highest priority first, and each level
is solved as well as it can be without touching the levels above (`solve/lexicographic.py`):

    level 0   the variable bounds and the torque limits                       hard
    level 1   joint and Cartesian bounds, shaped into acceleration bounds     hard, or least violation
    level 2…  the formulation's own levels (dcts: one or two per priority)     least squares
    last      ½ xᵀHx + fᵀx over whatever freedom is left

The joint and Cartesian bounds are first solved as hard rows with the torque limits (the usual
case: they hold exactly). When the torque limits cannot hold them all, the QP is solved again with
them as their own level below the torque limits: each bound is violated as little as they allow,
and no task can buy a larger violation (status "limits relaxed").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca

from .problem import ControlProblem

INF = float("inf")
HARD = "hard"
BOUNDS = "bounds"
TASK = "task"


@dataclass
class Affine:
    """y = offset + matrix · x."""

    offset: ca.SX
    matrix: ca.SX

    @staticmethod
    def constant(offset: ca.SX, nx: int) -> "Affine":
        return Affine(offset, ca.SX(offset.shape[0], nx))


@dataclass
class RowLevel:
    """A block of consecutive rows of A that share one priority."""

    name: str
    kind: str  # HARD, BOUNDS or TASK
    rows: int


@dataclass
class QP:
    """min ½ xᵀHx + fᵀx  s.t.  lbx ≤ x ≤ ubx,  lba ≤ A x ≤ uba, row levels solved lexicographically."""

    hessian: ca.SX
    gradient: ca.SX
    constraints: ca.SX
    lba: ca.SX
    uba: ca.SX
    lbx: ca.SX
    ubx: ca.SX
    variables: list[str]
    levels: list[RowLevel]

    @property
    def nx(self) -> int:
        return len(self.variables)

    @property
    def na(self) -> int:
        return int(self.constraints.shape[0])

    def rows_of(self, kind: str) -> range:
        """The rows of A in the levels of one kind (they are consecutive)."""
        start = 0
        first = last = None
        for level in self.levels:
            if level.kind == kind:
                first = start if first is None else first
                last = start + level.rows
            start += level.rows
        return range(0, 0) if first is None else range(first, last)

    def break_points(self, relaxed: bool = False) -> list[int]:
        """DAQP's break points: the end of each non-empty level, counting the nx variable bounds
        (DAQP's simple bounds) as the first rows of the hard level.

        The joint/Cartesian bounds are hard, with the torque limits, unless `relaxed`: then they are
        the level below them, violated as little as the torque limits allow. (DAQP meets a hard
        level exactly; a soft level only to within its proximal iterations, ~1e-5 relative.)"""
        points, end = [], self.nx
        for level in self.levels:
            if level.kind == BOUNDS and not relaxed:
                points[-1] += level.rows
                continue
            end = (points[-1] if points else end) + level.rows
            if level.rows or not points:
                points.append(end)
        return points


@dataclass
class ControlLaw:
    """The outputs of a formulation as affine maps of x (with nx = 0 for closed forms)."""

    torque: Affine
    scaling: Affine
    qp: QP | None = None
    notes: list[str] = field(default_factory=list)
    # False for formulations that ignore the torque limits: their torque is clipped naively.
    enforces_torque_limits: bool = True
    # An over-constrained lowest level (least squares, no scaling variable): its task
    # acceleration as (matrix, offset) in x; its scaling is computed after the solve (controller).
    least_squares_task: tuple[ca.SX, ca.SX] | None = None

    @property
    def nx(self) -> int:
        return 0 if self.qp is None else self.qp.nx


@dataclass
class TaskRows:
    """One task level of a lexicographic QP: lower ≤ matrix · x ≤ upper in the least-squares sense."""

    name: str
    matrix: ca.SX
    lower: ca.SX
    upper: ca.SX


def with_limits(
    problem: ControlProblem,
    acceleration: Affine,
    hessian: ca.SX,
    gradient: ca.SX,
    lbx: list[float],
    ubx: list[float],
    variables: list[str],
    tasks: list[TaskRows] = (),
) -> tuple[QP, Affine]:
    """The lexicographic QP: torque limits (hard), joint/Cartesian bounds, then `tasks`, then ½xᵀHx + fᵀx.

    Returns the QP and the torque as an affine map of x.
    """
    torque = Affine(problem.torque(acceleration.offset), ca.mtimes(problem.mass_matrix, acceleration.matrix))
    rows = problem.acceleration_rows
    R_c = ca.mtimes(rows.matrix, acceleration.offset) + rows.offset
    tau_max = ca.DM(problem.torque_max)
    A = ca.vertcat(torque.matrix, ca.mtimes(rows.matrix, acceleration.matrix), *[t.matrix for t in tasks])
    lba = ca.vertcat(-tau_max - torque.offset, rows.lower - R_c, *[t.lower for t in tasks])
    uba = ca.vertcat(tau_max - torque.offset, rows.upper - R_c, *[t.upper for t in tasks])
    levels = [RowLevel("torque limits", HARD, problem.n), RowLevel("joint and Cartesian bounds", BOUNDS, len(rows))]
    levels += [RowLevel(t.name, TASK, int(t.matrix.shape[0])) for t in tasks]
    qp = QP(hessian, gradient, A, lba, uba, ca.vertcat(*lbx), ca.vertcat(*ubx), variables, levels)
    return qp, torque
