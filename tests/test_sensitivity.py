"""Is a lexicographic answer determined by its QP data (solve/sensitivity.py)?"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from dcts_spec.codegen import compile_bundle
from dcts_spec.codegen.bundle import GOLDEN_TOLERANCES, SPREAD_FRACTION
from dcts_spec.robot.builtin import example_robot_data_dir
from dcts_spec.solve import solve_lexicographic
from dcts_spec.solve import sensitivity
from dcts_spec.solve.sensitivity import rounding_spread
from saved_qp import saved_acceleration_map, saved_qp


def _identity(x: np.ndarray) -> tuple[np.ndarray]:
    return (x,)


def test_an_answer_its_data_do_not_determine_is_told_from_one_they_do():
    """QP data of a golden state of a 27-joint Alex with hands (5 levels; first tried from
    outside): joint bounds relaxed, then levels bent on the thin feasible sets the relaxation and
    the bends leave. DAQP solves a stage or calls it infeasible depending on the last bits of the
    data, and changes of 1e-14 relative move the answer by 8 % of its size (by more than its size
    before the rows a scaled level's certificate holds active were held: `Cascade._hold_face`). The two states
    this test had before (a G1 with 29 joints, then one with 24) became determined: the first once
    a stage DAQP fails at its step went on at a larger one, the second once a stage DAQP fails
    after a relaxation was tried again with its rows widened. A state where a stage ran long
    (stalled_scale_stage) moves by ~1e-10 at most."""
    args, structure = saved_qp("undetermined_after_relaxation")
    x = solve_lexicographic(*args, structure)
    assert rounding_spread(*args, structure, x, _identity, samples=12, enough=np.inf)[0] > 0.01

    args, structure = saved_qp("stalled_scale_stage")
    x = solve_lexicographic(*args, structure)
    assert rounding_spread(*args, structure, x, _identity, samples=12, enough=np.inf)[0] < 1e-8


def test_the_spread_stops_at_enough_and_needs_changed_data(monkeypatch):
    """It stops sampling once a change exceeds `enough`; and it is the data's changes that move the
    answer: with ROUNDING 0 the same data give the same answer (the solve is deterministic)."""
    args, structure = saved_qp("undetermined_after_relaxation")
    x = solve_lexicographic(*args, structure)
    solves = []
    original = sensitivity.solve_lexicographic
    monkeypatch.setattr(sensitivity, "solve_lexicographic", lambda *a: solves.append(1) or original(*a))
    assert rounding_spread(*args, structure, x, _identity, samples=12, enough=1e-3)[0] > 1e-3
    assert len(solves) < 12
    monkeypatch.setattr(sensitivity, "ROUNDING", 0.0)
    assert rounding_spread(*args, structure, x, _identity, samples=3, enough=np.inf)[0] == 0.0


def test_each_group_of_outputs_has_its_own_spread_and_sampling_goes_on_while_one_is_small(monkeypatch):
    """A group the answer does not move keeps spread 0 while another's is large, and sampling stops
    early only once every group is above `enough` (the golden test compares the torques of a vector
    whose QP solution alone is undetermined)."""
    args, structure = saved_qp("undetermined_after_relaxation")
    x = solve_lexicographic(*args, structure)
    solves = []
    original = sensitivity.solve_lexicographic
    monkeypatch.setattr(sensitivity, "solve_lexicographic", lambda *a: solves.append(1) or original(*a))
    spread = rounding_spread(*args, structure, x, lambda a: (a, np.zeros(2)), samples=12, enough=1e-3)
    assert spread[0] > 1e-3 and spread[1] == 0.0 and len(solves) == 12


def _answers() -> list[sensitivity.AnswerData]:
    """Two saved states' answers, one its data determine and one they do not, with command maps
    (τ₀ = 0, T = I; q̈₀ = 0, Q = 2 I)."""
    answers = []
    for name in ("undetermined_after_relaxation", "stalled_scale_stage"):
        args, structure = saved_qp(name)
        x = solve_lexicographic(*args, structure)
        n = x.size
        answers.append(sensitivity.AnswerData(tuple(args), structure, x, np.zeros(n), np.eye(n), np.zeros(n), 2.0 * np.eye(n),
                                              np.zeros(len(structure.bound_rows))))
    return answers


def test_spreads_measured_in_worker_processes_are_those_measured_here(monkeypatch):
    """`spreads` shares the answers out among worker processes (the golden vectors' spreads at 29
    joints): the same numbers, in the answers' order, as measuring each in this process; a worker
    that cannot start leaves its answers to this process."""
    answers = _answers()
    here = sensitivity.spreads(answers, 4, [1e-3, 1e-3], workers=1)
    assert here[0][1] > 1e-3 and here[1][1] < 1e-8  # (the two kinds: an order swapped would show)
    started = []
    run = sensitivity.run_workers
    monkeypatch.setattr(sensitivity, "run_workers", lambda shares: started.append(len(shares)) or run(shares))
    assert all(np.array_equal(a, b) for a, b in zip(sensitivity.spreads(answers, 4, [1e-3, 1e-3], workers=2), here))
    assert started == [2]
    monkeypatch.setattr(sensitivity.sys, "executable", "/nonexistent/python")
    assert all(np.array_equal(a, b) for a, b in zip(sensitivity.spreads(answers, 4, [1e-3, 1e-3], workers=2), here))


def test_an_answer_after_a_relaxation_is_measured_at_the_stages_precision():
    """HyQ's legs at twice their URDF torques (found from outside: `dcts compile` refused the spec).
    At a relaxed golden vector the C's torques were 2.3e-3 relative from the Python's, beyond the
    relaxed tolerance (1e-3), both answers feasible: after the relaxation the bend runs on a sliver
    whose rows the stages above hold at their own answers, and the C's sat up to 5e-9 relative from
    the Python's. Rounding-size changes of the data (ROUNDING) do not show that the answer is not
    determined; changes at RELAXED_ROUNDING, which the golden vectors' relaxed answers are now
    measured at, do (by more than the SPREAD_FRACTION of the relaxed tolerance a determined answer
    may have)."""
    args, structure = saved_qp("relaxed_bend_on_a_sliver")
    Q = saved_acceleration_map("relaxed_bend_on_a_sliver")
    data = np.load(Path(__file__).parent / "data" / "relaxed_bend_on_a_sliver.npz")
    x = solve_lexicographic(*args, structure, Q)
    torques = lambda a: (data["tau0"].ravel() + data["T"] @ a,)  # noqa: E731
    limit = SPREAD_FRACTION * GOLDEN_TOLERANCES["dcts"][1]
    at_rounding = rounding_spread(*args, structure, x, torques, 12, np.inf, acceleration_map=Q)[0]
    at_stages = rounding_spread(*args, structure, x, torques, 12, np.inf, acceleration_map=Q,
                                rounding=sensitivity.RELAXED_ROUNDING)[0]
    assert at_rounding <= limit < at_stages, (at_rounding, at_stages)


HOME = "[-0.392699, 0.174533, -1.39626, -0.392699, -0.174533, 1.39626, -0.392699, 0.174533, -1.39626, -0.392699, -0.174533, 1.39626]"
FOOT = "{{name: {leg}_foot, type: position, frame: {leg}_foot, priority: 1, gains: {{kp: 100, kd: 20}}, reference: {{position: [{x}, {y}, -0.501688]}}}}"
HYQ_TWICE_ITS_TORQUES = f"""version: 1
name: hyq_2x
robot:
  urdf: {example_robot_data_dir() / "hyq_description" / "robots" / "hyq_no_sensors.urdf"}
limits:
  joint_torque: {{max: [{", ".join(["300"] * 12)}], allow_outside_urdf: true}}
controller: {{formulation: dcts}}
tasks:
""" + "".join(f"  - {FOOT.format(leg=leg, x=x, y=y)}\n" for leg, x, y in (
    ("lf", 0.637856, 0.414806), ("rf", 0.637856, -0.414806), ("lh", -0.637856, 0.414806), ("rh", -0.637856, -0.414806))) + f"""\
  - {{name: posture, type: joint, priority: 2, gains: {{kp: 10, kd: 6}}, reference: {{q: {HOME}}}}}
"""


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("DCTS_SLOW"), reason="builds a C bundle (~20 s): set DCTS_SLOW=1 to run it")
def test_hyq_at_twice_its_torques_compiles(tmp_path):
    """The spec `dcts compile` refused (the default tier's instance is the test above, on its QP):
    its golden test passes, vector 46 among those its data do not determine."""
    spec = tmp_path / "hyq_2x.yaml"
    spec.write_text(HYQ_TWICE_ITS_TORQUES)
    golden = compile_bundle(spec, tmp_path / "bundle", qemu=False).manifest["golden"]
    assert 46 in golden["undetermined"], golden
