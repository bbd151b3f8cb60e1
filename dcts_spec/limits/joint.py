"""Joint position, velocity and acceleration limits as bounds on each joint's acceleration."""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..robot.model import JointLimits
from .base import AccelerationRows
from .naming import joint_row_name
from .viability import acceleration_bounds, state_excess

# Braking acceleration the viability bound assumes when the spec gives no joint acceleration limit.
DEFAULT_BRAKING = 10.0  # rad/s² (or m/s² for prismatic joints)
# Where the torque limit cannot brake a joint at all (gravity alone beyond it), the bounds still
# need a braking > 0: this fraction of the nominal one (the joint then creeps toward its bound).
BRAKING_FLOOR = 0.01


@dataclass
class BrakingDynamics:
    """What a joint's braking is taken from: M(q)'s diagonal, the bias ν(q, q̇) + g(q) and the
    torque limits |τ| ≤ τ_max (run-time parameters where there are; inf where none)."""

    inertia: ca.SX  # M_jj (n)
    bias: ca.SX  # ν + g (n)
    torque_limit: ca.SX  # (n)

    def braking(self, j: int, nominal: ca.SX | float) -> tuple[ca.SX, ca.SX]:
        """(toward its upper bound, toward its lower bound): the deceleration joint j's own
        torque limit gives it at this state with the other joints still, τ = h + M e_j a, i.e.
        (τ_max ± h_j) / M_jj, at most `nominal` (the acceleration limit the position bounds
        assume otherwise) and at least BRAKING_FLOOR of it. Measured τ_ext is left out: the
        bounds follow the model, not a sensor's noise (a payload the robot carries belongs in
        `robot.payloads`)."""
        limit, bias, inertia = self.torque_limit[j], self.bias[j], self.inertia[j]
        floor = BRAKING_FLOOR * nominal
        return tuple(ca.fmax(ca.fmin((limit + sign * bias) / inertia, nominal), floor) for sign in (1.0, -1.0))


def joint_rows(limits: JointLimits, q: ca.SX, dq: ca.SX, dt: float, names: list[str],
               runtime: dict[str, list] | None = None, dynamics: BrakingDynamics | None = None) -> AccelerationRows:
    """One row per joint that has a finite position, velocity or acceleration bound. `runtime`
    replaces some limits (q_min, q_max, v_max, a_max: one value per joint) by run-time
    parameters; which rows and terms exist follows the compiled `limits`. The position bounds
    assume braking at the acceleration limit (DEFAULT_BRAKING without one), or at what the torque
    limit gives where that is less (a joint gravity pulls toward its bound), with `dynamics` and
    `limits.torque_limited_braking`."""
    n = q.shape[0]
    runtime = runtime or {}
    q_min, q_max, v_max, a_max = (runtime.get(key, getattr(limits, key)) for key in ("q_min", "q_max", "v_max", "a_max"))
    rows, lower, upper, excess, kept = [], [], [], [], []
    for j in range(n):
        bounded = [limits.q_min[j], limits.q_max[j], limits.v_max[j], limits.a_max[j]]
        if not np.isfinite(bounded).any():
            continue
        braking = a_max[j] if np.isfinite(limits.a_max[j]) else DEFAULT_BRAKING
        if dynamics is not None and limits.torque_limited_braking:
            braking = dynamics.braking(j, braking)
        lo, hi = acceleration_bounds(q[j], dq[j], q_min[j], q_max[j], v_max[j], a_max[j], braking, dt,
                                     (limits.q_min[j], limits.q_max[j], limits.v_max[j]))
        selection = ca.SX.zeros(1, n)
        selection[0, j] = 1.0
        rows.append(selection)
        lower.append(lo)
        upper.append(hi)
        excess.append(state_excess(q[j], dq[j], q_min[j], q_max[j], v_max[j], lo, hi, dt))
        kept.append(joint_row_name(names[j]))
    if not kept:
        return AccelerationRows.stack([], n)
    return AccelerationRows(ca.vertcat(*rows), ca.SX.zeros(len(kept)), ca.vertcat(*lower), ca.vertcat(*upper), kept,
                            ca.vertcat(*excess))
