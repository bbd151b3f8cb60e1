"""The `limits.collision` section resolved against the robot: bodies with their shapes, watched pairs.

A body is a link (its shapes move with a frame of the model) or an obstacle (fixed in the world).
Pairs that cannot move relative to each other (on the same rigid body, or both fixed in the world)
are never watched: their distance is a constant. Neither are links joined by one joint under
`watch: all`: their shapes meet at the joint.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..spec import Diagnostic, Spec
from ..spec.collision import Box, Capsule, CollisionSpec, Plane, Sphere
from ..spec.errors import KeyPath, did_you_mean
from ..spec.units import to_si
from .collision_defaults import default_exclusions, default_primitives
from .model import Robot

WORLD = 0  # Pinocchio's universe joint: what obstacles and the fixed base move with


@dataclass(frozen=True)
class Shape:
    """A swept sphere (the points within `radius` of the segment start–end; a sphere when they
    coincide), a box or a plane, in its body's frame (the world's for an obstacle)."""

    kind: str  # sphere, capsule, box, plane
    start: np.ndarray  # sphere or box centre, capsule start, a point of the plane
    end: np.ndarray  # capsule end; start otherwise
    radius: float = 0.0
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))  # box axes in the world
    half: np.ndarray = field(default_factory=lambda: np.zeros(3))  # box half edge lengths
    normal: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))  # plane, unit

    @property
    def swept(self) -> bool:
        """A sphere or a capsule (a core point or segment with a radius)."""
        return self.kind in ("sphere", "capsule")


@dataclass(frozen=True)
class Body:
    """A link's shapes (moving with `frame`) or an obstacle's (frame None: the world)."""

    name: str
    frame: str | None
    joint: int  # the Pinocchio joint the body moves with (WORLD for obstacles and the fixed base)
    shapes: tuple[Shape, ...]


@dataclass(frozen=True)
class WatchedPair:
    """Two bodies kept at least `min_distance` apart, braking their distance at `braking`."""

    a: Body  # always a link
    b: Body  # a link or an obstacle
    min_distance: float
    braking: float

    @property
    def name(self) -> str:
        """The name of its bound row, as logs and summary.json key it."""
        return pair_row_name(self.a.name, self.b.name)


@dataclass(frozen=True)
class CollisionModel:
    """Every body and the pairs the controller watches."""

    links: tuple[Body, ...]
    obstacles: tuple[Body, ...]
    pairs: tuple[WatchedPair, ...]
    activation_distance: float

    @staticmethod
    def empty() -> "CollisionModel":
        return CollisionModel((), (), (), 0.0)


def pair_row_name(a: str, b: str) -> str:
    return f"collision:{a}-{b}"


def shape_of(primitive: Sphere | Capsule | Box | Plane) -> Shape:
    """A primitive of the spec as a Shape (SI units)."""
    if isinstance(primitive, Sphere):
        c = np.array(primitive.center, dtype=float)
        return Shape("sphere", c, c, primitive.radius)
    if isinstance(primitive, Capsule):
        return Shape("capsule", np.array(primitive.start, dtype=float), np.array(primitive.end, dtype=float), primitive.radius)
    if isinstance(primitive, Box):
        c = np.array(primitive.center, dtype=float)
        rotation = pin.rpy.rpyToMatrix(*to_si(list(primitive.rpy), primitive.unit))
        return Shape("box", c, c, rotation=rotation, half=0.5 * np.array(primitive.size, dtype=float))
    n = np.array(primitive.normal, dtype=float)
    p = np.array(primitive.point, dtype=float)
    return Shape("plane", p, p, normal=n / np.linalg.norm(n))


def resolve_collision(spec: Spec, robot: Robot) -> tuple[CollisionModel, list[Diagnostic]]:
    """The collision model of a spec (empty without a `limits.collision` section), with diagnostics."""
    section = spec.limits.collision
    if section is None:
        return CollisionModel.empty(), []
    return _Resolver(spec, robot, section).resolve()


class _Resolver:
    def __init__(self, spec: Spec, robot: Robot, section: CollisionSpec):
        self.spec, self.model, self.section = spec, robot.model, section
        self.diags: list[Diagnostic] = []
        self.at: KeyPath = ("limits", "collision")

    def error(self, path: KeyPath, message: str, severity: str = "error") -> None:
        self.diags.append(self.spec.source.diagnostic(self.at + path, message, severity))

    def resolve(self) -> tuple[CollisionModel, list[Diagnostic]]:
        links = self._links()
        obstacles = self._obstacles()
        bodies = {b.name: b for b in (*links, *obstacles)}
        pairs = self._pairs(links, obstacles, bodies)
        watched = {body.name for pair in pairs for body in (pair.a, pair.b)}
        for link in links:
            if link.joint == WORLD and link.name in self.section.links and link.name not in watched:
                self.error(("links", link.name), f"{link.name} is fixed to the world and in no watched pair: its "
                           "shapes are never watched (against an obstacle neither moves); to keep the robot's links "
                           "off it, set self_collision: true or list its pairs", "warning")
        if not pairs and not any(d.severity == "error" for d in self.diags):
            self.error((), "no pair is watched: give links primitives (`links`), obstacles, or `pairs`", "warning")
        return CollisionModel(tuple(links), tuple(obstacles), tuple(pairs), self.section.activation_distance), self.diags

    def _links(self) -> list[Body]:
        primitives = default_primitives(self.spec.robot.model) if self.section.default_primitives else {}
        frames = [f.name for f in self.model.frames if f.name != "universe"]
        for name in self.section.links:
            if not self.model.existFrame(name) or name == "universe":
                self.error(("links", name), f"no link or frame {name!r}{did_you_mean(name, frames, 3)}")
        primitives.update({k: v for k, v in self.section.links.items() if self.model.existFrame(k)})
        # Model order (the base first), whatever order the spec lists them in.
        return [Body(f.name, f.name, int(f.parentJoint), tuple(shape_of(p) for p in primitives[f.name]))
                for f in self.model.frames if primitives.get(f.name)]

    def _obstacles(self) -> list[Body]:
        out = []
        for name, obstacle in self.section.obstacles.items():
            if self.model.existFrame(name):
                self.error(("obstacles", name), f"the robot has a frame named {name!r}: give the obstacle another name")
                continue
            out.append(Body(name, None, WORLD, (shape_of(obstacle),)))
        return out

    def _adjacent(self, a: Body, b: Body) -> bool:
        """Joined by one joint (or on the same rigid body)."""
        parents = self.model.parents
        return a.joint == b.joint or parents[a.joint] == b.joint or parents[b.joint] == a.joint

    def _pairs(self, links: list[Body], obstacles: list[Body], bodies: dict[str, Body]) -> list[WatchedPair]:
        s = self.section
        excluded = set()
        for i, names in enumerate(s.exclude):
            key = self._pair_key(("exclude", i), names, bodies, movable=False)
            if key is not None:
                excluded.add(key)
        # The built-in set's own exclusions; a pair listed in `pairs` is watched all the same.
        skipped = excluded | ({frozenset(p) for p in default_exclusions(self.spec.robot.model)}
                              if s.default_primitives else set())
        chosen: dict[frozenset[str], tuple[Body, Body, float, float]] = {}
        if s.watch == "all":
            candidates = [(a, o) for a in links if a.joint != WORLD for o in obstacles]
            if s.self_collision:
                candidates += [(a, b) for i, a in enumerate(links) for b in links[i + 1:] if not self._adjacent(a, b)]
            for a, b in candidates:
                if frozenset((a.name, b.name)) not in skipped:
                    chosen[frozenset((a.name, b.name))] = (a, b, s.min_distance, s.max_acceleration)
        listed: dict[frozenset[str], int] = {}
        for i, pair in enumerate(s.pairs):
            key = self._pair_key(("pairs", i, "between"), pair.between, bodies)
            if key is None:
                continue
            if key in listed:  # (the later one replaced the first: a safety distance weakened unseen)
                self.error(("pairs", i, "between"), f"{' and '.join(pair.between)} are already a pair at "
                           f"pairs[{listed[key]}]: give each pair once")
                continue
            listed[key] = i
            if key in excluded:
                self.error(("pairs", i, "between"), f"{' and '.join(pair.between)} are also in `exclude`: keep one")
                continue
            a, b = (bodies[n] for n in pair.between)
            if a.frame is None:
                a, b = b, a  # the link first
            d_min = s.min_distance if pair.min_distance is None else pair.min_distance
            if d_min >= s.activation_distance:
                self.error(("pairs", i, "min_distance"), f"min_distance ({d_min:g} m) must be below the "
                           f"activation_distance ({s.activation_distance:g} m)")
                continue
            braking = s.max_acceleration if pair.max_acceleration is None else pair.max_acceleration
            chosen[key] = (a, b, d_min, braking)
        return [WatchedPair(a, b, d_min, braking) for a, b, d_min, braking in chosen.values()]

    def _pair_key(self, path: KeyPath, names: list[str], bodies: dict[str, Body], movable: bool = True
                  ) -> frozenset[str] | None:
        """The pair's key, or None (with a diagnostic) if it names no two bodies, or (`movable`)
        if their distance cannot change."""
        for name in names:
            if name not in bodies:
                why = ("has no primitives (add some under `links`)" if self.model.existFrame(name)
                       else f"is neither a link with primitives nor an obstacle{did_you_mean(name, list(bodies), 3)}")
                self.error(path, f"{name!r} {why}")
                return None
        a, b = (bodies[n] for n in names)
        if a.name == b.name:
            self.error(path, f"a pair needs two different bodies, got {a.name!r} twice")
            return None
        if movable and a.joint == b.joint:
            where = "fixed in the world" if a.joint == WORLD else f"moved by the same joint ({self.model.names[a.joint]})"
            self.error(path, f"{a.name} and {b.name} are both {where}: their distance cannot change")
            return None
        return frozenset(names)
