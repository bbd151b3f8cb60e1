"""The campaign file of `dcts sweep`: distributions and grids over a spec's scenario and controller.

A value anywhere below is a number (fixed) or one of

    {uniform: [low, high]}     {loguniform: [low, high]}     {normal: [mean, std]}
    {choice: [a, b, ...]}      {grid: [a, b, ...]}

Random values are drawn per sample; grid values are crossed with each other, and `samples` draws
are made at every grid point. Loaded like a spec: every error says file:line, what is wrong and
what is allowed.
"""

from __future__ import annotations

import math

from pathlib import Path
from typing import Annotated, Any, Literal, get_args

from pydantic import AfterValidator, BeforeValidator, Field, WithJsonSchema, model_validator

from ..spec.controller import Formulation
from ..spec.errors import shown
from ..spec.loader import document_from_data
from ..spec.robot import PAYLOAD_MASS
from ..spec.scenario import MASS_SCALE, NOISE_STD
from ..spec.source import SourceMap, read_yaml, read_yaml_file
from ..spec.types import DURATION, TIME, TORQUE, FieldError, Integer, Number, Range, StrictModel
from ..spec.units import AngleUnit

KINDS = ("uniform", "loguniform", "normal", "choice", "grid")
CAMPAIGN_DOCUMENT = ("campaign file", ("version", "samples"))  # (for read_yaml's messages)
MAX_SAMPLES = 10_000_000  # in a campaign, its grids crossed included


def _fixed_or_distribution(value: Any) -> Any:
    """A plain number is a fixed value; a mapping is a distribution; anything else is refused."""
    if isinstance(value, bool) or not isinstance(value, (int, float, dict)):
        raise ValueError(f"expected a number or a distribution ({', '.join(KINDS)}), got {shown(value)}")
    return {"fixed": value} if isinstance(value, (int, float)) else value


class Distribution(StrictModel):
    """Exactly one of: a fixed number, a range drawn uniformly (or log-uniformly), a normal
    distribution, a choice among values, or a grid of values."""

    fixed: Number | None = Field(None, description="this value for every sample (write the number itself)")
    uniform: tuple[Number, Number] | None = Field(None, description="[low, high], drawn uniformly", examples=[[0, 80]])
    loguniform: tuple[Number, Number] | None = Field(
        None, description="[low, high], both positive, drawn uniformly in log scale", examples=[[10, 1000]])
    normal: tuple[Number, Number] | None = Field(None, description="[mean, standard deviation]", examples=[[0, 0.5]])
    choice: list[Number] | None = Field(None, min_length=1, description="one of these, equally likely",
                                        examples=[[0.9, 1.0, 1.1]])
    grid: list[Number] | None = Field(None, min_length=1, description="each of these in turn, crossed with the other "
                                      "grids", examples=[[0, 20, 40]])

    @model_validator(mode="after")
    def _exactly_one(self) -> "Distribution":
        given = [k for k in ("fixed", *KINDS) if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"give exactly one of {', '.join(KINDS)} (got {', '.join(given) or 'none'})")
        low_high = self.uniform or self.loguniform
        if low_high is not None and not low_high[0] < low_high[1]:
            raise ValueError(f"low {low_high[0]:g} must be below high {low_high[1]:g}")
        if low_high is not None and not math.isfinite(low_high[1] - low_high[0]):  # (the draw overflowed)
            raise ValueError(f"[{low_high[0]:g}, {low_high[1]:g}] is wider than a double can hold: narrow it")
        if self.loguniform is not None and not self.loguniform[0] > 0:
            raise ValueError(f"loguniform needs a positive low, got {self.loguniform[0]:g}")
        if self.normal is not None and self.normal[1] < 0:
            raise ValueError(f"the standard deviation must be ≥ 0, got {self.normal[1]:g}")
        return self

    @property
    def kind(self) -> str:
        return next(k for k in ("fixed", *KINDS) if getattr(self, k) is not None)

    @property
    def values(self) -> list[float]:
        """The finitely many values of a fixed value, a choice or a grid (empty for the others)."""
        return [self.fixed] if self.fixed is not None else list(self.choice or self.grid or [])

    @property
    def bounds(self) -> tuple[float, float] | None:
        """Lowest and highest value it can take (None for a normal distribution)."""
        if self.normal is not None:
            return None
        low_high = self.uniform or self.loguniform
        return (low_high[0], low_high[1]) if low_high is not None else (min(self.values), max(self.values))


_PAIR = {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2}
_LIST = {"type": "array", "items": {"type": "number"}, "minItems": 1}
# What an editor should accept: a number, or a mapping with one distribution.
VALUE_SCHEMA = {"anyOf": [{"type": "number"}, {
    "type": "object", "minProperties": 1, "maxProperties": 1, "additionalProperties": False,
    "properties": {"fixed": {"type": "number"}, "uniform": _PAIR, "loguniform": _PAIR, "normal": _PAIR,
                   "choice": _LIST, "grid": _LIST}}],
    "description": "a number, or one of {uniform: [low, high]}, {loguniform: [low, high]}, {normal: [mean, std]}, "
                   "{choice: [...]}, {grid: [...]}"}
Value = Annotated[Distribution, BeforeValidator(_fixed_or_distribution), WithJsonSchema(VALUE_SCHEMA)]
Vec3Value = tuple[Value, Value, Value]


# A normal distribution's draws are held to mean ± this many standard deviations (one draw in 10⁹
# falls beyond: that sample is invalid, as any draw the spec refuses)
NORMAL_REACH = 6.0


def within(limits: Range) -> AfterValidator:
    """A Value whose every draw the spec's key accepts (`limits`, the spec's range there), checked
    where the campaign says it: a draw outside made the sample invalid, blamed on the spec's line."""
    def check(value: Distribution) -> Distribution:
        bounds, what = value.bounds, ""
        if bounds is None:
            mean, std = value.normal
            bounds, what = (mean - NORMAL_REACH * std, mean + NORMAL_REACH * std), f" (mean ± {NORMAL_REACH:g} σ)"
        for v in bounds:
            try:
                limits.check(v)
            except ValueError as error:
                shown_bounds = f"{bounds[0]:g}" if bounds[0] == bounds[1] else f"from {bounds[0]:g} to {bounds[1]:g}"
                raise ValueError(f"values {shown_bounds}{what}: {error}") from None
        return value
    return AfterValidator(check)


class ForceMagnitude(StrictModel):
    """A force of a given size in a direction: fixed, or drawn per sample."""

    magnitude: Value = Field(description="size of the force, N", examples=[{"uniform": [0, 80]}])
    direction: Literal["any", "horizontal"] | tuple[Number, Number, Number] = Field(
        "any", description="any: uniform on the sphere; horizontal: uniform in the world x-y plane; or a fixed "
        "vector (normalized)", examples=["horizontal", [1, 0, 0]])

    @model_validator(mode="after")
    def _nonzero_direction(self) -> "ForceMagnitude":
        if isinstance(self.direction, tuple) and not any(self.direction):
            raise ValueError("direction [0, 0, 0] has no direction")
        return self


class PushSweep(StrictModel):
    """A force on a body during a window (added to the spec's scenario disturbances)."""

    body: str = Field(description="link or frame pushed", examples=["link7"])
    force: Vec3Value | ForceMagnitude = Field(description="[x, y, z] in N (world axes), or {magnitude, direction}",
                                              examples=[{"magnitude": {"uniform": [0, 80]}, "direction": "horizontal"}])
    point: Vec3Value = Field((0.0, 0.0, 0.0), validate_default=True, description="point in the body's frame, m", examples=[[0, 0, 0.05]])
    start: Annotated[Value, within(TIME)] = Field(description="s after the start of the run",
                                                  examples=[{"uniform": [0.2, 0.8]}])
    duration: Annotated[Value, within(DURATION)] = Field(description="s", examples=[{"choice": [0.05, 0.1, 0.2]}])


class PayloadSweep(StrictModel):
    """A mass the controller does not know about (added to the spec's scenario payloads)."""

    frame: str = Field(description="link or frame it is attached to", examples=["tool"])
    mass: Annotated[Value, within(PAYLOAD_MASS)] = Field(description="kg (> 0)", examples=[{"uniform": [0.5, 3]}])
    com: Vec3Value = Field((0.0, 0.0, 0.0), validate_default=True, description="centre of mass in the frame, m", examples=[[0, 0, 0.05]])


class MismatchSweep(StrictModel):
    """The controller's masses and inertias scaled by `mass_scale`: one C bundle per value, so only
    a fixed value, a choice or a grid."""

    mass_scale: Annotated[Value, within(MASS_SCALE)] = Field(description="scale of the controller's masses (unitless)",
                              examples=[{"choice": [0.9, 1.0, 1.1]}])

    @model_validator(mode="after")
    def _finitely_many(self) -> "MismatchSweep":
        if self.mass_scale.kind not in ("fixed", "choice", "grid"):
            raise FieldError("mass_scale", "each value needs its own C bundle: give a number, {choice: [...]} or "
                             f"{{grid: [...]}}, not {self.mass_scale.kind}")
        return self


class SensingSweep(StrictModel):
    """τ_ext noise and bias (the scenario's `external_torque: noisy`); the noise's seed is the sample's."""

    noise_std: Annotated[Value, within(NOISE_STD)] = Field(
        0.0, validate_default=True, description="Gaussian noise, Nm (one draw for all joints)", examples=[{"uniform": [0, 1]}])
    bias: Annotated[Value, within(TORQUE)] | list[Annotated[Value, within(TORQUE)]] = Field(0.0, validate_default=True, description="constant offset, Nm: one value drawn for each joint, or a "
                                      "list of one value per joint", examples=[{"normal": [0, 0.5]}])


class InitialStateSweep(StrictModel):
    """Where the runs start: an offset from the spec's initial_q, or anywhere within the limits."""

    offset: Value | list[Value] | None = Field(
        None, description="added to the spec's initial_q (or the middle of the range), in `unit`: one value drawn "
        "for each joint, or one value per joint; clipped into the joint position limits",
        examples=[{"uniform": [-10, 10]}])
    within_limits: Annotated[Number, Range(0, 0.5, "of the range")] | None = Field(
        None, description="uniform within the joint position limits, this fraction of each joint's range kept "
        "free at both ends", examples=[0.1])
    unit: AngleUnit = Field("rad", description="unit of `offset`", examples=["deg"])

    @model_validator(mode="after")
    def _exactly_one(self) -> "InitialStateSweep":
        if (self.offset is None) == (self.within_limits is None):
            raise ValueError("give exactly one of offset, within_limits")
        return self


def _formulation_or_choice(value: Any) -> Any:
    return {"fixed": value} if isinstance(value, str) else value


_FORMULATIONS = {"enum": list(get_args(Formulation))}
_FORMULATION_SCHEMA = {"anyOf": [_FORMULATIONS, {
    "type": "object", "minProperties": 1, "maxProperties": 1, "additionalProperties": False,
    "properties": {k: {"type": "array", "items": _FORMULATIONS, "minItems": 1} for k in ("choice", "grid")}}]}


class FormulationSweep(StrictModel):
    """A formulation, or several (one C bundle each, built once)."""

    fixed: Formulation | None = None
    choice: list[Formulation] | None = Field(None, min_length=1)
    grid: list[Formulation] | None = Field(None, min_length=1)

    @model_validator(mode="after")
    def _exactly_one(self) -> "FormulationSweep":
        if sum(v is not None for v in (self.fixed, self.choice, self.grid)) != 1:
            raise ValueError("a formulation name, or exactly one of choice, grid")
        return self


class ControllerSweep(StrictModel):
    """Controller values: the formulation, and run-time parameters the spec's `parameters` section
    declares (set at the start of every run, so the one compiled bundle serves every sample)."""

    formulation: Annotated[FormulationSweep, BeforeValidator(_formulation_or_choice),
                           WithJsonSchema(_FORMULATION_SCHEMA)] | None = Field(
        None, description="a formulation, or {choice: [...]} / {grid: [...]}", examples=[{"grid": ["dcts", "osc"]}])
    parameters: dict[str, Value | list[Value]] = Field(
        default_factory=dict, description="run-time parameter (as the bundle names it: ee_position.kp, "
        "ee_position.position, posture.q, ...) to a value, or one value per component; SI units",
        examples=[{"ee_position.kp": {"loguniform": [100, 1000]}}])


DEFAULT_METRICS = ("max_cartesian_violation", "max_joint_position_violation", "max_joint_velocity_violation",
                   "max_torque_violation", "primary_rms_error")


class ReportSettings(StrictModel):
    """What the report ranks and counts."""

    worst: Annotated[Integer, Range(0, 100)] = Field(3, description="worst cases listed (and written as replay "
                                                     "specs) per metric", examples=[3])
    metrics: list[str] = Field(list(DEFAULT_METRICS), min_length=1, description=(
        "metrics ranked and plotted against each swept value: summary keys (max_cartesian_violation, ...), "
        "task_rms_error.<task>, task_final_error.<task>, or primary_rms_error (the first task's)"),
        examples=[["max_cartesian_violation", "primary_rms_error"]])
    violation_tolerance: Annotated[Number, Range(0, 1e3)] = Field(
        1e-6, description="a limit counts as violated beyond this (rad, rad/s, Nm or m)", examples=[1e-6])
    convergence: dict[str, Annotated[Number, Range(0, 1e3, open=True)]] = Field(
        default_factory=dict, description="task to the final error (max over the last 10 % of the run, SI units) "
        "beyond which the run counts as not converged; a diverged run never converges",
        examples=[{"ee_position": 0.005}])


class Campaign(StrictModel):
    """Samples of a spec's scenario and controller, run with the spec's compiled C controller."""

    version: Literal[1] = Field(description="campaign language version; 1 is the only one", examples=[1])
    samples: Annotated[Integer, Range(1, MAX_SAMPLES)] = Field(
        description="random draws (at every grid point, when there are grids)", examples=[1000])
    seed: Annotated[Integer, Range(0, 2**32 - 1)] = Field(0, description="seed of every draw", examples=[7])
    duration: Annotated[Number, DURATION] | None = Field(None, description="length of each run, s (default: the "
                                                          "spec's scenario.duration)", examples=[1.5])
    pushes: list[PushSweep] = Field(default_factory=list, description="forces on bodies")
    payloads: list[PayloadSweep] = Field(default_factory=list, description="unmodelled masses")
    model_mismatch: MismatchSweep | None = Field(None, description="the controller's mass scale")
    external_torque: SensingSweep | None = Field(None, description="τ_ext noise and bias")
    initial_state: InitialStateSweep | None = Field(None, description="start configurations")
    controller: ControllerSweep | None = Field(None, description="formulation and run-time parameters")
    report: ReportSettings = Field(default_factory=ReportSettings, description="what the report ranks and counts")

    _source: SourceMap | None = None

    @property
    def source(self) -> SourceMap:
        return self._source or SourceMap("<campaign>")


def load_campaign(path: str | Path) -> Campaign:
    """Read a campaign file; a SpecError locates every problem."""
    return _campaign(*read_yaml_file(path, CAMPAIGN_DOCUMENT))


def load_campaign_text(text: str, file: str = "<campaign>") -> Campaign:
    return _campaign(*read_yaml(text, file, CAMPAIGN_DOCUMENT))


def _campaign(data: Any, source: SourceMap) -> Campaign:
    campaign = document_from_data(Campaign, data, source)
    campaign._source = source
    return campaign
