"""The package's modules import only from earlier stages of the data flow (README, "Layout").

spec → robot → symbolic → tasks/limits → formulations → validate → solve → controller → codegen →
sim → analysis → commands and cli. A module that imports from a later stage ties the early
stages to the late ones (the simulate command's module, which writes the analysis, once sat in
sim/)."""

from __future__ import annotations

import ast
from pathlib import Path

import dcts_spec

PACKAGE = Path(dcts_spec.__file__).parent
# each top-level module or package of dcts_spec, by stage; utilities (stage 0) import none of it
STAGES = [
    {"files", "choices", "phases", "buffered_function", "parameter_ramp"},
    {"spec"},
    {"robot"},
    {"symbolic"},
    {"tasks", "limits"},
    {"formulations"},
    {"validate", "validate_collision", "validate_parameters"},
    {"solve"},
    {"controller"},
    {"codegen"},
    {"sim"},
    {"analysis"},
    {"campaign", "sim_commands", "starter"},
    {"cli", "__init__", "__main__"},
]
STAGE = {name: i for i, names in enumerate(STAGES) for name in names}


def _unit(path: Path) -> str:
    """The top-level module or package a file belongs to."""
    rel = path.relative_to(PACKAGE)
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


def _imported_units(path: Path) -> set[str]:
    """The top-level parts of dcts_spec a file imports (relative or absolute, also inside functions)."""
    package = list(path.relative_to(PACKAGE).parts[:-1])
    units = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            parts = package[: len(package) - node.level + 1] + (node.module.split(".") if node.module else [])
            units.update([parts[0]] if parts else [alias.name for alias in node.names])
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("dcts_spec."):
            units.add(node.module.split(".")[1])
        elif isinstance(node, ast.Import):
            units.update(a.name.split(".")[1] for a in node.names if a.name.startswith("dcts_spec."))
    return units


def test_every_module_has_a_stage():
    units = {_unit(p) for p in PACKAGE.rglob("*.py")}
    assert units <= set(STAGE), f"add to STAGES: {sorted(units - set(STAGE))}"


def test_nothing_imports_from_a_later_stage():
    upward = []
    for path in sorted(PACKAGE.rglob("*.py")):
        unit = _unit(path)
        for imported in _imported_units(path) - {unit}:
            if STAGE.get(imported, -1) > STAGE[unit]:
                upward.append(f"{path.relative_to(PACKAGE)} imports {imported}")
    assert not upward, upward
