"""What a formulation produces: τ, a and s as affine maps of the QP variable x, and the QP itself.

A QP has hard rows (the torque limits), the joint/Cartesian bound rows, and, for dcts, priority
levels given as groups of variables (each level's scaling sᵢ and bend δᵢ): the lexicographic
solve (`solve/lexicographic.py`) fixes them one level after the other, highest first, and
minimizes ½ xᵀHx + fᵀx over the freedom left. A formulation without priority levels (QP-MT,
QP-MD) is one QP. The bound rows are hard unless the torque limits cannot hold them all; then
each is violated as little as they allow, before any priority level is considered.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca

from ..symbolic.linalg import product
from .problem import ControlProblem

INF = float("inf")
HARD = "hard"
BOUNDS = "bounds"


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
    """A block of consecutive rows of A of one kind."""

    name: str
    kind: str  # HARD or BOUNDS
    rows: int


@dataclass
class PriorityVariables:
    """The variables of one priority level: its scaling s (x index) and its bend δ (x indices)."""

    priority: int
    scaling: int
    bend: list[int]


@dataclass
class QP:
    """min ½ xᵀHx + fᵀx  s.t.  lbx ≤ x ≤ ubx,  lba ≤ A x ≤ uba, with the priority levels first."""

    hessian: ca.SX
    gradient: ca.SX
    constraints: ca.SX
    lba: ca.SX
    uba: ca.SX
    lbx: ca.SX
    ubx: ca.SX
    variables: list[str]
    levels: list[RowLevel]
    priorities: list[PriorityVariables] = field(default_factory=list)
    # the joint/Cartesian bound rows' constant part R a₀ + offset: their value in their own units
    # (rad/s², m/s²) is the row's A x plus it, and so are their bounds (`solve.check_bounds`)
    bound_shift: ca.SX = field(default_factory=lambda: ca.SX(0, 1))

    @property
    def nx(self) -> int:
        return len(self.variables)

    @property
    def na(self) -> int:
        return int(self.constraints.shape[0])

    def rows_of(self, kind: str) -> range:
        """The rows of A of one kind (they are consecutive)."""
        start = 0
        for level in self.levels:
            if level.kind == kind:
                return range(start, start + level.rows)
            start += level.rows
        return range(start, start)


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
    # The actual joint acceleration a(x) = M⁻¹(τ − ν − g + τ_ext), where the formulation has it at
    # hand (the QP ones): the commanded q̈ is then read from it, not formed again as M⁻¹(M a).
    acceleration: Affine | None = None
    # Some of the variables after the levels' own are seen by no row (up to rounding): DCTS's N_k z
    # below a run-time activation (solve.Structure.spare_variables)
    spare_variables: bool = False

    @property
    def nx(self) -> int:
        return 0 if self.qp is None else self.qp.nx


def with_limits(
    problem: ControlProblem,
    acceleration: Affine,
    hessian: ca.SX,
    gradient: ca.SX,
    lbx: list[float],
    ubx: list[float],
    variables: list[str],
    priorities: list[PriorityVariables] = (),
    mass_acceleration: ca.SX | None = None,
) -> tuple[QP, Affine]:
    """The QP: torque limits (hard), joint/Cartesian bounds, the priority levels, then ½xᵀHx + fᵀx.

    Returns the QP and the torque as an affine map of x. `mass_acceleration`: M times the
    acceleration's matrix, if the caller has it already (the same product, not a second one).
    """
    if mass_acceleration is None:
        mass_acceleration = product(problem.mass_matrix, acceleration.matrix)
    torque = Affine(problem.torque(acceleration.offset), mass_acceleration)
    rows = problem.acceleration_rows
    R_c = ca.mtimes(rows.matrix, acceleration.offset) + rows.offset
    tau_max = problem.torque_limit
    A = ca.vertcat(torque.matrix, product(rows.matrix, acceleration.matrix))
    lba = ca.vertcat(-tau_max - torque.offset, rows.lower - R_c)
    uba = ca.vertcat(tau_max - torque.offset, rows.upper - R_c)
    levels = [RowLevel("torque limits", HARD, problem.n), RowLevel("joint and Cartesian bounds", BOUNDS, len(rows))]
    qp = QP(hessian, gradient, A, lba, uba, ca.vertcat(*lbx), ca.vertcat(*ubx), variables, levels, list(priorities), R_c)
    return qp, torque
