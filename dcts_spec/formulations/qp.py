"""What a formulation produces: τ, a and s as affine maps of the QP variable x, and the QP itself."""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from .problem import ControlProblem

INF = float("inf")
# Penalty of each bound's relaxation slack, relative to the largest curvature of the objective:
# the slacks only exist in the second solve, when the limits and the torque bounds cannot all
# hold, where they must dominate every task weight.
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

    The last `relaxable_rows` rows are the joint/Cartesian acceleration bounds. If the QP is
    infeasible (the torque limits cannot hold them all), it is solved again with each of those
    bounds widened by its own slack, heavily penalized (`relaxed_qp`).
    """

    hessian: ca.SX
    gradient: ca.SX
    constraints: ca.SX
    lba: ca.SX
    uba: ca.SX
    lbx: ca.SX
    ubx: ca.SX
    variables: list[str]
    relaxable_rows: int = 0

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
    lbx: list[float],
    ubx: list[float],
    variables: list[str],
) -> tuple[QP, Affine]:
    """Add the torque bounds and the joint/Cartesian acceleration bounds to an objective in x.

    Returns the QP and the torque as an affine map of x.
    """
    torque = Affine(problem.torque(acceleration.offset), ca.mtimes(problem.mass_matrix, acceleration.matrix))
    rows = problem.acceleration_rows
    R_c = ca.mtimes(rows.matrix, acceleration.offset) + rows.offset
    tau_max = ca.DM(problem.torque_max)
    A = ca.vertcat(torque.matrix, ca.mtimes(rows.matrix, acceleration.matrix))
    lba = ca.vertcat(-tau_max - torque.offset, rows.lower - R_c)
    uba = ca.vertcat(tau_max - torque.offset, rows.upper - R_c)
    qp = QP(hessian, gradient, A, lba, uba, ca.vertcat(*lbx), ca.vertcat(*ubx), variables, len(rows))
    return qp, torque


def relaxed_qp(
    H: np.ndarray,
    f: np.ndarray,
    A: np.ndarray,
    lba: np.ndarray,
    uba: np.ndarray,
    lbx: np.ndarray,
    ubx: np.ndarray,
    relaxable_rows: int,
) -> tuple[np.ndarray, ...]:
    """The QP data with each of the last `relaxable_rows` rows widened by a slack sᵣ ≥ 0.

    Variables (x, s); objective ½xᵀHx + fᵀx + ½ρ‖s‖² with ρ = RELAXATION_WEIGHT · max|H_ii|;
    a relaxable row lo ≤ aᵀx ≤ hi becomes aᵀx − sᵣ ≤ hi and aᵀx + sᵣ ≥ lo, so every bound is
    violated only as much as the torque limits force it to be. NumPy in and out (the generated
    C does the same on its arrays).
    """
    nx, r = H.shape[0], relaxable_rows
    fixed = A.shape[0] - r
    rho = RELAXATION_WEIGHT * max(1.0, float(np.max(np.abs(np.diag(H))))) if nx else RELAXATION_WEIGHT
    H2 = np.zeros((nx + r, nx + r))
    H2[:nx, :nx] = H
    H2[nx:, nx:] = rho * np.eye(r)
    slack = np.eye(r)
    A2 = np.block([[A[:fixed], np.zeros((fixed, r))], [A[fixed:], -slack], [A[fixed:], slack]])
    inf = np.full(r, INF)
    lba2 = np.concatenate([lba[:fixed], -inf, lba[fixed:]])
    uba2 = np.concatenate([uba[:fixed], uba[fixed:], inf])
    return H2, np.concatenate([f, np.zeros(r)]), A2, lba2, uba2, np.concatenate([lbx, np.zeros(r)]), np.concatenate([ubx, inf])
