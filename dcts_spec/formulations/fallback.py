"""The safe fallback torque: gravity compensation and a damping that is stable at the control period.

    τ = M(q) a_d + ν + g,    a_d,j = −λ_j q̇_j,    λ_j = min(D_j / M_jj(q), β / dt)

With the torque held over a period dt, a joint's velocity becomes (1 − λ_j dt) q̇_j: it decays
without overshoot as long as λ_j dt ≤ 1, whatever the joint's inertia. A plain τ = g − D q̇
multiplies the velocity of a light joint by 1 − dt D / m each period, which is below −1 (growing
oscillation) once m < dt D / 2 (the iiwa14's last joint: 9e-4 kg·m² against 5e-3 for D = 10).
D_j / M_jj is the decay rate `controller.fallback_damping` gives a joint of inertia M_jj; β caps it.

Clipping each joint's torque to its limit would break that decay (a light joint driven by the
others' clipped coupling torques sped up); instead the damping part is scaled down by one factor
α ∈ [0, 1], the largest that keeps every torque within its limit: a = α a_d, still a decay. A joint
whose ν + g alone is beyond its limit on the side its braking pushes to (fast, or its torque limit
lowered at run time below its gravity load) is clipped whatever α is and does not count: with it,
α was 0 and no joint was braked (an iiwa14 with joint 2 limited to 40 Nm against 77 Nm of gravity:
joint 4 reached 12 rad/s in 0.3 s of fallback).

The caller (both runtimes) gives this function a velocity of 0 where the reading is non-finite,
or beyond any the joint can reach (`plausible_velocity`: a sensor fault). ν grows like q̇², and
at q̇ = 1e154 rad/s the torque overflowed and was zeroed, an iiwa14 losing its gravity
compensation; taken at a cap instead, its Coriolis term used up the torque room and no joint
was braked at all. (Done by the caller, not in this function: there it cost 12 % more
operations and 4 kB of Cortex-M7 flash.)
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from .problem import ControlProblem

STEP_DECAY = 0.5  # β: at most half of a joint's velocity is removed per period
VELOCITY_CAP = 10.0  # × the joint's velocity limit: beyond it, a reading is a fault
UNBOUNDED_VELOCITY_CAP = 100.0  # rad/s or m/s, for a joint without one


def plausible_velocity(v_max: np.ndarray) -> np.ndarray:
    """The largest |q̇| per joint the fallback takes as a reading (the rest count as 0)."""
    return np.where(np.isfinite(v_max), VELOCITY_CAP * np.asarray(v_max, dtype=float), UNBOUNDED_VELOCITY_CAP)


def fallback_torque(problem: ControlProblem) -> ca.SX:
    """The fallback torque as a function of q and q̇ (within the torque limits, except on a joint
    whose ν + g alone is not: the caller clips it)."""
    M = problem.mass_matrix
    damping = ca.DM(problem.vector("fallback_damping"))
    rate = ca.fmin(damping / ca.diag(M), STEP_DECAY / problem.period)
    hold, brake = problem.coriolis + problem.gravity, ca.mtimes(M, -rate * problem.dq)
    alpha = ca.SX(1.0)
    for j, compiled in enumerate(problem.torque_max):
        if not np.isfinite(compiled):
            continue
        limit = problem.torque_limit[j]  # (a run-time torque limit, if there is one)
        room = ca.if_else(brake[j] > 0, limit - hold[j], -limit - hold[j])  # brake[j]·α may use this
        share = ca.if_else(ca.fabs(brake[j]) > 0, room / (brake[j] + (brake[j] == 0)), 1.0)
        alpha = ca.fmin(alpha, ca.if_else(share >= 0, share, 1.0))  # (< 0: ν + g alone is beyond)
    return hold + alpha * brake
