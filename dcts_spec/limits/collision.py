"""Collision avoidance: each watched pair's signed distance d ≥ d_min as a bound on the acceleration.

The distance's rate is ḋ = nᵀ(v_a − v_b), with n the unit direction between the closest points
and v the velocities of the body points there (witness points, fixed to their bodies at this
instant): J_d = nᵀ(J_a − J_b). Its acceleration is taken as d̈ ≈ J_d a + nᵀ(J̇_a − J̇_b)q̇, leaving
out the terms of the turning normal and of the closest points sliding along the shapes (second
order in the velocity; the bound is shaped anew every period). d, ḋ then go through the same
discrete-time viability bound as a joint position (limits/viability.py): braking at the pair's
`max_acceleration`, d stays ≥ d_min.

A pair constrains only once it is near: when its distance, less what it needs to stop at its
braking acceleration, is within the activation distance. Farther away its lower bound is
INACTIVE, and the row stays, so the QP keeps its size.
"""

from __future__ import annotations

import casadi as ca

from ..robot.collision import Body, CollisionModel, Shape, WatchedPair
from ..symbolic import SymbolicRobot
from ..symbolic.distance import Box, Closest, HalfSpace, Swept, closest, nearest
from .base import AccelerationRows
from .viability import acceleration_bounds

INF = float("inf")
# A far pair's lower bound: as loose as the viability bound's own clip (it is never binding).
INACTIVE = -1e6


def collision_rows(model: CollisionModel, robot: SymbolicRobot, dt: float) -> AccelerationRows:
    """One row per watched pair: lower ≤ J_d a + J̇_d q̇ (the upper bound never binds)."""
    parts = [_pair_row(pair, model.activation_distance, robot, dt) for pair in model.pairs]
    return AccelerationRows.stack(parts, robot.nv)


def pair_closest(pair: WatchedPair, robot: SymbolicRobot) -> Closest:
    """The signed distance of a pair and its witness points, in the world."""
    shapes_b = [_placed(s, pair.b, robot) for s in pair.b.shapes]
    return nearest([closest(_placed(sa, pair.a, robot), sb) for sa in pair.a.shapes for sb in shapes_b])


def _pair_row(pair: WatchedPair, activation: float, robot: SymbolicRobot, dt: float) -> AccelerationRows:
    c = pair_closest(pair, robot)
    jacobian_a, bias_a = _point_terms(pair.a, c.core_a, c.normal, robot)
    jacobian_b, bias_b = _point_terms(pair.b, c.core_b, c.normal, robot)
    jacobian, bias = jacobian_a - jacobian_b, bias_a - bias_b
    d, rate = c.distance, ca.mtimes(jacobian, robot.dq)
    lower, upper = acceleration_bounds(d, rate, pair.min_distance, INF, INF, INF, pair.braking, dt)
    # What the pair needs to stop from its approach speed (braking in whole periods, as the bound does)
    stopping = ca.if_else(rate < 0, rate**2 / (2.0 * pair.braking) - dt * rate, 0.0)
    near = d - stopping < activation
    excess = ca.fmax(pair.min_distance - d, 0.0)
    return AccelerationRows(jacobian, bias, ca.if_else(near, lower, INACTIVE), upper, [pair.name], excess)


def _placed(shape: Shape, body: Body, robot: SymbolicRobot | None) -> Swept | Box | HalfSpace:
    """A shape in the world: a link's moves with its frame (`robot` needed), an obstacle's is a
    constant."""
    if shape.kind == "box":
        return Box(shape.start, shape.rotation, shape.half)
    if shape.kind == "plane":
        return HalfSpace(shape.start, shape.normal)
    if body.frame is None:
        return Swept(ca.DM(shape.start), ca.DM(shape.end), shape.radius, shape.kind == "sphere")
    position, rotation = robot.frame_placement(body.frame)
    start = position + ca.mtimes(rotation, ca.DM(shape.start))
    end = start if shape.kind == "sphere" else position + ca.mtimes(rotation, ca.DM(shape.end))
    return Swept(start, end, shape.radius, shape.kind == "sphere")


def _point_terms(body: Body, point: ca.SX, normal: ca.SX, robot: SymbolicRobot) -> tuple[ca.SX, ca.SX]:
    """nᵀJ_p and nᵀJ̇_p q̇ of the body's point at `point` (world): zero for an obstacle.

    With r the point relative to the frame origin, v_p = v + ω × r, so nᵀv_p = nᵀJ_v q̇ + (r × n)ᵀJ_ω q̇,
    and the bias acceleration a_p = a + α × r + ω × (ω × r)."""
    if body.frame is None or body.joint == 0:
        return ca.SX(1, robot.nv), ca.SX(0.0)
    origin, _ = robot.frame_placement(body.frame)
    jac = robot.frame_jacobian(body.frame)
    bias = robot.frame_bias_acceleration(body.frame)
    r = point - origin
    omega = ca.mtimes(jac[3:, :], robot.dq)
    jacobian = ca.mtimes(normal.T, jac[:3, :]) + ca.mtimes(ca.cross(r, normal).T, jac[3:, :])
    acceleration = bias[:3] + ca.cross(bias[3:], r) + ca.cross(omega, ca.cross(omega, r))
    return jacobian, ca.dot(normal, acceleration)


def obstacle_distance(obstacle: Body, point) -> float:
    """The signed distance of a point to an obstacle (its nearest shape), m: both in the world, or
    in any frame the body's shapes are constants of (a link's own, as validation uses it)."""
    p = ca.DM(point)
    return min(float(closest(Swept(p, p, 0.0, True), _placed(shape, obstacle, None)).distance)
               for shape in obstacle.shapes)


def distance_function(model: CollisionModel, robot: SymbolicRobot) -> ca.Function:
    """q ↦ the signed distance of every watched pair (validation, analysis and tests evaluate it)."""
    distances = [pair_closest(pair, robot).distance for pair in model.pairs]
    return ca.Function("distances", [robot.q], [ca.vertcat(*distances) if distances else ca.SX(0, 1)], ["q"], ["d"])
