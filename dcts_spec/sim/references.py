"""What the controller's run-time `ref` input receives during a run: held values and waypoints."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..robot.model import Robot
from ..spec.scenario import Waypoints
from ..spec.units import to_si
from ..tasks import CartesianTask, JointTask, ReferenceInput, Task


def initial_references(tasks: list[Task], layout: list[ReferenceInput], robot: Robot, q0: np.ndarray) -> np.ndarray:
    """A `ref` vector that holds every run-time reference at its value in q0 (zero feed-forward)."""
    ref = np.zeros(sum(r.size for r in layout))
    by_name = {t.name: t for t in tasks}
    for entry in layout:
        ref[entry.offset: entry.offset + entry.size] = _current_value(by_name[entry.task], entry.field, robot, q0)
    return ref


def _current_value(task: Task, field: str, robot: Robot, q: np.ndarray) -> np.ndarray:
    if isinstance(task, JointTask):
        return q[task.joint_indices] if field == "q" else np.zeros(task.dim)
    assert isinstance(task, CartesianTask)
    if field not in ("position", "rpy"):
        return np.zeros(task.dim)  # velocity and acceleration feed-forward
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    placement = data.oMf[robot.model.getFrameId(task.frame)]
    return placement.translation.copy() if field == "position" else pin.rpy.matrixToRpy(placement.rotation)


class WaypointFollower:
    """Feeds the waypoints to their task one after the other.

    A point counts as reached when the norm of the task's error (its controlled rows, in SI:
    m for positions, rad for orientations and joints) is within the tolerance at a control step;
    that step already gets the next point. The last point is held until the end of the run.
    """

    def __init__(self, waypoints: Waypoints, task: Task, layout: list[ReferenceInput], robot: Robot):
        self.task = task
        self.tolerance = float(waypoints.tolerance)
        entries = [r for r in layout if r.task == task.name and r.field in ("position", "rpy", "q")]
        self.slices = [(r.field, r.offset, r.size) for r in entries]
        self.points = [self._to_si(np.array(p, dtype=float), waypoints.unit) for p in waypoints.points]
        self.reached_at = np.full(len(self.points), np.nan)
        self.index = 0
        self._model = robot.model
        self._data = robot.model.createData()
        self._frame = robot.model.getFrameId(task.frame) if isinstance(task, CartesianTask) else None

    def _to_si(self, point: np.ndarray, unit: str) -> np.ndarray:
        out, start = point.copy(), 0
        for field, _, size in self.slices:
            if field in ("rpy", "q"):
                out[start: start + size] = to_si(list(point[start: start + size]), unit)
            start += size
        return out

    @property
    def finished(self) -> bool:
        return self.index >= len(self.points)

    def restart(self, ref: np.ndarray) -> None:
        """Back to the first point, none reached yet; the first point goes into `ref`."""
        self.index = 0
        self.reached_at[:] = np.nan
        self.write(ref)

    def write(self, ref: np.ndarray) -> None:
        """Put the current point into `ref`."""
        point = self.points[min(self.index, len(self.points) - 1)]
        start = 0
        for _, offset, size in self.slices:
            ref[offset: offset + size] = point[start: start + size]
            start += size

    def update(self, t: float, q: np.ndarray, ref: np.ndarray) -> None:
        """Move on to the next point if the current one is reached at (t, q)."""
        if self.finished or self.error_norm(q) > self.tolerance:
            return
        self.reached_at[self.index] = t
        self.index += 1
        self.write(ref)

    def error_norm(self, q: np.ndarray) -> float:
        """‖Δx‖ of the task towards the current point."""
        point = self.points[self.index]
        task = self.task
        if isinstance(task, JointTask):
            return float(np.linalg.norm(point - q[task.joint_indices]))
        assert isinstance(task, CartesianTask) and self._frame is not None
        pin.forwardKinematics(self._model, self._data, q)
        placement = pin.updateFramePlacement(self._model, self._data, self._frame)
        reference, start = {}, 0
        for field, _, size in self.slices:
            reference[field] = point[start: start + size]
            start += size
        return float(np.linalg.norm(task.numeric_error(placement.translation, placement.rotation, reference)))
