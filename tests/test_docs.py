"""Every YAML block of the README and docs/ means what it says: a whole spec (it has `version:`)
validates as it stands; a fragment's sections replace specs/minimal.yaml's, and that validates;
a campaign file of `dcts sweep` (it has `samples:`) loads as one."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from dcts_spec.campaign import load_campaign_text
from dcts_spec.spec import load_spec_text
from dcts_spec.validate import validate_spec

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
BLOCK = re.compile(r"^```yaml\n(.*?)^```", re.S | re.M)


def _blocks() -> list[tuple[str, int, str]]:
    out = []
    for path in DOCS:
        text = path.read_text()
        for match in BLOCK.finditer(text):
            out.append((path.relative_to(ROOT).as_posix(), text[: match.start()].count("\n") + 2, match.group(1)))
    return out


def test_the_docs_have_yaml_blocks():
    assert len(_blocks()) >= 2


@pytest.mark.parametrize(("file", "line", "block"), _blocks(), ids=lambda v: str(v)[:40])
def test_yaml_block_validates(file, line, block):
    data = yaml.safe_load(block)
    if "samples" in data:
        load_campaign_text(block, f"{file} (the block at line {line})")  # raises SpecError with the located message
        return
    if "version" in data:
        text = block
    else:
        minimal = yaml.safe_load((ROOT / "specs" / "minimal.yaml").read_text())
        assert set(data) <= set(minimal), f"{file}:{line}: a fragment with sections minimal.yaml lacks: {set(data) - set(minimal)}"
        minimal.update(data)  # its sections replace the minimal spec's
        text = yaml.safe_dump(minimal, sort_keys=False)
    validate_spec(load_spec_text(text, f"{file} (the block at line {line})"))  # raises SpecError with the located message
