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
    """What a joint's braking is taken from: M(q)'s diagonal, the Coriolis and gravity torques, and
    the torque limits |τ| ≤ τ_max (run-time parameters where there are; inf where none)."""

    inertia: ca.SX  # M_jj, which joint j's own motion does not change (n)
    coriolis: ca.SX  # ν(q, q̇), taken as it is now along the way (n)
    gravity: ca.SX  # g(q) (n)
    gravity_rate: ca.SX  # ∂g_j/∂q_j, the others fixed (n; `SymbolicRobot.gravity_rate`)
    revolute: list[bool]
    torque_limit: ca.SX  # (n)

    def braking(self, j: int, nominal: ca.SX | float, x: ca.SX, x_min: ca.SX | float,
                x_max: ca.SX | float) -> tuple[ca.SX, ca.SX]:
        """(toward x_max, toward x_min): the mean deceleration joint j's own torque limit gives it
        on its way to that bound, the other joints still: τ_max ∓ (ν_j + g_j) over M_jj, with g_j
        averaged over the way, so a joint that gravity pulls toward its bound less and less as it
        gets there (an arm swinging down to hang) counts on the braking it will have (the energy it
        can take out before the bound). At most `nominal` (the acceleration limit), at least
        BRAKING_FLOOR of it. Measured τ_ext is left out: the bounds follow the model, not a
        sensor's noise (a payload the robot carries belongs in `robot.payloads`)."""
        limit, inertia, coriolis = self.torque_limit[j], self.inertia[j], self.coriolis[j]
        g, rate = self.gravity[j], self.gravity_rate[j]
        toward_max = toward_min = g
        if self.revolute[j]:
            if _finite(x_max):
                toward_max = _mean_gravity(g, rate, x, x_max, 1.0)
            if _finite(x_min):
                toward_min = _mean_gravity(g, -rate, x, x_min, -1.0)
        floor = BRAKING_FLOOR * nominal
        return tuple(ca.fmax(ca.fmin(value / inertia, nominal), floor)
                     for value in (limit + coriolis + toward_max, limit - coriolis - toward_min))


def _finite(limit: ca.SX | float) -> bool:
    return isinstance(limit, ca.SX) or np.isfinite(limit)


# Below this gap (rad) the mean gravity torque over it is its Taylor polynomial (no 0/0).
_SHORT_GAP = 1e-4


def _mean_gravity(g: ca.SX, rate: ca.SX, x: ca.SX, bound: ca.SX | float, direction: float) -> ca.SX:
    """The mean of g cos θ + rate sin θ over θ ∈ [0, gap], gap = direction (bound − x) (g at once
    beyond the bound). sin(gap) and cos(gap) by the angle-sum formulas from sin x and cos x, which
    the kinematics compute already: no trigonometric call of its own (28 of them cost the bench
    spec's step 0.3 µs)."""
    gap = direction * (bound - x)
    sin_x, cos_x, sin_b, cos_b = ca.sin(x), ca.cos(x), ca.sin(bound), ca.cos(bound)  # (floats for a number)
    sin_gap = direction * (sin_b * cos_x - cos_b * sin_x)
    cos_gap = cos_b * cos_x + sin_b * sin_x
    long = (g * sin_gap + rate * (1.0 - cos_gap)) / ca.fmax(gap, _SHORT_GAP)
    return ca.if_else(gap > _SHORT_GAP, long, g + 0.5 * rate * ca.fmax(gap, 0.0))


def slack_weights(v_max: np.ndarray, prismatic: np.ndarray) -> np.ndarray:
    """Per joint, what one unit of its bound's slack weighs in the relaxation (min Σ wᵣσᵣ): 1 for a
    revolute joint (rad/s², as a Cartesian bound's m/s²), and a prismatic joint's m/s² brought to
    the revolute joints' scale by their velocity limits, × (their median) / (its own). Unweighted,
    a Tiago's torso lift (0.07 m/s, 2000 N) was driven down at 31 m/s² to ease its arm's
    saturated joints under a push: 1 m/s² of the lift weighed as 1 rad/s² of a 2.7 rad/s shoulder,
    and the lift ended 3.55 m beyond its limit (docs/formulations.md, "Bounds, their check and
    their relaxation"). Without a velocity limit on either side, 1."""
    v_max, prismatic = np.asarray(v_max, dtype=float), np.asarray(prismatic, dtype=bool)
    revolute = v_max[~prismatic & np.isfinite(v_max)]
    if not revolute.size:
        return np.ones(v_max.size)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(prismatic & np.isfinite(v_max), np.median(revolute) / v_max, 1.0)


def joint_rows(limits: JointLimits, q: ca.SX, dq: ca.SX, dt: float, names: list[str],
               runtime: dict[str, list] | None = None, dynamics: BrakingDynamics | None = None,
               prismatic: np.ndarray | None = None) -> AccelerationRows:
    """One row per joint that has a finite position, velocity or acceleration bound. `runtime`
    replaces some limits (q_min, q_max, v_max, a_max: one value per joint) by run-time
    parameters; which rows and terms exist follows the compiled `limits`. The position bounds
    assume braking at the acceleration limit (DEFAULT_BRAKING without one), or, given `dynamics`
    (limits.joint_braking "torque_limited"), at what the torque limit gives where that is less.
    `prismatic` (per joint) weighs the rows' slack (`slack_weights`; all revolute without it)."""
    n = q.shape[0]
    weights = slack_weights(limits.v_max, np.zeros(n, dtype=bool) if prismatic is None else prismatic)
    runtime = runtime or {}
    q_min, q_max, v_max, a_max = (runtime.get(key, getattr(limits, key)) for key in ("q_min", "q_max", "v_max", "a_max"))
    rows, lower, upper, excess, kept, weight = [], [], [], [], [], []
    for j in range(n):
        bounded = [limits.q_min[j], limits.q_max[j], limits.v_max[j], limits.a_max[j]]
        if not np.isfinite(bounded).any():
            continue
        braking = a_max[j] if np.isfinite(limits.a_max[j]) else DEFAULT_BRAKING
        if dynamics is not None:
            braking = dynamics.braking(j, braking, q[j], q_min[j], q_max[j])
        lo, hi = acceleration_bounds(q[j], dq[j], q_min[j], q_max[j], v_max[j], a_max[j], braking, dt,
                                     (limits.q_min[j], limits.q_max[j], limits.v_max[j]))
        selection = ca.SX.zeros(1, n)
        selection[0, j] = 1.0
        rows.append(selection)
        lower.append(lo)
        upper.append(hi)
        excess.append(state_excess(q[j], dq[j], q_min[j], q_max[j], v_max[j], lo, hi, dt))
        kept.append(joint_row_name(names[j]))
        weight.append(weights[j])
    if not kept:
        return AccelerationRows.stack([], n)
    return AccelerationRows(ca.vertcat(*rows), ca.SX.zeros(len(kept)), ca.vertcat(*lower), ca.vertcat(*upper), kept,
                            ca.vertcat(*excess), np.array(weight))
