"""`dcts validate --check` counts each formulation's QP-data operations without common-subexpression
elimination (CSE: what made it take 44 s at 28 joints); the count is the compiled function's
within a few percent, never below it."""

from __future__ import annotations

import os

import pytest

from command_line import MINIMAL, ROOT
from dcts_spec.controller import Controller, compile_check
from dcts_spec.formulations import FORMULATIONS
from dcts_spec.validate import validate_file

SPECS = [MINIMAL, ROOT / "specs" / "bench_iiwa14.yaml"]


@pytest.mark.parametrize("spec", SPECS, ids=lambda p: p.stem)
def test_check_counts_match_the_compiled_function(spec) -> None:
    report = validate_file(spec)
    checked = compile_check(report)
    assert list(checked) == list(FORMULATIONS)
    for name, info in checked.items():
        controller = Controller(report.spec, report.robot, name)  # what `dcts compile` builds
        compiled = controller.data.n_instructions()
        assert info["ok"] and info["variables"] == controller.nx and info["constraints"] == controller.na, name
        assert compiled <= info["instructions"] <= 1.1 * compiled, (name, compiled, info["instructions"])
        assert info["summary"].endswith(f"{info['instructions']} operations for the QP data (before CSE)") or \
            "(before CSE) (" in info["summary"], info["summary"]
        assert "refuses" not in info["summary"]


def test_check_says_which_formulations_no_bundle_takes(monkeypatch) -> None:
    """A law beyond controller.MAX_QP_DATA_OPERATIONS was listed with its count as any other, and
    `dcts compile` then refused it (the projector at 23 joints, found from outside)."""
    import dcts_spec.controller as controller_module

    report = validate_file(MINIMAL)
    counts = {name: info["instructions"] for name, info in compile_check(report).items()}
    limit = sorted(counts.values())[len(counts) // 2]
    monkeypatch.setattr(controller_module, "MAX_QP_DATA_OPERATIONS", limit)
    for name, info in compile_check(report).items():
        refused = "more than the {:,} a C bundle takes: `dcts compile` refuses it".format(limit) in info["summary"]
        assert info["ok"] and refused == (counts[name] > limit), (name, counts[name], info["summary"])
    # a law LOOPING_GAIN_AT_MOST times beyond it unrolled is not built again looped to be counted
    monkeypatch.setattr(controller_module, "LOOPED_PRODUCTS_FROM", 1)
    monkeypatch.setattr(controller_module, "MAX_QP_DATA_OPERATIONS", min(counts.values()) // 5)
    for name, info in compile_check(report).items():
        assert not info["looped_products"] and info["instructions"] == counts[name], name
        assert "takes, looped or not (counted unrolled): `dcts compile` refuses it" in info["summary"], info["summary"]


@pytest.mark.skipif(not os.environ.get("DCTS_SLOW"), reason="28-joint TALOS from example-robot-data (~15 s): "
                    "set DCTS_SLOW=1 to run it")
def test_check_of_28_joints_builds_every_formulation(tmp_path) -> None:
    """(How long it takes is measured by scripts/bench_sizes.py, its `validate --check` column.)"""
    import sys

    sys.path.insert(0, str(ROOT / "scripts"))
    from bench_sizes import MODELS, model_spec

    spec = tmp_path / "talos28.yaml"
    spec.write_text(model_spec(next(m for m in MODELS if m.key == "talos28")))
    checked = compile_check(validate_file(spec))
    assert list(checked) == list(FORMULATIONS)
    assert all(info["ok"] for info in checked.values()), checked
