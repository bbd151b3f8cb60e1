"""The comments of the bundled specs stay true: every setting they name (`controller.priority_weights`)
is one of the spec language, and every file they point to is in the repository."""

from __future__ import annotations

import re
import typing
from pathlib import Path

import pytest
from pydantic import BaseModel

from dcts_spec import Spec

ROOT = Path(__file__).resolve().parents[1]
SPECS = sorted((ROOT / "specs").glob("**/*.yaml"))
SETTING = re.compile(r"\b(?:controller|limits|robot|scenario)(?:\.[a-z_]+)+")
REPO_PATH = re.compile(r"\b(?:docs|scripts|schemas|specs|tests)/[\w./-]*\w")


def _comments(path: Path) -> list[tuple[int, str]]:
    """(line, text) of each YAML comment (no spec value holds a '#')."""
    return [(n, line.split("#", 1)[1]) for n, line in enumerate(path.read_text().splitlines(), 1) if "#" in line]


def _models(annotation: object) -> list[type[BaseModel]]:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in typing.get_args(annotation) for m in _models(arg)]


def _is_setting(dotted: str) -> bool:
    """Whether `a.b.c` is a path of keys through the spec's models."""
    models: list[type[BaseModel]] = [Spec]
    for key in dotted.split("."):
        fields = [m.model_fields[key] for m in models if key in m.model_fields]
        if not fields:
            return False
        models = [m for f in fields for m in _models(f.annotation)]
    return True


def test_the_checks_can_fail() -> None:
    assert _is_setting("controller.priority_weights") and _is_setting("limits.joint_velocity.max")
    assert not _is_setting("controller.scaling_weight") and not _is_setting("limits.joint_velocity.min")


@pytest.mark.parametrize("spec", SPECS, ids=[p.relative_to(ROOT).as_posix() for p in SPECS])
def test_comments_name_real_settings_and_files(spec: Path) -> None:
    stale = [(n, m) for n, text in _comments(spec) for m in SETTING.findall(text) if not _is_setting(m)]
    stale += [(n, m) for n, text in _comments(spec) for m in REPO_PATH.findall(text) if not (ROOT / m).exists()]
    assert not stale, f"{spec.name}: comments name what does not exist: {stale}"
