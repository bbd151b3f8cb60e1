"""Shared field types of the spec models, with messages a person can act on."""

from __future__ import annotations

import math
from typing import Annotated, Any

from pydantic import AllowInfNan, BaseModel, ConfigDict, PlainSerializer, PlainValidator, Strict, WithJsonSchema


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
        raise ValueError(f"expected a number, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"expected a finite number, got {value!r}")
    return float(value)


def _number_list(value: Any) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)):
        raise ValueError(f"expected a list of numbers, got {value!r}")
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
    try:
        return _number(value)
    except ValueError:
        raise ValueError(f"expected a number or a list of numbers, got {value!r}") from None


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


def as_list(value: float | tuple[float, ...], size: int) -> list[float]:
    """Broadcast a scalar-or-vector field to `size` entries (the size is checked by validation)."""
    if isinstance(value, tuple):
        return list(value)
    return [float(value)] * size


def size_of(value: float | tuple[float, ...] | None) -> int | None:
    """Number of entries of a vector field, None for a scalar (which broadcasts)."""
    return len(value) if isinstance(value, tuple) else None
