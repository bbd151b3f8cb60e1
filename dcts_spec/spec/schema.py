"""JSON Schema of the spec language, for editors (yaml-language-server) and other tools."""

from __future__ import annotations

import json

from .document import Spec

SCHEMA_ID = "https://dcts.dev/schemas/dcts-spec.schema.json"


def spec_json_schema() -> dict:
    schema = Spec.model_json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": SCHEMA_ID, **schema}


def spec_json_schema_text() -> str:
    return json.dumps(spec_json_schema(), indent=2, ensure_ascii=False) + "\n"
