"""YAML reading that remembers where every key and value came from."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from .errors import Diagnostic, KeyPath, SpecError


class _Loader(yaml.SafeLoader):
    """The safe loader, also reading `1e6` and `1.0e-3` as numbers (YAML 1.2; YAML 1.1 wants `1.0e+6`)."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


@dataclass
class SourceMap:
    """File name and the (line, column) of every key path of a YAML document."""

    file: str
    positions: dict[KeyPath, tuple[int, int]] = field(default_factory=dict)

    def locate(self, path: KeyPath) -> tuple[int | None, int | None]:
        """Position of the longest prefix of `path` present in the document."""
        for end in range(len(path), -1, -1):
            pos = self.positions.get(tuple(path[:end]))
            if pos is not None:
                return pos
        return None, None

    def diagnostic(self, path: KeyPath, message: str, severity: str = "error") -> Diagnostic:
        line, column = self.locate(path)
        return Diagnostic(message, severity, self.file, line, column, tuple(path))  # type: ignore[arg-type]


def _construct(node: yaml.Node, path: KeyPath, source: SourceMap, errors: list[Diagnostic]) -> Any:
    """Build Python data from a composed YAML node, recording positions on the way."""
    source.positions.setdefault(path, (node.start_mark.line + 1, node.start_mark.column + 1))
    if isinstance(node, yaml.MappingNode):
        out: dict[str, Any] = {}
        for key_node, value_node in node.value:
            where = (key_node.start_mark.line + 1, key_node.start_mark.column + 1)
            if key_node.tag == "tag:yaml.org,2002:merge":
                message = "YAML merge keys (`<<`) are not supported; write the keys out"
                errors.append(Diagnostic(message, "error", source.file, *where, path))
                continue
            key = _scalar(key_node)
            if not isinstance(key, str):
                errors.append(Diagnostic(f"keys must be text, got {key!r}", "error", source.file, *where, path))
                continue
            if key in out:
                errors.append(Diagnostic(f"duplicate key {key!r}", "error", source.file, *where, path + (key,)))
                continue
            source.positions[path + (key,)] = where
            out[key] = _construct(value_node, path + (key,), source, errors)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_construct(item, path + (i,), source, errors) for i, item in enumerate(node.value)]
    return _scalar(node)


def _scalar(node: yaml.Node) -> Any:
    """A YAML scalar (or a complex key) as Python data, with YAML 1.1 typing rules."""
    return yaml.constructor.SafeConstructor().construct_object(node, deep=True)


def read_yaml(text: str, file: str) -> tuple[Any, SourceMap]:
    """Parse YAML text into plain data and a source map; syntax errors become located diagnostics."""
    source = SourceMap(file)
    try:
        node = yaml.compose(text, Loader=_Loader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        problem = " ".join(filter(None, [exc.context, exc.problem]))
        hint = ""
        if "\t" in text:
            hint = " (YAML does not allow tabs for indentation)"
        elif "mapping values are not allowed" in problem or "expected <block end>" in problem:
            hint = " (check the indentation of this line and the one above)"
        line = mark.line + 1 if mark else None
        column = mark.column + 1 if mark else None
        raise SpecError([Diagnostic(f"invalid YAML: {problem}{hint}", "error", file, line, column)]) from None
    except yaml.YAMLError as exc:
        raise SpecError([Diagnostic(f"invalid YAML: {exc}", "error", file, 1, 1)]) from None
    if node is None:
        raise SpecError(
            [Diagnostic("the file is empty; a spec is a mapping with at least `version`, `name`, `robot` and `tasks`", "error", file, 1, 1)]
        )
    errors: list[Diagnostic] = []
    try:
        data = _construct(node, (), source, errors)
    except yaml.constructor.ConstructorError as exc:
        mark = exc.problem_mark
        raise SpecError([Diagnostic(f"invalid YAML value: {exc.problem}", "error", file, mark.line + 1, mark.column + 1)]) from None
    if errors:
        raise SpecError(errors)
    if not isinstance(data, dict):
        kind = "a list" if isinstance(data, list) else f"the value {data!r}"
        message = f"a spec must be a mapping of keys (version, name, robot, tasks, ...), but the file holds {kind}"
        raise SpecError([source.diagnostic((), message)])
    return data, source


def read_yaml_file(path: str | Path) -> tuple[Any, SourceMap]:
    """Read a YAML file; a missing or unreadable file is a located diagnostic too."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SpecError([Diagnostic("no such file", "error", str(path))]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError([Diagnostic(f"cannot read the file: {exc}", "error", str(path))]) from None
    return read_yaml(text, str(path))
