"""The closed loop: the compiled controller drives the MuJoCo robot through a scenario."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from ..controller import STATUS_LIMITS_RELAXED
from ..formulations.parameters import ParameterLayout
from ..parameter_ramp import ParameterRamp, ramp_steps
from ..robot.collision import resolve_collision
from ..robot.model import Robot
from ..spec import Spec, load_spec
from ..tasks import make_task
from ..validate import validate_spec
from .disturbances import Disturbances
from .log import SimulationLog
from .mismatch import scaled_robot
from .mujoco_model import build_mujoco_model
from .references import WaypointFollower, initial_references
from .runtime import Runtime, make_runtime
from .scenario import Scenario, resolve_scenario
from .sensing import TorqueSensor

if TYPE_CHECKING:
    from ..codegen import BundleCache


@dataclass(frozen=True)
class Hook:
    """Called as `call(k)` after every `every` control steps (k: the step just simulated)."""

    every: int
    call: Callable[[int], None]


class Simulation:
    """One spec's robot in MuJoCo with a runtime in the loop; `run` simulates the scenario."""

    def __init__(self, spec: Spec, robot: Robot, scenario: Scenario, runtime: Runtime,
                 controller_robot: Robot | None = None, runtime_kind: str = "python",
                 formulation: str | None = None):
        self.spec = spec
        self.robot = robot  # the simulated robot (without payloads)
        self.controller_robot = controller_robot or robot
        self.scenario = scenario
        self.runtime = runtime
        self.runtime_kind = runtime_kind
        self.formulation = formulation or spec.controller.formulation
        self.collision = resolve_collision(spec, robot)[0]  # its shapes in MuJoCo; the analysis' pairs
        self.mj_model = build_mujoco_model(robot.model, timestep=scenario.timestep, integrator=scenario.integrator,
                                           payloads=scenario.payloads, scenery=True, collision=self.collision)
        self.mj_data = mujoco.MjData(self.mj_model)
        self.tasks = [make_task(t, robot) for t in spec.tasks]
        self.initial_ref = initial_references(self.tasks, runtime.ref_layout, robot, scenario.q0)
        self.waypoints: WaypointFollower | None = None
        if scenario.waypoints is not None:
            task = next(t for t in self.tasks if t.name == scenario.waypoints.task)
            self.waypoints = WaypointFollower(scenario.waypoints, task, runtime.ref_layout, robot, self.param_layout)

    @property
    def param_layout(self) -> ParameterLayout:
        """The runtime's run-time parameters (none for a runtime without them)."""
        return getattr(self.runtime, "param_layout", None) or ParameterLayout()

    def reset(self) -> None:
        """MuJoCo at the scenario's initial state."""
        mujoco.mj_resetData(self.mj_model, self.mj_data)
        self.mj_data.qpos[:] = self.scenario.q0
        self.mj_data.qvel[:] = self.scenario.dq0
        mujoco.mj_forward(self.mj_model, self.mj_data)

    def run(self, hooks: Sequence[Hook] = ()) -> SimulationLog:
        """Simulate the whole scenario, or until MuJoCo rejects the state or the torque."""
        sc, m, d = self.scenario, self.mj_model, self.mj_data
        steps, substeps, period = sc.steps, sc.substeps, sc.period
        n = self.robot.nv
        levels = len(self.runtime.priorities)
        bound_names = list(getattr(self.runtime, "bound_names", []))
        log = SimulationLog.allocate(steps, n, self.initial_ref.size, levels, period, bound_names,
                                     self.param_layout.size)
        disturbances = Disturbances(sc, self.robot.model, m)
        sensor = TorqueSensor(sc.sensing, self.controller_robot.model, steps,
                              at_start=sc.integrator != "rk4" and substeps == 1)
        follower = self.waypoints
        # Run-time parameter changes, given to the runtime at their time; `ramp` replays the ramp
        # both runtimes apply, for the log (parameter_ramp.py)
        changes = sorted(sc.parameter_changes, key=lambda c: c.time)
        layout = self.param_layout
        ramp = ParameterRamp(layout.defaults, ramp_steps(layout.ramp_time, period), layout.periodic)
        if changes:
            self.runtime.set_params(layout.defaults)
        params = log.param
        ref = self.initial_ref.copy()
        self.reset()
        # Locals: attribute look-ups cost as much as the small numpy operations here.
        q, dq, ddq, tau, ddq_cmd = log.q, log.dq, log.ddq, log.tau, log.ddq_commanded
        tau_true, tau_meas, refs, times = log.tau_ext_true, log.tau_ext_measured, log.ref, log.time
        scaling, status, optimal = log.scaling, log.status, log.optimal
        substep_tau = np.zeros(n)  # a later substep's τ_ext, summed into the period's
        step, mj_step, ctrl = self.runtime.step, mujoco.mj_step, d.ctrl
        # The C runtime writes its outputs straight into the log (no result objects per step).
        step_into = getattr(self.runtime, "step_into", None)
        # MuJoCo resets the state on a huge acceleration and zeroes a huge or NaN control: either
        # makes the rest of the run meaningless.
        bad_qacc, bad_ctrl = d.warning[mujoco.mjtWarning.mjWARN_BADQACC], d.warning[mujoco.mjtWarning.mjWARN_BADCTRL]
        warn_handler = mujoco.get_mju_user_warning()
        mujoco.set_mju_user_warning(lambda message: None)  # divergence is reported in the log instead
        start = time.perf_counter()
        hook_time = 0.0  # viewer, video and progress display: not part of the loop's speed
        done = steps
        try:
            for k in range(steps):
                q[k] = d.qpos
                dq[k] = d.qvel
                if k:
                    np.subtract(dq[k], dq[k - 1], out=ddq[k - 1])
                    ddq[k - 1] /= period
                sensor.measure(k, q[k - 1], dq[k - 1], q[k], dq[k], ddq[k - 1], tau[k - 1], tau_meas[k])
                while changes and times[k] >= changes[0].time - 1e-9 * period:
                    values = layout.vector(dict(changes.pop(0).values), ramp.target)
                    self.runtime.set_params(values)
                    ramp.set(values)
                params[k] = ramp.advance()
                if follower is not None:  # (its segments timed with the gains set, not half-way along a ramp)
                    if k == 0:  # (after the changes at t = 0: the first segment is timed with them)
                        follower.restart(ref, ramp.target)
                    follower.update(times[k], q[k], ref, ramp.target)
                refs[k] = ref
                if step_into is not None:
                    status[k] = step_into(q[k], dq[k], tau_meas[k], ref, tau[k], ddq_cmd[k], scaling[k])
                    ctrl[:] = tau[k]
                    if status[k] == STATUS_LIMITS_RELAXED:
                        _mark(log, k, self.runtime.last_relaxed())
                    optimal[k] = _flag(self.runtime.last_optimal())
                else:
                    result = step(q[k], dq[k], tau_meas[k], ref)
                    ctrl[:] = tau[k] = result.tau
                    ddq_cmd[k] = result.ddq
                    scaling[k] = result.scaling
                    status[k] = result.status
                    _mark(log, k, result.relaxed)
                    optimal[k] = _flag(result.optimal)
                # τ_ext of the period is the mean of its substeps' (the impulse over T, what the motion
                # and the motion-based estimate see): a push starting or ending mid-period counts.
                for s in range(substeps):
                    j = k * substeps + s
                    disturbances.apply(m, d, j)
                    if s == 0:
                        disturbances.generalized(m, d, j, tau_true[k])
                    else:
                        disturbances.generalized(m, d, j, substep_tau)
                        tau_true[k] += substep_tau
                    mj_step(m, d)
                if substeps > 1:
                    tau_true[k] /= substeps
                if bad_qacc.number or bad_ctrl.number:
                    log.diverged_at = float(times[k])
                    done = k  # step k has no valid successor
                    break
                for hook in hooks:
                    if (k + 1) % hook.every == 0:
                        hook_start = time.perf_counter()
                        hook.call(k)
                        hook_time += time.perf_counter() - hook_start
            else:
                ddq[-1] = (d.qvel - dq[-1]) / period
        finally:
            mujoco.set_mju_user_warning(warn_handler)
        log.wall_time = time.perf_counter() - start - hook_time
        if done < steps:
            log.truncate(done)
        if follower is not None:
            log.waypoint_times = follower.reached_at.copy()
        return log


def prepare_simulation(spec: Spec | str | Path, runtime: str = "python", formulation: str | None = None,
                       duration: float | None = None, work_dir: str | Path | None = None,
                       cache: bool | BundleCache = True) -> Simulation:
    """Validate the spec, resolve its scenario, build the runtime and the MuJoCo model.

    The C runtime comes from the bundle cache unless `cache` is False (then it is built in
    `work_dir`); with model mismatch it is generated for the scaled model.

    Raises SpecError for a broken spec or a missing scenario, RuntimeUnavailable when the
    runtime cannot be built here. `spec`: a Spec or a spec file, as for `build_controller`.
    """
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    report = validate_spec(spec)
    scenario = resolve_scenario(spec, report.robot)
    if duration is not None:
        scenario = scenario.with_duration(duration)
    controller_robot = scaled_robot(report.robot, scenario.mass_scale)
    changes = {"mass_scale": scenario.mass_scale} if scenario.mass_scale != 1.0 else None
    rt = make_runtime(spec, runtime, formulation, robot=controller_robot, work_dir=work_dir, cache=cache,
                      model_changes=changes)
    return Simulation(spec, report.robot, scenario, rt, controller_robot, runtime, formulation)


def _flag(optimal: bool | None) -> int:
    """StepResult.optimal as the log keeps it: 1, 0, or −1 where not checked."""
    return -1 if optimal is None else int(optimal)


def _mark(log: SimulationLog, k: int, relaxed: list[str]) -> None:
    """Record which bounds gave way at step k."""
    for name in relaxed:
        log.relaxed[k, log.bound_names.index(name)] = True
