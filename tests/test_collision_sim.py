"""The collision primitives in MuJoCo: visible geoms that collide in the watched pairs only, and
whose distances, by MuJoCo's own collision code, are the controller's."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import yaml

from dcts_spec.limits.collision import distance_function
from dcts_spec.robot.collision import resolve_collision
from dcts_spec.robot.resolve import resolve_robot
from dcts_spec.sim.mujoco_model import build_mujoco_model
from dcts_spec.spec import load_spec_text
from dcts_spec.symbolic import SymbolicRobot

OBSTACLES = {
    "ball": {"type": "sphere", "center": [0.45, -0.25, 0.55], "radius": 0.1},
    "post": {"type": "capsule", "start": [-0.35, 0.3, 0.0], "end": [-0.3, 0.35, 0.9], "radius": 0.05},
    "crate": {"type": "box", "center": [0.3, 0.4, 0.25], "size": [0.3, 0.2, 0.4], "rpy": [0, 0, 30], "unit": "deg"},
    "wall": {"type": "plane", "normal": [-1, 0, 0], "point": [0.8, 0, 0]},
}


@pytest.fixture(scope="module", params=["iiwa14", "panda"])
def case(request):
    text = yaml.safe_dump({"version": 1, "name": "c", "robot": {"model": request.param},
                           "limits": {"collision": {"obstacles": OBSTACLES}},
                           "tasks": [{"name": "d", "type": "joint", "priority": 1, "gains": {"kp": 0, "kd": 1}}]})
    spec = load_spec_text(text)
    robot = resolve_robot(spec)[0]
    model, _ = resolve_collision(spec, robot)
    return robot, model, build_mujoco_model(robot.model, collision=model)


def _geoms(mj: mujoco.MjModel, body: str) -> list[int]:
    return [g for g in range(mj.ngeom) if mj.geom(g).name.startswith(f"collision_{body}_")]


def test_geoms_are_visible_and_collide_in_the_watched_pairs_only(case) -> None:
    robot, model, mj = case
    owner = {}
    for body in (*model.links, *model.obstacles):
        geoms = _geoms(mj, body.name)
        assert len(geoms) == len(body.shapes)
        assert all(mj.geom_rgba[g][3] > 0 and mj.geom_contype[g] == 0 and mj.geom_conaffinity[g] == 0 for g in geoms)
        owner |= {g: body.name for g in geoms}
    pairs = [frozenset((owner[int(a)], owner[int(b)])) for a, b in zip(mj.pair_geom1, mj.pair_geom2, strict=True)]
    assert sorted(pairs, key=sorted) == sorted((frozenset((p.a.name, p.b.name)) for p in model.pairs
                                                for _ in range(len(p.a.shapes) * len(p.b.shapes))), key=sorted)


def test_mujoco_measures_the_same_distances(case) -> None:
    """MuJoCo's own narrow phase (mj_geomDistance) on random configurations: an independent
    implementation of every pair kind, the box and the plane included."""
    robot, model, mj = case
    data = mujoco.MjData(mj)
    ours = distance_function(model, SymbolicRobot(robot.model))
    rng = np.random.default_rng(11)
    compared = 0
    for _ in range(20):
        q = rng.uniform(robot.limits.q_min, robot.limits.q_max)
        data.qpos[:] = q
        mujoco.mj_kinematics(mj, data)
        d = np.asarray(ours(q)).ravel()
        for k, pair in enumerate(model.pairs):
            theirs = min(mujoco.mj_geomDistance(mj, data, a, b, 10.0, None)
                         for a in _geoms(mj, pair.a.name) for b in _geoms(mj, pair.b.name))
            if d[k] > 1e-3:  # penetration depths differ by definition (see symbolic/distance.py)
                assert theirs == pytest.approx(d[k], abs=2e-5), pair.name
                compared += 1
            else:
                assert theirs <= max(d[k], 0.0) + 2e-5
    assert compared > 10 * len(model.pairs)


def test_a_pair_reads_as_its_bound_in_the_run_summary(case) -> None:
    """A crossed distance row is named in words in summary.json's relaxed_bounds, as the joint and
    Cartesian bounds are (limits/naming.row_text)."""
    from dcts_spec.limits.naming import row_text

    robot, model, _ = case
    pair = model.pairs[0]
    assert row_text(robot, pair.name, model) == f"distance({pair.a.name}, {pair.b.name}) ≥ {pair.min_distance:.4g} m"
    assert row_text(robot, pair.name) == pair.name  # without the collision model: the row's name
