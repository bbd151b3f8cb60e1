"""The paper's eq. (3): tasks as weighted least squares in one QP, plus a regularization term.

    min_a  Σᵢ ŵᵢ ‖Jᵢ a + J̇ᵢ q̇ − ẍ_d,ᵢ‖² + w_r r(a)   s.t. torque, joint and Cartesian bounds

with ŵᵢ = wᵢ / w₁ (soft priorities) and the regularization weighted `regularization_weight` times
the lowest level. The variable is the actual acceleration a; τ = M a + ν + g − τ_ext.
"""

from __future__ import annotations

import casadi as ca

from ..symbolic.linalg import symmetric_product
from .problem import ControlProblem
from .qp import INF, Affine, ControlLaw, with_limits

# ε‖a‖², relative to the top level: keeps the Hessian positive definite with a sane condition number
# where neither the tasks nor the regularization see a joint (QP-MT barely sees a light wrist,
# whose torques are tiny); it changes the solution by ~ε.
ACCELERATION_REGULARIZATION = 1e-8


def weighted_qp(problem: ControlProblem, regularization_hessian: ca.SX, regularization_gradient: ca.SX) -> ControlLaw:
    """QP-MT / QP-MD given their regularization ½aᵀH_r a + f_rᵀa (up to a constant)."""
    n = problem.n
    top = problem.levels[0].weight
    H = ca.SX(n, n)
    f = ca.SX(n, 1)
    for level in problem.levels:
        w = level.weight / top
        J = level.jacobian
        # a task's run-time activation scales its weight (0: it is left out)
        Jw = J if level.activation is None else ca.mtimes(ca.diag(level.activation), J)
        H += 2.0 * w * symmetric_product(Jw, J)
        f += -2.0 * w * ca.mtimes(Jw.T, level.target - level.bias)
    w_r = problem.spec.controller.regularization_weight * problem.levels[-1].weight / top
    H += w_r * regularization_hessian + ACCELERATION_REGULARIZATION * ca.SX.eye(n)
    f += w_r * regularization_gradient
    acceleration = Affine(ca.SX.zeros(n), ca.SX.eye(n))
    qp, torque = with_limits(problem, acceleration, H, f, [-INF] * n, [INF] * n, [f"a[{j}]" for j in range(n)])
    scaling = Affine.constant(ca.SX.ones(len(problem.levels)), qp.nx)
    return ControlLaw(torque, scaling, qp, acceleration=acceleration)
