"""QP-MT: eq. (3) regularized by the torque norm r = ‖τ‖² (minimum torque), or by ‖τ − g‖² with
`controller.minimized_torque: without_gravity`."""

from __future__ import annotations

import casadi as ca

from ..symbolic.linalg import symmetric_product
from .problem import ControlProblem
from .qp import ControlLaw
from .weighted import weighted_qp


def qp_mt(problem: ControlProblem) -> ControlLaw:
    # τ = M a + c with c = ν + g − τ_ext:  ‖τ‖² = aᵀMᵀM a + 2cᵀM a + const; without gravity, c
    # drops g (the torque an OSC computes before adding g), so the null space no longer lets the
    # arm fall to save the gravity torque
    M = problem.mass_matrix
    c = problem.coriolis - problem.external_torque
    if problem.spec.controller.minimized_torque == "full":
        c = c + problem.gravity
    return weighted_qp(problem, 2.0 * symmetric_product(M, M), 2.0 * ca.mtimes(M.T, c))
