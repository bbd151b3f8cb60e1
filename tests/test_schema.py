"""The committed JSON Schema of the spec language is up to date, and accepts the example specs."""

from __future__ import annotations

import json
import re
import typing
from pathlib import Path
from typing import Annotated

import pytest
import yaml
from pydantic import BaseModel, TypeAdapter

from dcts_spec.formulations.problem import DEFAULT_WEIGHT_LOWEST, DEFAULT_WEIGHT_RATIO
from dcts_spec.spec import Spec, load_spec_text
from dcts_spec.spec.schema import spec_json_schema_text
from dcts_spec.validate import validate_spec

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = ROOT / "schemas" / "dcts-spec.schema.json"


def test_committed_schema_is_up_to_date() -> None:
    assert SCHEMA.is_file(), "schemas/dcts-spec.schema.json is missing; write it with `dcts schema -o schemas/dcts-spec.schema.json`"
    assert SCHEMA.read_text(encoding="utf-8") == spec_json_schema_text(), (
        "schemas/dcts-spec.schema.json is out of date with the spec models; "
        "regenerate it with `dcts schema -o schemas/dcts-spec.schema.json` and commit it"
    )


def test_schema_accepts_the_minimal_spec() -> None:
    jsonschema = pytest.importorskip("jsonschema")
    schema = json.loads(SCHEMA.read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    spec = yaml.safe_load((ROOT / "specs" / "minimal.yaml").read_text(encoding="utf-8"))
    assert [e.message for e in validator.iter_errors(spec)] == []
    spec["controller"] = {"period": 0}
    assert list(validator.iter_errors(spec)), "the schema should carry the field constraints (period > 0)"


# --- every property is described (with its unit) and has examples ------------------------------------

def _properties(schema: dict) -> list[tuple[str, str, dict]]:
    """(model, property, its schema) for the root and every model of $defs."""
    models = [("Spec", schema), *schema["$defs"].items()]
    return [(model, name, prop) for model, body in models for name, prop in body.get("properties", {}).items()]


def _is_numeric(prop: dict) -> bool:
    """Whether a property's values are (lists of) real numbers, looking through anyOf/items (integers are
    counts, levels or seeds)."""
    if prop.get("type") == "number":
        return True
    return any(_is_numeric(p) for p in [*prop.get("anyOf", []), *([prop["items"]] if "items" in prop else [])])


# A number's description names its unit, or says it has none.
UNIT = re.compile(r"\b(m|s|N|Nm|kg|rad|deg|m/s|rad/s|m/s²|rad/s²|1/s|1/s²|Nm·s/rad)(?=[\s,;.)]|$)|unitless|`unit`")


def test_every_property_has_a_description_and_examples() -> None:
    props = _properties(json.loads(SCHEMA.read_text(encoding="utf-8")))
    assert len(props) >= 90, "the walk missed the models of $defs"
    undescribed = [f"{m}.{p}" for m, p, s in props if not s.get("description", "").strip()]
    assert not undescribed, f"properties without a description: {undescribed}"
    without = [f"{m}.{p}" for m, p, s in props if not s.get("examples")]
    assert not without, f"properties without examples: {without}"
    unitless = [f"{m}.{p}: {s['description']}" for m, p, s in props if _is_numeric(s) and not UNIT.search(s["description"])]
    assert not unitless, "numeric properties whose description names no unit:\n" + "\n".join(unitless)


def test_the_schema_has_a_whole_spec_as_example() -> None:
    (example,) = json.loads(SCHEMA.read_text(encoding="utf-8"))["examples"]
    validate_spec(load_spec_text(yaml.safe_dump(example), "the schema's example"))


def _models(model: type[BaseModel]) -> set[type[BaseModel]]:
    """A model and every model its fields mention."""
    found = {model}
    for field in model.model_fields.values():
        for inner in _classes(field.annotation):
            if issubclass(inner, BaseModel) and inner not in found:
                found |= _models(inner)
    return found


def _classes(annotation) -> list[type]:
    if isinstance(annotation, type):
        return [annotation]
    return [c for arg in typing.get_args(annotation) for c in _classes(arg)]


FIELDS = [(m, name, f) for m in sorted(_models(Spec), key=lambda m: m.__name__) for name, f in m.model_fields.items()]


@pytest.mark.parametrize(("model", "name", "field"), FIELDS, ids=[f"{m.__name__}.{n}" for m, n, _ in FIELDS])
def test_property_examples_are_valid_values(model, name, field) -> None:
    adapter = TypeAdapter(Annotated[field.annotation, field])  # with its constraints (gt, min_length, ...)
    for example in field.examples or []:
        adapter.validate_python(example)  # raises on an example the spec would refuse


def test_default_priority_weights_are_those_of_the_formulations() -> None:
    """The schema states the default weights; the QP-MT/QP-MD code must use the same."""
    text = Spec.model_fields["controller"].annotation.model_fields["priority_weights"].description
    lowest, ratio = re.search(r"default: (\S+) for the lowest level and (\S+) times more", text).groups()
    assert (float(lowest), float(ratio)) == (DEFAULT_WEIGHT_LOWEST, DEFAULT_WEIGHT_RATIO)
    three = [float(w) for w in re.search(r"three levels: \[(.*?)\]", text)[1].split(",")]
    assert three == [DEFAULT_WEIGHT_LOWEST * DEFAULT_WEIGHT_RATIO ** k for k in (2, 1, 0)]
