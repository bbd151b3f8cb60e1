"""YAML reading that remembers where every key and value came from."""

from __future__ import annotations

import os
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from .compose import LimitError, compose
from .errors import Diagnostic, KeyPath, SpecError, shown


MAX_BYTES = 1_000_000  # a spec is a few kB; a bigger file is not one (and /dev/zero never ends)
MAX_NUMBER_CHARS = 30  # longer whole numbers are no spec value (and Python refuses 4,300 digits)
_INT_TAG = "tag:yaml.org,2002:int"
_STR_TAG = "tag:yaml.org,2002:str"


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
    """Build Python data from a composed YAML node, recording positions on the way.

    The composer bounds the depth and the alias expansion, so this recursion is bounded too.
    """
    source.positions.setdefault(path, _position(node.start_mark))
    if isinstance(node, yaml.MappingNode):
        out: dict[str, Any] = {}
        for key_node, value_node in node.value:
            where = _position(key_node.start_mark)
            if key_node.tag == "tag:yaml.org,2002:merge":
                message = "YAML merge keys (`<<`) are not supported; write the keys out"
                errors.append(Diagnostic(message, "error", source.file, *where, path))
                continue
            if not isinstance(key_node, yaml.ScalarNode):
                errors.append(Diagnostic(f"keys must be text, got a {key_node.id}", "error", source.file, *where, path))
                continue
            key = _scalar(key_node, source, errors)
            if not isinstance(key, str):
                errors.append(Diagnostic(f"keys must be text, got {shown(key)}", "error", source.file, *where, path))
                continue
            if key in out:
                errors.append(Diagnostic(f"duplicate key {shown(key)}", "error", source.file, *where, path + (key,)))
                continue
            source.positions[path + (key,)] = where
            out[key] = _construct(value_node, path + (key,), source, errors)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_construct(item, path + (i,), source, errors) for i, item in enumerate(node.value)]
    return _scalar(node, source, errors)


def _position(mark: yaml.Mark) -> tuple[int, int]:
    return mark.line + 1, mark.column + 1


def _scalar(node: yaml.ScalarNode, source: SourceMap, errors: list[Diagnostic]) -> Any:
    """A YAML scalar as Python data (YAML 1.1 typing rules); a value YAML cannot make is an error."""
    if node.tag == _INT_TAG and len(node.value) > MAX_NUMBER_CHARS:
        message = f"a whole number of {len(node.value)} characters is out of range for any spec value"
        errors.append(Diagnostic(message, "error", source.file, *_position(node.start_mark)))
        return None
    if node.tag == _STR_TAG:
        return node.value  # most scalars: no need for PyYAML's constructor
    try:
        return yaml.constructor.SafeConstructor().construct_object(node, deep=True)
    except (yaml.constructor.ConstructorError, ValueError, TypeError, OverflowError) as exc:
        problem = exc.problem if isinstance(exc, yaml.MarkedYAMLError) else str(exc)
        errors.append(Diagnostic(f"invalid YAML value: {problem}", "error", source.file, *_position(node.start_mark)))
        return None


# What a document is, for the messages about a file that holds none: its name and required keys
SPEC_DOCUMENT = ("spec", ("version", "name", "robot", "tasks"))


def read_yaml(text: str, file: str, document: tuple[str, tuple[str, ...]] = SPEC_DOCUMENT) -> tuple[Any, SourceMap]:
    """Parse YAML text into plain data and a source map; syntax errors become located diagnostics.
    `document`: what the file should hold (a spec, a campaign file), for the message when it does not."""
    source = SourceMap(file)
    try:
        node = compose(text)
    except LimitError as exc:
        raise SpecError([Diagnostic(exc.problem, "error", file, *_position(exc.problem_mark))]) from None
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
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1
        column = exc.position - text.rfind("\n", 0, exc.position)
        message = f"invalid YAML: the character U+{exc.character:04X} is not allowed (control characters other than tab and newline)"
        raise SpecError([Diagnostic(message, "error", file, line, column)]) from None
    except yaml.YAMLError as exc:
        raise SpecError([Diagnostic(f"invalid YAML: {exc}", "error", file, 1, 1)]) from None
    name, keys = document
    if node is None:
        required = ", ".join(f"`{k}`" for k in keys[:-1]) + f" and `{keys[-1]}`"
        raise SpecError([Diagnostic(f"the file is empty; a {name} is a mapping with at least {required}", "error",
                                    file, 1, 1)])
    errors: list[Diagnostic] = []
    data = _construct(node, (), source, errors)
    if errors:
        raise SpecError(errors)
    if not isinstance(data, dict):
        kind = "a list" if isinstance(data, list) else f"the value {shown(data)}"
        message = f"a {name} must be a mapping of keys ({', '.join(keys)}, ...), but the file holds {kind}"
        raise SpecError([source.diagnostic((), message)])
    return data, source


def _named_pipe(path: Path) -> bool:
    """Is `path` a named pipe other than this process's standard input (`/dev/stdin` of a pipeline
    is read as it flows)? Opening one waits for a writer: `dcts validate` hung (found from outside)."""
    try:
        status = path.stat()
    except OSError:
        return False
    if not stat.S_ISFIFO(status.st_mode):
        return False
    try:
        own = os.fstat(0)
    except OSError:
        return True
    return (own.st_dev, own.st_ino) != (status.st_dev, status.st_ino)


def read_yaml_file(path: str | Path, document: tuple[str, tuple[str, ...]] = SPEC_DOCUMENT) -> tuple[Any, SourceMap]:
    """Read a YAML file of at most MAX_BYTES; a missing, unreadable or too big file is a located diagnostic too."""
    path = Path(path)
    if _named_pipe(path):
        raise SpecError([Diagnostic("a named pipe, not a file: reading it waits for a writer that may never come; "
                                    "give the YAML file itself", "error", str(path))])
    try:
        with path.open("rb") as stream:
            raw = stream.read(MAX_BYTES + 1)
    except FileNotFoundError:
        raise SpecError([Diagnostic("no such file", "error", str(path))]) from None
    except OSError as exc:
        raise SpecError([Diagnostic(f"cannot read the file: {exc.strerror or exc}", "error", str(path))]) from None
    if len(raw) > MAX_BYTES:
        message = f"the file is larger than {MAX_BYTES // 1000} kB; a {document[0]} is a few kB of YAML"
        raise SpecError([Diagnostic(message, "error", str(path), 1, 1)])
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        column = exc.start - raw.rfind(b"\n", 0, exc.start)
        message = f"cannot read the file: byte 0x{raw[exc.start]:02x} is not UTF-8 text"
        raise SpecError([Diagnostic(message, "error", str(path), line, column)]) from None
    return read_yaml(text, str(path), document)
