"""The distance rows: their Jacobian and bias against finite differences of the distance, their
activation, and the closed loop: a task pulling the tool through an obstacle stops at the minimum."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import yaml

from dcts_spec.analysis.plots import write_plots
from dcts_spec.analysis.run import analyze
from dcts_spec.limits.collision import INACTIVE, collision_rows, distance_function
from dcts_spec.robot.collision import resolve_collision
from dcts_spec.robot.resolve import resolve_robot
from dcts_spec.sim.runner import prepare_simulation
from dcts_spec.spec import load_spec_text
from dcts_spec.symbolic import SymbolicRobot

OBSTACLES = {
    "ball": {"type": "sphere", "center": [0.5, 0.2, 0.6], "radius": 0.1},
    "post": {"type": "capsule", "start": [0.3, -0.4, 0.0], "end": [0.35, -0.3, 0.9], "radius": 0.05},
    "crate": {"type": "box", "center": [-0.4, 0.3, 0.3], "size": [0.3, 0.2, 0.4], "rpy": [0.1, 0.2, 0.7]},
    "floor": {"type": "plane", "normal": [0, 0.1, 1], "point": [0, 0, 0.05]},
}


def _spec(collision: dict, extra: str = "") -> str:
    return yaml.safe_dump({"version": 1, "name": "c", "robot": {"model": "iiwa14"}, "limits": {"collision": collision},
                           "tasks": [{"name": "d", "type": "joint", "priority": 1, "gains": {"kp": 0, "kd": 1}}]})


@pytest.fixture(scope="module")
def rows_case():
    spec = load_spec_text(_spec({"obstacles": OBSTACLES, "activation_distance": 5.0}))
    robot = resolve_robot(spec)[0]
    model, _ = resolve_collision(spec, robot)
    sym = SymbolicRobot(robot.model)
    rows = collision_rows(model, sym, 0.001)
    f = ca.Function("rows", [sym.q, sym.dq], [rows.matrix, rows.offset, rows.lower])
    return robot, model, f, distance_function(model, sym)


def test_every_kind_of_pair_is_there(rows_case) -> None:
    _, model, _, _ = rows_case
    kinds = {(s.kind, t.kind) for p in model.pairs for s in p.a.shapes for t in p.b.shapes}
    assert kinds == {("capsule", k) for k in ("capsule", "sphere", "box", "plane")}


def test_jacobian_is_the_distance_derivative(rows_case) -> None:
    """J_d q̇ is the rate of the distance: central differences along random directions."""
    robot, model, f, distance = rows_case
    rng = np.random.default_rng(3)
    checked = 0
    for _ in range(25):
        q = rng.uniform(robot.limits.q_min + 0.1, robot.limits.q_max - 0.1)
        v = rng.normal(size=robot.nv)
        J = np.asarray(f(q, v)[0])
        h = 1e-6
        rate = (np.asarray(distance(q + h * v)) - np.asarray(distance(q - h * v))).ravel() / (2 * h)
        d = np.asarray(distance(q)).ravel()
        away = d > 0.01  # overlapping cores have no derivative worth checking
        np.testing.assert_allclose((J @ v)[away], rate[away], atol=1e-5 * max(1.0, np.abs(rate).max()))
        checked += int(away.sum())
    assert checked > 25 * len(model.pairs) // 2


def test_bias_is_the_distance_acceleration_against_a_plane(rows_case) -> None:
    """For a link against a plane the normal does not turn: d̈ = J_d a + J̇_d q̇ exactly."""
    robot, model, f, distance = rows_case
    planes = [i for i, p in enumerate(model.pairs) if p.b.name == "floor"]
    rng = np.random.default_rng(4)
    for _ in range(10):
        q = rng.uniform(robot.limits.q_min + 0.1, robot.limits.q_max - 0.1)
        v, a = rng.normal(size=robot.nv), rng.normal(size=robot.nv)
        J, bias, _ = (np.asarray(x) for x in f(q, v))
        h = 1e-4
        at = lambda t: np.asarray(distance(q + v * t + 0.5 * a * t * t)).ravel()  # noqa: E731
        second = (at(h) - 2 * at(0) + at(-h)) / h**2
        np.testing.assert_allclose((J @ a + bias.ravel())[planes], second[planes], atol=2e-3 * max(1, np.abs(second).max()))


def test_far_pairs_are_inactive_and_near_ones_bind() -> None:
    spec = load_spec_text(_spec({"watch": "listed", "obstacles": {"ball": OBSTACLES["ball"]},
                                 "pairs": [{"between": ["link7", "ball"]}], "activation_distance": 0.2}))
    robot = resolve_robot(spec)[0]
    model, _ = resolve_collision(spec, robot)
    sym = SymbolicRobot(robot.model)
    rows = collision_rows(model, sym, 0.001)
    f = ca.Function("rows", [sym.q, sym.dq], [rows.lower, rows.excess])
    distance = distance_function(model, sym)
    rng = np.random.default_rng(5)
    seen = set()
    for _ in range(300):
        q = rng.uniform(robot.limits.q_min, robot.limits.q_max)
        d = float(distance(q))
        lower, excess = (float(x) for x in f(q, np.zeros(robot.nv)))
        assert excess == pytest.approx(max(0.02 - d, 0.0))
        if d > 0.2:
            assert lower == INACTIVE
            seen.add("far")
        elif d > 0.02:
            assert INACTIVE < lower < 0  # at rest: it may brake toward the ball, not arbitrarily
            seen.add("near")
    assert seen == {"far", "near"}


THROUGH = """
version: 1
name: through_ball
robot: {model: iiwa14}
limits:
  joint_torque: {max: 300, allow_outside_urdf: true}
  collision:
    self_collision: false
    obstacles:
      ball: {type: sphere, center: [0.55, 0.0, 0.42], radius: 0.07}
tasks:
  - {name: reach, type: position, frame: tool, priority: 1, gains: {kp: 60, kd: 16}, reference: {position: [0.42, 0.0, 0.25]}}
  - {name: damping, type: joint, priority: 2, gains: {kp: 0, kd: 5}}
scenario: {duration: 1.0, initial_q: [0, 30, 0, -60, 0, 60, 0], unit: deg}
"""


@pytest.mark.parametrize("formulation", ["dcts", pytest.param("osc", marks=pytest.mark.slow)])
def test_a_task_pulling_the_tool_through_a_ball_stops_at_the_minimum_distance(formulation, tmp_path) -> None:
    """The target is beyond the ball: dcts stops the wrist at 2 cm with status ok; OSC, which
    keeps no bound, runs into it (the ball is a MuJoCo contact: it cannot go through, but comes
    closer than its minimum, and summary.json says so)."""
    sim = prepare_simulation(load_spec_text(THROUGH), "python", formulation)
    log = sim.run()
    run = analyze(sim, log)
    model = run.collision
    distances = np.asarray(distance_function(model, SymbolicRobot(sim.robot.model)).map(len(log.q))(log.q.T))
    np.testing.assert_allclose(run.distances, distances.T)
    wrist = next(p.name for p in model.pairs if p.a.name == "link7")
    summary = run.summary
    assert summary["min_distances"] == pytest.approx({p.name: d for p, d in zip(model.pairs, distances.min(axis=1))})
    write_plots(run, tmp_path)
    assert (tmp_path / "collision_distances.png").stat().st_size > 10_000
    if formulation == "osc":
        violation = summary["collision_violations"][wrist]
        assert violation["by"] > 0.015 and violation["steps"] > 10 and summary["max_collision_violation"] >= violation["by"]
        return
    assert (log.status == 0).all()
    assert distances.min() >= 0.02 - 1e-5
    assert summary["min_distances"][wrist] < 0.021  # it did get there
    assert summary["collision_violations"] == {} and summary["max_collision_violation"] == 0.0
    assert summary["solver_failures"] == 0
