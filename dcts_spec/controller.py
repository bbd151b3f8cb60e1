"""The compiled controller: a CasADi function for the QP data, a QP solver, and a safe fallback.

    qp_data(q, dq, tau_ext, ref) → H, f, A, lba, uba, lbx, ubx, tau0, T, ddq0, Q, s0, S

τ = tau0 + T x, q̈ = ddq0 + Q x (commanded: M⁻¹(τ − ν − g)), s = s0 + S x, where x solves the QP
(empty for closed-form formulations). The generated C code runs the very same function.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from .formulations import FORMULATIONS, ControlLaw, ControlProblem, build_problem
from .formulations.qp import relaxed_qp
from .robot.model import Robot
from .spec import Spec, load_spec
from .tasks import ReferenceInput

STATUS_OK = 0
STATUS_LIMITS_RELAXED = 1  # joint/Cartesian bounds violated as little as the torque limits allow
STATUS_NONFINITE_INPUT = -1  # fallback torque
STATUS_SOLVER_FAILED = -2  # fallback torque
STATUS_INVALID_OUTPUT = -3  # the solution was not finite or broke a torque limit: fallback torque
STATUS_NAMES = {
    STATUS_OK: "ok",
    STATUS_LIMITS_RELAXED: "limits relaxed",
    STATUS_NONFINITE_INPUT: "non-finite input",
    STATUS_SOLVER_FAILED: "solver failed",
    STATUS_INVALID_OUTPUT: "invalid output",
}
TORQUE_TOLERANCE = 1e-5  # relative to max(1, τ_max): what solver tolerances may leave (then clipped)
# With the limits relaxed the QP data holds huge bounds (a velocity excess asks for ~1e3 rad/s² in
# one period), and the solver's tolerance, relative to them, leaves a larger overshoot to clip.
RELAXED_TORQUE_TOLERANCE = 1e-3
# DAQP settings shared by the Python runtime and the generated C: a tighter primal tolerance than
# DAQP's 1e-6 so that bounds hold to 1e-6 in their own units, and a bounded iteration count.
DAQP_SETTINGS = {"primal_tol": 1e-8, "iter_limit": 200}
DATA_OUTPUTS = ("H", "f", "A", "lba", "uba", "lbx", "ubx", "tau0", "T", "ddq0", "Q", "s0", "S")


@dataclass
class StepResult:
    """Output of one control step."""

    tau: np.ndarray  # joint torques to apply (gravity included), within the torque limits
    ddq: np.ndarray  # commanded joint acceleration M⁻¹(τ − ν − g); the actual one adds M⁻¹τ_ext
    scaling: np.ndarray  # one task scaling factor per priority level, highest first, in [0, 1] (1 = not scaled)
    status: int  # STATUS_* code; negative means the fallback torque was applied
    x: np.ndarray  # the QP solution, in scaled variables (empty for closed forms)

    @property
    def ok(self) -> bool:
        return self.status >= 0


def data_function(problem: ControlProblem, law: ControlLaw, name: str = "qp_data") -> ca.Function:
    """The CasADi function that maps the controller inputs to the QP data and output maps.

    The QP variables are scaled so that the Hessian has a unit diagonal, x = D x̃ with
    D = diag(H)^(-1/2): the same problem, but priority weights spanning 1e3…1e9 no longer make
    its condition number explode, which some DAQP versions (and qpOASES) cannot stand.
    """
    nx = law.nx
    qp = law.qp
    torque_matrix, scaling_matrix = law.torque.matrix, law.scaling.matrix
    if qp is None:
        empty = ca.SX(0, 1)
        H, f, A, lba, uba, lbx, ubx = ca.SX(0, 0), empty, ca.SX(0, 0), empty, empty, empty, empty
    else:
        d = 1.0 / ca.sqrt(ca.diag(qp.hessian))
        D = ca.diag(d)
        H = ca.mtimes([D, qp.hessian, D])
        f, A, lbx, ubx = d * qp.gradient, ca.mtimes(qp.constraints, D), qp.lbx / d, qp.ubx / d
        lba, uba = qp.lba, qp.uba
        torque_matrix, scaling_matrix = ca.mtimes(torque_matrix, D), ca.mtimes(scaling_matrix, D)
    torque = law.torque
    ddq0 = problem.commanded_acceleration(torque.offset)
    Q = ca.mtimes(problem.mass_matrix_inverse, torque_matrix) if nx else ca.SX(problem.n, 0)
    outputs = [H, f, A, lba, uba, lbx, ubx, torque.offset, torque_matrix, ddq0, Q, law.scaling.offset, scaling_matrix]
    inputs = [problem.q, problem.dq, problem.tau_ext, problem.ref]
    return ca.Function(
        name,
        inputs,
        [ca.densify(o) for o in outputs],
        ["q", "dq", "tau_ext", "ref"],
        list(DATA_OUTPUTS),
        {"cse": True},
    )


class Controller:
    """A spec compiled for one formulation; `step` runs it from Python."""

    def __init__(self, spec: Spec, robot: Robot, formulation: str | None = None, solver: str | None = None):
        self.spec = spec
        self.robot = robot
        self.formulation = formulation or spec.controller.formulation
        self.solver = solver or spec.controller.solver
        if self.formulation not in FORMULATIONS:
            raise ValueError(f"unknown formulation {self.formulation!r}; choose one of {', '.join(FORMULATIONS)}")
        if self.solver not in ("daqp", "qpoases"):
            raise ValueError(f"unknown solver {self.solver!r}; choose daqp or qpoases")
        self.problem = build_problem(spec, robot)
        self.law = FORMULATIONS[self.formulation](self.problem)
        self.data = data_function(self.problem, self.law)
        self.gravity_function = ca.Function("gravity", [self.problem.q], [self.problem.gravity], ["q"], ["g"])
        self.tau_max = np.asarray(robot.limits.tau_max, dtype=float)
        self.fallback_damping = self.problem.vector("fallback_damping")
        self._last_gravity = np.zeros(self.n)
        self._solver = self._make_solver(self.nx, self.na) if self.nx else None
        self._relaxed_solver: ca.Function | None = None

    # -- sizes and layout ------------------------------------------------------------------------

    @property
    def n(self) -> int:
        return self.problem.n

    @property
    def nx(self) -> int:
        return self.law.nx

    @property
    def na(self) -> int:
        return 0 if self.law.qp is None else self.law.qp.na

    @property
    def ref_layout(self) -> list[ReferenceInput]:
        """Where each run-time reference sits in the `ref` vector."""
        return list(self.problem.ref_layout)

    @property
    def ref_size(self) -> int:
        return int(self.problem.ref.shape[0])

    @property
    def priorities(self) -> list[int]:
        """The priority of each entry of `scaling`."""
        return [lv.priority for lv in self.problem.levels]

    # -- running ---------------------------------------------------------------------------------

    def _make_solver(self, nx: int, na: int) -> ca.Function:
        qp = {"h": ca.Sparsity.dense(nx, nx), "a": ca.Sparsity.dense(na, nx)}
        if self.solver == "daqp":
            return ca.conic("dcts_qp", "daqp", qp, {"error_on_fail": False, "daqp": dict(DAQP_SETTINGS)})
        options = {"error_on_fail": False, "printLevel": "none", "sparse": False, "enableRegularisation": False}
        return ca.conic("dcts_qp", "qpoases", qp, options)

    def _solve(self, data: dict[str, np.ndarray]) -> tuple[np.ndarray | None, int]:
        """Solve the QP; if it is infeasible, solve it again with the limits relaxed."""
        assert self._solver is not None and self.law.qp is not None
        names = ("H", "f", "A", "lba", "uba", "lbx", "ubx")
        H, f, A, lba, uba, lbx, ubx = (data[k] if k in ("H", "A") else data[k].ravel() for k in names)
        sol = self._solver(h=H, g=f, a=A, lba=lba, uba=uba, lbx=lbx, ubx=ubx)
        if self._solver.stats()["success"]:
            return np.array(sol["x"]).ravel(), STATUS_OK
        rows = self.law.qp.relaxable_rows
        if not rows:
            return None, STATUS_SOLVER_FAILED
        H2, f2, A2, lba2, uba2, lbx2, ubx2 = relaxed_qp(H, f, A, lba, uba, lbx, ubx, rows)
        if self._relaxed_solver is None:
            self._relaxed_solver = self._make_solver(*A2.shape[::-1])
        sol = self._relaxed_solver(h=H2, g=f2, a=A2, lba=lba2, uba=uba2, lbx=lbx2, ubx=ubx2)
        if self._relaxed_solver.stats()["success"]:
            return np.array(sol["x"]).ravel()[: self.nx], STATUS_LIMITS_RELAXED
        return None, STATUS_SOLVER_FAILED

    def fallback_torque(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """τ = g(q) − D q̇ clipped to the torque limits; non-finite parts are left out."""
        if np.all(np.isfinite(q)):
            self._last_gravity = np.array(self.gravity_function(q)).ravel()
        damping = -self.fallback_damping * np.where(np.isfinite(dq), dq, 0.0)
        return np.clip(self._last_gravity + damping, -self.tau_max, self.tau_max)

    def evaluate_data(self, q, dq, tau_ext=None, ref=None) -> dict[str, np.ndarray]:
        """The QP data and output maps at a state (for tests and tools)."""
        return self._evaluate(*self._inputs(q, dq, tau_ext, ref))

    def _evaluate(self, q: np.ndarray, dq: np.ndarray, tau_ext: np.ndarray, ref: np.ndarray) -> dict[str, np.ndarray]:
        return {name: np.array(v) for name, v in zip(DATA_OUTPUTS, self.data(q, dq, tau_ext, ref))}

    def _inputs(self, q, dq, tau_ext, ref) -> tuple[np.ndarray, ...]:
        q = np.asarray(q, dtype=float).reshape(-1)
        dq = np.asarray(dq, dtype=float).reshape(-1)
        tau_ext = np.zeros(self.n) if tau_ext is None else np.asarray(tau_ext, dtype=float).reshape(-1)
        if ref is None:
            if self.ref_size:
                raise ValueError(f"this controller takes a reference vector of {self.ref_size} values (see ref_layout)")
            ref = np.zeros(0)
        ref = np.asarray(ref, dtype=float).reshape(-1)
        for name, value, size in (("q", q, self.n), ("dq", dq, self.n), ("tau_ext", tau_ext, self.n), ("ref", ref, self.ref_size)):
            if value.size != size:
                raise ValueError(f"{name} must have {size} values, got {value.size}")
        return q, dq, tau_ext, ref

    def _fallback(self, q: np.ndarray, dq: np.ndarray, status: int, x: np.ndarray) -> StepResult:
        return StepResult(self.fallback_torque(q, dq), np.zeros(self.n), np.zeros(len(self.problem.levels)), status, x)

    def step(self, q, dq, tau_ext=None, ref=None) -> StepResult:
        """One control step: τ, commanded q̈, scalings and a status code."""
        q, dq, tau_ext, ref = self._inputs(q, dq, tau_ext, ref)
        if not all(np.all(np.isfinite(v)) for v in (q, dq, tau_ext, ref)):
            return self._fallback(q, dq, STATUS_NONFINITE_INPUT, np.zeros(0))
        data = self._evaluate(q, dq, tau_ext, ref)
        status = STATUS_OK
        x = np.zeros(0)
        if self.nx:
            solution, status = self._solve(data)
            if solution is None:
                return self._fallback(q, dq, status, np.zeros(0))
            x = solution
        tau = data["tau0"].ravel() + data["T"] @ x
        relative = RELAXED_TORQUE_TOLERANCE if status == STATUS_LIMITS_RELAXED else TORQUE_TOLERANCE
        tolerance = relative * np.maximum(1.0, np.where(np.isfinite(self.tau_max), self.tau_max, 1.0))
        out_of_limits = self.law.enforces_torque_limits and np.any(np.abs(tau) > self.tau_max + tolerance)
        if not np.all(np.isfinite(tau)) or out_of_limits:
            return self._fallback(q, dq, STATUS_INVALID_OUTPUT, x)
        self._last_gravity = np.array(self.gravity_function(q)).ravel()
        ddq = data["ddq0"].ravel() + data["Q"] @ x
        scaling = np.clip(data["s0"].ravel() + data["S"] @ x, 0.0, 1.0)
        return StepResult(np.clip(tau, -self.tau_max, self.tau_max), ddq, scaling, status, x)


def build_controller(spec: Spec | str | Path, formulation: str | None = None, solver: str | None = None) -> Controller:
    """Validate a spec (object or file) and compile it into a Python-runnable controller."""
    from .validate import validate_spec

    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    report = validate_spec(spec)
    return Controller(spec, report.robot, formulation, solver)
