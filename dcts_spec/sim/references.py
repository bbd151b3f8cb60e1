"""What the controller's run-time `ref` input receives during a run: held values and waypoints."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..formulations.parameters import ParameterLayout
from ..robot.model import Robot
from ..spec.scenario import Waypoints
from ..spec.units import joint_to_si, to_si
from ..tasks import CartesianTask, JointTask, ReferenceInput, Task
from .paths import Segment, segment_duration

# Step (m or rad along the path's direction) of the differences that turn the path's rates into
# the task's rows: exact for positions and joints, O(step²) for orientations.
DIFFERENCE_STEP = 1e-4


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
    m for positions, rad for orientations and joints) is within the tolerance at a control step.

    Without feed-forward each point is fed as it is, a step, until it is reached; that step already
    gets the next point. With `feedforward: true` the task follows a minimum-jerk path (`paths.py`)
    from where it starts to the first point, then from each point to the next: the reference with
    its velocity and acceleration in the task's rows. A segment starts when the previous point is
    reached and the previous segment's time is over (the path waits at a point not yet reached).
    Either way the last point is held until the end of the run.
    """

    def __init__(self, waypoints: Waypoints, task: Task, layout: list[ReferenceInput], robot: Robot,
                 parameters: ParameterLayout | None = None):
        self.task = task
        # where the task's kp and max_velocity are run-time parameters: a segment is timed with the
        # values in force when it starts (it was timed with the compiled ones)
        names = {e.name: e.slice for e in (parameters or ParameterLayout()).entries}
        self._gain_slices = {gain: names.get(f"{task.name}.{gain}") for gain in ("kp", "max_velocity")}
        self._param: np.ndarray = parameters.defaults if parameters is not None else np.zeros(0)
        self.tolerance = float(waypoints.tolerance)
        entries = [r for r in layout if r.task == task.name and r.field in ("position", "rpy", "q")]
        self.slices = [(r.field, r.offset, r.size) for r in entries]
        # (a joint task's prismatic joints in m whatever the unit)
        self._prismatic = robot.prismatic[task.joint_indices] if isinstance(task, JointTask) else None
        self.points = [self._to_si(np.array(p, dtype=float), waypoints.unit) for p in waypoints.points]
        self.reached_at = np.full(len(self.points), np.nan)
        self.index = 0
        feeds = {r.field: r.offset for r in layout if r.task == task.name and r.field in ("velocity", "acceleration")}
        self._feeds = (feeds["velocity"], feeds["acceleration"]) if len(feeds) == 2 else None
        self._segment: Segment | None = None
        self._model = robot.model
        self._data = robot.model.createData()
        self._frame = robot.model.getFrameId(task.frame) if isinstance(task, CartesianTask) else None

    def _to_si(self, point: np.ndarray, unit: str) -> np.ndarray:
        out, start = point.copy(), 0
        for field, _, size in self.slices:
            if field == "rpy":
                out[start: start + size] = to_si(list(point[start: start + size]), unit)
            elif field == "q":
                out[start: start + size] = joint_to_si(list(point[start: start + size]), unit, self._prismatic)
            start += size
        return out

    @property
    def finished(self) -> bool:
        return self.index >= len(self.points)

    @property
    def feedforward(self) -> bool:
        """The task takes velocity and acceleration: the points are joined by a timed path."""
        return self._feeds is not None

    def restart(self, ref: np.ndarray, param: np.ndarray | None = None) -> None:
        """Back to the first point, none reached yet. `ref` holds the task's value at the start:
        without feed-forward the first point goes into it, with it the path's start (at rest).
        `param`: the run-time parameters in force at the start (default: the compiled values)."""
        self.index = 0
        self.reached_at[:] = np.nan
        if param is not None:
            self._param = param
        if self.feedforward:
            self._segment = self._segment_to(self._read(ref), 0.0)
            self._write_rates(ref, np.zeros(self.task.dim), np.zeros(self.task.dim))
        else:
            self._write_point(ref, self.points[0])

    def update(self, t: float, q: np.ndarray, ref: np.ndarray, param: np.ndarray | None = None) -> None:
        """Move on to the next point if the current one is reached at (t, q); with feed-forward,
        write the path at t into `ref`. `param`: the run-time parameters in force at t."""
        if param is not None:
            self._param = param
        segment = self._segment
        if segment is None:
            if self.finished or self.error_norm(q) > self.tolerance:
                return
            self.reached_at[self.index] = t
            self.index += 1
            self._write_point(ref, self.points[min(self.index, len(self.points) - 1)])
            return
        if not self.finished and segment.over(t) and self.error_norm(q) <= self.tolerance:
            self.reached_at[self.index] = t
            self.index += 1
            if not self.finished:
                segment = self._segment = self._segment_to(segment.end, t)
        value, rate, second = segment.at(t)
        self._write_point(ref, value)
        self._write_rates(ref, *self._task_rates(q, value, rate, second))

    def error_norm(self, q: np.ndarray) -> float:
        """‖Δx‖ of the task towards the current point."""
        return float(np.linalg.norm(self._error(q, self.points[self.index])))

    # -- the reference vector and the task's rows ----------------------------------------------

    def _read(self, ref: np.ndarray) -> np.ndarray:
        return np.concatenate([ref[offset: offset + size] for _, offset, size in self.slices])

    def _write_point(self, ref: np.ndarray, point: np.ndarray) -> None:
        start = 0
        for _, offset, size in self.slices:
            ref[offset: offset + size] = point[start: start + size]
            start += size

    def _write_rates(self, ref: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray) -> None:
        assert self._feeds is not None
        dim = self.task.dim
        ref[self._feeds[0]: self._feeds[0] + dim] = velocity
        ref[self._feeds[1]: self._feeds[1] + dim] = acceleration

    def _fields(self, point: np.ndarray) -> dict[str, np.ndarray]:
        out, start = {}, 0
        for field, _, size in self.slices:
            out[field] = point[start: start + size]
            start += size
        return out

    def _error(self, q: np.ndarray, point: np.ndarray) -> np.ndarray:
        """Δx of the task at q towards the reference `point`."""
        task = self.task
        if isinstance(task, JointTask):
            return point - q[task.joint_indices]
        assert isinstance(task, CartesianTask) and self._frame is not None
        pin.forwardKinematics(self._model, self._data, q)
        placement = pin.updateFramePlacement(self._model, self._data, self._frame)
        return task.numeric_error(placement.translation, placement.rotation, self._fields(point))

    def _segment_to(self, start: np.ndarray, t0: float) -> Segment:
        """The path's segment from `start` to the current point, beginning at t0."""
        end = self.points[self.index].copy()
        begin = 0
        for field, _, size in self.slices:
            if field == "rpy":  # each angle the short way round
                part = slice(begin, begin + size)
                end[part] = start[part] + np.angle(np.exp(1j * (end[part] - start[part])))
            begin += size
        distance = float(np.linalg.norm(self._distance(start, end)))
        kp, max_velocity = self.task.kp, self.task.max_velocity
        if self._gain_slices["kp"] is not None:
            kp = self._param[self._gain_slices["kp"]]
        if self._gain_slices["max_velocity"] is not None:
            max_velocity = float(self._param[self._gain_slices["max_velocity"]][0])
        return Segment(start, end, t0, segment_duration(distance, kp, max_velocity))

    def _distance(self, start: np.ndarray, end: np.ndarray) -> np.ndarray:
        """The task's error at the reference `start` towards `end` (rows as the task has them)."""
        task = self.task
        if isinstance(task, JointTask):
            return end - start
        assert isinstance(task, CartesianTask)
        fields = self._fields(start)
        position = fields.get("position", np.zeros(3))
        rotation = pin.rpy.rpyToMatrix(*fields["rpy"]) if "rpy" in fields else np.eye(3)
        return task.numeric_error(position, rotation, self._fields(end))

    def _task_rates(self, q: np.ndarray, value: np.ndarray, rate: np.ndarray,
                    second: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The reference's velocity and acceleration in the task's rows: the first and second time
        derivatives of Δx(q, r(t)) at the current q (how fast the target moves in what the task
        controls), by central differences along ṙ and r̈ for a Cartesian task."""
        if isinstance(self.task, JointTask):
            return rate, second
        zero = np.zeros(self.task.dim)
        if not rate.any() and not second.any():  # at rest: before, between and after the segments
            return zero, zero

        def differences(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """First and second derivative of Δx along `direction` (zero for a zero direction)."""
            size = float(np.linalg.norm(direction))
            if size == 0.0:
                return zero, zero
            h = DIFFERENCE_STEP / size
            ahead, behind = self._error(q, value + h * direction), self._error(q, value - h * direction)
            return (ahead - behind) / (2.0 * h), (ahead - 2.0 * self._error(q, value) + behind) / h**2

        velocity, curvature = differences(rate)
        along_second, _ = differences(second)
        return velocity, along_second + curvature
