"""Quantities derived from a simulation log after the run, for all samples at once.

One CasADi function of (q, q̇, ref, a) — task errors, task-acceleration errors, frame
positions, M, g and the stacked task Jacobian — is mapped over the samples; the energies
are then batched NumPy linear algebra. Everything uses the simulated robot's rigid-body
model (true masses, no payloads): the payloads and the controller's model errors are what
is being measured against.

A pure damping task (no reference, kd only) has no position error; its error here is its
velocity error 0 − ẋ, in units per second.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np
import pinocchio as pin

from ..formulations import ControlProblem, build_problem
from ..formulations.parameters import LimitsInForce, limits_in_force
from ..robot.model import Robot
from ..sim.log import SimulationLog
from ..spec import Spec
from ..spec.scenario import Payload
from ..tasks import CartesianTask
from .units import level_units, pure_damping, task_error_units

PINV_RCOND = 1e-10  # relative cut-off of the pseudo-inverse of J M⁻¹ Jᵀ


@dataclass
class TimeSeries:
    """Per-sample derived quantities, aligned with the log."""

    task_errors: dict[str, np.ndarray]  # task → (N, m) Δx; −ẋ for a pure damping task
    acceleration_errors: dict[int, np.ndarray]  # priority → (N, m) J a + J̇q̇ − ẍ_d
    frame_positions: dict[str, np.ndarray]  # frame → (N, 3), Cartesian task and bound frames
    frame_velocities: dict[str, np.ndarray]  # frame → (N, 3), the velocity of its origin (world axes)
    kinetic_energy: np.ndarray  # ½ q̇ᵀ M q̇
    task_kinetic_energy: np.ndarray  # ½ ẋᵀ Λ ẋ, all task rows stacked
    null_kinetic_energy: np.ndarray  # the rest
    acceleration_energy: np.ndarray  # ½ (τ − g)ᵀ M⁻¹ (τ − g)
    payload_torque: np.ndarray  # (N, n) joint torque the scenario's payloads exert (0 without)
    tau_ext_used: np.ndarray  # (N, n) the τ_ext the controller used: the measured one, 0 if it ignores it
    controller_acceleration: np.ndarray  # (N, n) a = M_c⁻¹(τ + τ_ext,used − ν_c − g_c): what joint_acceleration bounds
    damping: tuple[str, ...]  # pure damping tasks: their task_errors are velocity errors
    task_units: dict[str, str]  # task → unit of its task_errors rows ("m", "rad", "rad/s", "m, rad")
    level_tasks: dict[int, tuple[str, ...]]  # priority → its tasks
    level_units: dict[int, str]  # priority → unit of its rows' positions (accelerations: per s²)
    limits: LimitsInForce  # the limits each sample was held to: the compiled ones, as run-time parameters set them

    def arrays(self) -> dict[str, np.ndarray]:
        """Flat name → array, for saving next to the log."""
        out = {f"{'velocity_error' if k in self.damping else 'error'}_{k}": v for k, v in self.task_errors.items()}
        out |= {f"acceleration_error_{k}": v for k, v in self.acceleration_errors.items()}
        out |= {f"position_{k}": v for k, v in self.frame_positions.items()}
        for name in ("kinetic_energy", "task_kinetic_energy", "null_kinetic_energy", "acceleration_energy",
                     "payload_torque", "tau_ext_used", "controller_acceleration"):
            out[name] = getattr(self, name)
        return out


def evaluate(spec: Spec, robot: Robot, log: SimulationLog, problem: ControlProblem | None = None,
             controller_robot: Robot | None = None) -> TimeSeries:
    """Derived time series of a run of `spec` on `robot` (the simulated robot). `problem`: the
    spec's symbolic problem on that robot if the caller has it (building it is most of the time
    of a short run's analysis; a campaign's samples share it). `controller_robot`: the model the
    controller was built on, if it differs (model mismatch)."""
    problem = problem or build_problem(spec, robot)
    n, samples = problem.n, log.steps
    a = ca.SX.sym("a", n)
    levels = problem.levels
    frames = _cartesian_frames(robot, problem)
    jacobian = ca.vertcat(*[lv.jacobian for lv in levels])
    outputs = {
        "error": ca.vertcat(*[lv.error for lv in levels]),
        "acceleration_error": ca.vertcat(*[ca.mtimes(lv.jacobian, a) + lv.bias - lv.target for lv in levels]),
        "position": ca.vertcat(*[problem.sym.frame_placement(f)[0] for f in frames]) if frames else ca.SX(0, 1),
        "velocity": ca.vertcat(*[ca.mtimes(problem.sym.frame_jacobian(f)[:3, :], problem.dq) for f in frames])
        if frames else ca.SX(0, 1),
        "M": ca.reshape(problem.mass_matrix, n * n, 1),
        "g": problem.gravity,
        "J": ca.reshape(jacobian, jacobian.numel(), 1),
    }
    function = ca.Function("series", [problem.q, problem.dq, problem.ref, problem.param, a], list(outputs.values()))
    param = log.param if log.param.shape == (samples, problem.param.shape[0]) else np.tile(
        problem.param_layout.defaults, (samples, 1))  # (a log from before run-time parameters)
    if samples == 0:
        values = [np.zeros((samples, int(v.numel()))) for v in outputs.values()]
    else:
        mapped = function.map(samples, "thread", 2)
        values = [np.array(v).T for v in mapped(log.q.T, log.dq.T, log.ref.T, param.T, log.ddq.T)]
    out = dict(zip(outputs, values, strict=True))

    # CasADi reshapes column-major: the flat vector holds the columns one after the other.
    M = out["M"].reshape(samples, n, n).transpose(0, 2, 1)
    m = jacobian.shape[0]
    J = out["J"].reshape(samples, n, m).transpose(0, 2, 1)
    velocity_error = -np.einsum("kij,kj->ki", J, log.dq)

    task_errors, acceleration_errors, damping, row = {}, {}, [], 0
    for lv in levels:
        acceleration_errors[lv.priority] = out["acceleration_error"][:, row: row + lv.dim]
        for task in lv.tasks:
            rows = slice(row, row + task.dim)
            if pure_damping(task):
                damping.append(task.name)
                task_errors[task.name] = velocity_error[:, rows]
            else:
                task_errors[task.name] = out["error"][:, rows]
            row += task.dim
    positions = {f: out["position"][:, 3 * i: 3 * i + 3] for i, f in enumerate(frames)}
    velocities = {f: out["velocity"][:, 3 * i: 3 * i + 3] for i, f in enumerate(frames)}
    level_tasks = {lv.priority: tuple(t.name for t in lv.tasks) for lv in levels}

    kinetic, task_kinetic = _kinetic_energies(M, J, log.dq)
    effort = log.tau - out["g"]
    acceleration_energy = 0.5 * np.einsum("ki,ki->k", effort, np.linalg.solve(M, effort[..., None])[..., 0])
    payloads = spec.scenario.payloads if spec.scenario is not None else []
    # (problem.py: with `ignored` the controller's tasks and limits take τ_ext = 0, whatever it is given)
    used = log.tau_ext_measured if spec.controller.external_torque == "measured" else np.zeros_like(log.tau)
    return TimeSeries(task_errors, acceleration_errors, positions, velocities, kinetic, task_kinetic,
                      kinetic - task_kinetic, acceleration_energy, payload_torque(robot, payloads, log), used,
                      controller_acceleration(log, used, M if controller_robot is None or controller_robot is robot
                                              else _mass_matrices(controller_robot, log.q)),
                      tuple(damping), task_error_units(levels, robot), level_tasks, level_units(levels, robot),
                      limits_in_force(problem.param_layout, param, robot))


def payload_torque(robot: Robot, payloads: Sequence[Payload], log: SimulationLog) -> np.ndarray:
    """The joint torque the payloads (point masses at frames, unknown to the controller) exert on
    the robot at each step, with the step's actual acceleration: what the τ_ext estimate sees of
    them, rnea(q, q̇, a) − rnea_with_payloads(q, q̇, a)."""
    out = np.zeros_like(log.tau)
    if not payloads or not log.steps:
        return out
    model = robot.model
    loaded = model.copy()
    for p in payloads:
        frame = loaded.frames[loaded.getFrameId(p.frame)]
        mass = pin.Inertia(float(p.mass), frame.placement.act(np.array(p.com, dtype=float)), np.zeros((3, 3)))
        loaded.inertias[frame.parentJoint] = loaded.inertias[frame.parentJoint] + mass
    data, loaded_data = model.createData(), loaded.createData()
    for k in range(log.steps):
        out[k] = pin.rnea(model, data, log.q[k], log.dq[k], log.ddq[k]) - pin.rnea(
            loaded, loaded_data, log.q[k], log.dq[k], log.ddq[k])
    return out


def controller_acceleration(log: SimulationLog, tau_ext_used: np.ndarray, M_c: np.ndarray) -> np.ndarray:
    """The joint acceleration the controller solved for at each step, with its model (M_c, one
    matrix a step) and its τ_ext input: a = q̈_cmd + M_c(q)⁻¹ τ_ext,used, where q̈_cmd =
    M_c⁻¹(τ − ν_c − g_c) is the one the runtime returns (docs/formulations.md). The joint
    acceleration limits bound a, not q̈_cmd."""
    if not tau_ext_used.any():
        return log.ddq_commanded.copy()
    return log.ddq_commanded + np.linalg.solve(M_c, tau_ext_used[..., None])[..., 0]


def _mass_matrices(robot: Robot, q: np.ndarray) -> np.ndarray:
    """M(q_k) of `robot` at each step (the controller's model, where it differs from the simulated one)."""
    model = robot.model
    data = model.createData()
    out = np.empty((len(q), model.nv, model.nv))
    for k, q_k in enumerate(q):
        M = pin.crba(model, data, q_k)
        out[k] = np.triu(M) + np.triu(M, 1).T  # (crba fills the upper triangle)
    return out


def _kinetic_energies(M: np.ndarray, J: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """T = ½q̇ᵀMq̇ and its task part ½ẋᵀΛẋ, Λ = (J M⁻¹ Jᵀ)⁺ (an M-orthogonal split of T)."""
    kinetic = 0.5 * np.einsum("ki,kij,kj->k", dq, M, dq)
    if J.shape[1] == 0:
        return kinetic, np.zeros_like(kinetic)
    inverse_jt = np.linalg.solve(M, J.transpose(0, 2, 1))
    operational = np.linalg.pinv(J @ inverse_jt, rcond=PINV_RCOND, hermitian=True)
    velocity = np.einsum("kij,kj->ki", J, dq)
    return kinetic, 0.5 * np.einsum("ki,kij,kj->k", velocity, operational, velocity)


def _cartesian_frames(robot: Robot, problem: ControlProblem) -> list[str]:
    """Frames of the Cartesian tasks and bounds, in order of appearance."""
    frames = [t.frame for lv in problem.levels for t in lv.tasks if isinstance(t, CartesianTask)]
    frames += [b.frame for b in robot.cartesian_bounds]
    return list(dict.fromkeys(frames))
