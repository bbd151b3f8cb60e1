"""The `limits.collision` section: primitives on the links, obstacles in the world, the pairs kept apart.

Every shape is a swept sphere (a sphere, or a capsule: the points within `radius` of a segment) on a
link, or an obstacle fixed in the world: a sphere, a capsule, a box or a plane. The controller keeps
the signed distance of each watched pair (link–link or link–obstacle) at least its minimum distance.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from .types import JOINT_VALUE, LENGTH, FieldError, Flag, Number, Range, StrictModel, Vec3
from .units import AngleUnit

RADIUS = Range(0, 100, "m", open=True)
SIZE = Range(0, 1e3, "m", open=True)
DISTANCE = Range(0, 10, "m")
BRAKING = Range(0, 1e5, "m/s²", open=True)


class Sphere(StrictModel):
    """A sphere: the points within `radius` of `center`."""

    type: Literal["sphere"] = Field(description="sphere", examples=["sphere"])
    center: Annotated[Vec3, LENGTH] = Field((0.0, 0.0, 0.0), description=(
        "centre, m, in the link's frame (in the world for an obstacle)"), examples=[[0, 0, 0.05]])
    radius: Annotated[Number, RADIUS] = Field(description="radius, m", examples=[0.08])


class Capsule(StrictModel):
    """A capsule: the points within `radius` of the segment from `start` to `end`."""

    type: Literal["capsule"] = Field(description="capsule", examples=["capsule"])
    start: Annotated[Vec3, LENGTH] = Field(description="one end of its axis, m, in the link's frame (in the world "
                                           "for an obstacle)", examples=[[0, 0, 0]])
    end: Annotated[Vec3, LENGTH] = Field(description="the other end of its axis, m, same frame", examples=[[0, 0, 0.2]])
    radius: Annotated[Number, RADIUS] = Field(description="radius, m", examples=[0.06])

    @model_validator(mode="after")
    def _has_length(self) -> "Capsule":
        if sum((a - b) ** 2 for a, b in zip(self.start, self.end)) < 1e-12:
            raise FieldError("end", f"end {list(self.end)} is start: a capsule needs an axis (use a sphere instead)")
        return self


class Box(StrictModel):
    """A box fixed in the world."""

    type: Literal["box"] = Field(description="box", examples=["box"])
    center: Annotated[Vec3, LENGTH] = Field(description="centre in the world, m", examples=[[0.6, 0, 0.2]])
    size: Annotated[Vec3, SIZE] = Field(description="edge lengths along its own x, y, z axes, m", examples=[[0.4, 0.8, 0.05]])
    rpy: Annotated[Vec3, JOINT_VALUE] = Field((0.0, 0.0, 0.0), description="roll, pitch, yaw of its axes in the "
                                              "world, in `unit`", examples=[[0, 0, 45]])
    unit: AngleUnit = Field("rad", description="unit of rpy", examples=["deg"])


class Plane(StrictModel):
    """A plane fixed in the world; everything behind it (against its normal) is the obstacle."""

    type: Literal["plane"] = Field(description="plane: the half-space behind it is solid", examples=["plane"])
    normal: Annotated[Vec3, Range(-1e6, 1e6)] = Field(description="normal pointing to the free side (unitless, any "
                                                      "length: it is normalized)", examples=[[0, 0, 1]])
    point: Annotated[Vec3, LENGTH] = Field((0.0, 0.0, 0.0), description="a point of the plane in the world, m",
                                           examples=[[0, 0, 0]])

    @model_validator(mode="after")
    def _nonzero(self) -> "Plane":
        if not sum(v * v for v in self.normal) > 1e-12:
            raise FieldError("normal", f"the normal must not be zero, got {list(self.normal)}")
        return self


LinkPrimitive = Annotated[Sphere | Capsule, Field(discriminator="type")]
Obstacle = Annotated[Sphere | Capsule | Box | Plane, Field(discriminator="type")]
PairNames = Annotated[list[str], Field(min_length=2, max_length=2)]


class CollisionPair(StrictModel):
    """A pair to keep apart, with its own settings."""

    between: PairNames = Field(description="two link names, or a link and an obstacle name", examples=[["link7", "table"]])
    min_distance: Annotated[Number, DISTANCE] | None = Field(
        None, description="smallest distance allowed between their surfaces, m; default: the section's",
        examples=[0.05])
    max_acceleration: Annotated[Number, BRAKING] | None = Field(
        None, description="braking acceleration of their distance assumed by the viability bound, m/s²; default: "
                          "the section's", examples=[3.0])


class CollisionSpec(StrictModel):
    """Collision avoidance as hard bounds: each watched pair's distance stays ≥ its minimum."""

    default_primitives: Flag = Field(True, description=(
        "start from the built-in robot's primitives (iiwa14, panda: every link covered); a URDF robot has none"),
        examples=[True])
    links: dict[str, list[LinkPrimitive]] = Field(default_factory=dict, description=(
        "primitives per link, in the link's frame; a link listed here replaces its default ones ([] removes it)"),
        examples=[{"link7": [{"type": "capsule", "start": [0, 0, 0], "end": [0, 0, 0.15], "radius": 0.05}]}])
    obstacles: dict[str, Obstacle] = Field(default_factory=dict, description="obstacles fixed in the world, by name",
                                           examples=[{"ball": {"type": "sphere", "center": [0.5, 0.2, 0.6], "radius": 0.1}}])
    watch: Literal["all", "listed"] = Field("all", description=(
        "all: every link against every obstacle and (with self_collision) every pair of links not joined by a "
        "joint, minus `exclude`; listed: only the pairs in `pairs`"), examples=["all"])
    self_collision: Flag = Field(True, description="with watch: all, also keep the links apart from each other",
                                 examples=[True])
    exclude: list[PairNames] = Field(default_factory=list, description="pairs not watched (with watch: all)",
                                     examples=[[["link1", "link3"]]])
    pairs: list[CollisionPair] = Field(default_factory=list, description=(
        "pairs with their own settings; with watch: listed, the only pairs watched"),
        examples=[[{"between": ["link7", "ball"], "min_distance": 0.05}]])
    min_distance: Annotated[Number, DISTANCE] = Field(0.02, description="smallest distance allowed between two "
                                                      "surfaces, m", examples=[0.02])
    activation_distance: Annotated[Number, Range(0, 10, "m", open=True)] = Field(0.15, description=(
        "a pair constrains the motion once its distance, less what it needs to stop, is below this, m; "
        "farther away its bound is inactive (its row stays: the QP size is fixed)"), examples=[0.15])
    max_acceleration: Annotated[Number, BRAKING] = Field(5.0, description=(
        "braking acceleration of a distance assumed by the viability bound, m/s²"), examples=[5.0])

    @model_validator(mode="after")
    def _consistent(self) -> "CollisionSpec":
        if self.activation_distance <= self.min_distance:
            raise FieldError("activation_distance", f"activation_distance ({self.activation_distance:g} m) must exceed "
                             f"min_distance ({self.min_distance:g} m)")
        if self.watch == "listed" and not self.pairs:
            raise FieldError("pairs", "watch: listed needs at least one entry in `pairs`")
        if self.watch == "listed" and self.exclude:
            raise FieldError("exclude", "exclude applies to watch: all; with watch: listed, leave the pair out of `pairs`")
        return self
