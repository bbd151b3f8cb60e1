"""Signed distances between convex primitives and their witness points, as CasADi SX expressions.

A swept sphere is the set of points within `radius` of its core, a point (sphere) or a segment
(capsule); the distance of two swept spheres is the distance of their cores less both radii, and
the witness points lie on the surfaces along the line joining the closest points of the cores.
Boxes and planes are fixed in the world. Every branch is an `if_else`, so the cost is fixed: the
same operations run whatever the configuration, as in the generated C.

The distance is negative when the shapes overlap: by the penetration depth for a sphere against a
box and a swept sphere against a plane; by how deep the deepest point of its axis is for a capsule
against a box; by the overlap of the radii along the cores' closest points for two swept spheres
(whose cores do not cross until the overlap is deep). Never deeper than the penetration depth (the
translation separating the shapes), so a bound d ≥ d_min is never tighter than the geometry asks.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

Vector = ca.SX | ca.DM

# Closest points of two segments: below this, relative to the product of their squared lengths,
# they are parallel and the closest pair is taken in the middle of their overlap.
_PARALLEL = 1e-9
# A norm below this is a coincidence: the direction is then whatever the guard gives (no NaN).
_TINY = 1e-12
# Bisection steps for a capsule against a box: the closest point of the axis within 2^-24 (6e-8)
# of its length, hence a distance within that of the exact one.
BOX_BISECTIONS = 24


@dataclass(frozen=True)
class Swept:
    """A sphere (start is end: give `point=True`) or a capsule, placed in the world."""

    start: Vector
    end: Vector
    radius: float
    point: bool = False


@dataclass(frozen=True)
class Box:
    """A box fixed in the world: centre, axes (rotation, world ← box) and half edge lengths."""

    center: np.ndarray
    rotation: np.ndarray
    half: np.ndarray


@dataclass(frozen=True)
class HalfSpace:
    """The solid behind a plane fixed in the world: points x with nᵀ(x − point) ≤ 0."""

    point: np.ndarray
    normal: np.ndarray  # unit


@dataclass(frozen=True)
class Closest:
    """The signed distance of two shapes a and b and where it is attained.

    `normal` is the unit direction from b to a (the distance grows when a moves along it);
    `core_a`, `core_b` are the points of a's and b's core (on the surface of a box or a plane)
    the distance is measured between: points fixed to their bodies at this instant, whose
    velocities give the distance's rate nᵀ(v_a − v_b). `point_a`, `point_b` are the witness
    points on the surfaces, core − radius · normal along the same line.
    """

    distance: ca.SX
    normal: ca.SX
    core_a: ca.SX
    core_b: ca.SX
    point_a: ca.SX
    point_b: ca.SX

    @staticmethod
    def of_cores(distance: ca.SX, normal: ca.SX, core_a: Vector, core_b: Vector, radius_a: float, radius_b: float
                 ) -> "Closest":
        return Closest(distance, normal, ca.SX(core_a), ca.SX(core_b), core_a - radius_a * normal,
                       core_b + radius_b * normal)


def _clamp01(x: ca.SX) -> ca.SX:
    return ca.fmin(ca.fmax(x, 0.0), 1.0)


def _unit(v: ca.SX) -> tuple[ca.SX, ca.SX]:
    """(v/|v|, |v|), guarded at v = 0."""
    length = ca.norm_2(v)
    return v / ca.fmax(length, _TINY), length


def point_segment(x: Vector, p: Vector, q: Vector) -> ca.SX:
    """Parameter t ∈ [0, 1] of the point of segment p–q closest to x."""
    d = q - p
    return _clamp01(ca.dot(x - p, d) / ca.dot(d, d))


def segment_segment(p1: Vector, q1: Vector, p2: Vector, q2: Vector) -> tuple[ca.SX, ca.SX]:
    """Parameters (s, t) of the closest points p1 + s(q1 − p1), p2 + t(q2 − p2) of two segments
    (Ericson, Real-Time Collision Detection, 5.1.9). Parallel segments take s in the middle of the
    overlap of their projections (else the nearer end), so the points do not jump between the two
    ends as the segments turn through parallel."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = ca.dot(d1, d1), ca.dot(d2, d2), ca.dot(d2, r)
    c, b = ca.dot(d1, r), ca.dot(d1, d2)
    denom = a * e - b * b
    general = _clamp01((b * f - c * e) / ca.fmax(denom, _TINY))
    s_start, s_end = -c / a, (b - c) / a  # segment 2's ends projected on segment 1
    lo, hi = ca.fmax(ca.fmin(s_start, s_end), 0.0), ca.fmin(ca.fmax(s_start, s_end), 1.0)
    s = ca.if_else(denom > _PARALLEL * a * e, general, _clamp01(0.5 * (lo + hi)))
    t_free = (b * s + f) / e
    t = _clamp01(t_free)
    # t clamped to an end: s is then the point of segment 1 closest to that end
    s = ca.if_else(t_free == t, s, _clamp01((b * t - c) / a))
    return s, t


def _cores(a: Swept, b: Swept) -> tuple[ca.SX, ca.SX]:
    """The closest points of two cores (points or segments)."""
    if a.point and b.point:
        return ca.SX(a.start), ca.SX(b.start)
    if a.point:
        t = point_segment(a.start, b.start, b.end)
        return ca.SX(a.start), b.start + t * (b.end - b.start)
    if b.point:
        s = point_segment(b.start, a.start, a.end)
        return a.start + s * (a.end - a.start), ca.SX(b.start)
    s, t = segment_segment(a.start, a.end, b.start, b.end)
    return a.start + s * (a.end - a.start), b.start + t * (b.end - b.start)


def swept_swept(a: Swept, b: Swept) -> Closest:
    """Two spheres or capsules."""
    core_a, core_b = _cores(a, b)
    normal, length = _unit(core_a - core_b)
    return Closest.of_cores(length - a.radius - b.radius, normal, core_a, core_b, a.radius, b.radius)


def swept_halfspace(a: Swept, plane: HalfSpace) -> Closest:
    """A sphere or capsule against the solid behind a plane: its core's lowest end decides."""
    n = ca.DM(plane.normal)
    height_start = ca.dot(n, a.start - ca.DM(plane.point))
    core, height = ca.SX(a.start), height_start
    if not a.point:
        height_end = ca.dot(n, a.end - ca.DM(plane.point))
        core = ca.if_else(height_end < height_start, a.end, a.start)
        height = ca.fmin(height_start, height_end)
    return Closest.of_cores(height - a.radius, ca.SX(n), core, core - height * n, a.radius, 0.0)


def _box_local(box: Box, x: Vector) -> ca.SX:
    return ca.mtimes(ca.DM(box.rotation.T), x - ca.DM(box.center))


def _box_direction(box: Box, local: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
    """At a point in box coordinates: the signed distance, the direction of its gradient (not
    normalized outside the box; the inward face's outward normal inside) and the closest point of
    the surface, all in box coordinates."""
    h = ca.DM(box.half)
    excess = ca.fabs(local) - h
    clamped = ca.fmin(ca.fmax(local, -h), h)
    outside_vector = local - clamped
    deepest = ca.fmax(ca.fmax(excess[0], excess[1]), excess[2])  # the nearest face, inside
    face = ca.if_else(excess[0] == deepest, 0, ca.if_else(excess[1] == deepest, 1, 2))
    signs = ca.if_else(local >= 0, ca.DM.ones(3), -ca.DM.ones(3))
    inside_normal = ca.vertcat(*[ca.if_else(face == k, signs[k], 0.0) for k in range(3)])
    on_face = ca.vertcat(*[ca.if_else(face == k, signs[k] * h[k], local[k]) for k in range(3)])
    outside = deepest > 0
    distance = ca.if_else(outside, ca.norm_2(outside_vector), deepest)
    direction = ca.if_else(outside, outside_vector, inside_normal)
    surface = ca.if_else(outside, clamped, on_face)
    return distance, direction, surface


def swept_box(a: Swept, box: Box) -> Closest:
    """A sphere or capsule against a box. A capsule's core point is found by bisection on the
    slope of the box's signed distance along the axis, which is convex: BOX_BISECTIONS steps."""
    core = ca.SX(a.start)
    if not a.point:
        origin, axis = _box_local(box, a.start), ca.mtimes(ca.DM(box.rotation.T), a.end - a.start)
        lo, hi = ca.SX(0.0), ca.SX(1.0)
        for _ in range(BOX_BISECTIONS):
            mid = 0.5 * (lo + hi)
            _, direction, _ = _box_direction(box, origin + mid * axis)
            rising = ca.dot(direction, axis) > 0
            lo, hi = ca.if_else(rising, lo, mid), ca.if_else(rising, mid, hi)
        core = a.start + 0.5 * (lo + hi) * (a.end - a.start)
    distance, direction, surface = _box_direction(box, _box_local(box, core))
    rotation = ca.DM(box.rotation)
    normal, _ = _unit(ca.mtimes(rotation, direction))
    on_box = ca.mtimes(rotation, surface) + ca.DM(box.center)
    return Closest.of_cores(distance - a.radius, normal, core, on_box, a.radius, 0.0)


def closest(a: Swept, b: Swept | Box | HalfSpace) -> Closest:
    """The signed distance of a sphere or capsule to any shape, with its witness points."""
    if isinstance(b, Swept):
        return swept_swept(a, b)
    if isinstance(b, Box):
        return swept_box(a, b)
    return swept_halfspace(a, b)


def nearest(candidates: list[Closest]) -> Closest:
    """The closest of several pairs of shapes (of the same two bodies): one distance, one normal."""
    best = candidates[0]
    for other in candidates[1:]:
        nearer = other.distance < best.distance
        best = Closest(*(ca.if_else(nearer, x, y) for x, y in zip(_fields(other), _fields(best), strict=True)))
    return best


def _fields(c: Closest) -> tuple[ca.SX, ...]:
    return c.distance, c.normal, c.core_a, c.core_b, c.point_a, c.point_b
