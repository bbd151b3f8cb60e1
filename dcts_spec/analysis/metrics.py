"""The summary of a run: limit violations, task errors, energies, solver health, speed.

Definitions (N samples t_k = k T; violations are 0 when a limit holds or does not exist; a limit
is the one in force at the sample: the compiled value, or the run-time parameter the controller
applied then, ramps included):
- max_joint_position_violation = max_{k,j} max(0, q_j − q_max,j, q_min,j − q_j), rad
- max_joint_velocity_violation = max_{k,j} max(0, |q̇_j| − q̇_max,j), rad/s; `_ratio`: over q̇_max,j
- max_torque_violation = max_{k,j} max(0, |τ_j| − τ_max,j), Nm (τ as applied)
- max_cartesian_violation = max over bounds and samples of the distance outside [c_min, c_max], m;
  max_cartesian_velocity_violation = max over bounds with a max_velocity and samples of
  max(0, |dᵀṗ| − v_max), m/s (ṗ the velocity of the bound frame's origin)
- max_torque_jump = max_{k,j} |τ_j,k − τ_j,k−1|, Nm; `_ratio`: over τ_max,j; torque_jump_steps =
  #{k: |τ_j,k − τ_j,k−1| > TORQUE_JUMP_FRACTION τ_max,j for some j}: step-to-step chatter (a push or
  a saturation can cause some); max_controller_acceleration = max_{k,j} |a_j,k|, rad/s², with
  a = q̈_cmd + M_c⁻¹τ_ext,used = M_c⁻¹(τ + τ_ext,used − ν − g) the joint acceleration the controller
  solved for (its model M_c, its τ_ext input: series.controller_acceleration), the one
  limits.joint_acceleration bounds; joint_acceleration_limits: whether the spec bounds it
  (without, the velocity limits alone allow up to 2 q̇_max/T a step)
- crossed_after_ok_steps = #{k: status_k = 0 and some joint position, velocity, Cartesian or
  collision bound's excess at sample k+1 exceeds the one at k by more than CROSSING_TOLERANCE, both
  under the limits sample k was held to (a run-time parameter that narrows a limit at k+1 is not the
  plant's doing)}, crossed_after_ok_first
  the first such t_k (None if none): where the plant is not the model the status vouched for (an
  unknown payload, a late τ_ext, a mass mismatch); None as limits_relaxed is
- solver_failures = #{k: status_k < 0}; limits_relaxed = #{k: status_k = 1}, None for a formulation
  that checks no joint or Cartesian bound (osc, projector: closed forms; run.py, bounds_checked: false),
  whose status is 0 whatever its bounds; relaxed_bounds: for
  each joint/Cartesian bound that gave way (keyed by its row name), the bound as validate words it,
  its number of steps and the first and last time; for a joint also `beyond`, which of its limits
  (position, velocity) its state was beyond in those steps and by how much at most
- lowest_level_off_optimum_steps = #{k: status_k = 0 and the answer does not minimize the lowest
  level's objective (½xᵀHx + fᵀx: acceleration energy, least-squares posture) given the levels
  above, even after the step that takes a missed optimum to it}: the KKT check of every "ok"
  step's answer in either runtime (solve/optimality.py, StepResult.optimal; the log's `optimal`:
  1, 0, −1 not checked)
- min_scaling = min over samples and levels of the task scalings; min_scaling_at: the first sample
  and the highest level where it occurs (priority, its tasks, time), None if no level ever scaled;
  min_scaling_by_priority[p] = min over samples of level p's scaling (min_scaling_at may name a
  posture's early dip while priority 1 sat at 0 for hundreds of steps later on)
- task_rms_error[t] = sqrt(mean_k ‖Δx_t,k‖²), task_mean_error[t] = mean_k ‖Δx_t,k‖ (SI units); for
  a pure damping task (no reference) Δx is the velocity error −ẋ: task_error_quantity says which
- task_final_error[t] = max ‖Δx_t,k‖ over the last 10 % of the samples: a task still moving or
  oscillating at the end shows its amplitude here, where an RMS over the run would hide it
- mean_acceleration_error[p] = mean_k ‖J_p a_k + J̇_p q̇_k − ẍ_d,p,k‖ with the actual acceleration
  a_k = (q̇_{k+1} − q̇_k)/T; primary_mean_acceleration_error is the one of the first priority
- acceleration_energy_integral = Σ_k ½(τ_k − g_k)ᵀM_k⁻¹(τ_k − g_k) T
- kinetic_energy_peak = max_k ½q̇ᵀMq̇, split M-orthogonally into task_space_kinetic_energy_peak
  (max_k ½ẋᵀΛẋ, all levels' Jacobians stacked, Λ = (J M⁻¹ Jᵀ)⁺) and null_space_kinetic_energy_peak
  (max_k of the rest)
- max_disturbance_torque = max_{k,j} |τ_dist,j,k + τ_payload,j,k|: pushes, joint torques and the
  payloads the controller does not know (series.payload_torque), all external to its model
- max_external_torque_estimate_error = max_{k,j} |τ_ext,used,j,k+1 − (τ_dist + τ_payload)_j,k|: how
  far the τ_ext the controller used was from that (one step late: a motion-based estimate needs the
  step's acceleration); the model mismatch, sensor noise and bias, or all of it when the scenario's
  sensing or the controller's external_torque is `ignored` (the controller then uses 0)
- min_distances[pair] = min_k d_pair,k, the signed distance of each watched collision pair (m);
  collision_violations[pair]: for each pair closer than its minimum d_min at some sample, by how
  much at worst (max_k d_min − d_k, m), for how many steps, the first and last time;
  max_collision_violation = the largest of those (0 when every pair kept its minimum)
- waypoints_reached = points reached (None without waypoints); waypoint_times: when each was, or None
- worst_joints[metric] = the joint where each per-joint maximum above is reached, ratios included
  (None where it is 0)
- realtime_factor = simulated time / wall time of the simulation loop (controller, physics and
  logging; not the viewer, video or progress display)

`units` maps every numeric entry to its unit (a map per task or level for the nested ones).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..controller import STATUS_LIMITS_RELAXED
from ..formulations.parameters import LimitsInForce
from ..limits.collision import distance_function
from ..limits.naming import cartesian_row_name, joint_force_unit, joint_row_name, joint_unit, row_text
from ..robot.collision import CollisionModel
from ..robot.model import CartesianBound, JointLimits, Robot
from ..sim.log import SimulationLog
from ..symbolic import SymbolicRobot
from .series import TimeSeries
from .units import per, run_units

# A torque step between consecutive periods above this fraction of the joint's limit counts as a jump
# (the continuity check: no jump > 10 % of τ_max between states 1e-4 apart).
TORQUE_JUMP_FRACTION = 0.1
# A bound counts as crossed after an "ok" step when that step left the state further beyond it by
# more than this, in the bound's own unit (rad, rad/s, m): the status vouches for the controller's
# model, and the plant did something else (issue 9's check: 1e-5 of the unit)
CROSSING_TOLERANCE = 1e-5

# The headline metrics: numbers (or per-task numbers) in every summary, finite for a completed run.
SUMMARY_KEYS = (
    "max_joint_position_violation",
    "max_joint_velocity_violation",
    "max_joint_velocity_violation_ratio",
    "max_torque_violation",
    "solver_failures",
    "min_scaling",
    "task_rms_error",
    "primary_mean_acceleration_error",
    "acceleration_energy_integral",
    "task_space_kinetic_energy_peak",
    "null_space_kinetic_energy_peak",
    "realtime_factor",
)


def summarize(log: SimulationLog, series: TimeSeries, robot: Robot, priorities: list[int],
              collision: CollisionModel | None = None, distances: np.ndarray | None = None) -> dict[str, Any]:
    """The summary.json metrics of a run (see the module docstring for the definitions);
    `distances`: the collision pairs' (`pair_distances`)."""
    lim = series.limits.joint

    def excesses(states: slice, limits: slice) -> list[np.ndarray]:
        """Each bound family's excess (samples, bounds) of the samples `states` under the limits of
        the samples `limits`."""
        q, joint = log.q[states], series.limits.joint
        out = [np.maximum(_excess(q, joint.q_max[limits]), _excess(-q, -joint.q_min[limits])),
               _excess(np.abs(log.dq[states]), joint.v_max[limits]),
               _cartesian_excess(series, robot, states, limits)]
        if collision is not None and distances is not None and collision.pairs:
            out.append(np.maximum(np.array([p.min_distance for p in collision.pairs]) - distances[states], 0.0))
        return out

    now = excesses(slice(None), slice(None))
    position_excess, velocity_excess, cartesian_excess, *_ = now
    acceleration_errors = {str(p): _mean_norm(series.acceleration_errors[p]) for p in priorities}
    waypoints = log.waypoint_times
    disturbance = log.tau_ext_true + series.payload_torque
    torque_jump = np.abs(np.diff(log.tau, axis=0))
    # (each sample k+1 under the limits sample k held)
    crossed = _crossed_after_ok(log, now, excesses(slice(1, None), slice(None, -1)))
    per_joint = {  # (samples, joints) whose peak is a metric
        "max_joint_position_violation": position_excess,
        "max_joint_velocity_violation": velocity_excess,
        "max_torque_violation": _excess(np.abs(log.tau), lim.tau_max),
        "max_torque_jump": torque_jump,
        "max_controller_acceleration": np.abs(series.controller_acceleration),
        "max_disturbance_torque": np.abs(disturbance),
        "max_external_torque_estimate_error": np.abs(series.tau_ext_used[1:] - disturbance[:-1]),
    }
    peak = {key: _peak(values) for key, values in per_joint.items()}
    ratios = {  # (over each joint's own limit: their peak may be at another joint than the value's)
        "max_joint_velocity_violation_ratio": velocity_excess / lim.v_max,
        "max_torque_jump_ratio": torque_jump / lim.tau_max[1:],
    }
    summary: dict[str, Any] = {
        "duration": log.duration,
        "steps": log.steps,
        "completed": log.diverged_at is None,
        "diverged_at": log.diverged_at,
        "max_joint_position_violation": peak["max_joint_position_violation"],
        "max_joint_velocity_violation": peak["max_joint_velocity_violation"],
        "max_joint_velocity_violation_ratio": _peak(ratios["max_joint_velocity_violation_ratio"]),
        "max_torque_violation": peak["max_torque_violation"],
        "max_cartesian_violation": _peak(cartesian_excess),
        "max_cartesian_velocity_violation": _peak(np.array([
            _peak(_excess(np.abs(b.coordinate(series.frame_velocities[b.frame])), np.array(b.v_max)))
            for b in robot.cartesian_bounds if np.isfinite(b.v_max)])),
        "max_torque_jump": peak["max_torque_jump"],
        "max_torque_jump_ratio": _peak(ratios["max_torque_jump_ratio"]),
        "torque_jump_steps": int(np.count_nonzero((torque_jump > TORQUE_JUMP_FRACTION * lim.tau_max[1:]).any(axis=1))),
        "max_controller_acceleration": peak["max_controller_acceleration"],
        "joint_acceleration_limits": bool(np.isfinite(lim.a_max).any()),
        "solver_failures": int(np.count_nonzero(log.status < 0)),
        "limits_relaxed": int(np.count_nonzero(log.status == STATUS_LIMITS_RELAXED)),
        "lowest_level_off_optimum_steps": int(np.count_nonzero(log.optimal == 0)),
        "crossed_after_ok_steps": int(crossed.size),
        "crossed_after_ok_first": float(log.time[crossed[0]]) if crossed.size else None,
        "relaxed_bounds": _relaxed_bounds(log, series, robot, collision, position_excess, velocity_excess),
        "min_scaling": _peak(log.scaling, np.min, default=1.0),
        "min_scaling_at": _min_scaling_at(log, series, priorities),
        "min_scaling_by_priority": {str(p): _peak(log.scaling[:, i], np.min, default=1.0)
                                    for i, p in enumerate(priorities)},
        "task_error_quantity": {t: "damping (velocity error)" if t in series.damping else "tracking error"
                                for t in series.task_errors},
        "task_rms_error": {t: _rms_norm(e) for t, e in series.task_errors.items()},
        "task_mean_error": {t: _mean_norm(e) for t, e in series.task_errors.items()},
        "task_final_error": {t: _final_norm(e) for t, e in series.task_errors.items()},
        "primary_mean_acceleration_error": acceleration_errors[str(priorities[0])],
        "mean_acceleration_error": acceleration_errors,
        "acceleration_energy_integral": float(np.sum(series.acceleration_energy) * log.period),
        "kinetic_energy_peak": _peak(series.kinetic_energy),
        "task_space_kinetic_energy_peak": _peak(series.task_kinetic_energy),
        "null_space_kinetic_energy_peak": _peak(series.null_kinetic_energy),
        "max_disturbance_torque": peak["max_disturbance_torque"],
        "max_external_torque_estimate_error": peak["max_external_torque_estimate_error"],
        "waypoints_total": int(waypoints.size),
        "waypoints_reached": int(np.count_nonzero(np.isfinite(waypoints))) if waypoints.size else None,
        "waypoint_times": [None if math.isnan(t) else float(t) for t in waypoints],
        "worst_joints": {key: _worst_joint(values, robot) for key, values in {**per_joint, **ratios}.items()},
        "wall_time": log.wall_time,
        "realtime_factor": log.duration / log.wall_time if log.wall_time > 0 else None,
    }
    return summary


def summary_units(summary: dict[str, Any], series: TimeSeries, robot: Robot) -> dict[str, Any]:
    """The unit of every numeric entry of `summary` (per task or level for the nested ones): the
    `units` entry of summary.json."""
    units = run_units(series.task_units, series.level_units, robot)
    return {key: units[key] for key in summary if key in units}


def _min_scaling_at(log: SimulationLog, series: TimeSeries, priorities: list[int]) -> dict[str, Any] | None:
    """Where the smallest scaling is first reached: the priority level, its tasks, the time."""
    if not log.scaling.size or log.scaling.min() >= 1.0:
        return None
    # Row-major: the earliest sample first, then the highest level at it.
    k, level = np.unravel_index(np.argmin(log.scaling), log.scaling.shape)
    priority = priorities[level]
    return {"priority": priority, "tasks": list(series.level_tasks.get(priority, ())), "time": float(log.time[k])}


def _relaxed_bounds(log: SimulationLog, series: TimeSeries, robot: Robot, collision: CollisionModel | None,
                    position_excess: np.ndarray, velocity_excess: np.ndarray) -> dict[str, dict[str, Any]]:
    """Each bound that gave way: the bound as text (as compiled, and as run-time parameters narrowed
    it in those steps), how many steps, the first and last time (s); for a joint, which of its
    limits the state was beyond in those steps (one row holds both), from the (samples, joints)
    excesses over its position and velocity limits in force."""
    out = {}
    joints = {joint_row_name(joint): j for j, joint in enumerate(robot.joint_names)}
    bounds = {cartesian_row_name(b): i for i, b in enumerate(robot.cartesian_bounds)}
    for r, name in enumerate(log.bound_names):
        steps = np.flatnonzero(log.relaxed[:, r])
        if not steps.size:
            continue
        text = row_text(robot, name, collision)
        if name in joints:
            narrowed = _narrowed_joint(robot, series.limits.joint, joints[name], steps)
        elif name in bounds:
            narrowed = _narrowed_cartesian(robot.cartesian_bounds[bounds[name]], series.limits, bounds[name], steps)
        else:
            narrowed = ""
        out[name] = {"bound": text + (f" (narrowed at run time in those steps: {narrowed})" if narrowed else ""),
                     "steps": int(steps.size), "first": float(log.time[steps[0]]), "last": float(log.time[steps[-1]])}
        if name in joints:
            j = joints[name]
            out[name]["beyond"] = _joint_beyond(_peak(position_excess[steps, j]), _peak(velocity_excess[steps, j]),
                                                joint_unit(robot, j))
    return out


def _narrowed_joint(robot: Robot, limits: JointLimits, j: int, steps: np.ndarray) -> str:
    """Joint j's limits that differ from the compiled ones in `steps`, as text ('' if none)."""
    unit, force = joint_unit(robot, j), joint_force_unit(robot, j)
    quantities = (("q_min", "min position", unit), ("q_max", "max position", unit),
                  ("v_max", "max velocity", per(unit, "s")), ("a_max", "max acceleration", per(unit, "s²")),
                  ("tau_max", "max torque" if force == "Nm" else "max force", force))
    return _narrowed(((what, getattr(limits, key)[steps, j], getattr(robot.limits, key)[j], u)
                      for key, what, u in quantities))


def _narrowed_cartesian(bound: CartesianBound, limits: LimitsInForce, i: int, steps: np.ndarray) -> str:
    """A Cartesian bound's sides that differ from the compiled ones in `steps`, as text."""
    return _narrowed((("min", limits.c_min[steps, i], bound.c_min, "m"), ("max", limits.c_max[steps, i], bound.c_max, "m")))


def _narrowed(values) -> str:
    """'what lo–hi unit' for each (what, values in force, compiled value, unit) whose values differ
    from the compiled one."""
    parts = []
    for what, in_force, compiled, unit in values:
        if np.any(in_force != compiled):
            lo, hi = float(np.min(in_force)), float(np.max(in_force))
            parts.append(f"{what} {lo:.4g} {unit}" if lo == hi else f"{what} {lo:.4g}–{hi:.4g} {unit}")
    return ", ".join(parts)


def _joint_beyond(position: float, velocity: float, unit: str) -> str:
    """Which of a joint's limits its state was beyond, and by how much at most, as text."""
    parts = [f"its {what} limit by up to {by:.3g} {u}" for what, by, u in
             (("position", position, unit), ("velocity", velocity, per(unit, "s"))) if by > 0.0]
    return " and ".join(parts) if parts else "none of its limits (the braking it asked for was more than the torques give)"


def pair_distances(collision: CollisionModel, robot: Robot, q: np.ndarray) -> np.ndarray:
    """(N, pairs) signed distance of each watched pair at each sample of q (N, n)."""
    if not collision.pairs or not len(q):
        return np.zeros((len(q), len(collision.pairs)))
    function = distance_function(collision, SymbolicRobot(robot.model))
    return np.asarray(function.map(len(q))(np.asarray(q).T)).T


def collision_metrics(collision: CollisionModel, distances: np.ndarray, time: np.ndarray) -> dict[str, Any]:
    """min_distances, collision_violations and max_collision_violation (module docstring); none
    without a collision section."""
    if not collision.pairs:
        return {}
    violations = {}
    for j, pair in enumerate(collision.pairs):
        below = pair.min_distance - distances[:, j]
        steps = np.flatnonzero(below > 0)
        if steps.size:
            violations[pair.name] = {"min_distance": pair.min_distance, "by": float(below.max()), "steps": int(steps.size),
                                     "first": float(time[steps[0]]), "last": float(time[steps[-1]])}
    return {
        "min_distances": {p.name: _peak(distances[:, j], np.min, default=np.inf) for j, p in enumerate(collision.pairs)},
        "collision_violations": violations,
        "max_collision_violation": max((v["by"] for v in violations.values()), default=0.0),
    }


def _excess(values: np.ndarray, bound: np.ndarray) -> np.ndarray:
    """How far values are above bound (0 below it, and where the bound is infinite)."""
    return np.maximum(values - np.where(np.isfinite(bound), bound, np.inf), 0.0)


def _peak(values: np.ndarray, reduce=np.max, default: float = 0.0) -> float:
    return float(reduce(values)) if values.size else default


def _worst_joint(values: np.ndarray, robot: Robot) -> str | None:
    """The joint of the largest of (samples, joints) values (None if all are 0): its unit is the
    peak's on a robot that mixes revolute and prismatic joints."""
    if not values.size or values.max() <= 0.0:
        return None
    return robot.joint_names[int(np.argmax(values)) % values.shape[1]]


def _mean_norm(errors: np.ndarray) -> float:
    return float(np.mean(np.linalg.norm(errors, axis=1))) if errors.size else 0.0


def _final_norm(errors: np.ndarray, fraction: float = 0.1) -> float:
    if not errors.size:
        return 0.0
    tail = errors[-max(1, int(round(fraction * len(errors)))):]
    return float(np.max(np.linalg.norm(tail, axis=1)))


def _rms_norm(errors: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(errors**2, axis=1)))) if errors.size else 0.0


def _cartesian_excess(series: TimeSeries, robot: Robot, states: slice = slice(None),
                      limits: slice = slice(None)) -> np.ndarray:
    """(samples, bounds): how far each Cartesian bound's coordinate at the samples `states` is
    outside [c_min, c_max] of the samples `limits`, m."""
    c_min, c_max = series.limits.c_min[limits], series.limits.c_max[limits]
    excess = np.zeros(c_min.shape)
    for i, b in enumerate(robot.cartesian_bounds):
        c = b.coordinate(series.frame_positions[b.frame][states])
        excess[:, i] = np.maximum(_excess(c, c_max[:, i]), _excess(-c, -c_min[:, i]))
    return excess


def _crossed_after_ok(log: SimulationLog, now: list[np.ndarray], next_held: list[np.ndarray]) -> np.ndarray:
    """The samples k whose step had status 0 and left some bound's excess larger at k+1 by more
    than CROSSING_TOLERANCE: `now`, each bound family's excess (samples, bounds) under its own
    sample's limits; `next_held`, the one of sample k+1 under the limits of sample k (the ones
    that step held)."""
    grew = np.zeros(max(len(log.status) - 1, 0), dtype=bool)
    for excess, after in zip(now, next_held, strict=True):
        if excess.size:
            grew |= (after - excess[:-1] > CROSSING_TOLERANCE).any(axis=1)
    return np.flatnonzero(grew & (log.status[:-1] == 0))


def json_ready(value: Any) -> Any:
    """Non-finite floats become None (JSON has no NaN or ∞), numpy scalars Python numbers."""
    if isinstance(value, dict):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
