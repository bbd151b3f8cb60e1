"""Bounds on the robot's (actual) joint acceleration a, as linear rows."""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np


# The state is beyond a bound's position or velocity limit if it is by more than this (rad, m,
# rad/s or m/s): what "a bound crossed" means to the user (the status; `viability`'s give-way).
STATE_TOLERANCE = 1e-5


@dataclass
class AccelerationRows:
    """lower ≤ matrix · a + offset ≤ upper, one row per bounded coordinate."""

    matrix: ca.SX  # (r × n)
    offset: ca.SX  # (r)
    lower: ca.SX  # (r)
    upper: ca.SX  # (r)
    names: list[str]
    # How far the state already is beyond each row's position or velocity limit (rad, m, rad/s
    # or m/s; 0 within): after a push the acceleration bound can hold while the joint is still
    # outside its range, and a status must not call that "ok".
    excess: ca.SX  # (r)
    # What one unit of each row's slack weighs when the torque limits cannot hold every bound
    # (the relaxation's min Σ wᵣσᵣ): 1, but a prismatic joint's (limits/joint.py, slack_weights)
    slack_weight: np.ndarray | None = None

    @property
    def slack_weights(self) -> np.ndarray:
        return np.ones(len(self.names)) if self.slack_weight is None else np.asarray(self.slack_weight, dtype=float)

    @staticmethod
    def stack(parts: list["AccelerationRows"], n: int) -> "AccelerationRows":
        parts = [p for p in parts if p.names]
        if not parts:
            return AccelerationRows(ca.SX(0, n), ca.SX(0, 1), ca.SX(0, 1), ca.SX(0, 1), [], ca.SX(0, 1))
        return AccelerationRows(
            ca.vertcat(*[p.matrix for p in parts]),
            ca.vertcat(*[p.offset for p in parts]),
            ca.vertcat(*[p.lower for p in parts]),
            ca.vertcat(*[p.upper for p in parts]),
            [name for p in parts for name in p.names],
            ca.vertcat(*[p.excess for p in parts]),
            np.concatenate([p.slack_weights for p in parts]),
        )

    def __len__(self) -> int:
        return len(self.names)
