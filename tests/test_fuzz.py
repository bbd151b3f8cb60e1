"""Fuzzing the spec reader and validator with seeded mutations of the bundled specs.

Every case is one of specs/*.yaml or specs/paper/*.yaml with one to three mutations, some on the
text (a hostile scalar, a stray character, a deleted or re-indented line, deep nesting, an alias
bomb, a huge list) and some on the parsed data (a key dropped, added, misspelt, a value of another
type). Validation runs in this process under a time bound and must end in one of two ways:

- a report (what `dcts validate` exits 0 on), its diagnostics located;
- a SpecError (exit 1) with at least one error, every diagnostic at a `file:line`;

never another exception, a Python warning or text on stderr. A subset goes through the real
command line, which must exit 0 or 1 accordingly and print located errors only.

DCTS_FUZZ_SEED and DCTS_FUZZ_CASES run other or more cases; a failing case's id names its seed
and index, and `_case(seed, index)` rebuilds it.
"""

from __future__ import annotations

import os
import random
import re
import signal
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml

import command_line
from command_line import ROOT
from dcts_spec.spec import SpecError
from dcts_spec.validate import validate_file

SEED = int(os.environ.get("DCTS_FUZZ_SEED", "20240612"))
CASES = int(os.environ.get("DCTS_FUZZ_CASES", "300"))
TIME_BOUND = 2.0  # s per case in this process (a valid spec takes ~10 ms; the machine may be loaded)
SOURCES = sorted([*ROOT.glob("specs/*.yaml"), *ROOT.glob("specs/paper/*.yaml")])

# Scalars that broke earlier versions or sit at the edges of YAML's typing.
HOSTILE = [
    "0", "-1", "1e308", "-1e308", "1e-320", ".nan", ".inf", "-.inf", "9" * 400, "9" * 5000, "yes", "no", "on",
    "true", "null", "~", "''", "[]", "{}", "2001-13-45", "0x1F", "0o17", "1_000", "1:30", "!!binary AAAA",
    "!!timestamp 2001-13-45", "!!python/object:os.system x", "&x [*x]", "*undefined", '"\\0"', "a" * 300,
    "é", "💥", "[1, [2, [3]]]", "{a: 1}", "-", "'unterminated", "1e6", "-0.0", "1" * 25,
]
JUNK = ["\0", "\t", "\x07", ":", "- ", "[", "{", "}", "&a ", "*a", "<<: *a", "---\n", "'", '"', "\ufeff", "? ", "#",
        "\r", "\u2028", "%YAML 1.1\n"]
NAMES = ["type", "frame", "priority", "gains", "kp", "reference", "position", "joints", "max", "unit", "robot",
         "model", "urdf", "tasks", "limits", "scenario", "name", "version", "waypoints", "disturbances"]


@dataclass(frozen=True)
class Case:
    id: str
    source: Path
    mutations: tuple[str, ...]
    text: str


# --- mutations of the text --------------------------------------------------------------------------------


def _scalar_spans(text: str) -> list[tuple[int, int]]:
    """Where the scalar values are: after `key: `, or items of a flow list."""
    return [m.span(1) for m in re.finditer(r"(?::\s+|[\[,]\s*)([^\s\[\]{},#:][^\[\]{},#\n]*?)(?=\s*(?:[\]},\n#]|$))", text)]


def replace_scalar(text: str, rng: random.Random) -> str:
    spans = _scalar_spans(text)
    if not spans:
        return text
    start, end = rng.choice(spans)
    return text[:start] + rng.choice(HOSTILE) + text[end:]


def insert_junk(text: str, rng: random.Random) -> str:
    at = rng.randrange(len(text) + 1)
    return text[:at] + rng.choice(JUNK) + text[at:]


def _lines(text: str, rng: random.Random, edit: Callable[[list[str], int, random.Random], None]) -> str:
    lines = text.split("\n")
    edit(lines, rng.randrange(len(lines)), rng)
    return "\n".join(lines)


def delete_line(text: str, rng: random.Random) -> str:
    return _lines(text, rng, lambda lines, i, _: lines.pop(i))


def duplicate_line(text: str, rng: random.Random) -> str:
    return _lines(text, rng, lambda lines, i, _: lines.insert(i, lines[i]))


def swap_lines(text: str, rng: random.Random) -> str:
    def edit(lines: list[str], i: int, r: random.Random) -> None:
        j = r.randrange(len(lines))
        lines[i], lines[j] = lines[j], lines[i]
    return _lines(text, rng, edit)


def reindent_line(text: str, rng: random.Random) -> str:
    def edit(lines: list[str], i: int, r: random.Random) -> None:
        shift = r.choice([-3, -2, -1, 1, 2, 4])
        lines[i] = " " * shift + lines[i] if shift > 0 else lines[i][min(-shift, len(lines[i]) - len(lines[i].lstrip())):]
    return _lines(text, rng, edit)


def truncate(text: str, rng: random.Random) -> str:
    return text[: rng.randrange(len(text))]


def nest_deeply(text: str, rng: random.Random) -> str:
    spans = _scalar_spans(text)
    if not spans:
        return text
    start, end = rng.choice(spans)
    depth = rng.choice([5, 40, 500, 5000])
    return text[:start] + "[" * depth + "1" + "]" * depth + text[end:]


def add_alias_bomb(text: str, rng: random.Random) -> str:
    levels = rng.choice([3, 9, 12])
    bomb = "x_bomb:\n  a: &a [l, l, l, l, l, l, l, l, l]\n" + "".join(
        f"  {chr(98 + k)}: &{chr(98 + k)} [{', '.join(['*' + chr(97 + k)] * 9)}]\n" for k in range(levels - 1))
    recursive = "x_loop: &loop\n  again: *loop\n"
    return text + "\n" + rng.choice([bomb, recursive])


def grow_list(text: str, rng: random.Random) -> str:
    count = rng.choice([100, 20_000, 100_000])
    item = rng.choice(["0", "x", "{}", "[1]"])
    return re.sub(r"\[[^\[\]\n]*\]", "[" + ", ".join([item] * count) + "]", text, count=1)


# --- mutations of the data -------------------------------------------------------------------------------


def _nodes(data: Any, path: tuple = ()) -> Iterator[tuple[tuple, Any]]:
    yield path, data
    items = data.items() if isinstance(data, dict) else enumerate(data) if isinstance(data, list) else []
    for key, value in items:
        yield from _nodes(value, path + (key,))


def _parent(data: Any, path: tuple) -> Any:
    for key in path[:-1]:
        data = data[key]
    return data


def _random_value(rng: random.Random) -> Any:
    return rng.choice([
        0, -1, 1e308, -1e300, 5e-324, 10 ** 30, rng.uniform(-1e3, 1e3), True, None, "", "tool", "link7",
        "joint1", "x" * 300, [], {}, [1, 2, 3], [0.0] * 7, {"a": 1}, [[1, 2], [3]], float("inf"),
    ])


def _data_mutation(edit: Callable[[Any, random.Random], None]) -> Callable[[str, random.Random], str]:
    def mutate(text: str, rng: random.Random) -> str:
        if "&" in text or "[" * 10 in text or len(text) > 50_000:
            return text  # an alias bomb, deep nesting or a huge list from an earlier mutation: keep it
        try:
            data = yaml.safe_load(text)
        except (yaml.YAMLError, ValueError):
            return text  # an earlier mutation broke the text; keep it
        if not isinstance(data, dict):
            return text
        edit(data, rng)
        return yaml.safe_dump(data, sort_keys=False, allow_unicode=True)
    mutate.__name__ = edit.__name__
    return mutate


def _pick(data: Any, rng: random.Random, kind: type) -> tuple[tuple, Any] | None:
    found = [(p, v) for p, v in _nodes(data) if p and isinstance(_parent(data, p), kind)]
    return rng.choice(found) if found else None


def drop_key(data: dict, rng: random.Random) -> None:
    if (hit := _pick(data, rng, dict)) is not None:
        del _parent(data, hit[0])[hit[0][-1]]


def add_key(data: dict, rng: random.Random) -> None:
    mappings = [v for _, v in _nodes(data) if isinstance(v, dict)]
    rng.choice(mappings)[rng.choice([*NAMES, "extra", "Priority"])] = _random_value(rng)


def misspell_key(data: dict, rng: random.Random) -> None:
    if (hit := _pick(data, rng, dict)) is not None:
        parent, key = _parent(data, hit[0]), hit[0][-1]
        word = str(key)
        at = rng.randrange(len(word)) if word else 0
        parent[word[:at] + word[at + 1:] + rng.choice("xe_")] = parent.pop(key)


def replace_value(data: dict, rng: random.Random) -> None:
    path, _ = rng.choice(list(_nodes(data))[1:])
    _parent(data, path)[path[-1]] = _random_value(rng)


def rename_reference(data: dict, rng: random.Random) -> None:
    """A frame, joint, body or task name that the robot (or the spec) does not have."""
    names = [(p, v) for p, v in _nodes(data) if isinstance(v, str) and p and p[-1] in ("frame", "body", "task", "parent")
             or isinstance(v, str) and len(p) > 1 and p[-2] == "joints"]
    if names:
        path, value = rng.choice(names)
        _parent(data, path)[path[-1]] = rng.choice([value + "_x", value.upper(), "", "jointX", "link" + "9" * 40])


def duplicate_item(data: dict, rng: random.Random) -> None:
    lists = [v for _, v in _nodes(data) if isinstance(v, list) and v]
    if lists:
        chosen = rng.choice(lists)
        chosen.append(chosen[rng.randrange(len(chosen))])


MUTATIONS: list[Callable[[str, random.Random], str]] = [
    replace_scalar, replace_scalar, insert_junk, delete_line, duplicate_line, swap_lines, reindent_line, truncate,
    nest_deeply, add_alias_bomb, grow_list,
    *(_data_mutation(m) for m in (drop_key, add_key, misspell_key, replace_value, replace_value, rename_reference,
                                  duplicate_item)),
]


def _case(seed: int, index: int) -> Case:
    """Case `index` of a run, the same whatever the other cases are."""
    rng = random.Random(f"{seed}-{index}")
    source = rng.choice(SOURCES)
    text = source.read_text(encoding="utf-8")
    chosen = [rng.choice(MUTATIONS) for _ in range(rng.choice([1, 1, 2, 3]))]
    for mutate in chosen:
        text = mutate(text, rng)
    names = tuple(m.__name__ for m in chosen)
    return Case(f"{seed}-{index:03d}-{source.stem}-{'+'.join(names)}", source, names, text)


ALL = [_case(SEED, i) for i in range(CASES)]


# --- running a case --------------------------------------------------------------------------------------


@contextmanager
def _time_bound(seconds: float) -> Iterator[None]:
    """Interrupt the case (between Python bytecodes) after `seconds`."""
    def expire(*_: object) -> None:
        raise TimeoutError(f"validation took longer than {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def _write(case: Case, folder: Path) -> Path:
    path = folder / f"{case.id[:80]}.yaml"
    path.write_text(case.text, encoding="utf-8")
    return path


def _exit_code(path: Path) -> int:
    """What `dcts validate PATH` exits with, found in this process; asserts the diagnostics are located."""
    with warnings.catch_warnings(record=True) as caught, _time_bound(TIME_BOUND):
        warnings.simplefilter("always")
        try:
            report = validate_file(path)
        except SpecError as error:
            diagnostics, code = error.diagnostics, 1
            assert error.errors, "a SpecError without an error"
        else:
            diagnostics, code = report.diagnostics, 0
    assert not caught, f"Python warnings: {[str(w.message) for w in caught]}"
    unlocated = [str(d) for d in diagnostics if d.file != str(path) or d.line is None]
    assert not unlocated, "diagnostics without file:line:\n" + "\n".join(unlocated)
    return code


def test_the_mutations_reach_both_outcomes(tmp_path: Path) -> None:
    """The fuzzer is worth running: its cases are not all refused, nor all accepted."""
    codes = [_exit_code(_write(c, tmp_path)) for c in ALL[:40]]
    assert 0 in codes and 1 in codes


@pytest.mark.parametrize("case", ALL, ids=[c.id for c in ALL])
def test_validation_ends_in_a_located_verdict(case: Case, tmp_path: Path, capfd: pytest.CaptureFixture) -> None:
    _exit_code(_write(case, tmp_path))
    assert capfd.readouterr().err == "", "validation wrote to stderr (a library's own output?)"


LINE = re.compile(r"^(?P<file>.+?):(?P<line>\d+):(?P<column>\d+): (?P<severity>error|warning|info): ")


def test_the_command_line_agrees(tmp_path: Path) -> None:
    """A subset through `dcts validate`: exit 0 when every file is valid, 1 when one is not, and every
    line on stderr a located diagnostic (no traceback, no library's text)."""
    subset = ALL[:: max(1, len(ALL) // 16)]
    paths = {c.id: _write(c, tmp_path) for c in subset}
    codes = {c.id: _exit_code(paths[c.id]) for c in subset}
    valid = [str(paths[i]) for i, code in codes.items() if code == 0] or [str(ROOT / "specs" / "minimal.yaml")]
    invalid = [str(paths[i]) for i, code in codes.items() if code == 1]
    assert invalid, "the subset has no invalid spec; choose another"

    ok = command_line.dcts("validate", *valid, timeout=120)
    assert ok.returncode == 0, ok.stderr
    assert ok.stderr == ""

    bad = command_line.dcts("validate", *valid, *invalid, timeout=120)
    assert bad.returncode == 1
    lines = bad.stderr.splitlines()
    stray = [line for line in lines if not LINE.match(line)]
    assert not stray, "stderr lines that are not located diagnostics:\n" + "\n".join(stray[:10])
    for path in invalid:
        assert any(LINE.match(line)["file"] == path and LINE.match(line)["severity"] == "error" for line in lines), (
            f"no located error for {path}")
