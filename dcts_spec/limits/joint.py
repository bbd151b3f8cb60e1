"""Joint position, velocity and acceleration limits as bounds on each joint's acceleration."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..robot.model import JointLimits
from .base import AccelerationRows
from .naming import joint_row_name
from .viability import acceleration_bounds, state_excess

# Braking acceleration the viability bound assumes when the spec gives no joint acceleration limit.
DEFAULT_BRAKING = 10.0  # rad/s² (or m/s² for prismatic joints)


def joint_rows(limits: JointLimits, q: ca.SX, dq: ca.SX, dt: float, names: list[str],
               runtime: dict[str, list] | None = None) -> AccelerationRows:
    """One row per joint that has a finite position, velocity or acceleration bound. `runtime`
    replaces some limits (q_min, q_max, v_max, a_max: one value per joint) by run-time
    parameters; which rows and terms exist follows the compiled `limits`."""
    n = q.shape[0]
    runtime = runtime or {}
    q_min, q_max, v_max, a_max = (runtime.get(key, getattr(limits, key)) for key in ("q_min", "q_max", "v_max", "a_max"))
    rows, lower, upper, excess, kept = [], [], [], [], []
    for j in range(n):
        bounded = [limits.q_min[j], limits.q_max[j], limits.v_max[j], limits.a_max[j]]
        if not np.isfinite(bounded).any():
            continue
        braking = a_max[j] if np.isfinite(limits.a_max[j]) else DEFAULT_BRAKING
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
