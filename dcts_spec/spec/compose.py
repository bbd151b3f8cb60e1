"""YAML text → node graph, with bounds a spec never needs to cross.

PyYAML's composer recurses once per nesting level (500 nested lists exhaust Python's stack) and
expands aliases without limit (a 500-byte "billion laughs" takes minutes). This composer reads the
parser's events without recursion and refuses, at the line and column where it happens: nesting
deeper than `MAX_DEPTH`, more than `MAX_VALUES` values (aliases expanded; every value costs time
downstream) and an alias that refers to a value containing it. It uses libyaml's parser when
PyYAML has it (10x faster).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import yaml
from yaml.error import Mark
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

MAX_DEPTH = 32  # a spec nests 6 levels (scenario.waypoints.points[i][j])
MAX_VALUES = 10_000  # scalars, lists and mappings, aliases expanded; a spec has a few hundred

_EventLoader = getattr(yaml, "CBaseLoader", yaml.BaseLoader)


class LimitError(yaml.MarkedYAMLError):
    """Valid YAML that a spec refuses (too deep, too many values, a recursive alias)."""


class _Resolver(yaml.resolver.Resolver):
    """YAML 1.1's tag rules, closer to YAML 1.2: `1e6` is a number; only true/false are booleans
    (`version: yes` or `name: on` stay text) and nothing is a date (`version: 2001-13-45` is text)."""


_Resolver.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"), list("-+0123456789")
)
for _first, _rules in _Resolver.yaml_implicit_resolvers.items():
    _rules[:] = [(tag, rule) for tag, rule in _rules
                 if tag not in ("tag:yaml.org,2002:bool", "tag:yaml.org,2002:timestamp")]
_Resolver.add_implicit_resolver("tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"),
                                list("tTfF"))


@dataclass
class _Open:
    """A collection being composed, with what its values add up to (aliases expanded)."""

    node: MappingNode | SequenceNode
    anchor: str | None
    values: int = 1
    height: int = 1
    items: list = field(default_factory=list)


@dataclass
class _Composer:
    anchors: dict[str, tuple[Node, int, int]] = field(default_factory=dict)  # node, values, height
    stack: list[_Open] = field(default_factory=list)
    open_anchors: set[str] = field(default_factory=set)
    values: int = 0
    resolver: _Resolver = field(default_factory=_Resolver)
    root: Node | None = None

    def add(self, node: Node, values: int, height: int, mark: Mark) -> None:
        """Put a finished node into the collection being composed (or make it the document)."""
        if len(self.stack) + height > MAX_DEPTH:
            raise LimitError(None, None, f"nested deeper than {MAX_DEPTH} levels (a spec needs about 6)", mark)
        if not self.stack:
            self.root = node
            return
        parent = self.stack[-1]
        parent.items.append(node)
        parent.values += values
        parent.height = max(parent.height, height + 1)

    def scalar(self, event: yaml.ScalarEvent) -> None:
        tag = event.tag
        if tag is None or tag == "!":
            tag = self.resolver.resolve(ScalarNode, event.value, event.implicit)
        node = ScalarNode(tag, event.value, event.start_mark, event.end_mark, style=event.style)
        self._count(1, event.start_mark)
        self._anchor(event.anchor, node, 1, 1, event.start_mark)
        self.add(node, 1, 1, event.start_mark)

    def start(self, event: yaml.CollectionStartEvent, kind: type[MappingNode] | type[SequenceNode]) -> None:
        tag = event.tag
        if tag is None or tag == "!":
            tag = self.resolver.resolve(kind, None, event.implicit)
        node = kind(tag, [], event.start_mark, None, flow_style=event.flow_style)
        self._count(1, event.start_mark)
        if len(self.stack) + 1 > MAX_DEPTH:
            raise LimitError(None, None, f"nested deeper than {MAX_DEPTH} levels (a spec needs about 6)", event.start_mark)
        if event.anchor is not None:
            self.open_anchors.add(event.anchor)
        self.stack.append(_Open(node, event.anchor))

    def end(self, event: yaml.CollectionEndEvent) -> None:
        done = self.stack.pop()
        node = done.node
        node.end_mark = event.end_mark
        node.value = done.items if isinstance(node, SequenceNode) else list(zip(done.items[::2], done.items[1::2]))
        if done.anchor is not None:
            self.open_anchors.discard(done.anchor)
        self._anchor(done.anchor, node, done.values, done.height, node.start_mark)
        self.add(node, done.values, done.height, node.start_mark)

    def alias(self, event: yaml.AliasEvent) -> None:
        name, mark = event.anchor, event.start_mark
        if name in self.open_anchors:
            raise LimitError(None, None, f"the alias *{name} refers to a value that contains it (a recursive alias)", mark)
        if name not in self.anchors:
            raise LimitError(None, None, f"the alias *{name} names no anchor (&{name}) above it", mark)
        node, values, height = self.anchors[name]
        self._count(values, mark, f" once the alias *{name} is expanded (an alias bomb?)")
        self.add(node, values, height, mark)

    def _count(self, values: int, mark: Mark, how: str = "") -> None:
        self.values += values
        if self.values > MAX_VALUES:
            raise LimitError(None, None, f"the document has more than {MAX_VALUES} values{how}; a spec has a few "
                             "hundred", mark)

    def _anchor(self, name: str | None, node: Node, values: int, height: int, mark: Mark) -> None:
        if name is not None:
            self.anchors[name] = (node, values, height)


def compose(text: str) -> Node | None:
    """The single YAML document of `text` as a node graph (None if it has none).

    Raises yaml.MarkedYAMLError (LimitError for the bounds above) with the place of the problem.
    """
    composer = _Composer()
    documents = 0
    for event in yaml.parse(text, Loader=_EventLoader):
        if isinstance(event, yaml.ScalarEvent):
            composer.scalar(event)
        elif isinstance(event, yaml.MappingStartEvent):
            composer.start(event, MappingNode)
        elif isinstance(event, yaml.SequenceStartEvent):
            composer.start(event, SequenceNode)
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            composer.end(event)
        elif isinstance(event, yaml.AliasEvent):
            composer.alias(event)
        elif isinstance(event, yaml.DocumentStartEvent):
            documents += 1
            if documents > 1:
                raise yaml.composer.ComposerError(
                    "expected a single document in the stream", None, "but found another document", event.start_mark)
    return composer.root
