"""The few lines about a run printed to the terminal, every number with its unit (summary.json's)."""

from __future__ import annotations

from typing import Any

from .metrics import TORQUE_JUMP_FRACTION
from .run import RunResult
from .units import joint_peak_units


def quantity(value: float | None, unit: str) -> str:
    """`0.012 rad`, `3 steps`; a ratio ("1") or a bare number ("") without a unit; – for a missing value."""
    if value is None:
        return "–"
    number = f"{value:.3g}"
    return number if unit in ("1", "") else f"{number} {unit}"


def peak_unit(run: RunResult, key: str) -> str:
    """The unit of a summary entry; for a peak over joints on a robot that mixes revolute and
    prismatic joints ("N, Nm"), that of the joint where it is reached, or none for a 0 (no joint)."""
    unit = run.summary["units"][key]
    worst = run.summary.get("worst_joints", {})
    if key not in worst or ", " not in unit:
        return unit
    if worst[key] is None:
        return ""
    return joint_peak_units(run.robot, [run.robot.joint_names.index(worst[key])])[key]


def share_of_limit(run: RunResult, key: str) -> str:
    """`12.6% of its limit`, or where the largest share of a limit is at another joint than the
    largest value (a prismatic lift's 1,132 N is 11 % of its limit; a shoulder's 56 Nm, 188 %):
    `on torso_lift; as a share of a joint's limit, up to 188% on r_shoulder_pan` (two joints, and
    said so: "188% of r_shoulder_pan's limit" after torso_lift's value read as one joint's, found
    from outside)."""
    s = run.summary
    share = f"{100 * s[key + '_ratio']:.3g}%"
    worst = s.get("worst_joints", {})
    joint, joint_of_ratio = worst.get(key), worst.get(key + "_ratio")
    if joint == joint_of_ratio or joint is None or joint_of_ratio is None:
        return f"{share} of its limit"
    return f"on {joint}; as a share of a joint's limit, up to {share} on {joint_of_ratio}"


def min_scaling_text(summary: dict[str, Any]) -> str:
    """`0.42 (priority 2: posture, at t = 1.234 s)`, `1 − 4e-05 (…)` (not "1" for a scaling that
    rounds to it) or `1 (never scaled)`."""
    at = summary.get("min_scaling_at")
    value = summary["min_scaling"]
    if at is None:
        return f"{value:.3g} (never scaled)"
    text = f"{value:.3g}" if f"{value:.3g}" != "1" else f"1 − {1.0 - value:.2g}"
    return f"{text} (priority {at['priority']}: {', '.join(at['tasks'])}, at t = {at['time']:.4g} s)"


def describe(run: RunResult) -> str:
    """A few lines about a run for the terminal."""
    s = run.summary
    speed = f" ({s['realtime_factor']:.3g}× real time)" if s["realtime_factor"] else ""
    lines = [f"{s['spec']}: {s['formulation']}, {s['runtime']} runtime — {s['duration']:.3g} s simulated in "
             f"{s['wall_time']:.3g} s{speed}"]
    if not s["completed"]:
        lines.append(f"  UNSTABLE   MuJoCo stopped the run at t = {s['diverged_at']:.4g} s")

    def q(key: str) -> str:
        return quantity(s[key], peak_unit(run, key))

    lines.append(f"  limits     worst excess: position {q('max_joint_position_violation')}, velocity "
                 f"{q('max_joint_velocity_violation')} ({share_of_limit(run, 'max_joint_velocity_violation')}), "
                 f"torque {q('max_torque_violation')}, Cartesian {q('max_cartesian_violation')}"
                 + (f" (speed {q('max_cartesian_velocity_violation')})" if s.get("max_cartesian_velocity_violation")
                    else "")
                 + (f", collision {q('max_collision_violation')}" if "max_collision_violation" in s else ""))
    smoothness = (f"  smoothness torque steps between periods up to {q('max_torque_jump')} "
                  f"({share_of_limit(run, 'max_torque_jump')}; {s['torque_jump_steps']} above "
                  f"{100 * TORQUE_JUMP_FRACTION:g}%), the controller's joint accelerations up to {q('max_controller_acceleration')}")
    if s["torque_jump_steps"] and not s["joint_acceleration_limits"]:
        smoothness += " (no limits.joint_acceleration: the velocity limits alone allow 2 q̇_max/T a step)"
    lines.append(smoothness)
    relaxed = (f"{s['limits_relaxed']} steps with relaxed limits" if s["limits_relaxed"] is not None else
               f"joint and Cartesian bounds not checked ({s['formulation']} is a closed form: its torque is clipped, "
               "its bounds are not rows; see the worst excess above)")
    lines.append(f"  solver     {s['solver_failures']} failures, {relaxed}, min scaling {min_scaling_text(s)}")
    if s.get("lowest_level_off_optimum_steps"):
        lines.append(f"  optimum    {s['lowest_level_off_optimum_steps']} \"ok\" steps whose answer does not minimize "
                     "the lowest level's objective given the levels above (the KKT check of each answer; the "
                     "bounds and the levels above are not affected)")
    if s.get("crossed_after_ok_steps"):
        causes = "a payload it does not know: robot.payloads; τ_ext one step late; a mass mismatch"
        if not s["joint_acceleration_limits"]:
            # (the plant holds the torque over a period, the model the acceleration: they part as
            # the acceleration grows; docs/formulations.md)
            causes += (f"; the torque held over a period, not the acceleration, at up to "
                       f"{q('max_controller_acceleration')}: a limits.joint_acceleration keeps that small")
        lines.append(f"  model      {s['crossed_after_ok_steps']} \"ok\" steps left a bound crossed further (the first at "
                     f"t = {s['crossed_after_ok_first']:.4g} s): the plant is not the controller's model ({causes})")
    for r in s.get("relaxed_bounds", {}).values():
        beyond = f"; beyond {r['beyond']}" if "beyond" in r else ""
        lines.append(f"  relaxed    {r['bound']}: {r['steps']} steps between t = {r['first']:.4g} s and {r['last']:.4g} s"
                     f"{beyond}")
    lines.append(f"  tasks      RMS error (final): {task_errors_text(s)}")
    lines.append(f"             priority-1 mean acceleration error {q('primary_mean_acceleration_error')}")
    lines.append(f"  external   disturbance torque up to {q('max_disturbance_torque')} (payloads included), "
                 f"the τ_ext estimate off by up to {q('max_external_torque_estimate_error')}")
    lines.append(f"  energy     ∫acceleration energy {q('acceleration_energy_integral')}, kinetic peaks: "
                 f"task {q('task_space_kinetic_energy_peak')}, null space {q('null_space_kinetic_energy_peak')}")
    if s["waypoints_total"]:
        lines.append(f"  waypoints  {s['waypoints_reached']}/{s['waypoints_total']} reached")
    return "\n".join(lines)


def task_errors_text(summary: dict[str, Any]) -> str:
    """`reach 1.2e-3 m (0.3e-3 m), rest [damping, velocity] 0.01 rad/s (0.002 rad/s)`."""
    units = summary["units"]["task_rms_error"]
    parts = []
    for name, rms in summary["task_rms_error"].items():
        damping = summary["task_error_quantity"][name] != "tracking error"
        label = f"{name} [damping, velocity]" if damping else name
        unit = units[name]
        parts.append(f"{label} {quantity(rms, unit)} ({quantity(summary['task_final_error'][name], unit)})")
    return ", ".join(parts) or "no tasks"
