"""Checks of the spec's `parameters` section against its tasks and the robot's limits."""

from __future__ import annotations

import numpy as np

from .formulations.parameters import ParameterError, build_parameters
from .parameter_ramp import ramp_steps
from .robot.model import Robot
from .spec import Diagnostic, Spec
from .spec.errors import did_you_mean
from .tasks import make_task


def check_parameters(spec: Spec, robot: Robot) -> list[Diagnostic]:
    """Every named task exists and has what its run-time fields replace; every limit group has a
    finite compiled limit to narrow; nothing is named twice."""
    settings, src, diags = spec.parameters, spec.source, []
    if settings is None:
        return _check_schedule(spec, robot)
    period = spec.controller.period
    if settings.ramp_time and ramp_steps(settings.ramp_time, period) == 1:  # (0 asks for no ramp)
        diags.append(src.diagnostic(("parameters", "ramp_time"), f"{settings.ramp_time:g} s is at most one control "
                                    f"period ({period:g} s): a new set is taken at once, with no ramp (a gain or limit "
                                    f"change steps the torque); use at least a few periods", "warning"))
    tasks = {t.name: t for t in spec.tasks}
    for name, fields in settings.tasks.items():
        at = ("parameters", "tasks", name)
        task = tasks.get(name)
        if task is None:
            diags.append(src.diagnostic(at, f"no task {name!r}{did_you_mean(name, list(tasks))}; tasks: {', '.join(tasks)}"))
            continue
        for i, field in enumerate(fields):
            where = at + (i,)
            if field in fields[:i]:
                diags.append(src.diagnostic(where, f"{field!r} is named twice"))
            elif field == "max_velocity" and task.gains.max_velocity is None:
                diags.append(src.diagnostic(where, f"task {name!r} has no gains.max_velocity to change at run time; "
                                                   "give it one in the spec (the compiled value is the default)"))
            elif field == "reference" and (task.reference is None or task.reference.input):
                what = "its reference is already a run-time input (`input: true`)" if task.reference else "it has no reference"
                diags.append(src.diagnostic(where, f"task {name!r}: {what}; `reference` makes a constant reference "
                                                   "a run-time parameter"))
    lim = robot.limits
    finite = {
        "joint_position": np.isfinite(lim.q_min).any() or np.isfinite(lim.q_max).any(),
        "joint_velocity": np.isfinite(lim.v_max).any(),
        "joint_acceleration": np.isfinite(lim.a_max).any(),
        "joint_torque": np.isfinite(lim.tau_max).any(),
        "cartesian": bool(robot.cartesian_bounds),
    }
    for i, group in enumerate(settings.limits):
        where = ("parameters", "limits", i)
        if group in settings.limits[:i]:
            diags.append(src.diagnostic(where, f"{group!r} is named twice"))
        elif not finite[group]:
            source = "limits.cartesian" if group == "cartesian" else f"limits.{group}"
            diags.append(src.diagnostic(where, f"the compiled controller has no {group.replace('_', ' ')} limit to "
                                               f"narrow at run time; give one in {source} (it becomes the envelope)"))
    return diags or _check_schedule(spec, robot)


def _check_schedule(spec: Spec, robot: Robot) -> list[Diagnostic]:
    """Each of the scenario's parameter changes, applied in time order over the set before it,
    names parameters of the controller and gives a valid set."""
    changes = [] if spec.scenario is None else spec.scenario.parameters
    if not changes:
        return []
    try:
        tasks = [make_task(t, robot) for t in spec.tasks]
    except ValueError:  # (a task that does not resolve: reported by the task checks)
        return []
    layout = build_parameters(spec, robot, tasks).layout
    values, diags = layout.defaults, []
    for i in sorted(range(len(changes)), key=lambda i: changes[i].time):
        try:
            values = layout.vector(dict(changes[i].values), values)
            layout.check(values)
        except ParameterError as error:
            at = ("scenario", "parameters", i, "values")
            key = at + (error.field,) if error.field in changes[i].values else at
            diags.append(spec.source.diagnostic(key, str(error)))
            break
    return diags
