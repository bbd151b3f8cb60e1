"""What a formulation produces: τ, a and s as affine maps of the QP variable x, and the QP itself."""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca

from .problem import ControlProblem

INF = float("inf")
# Penalty on the limit relaxation σ, relative to the largest curvature of the objective: σ is only
# in play when the limits and the torque bounds cannot all hold, where it must dominate every task
# weight; relative, so the Hessian stays as well conditioned as the formulation allows.
RELAXATION_WEIGHT = 1e3


@dataclass
class Affine:
    """y = offset + matrix · x."""

    offset: ca.SX
    matrix: ca.SX

    @staticmethod
    def constant(offset: ca.SX, nx: int) -> "Affine":
        return Affine(offset, ca.SX(offset.shape[0], nx))


@dataclass
class QP:
    """min ½ xᵀHx + fᵀx  s.t.  lbx ≤ x ≤ ubx,  lba ≤ A x ≤ uba.

    If `relaxation` is set, x[relaxation] is the limit relaxation σ ≥ 0: it is held at 0 in
    the first solve and freed (its upper bound set to +inf) only if that solve is infeasible.
    """

    hessian: ca.SX
    gradient: ca.SX
    constraints: ca.SX
    lba: ca.SX
    uba: ca.SX
    lbx: ca.SX
    ubx: ca.SX
    variables: list[str]
    relaxation: int | None = None

    @property
    def nx(self) -> int:
        return len(self.variables)

    @property
    def na(self) -> int:
        return int(self.constraints.shape[0])


@dataclass
class ControlLaw:
    """The outputs of a formulation as affine maps of x (with nx = 0 for closed forms)."""

    torque: Affine
    scaling: Affine
    qp: QP | None = None
    notes: list[str] = field(default_factory=list)
    # False for formulations that ignore the torque limits: their torque is clipped naively.
    enforces_torque_limits: bool = True

    @property
    def nx(self) -> int:
        return 0 if self.qp is None else self.qp.nx


def with_limits(
    problem: ControlProblem,
    acceleration: Affine,
    hessian: ca.SX,
    gradient: ca.SX,
    lbx: list,
    ubx: list,
    variables: list[str],
) -> tuple[QP, Affine]:
    """Add the torque bounds, the joint/Cartesian acceleration bounds and the relaxation σ.

    Each acceleration bound lo ≤ R a + r ≤ hi becomes two one-sided rows, R a + r − σ ≤ hi and
    R a + r + σ ≥ lo, so a single σ widens every bound when the torque limits leave no choice.
    Returns the QP and the torque as an affine map of the extended x.
    """
    nx = len(variables) + 1
    sigma = len(variables)
    G = ca.horzcat(acceleration.matrix, ca.SX.zeros(problem.n, 1))
    torque = Affine(problem.torque(acceleration.offset), ca.mtimes(problem.mass_matrix, G))

    rows = problem.acceleration_rows
    R_G = ca.mtimes(rows.matrix, G)
    R_c = ca.mtimes(rows.matrix, acceleration.offset) + rows.offset
    e_sigma = ca.SX.zeros(1, nx)
    e_sigma[0, sigma] = 1.0
    ones = ca.SX.ones(len(rows), 1)
    upper_rows = R_G - ca.mtimes(ones, e_sigma)
    lower_rows = R_G + ca.mtimes(ones, e_sigma)
    tau_max = ca.DM(problem.torque_max)
    A = ca.vertcat(torque.matrix, upper_rows, lower_rows)
    lba = ca.vertcat(-tau_max - torque.offset, -INF * ones, rows.lower - R_c)
    uba = ca.vertcat(tau_max - torque.offset, rows.upper - R_c, INF * ones)

    largest = ca.mmax(ca.fabs(ca.diag(hessian))) if len(variables) else ca.SX(1.0)
    H = ca.diagcat(hessian, RELAXATION_WEIGHT * largest)
    f = ca.vertcat(gradient, 0.0)
    qp = QP(H, f, A, lba, uba, ca.vertcat(*lbx, 0.0), ca.vertcat(*ubx, 0.0), [*variables, "sigma"], sigma)
    return qp, torque
