"""The `limits.collision` section: default primitives covering the built-in robots, the pairs
watched, located errors, and what validate reports (initial distances, pair count and cost)."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
import yaml

from command_line import dcts
from dcts_spec.robot.builtin import builtin_urdf_path, example_robot_data_dir
from dcts_spec.robot.collision import resolve_collision
from dcts_spec.robot.collision_defaults import default_primitives
from dcts_spec.robot.resolve import resolve_robot
from dcts_spec.spec import SpecError, load_spec_text
from dcts_spec.spec.errors import format_path
from dcts_spec.validate import validate_spec

coal = pytest.importorskip("coal")


def _spec(collision: dict, robot: str = "iiwa14", initial_q: list | None = None) -> str:
    scenario = {"duration": 1.0, **({"initial_q": initial_q, "unit": "deg"} if initial_q else {})}
    return yaml.safe_dump({
        "version": 1, "name": "c", "robot": {"model": robot}, "limits": {"collision": collision},
        "tasks": [{"name": "d", "type": "joint", "priority": 1, "gains": {"kp": 0, "kd": 1}}],
        "scenario": scenario}, sort_keys=False)


def _pairs(collision: dict, robot: str = "iiwa14") -> dict[str, tuple[float, float]]:
    spec = load_spec_text(_spec(collision, robot))
    model, diags = resolve_collision(spec, resolve_robot(spec)[0])
    assert not [d for d in diags if d.severity == "error"], diags
    return {p.name.removeprefix("collision:"): (p.min_distance, p.braking) for p in model.pairs}


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = b - a
    t = np.clip((points - a) @ d / (d @ d), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * d), axis=1)


def _link_points(robot: str) -> dict[str, np.ndarray]:
    """Points of each link's URDF collision geometry in the link's frame: mesh vertices, box
    corners, and dense samples of a cylinder's rims."""
    path = builtin_urdf_path(robot)
    model = pin.buildModelFromUrdf(str(path))
    geometry = pin.buildGeomFromUrdf(model, str(path), pin.COLLISION, package_dirs=[str(example_robot_data_dir().parents[1])])
    out: dict[str, list[np.ndarray]] = {}
    for obj in geometry.geometryObjects:
        shape = obj.geometry
        if isinstance(shape, coal.Cylinder):
            angle = np.linspace(0, 2 * np.pi, 72, endpoint=False)
            rim = np.stack([shape.radius * np.cos(angle), shape.radius * np.sin(angle), np.zeros_like(angle)], axis=1)
            local = np.vstack([rim + [0, 0, z] for z in np.linspace(-shape.halfLength, shape.halfLength, 9)])
        elif isinstance(shape, coal.Box):
            local = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * shape.halfSide
        else:
            local = np.asarray(shape.vertices())
        frame = model.frames[obj.parentFrame]
        in_joint = local @ obj.placement.rotation.T + obj.placement.translation
        out.setdefault(frame.name, []).append((in_joint - frame.placement.translation) @ frame.placement.rotation)
    return {link: np.vstack(points) for link, points in out.items()}


@pytest.mark.parametrize("robot", ["iiwa14", "panda"])
def test_default_primitives_cover_every_link(robot) -> None:
    points = _link_points(robot)
    primitives = default_primitives(robot)
    assert set(points) == set(primitives), "every link with collision geometry has primitives, and only those"
    for link, capsules in primitives.items():
        outside = np.min([_segment_distance(points[link], np.array(c.start), np.array(c.end)) - c.radius
                          for c in capsules], axis=0)
        assert outside.max() <= 1e-9, f"{link}: a point of its geometry is {outside.max():.4f} m outside its capsules"


def test_all_non_adjacent_pairs_minus_the_exclusions() -> None:
    pairs = _pairs({})
    links = ["base", *[f"link{i}" for i in range(1, 8)]]
    expected = {f"{a}-{b}" for i, a in enumerate(links) for b in links[i + 2:]} - {"link5-link7"}  # the default exclusion
    assert set(pairs) == expected
    assert set(_pairs({"exclude": [["link1", "link3"], ["link6", "base"]]})) == expected - {"link1-link3", "base-link6"}
    # a default exclusion listed in `pairs` is watched, with its own minimum
    assert _pairs({"pairs": [{"between": ["link7", "link5"], "min_distance": 0.001}]})["link7-link5"][0] == 0.001


def test_obstacles_pairs_and_their_settings() -> None:
    collision = {"self_collision": False, "min_distance": 0.03, "max_acceleration": 4.0,
                 "obstacles": {"ball": {"type": "sphere", "center": [0.5, 0, 0.5], "radius": 0.1}},
                 "pairs": [{"between": ["ball", "link7"], "min_distance": 0.05, "max_acceleration": 2.0}]}
    pairs = _pairs(collision)
    # the base is fixed in the world: its distance to an obstacle cannot change
    assert set(pairs) == {f"link{i}-ball" for i in range(1, 8)}
    assert pairs["link6-ball"] == (0.03, 4.0) and pairs["link7-ball"] == (0.05, 2.0)
    listed = _pairs({"watch": "listed", "default_primitives": False,
                     "links": {"panda_hand": [{"type": "sphere", "center": [0, 0, 0.05], "radius": 0.06}]},
                     "obstacles": {"table": {"type": "box", "center": [0.5, 0, 0.1], "size": [0.4, 0.6, 0.2]}},
                     "pairs": [{"between": ["panda_hand", "table"]}]}, robot="panda")
    assert listed == {"panda_hand-table": (0.02, 5.0)}


BAD = [
    ({"links": {"lnk7": []}}, "links.lnk7", "no link or frame 'lnk7' (did you mean 'link7'"),
    ({"obstacles": {"tool": {"type": "sphere", "radius": 0.1}}}, "obstacles.tool", "the robot has a frame named 'tool'"),
    ({"exclude": [["link1", "lnk3"]]}, "exclude[0]", "'lnk3' is neither a link with primitives nor an obstacle"),
    ({"pairs": [{"between": ["link2", "link2"]}]}, "pairs[0].between", "two different bodies"),
    ({"pairs": [{"between": ["tool", "link2"]}]}, "pairs[0].between", "'tool' has no primitives"),
    ({"obstacles": {"a": {"type": "sphere", "radius": 0.1}, "b": {"type": "plane", "normal": [0, 0, 1]}},
      "pairs": [{"between": ["a", "b"]}]}, "pairs[0].between", "both fixed in the world"),
    ({"exclude": [["link1", "link3"]], "pairs": [{"between": ["link3", "link1"]}]}, "pairs[0].between", "also in `exclude`"),
    # (the later, looser minimum replaced the first, unseen)
    ({"pairs": [{"between": ["link1", "link3"], "min_distance": 0.05}, {"between": ["link3", "link1"], "min_distance": 0.01}]},
     "pairs[1].between", "already a pair at pairs[0]"),
    ({"pairs": [{"between": ["link1", "link3"], "min_distance": 0.2}]}, "pairs[0].min_distance",
     "must be below the activation_distance (0.15 m)"),
    ({"links": {"link7": [{"type": "capsule", "start": [0, 0, 0.1], "end": [0, 0, 0.1], "radius": 0.05}]}},
     "links.link7[0].end", "a capsule needs an axis"),
    ({"obstacles": {"p": {"type": "plane", "normal": [0, 0, 0]}}}, "obstacles.p.normal", "must not be zero"),
    ({"obstacles": {"p": {"type": "cylinder", "radius": 0.1}}}, "obstacles.p", "unknown type 'cylinder'"),
    ({"min_distance": 0.2, "activation_distance": 0.1}, "activation_distance", "must exceed min_distance"),
    ({"min_distance": 0.2}, "collision", "must exceed min_distance"),  # at the section: the default is not written
    ({"watch": "listed", "pairs": []}, "pairs", "watch: listed needs at least one entry"),
]


@pytest.mark.parametrize(("collision", "key", "message"), BAD, ids=[b[1] + ":" + b[2][:20] for b in BAD])
def test_located_errors(collision, key, message) -> None:
    text = _spec(collision)
    with pytest.raises(SpecError) as caught:
        validate_spec(load_spec_text(text, "c.yaml"))
    found = [d for d in caught.value.errors if message in d.message]
    assert found, [str(d) for d in caught.value.errors]
    assert format_path(found[0].path).endswith(key) and found[0].line is not None, str(found[0])


def test_a_pair_closer_than_its_minimum_at_the_start_is_an_error_with_its_distance() -> None:
    q0 = [0, 30, 0, -60, 0, 60, 0]  # the elbow (link4, link5) at z = 0.724, just under the ball
    ball = {"type": "sphere", "center": [0.5, 0.0, 0.85], "radius": 0.05}
    with pytest.raises(SpecError) as caught:
        validate_spec(load_spec_text(_spec({"obstacles": {"ball": ball}}, initial_q=q0), "c.yaml"))
    errors = [d for d in caught.value.errors if "at the initial configuration" in d.message]
    assert errors and all(format_path(d.path) == "limits.collision.obstacles.ball" for d in errors)
    spec = load_spec_text(_spec({"obstacles": {"ball": ball}}, initial_q=q0))
    robot = resolve_robot(spec)[0]
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, np.radians(q0))
    # link5's capsule runs from its origin along its z axis: the exact distance, in the message
    origin, rotation = data.oMf[robot.model.getFrameId("link5")].translation, data.oMf[robot.model.getFrameId("link5")].rotation
    d = _segment_distance(np.array([ball["center"]]), origin, origin + rotation @ [0, 0, 0.2155])[0] - 0.06 - 0.05
    assert any(f"link5 and ball {'overlap by' if d < 0 else 'are'} {abs(d):.4g} m" in e.message for e in errors), \
        [e.message for e in errors]


def test_validate_reports_pairs_and_their_cost(tmp_path) -> None:
    path = tmp_path / "c.yaml"
    path.write_text(_spec({"obstacles": {"floor": {"type": "plane", "normal": [0, 0, 1]}}}, initial_q=[0, 30, 0, -60, 0, 60, 0]))
    result = dcts("validate", "--json", str(path))
    assert result.returncode == 0, result.stdout + result.stderr
    (report,) = json.loads(result.stdout)
    collision = report["collision"]
    assert collision["pairs"] == 20 + 7  # 20 link pairs, 7 moving links against the floor
    assert collision["operations"] > 100 * collision["pairs"]
    assert collision["initial_distances"]["collision:link4-floor"] == pytest.approx(0.724 - 0.06, abs=2e-3)
    human = dcts("validate", str(path)).stdout
    assert f"collision   27 pairs watched, their rows {collision['operations']} operations" in human


def test_a_position_target_an_obstacle_keeps_out_is_a_warning_at_the_target() -> None:
    """A task whose target puts its frame inside an obstacle (or nearer than a watched pair's
    minimum) coasts at that bound with its scaling at 0, as at a Cartesian bound the target is
    beyond: validate says so at the target (found from outside: a Panda's hand aimed at a ball's
    centre, its level-1 scaling below 0.05 in 2,650 of 3,000 steps, the arm never at rest)."""
    ball = {"type": "sphere", "center": [0.5, 0.0, 0.4], "radius": 0.05}

    def warnings(target: list[float]) -> list:
        data = yaml.safe_load(_spec({"obstacles": {"ball": ball}}, initial_q=[0, 30, 0, -60, 0, 60, 0]))
        data["tasks"].insert(0, {"name": "reach", "type": "position", "frame": "link7", "priority": 1,
                                 "gains": {"kp": 100, "kd": 20}, "reference": {"position": target}})
        data["tasks"][1]["priority"] = 2
        report = validate_spec(load_spec_text(yaml.safe_dump(data, sort_keys=False), "c.yaml"))
        return [d for d in report.diagnostics if "limits.collision" in d.message]

    (inside,) = warnings([0.5, 0.0, 0.4])
    assert inside.severity == "warning" and format_path(inside.path) == "tasks[0].reference.position"
    assert "puts link7 inside ball, where link7 keeps 0.02 m from it" in inside.message
    (near,) = warnings([0.5, 0.0, 0.46])  # (0.01 m from the ball's surface)
    assert "puts link7 0.01 m from ball" in near.message
    assert not warnings([0.5, 0.0, 0.7])


@pytest.mark.parametrize("self_collision", [False, True])
def test_shapes_on_a_link_fixed_to_the_world_that_no_pair_watches_are_a_warning(self_collision) -> None:
    """Primitives on the world-fixed base pair only with the robot's own links (self_collision):
    against an obstacle neither moves, and they were accepted and never watched without a word
    (found from outside)."""
    section = {"links": {"base": [{"type": "sphere", "radius": 0.1}]}, "self_collision": self_collision,
               "obstacles": {"ball": {"type": "sphere", "center": [0.5, 0.0, 0.85], "radius": 0.05}}}
    spec = load_spec_text(_spec(section), "c.yaml")
    _, diags = resolve_collision(spec, resolve_robot(spec)[0])
    warned = [d for d in diags if "fixed to the world and in no watched pair" in d.message]
    assert len(warned) == (0 if self_collision else 1)
    assert all(d.severity == "warning" and format_path(d.path) == "limits.collision.links.base" for d in warned)
