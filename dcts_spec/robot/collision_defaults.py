"""Collision primitives of the built-in robots: capsules covering each link, in the link's frame.

iiwa14: the capsule of each link's URDF collision cylinder (same axis, same radius), which holds the
cylinder. panda: one capsule per link enclosing every vertex of example-robot-data's collision mesh
(its convex hull), axis fitted to the least volume then rounded to the millimetre, radius rounded up;
the fingers' boxes likewise. tests/test_collision_spec.py checks that they cover the geometry.
"""

from __future__ import annotations

from ..spec.collision import Capsule

Segment = tuple[tuple[float, float, float], tuple[float, float, float], float]  # start, end, radius

_IIWA14: dict[str, list[Segment]] = {
    "base": [((0, 0, 0), (0, 0, 0.1575), 0.06)],
    "link1": [((0, 0, 0), (0, 0, 0.2025), 0.06)],
    "link2": [((0, 0, 0), (0, 0.2045, 0), 0.06)],
    "link3": [((0, 0, 0), (0, 0, 0.2155), 0.06)],
    "link4": [((0, 0, 0), (0, 0.1845, 0), 0.06)],
    "link5": [((0, 0, 0), (0, 0, 0.2155), 0.06)],
    "link6": [((0, 0, 0), (0, 0.081, 0), 0.06)],
    "link7": [((0, 0, 0), (0, 0, 0.045), 0.04)],
}

_PANDA: dict[str, list[Segment]] = {
    "panda_link0": [((-0.001, 0, 0.051), (-0.057, 0, 0.018), 0.106)],
    "panda_link1": [((0, -0.053, 0.001), (0, 0.002, -0.142), 0.077)],
    "panda_link2": [((0, -0.145, 0.002), (0, 0.003, 0.054), 0.077)],
    "panda_link3": [((0.094, 0.049, 0.012), (0.002, -0.002, -0.083), 0.070)],
    "panda_link4": [((0, 0, 0.042), (-0.082, 0.086, -0.003), 0.070)],
    "panda_link5": [((0, 0.064, 0.003), (0, 0.01, -0.244), 0.068)],
    "panda_link6": [((0.025, -0.004, 0.008), (0.094, 0.01, -0.005), 0.078)],
    "panda_link7": [((-0.005, -0.005, 0.073), (0.033, 0.033, 0.08), 0.050)],
    "panda_hand": [((0, -0.075, 0.021), (0, 0.061, 0.031), 0.050)],
    "panda_leftfinger": [((0, 0.012, 0.012), (0, 0.012, 0.042), 0.021)],
    "panda_rightfinger": [((0, -0.012, 0.012), (0, -0.012, 0.042), 0.021)],
}

_DEFAULTS = {"iiwa14": _IIWA14, "panda": _PANDA}

# Pairs of links more than one joint apart that these capsules cannot keep apart: the wrist's short
# middle link puts its neighbours' capsules within millimetres or into each other in ordinary
# postures (20,000 random configurations within the joint limits: iiwa14 link5–link7 always overlap;
# panda link3–link5 stay 10-14 mm apart, link5–link7 overlap in 33 % and link5–hand in 14 %).
# `watch: all` leaves them out; the joint limits keep those links apart.
_EXCLUDED = {
    "iiwa14": [("link5", "link7")],
    "panda": [("panda_link3", "panda_link5"), ("panda_link5", "panda_link7"), ("panda_link5", "panda_hand")],
}


def default_primitives(robot: str | None) -> dict[str, list[Capsule]]:
    """The built-in robot's primitives by link; none for another robot (a URDF)."""
    table = _DEFAULTS.get(robot or "", {})
    return {link: [Capsule(type="capsule", start=a, end=b, radius=r) for a, b, r in segments]
            for link, segments in table.items()}


def default_exclusions(robot: str | None) -> list[tuple[str, str]]:
    """Pairs of the built-in robot's links that `watch: all` leaves out (see _EXCLUDED)."""
    return list(_EXCLUDED.get(robot or "", []))
