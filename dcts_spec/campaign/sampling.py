"""The samples of a campaign: every swept value, drawn per sample from (seed, index) alone.

Sample i sits at grid point i // samples (the grids crossed in the order of `variables`, then the
formulation's; the first varies slowest) and draws its random values from a generator seeded
with (campaign seed, i): any sample can be drawn again on its own, in any order, which is what
resuming and replaying rely on.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..spec.errors import KeyPath, format_path
from .document import Campaign, Distribution, ForceMagnitude, Value

SEED_RANGE = 2**32  # the scenario's noise seed range


@dataclass(frozen=True)
class Variable:
    """One swept value of the campaign file: `size` draws (one per joint for a per-joint value)."""

    path: KeyPath  # where it is written in the campaign file
    distribution: Distribution
    size: int = 1

    @property
    def name(self) -> str:
        return format_path(self.path)


@dataclass(frozen=True)
class Sample:
    """The values of one sample: by variable name, plus the formulation and the noise seed."""

    index: int
    seed: int  # of the τ_ext noise (the scenario's external_torque.seed)
    values: dict[str, float | list[float]]
    formulation: str | None
    directions: dict[str, list[float]]  # push force directions (unit vectors), by push path

    def value(self, *path: str | int) -> float | list[float]:
        return self.values[format_path(tuple(path))]

    def columns(self) -> dict[str, float | str | None]:
        """Flat columns for the results: a per-joint value as name[j], and its norm."""
        out: dict[str, float | str | None] = {}
        for name, value in self.values.items():
            if isinstance(value, list):
                out |= {f"{name}[{j}]": v for j, v in enumerate(value)}
                out[f"{name}.norm"] = math.sqrt(sum(v * v for v in value))  # what its plots show
            else:
                out[name] = value
        for name, direction in self.directions.items():
            out |= {f"{name}.direction[{j}]": v for j, v in enumerate(direction)}
        if self.formulation is not None:
            out["controller.formulation"] = self.formulation
        return out


class Sampler:
    """Draws the samples of a campaign for a robot with `joints` joints."""

    def __init__(self, campaign: Campaign, joints: int):
        self.campaign = campaign
        self.variables = list(variables(campaign, joints))
        formulation = campaign.controller.formulation if campaign.controller else None
        self._formulations = None if formulation is None else (formulation.choice or formulation.grid or [formulation.fixed])
        self._formulation_grid = formulation is not None and formulation.grid is not None
        self._grids: list[list] = [v.distribution.grid for v in self.variables if v.distribution.grid is not None]
        if self._formulation_grid:
            self._grids.append(list(self._formulations))

    @property
    def grid_points(self) -> int:
        """The grids crossed: how many points (1 without grids)."""
        return math.prod(len(g) for g in self._grids)

    @property
    def count(self) -> int:
        """Samples in the campaign: the draws at every grid point."""
        return self.campaign.samples * self.grid_points

    def _grid_point(self, k: int) -> list:
        """The values of grid point k, in the order of itertools.product over the grids (the last
        grid varies fastest), without listing the points (a product of large grids is huge)."""
        point = []
        for grid in reversed(self._grids):
            k, r = divmod(k, len(grid))
            point.append(grid[r])
        return point[::-1]

    @property
    def formulations(self) -> list[str | None]:
        """Every formulation a sample may use (None: the spec's)."""
        return list(self._formulations) if self._formulations else [None]

    def mass_scales(self) -> list[float]:
        mismatch = self.campaign.model_mismatch
        return [1.0] if mismatch is None else sorted(set(mismatch.mass_scale.values))

    def sample(self, index: int) -> Sample:
        if not 0 <= index < self.count:
            raise IndexError(f"sample {index} of {self.count}")
        rng = np.random.default_rng([self.campaign.seed, index])
        seed = int(rng.integers(SEED_RANGE))
        point = iter(self._grid_point(index // self.campaign.samples))
        values: dict[str, float | list[float]] = {}
        for v in self.variables:
            if v.distribution.grid is not None:
                values[v.name] = float(next(point))
            else:
                drawn = [_draw(v.distribution, rng) for _ in range(v.size)]
                values[v.name] = drawn if v.size > 1 else drawn[0]
        formulation = None
        if self._formulation_grid:
            formulation = next(point)
        elif self._formulations:
            formulation = self._formulations[int(rng.integers(len(self._formulations)))]
        directions = {format_path(("pushes", i, "force")): _direction(p.force.direction, rng)
                      for i, p in enumerate(self.campaign.pushes) if isinstance(p.force, ForceMagnitude)}
        return Sample(index, seed, values, formulation, directions)

    def swept(self) -> list[str]:
        """Names of the variables that vary between samples (the x axes of the plots)."""
        return [v.name for v in self.variables if v.distribution.kind != "fixed"
                and not (v.distribution.values and len(set(v.distribution.values)) == 1)]


def variables(campaign: Campaign, joints: int) -> Iterator[Variable]:
    """Every value of the campaign file, section by section (pushes, payloads, model_mismatch,
    external_torque, initial_state, controller parameters): the order of the draws."""
    for i, push in enumerate(campaign.pushes):
        at = ("pushes", i)
        if isinstance(push.force, ForceMagnitude):
            yield Variable(at + ("force", "magnitude"), push.force.magnitude)
        else:
            yield from _vector(at + ("force",), push.force)
        yield from _vector(at + ("point",), push.point)
        yield Variable(at + ("start",), push.start)
        yield Variable(at + ("duration",), push.duration)
    for i, payload in enumerate(campaign.payloads):
        yield Variable(("payloads", i, "mass"), payload.mass)
        yield from _vector(("payloads", i, "com"), payload.com)
    if campaign.model_mismatch is not None:
        yield Variable(("model_mismatch", "mass_scale"), campaign.model_mismatch.mass_scale)
    if campaign.external_torque is not None:
        yield Variable(("external_torque", "noise_std"), campaign.external_torque.noise_std)
        yield from _per_joint(("external_torque", "bias"), campaign.external_torque.bias, joints)
    state = campaign.initial_state
    if state is not None and state.offset is not None:
        yield from _per_joint(("initial_state", "offset"), state.offset, joints)
    elif state is not None:  # where in its shrunk range each joint starts, 0 to 1
        yield Variable(("initial_state", "within_limits"), Distribution(uniform=(0.0, 1.0)), joints)
    if campaign.controller is not None:
        for name, value in campaign.controller.parameters.items():
            yield from _per_joint(("controller", "parameters", name), value, 1)


def _vector(path: KeyPath, values: tuple[Value, ...]) -> Iterator[Variable]:
    for j, value in enumerate(values):
        yield Variable(path + ("xyz"[j],), value)


def parameter_columns(name: str, value: Any) -> dict[str, Any]:
    """A run-time parameter's value (a number, or a list of its components) as the sample's values
    (and the results' columns) hold it: `controller.parameters.<name>`, or `…<name>[j]` each."""
    path = ("controller", "parameters", name)
    if isinstance(value, list):
        return {format_path(path + (j,)): v for j, v in enumerate(value)}
    return {format_path(path): value}


def _per_joint(path: KeyPath, value: Value | list[Value], size: int) -> Iterator[Variable]:
    """One variable of `size` draws, or one per entry of a list."""
    if isinstance(value, list):
        for j, entry in enumerate(value):
            yield Variable(path + (j,), entry)
    else:
        yield Variable(path, value, size)


def _draw(d: Distribution, rng: np.random.Generator) -> float:
    if d.fixed is not None:
        return float(d.fixed)
    if d.uniform is not None:
        return float(rng.uniform(*d.uniform))
    if d.loguniform is not None:
        low, high = d.loguniform
        return float(math.exp(rng.uniform(math.log(low), math.log(high))))
    if d.normal is not None:
        return float(rng.normal(*d.normal))
    choices = d.choice or []
    return float(choices[int(rng.integers(len(choices)))])


def _direction(direction: str | tuple[float, float, float], rng: np.random.Generator) -> list[float]:
    """A unit vector: fixed, uniform on the sphere (`any`) or on the horizontal circle."""
    if direction == "any":
        v = rng.normal(size=3)
    elif direction == "horizontal":
        angle = rng.uniform(0.0, 2.0 * math.pi)
        v = np.array([math.cos(angle), math.sin(angle), 0.0])
    else:
        v = np.array(direction, dtype=float)
    return [float(x) for x in v / np.linalg.norm(v)]
