"""Table II of the paper (average position and acceleration errors on a waypoint path), as a reader
of the paper would compute them, and the alternative readings beside them.

Every function works on arrays a run's log.npz holds (`time`, `q`, `dq`, `ref`, `position_<frame>`,
`acceleration_error_<priority>`, `waypoint_times`, `period`), so the numbers can be recomputed from
the files; only the tool velocity needs the robot model (Pinocchio's frame velocity).

Definitions, over the path phase k = 0 … n−1 (up to the sample the last point is reached; all
samples if it is not), with x_k the tool position and b_k = ref[k, :3] the current target:

- segment start a_k: the tool's start x_0 until the target first changes; from a sample k where
  b_k ≠ b_{k−1}, the previous target b_{k−1}, and t_s = t_k is that segment's start time;
- reference point r_k = a_k + min(v_sat (t_k − t_s), ‖b_k − a_k‖) (b_k − a_k)/‖b_k − a_k‖: a point
  moving from the previous point to the target at v_sat, then waiting there;
- position error = mean_k ‖x_k − r_k‖;
- desired acceleration (the task's saturated law) ẍ_d,k = −k_v (ẋ_k − v_k ẋ_d,k) with
  ẋ_d,k = (k_p/k_v)(b_k − x_k), v_k = min(1, v_sat/‖ẋ_d,k‖);
- acceleration error (central) = mean_{k=1…n−2} ‖(ẋ_{k+1} − ẋ_{k−1})/(2T) − ẍ_d,k‖, ẋ_k the tool
  frame's linear velocity in world axes (Pinocchio LOCAL_WORLD_ALIGNED at q_k, q̇_k);
  backward = mean_{k=1…n−1} ‖(ẋ_k − ẋ_{k−1})/T − ẍ_d,k‖;
- alternatives: path error = mean_k distance of x_k to the segment [a_k, b_k]; target error =
  mean_k ‖x_k − b_k‖; model acceleration error = mean_k ‖J a_k + J̇q̇_k − ẍ_d,k‖ with the
  simulator's actual joint acceleration a_k = (q̇_{k+1} − q̇_k)/T (the log's
  acceleration_error_<priority>).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin


@dataclass(frozen=True)
class SaturatedLaw:
    """The gains of ẍ = −k_v(ẋ − v ẋ_d), ẋ_d = (k_p/k_v)Δx, v = min(1, v_sat/‖ẋ_d‖)."""

    kp: float  # 1/s²
    kv: float  # 1/s
    v_sat: float  # m/s


def path_samples(waypoint_times: np.ndarray, period: float, steps: int) -> int:
    """n: the samples up to (and with) the one the last point is reached; all if it is not."""
    if waypoint_times.size and np.all(np.isfinite(waypoint_times)):
        return min(int(round(float(waypoint_times[-1]) / period)) + 1, steps)
    return steps


def segment_starts(target: np.ndarray, first: np.ndarray, time: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(a_k, t_s,k): each sample's segment start point and start time (see the module's docstring)."""
    start = np.empty_like(target)
    since = np.empty(len(target))
    point, t0 = np.asarray(first, float).copy(), float(time[0]) if len(time) else 0.0
    for k in range(len(target)):
        if k and np.any(target[k] != target[k - 1]):
            point, t0 = target[k - 1].copy(), float(time[k])
        start[k], since[k] = point, t0
    return start, since


def moving_reference(target: np.ndarray, first: np.ndarray, time: np.ndarray, v_sat: float) -> np.ndarray:
    """r_k: a point leaving the segment's start when the target switches, at v_sat, waiting at the target."""
    start, since = segment_starts(target, first, time)
    direction = target - start
    length = np.linalg.norm(direction, axis=1)
    travelled = np.minimum(v_sat * (time - since), length)
    unit = np.divide(direction, length[:, None], out=np.zeros_like(direction), where=length[:, None] > 0)
    return start + travelled[:, None] * unit


def segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of each point p[k] to the segment [a[k], b[k]]."""
    ab = b - a
    length2 = np.einsum("ij,ij->i", ab, ab)
    s = np.where(length2 > 0, np.einsum("ij,ij->i", p - a, ab) / np.where(length2 > 0, length2, 1.0), 0.0)
    return np.linalg.norm(p - (a + np.clip(s, 0.0, 1.0)[:, None] * ab), axis=1)


def frame_velocity(model: pin.Model, q: np.ndarray, dq: np.ndarray, frame: str) -> np.ndarray:
    """(N, 3) linear velocity of a frame's origin in world axes (Pinocchio LOCAL_WORLD_ALIGNED)."""
    data = model.createData()
    fid = model.getFrameId(frame)
    out = np.empty((len(q), 3))
    for k in range(len(q)):
        pin.forwardKinematics(model, data, q[k], dq[k])
        out[k] = pin.getFrameVelocity(model, data, fid, pin.LOCAL_WORLD_ALIGNED).linear
    return out


def desired_acceleration(position: np.ndarray, velocity: np.ndarray, target: np.ndarray,
                         law: SaturatedLaw) -> np.ndarray:
    """ẍ_d,k of the saturated law at each sample (unscaled)."""
    xd = (law.kp / law.kv) * (target - position)
    speed = np.linalg.norm(xd, axis=1)
    v = np.minimum(1.0, law.v_sat / np.maximum(speed, 1e-300))
    return -law.kv * (velocity - v[:, None] * xd)


def differentiated_acceleration_errors(velocity: np.ndarray, desired: np.ndarray,
                                       period: float) -> tuple[np.ndarray, np.ndarray]:
    """(central, backward) ‖ẍ_k − ẍ_d,k‖ with ẍ_k differentiated from the velocity samples:
    central for k = 1…n−2, backward for k = 1…n−1."""
    central = (velocity[2:] - velocity[:-2]) / (2.0 * period)
    backward = (velocity[1:] - velocity[:-1]) / period
    return (np.linalg.norm(central - desired[1:-1], axis=1), np.linalg.norm(backward - desired[1:], axis=1))


@dataclass
class Table2Series:
    """The per-sample quantities of the path phase the Table II numbers are means of."""

    reference: np.ndarray  # (n, 3) r_k
    velocity: np.ndarray  # (n, 3) ẋ_k
    desired_acceleration: np.ndarray  # (n, 3) ẍ_d,k
    position_error: np.ndarray  # (n,) ‖x_k − r_k‖
    acceleration_error_central: np.ndarray  # (n − 2,)
    acceleration_error_backward: np.ndarray  # (n − 1,)
    path_error: np.ndarray  # (n,) distance to the segment
    target_error: np.ndarray  # (n,) ‖x_k − b_k‖

    def means(self) -> dict[str, float]:
        return {name: float(getattr(self, name).mean()) if getattr(self, name).size else float("nan")
                for name in ("position_error", "acceleration_error_central", "acceleration_error_backward",
                             "path_error", "target_error")}


def table2_series(model: pin.Model, frame: str, time: np.ndarray, q: np.ndarray, dq: np.ndarray,
                  position: np.ndarray, target: np.ndarray, period: float, law: SaturatedLaw) -> Table2Series:
    """The Table II series of a path phase (arrays already cut to its n samples)."""
    reference = moving_reference(target, position[0], time, law.v_sat)
    velocity = frame_velocity(model, q, dq, frame)
    desired = desired_acceleration(position, velocity, target, law)
    central, backward = differentiated_acceleration_errors(velocity, desired, period)
    start, _ = segment_starts(target, position[0], time)
    return Table2Series(reference, velocity, desired, np.linalg.norm(position - reference, axis=1), central, backward,
                        segment_distance(position, start, target), np.linalg.norm(position - target, axis=1))
