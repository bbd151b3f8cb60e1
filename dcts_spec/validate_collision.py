"""Validation of `limits.collision`: the model resolves, no watched pair starts too close, and what
the distance rows cost in the compiled controller."""

from __future__ import annotations

from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from .limits.collision import collision_rows, distance_function, obstacle_distance
from .robot.collision import CollisionModel, resolve_collision
from .robot.model import Robot
from .spec import Diagnostic, Spec
from .symbolic import SymbolicRobot


@dataclass
class CollisionReport:
    """The watched pairs at the initial configuration and the cost of their rows."""

    model: CollisionModel
    distances: np.ndarray  # signed distance of each pair at the initial configuration, m
    operations: int  # CasADi operations of the distance rows (bounds, Jacobians and biases)

    def closest(self) -> tuple[str, float, float] | None:
        """(pair, its distance, its minimum) of the pair nearest its minimum, None without pairs."""
        if not self.model.pairs:
            return None
        margins = [d - p.min_distance for d, p in zip(self.distances, self.model.pairs, strict=True)]
        k = int(np.argmin(margins))
        pair = self.model.pairs[k]
        return pair.name.removeprefix("collision:"), float(self.distances[k]), pair.min_distance

    def to_dict(self) -> dict:
        return {"pairs": len(self.model.pairs), "operations": self.operations,
                "initial_distances": {p.name: float(d) for p, d in zip(self.model.pairs, self.distances, strict=True)}}

    def summary(self) -> str:
        closest = self.closest()
        start = "" if closest is None else f"; closest at the start: {closest[0]} {closest[1]:.3g} m (min {closest[2]:.3g} m)"
        return (f"  collision   {len(self.model.pairs)} pairs watched, their rows {self.operations} operations of the QP "
                f"data{start}")


def check_collision(spec: Spec, robot: Robot, q0: np.ndarray) -> tuple[CollisionReport | None, list[Diagnostic]]:
    """The collision report (None without a collision section, or when it does not resolve) and
    the diagnostics: the section's own, and an error for each pair closer than its minimum at q0."""
    if spec.limits.collision is None:
        return None, []
    model, diags = resolve_collision(spec, robot)
    if any(d.severity == "error" for d in diags):
        return None, diags
    sym = SymbolicRobot(robot.model)
    distances = np.asarray(distance_function(model, sym)(q0), dtype=float).ravel()
    for pair, d in zip(model.pairs, distances, strict=True):
        if d < pair.min_distance:
            what = f"overlap by {-d:.4g} m" if d < 0 else f"are {d:.4g} m apart"
            diags.append(spec.source.diagnostic(
                _where(spec, pair.a.name, pair.b.name), f"{pair.a.name} and {pair.b.name} {what} at the initial "
                f"configuration, closer than their minimum distance {pair.min_distance:.4g} m: move them apart (initial_q, "
                f"the obstacle) or leave the pair out (`exclude`)"))
    rows = collision_rows(model, sym, spec.controller.period)
    cost = ca.Function("rows", [sym.q, sym.dq], [rows.matrix, rows.offset, rows.lower, rows.upper, rows.excess],
                       {"cse": True})
    return CollisionReport(model, distances, cost.n_instructions()), diags


def _where(spec: Spec, a: str, b: str) -> tuple:
    """Where a pair is written: its `pairs` entry, else its obstacle, else the initial configuration."""
    section = spec.limits.collision
    for i, pair in enumerate(section.pairs):
        if {a, b} == set(pair.between):
            return ("limits", "collision", "pairs", i)
    if b in section.obstacles:
        return ("limits", "collision", "obstacles", b)
    if spec.scenario is not None and spec.scenario.initial_q is not None:
        return ("scenario", "initial_q")
    return ("limits", "collision")


def target_diagnostics(spec: Spec, robot: Robot, model: CollisionModel,
                       targets: list[tuple[str, tuple, str, np.ndarray]]) -> list[Diagnostic]:
    """A warning for each constant position target (frame, key path, wording, position) that puts its
    frame closer to an obstacle than a watched pair allows, where the frame's origin lies within
    that pair's link shapes (so the link could not get there either): at the bound the task's
    scaling falls to 0 and it coasts, as at a Cartesian bound (validate._check_cartesian_bounds)."""
    diags = []
    for frame, at, what, position in targets:
        fid, warned = robot.model.getFrameId(frame), set()
        for pair in model.pairs:
            if pair.b.frame is not None or pair.b.name in warned or not _origin_within(robot, fid, pair.a):
                continue
            d = obstacle_distance(pair.b, position)
            if d < pair.min_distance:
                warned.add(pair.b.name)
                where = f"inside {pair.b.name}" if d < 0 else f"{d:.3g} m from {pair.b.name}"
                diags.append(spec.source.diagnostic(
                    at, f"{what} puts {frame} {where}, where {pair.a.name} keeps {pair.min_distance:g} m from it "
                        f"(limits.collision): at that bound the task's scaling falls to 0 (direction kept), so it "
                        f"stops accelerating {frame}, and motion along the obstacle is no longer damped; put the "
                        "target outside", "warning"))
    return diags


def _origin_within(robot: Robot, fid: int, link: Body) -> bool:
    """Is the origin of frame `fid` inside one of the link's swept shapes (the two on one joint)?"""
    frame, body = robot.model.frames[fid], robot.model.frames[robot.model.getFrameId(link.frame)]
    if frame.parentJoint != body.parentJoint:
        return False
    p = (body.placement.inverse() * frame.placement).translation  # (in the link's frame)
    swept = tuple(shape for shape in link.shapes if shape.swept)
    # (the shapes as constants of the link's frame, where p is: an obstacle's distance)
    return bool(swept) and obstacle_distance(replace(link, frame=None, shapes=swept), p) <= 0.0

