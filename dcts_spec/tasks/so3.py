"""Rotations in CasADi: rpy to matrix, the SO(3) logarithm, and the errors of orientation tasks."""

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


OWN_AXIS = {"rx": 0, "ry": 1, "rz": 2}
SMALL_ANGLE = 1e-4  # below: θ/sin θ by its Taylor series
ANTIPODAL = 1e-9  # |a × a_d| below this with a·a_d < 0: the swing axis is undefined


def orientation_rows(rotation: ca.SX, axes: tuple[str, ...]) -> ca.SX:
    """The world directions (3 × m) whose angular velocity components a task on `axes` controls:
    the world axes for all three, else the frame's own selected axes (columns of R)."""
    if len(axes) == 3:
        return ca.SX.eye(3)[:, [OWN_AXIS[a] for a in axes]]
    return ca.horzcat(*[rotation[:, OWN_AXIS[a]] for a in axes])


def orientation_error(rotation: ca.SX, target: ca.SX, axes: tuple[str, ...]) -> ca.SX:
    """The error of an orientation task on `axes`, along `orientation_rows` (m values).

    All three axes: log(R_d Rᵀ), the world rotation vector. Two of the frame's own axes (the third
    free): the *swing* that turns the free axis a = R e_k onto the target's a_d = R_d e_k, i.e.
    θ u with u ∥ a × a_d and θ = ∠(a, a_d), in components along the two controlled axes; a rotation
    about the free axis does not change it. One own axis k (the others free): the *twist* about
    it, ψ = 2 atan2(q_k, q_w) for the quaternion q of Rᵀ R_d (the swing–twist split), in (−π, π].
    """
    if len(axes) == 3:
        return log3(ca.mtimes(target, rotation.T))[[OWN_AXIS[a] for a in axes]]
    if len(axes) == 2:
        (free,) = set(OWN_AXIS) - set(axes)
        k = OWN_AXIS[free]
        a, a_d = rotation[:, k], target[:, k]
        c = ca.cross(a, a_d)  # sin θ · u
        sin_theta, cos_theta = ca.norm_2(c), ca.dot(a, a_d)
        theta = ca.atan2(sin_theta, cos_theta)
        small = theta < SMALL_ANGLE
        swing = ca.if_else(small, 1.0 + theta**2 / 6.0, theta / ca.if_else(small, 1.0, sin_theta)) * c
        # turned half a turn away: any axis normal to a is a shortest swing; take the first controlled one
        swing = ca.if_else(ca.logic_and(sin_theta < ANTIPODAL, cos_theta < 0), theta * rotation[:, OWN_AXIS[axes[0]]], swing)
        return ca.mtimes(orientation_rows(rotation, axes).T, swing)
    k = OWN_AXIS[axes[0]]
    i, j = (k + 1) % 3, (k + 2) % 3
    relative = ca.mtimes(rotation.T, target)
    ww = 1.0 + relative[0, 0] + relative[1, 1] + relative[2, 2]  # 4 q_w²
    kk = 1.0 + 2.0 * relative[k, k] - (relative[0, 0] + relative[1, 1] + relative[2, 2])  # 4 q_k²
    wk = relative[j, i] - relative[i, j]  # 4 q_w q_k
    # tan(ψ/2) = q_k / q_w = 4 q_w q_k / 4 q_w² whatever q's sign (4 q_w² ≥ 0: ψ in [−π, π]); near a
    # half turn (q_w → 0) that is atan2(0, 0), its derivative unbounded (QP rows of 1e14, the step
    # fell back: a Panda's [rz] target half a turn from the tool, found from outside), so where
    # |q_k| > |q_w| the same ratio is read as 4 q_k² / 4 q_w q_k (scaled by q_k: ψ, or ψ + 2π for
    # q_k < 0, wrapped back). Undefined only where q_k = q_w = 0: a swing of half a turn.
    by_w = 2.0 * ca.atan2(wk, ww)
    by_k = 2.0 * ca.atan2(kk, wk)
    by_k = ca.if_else(by_k > ca.pi, by_k - 2.0 * ca.pi, by_k)
    return ca.if_else(ww >= kk, by_w, by_k)
