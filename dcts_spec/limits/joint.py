"""Joint position, velocity and acceleration limits as bounds on each joint's acceleration."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..robot.model import JointLimits
from .base import AccelerationRows
from .viability import acceleration_bounds, state_excess

# Braking acceleration the viability bound assumes when the spec gives no joint acceleration limit.
DEFAULT_BRAKING = 10.0  # rad/s² (or m/s² for prismatic joints)


def joint_rows(limits: JointLimits, q: ca.SX, dq: ca.SX, dt: float, names: list[str]) -> AccelerationRows:
    """One row per joint that has a finite position, velocity or acceleration bound."""
    n = q.shape[0]
    rows, lower, upper, excess, kept = [], [], [], [], []
    for j in range(n):
        bounded = [limits.q_min[j], limits.q_max[j], limits.v_max[j], limits.a_max[j]]
        if not np.isfinite(bounded).any():
            continue
        braking = limits.a_max[j] if np.isfinite(limits.a_max[j]) else DEFAULT_BRAKING
        lo, hi = acceleration_bounds(
            q[j], dq[j], limits.q_min[j], limits.q_max[j], limits.v_max[j], limits.a_max[j], braking, dt
        )
        selection = ca.SX.zeros(1, n)
        selection[0, j] = 1.0
        rows.append(selection)
        lower.append(lo)
        upper.append(hi)
        excess.append(state_excess(q[j], dq[j], limits.q_min[j], limits.q_max[j], limits.v_max[j]))
        kept.append(f"joint:{names[j]}")
    if not kept:
        return AccelerationRows.stack([], n)
    return AccelerationRows(ca.vertcat(*rows), ca.SX.zeros(len(kept)), ca.vertcat(*lower), ca.vertcat(*upper), kept,
                            ca.vertcat(*excess))
