"""QP-MD: eq. (3) regularized by a joint damping task r = ‖q̈ − q̈_d‖², q̈_d = −D q̇."""

from __future__ import annotations

import casadi as ca

from .problem import ControlProblem
from .qp import ControlLaw
from .weighted import weighted_qp


def qp_md(problem: ControlProblem) -> ControlLaw:
    # q̈ = a − M⁻¹τ_ext is the commanded acceleration:  ‖a − (M⁻¹τ_ext − D q̇)‖²
    damping = ca.DM(problem.vector("joint_damping"))
    desired = ca.mtimes(problem.mass_matrix_inverse, problem.external_torque) - damping * problem.dq
    return weighted_qp(problem, 2.0 * ca.SX.eye(problem.n), -2.0 * desired)
