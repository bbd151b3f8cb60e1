"""A finished run with everything derived from it: what plots, tables and files are made from."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..formulations import ControlProblem
from ..robot.collision import CollisionModel
from ..robot.model import Robot
from ..sim.log import SimulationLog
from ..sim.runner import Simulation
from ..tasks import CartesianTask
from .metrics import collision_metrics, json_ready, pair_distances, summarize, summary_units
from .series import TimeSeries, evaluate


@dataclass
class RunResult:
    """A run's log, derived time series and summary, with what is needed to label them."""

    label: str  # e.g. the formulation
    robot: Robot
    log: SimulationLog
    series: TimeSeries
    summary: dict[str, Any]
    priorities: list[int]
    row_names: dict[str, tuple[str, ...]]  # task → names of its error rows
    waypoint_frame: str | None = None
    waypoint_positions: np.ndarray | None = None  # (P, 3) world points of a position waypoint path
    collision: CollisionModel = field(default_factory=CollisionModel.empty)
    distances: np.ndarray | None = None  # (N, pairs) signed distance of each watched pair, m

    def save_log(self, path: Path) -> None:
        """log.npz: the log's arrays, the derived series, and names to read them by."""
        np.savez_compressed(
            path,
            **self.log.arrays(),
            **self.series.arrays(),
            period=self.log.period,
            joint_names=np.array(self.robot.joint_names),
            bound_names=np.array(self.log.bound_names, dtype=str),
            task_names=np.array(list(self.row_names)),
            priorities=np.array(self.priorities),
            frames=np.array(list(self.series.frame_positions)),
        )

    def save_summary(self, path: Path) -> None:
        path.write_text(json.dumps(json_ready(self.summary), indent=2) + "\n", encoding="utf-8")


def analyze(sim: Simulation, log: SimulationLog, label: str | None = None,
            problem: ControlProblem | None = None) -> RunResult:
    """Derive the time series and the summary of a finished run of `sim` (`problem`: see `evaluate`)."""
    spec, robot = sim.spec, sim.robot
    series = evaluate(spec, robot, log, problem, sim.controller_robot)
    priorities = list(sim.runtime.priorities)
    summary = {
        "spec": spec.name,
        "formulation": sim.formulation,
        "runtime": sim.runtime_kind,
        "period": sim.scenario.period,
        "substeps": sim.scenario.substeps,
        "integrator": sim.scenario.integrator,
        "external_torque_sensing": sim.scenario.sensing.mode,
        "mass_scale": sim.scenario.mass_scale,
    }
    collision = sim.collision
    distances = pair_distances(collision, robot, log.q)
    summary |= summarize(log, series, robot, priorities, collision, distances)
    # A closed form (osc, projector) has no joint or Cartesian bound rows: no step of it is checked,
    # so none is "relaxed" (its status is 0 whatever the bounds: a count of 0 read as "held")
    summary["bounds_checked"] = bool(sim.runtime.nx)
    if not summary["bounds_checked"]:
        summary["limits_relaxed"] = summary["crossed_after_ok_steps"] = None
    summary |= collision_metrics(collision, distances, log.time)
    summary["units"] = summary_units(summary, series, robot)
    result = RunResult(label or sim.formulation, robot, log, series, summary, priorities,
                       {t.name: t.row_names for t in sim.tasks}, collision=collision, distances=distances)
    follower = sim.waypoints
    if follower is not None and isinstance(follower.task, CartesianTask):
        fields = [f for f, _, _ in follower.slices]
        if "position" in fields:
            result.waypoint_frame = follower.task.frame
            result.waypoint_positions = np.array([p[:3] for p in follower.points])
    return result
