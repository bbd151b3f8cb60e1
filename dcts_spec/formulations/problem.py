"""The control problem every formulation starts from: dynamics, task levels, limits, inputs."""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..limits.base import AccelerationRows
from ..limits.cartesian import cartesian_rows
from ..limits.collision import collision_rows
from ..limits.joint import BrakingDynamics, joint_rows
from ..robot.collision import resolve_collision
from ..robot.model import Robot
from ..spec import Spec
from ..spec.types import as_list
from ..symbolic import SymbolicRobot
from ..symbolic.linalg import spd_inverse
from ..tasks import ReferenceInput, Task, make_task
from .parameters import ParameterLayout, build_parameters, torque_limit

DEFAULT_WEIGHT_LOWEST = 1e6  # lowest priority level: w ≫ the acceleration energy of null-space motion
DEFAULT_WEIGHT_RATIO = 1e3  # each level above weighs this much more


@dataclass
class Level:
    """The tasks of one priority level, stacked."""

    priority: int
    tasks: list[Task]
    jacobian: ca.SX  # J (m × n)
    bias: ca.SX  # J̇ q̇ (m)
    target: ca.SX  # ẍ_d (m)
    error: ca.SX  # Δx (m)
    weight: float
    # Each row's run-time activation in [0, 1] (None: every task of the level fully active); see hierarchy.py
    activation: ca.SX | None = None

    @property
    def dim(self) -> int:
        return int(self.jacobian.shape[0])


@dataclass
class ControlProblem:
    """Symbolic state, dynamics, task levels and limits of one spec.

    The controller's inputs are q, dq, tau_ext, ref and param (run-time parameters). Accelerations
    are *actual* joint accelerations a = M⁻¹(τ + τ_ext − ν − g); the controller uses τ_ext only when
    `controller.external_torque` is `measured` (the paper's section III-B), otherwise it
    assumes τ_ext = 0.
    """

    spec: Spec
    robot: Robot
    sym: SymbolicRobot
    tau_ext: ca.SX  # input
    ref: ca.SX  # input
    ref_layout: list[ReferenceInput]
    mass_matrix: ca.SX  # M
    mass_matrix_inverse: ca.SX  # M⁻¹
    coriolis: ca.SX  # ν = C q̇
    gravity: ca.SX  # g
    external_torque: ca.SX  # τ_ext as used by the controller (0 when ignored)
    levels: list[Level]
    acceleration_rows: AccelerationRows  # joint, Cartesian and collision bounds on a
    acceleration_limit: ca.SX  # |q̈_j| ≤ this, the joint acceleration limits (inf: none; or run-time parameters)
    torque_max: np.ndarray  # |τ| ≤ τ_max (full torque, gravity included), as compiled: the envelope
    period: float
    param: ca.SX  # input: run-time parameters
    param_layout: ParameterLayout
    torque_limit: ca.SX  # |τ| ≤ this at run time (torque_max, or run-time parameters within it)

    @property
    def n(self) -> int:
        return self.sym.nv

    @property
    def q(self) -> ca.SX:
        return self.sym.q

    @property
    def dq(self) -> ca.SX:
        return self.sym.dq

    @property
    def free_acceleration(self) -> ca.SX:
        """a₀ = M⁻¹(τ_ext − ν): the acceleration with gravity compensated and no other torque."""
        return ca.mtimes(self.mass_matrix_inverse, self.external_torque - self.coriolis)

    def torque(self, acceleration: ca.SX) -> ca.SX:
        """τ producing the actual acceleration a: τ = M a + ν + g − τ_ext."""
        return ca.mtimes(self.mass_matrix, acceleration) + self.coriolis + self.gravity - self.external_torque

    def commanded_acceleration(self, torque: ca.SX) -> ca.SX:
        """q̈ = M⁻¹(τ − ν − g): the part of the acceleration the torque commands."""
        return ca.mtimes(self.mass_matrix_inverse, torque - self.coriolis - self.gravity)

    def vector(self, field: str) -> np.ndarray:
        """A per-joint controller setting broadcast to n values."""
        return np.array(as_list(getattr(self.spec.controller, field), self.n))


def level_weights(spec: Spec) -> list[float]:
    """Penalty weight of each priority level, highest first."""
    count = len(spec.priority_levels)
    if spec.controller.priority_weights is not None:
        return [float(w) for w in spec.controller.priority_weights]
    return [DEFAULT_WEIGHT_LOWEST * DEFAULT_WEIGHT_RATIO ** (count - 1 - i) for i in range(count)]


def build_problem(spec: Spec, robot: Robot) -> ControlProblem:
    """Assemble the symbolic control problem of a validated spec."""
    sym = SymbolicRobot(robot.model)
    n = sym.nv
    tasks = [make_task(t, robot) for t in spec.tasks]
    layout: list[ReferenceInput] = []
    offsets: dict[str, int] = {}
    for task in tasks:
        offsets[task.name] = sum(r.size for r in layout)
        layout += task.reference_inputs(offsets[task.name])
    ref = ca.SX.sym("ref", sum(r.size for r in layout))
    tau_ext = ca.SX.sym("tau_ext", n)
    params = build_parameters(spec, robot, tasks)

    levels = []
    for priority, weight in zip(spec.priority_levels, level_weights(spec)):
        members = [t for t in tasks if t.priority == priority]
        terms = [t.build(sym, ref, offsets[t.name], params.tasks.get(t.name)) for t in members]
        activation = None
        if any(t.name in params.activation for t in members):
            activation = ca.vertcat(*[ca.repmat(params.activation.get(t.name, ca.SX(1.0)), t.dim, 1) for t in members])
        levels.append(
            Level(
                priority,
                members,
                ca.vertcat(*[t.jacobian for t in terms]),
                ca.vertcat(*[t.bias for t in terms]),
                ca.vertcat(*[t.target for t in terms]),
                ca.vertcat(*[t.error for t in terms]),
                weight,
                activation,
            )
        )

    mass, coriolis, gravity = sym.mass_matrix(), sym.coriolis(), sym.gravity()
    limit = torque_limit(params, robot.limits.tau_max)
    braking = (BrakingDynamics(ca.diag(mass), coriolis, gravity, sym.gravity_rate(), sym.revolute, limit)
               if robot.limits.torque_limited_braking else None)
    period = spec.controller.period
    rows = AccelerationRows.stack(
        [
            joint_rows(robot.limits, sym.q, sym.dq, period, robot.joint_names, params.joint, braking, robot.prismatic),
            cartesian_rows(robot.cartesian_bounds, sym, period, params.cartesian),
            collision_rows(resolve_collision(spec, robot)[0], sym, period),
        ],
        n,
    )
    used_tau_ext = tau_ext if spec.controller.external_torque == "measured" else ca.SX.zeros(n)
    return ControlProblem(
        spec=spec,
        robot=robot,
        sym=sym,
        tau_ext=tau_ext,
        ref=ref,
        ref_layout=layout,
        mass_matrix=mass,
        mass_matrix_inverse=spd_inverse(mass),
        coriolis=coriolis,
        gravity=gravity,
        external_torque=used_tau_ext,
        levels=levels,
        acceleration_rows=rows,
        acceleration_limit=ca.vertcat(*[ca.SX(a) for a in params.joint.get("a_max", robot.limits.a_max)]),
        torque_max=robot.limits.tau_max,
        period=period,
        param=params.param,
        param_layout=params.layout,
        torque_limit=limit,
    )
