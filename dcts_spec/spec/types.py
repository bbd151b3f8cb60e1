"""Shared field types of the spec models, with messages a person can act on."""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Annotated, Any

from pydantic import (AllowInfNan, BaseModel, ConfigDict, GetCoreSchemaHandler, GetJsonSchemaHandler, PlainSerializer,
                      PlainValidator, Strict, WithJsonSchema)
from pydantic_core import core_schema

from .errors import shown


class FieldError(ValueError):
    """A model-level check that blames one key of the model (so the message points at its line)."""

    def __init__(self, key: str, message: str):
        super().__init__(message)
        self.key = key


class StrictModel(BaseModel):
    """Base of every spec section: unknown keys are errors, values are immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True)


def _number(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"expected a number, got {shown(value)}")
    if not math.isfinite(value):
        raise ValueError(f"expected a finite number, got {shown(value)}")
    return float(value)


def _number_list(value: Any) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)):
        raise ValueError(f"expected a list of numbers, got {shown(value)}")
    out = []
    for i, item in enumerate(value):
        try:
            out.append(_number(item))
        except ValueError as exc:
            raise ValueError(f"item {i}: {exc}") from None
    return tuple(out)


def _scalar_or_list(value: Any) -> float | tuple[float, ...]:
    if isinstance(value, (list, tuple)):
        if not value:
            raise ValueError("expected a number or a non-empty list of numbers, got an empty list")
        return _number_list(value)
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"expected a finite number or a list of finite numbers, got {shown(value)}")
    try:
        return _number(value)
    except ValueError:
        raise ValueError(f"expected a number or a list of numbers, got {shown(value)}") from None


def _vec3(value: Any) -> tuple[float, float, float]:
    out = _number_list(value)
    if len(out) != 3:
        raise ValueError(f"expected a list of 3 numbers [x, y, z], got {len(out)}")
    return out  # type: ignore[return-value]


_NUMBER_SCHEMA = {"type": "number"}
_LIST_SCHEMA = {"type": "array", "items": _NUMBER_SCHEMA, "minItems": 1}

# A native (strict, finite) float rather than a PlainValidator: a plain validator replaces the core schema,
# and pydantic then silently drops field constraints such as `Field(gt=0)` (in validation and JSON Schema).
Number = Annotated[float, Strict(), AllowInfNan(False)]
# The names that go into the generated C (the spec's, its tasks', the frames it adds)
IDENTIFIER = r"^[A-Za-z_][A-Za-z0-9_]*$"
IDENTIFIER_RULE = "letters, digits and _, not starting with a digit"
# Strict too: a quoted 'true' or 'yes' is text, refused as `kp: '100'` is (found from outside: they were read as true)
Flag = Annotated[bool, Strict()]
# Strict: YAML reads `yes`/`on` as true, and a lax int would take true (and "1") as 1.
Integer = Annotated[int, Strict()]


def _serialize(value: Any) -> Any:
    """Vectors serialize as lists (however they were stored)."""
    return list(value) if isinstance(value, (list, tuple)) else value


_AS_LIST = PlainSerializer(_serialize)

NumberList = Annotated[tuple[float, ...], PlainValidator(_number_list), _AS_LIST, WithJsonSchema(_LIST_SCHEMA)]
ScalarOrVector = Annotated[
    float | tuple[float, ...],
    PlainValidator(_scalar_or_list),
    _AS_LIST,
    WithJsonSchema({"anyOf": [_NUMBER_SCHEMA, _LIST_SCHEMA], "description": "one value for all, or one per joint/axis"}),
]
Vec3 = Annotated[
    tuple[float, float, float],
    PlainValidator(_vec3),
    _AS_LIST,
    WithJsonSchema({"type": "array", "items": _NUMBER_SCHEMA, "minItems": 3, "maxItems": 3}),
]


@dataclass(frozen=True)
class Range:
    """Values a number field (every entry of a list field) may take: from `low` (excluded if `open`)
    to `high`, in `unit`. Beyond them the compiled controller overflows or is meaningless (a torque
    limit of 1e308, a weight of 0), so validation refuses them with the range, and JSON Schema states it.
    """

    low: float
    high: float
    unit: str = ""
    open: bool = False

    def __get_pydantic_core_schema__(self, source: Any, handler: GetCoreSchemaHandler) -> core_schema.CoreSchema:
        return core_schema.no_info_after_validator_function(self.check, handler(source))

    def __get_pydantic_json_schema__(self, schema: core_schema.CoreSchema, handler: GetJsonSchemaHandler) -> dict:
        out = copy.deepcopy(handler(schema))  # the number schemas above are shared between types
        self._bound(out)
        return out

    def _bound(self, schema: dict) -> None:
        if schema.get("type") in ("number", "integer"):
            schema["exclusiveMinimum" if self.open else "minimum"] = self.low
            schema["maximum"] = self.high
        for inner in [*schema.get("anyOf", []), *([schema["items"]] if "items" in schema else [])]:
            self._bound(inner)

    def check(self, value: Any) -> Any:
        """`value` (a number or tuple of numbers) if within the range, else ValueError saying why."""
        if isinstance(value, tuple):
            for i, v in enumerate(value):
                if not self._holds(v):
                    raise ValueError(f"item {i}: {self._message(v)}")
        elif value is not None and not self._holds(value):
            raise ValueError(self._message(value))
        return value

    def _holds(self, value: float) -> bool:
        return (self.low < value if self.open else self.low <= value) and value <= self.high

    def _message(self, value: float) -> str:
        unit = f" {self.unit}" if self.unit else ""
        return f"must be {'>' if self.open else '≥'} {_short(self.low)} and ≤ {_short(self.high)}{unit}, got {_short(value)}"


# Ranges shared by several sections. Angles and joint values are bounded in whatever unit the section
# uses (rad or deg; m for a prismatic joint): the bound is about floating point, not about a robot.
LENGTH = Range(-1e3, 1e3, "m")
JOINT_VALUE = Range(-1e4, 1e4)
TIME = Range(0, 1e4, "s")
DURATION = Range(0, 1e4, "s", open=True)
TORQUE = Range(-1e6, 1e6, "Nm")


def _short(x: float) -> str:
    """1e6 for powers of ten, 4294967295 for other whole numbers, 0.001 or 2.5e-7 otherwise."""
    exponent = math.log10(abs(x)) if x else 0.0
    if x and abs(exponent) >= 4 and exponent.is_integer():
        return f"{'-' if x < 0 else ''}1e{int(exponent)}"
    if float(x).is_integer() and abs(x) < 1e16:
        return str(int(x))
    return f"{x:g}".replace("e+0", "e").replace("e+", "e").replace("e-0", "e-")


def as_list(value: float | tuple[float, ...], size: int) -> list[float]:
    """Broadcast a scalar-or-vector field to `size` entries (the size is checked by validation)."""
    if isinstance(value, tuple):
        return list(value)
    return [float(value)] * size


def size_of(value: float | tuple[float, ...] | None) -> int | None:
    """Number of entries of a vector field, None for a scalar (which broadcasts)."""
    return len(value) if isinstance(value, tuple) else None
