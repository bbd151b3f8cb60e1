"""QP-MT: eq. (3) regularized by the torque norm r = ‖τ‖² (minimum torque)."""

from __future__ import annotations

import casadi as ca

from .problem import ControlProblem
from .qp import ControlLaw
from .weighted import weighted_qp


def qp_mt(problem: ControlProblem) -> ControlLaw:
    # τ = M a + c with c = ν + g − τ_ext:  ‖τ‖² = aᵀMᵀM a + 2cᵀM a + const
    M = problem.mass_matrix
    c = problem.coriolis + problem.gravity - problem.external_torque
    return weighted_qp(problem, 2.0 * ca.mtimes(M.T, M), 2.0 * ca.mtimes(M.T, c))
