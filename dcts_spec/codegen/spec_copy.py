"""The bundle's copy of its spec: `spec.yaml`, and the robot's URDF beside it when the spec names
one (`robot/<file>.urdf`, which the copy's `robot.urdf` then points at), so that the bundle
re-validates and recompiles wherever it is copied. A built-in robot (`robot: {model: iiwa14}`)
needs nothing: dcts ships it, and the manifest keeps its model's SHA-256.

The copy differs from the spec file only in that value and in an editor's schema line
(`# yaml-language-server: $schema=../schemas/...`) whose relative path leads nowhere from the
bundle: that line goes (a URL stays). `spec_sha256` stays the file's. A spec edited in Python
is copied as its values (`spec.loader.recorded_bytes`), and `spec_sha256` is theirs.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import yaml

from ..spec import Spec

URDF_FOLDER = "robot"
_PLAIN = re.compile(r"[A-Za-z0-9_./-]+")  # a path YAML reads as the same string unquoted
# yaml-language-server's modeline with a relative path (a URL has a scheme: "https:")
_RELATIVE_SCHEMA_LINE = re.compile(r"^[ \t]*#[ \t]*yaml-language-server:[ \t]*\$schema=(?![A-Za-z][\w+.-]*:|/)[^\n]*\n?",
                                   re.MULTILINE)


def copy_spec(spec: Spec, spec_bytes: bytes | None, directory: Path) -> dict[str, str]:
    """Write spec.yaml (and the URDF) into `directory`; returns what was written, by role
    ("spec", "urdf": paths relative to the bundle). Nothing without a spec file."""
    source = Path(spec.source.file) if spec.source.file else None
    if spec_bytes is None:
        if source is None or not source.is_file():
            return {}
        spec_bytes = source.read_bytes()
    written = {"spec": "spec.yaml"}
    spec_bytes = _RELATIVE_SCHEMA_LINE.sub("", spec_bytes.decode("utf-8")).encode("utf-8")
    if spec.robot.urdf is not None:
        urdf = spec.base_dir / spec.robot.urdf
        target = f"{URDF_FOLDER}/{urdf.name}"
        (directory / URDF_FOLDER).mkdir(exist_ok=True)
        shutil.copyfile(urdf, directory / target)
        spec_bytes = with_urdf(spec_bytes.decode("utf-8"), target).encode("utf-8")
        written["urdf"] = target
    (directory / "spec.yaml").write_bytes(spec_bytes)
    return written


def with_urdf(text: str, path: str) -> str:
    """The spec's text with the value of robot.urdf replaced by `path` (the rest byte for byte)."""
    root = yaml.compose(text, Loader=yaml.SafeLoader)
    value = _mapping_value(_mapping_value(root, "robot"), "urdf")
    if value is None:
        raise ValueError("the spec has no robot.urdf to point at the copy")
    literal = path if _PLAIN.fullmatch(path) else json.dumps(path)  # JSON's string is a YAML string
    return text[: value.start_mark.index] + literal + text[value.end_mark.index:]


def _mapping_value(node: yaml.Node | None, key: str) -> yaml.Node | None:
    if not isinstance(node, yaml.MappingNode):
        return None
    return next((v for k, v in node.value if isinstance(k, yaml.ScalarNode) and k.value == key), None)
