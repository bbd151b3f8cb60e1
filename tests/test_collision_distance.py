"""Signed distances and witness points of symbolic/distance.py against coal (hpp-fcl's successor,
an independent GJK/EPA and analytic implementation) on random shapes, and a brute-force check."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from dcts_spec.symbolic.distance import Box, HalfSpace, Swept, closest, nearest, segment_segment

coal = pytest.importorskip("coal")

RNG_SEED = 7
CASES = 150
TOLERANCE = 1e-6  # m


def _evaluate(a: Swept, b, inputs: list[ca.SX], values: list[np.ndarray]):
    c = closest(a, b)
    f = ca.Function("f", inputs, [c.distance, c.normal, c.point_a, c.point_b])
    d, n, pa, pb = (np.asarray(v).ravel() for v in f(*values))
    return float(d[0]), n, pa, pb


def _symbolic_swept(kind: str, radius: float) -> tuple[Swept, list[ca.SX]]:
    start, end = ca.SX.sym("s", 3), ca.SX.sym("e", 3)
    if kind == "sphere":
        return Swept(start, start, radius, point=True), [start]
    return Swept(start, end, radius), [start, end]


def _coal_swept(kind: str, radius: float, start: np.ndarray, end: np.ndarray):
    if kind == "sphere":
        return coal.Sphere(radius), coal.Transform3s(np.eye(3), start)
    axis = end - start
    length = np.linalg.norm(axis)
    rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), axis / length).matrix()
    return coal.Capsule(radius, length), coal.Transform3s(rotation, 0.5 * (start + end))


def _coal_distance(g1, t1, g2, t2):
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    request.enable_signed_distance = True
    coal.distance(g1, t1, g2, t2, request, result)
    return result.min_distance, result.getNearestPoint1(), result.getNearestPoint2()


def _random_swept(rng, kind):
    start = rng.uniform(-0.3, 0.3, 3)
    end = start + rng.normal(size=3) * rng.uniform(0.05, 0.4)
    return start, end, rng.uniform(0.02, 0.12)


@pytest.mark.parametrize(("kind_a", "kind_b"), [("sphere", "sphere"), ("sphere", "capsule"), ("capsule", "sphere"),
                                                ("capsule", "capsule")])
def test_swept_pairs_match_coal(kind_a, kind_b) -> None:
    rng = np.random.default_rng(RNG_SEED)
    separated = 0
    for _ in range(CASES):
        sa, ea, ra = _random_swept(rng, kind_a)
        sb, eb, rb = _random_swept(rng, kind_b)
        a, in_a = _symbolic_swept(kind_a, ra)
        b, in_b = _symbolic_swept(kind_b, rb)
        values = [sa, ea][: len(in_a)] + [sb, eb][: len(in_b)]
        d, n, pa, pb = _evaluate(a, b, in_a + in_b, values)
        expected, p1, p2 = _coal_distance(*_coal_swept(kind_a, ra, sa, ea), *_coal_swept(kind_b, rb, sb, eb))
        if expected > 0:  # coal's penetration depth of two capsules is its own (EPA) measure
            separated += 1
            assert d == pytest.approx(expected, abs=TOLERANCE)
            assert np.linalg.norm(pa - p1) < 1e-5 and np.linalg.norm(pb - p2) < 1e-5
        else:
            assert d <= TOLERANCE
        assert np.linalg.norm(n) == pytest.approx(1.0)
        assert np.dot(pa - pb, n) == pytest.approx(d, abs=TOLERANCE)
    assert separated > CASES // 3


def _random_box(rng) -> Box:
    rotation = pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3))
    return Box(rng.uniform(-0.2, 0.2, 3), rotation, rng.uniform(0.03, 0.3, 3))


@pytest.mark.parametrize("kind", ["sphere", "capsule"])
def test_swept_against_box_matches_coal(kind) -> None:
    rng = np.random.default_rng(RNG_SEED + 1)
    inside = 0
    for _ in range(CASES if kind == "sphere" else CASES // 3):  # a capsule's 24 bisections take a while to build
        box = _random_box(rng)
        s, e, r = _random_swept(rng, kind)
        a, inputs = _symbolic_swept(kind, r)
        d, n, pa, pb = _evaluate(a, box, inputs, [s, e][: len(inputs)])
        g1, t1 = _coal_swept(kind, r, s, e)
        expected, p1, p2 = _coal_distance(g1, t1, coal.Box(*(2 * box.half)), coal.Transform3s(box.rotation, box.center))
        inside += expected < 0
        if expected > 0 or kind == "sphere":
            assert d == pytest.approx(expected, abs=1e-5), (s, e, r, box)
        else:  # the depth of the axis's deepest point: never deeper than the translation separating them
            assert expected - 1e-5 <= d <= 1e-5
        assert np.dot(pa - pb, n) == pytest.approx(d, abs=1e-5)
        if expected > 0:
            assert np.linalg.norm(pa - p1) < 1e-3 and np.linalg.norm(pb - p2) < 1e-3
    assert inside > 0, "no case penetrated the box: the inside branch went untested"


@pytest.mark.parametrize("kind", ["sphere", "capsule"])
def test_swept_against_plane_matches_coal(kind) -> None:
    rng = np.random.default_rng(RNG_SEED + 2)
    for _ in range(CASES):
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        point = rng.uniform(-0.2, 0.2, 3)
        s, e, r = _random_swept(rng, kind)
        a, inputs = _symbolic_swept(kind, r)
        d, n, pa, pb = _evaluate(a, HalfSpace(point, normal), inputs, [s, e][: len(inputs)])
        g1, t1 = _coal_swept(kind, r, s, e)
        expected, _, _ = _coal_distance(g1, t1, coal.Halfspace(normal, float(normal @ point)), coal.Transform3s())
        assert d == pytest.approx(expected, abs=TOLERANCE)
        assert np.dot(pb - point, normal) == pytest.approx(0.0, abs=TOLERANCE)  # b's witness on the plane
        assert np.allclose(n, normal)


def test_parallel_segments_are_finite_and_take_the_middle_of_the_overlap() -> None:
    p1, q1, p2, q2 = (ca.SX.sym(k, 3) for k in ("p1", "q1", "p2", "q2"))
    f = ca.Function("f", [p1, q1, p2, q2], list(segment_segment(p1, q1, p2, q2)))
    # segment 2 is segment 1 shifted by 0.1 sideways and by a third of its length along it
    s, t = (float(v) for v in f([0, 0, 0], [0, 0, 0.3], [0.1, 0, 0.1], [0.1, 0, 0.4]))
    assert (s, t) == pytest.approx((2 / 3, 1 / 3))  # the overlap is z in [0.1, 0.3]: its middle is 0.2
    # anti-parallel, and nearly parallel (1e-7 rad): finite, the same distance
    for q2_tip in ([0.1, 0, -0.2], [0.1 + 3e-8, 0, 0.4]):
        s, t = (float(v) for v in f([0, 0, 0], [0, 0, 0.3], [0.1, 0, 0.1], q2_tip))
        a, b = np.array([0, 0, 0.3]) * s, np.array([0.1, 0, 0.1]) + t * (np.array(q2_tip) - [0.1, 0, 0.1])
        assert np.isfinite([s, t]).all() and np.linalg.norm(a - b) == pytest.approx(0.1, abs=1e-7)


def _surface_samples(start, end, radius, count, rng) -> np.ndarray:
    """Points on a capsule's surface: on spheres around points of the axis, kept if on the hull."""
    t = rng.uniform(0, 1, count)
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return start + t[:, None] * (end - start) + radius * directions


def test_capsule_distance_by_brute_force_sampling() -> None:
    """No coal needed: the distance is the smallest over dense samples of both surfaces (within
    the sampling's resolution), never above it."""
    rng = np.random.default_rng(RNG_SEED + 3)
    a, in_a = _symbolic_swept("capsule", 0.05)
    b, in_b = _symbolic_swept("capsule", 0.04)
    for _ in range(5):
        sa, ea, _ = _random_swept(rng, "capsule")
        sb, eb, _ = sa + [0.4, 0, 0], ea + rng.normal(size=3) * 0.2 + [0.4, 0, 0], None
        d, _, _, _ = _evaluate(a, b, in_a + in_b, [sa, ea, sb, eb])
        pa, pb = _surface_samples(sa, ea, 0.05, 3000, rng), _surface_samples(sb, eb, 0.04, 3000, rng)
        sampled = min(np.min(np.linalg.norm(pb - p, axis=1)) for p in pa)
        if d > 0:
            assert d <= sampled + 1e-9 and sampled - d < 0.02


def test_nearest_picks_the_closest_pair() -> None:
    x = ca.SX.sym("x", 3)
    near = closest(Swept(x, x, 0.1, point=True), HalfSpace(np.zeros(3), np.array([0.0, 0.0, 1.0])))
    far = closest(Swept(x, x, 0.1, point=True), Box(np.array([1.0, 0, 0]), np.eye(3), np.full(3, 0.1)))
    best = nearest([far, near])
    f = ca.Function("f", [x], [best.distance, best.normal])
    for point, expected, normal in (([0, 0, 0.5], 0.4, [0, 0, 1]), ([0.7, 0, 2.0], np.hypot(0.2, 1.9) - 0.1, None)):
        d, n = f(point)
        assert float(d) == pytest.approx(expected)
        if normal is not None:
            assert np.allclose(np.asarray(n).ravel(), normal)
