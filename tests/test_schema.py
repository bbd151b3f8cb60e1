"""The committed JSON Schema of the spec language is up to date, and accepts the example specs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from dcts_spec.spec.schema import spec_json_schema_text

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
