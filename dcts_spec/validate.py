"""Semantic validation of a spec against its robot, and the summary `dcts validate` prints."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from .formulations import build_problem
from .formulations.hierarchy import OverConstrainedLevel, level_structure
from .limits.naming import bound_text, joint_force_unit
from .robot.model import Robot
from .robot.resolve import frame_candidates, locked_joints, resolve_robot
from .spec import Diagnostic, Spec, SpecError, check_structure, load_spec
from .spec.errors import did_you_mean
from .spec.scenario import run_steps_problem
from .spec.tasks import TaskSpec
from .spec.types import size_of
from .spec.units import joint_to_si, to_si
from .validate_collision import CollisionReport, check_collision, target_diagnostics
from .validate_parameters import check_parameters
from .tasks import CartesianTask, JointTask, make_task, task_dimension, task_joints

RANK_TOLERANCE = 1e-6


@dataclass
class LevelReport:
    """One priority level at the initial configuration."""

    priority: int
    tasks: list[tuple[str, str, int]]  # name, type, dimension
    dimension: int
    rank: int  # new directions this level controls beyond the higher levels
    free_before: int  # joint-space freedom left by the higher levels

    @property
    def over_constrained(self) -> bool:
        return self.rank < self.dimension


@dataclass
class ValidationReport:
    """What `dcts validate` found: the resolved robot, the levels, and every diagnostic."""

    spec: Spec
    robot: Robot
    initial_q: np.ndarray
    levels: list[LevelReport]
    gravity_torque: np.ndarray  # g(q0)
    diagnostics: list[Diagnostic] = field(default_factory=list)
    collision: CollisionReport | None = None  # with a limits.collision section

    @property
    def file(self) -> str:
        return self.spec.source.file

    @property
    def gravity_torque_ratio(self) -> float:
        """Largest share of a joint's torque limit that holding the initial configuration takes."""
        return float(np.max(np.abs(self.gravity_torque) / self.robot.limits.tau_max))

    def to_dict(self) -> dict:
        lim = self.robot.limits

        def finite(a: np.ndarray) -> list[float | None]:
            return [float(v) if np.isfinite(v) else None for v in a]

        return {
            "file": self.file,
            "valid": True,
            "name": self.spec.name,
            "robot": {"name": self.robot.name, "urdf": str(self.robot.urdf_path), "dof": self.robot.nv,
                      "joints": self.robot.joint_names},
            "formulation": self.spec.controller.formulation,
            "levels": [
                {"priority": lv.priority, "dimension": lv.dimension, "rank": lv.rank, "free_before": lv.free_before,
                 "tasks": [{"name": n, "type": t, "dimension": d} for n, t, d in lv.tasks]}
                for lv in self.levels
            ],
            "limits": {
                "q_min": finite(lim.q_min), "q_max": finite(lim.q_max), "v_max": finite(lim.v_max),
                "a_max": finite(lim.a_max), "tau_max": finite(lim.tau_max),
                "cartesian": [{"frame": b.frame, "axis": b.label, "normal": list(b.direction), "min": b.c_min if np.isfinite(b.c_min) else None,
                               "max": b.c_max if np.isfinite(b.c_max) else None} for b in self.robot.cartesian_bounds],
            },
            "gravity_torque_ratio": self.gravity_torque_ratio,
            **({"collision": self.collision.to_dict()} if self.collision else {}),
            "diagnostics": [d.to_dict() for d in self.diagnostics],
        }

    def summary(self) -> str:
        """A few lines a person reads: robot, tasks by priority, limits, warnings."""
        spec, robot, lim = self.spec, self.robot, self.robot.limits
        lines = [
            f"{self.file}: ok — {spec.name}",
            f"  robot       {robot.name} ({robot.nv} DOF: {', '.join(robot.joint_names)})"
            + "".join(f", carrying {p.mass:g} kg at {p.frame}" for p in spec.robot.payloads),
            f"  controller  {spec.controller.formulation}, solver {spec.controller.solver}, "
            f"period {spec.controller.period * 1e3:g} ms, external torque {spec.controller.external_torque}",
        ]
        for lv in self.levels:
            tasks = ", ".join(f"{n} ({t}, {d})" for n, t, d in lv.tasks)
            lines.append(f"  priority {lv.priority}  dim {lv.dimension}, rank {lv.rank} of {lv.free_before} free: {tasks}")

        def fmt(a: np.ndarray, scale: float | np.ndarray = 1.0) -> str:
            scaled = np.broadcast_to(scale, np.shape(a)) * np.where(np.isfinite(a), a, 0.0)
            return "[" + ", ".join(("∞" if v > 0 else "-∞") if not np.isfinite(v) else f"{w:.4g}"
                                   for v, w in zip(a, scaled)) + "]"

        prismatic = robot.prismatic
        deg = np.where(prismatic, 1.0, 180.0 / np.pi)  # a prismatic joint's entries stay in m, m/s, N
        lines.append(f"  limits      q ∈ {fmt(lim.q_min, deg)} .. {fmt(lim.q_max, deg)} deg")
        lines.append(f"              |q̇| ≤ {fmt(lim.v_max, deg)} deg/s, |τ| ≤ {fmt(lim.tau_max)} Nm")
        if np.isfinite(lim.a_max).any():
            lines.append(f"              |q̈| ≤ {fmt(lim.a_max, deg)} deg/s²")
        if prismatic.any():
            names = ", ".join(n for n, p in zip(robot.joint_names, prismatic) if p)
            lines.append(f"              (m, m/s, N, m/s² for the prismatic {names})")
        for b in robot.cartesian_bounds:
            lines.append(f"              {bound_text(b)}"
                         + ("" if b.axis is not None else f" (world normal {fmt(np.array(b.direction))})"))
        if self.collision:
            lines.append(self.collision.summary())
        lines.append(f"  gravity     needs {self.gravity_torque_ratio * 100:.0f}% of the torque limit at the initial configuration")
        lines.extend(f"  {d}" for d in self.diagnostics)
        return "\n".join(lines)


def validate_file(path: str | Path) -> ValidationReport:
    """Load and validate a spec file; raises SpecError listing every problem."""
    return validate_spec(load_spec(path))


def validate_spec(spec: Spec) -> ValidationReport:
    """Check a spec (its structure again, if it was edited in Python) against its robot; raises
    SpecError on errors."""
    check_structure(spec)
    robot, diags = resolve_robot(spec)
    diags += _check_tasks(spec, robot)
    diags += _check_controller(spec, robot)
    diags += _gains_at_the_period(spec)
    diags += _check_scenario(spec, robot)
    diags += check_parameters(spec, robot)
    if any(d.severity == "error" for d in diags):
        raise SpecError(diags)
    q0 = initial_configuration(spec, robot)
    diags += _check_cartesian_bounds(spec, robot, q0)
    collision, collision_diags = check_collision(spec, robot, q0)
    diags += collision_diags
    if collision is not None:
        diags += target_diagnostics(spec, robot, collision.model,
                                    [(t.frame, at, what, p) for t, at, what, p in _position_targets(spec)])
    if any(d.severity == "error" for d in diags):
        raise SpecError(diags)
    levels, level_diags = _levels(spec, robot, q0)
    diags += level_diags
    if any(d.severity == "error" for d in level_diags):
        raise SpecError(diags)
    gravity = pin.computeGeneralizedGravity(robot.model, robot.model.createData(), q0)
    over = np.flatnonzero(np.abs(gravity) > robot.limits.tau_max)
    if over.size:
        j = over[0]
        unit = joint_force_unit(robot, int(j))  # (a NumPy integer is no Pinocchio index)
        diags.append(
            spec.source.diagnostic(
                ("limits", "joint_torque") if spec.limits.joint_torque else ("robot",),
                f"the torque limits cannot hold the robot against gravity at the initial configuration "
                f"(joint {j + 1}, {robot.joint_names[j]}, needs {abs(gravity[j]):.1f} {unit}, limit "
                f"{robot.limits.tau_max[j]:.1f} {unit})",
                "warning",
            )
        )
    return ValidationReport(spec, robot, q0, levels, gravity, diags, collision)


def _check_cartesian_bounds(spec: Spec, robot: Robot, q0: np.ndarray) -> list[Diagnostic]:
    """A Cartesian bound crossed at the initial configuration is an error (the controller could
    only relax it from the first step); a constant position target on the bound's frame beyond it
    is a warning (the task will be scaled or bent there, as the bound asks)."""
    diags: list[Diagnostic] = []
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, q0)
    pin.updateFramePlacements(robot.model, data)
    targets = _position_targets(spec)
    for i, b in enumerate(robot.cartesian_bounds):
        c = float(b.coordinate(data.oMf[robot.model.getFrameId(b.frame)].translation))
        text = bound_text(b)
        if not b.c_min - 1e-9 <= c <= b.c_max + 1e-9:
            diags.append(spec.source.diagnostic(("limits", "cartesian", i),
                                                f"{b.frame}.{b.label} starts at {c:.4g} m, outside its bound {text}"))
        if robot.fixed_to_world(b.frame):
            diags.append(spec.source.diagnostic(
                ("limits", "cartesian", i, "frame"), f"{b.frame} is fixed to the world: no joint moves it, so this "
                "bound constrains nothing (it holds, or is crossed, whatever the controller does); bound a frame "
                "the robot moves", "warning"))
            continue
        reach = _acceleration_reach(robot, data, b)
        if reach < b.a_max:
            diags.append(spec.source.diagnostic(
                ("limits", "cartesian", i),
                f"the joint acceleration limits move {b.frame}.{b.label} at {reach:.3g} m/s² at most (at the initial "
                f"configuration), less than the {b.a_max:g} m/s² this bound counts on to brake before it: near the "
                f"bound it can be crossed (status \"limits relaxed\"); give it max_acceleration: {_round_down(reach)} "
                "or less", "warning"))
        for task, at, what, position in targets:
            target = float(b.coordinate(position))
            if task.frame == b.frame and not b.c_min <= target <= b.c_max:
                # (a level's tasks share its scaling: a bounded foot stopped the other feet of its level)
                peers = [t.name for t in spec.tasks if t.priority == task.priority and t.name != task.name]
                one = len(peers) == 1
                shared = (f"; {', '.join(peers)}, at the same priority, {'shares' if one else 'share'} that scaling "
                          f"and {'is' if one else 'are'} no longer driven either: give {'it' if one else 'them'} a "
                          f"priority of {'its' if one else 'their'} own to keep {'it' if one else 'them'} tracking"
                          ) if peers else ""
                diags.append(spec.source.diagnostic(
                    at, f"{what} puts {b.frame}.{b.label} at {target:.4g} m, outside its bound {text} "
                        f"(limits.cartesian[{i}]): at the bound its scaling falls to 0 (direction kept), so it stops "
                        f"accelerating {b.frame}, and motion along the bound is no longer damped{shared}; put the "
                        f"target inside", "warning"))
    return diags


def _acceleration_reach(robot: Robot, data: pin.Data, bound) -> float:
    """The largest acceleration of the bound's coordinate the joint acceleration limits allow at
    the configuration of `data` (its Jacobians computed), velocity terms aside: Σⱼ |dᵀJⱼ| a_max,j."""
    J = pin.getFrameJacobian(robot.model, data, robot.model.getFrameId(bound.frame), pin.LOCAL_WORLD_ALIGNED)
    row = np.abs(np.asarray(bound.direction) @ J[:3])
    moving = row > 0.0  # (a joint without a limit that moves it: no bound on the reach)
    if not moving.any():  # (no joint moves it here: nothing to brake)
        return float("inf")
    return float(np.sum(row[moving] * robot.limits.a_max[moving]))


def _round_down(value: float) -> str:
    """A round number at most `value` (two significant digits), for a suggestion."""
    if value <= 0.0:
        return "0"
    step = 10.0 ** (np.floor(np.log10(value)) - 1)
    return f"{np.floor(value / step) * step:.10g}"


def _position_targets(spec: Spec) -> list[tuple[TaskSpec, tuple, str, np.ndarray]]:
    """(task, key path, wording, position) of every constant position target: the references
    of position and pose tasks, and the waypoints of such a task (their position comes first)."""
    out = []
    for k, t in enumerate(spec.tasks):
        if t.type not in ("position", "pose"):
            continue
        if t.reference is not None and t.reference.position is not None:
            out.append((t, ("tasks", k, "reference", "position"), "the target", np.asarray(t.reference.position, dtype=float)))
        waypoints = spec.scenario.waypoints if spec.scenario is not None else None
        if waypoints is not None and waypoints.task == t.name:
            out += [(t, ("scenario", "waypoints", "points", j), "this waypoint", np.asarray(p[:3], dtype=float))
                    for j, p in enumerate(waypoints.points)]
    return out


def initial_configuration(spec: Spec, robot: Robot) -> np.ndarray:
    """The scenario's initial q, or the middle of the joint range."""
    if spec.scenario is not None and spec.scenario.initial_q is not None:
        return np.array(joint_to_si(list(spec.scenario.initial_q), spec.scenario.unit, robot.prismatic))
    return robot.neutral_configuration()


def _check_tasks(spec: Spec, robot: Robot) -> list[Diagnostic]:
    src, diags = spec.source, []
    seen: dict[str, int] = {}
    frames = [f.name for f in robot.model.frames]
    locked = locked_joints(spec)
    for i, task in enumerate(spec.tasks):
        at = ("tasks", i)
        # (names compared in upper case: the generated header's macros spell them so, <NAME>_REF_<TASK>_…)
        other = seen.get(task.name.upper())
        if other is not None and spec.tasks[other].name == task.name:
            diags.append(src.diagnostic(at + ("name",), f"task name {task.name!r} is already used by tasks[{other}]"))
        elif other is not None:
            diags.append(src.diagnostic(at + ("name",), f"task name {task.name!r} differs from tasks[{other}]'s "
                                        f"{spec.tasks[other].name!r} only in case: the generated C spells task names "
                                        f"in upper case in its macros (…_REF_{task.name.upper()}_…); choose another name"))
        seen.setdefault(task.name.upper(), i)
        if task.frame is not None and not robot.has_frame(task.frame):
            diags.append(src.diagnostic(at + ("frame",), f"no frame {task.frame!r} in the robot{frame_candidates(task.frame, frames, spec)}"))
        elif task.frame is not None and robot.fixed_to_world(task.frame):
            diags.append(src.diagnostic(at + ("frame",), f"frame {task.frame!r} is fixed to the world (no joint moves "
                                                         "it): a task on it can do nothing; name a frame the joints move"))
            continue
        if task.type != "joint":
            continue
        unknown = [j for j in task_joints(task, robot) if j not in robot.joint_names]
        for j in unknown:
            why = (" (it is locked in robot.locked_joints: a task cannot move it)" if j in spec.robot.locked_joints
                   else f" (the built-in {spec.robot.model} locks it: a task cannot move it)" if j in locked
                   else did_you_mean(j, robot.joint_names, 3))
            diags.append(src.diagnostic(at + ("joints",), f"no joint {j!r}{why}; joints: {', '.join(robot.joint_names)}"))
        if unknown:
            continue
        dim = task_dimension(task, robot)
        for name in ("kp", "kd"):
            size = size_of(getattr(task.gains, name))
            if size is not None and size != dim:
                diags.append(src.diagnostic(at + ("gains", name), f"{size} values for a joint task of {dim} joints"))
        if task.reference is not None and task.reference.q is not None:
            if len(task.reference.q) != dim:
                diags.append(src.diagnostic(at + ("reference", "q"), f"{len(task.reference.q)} values for a joint task of {dim} joints"))
            else:
                diags.extend(_targets_beyond_range(spec, robot, task, at))
    return diags


def _targets_beyond_range(spec: Spec, robot: Robot, task: TaskSpec, at: tuple) -> list[Diagnostic]:
    """A joint target outside the joint's position range (a warning: the joint stops at its limit
    and the level gives way there, which may be what was meant)."""
    ref, lim, prismatic, diags = task.reference, robot.limits, robot.prismatic, []
    names = task_joints(task, robot)
    indices = [robot.joint_names.index(name) for name in names]
    values = joint_to_si(list(ref.q), ref.unit, prismatic[indices])
    for i, (name, j, value) in enumerate(zip(names, indices, values, strict=True)):
        unit = "m" if prismatic[j] else ref.unit
        scale = 1.0 if prismatic[j] else to_si(1.0, ref.unit)
        lo, hi = lim.q_min[j], lim.q_max[j]
        if lo - 1e-9 <= value <= hi + 1e-9:
            continue
        diags.append(spec.source.diagnostic(
            at + ("reference", "q", i),
            f"{value / scale:.6g} {unit} is outside {name}'s range [{lo / scale:.6g}, {hi / scale:.6g}] {unit}: the "
            f"joint stops at its limit and this priority level gives way there", "warning"))
    return diags


def _gains_at_the_period(spec: Spec) -> list[Diagnostic]:
    """A warning where a task's PD is unstable at the control period. Each level gets its commanded
    acceleration exactly, so each axis is a double integrator held over the period T:
    ẍ = kp Δx − kd ẋ is stable in discrete time only for kp T / 2 < kd < 2 / T (Jury's test on
    x, ẋ over one period). kd T ≥ 2 turns the damping over at every step (the velocity times
    1 − kd T): a stiff, critically damped task at 250 Hz (kp 1e5, kd 632) swung its torques between
    the limits at every period. kd ≤ kp T / 2 lets the oscillation grow (kd = 0 too, slowly)."""
    period, diags = spec.controller.period, []
    for i, task in enumerate(spec.tasks):
        axes = task.gains.axes()
        if not axes:
            continue
        kp, kd = np.array(axes, dtype=float).T
        over = kd * period >= 2.0
        under = (kp > 0) & (kd <= kp * period / 2)
        if over.any():
            k = int(np.argmax(kd))
            diags.append(spec.source.diagnostic(
                ("tasks", i, "gains", "kd"),
                f"kd × controller.period = {kd[k]:g} × {period:g} s = {kd[k] * period:.3g} ≥ 2: at this period the "
                f"damping is unstable (each step multiplies the task's velocity by 1 − kd T = {1 - kd[k] * period:.3g}), "
                f"and the torque swings between its limits; use kd < {2 / period:g} 1/s or a shorter period", "warning"))
        elif under.any():
            k = int(np.flatnonzero(under)[0])
            diags.append(spec.source.diagnostic(
                ("tasks", i, "gains", "kd"),
                f"kd = {kd[k]:g} 1/s is at most kp × controller.period / 2 = {kp[k] * period / 2:.3g}: at this period "
                f"the task's oscillation grows{' (undamped)' if kd[k] == 0 else ''}; raise kd (critical damping: "
                f"2√kp = {2 * np.sqrt(kp[k]):.3g}) or shorten the period", "warning"))
    return diags


def _check_controller(spec: Spec, robot: Robot) -> list[Diagnostic]:
    src, ctl, diags = spec.source, spec.controller, []
    n_levels = len(spec.priority_levels)
    if ctl.priority_weights is not None and len(ctl.priority_weights) != n_levels:
        diags.append(src.diagnostic(("controller", "priority_weights"),
                                    f"{len(ctl.priority_weights)} weights for {n_levels} priority levels"))
    elif ctl.priority_weights is not None and ctl.formulation == "dcts":
        diags.append(src.diagnostic(("controller", "priority_weights"),
                                    "no effect on dcts, which solves its priority levels lexicographically; the "
                                    "weights apply to qp_mt and qp_md only", "warning"))
    unkept = {"osc": "keeps no limit (its torque is only clipped)",
              "projector": "keeps the joint limits only (its torque is clipped)"}.get(ctl.formulation)
    for section in ("cartesian", "collision"):
        if unkept and getattr(spec.limits, section):  # (the run's summary then read "ok", inside an obstacle)
            diags.append(src.diagnostic(
                ("limits", section), f"formulation {ctl.formulation} {unkept}: these {section} limits are not "
                f"held, and its steps say \"ok\" all the same (dcts, qp_mt and qp_md hold them)", "warning"))
    for name in ("joint_damping", "fallback_damping"):
        size = size_of(getattr(ctl, name))
        if size is not None and size != robot.nv:
            diags.append(src.diagnostic(("controller", name), f"{size} values for {robot.nv} joints"))
    return diags


def _check_scenario(spec: Spec, robot: Robot) -> list[Diagnostic]:
    sc, src, n, diags = spec.scenario, spec.source, robot.nv, []
    if sc is None:
        return diags
    at = ("scenario",)
    if (problem := run_steps_problem(sc.duration, spec.controller.period)) is not None:
        diags.append(src.diagnostic(at + ("duration",), problem))
    for name in ("initial_q", "initial_dq"):
        value = getattr(sc, name)
        if value is not None and len(value) != n:
            diags.append(src.diagnostic(at + (name,), f"{len(value)} values for {n} joints"))
    if sc.initial_q is not None and len(sc.initial_q) == n:
        q0 = np.array(joint_to_si(list(sc.initial_q), sc.unit, robot.prismatic))
        outside = np.flatnonzero((q0 < robot.limits.q_min) | (q0 > robot.limits.q_max))
        if outside.size:
            prismatic = robot.prismatic
            unit = ["m" if p else sc.unit for p in prismatic]
            scale = np.where(prismatic, 1.0, 180.0 / np.pi if sc.unit == "deg" else 1.0)
            beyond = np.maximum(robot.limits.q_min - q0, q0 - robot.limits.q_max) * scale
            where = "; ".join(f"joint {j + 1} ({robot.joint_names[j]}) at {q0[j] * scale[j]:.4g}, {beyond[j]:.3g} "
                              f"{unit[j]} beyond its limits [{robot.limits.q_min[j] * scale[j]:.4g}, "
                              f"{robot.limits.q_max[j] * scale[j]:.4g}] {unit[j]}" for j in outside)
            diags.append(src.diagnostic(at + ("initial_q",), f"joints start outside their position limits: {where}"))
    if sc.initial_dq is not None and len(sc.initial_dq) == n:
        dq0 = np.abs(joint_to_si(list(sc.initial_dq), sc.unit, robot.prismatic))
        fast = np.flatnonzero(dq0 > robot.limits.v_max)
        if fast.size:
            where = ", ".join(f"joint {j + 1} ({robot.joint_names[j]}) at {dq0[j] / robot.limits.v_max[j]:.3g} × its "
                              "limit" for j in fast)
            diags.append(src.diagnostic(at + ("initial_dq",), f"joints start beyond their velocity limits: {where} (the "
                                        "first steps are relaxed ones, braking as hard as the torque limits allow)",
                                        "warning"))
    frames = [f.name for f in robot.model.frames]
    for i, d in enumerate(sc.disturbances):
        where = at + ("disturbances", i)
        if d.type == "force":
            if not robot.has_frame(d.body):
                diags.append(src.diagnostic(where + ("body",), f"no link or frame {d.body!r}{frame_candidates(d.body, frames, spec)}"))
                continue
            if robot.fixed_to_world(d.body):
                diags.append(src.diagnostic(where + ("body",), f"{d.body} is fixed to the world: the robot does not feel "
                                            "this push", "warning"))
            if not any(d.force) and not any(d.torque):
                diags.append(src.diagnostic(where, "neither force nor torque: this push does nothing", "warning"))
            diags += _push_sampling(spec, d, where)
        elif len(d.torque) != n:
            diags.append(src.diagnostic(where + ("torque",), f"{len(d.torque)} values for {n} joints"))
        elif 2 * d.ramp > d.duration:
            diags.append(src.diagnostic(where + ("ramp",), f"a rise and a fall of {d.ramp:g} s each in a duration of "
                                        f"{d.duration:g} s (ramps included): it never reaches its full torque", "warning"))
    late = [(("disturbances", i, "start"), "this push starts", d.start) for i, d in enumerate(sc.disturbances)]
    late += [(("parameters", i, "time"), "this parameter change comes", c.time) for i, c in enumerate(sc.parameters)]
    for where, what, time in late:
        if time >= sc.duration:
            diags.append(src.diagnostic(at + where, f"{what} at {time:g} s, not before the run ends "
                                        f"(scenario.duration: {sc.duration:g} s): it has no effect", "warning"))
    for i, p in enumerate(sc.payloads):
        if not robot.has_frame(p.frame):
            diags.append(src.diagnostic(at + ("payloads", i, "frame"), f"no frame {p.frame!r}{frame_candidates(p.frame, frames, spec)}"))
        elif robot.fixed_to_world(p.frame):
            diags.append(src.diagnostic(at + ("payloads", i, "frame"), f"{p.frame} is fixed to the world: the robot does "
                                        "not carry this payload", "warning"))
    sensing = sc.sensing
    for name in ("noise_std", "bias"):
        value = getattr(sensing, name)
        size = size_of(value)
        if size is not None and size != n:
            diags.append(src.diagnostic(at + ("external_torque", name), f"{size} values for {n} joints"))
        elif sensing.mode != "noisy" and np.any(np.asarray(value) != 0):
            diags.append(src.diagnostic(at + ("external_torque", name), f"acts only with mode: noisy (the mode is "
                                        f"{sensing.mode}): it has no effect", "warning"))
    if sc.waypoints is not None:
        diags += _check_waypoints(spec, robot)
    return diags


def _push_sampling(spec: Spec, push, where: tuple) -> list[Diagnostic]:
    """A warning when the simulation's steps give a push much more or less time than its duration:
    MuJoCo holds a force over whole steps, those that start in [start, start + duration) (a 0.4 ms
    push between two 1 ms steps acted on none, one at a step's start for the whole 1 ms)."""
    step = spec.controller.period / spec.scenario.substeps  # type: ignore[union-attr]
    first, end = (math.ceil(t / step - 1e-9) for t in (push.start, push.start + push.duration))
    applied = (end - first) * step
    if abs(applied - push.duration) <= 0.1 * push.duration:
        return []
    return [spec.source.diagnostic(where + ("duration",), (
        f"the simulation's steps of {step:g} s give this push {applied:g} s of force for its {push.duration:g} s (MuJoCo "
        "holds a force over whole steps): make it last several steps, or raise scenario.substeps"), "warning")]


def _check_waypoints(spec: Spec, robot: Robot) -> list[Diagnostic]:
    wp, src = spec.scenario.waypoints, spec.source  # type: ignore[union-attr]
    at = ("scenario", "waypoints")
    names = [t.name for t in spec.tasks]
    if wp.task not in names:
        return [src.diagnostic(at + ("task",), f"no task {wp.task!r}{did_you_mean(wp.task, names)}; tasks: {', '.join(names)}")]
    task = spec.tasks[names.index(wp.task)]
    if task.reference is None or not task.reference.input:
        return [src.diagnostic(at + ("task",), f"task {wp.task!r} needs `reference: {{input: true}}` to follow waypoints")]
    if not _task_resolves(task, robot):
        return []  # the task's unknown frame or joint is reported; the size of its reference is unknown
    size = sum(f[1] for f in make_task(task, robot).reference_fields())
    return [
        src.diagnostic(at + ("points", i), f"{len(p)} values, but task {wp.task!r} takes a reference of {size}")
        for i, p in enumerate(wp.points)
        if len(p) != size
    ]


def _task_resolves(task: TaskSpec, robot: Robot) -> bool:
    """Whether a task's frame or joints are the robot's (else `_check_tasks` reports them)."""
    if task.type != "joint":
        return task.frame is not None and robot.has_frame(task.frame)
    return all(j in robot.joint_names for j in task_joints(task, robot))


def _levels(spec: Spec, robot: Robot, q: np.ndarray) -> tuple[list[LevelReport], list[Diagnostic]]:
    """Dimension and rank of each priority level at q, with warnings for conflicts and singularities."""
    model = robot.model
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    levels, diags = [], []
    stacked = np.zeros((0, robot.nv))
    priorities = spec.priority_levels
    asked = 0  # directions the levels so far ask for
    conflicting = []  # levels above the lowest that conflict with the higher ones at q (only here?)
    for p in priorities:
        rows, entries = [], []
        for task_spec in spec.tasks_at(p):
            task = make_task(task_spec, robot)
            J = _numeric_jacobian(task, model, data)
            entries.append((task.name, task_spec.type, task.dim))
            rows.append(J)
            rank = np.linalg.matrix_rank(J, RANK_TOLERANCE)
            if rank < task.dim:
                i = spec.tasks.index(task_spec)
                message = f"task {task.name!r} is singular at the initial configuration (rank {rank} < {task.dim})"
                diags.append(spec.source.diagnostic(("tasks", i), message, "warning"))
        J_level = np.vstack(rows)
        # Plain ints: numpy's would not survive `--json` (json.dumps rejects numpy.int64).
        before = int(np.linalg.matrix_rank(stacked, RANK_TOLERANCE)) if stacked.size else 0
        stacked = np.vstack([stacked, J_level])
        after = int(np.linalg.matrix_rank(stacked, RANK_TOLERANCE))
        level = LevelReport(p, entries, J_level.shape[0], after - before, robot.nv - before)
        levels.append(level)
        asked += level.dimension
        if p == priorities[-1] and before == robot.nv:  # (a higher level with none left is an error below)
            diags.append(spec.source.diagnostic(
                spec.priority_path(p),
                f"priority {p} gets no freedom: the higher priorities take all {robot.nv} of the robot's joint "
                "directions, so its tasks can have no effect (give the higher priorities fewer axes, or remove "
                "these tasks)", "warning"))
        if level.over_constrained and p != priorities[-1]:
            if asked > robot.nv:  # at every configuration, not only this one: the controller cannot be built
                diags.append(spec.source.diagnostic(
                    spec.priority_path(p),
                    f"priority {p} asks for {level.dimension} directions, and with the higher priorities "
                    f"{asked} of the robot's {robot.nv} joints' directions: only the lowest priority may be "
                    "over-constrained (give these tasks the lowest priority, or fewer axes)"))
            else:
                conflicting.append(level)
    if conflicting:  # (compile's own check, once, whichever levels conflict here)
        structure_error = _over_constrained_everywhere(spec, robot)
        if structure_error is not None:
            diags.append(spec.source.diagnostic(spec.priority_path(structure_error.priority), str(structure_error)))
        else:
            diags += [spec.source.diagnostic(
                spec.priority_path(level.priority),
                f"priority {level.priority} asks for {level.dimension} directions but only {level.rank} are free of "
                "higher priorities at the initial configuration; only the lowest priority may be over-constrained",
                "warning") for level in conflicting]
    return levels, diags


def _over_constrained_everywhere(spec: Spec, robot: Robot) -> OverConstrainedLevel | None:
    """What compiling the spec would say of its levels' structure (`level_structure`, at the
    configurations it samples), asked where one conflicts at the initial configuration: validate
    said "ok" to a spec that `compile` then refused."""
    try:
        level_structure(build_problem(spec, robot))
    except OverConstrainedLevel as error:
        return error
    return None


def _numeric_jacobian(task: CartesianTask | JointTask, model: pin.Model, data: pin.Data) -> np.ndarray:
    if isinstance(task, CartesianTask):
        frame = model.getFrameId(task.frame)
        J = pin.getFrameJacobian(model, data, frame, pin.LOCAL_WORLD_ALIGNED)
        return task.numeric_jacobian(J, data.oMf[frame].rotation)
    return task.selection_matrix()
