"""JSON Schema of the campaign files, for editors (yaml-language-server):

    python -m dcts_spec.campaign.schema schemas/dcts-campaign.schema.json
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .document import Campaign

SCHEMA_ID = "https://dcts.dev/schemas/dcts-campaign.schema.json"


def campaign_json_schema_text() -> str:
    schema = {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": SCHEMA_ID,
              **Campaign.model_json_schema()}
    return json.dumps(schema, indent=2, ensure_ascii=False) + "\n"


if __name__ == "__main__":
    text = campaign_json_schema_text()
    if len(sys.argv) > 1:
        Path(sys.argv[1]).write_text(text, encoding="utf-8")
    else:
        sys.stdout.write(text)
