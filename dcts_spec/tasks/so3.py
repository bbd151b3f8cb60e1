"""Rotations in CasADi: rpy to matrix, and the SO(3) logarithm used for orientation errors."""

from __future__ import annotations

import casadi as ca


def rpy_to_matrix(rpy: ca.SX) -> ca.SX:
    """R = Rz(yaw) Ry(pitch) Rx(roll), the URDF/Pinocchio convention."""
    r, p, y = rpy[0], rpy[1], rpy[2]
    cr, sr, cp, sp, cy, sy = ca.cos(r), ca.sin(r), ca.cos(p), ca.sin(p), ca.cos(y), ca.sin(y)
    return ca.vertcat(
        ca.horzcat(cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
        ca.horzcat(sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
        ca.horzcat(-sp, cp * sr, cp * cr),
    )


def log3(R: ca.SX) -> ca.SX:
    """Rotation vector θ·u of R (|θ| ≤ π), robust near 0 and near π.

    Near 0, θ/sin θ is replaced by its Taylor series; near π, where the skew part of R
    vanishes, the axis is read from the diagonal of R (R ≈ 2uuᵀ − I), with the sign of the
    largest component taken from the skew part.
    """
    skew = 0.5 * ca.vertcat(R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1])  # sin θ · u
    cos_theta = ca.fmin(ca.fmax(0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0), -1.0), 1.0)
    sin_theta = ca.norm_2(skew)
    theta = ca.atan2(sin_theta, cos_theta)
    small = theta < 1e-4
    ratio = ca.if_else(small, 1.0 + theta**2 / 6.0, theta / ca.if_else(small, 1.0, sin_theta))
    regular = ratio * skew

    # Near π: u_i² = (R_ii − cos θ)/(1 − cos θ); pick the largest, the others from R's symmetric part.
    one_minus_cos = ca.fmax(1.0 - cos_theta, 1e-12)
    candidates = []
    for k in range(3):
        i, j = (k + 1) % 3, (k + 2) % 3
        u_k = ca.sqrt(ca.fmax((R[k, k] - cos_theta) / one_minus_cos, 0.0))
        u = [None, None, None]
        u[k] = u_k
        denom = ca.fmax(u_k, 1e-12) * 2.0 * one_minus_cos
        u[i] = (R[i, k] + R[k, i]) / denom
        u[j] = (R[j, k] + R[k, j]) / denom
        sign = ca.if_else(skew[k] >= 0, 1.0, -1.0)
        candidates.append(sign * theta * ca.vertcat(*u))
    d0, d1, d2 = R[0, 0], R[1, 1], R[2, 2]
    near_pi = ca.if_else(
        ca.logic_and(d0 >= d1, d0 >= d2), candidates[0], ca.if_else(d1 >= d2, candidates[1], candidates[2])
    )
    return ca.if_else(theta > 3.0, near_pi, regular)
