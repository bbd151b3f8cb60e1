"""The safe fallback torque: gravity compensation and a damping that is stable at the control period.

    τ = M(q) a_d + ν + g,    a_d,j = −λ_j q̇_j,    λ_j = min(D_j / M_jj(q), β / dt)

With the torque held over a period dt, a joint's velocity becomes (1 − λ_j dt) q̇_j: it decays
without overshoot as long as λ_j dt ≤ 1, whatever the joint's inertia. A plain τ = g − D q̇
multiplies the velocity of a light joint by 1 − dt D / m each period, which is below −1 (growing
oscillation) once m < dt D / 2 (the iiwa14's last joint: 9e-4 kg·m² against 5e-3 for D = 10).
D_j / M_jj is the decay rate `controller.fallback_damping` gives a joint of inertia M_jj; β caps it.
"""

from __future__ import annotations

import casadi as ca

from .problem import ControlProblem

STEP_DECAY = 0.5  # β: at most half of a joint's velocity is removed per period


def fallback_torque(problem: ControlProblem) -> ca.SX:
    """The fallback torque (before clipping to the torque limits) as a function of q and q̇."""
    M = problem.mass_matrix
    damping = ca.DM(problem.vector("fallback_damping"))
    rate = ca.fmin(damping / ca.diag(M), STEP_DECAY / problem.period)
    return ca.mtimes(M, -rate * problem.dq) + problem.coriolis + problem.gravity
