"""The golden test's second look (codegen.bundle.recheck_golden): a vector the C misses is measured
again with more samples, and only a vector whose own answer rounding moves is compared less."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import dcts_spec
from dcts_spec.codegen import bundle, compile_bundle
from dcts_spec.codegen.states import golden_states
from dcts_spec.controller import Controller

MINIMAL = Path(__file__).resolve().parent.parent / "specs" / "minimal.yaml"
VECTOR = 5  # the vector made to mismatch
GOLDEN_COUNT = 30  # (fewer than a bundle has: the test is about one vector)


def _tampered_solution():
    """compute_golden with VECTOR's QP solution moved off the Python runtime's answer, so the C
    test fails there."""
    real = bundle.compute_golden

    def compute(controller, states):
        golden = real(controller, states)
        golden.x[VECTOR, 0] += 1.0
        return golden

    return compute


def test_a_vector_whose_answer_rounding_moves_is_compared_less_on_a_second_look(tmp_path, monkeypatch):
    """The C misses VECTOR's QP solution; measured again, that solution moves with rounding (made
    so here: the spread of RECHECK_SAMPLES samples is infinite for it) and the torques do not: the
    test then compares its torques only, passes, and the manifest and a note say so."""
    monkeypatch.setattr(bundle, "compute_golden", _tampered_solution())
    spread = Controller.answer_spread

    def second_look(self, q, dq, tau_ext, ref, x, samples, enough, relaxed=False):
        measured = spread(self, q, dq, tau_ext, ref, x, samples, enough, relaxed)
        return np.array([measured[0], np.inf]) if samples == bundle.RECHECK_SAMPLES else measured

    monkeypatch.setattr(Controller, "answer_spread", second_look)
    report = compile_bundle(MINIMAL, tmp_path / "bundle", golden_count=GOLDEN_COUNT)
    golden = report.manifest["golden"]
    assert golden["undetermined_on_a_second_look"] == [VECTOR] and VECTOR in golden["compared_on_command"]
    assert any(f"golden vectors [{VECTOR}]" in note for note in report.notes), report.notes
    assert "1 compared on tau and ddq only" in report.manifest["host"]["test_summary"]


def test_a_determined_vector_or_one_the_replay_does_not_give_stays_compared():
    """recheck_golden on vectors whose answers rounding does not move, and on one whose stored
    torques the Python runtime's replay does not give (a mismatch that is not the C's choice
    among answers): nothing is compared less, so the build's GoldenMismatch stands."""
    controller = dcts_spec.build_controller(MINIMAL)
    golden = bundle.compute_golden(controller, golden_states(controller, GOLDEN_COUNT))
    golden.tau[VECTOR, 0] += 1.0
    before = golden.compared.copy()
    assert bundle.recheck_golden(controller, golden, [3, VECTOR, 7]) == []
    assert np.array_equal(golden.compared, before)
