"""Load a spec file: YAML with locations, then the pydantic models, with every error located."""

from __future__ import annotations

import re
import types
import typing
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ValidationError

from .document import Spec
from .errors import Diagnostic, KeyPath, SpecError, did_you_mean, shown
from .source import SourceMap, read_yaml, read_yaml_file
from .types import IDENTIFIER_RULE, FieldError

Document = typing.TypeVar("Document", bound=BaseModel)


def load_spec(path: str | Path) -> Spec:
    """Read and check the structure of a spec file; raises SpecError listing every problem."""
    data, source = read_yaml_file(path)
    return spec_from_data(data, source)


def load_spec_text(text: str, file: str = "<text>") -> Spec:
    """Like `load_spec`, from YAML text."""
    data, source = read_yaml(text, file)
    return spec_from_data(data, source)


def check_structure(spec: Spec) -> None:
    """Raise SpecError if `spec`'s values do not pass the checks `load_spec` makes: a Spec edited in
    Python (frozen models change by `model_copy(update=...)`, which pydantic does not validate) had
    a NaN torque limit built into a controller whose every torque was NaN. The errors name the
    edited value's path, in no line of the file (which still holds the old value)."""
    data = spec.model_dump(by_alias=True)
    try:
        Spec.model_validate(data)
    except ValidationError as exc:
        raise SpecError(_diagnostics(exc, data, SourceMap(f"{spec.source.file} (as edited in Python)"), Spec)) from None


def spec_yaml(spec: Spec) -> str:
    """The spec's values as YAML that loads back to the same spec (units as written, nothing
    converted)."""
    def plain(value: Any) -> Any:  # (tuples as lists: YAML's safe dumper knows no tuple)
        if isinstance(value, dict):
            return {k: plain(v) for k, v in value.items()}
        return [plain(v) for v in value] if isinstance(value, (list, tuple)) else value

    return yaml.safe_dump(plain(spec.model_dump(by_alias=True)), sort_keys=False, allow_unicode=True)


def recorded_bytes(spec: Spec) -> bytes | None:
    """What a bundle records as its spec (spec.yaml, SPEC_SHA256): the bytes of the file `spec` was
    loaded from if that file still gives this spec, else its values as YAML (a spec edited in
    Python: the bundle compiled at a 40 Nm limit recorded the file's 100 Nm, found from outside);
    None for a spec that has no file (from text)."""
    file = Path(spec.source.file)
    if not file.is_file():
        return None
    try:
        same = load_spec(file).model_dump() == spec.model_dump()
    except SpecError:
        same = False
    return file.read_bytes() if same else spec_yaml(spec).encode("utf-8")


def spec_from_data(data: dict[str, Any], source: SourceMap) -> Spec:
    spec = document_from_data(Spec, data, source)
    spec._source = source
    return spec


def document_from_data(model: type[Document], data: dict[str, Any], source: SourceMap) -> Document:
    """`data` as a `model` document (the spec, a campaign file): a SpecError locates every problem
    in `source`, allowed keys named from `model`."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise SpecError(_diagnostics(exc, data, source, model)) from None


def _diagnostics(exc: ValidationError, data: Any, source: SourceMap, root: type[BaseModel]) -> list[Diagnostic]:
    found: dict[KeyPath, tuple[int, Diagnostic]] = {}
    for error in exc.errors(include_url=False):
        path, rest = _data_path(data, error["loc"])
        blamed = error.get("ctx", {}).get("error")
        if isinstance(blamed, FieldError):
            value = _value_at(data, path)
            if isinstance(value, dict) and blamed.key in value:
                path = path + (blamed.key,)
        key = path + rest if error["type"] in ("missing", "extra_forbidden") else path
        rank = _GENERIC_RANK.get(error["type"], 0)
        # A union reports one error per alternative; keep the most specific one.
        if key not in found or rank < found[key][0]:
            found[key] = (rank, source.diagnostic(path, _message(error, path, rest, data, root)))
    # A type mismatch of one alternative says nothing when another alternative found problems inside the
    # value (`external_torque: {mode: noisey}` is not the literal `ideal`, but the useful error is about `mode`).
    inside = {key[:end] for key in found for end in range(len(key))}  # proper prefixes: keys with errors below
    kept = [d for key, (rank, d) in found.items() if rank == 0 or key not in inside]
    return sorted(kept, key=lambda d: (d.line or 0, d.column or 0))


# How generic an error type is: a union alternative's type mismatch says less than the others.
_GENERIC_RANK = {"literal_error": 1, "model_type": 2, "dict_type": 2, "model_attributes_type": 2, "list_type": 2,
                 "tuple_type": 2}


def _data_path(data: Any, loc: tuple) -> tuple[KeyPath, tuple]:
    """Split a pydantic location into the part that exists in the data and the rest.

    Location parts that are not keys of the data (names of union alternatives) are dropped, and so is
    the tag of a discriminated union (the entry's `type`), even when the entry also has a key of that
    name (`{type: force, force: [...]}`).
    """
    path: list[str | int] = []
    current = data
    last = len(loc) - 1
    for i, part in enumerate(loc):
        if isinstance(current, dict) and i < last and current.get("type") == part:
            continue
        if isinstance(current, dict) and part in current:
            current = current[part]
            path.append(part)
        elif isinstance(current, list) and isinstance(part, int) and 0 <= part < len(current):
            current = current[part]
            path.append(part)
        elif i == last:
            return tuple(path), (part,)
    return tuple(path), ()


def _value_at(data: Any, path: KeyPath) -> Any:
    for part in path:
        data = data[part]
    return data


def _message(error: dict, path: KeyPath, rest: tuple, data: Any, root: type[BaseModel]) -> str:
    kind = error["type"]
    if kind == "extra_forbidden":
        key = rest[0] if rest else path[-1]
        parent = path if rest else path[:-1]
        allowed = _allowed_keys(root, parent, data)
        hint = did_you_mean(key, allowed)
        return f"unknown key {shown(key)}{hint}; allowed keys: {', '.join(allowed)}" if allowed else f"unknown key {shown(key)}"
    if kind == "missing" and rest and isinstance(rest[0], int):  # (a fixed-length list, too short)
        given = _value_at(data, path)
        return f"too few values: got {len(given)}, value {rest[0] + 1} is missing"
    if kind == "missing":
        return f"missing required key {rest[0]!r}" if rest else "missing required value"
    if kind == "literal_error":
        # `expected` reads "'a', 'b' or 'c'" for text and "1 or 2" for numbers.
        allowed = [text or number for text, number in re.findall(r"'([^']*)'|(-?\d+)", error["ctx"]["expected"])]
        got = error["input"]
        if isinstance(got, str) and got in allowed:  # `version: "1"`
            return f"expected the number {got}, got the text {got!r} (remove the quotes)"
        return f"{shown(got)} is not allowed{did_you_mean(got, allowed)}; allowed: {', '.join(allowed)}"
    if kind == "union_tag_invalid":
        allowed = re.findall(r"'([^']*)'", error["ctx"]["expected_tags"])
        got = error["ctx"]["tag"]
        return f"unknown type {shown(got)}{did_you_mean(got, allowed)}; allowed: {', '.join(allowed)}"
    if kind == "union_tag_not_found":
        tag_key = error["ctx"]["discriminator"].strip("'")  # pydantic quotes it: "'type'"
        return f"missing key {tag_key!r} (what kind of entry this is)"
    if kind in ("model_type", "dict_type", "model_attributes_type"):
        return f"expected a mapping of keys, got {_describe(error['input'])}"
    if kind in ("list_type", "tuple_type"):
        return f"expected a list, got {_describe(error['input'])}"
    if kind == "string_pattern_mismatch":
        return f"{shown(error['input'])} is not an identifier ({IDENTIFIER_RULE})"
    if kind == "string_too_long":
        return f"at most {error['ctx']['max_length']} characters, got {len(error['input'])}"
    if kind in ("bool_type", "bool_parsing"):
        got = error["input"]
        unquote = " (remove the quotes)" if isinstance(got, str) and got.lower() in ("true", "false") else ""
        return f"expected true or false, got {_describe(got)}{unquote}"
    if kind == "string_type":
        return f"expected text, got {_describe(error['input'])}"
    if kind in ("float_type", "float_parsing"):
        return f"expected a number, got {_describe(error['input'])}"
    if kind == "finite_number":
        return f"expected a finite number, got {_describe(error['input'])}"
    if kind in ("int_type", "int_parsing", "int_from_float"):
        return f"expected a whole number, got {_describe(error['input'])}"
    if kind in _BOUNDS:
        symbol, bound = _BOUNDS[kind]
        return f"must be {symbol} {error['ctx'][bound]:g}, got {_describe(error['input'])}"
    if kind == "too_short" and error["ctx"].get("min_length") == 1:
        return "expected at least one entry, got an empty list"
    if kind in ("too_short", "too_long"):
        most = kind == "too_long"
        limit = error["ctx"]["max_length" if most else "min_length"]
        return f"expected at {'most' if most else 'least'} {limit} values, got {error['ctx']['actual_length']}"
    message = error["msg"]
    for prefix in ("Value error, ", "Assertion failed, "):
        message = message.removeprefix(prefix)
    return message


_BOUNDS = {"greater_than": (">", "gt"), "greater_than_equal": ("≥", "ge"), "less_than": ("<", "lt"), "less_than_equal": ("≤", "le")}


def _describe(value: Any) -> str:
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    if value is None:
        return "nothing (an empty value)"
    return shown(value)


def _allowed_keys(root: type[BaseModel], path: KeyPath, data: Any) -> list[str]:
    """Keys the `root` model accepts at `path` (found by walking the model classes)."""
    model = _model_at(root, path, data)
    return list(model.model_fields) if model is not None else []


def _model_at(annotation: Any, path: KeyPath, data: Any) -> type[BaseModel] | None:
    current = annotation
    node = data
    for part in (*path, None):
        current = _unwrap(current, node)
        if part is None:
            break
        if isinstance(current, type) and issubclass(current, BaseModel):
            field = current.model_fields.get(str(part))
            if field is None:
                return None
            current = field.annotation
        else:
            origin = typing.get_origin(current)
            args = typing.get_args(current)
            if origin in (list, tuple) and args:
                current = args[0]
            elif origin is dict and args:
                current = args[1]
            else:
                return None
        node = node[part] if isinstance(node, (dict, list)) else None
    return current if isinstance(current, type) and issubclass(current, BaseModel) else None


def _unwrap(annotation: Any, node: Any) -> Any:
    """Strip Annotated/Optional; pick the union member that fits the data (by its `type` tag)."""
    while True:
        origin = typing.get_origin(annotation)
        if origin is typing.Annotated:
            annotation = typing.get_args(annotation)[0]
            continue
        if origin in (typing.Union, types.UnionType):
            members = [a for a in typing.get_args(annotation) if a is not type(None)]
            models = [m for m in members if isinstance(m, type) and issubclass(m, BaseModel)]
            tag = node.get("type") if isinstance(node, dict) else None
            tagged = [m for m in models if "type" in m.model_fields and tag in typing.get_args(m.model_fields["type"].annotation)]
            if tagged:
                annotation = tagged[0]
            elif models and isinstance(node, dict):
                annotation = models[0]
            else:
                annotation = members[0]
            continue
        return annotation
