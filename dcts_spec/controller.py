"""The compiled controller: a CasADi function for the QP data, the lexicographic solve, a safe fallback.

    qp_data(q, dq, tau_ext, ref, param) → H, f, A, lba, uba, lbx, ubx, tau0, T, ddq0, Q, s0, S, p0, P, excess

τ = tau0 + T x, q̈ = ddq0 + Q x (commanded: M⁻¹(τ − ν − g)), s = s0 + S x, and p0 + P x the task
acceleration of an over-constrained lowest level (empty if there is none), where x solves the
lexicographic QP (`solve/`; empty for closed-form formulations). The generated C code runs the very
same function and the same DAQP. `param` holds the run-time parameters (`formulations/parameters.py`),
which `Controller.set_params` changes without a bump (`parameter_ramp.py`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from .buffered_function import BufferedFunction
from .formulations import FORMULATIONS, ControlLaw, ControlProblem, build_problem
from .formulations.fallback import fallback_torque, plausible_velocity
from .formulations.hierarchy import OverConstrainedLevel
from .formulations.parameters import ParameterLayout
from .formulations.qp import BOUNDS
from .limits.base import STATE_TOLERANCE
from .parameter_ramp import ParameterRamp, ramp_steps
from .robot.model import Robot
from .solve import (Hint, Structure, check_bounds, marginal_rows, solve_hinted, to_optimum,
                    unbounded_solution)
from .solve.sensitivity import RELAXED_ROUNDING, ROUNDING, AnswerData
from .solve.stage_qp import FEASIBILITY_TOLERANCE
from .spec import Spec, SpecError, load_spec
from .symbolic.linalg import looped_products
from .tasks import ReferenceInput
from .validate import ValidationReport, validate_spec

# every torque, joint and Cartesian bound holds (checked after the solve); a closed form (osc,
# projector) has no joint or Cartesian bound rows: its torque is clipped, and nothing else checked
STATUS_OK = 0
# a joint/Cartesian bound is crossed: its acceleration bound violated as little as the torque
# limits allow, or the state already beyond its position or velocity limit (after a push; the
# bound then brings it back), or too close to a position limit for its speed: it crosses it during
# this step whatever the torque (limits.viability.state_excess)
STATUS_LIMITS_RELAXED = 1
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
# What solver tolerances may leave of a torque limit (the torque is then clipped): relative to
# max(1, τ_max), plus what the cascade held the torque rows to, FEASIBILITY_TOLERANCE relative to
# their bounds ±τ_max − τ₀ (`Cascade._holds`). The second term counts only where τ₀ ≫ τ_max: an
# Alex at 78–91 rad/s on its 100 rad/s placeholder limits had τ₀ = 4.2e4 Nm against 300, and its
# answer, 7.6e-8 of τ₀ beyond a limit (3.2e-3 Nm), fell back as "invalid output" in both runtimes.
TORQUE_TOLERANCE = 1e-5
# A row is active (binding) at the solution when it is this close to its bound, relative to
# max(1, |bound|): then an over-constrained lowest level's scaling needs the solve without bounds.
ACTIVE_TOLERANCE = 1e-9
# From this many QP-data operations on, a control law's large products are kernel calls
# (`symbolic.linalg.looped_products`): unrolled QP data that large compile only at -O0
# (codegen.flags.QP_DATA_O0_FROM is this number), slower than the looped code at -O1. Counted
# before CSE (~5 % above the generated function's count, which the -O level reads).
LOOPED_PRODUCTS_FROM = 150_000
# No C bundle beyond this (codegen): gcc needs ~12 kB per operation of one function even at -O0,
# and the projector baseline on a 21-joint human model (~3 M operations, 74 MB of C) ran it out of
# memory. `validate --check` says where a formulation is beyond it.
MAX_QP_DATA_OPERATIONS = 500_000
# Looped products cut a law's QP-data operations 1.7–2.5 times (the projector baseline on TALOS's
# 16 joints and a 28-joint human, a 32- and a 48-joint chain): a law this many times beyond the
# bundle's limit unrolled stays beyond it looped, and `validate --check` does not build it again
# to count (the human's projector: 4.3 M operations unrolled, 2.5 M looped, 13 s each).
LOOPING_GAIN_AT_MOST = 4
DATA_OUTPUTS = ("H", "f", "A", "lba", "uba", "lbx", "ubx", "tau0", "T", "ddq0", "Q", "s0", "S", "p0", "P", "excess",
                "bound_shift")


@dataclass
class StepResult:
    """Output of one control step."""

    tau: np.ndarray  # joint torques to apply (gravity included), within the torque limits
    # commanded joint acceleration M⁻¹(τ − ν − g); the actual one adds M⁻¹τ_ext. For a law that
    # does not bound its torque (osc, projector), of the torque before it is clipped to the limits
    ddq: np.ndarray
    scaling: np.ndarray  # one task scaling factor per priority level, highest first, in [0, 1] (1 = not scaled)
    status: int  # STATUS_* code; negative means the fallback torque was applied
    x: np.ndarray  # the QP solution, in scaled variables (empty for closed forms)
    relaxed: list[str] = field(default_factory=list)  # bounds crossed (status 1), in row order
    # status "ok" with a QP: is the lowest level's objective (½xᵀHx + fᵀx) at its optimum given
    # the levels above, checked at x (solve/optimality.py)? None where not checked
    optimal: bool | None = None
    # is the answer the relaxation's own point (the least violation the torque limits allow), DAQP
    # having failed the levels' stages on the relaxed bounds (status "limits relaxed")? Such an
    # answer holds every bound as far as it can, its levels only as that point happens to
    from_relaxation: bool = False

    @property
    def ok(self) -> bool:
        return self.status >= 0


def data_function(problem: ControlProblem, law: ControlLaw, name: str = "qp_data", cse: bool = True) -> ca.Function:
    """The CasADi function that maps the controller inputs to the QP data and output maps.

    The QP variables are scaled so that the Hessian has a unit diagonal, x = D x̃ with
    D = diag(H)^(-1/2): the same problem (rows keep their units), better conditioned for DAQP's
    factorization (the mass matrix's diagonal spans ~4 decades). The bend variables δ of one
    level share one factor (their largest diagonal's): the bend stage minimizes ‖x̃_δ‖², which is
    then ‖δ‖² up to a constant, as the priority semantics ask (per-variable factors made it a
    weighted norm, and levels were bent up to 40 % more than needed with a posture's least
    squares on the diagonal).

    `cse=False` skips common-subexpression elimination (minutes for the projector's closed form
    at 30 joints): for counting operations, not for code.
    """
    nx = law.nx
    qp = law.qp
    torque_matrix, scaling_matrix = law.torque.matrix, law.scaling.matrix
    if qp is None:
        empty = ca.SX(0, 1)
        H, f, A, lba, uba, lbx, ubx = ca.SX(0, 0), empty, ca.SX(0, 0), empty, empty, empty, empty
    else:
        d = 1.0 / ca.sqrt(ca.diag(qp.hessian))
        for level in qp.priorities:
            shared = d[level.bend[0]]
            for j in level.bend[1:]:
                shared = ca.fmin(shared, d[j])
            for j in level.bend:
                d[j] = shared
        D = ca.diag(d)
        H = ca.mtimes([D, qp.hessian, D])
        f, A, lbx, ubx = d * qp.gradient, ca.mtimes(qp.constraints, D), qp.lbx / d, qp.ubx / d
        lba, uba = qp.lba, qp.uba
        torque_matrix, scaling_matrix = ca.mtimes(torque_matrix, D), ca.mtimes(scaling_matrix, D)
    torque = law.torque
    if law.acceleration is not None:  # q̈ = a − M⁻¹τ_ext, from the map the QP formulation has at hand
        ddq0 = law.acceleration.offset - ca.mtimes(problem.mass_matrix_inverse, problem.external_torque)
        Q = ca.mtimes(law.acceleration.matrix, D)
    else:  # (a closed form: Q has no column)
        ddq0 = problem.commanded_acceleration(torque.offset)
        Q = ca.mtimes(problem.mass_matrix_inverse, torque_matrix)
    P, p0 = ca.SX(0, nx), ca.SX(0, 1)
    if law.least_squares_task is not None:
        P, p0 = ca.mtimes(law.least_squares_task[0], D), law.least_squares_task[1]
    excess = problem.acceleration_rows.excess if qp is not None else ca.SX(0, 1)
    bound_shift = qp.bound_shift if qp is not None else ca.SX(0, 1)
    outputs = [H, f, A, lba, uba, lbx, ubx, torque.offset, torque_matrix, ddq0, Q, law.scaling.offset, scaling_matrix, p0, P,
               excess, bound_shift]
    inputs = [problem.q, problem.dq, problem.tau_ext, problem.ref, problem.param]
    return ca.Function(
        name,
        inputs,
        [ca.densify(o) for o in outputs],
        ["q", "dq", "tau_ext", "ref", "param"],
        list(DATA_OUTPUTS),
        {"cse": cse},
    )


def least_squares_scaling(achieved: np.ndarray, unbounded: np.ndarray) -> float:
    """Scaling reported for an over-constrained lowest level: 1 − the deviation of its task
    acceleration from what it gets when the bounds are ignored, relative to the latter, in [0, 1]."""
    return float(np.clip(1.0 - np.linalg.norm(achieved - unbounded) / (np.linalg.norm(unbounded) + 1e-9), 0.0, 1.0))


def control_law(spec: Spec, problem: ControlProblem, formulation: str) -> ControlLaw:
    """The formulation's control law of the spec. A level above the lowest that its tasks
    over-constrain at every configuration is an error of the spec, at that priority's line."""
    try:
        return FORMULATIONS[formulation](problem)
    except OverConstrainedLevel as error:
        raise SpecError([spec.source.diagnostic(spec.priority_path(error.priority), str(error))]) from None


def sized_law(spec: Spec, problem: ControlProblem, formulation: str,
              unrolled: ControlLaw | None = None) -> tuple[ControlLaw, bool, int]:
    """The formulation's control law (`unrolled`: the one already built), whether its large products
    are looped (from LOOPED_PRODUCTS_FROM operations), and its QP data's operations before CSE."""
    law = control_law(spec, problem, formulation) if unrolled is None else unrolled
    operations = qp_data_operations(problem, law)
    if operations < LOOPED_PRODUCTS_FROM:
        return law, False, operations
    return looped_law(spec, problem, formulation)


def qp_data_operations(problem: ControlProblem, law: ControlLaw) -> int:
    """The law's QP-data operations before CSE (~5 % above the generated function's)."""
    return data_function(problem, law, cse=False).n_instructions()


def looped_law(spec: Spec, problem: ControlProblem, formulation: str) -> tuple[ControlLaw, bool, int]:
    """The formulation's control law with its large products as kernel calls, and its operations."""
    with looped_products():
        law = control_law(spec, problem, formulation)
    return law, True, qp_data_operations(problem, law)


class Controller:
    """A spec compiled for one formulation; `step` runs it from Python."""

    def __init__(self, spec: Spec, robot: Robot, formulation: str | None = None):
        self.spec = spec
        self.robot = robot
        self.formulation = formulation or spec.controller.formulation
        if self.formulation not in FORMULATIONS:
            raise ValueError(f"unknown formulation {self.formulation!r}; choose one of {', '.join(FORMULATIONS)}")
        self.problem = build_problem(spec, robot)
        self.law, self.looped, _ = sized_law(spec, self.problem, self.formulation)
        self.data = data_function(self.problem, self.law)
        self._ref_size = int(self.problem.ref.shape[0])  # (asking the SX each step costs microseconds)
        self._data_buffer: BufferedFunction | None = None
        fallback = fallback_torque(self.problem)
        p = self.problem
        self.fallback_function = ca.Function("fallback", [p.q, p.dq, p.param], [fallback], ["q", "dq", "param"], ["tau"])
        self._plausible_velocity = plausible_velocity(robot.limits.v_max)
        self.tau_max = np.asarray(robot.limits.tau_max, dtype=float)  # as compiled (the envelope)
        self.reset_params()
        # the joints whose torque limit is a run-time parameter, and where it is in `param`
        self._torque_joints = np.array([j for j, i in enumerate(self.param_layout.torque_index) if i >= 0], dtype=int)
        self._torque_params = np.array([i for i in self.param_layout.torque_index if i >= 0], dtype=int)
        self._last_q: np.ndarray | None = None
        self._hint: Hint | None = None  # where the last solve gave way (as the C runtime's hint_first)
        # (else tau_ext is not read: zero, whatever the sensor gives; the C runtime the same)
        self.reads_tau_ext = spec.controller.external_torque == "measured"
        qp = self.law.qp
        self._structure = None if qp is None else Structure(
            qp.rows_of(BOUNDS), tuple((p.scaling, tuple(p.bend)) for p in qp.priorities), self.law.spare_variables,
            tuple(self.problem.acceleration_rows.slack_weights.tolist()))

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
    def bound_names(self) -> list[str]:
        """The joint and Cartesian bounds, in the order of the bound rows (none for a closed form,
        which has no bound rows: as the C runtime's)."""
        return [] if self.law.qp is None else list(self.problem.acceleration_rows.names)

    def __reduce__(self):
        raise TypeError("a Controller holds CasADi expressions and cannot be copied or pickled: build another "
                        "with build_controller(spec) (in another process: from the spec file)")

    @property
    def ref_layout(self) -> list[ReferenceInput]:
        """Where each run-time reference sits in the `ref` vector."""
        return list(self.problem.ref_layout)

    @property
    def ref_size(self) -> int:
        return self._ref_size

    @property
    def param_layout(self) -> ParameterLayout:
        """The run-time parameters: where each sits in `param`, its default and allowed range."""
        return self.problem.param_layout

    @property
    def param_size(self) -> int:
        return self.param_layout.size

    @property
    def priorities(self) -> list[int]:
        """The priority of each entry of `scaling`."""
        return [lv.priority for lv in self.problem.levels]

    # -- run-time parameters ---------------------------------------------------------------------

    def set_params(self, values: dict | np.ndarray) -> None:
        """Take a new parameter set, reached over the spec's ramp time (`parameter_ramp.py`).

        `values`: {name: value or values} over the current set (names as in `param_layout`, e.g.
        "tool_position.kp"; one value sets every component), or a whole vector. The whole set is
        checked: on a ParameterError (naming the field) the current set is kept."""
        vector = self.param_layout.vector(values, self._ramp.target)
        self.param_layout.check(vector)
        self._ramp.set(vector)

    def params(self) -> dict[str, list[float]]:
        """The parameter set last taken (the ramp's target), by name."""
        return self.param_layout.as_dict(self._ramp.target)

    def params_default(self) -> dict[str, list[float]]:
        """The compiled values, by name."""
        return self.param_layout.as_dict(self.param_layout.defaults)

    def reset(self) -> None:
        """Forget the history (the last finite q, which the fallback torque holds, and where the last
        solve gave way), as the C runtime's reset; the parameter set and its ramp are kept."""
        self._last_q = None
        self._hint = None

    def reset_params(self) -> None:
        """Back to the compiled values at once (no ramp), as a freshly initialized controller."""
        layout = self.param_layout
        self._ramp = ParameterRamp(layout.defaults, ramp_steps(layout.ramp_time, self.problem.period), layout.periodic)

    def torque_limit(self, param: np.ndarray) -> np.ndarray:
        """|τ| ≤ this with the parameter values `param` (the compiled limit where there is none)."""
        out = self.tau_max.copy()
        out[self._torque_joints] = param[self._torque_params]
        return out

    # -- running ---------------------------------------------------------------------------------

    @staticmethod
    def _qp(data: dict[str, np.ndarray]) -> tuple[np.ndarray, ...]:
        """H, f, A, lbx, ubx, lba, uba: the arguments of the lexicographic solve, as vectors."""
        return (data["H"], data["f"].ravel(), data["A"], data["lbx"].ravel(), data["ubx"].ravel(),
                data["lba"].ravel(), data["uba"].ravel())

    def _solve(self, data: dict[str, np.ndarray]) -> tuple[np.ndarray | None, bool]:
        """The lexicographic solution at the data (None if DAQP failed), its cascade started where
        the last step's gave way (`solve.Hint`: fewer QPs, the same answer), and whether it is the
        relaxation's own point (`solve_hinted`)."""
        x, self._hint, from_relaxation = solve_hinted(*self._qp(data), self._structure, data["Q"], self._hint)
        return x, from_relaxation

    def answer_data(self, q, dq, tau_ext, ref, x: np.ndarray, relaxed: bool = False) -> AnswerData | None:
        """The last step's answer x (its QP solution, at this state) with its QP data and command
        maps, for `solve.sensitivity` (None without a QP); `relaxed`: the answer came after a
        relaxation (its spread is measured at RELAXED_ROUNDING)."""
        if not self.nx:
            return None
        data = self.evaluate_data(q, dq, tau_ext, ref)
        return AnswerData(self._qp(data), self._structure, x, data["tau0"].ravel(), data["T"], data["ddq0"].ravel(),
                          data["Q"], data["bound_shift"].ravel(), RELAXED_ROUNDING if relaxed else ROUNDING)

    def answer_spread(self, q, dq, tau_ext, ref, x: np.ndarray, samples: int, enough: float,
                      relaxed: bool = False) -> np.ndarray:
        """How far the last step's answer x (its QP solution, at this state) is determined by its QP
        data: [the command's, the solution's] largest relative change when the data change at the
        level of their rounding (`solve/sensitivity.py`; `samples` solves, stopping once both are
        above `enough`), the command being τ and q̈, the solution x. Zeros without a QP."""
        answer = self.answer_data(q, dq, tau_ext, ref, x, relaxed)
        return np.zeros(2) if answer is None else answer.spread(samples, enough)

    def status_determined(self, q, dq, tau_ext, ref, x: np.ndarray) -> bool:
        """Is the last step's status ("ok" or "limits relaxed", its answer x at this state) one that
        any answer the cascade accepts here would get? Not where the bound check of a row it turns
        on is within rounding of its tolerance (`solve.marginal_rows`): then another runtime's
        answer, as good, may get the other status. A state beyond a limit decides it by itself."""
        if not self.nx:
            return True
        data = self.evaluate_data(q, dq, tau_ext, ref)
        if (data["excess"].ravel() > STATE_TOLERANCE).any():
            return True
        rows, A, lba, uba, shift = (self._structure.bound_rows, data["A"], data["lba"].ravel(), data["uba"].ravel(),
                                    data["bound_shift"].ravel())
        marginal = marginal_rows(rows, A, lba, uba, x, shift)
        crossed = np.zeros(marginal.size, dtype=bool)
        crossed[check_bounds(rows, A, lba, uba, x, shift).violated] = True
        return not marginal[crossed].all() if crossed.any() else not marginal.any()

    def _binding(self, data: dict[str, np.ndarray], x: np.ndarray) -> bool:
        """Does a torque limit or a joint/Cartesian bound bind at x: is a row within ACTIVE_TOLERANCE
        of a bound, or beyond it? (Beyond: a relaxed answer. Counted only within the tolerance, a
        relaxed step whose crossed rows all missed it by more reported its over-constrained
        lowest level met, s = 1, where the other runtime's rounding left one row on its bound: a
        Kinova's golden vector, 1 against 0.)"""
        qp = self.law.qp
        end = qp.rows_of(BOUNDS).stop
        value = data["A"][:end] @ x
        lo, hi = data["lba"].ravel()[:end], data["uba"].ravel()[:end]
        tolerance = ACTIVE_TOLERANCE * np.maximum(1.0, np.minimum(np.abs(lo), np.abs(hi)))
        return bool(np.any((value - lo <= tolerance) | (hi - value <= tolerance)))

    def _least_squares_scaling(self, data: dict[str, np.ndarray], x: np.ndarray) -> float:
        if not self._binding(data, x):
            return 1.0
        free = unbounded_solution(data["H"], data["f"].ravel(), data["ubx"].ravel(), self._structure)
        P, p0 = data["P"], data["p0"].ravel()
        return least_squares_scaling(P @ x + p0, P @ free + p0)

    def fallback_torque(self, q: np.ndarray, dq: np.ndarray, param: np.ndarray | None = None) -> np.ndarray:
        """The stable damping of `formulations/fallback.py` at q (else the last finite q), clipped to
        the torque limits; non-finite and implausible velocities count as 0. `param`: the parameter
        values (default: those of the last step)."""
        param = self._ramp.now if param is None else param
        if np.all(np.isfinite(q)):
            self._last_q = np.array(q, dtype=float)  # (a copy: a caller may reuse its array)
        dq = np.where(np.isfinite(dq) & (np.abs(dq) <= self._plausible_velocity), dq, 0.0)
        if self._last_q is None:
            return np.zeros(self.n)
        tau = np.array(self.fallback_function(self._last_q, dq, param)).ravel()
        limit = self.torque_limit(param)
        return np.clip(np.where(np.isfinite(tau), tau, 0.0), -limit, limit)

    def evaluate_data(self, q, dq, tau_ext=None, ref=None, param=None) -> dict[str, np.ndarray]:
        """The QP data and output maps at a state (for tests and tools); `param` defaults to the
        values of the last step."""
        param = self._ramp.now if param is None else np.asarray(param, dtype=float).reshape(-1)
        if param.size != self.param_size:
            raise ValueError(f"param must have {self.param_size} values (see param_layout), got {param.size}")
        data = self._evaluate(*self._inputs(q, dq, tau_ext, ref), param)
        return {name: value.copy() for name, value in data.items()}

    def _evaluate(self, q: np.ndarray, dq: np.ndarray, tau_ext: np.ndarray, ref: np.ndarray,
                  param: np.ndarray) -> dict[str, np.ndarray]:
        """The QP data in arrays the next evaluation overwrites (evaluate_data copies them)."""
        if self._data_buffer is None:  # set up at the first step: building a controller stays cheap
            self._data_buffer = BufferedFunction(self.data)
        return self._data_buffer(q, dq, tau_ext, ref, param)

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
        """One control step: τ, commanded q̈, scalings and a status code. Each step moves a
        parameter change one period along its ramp (also a step that falls back)."""
        q, dq, tau_ext, ref = self._inputs(q, dq, tau_ext, ref)
        param = self._ramp.advance()
        if not self.reads_tau_ext:
            tau_ext = np.zeros(self.n)  # ignored: zero, whatever the sensor reads (a NaN too)
        if not np.isfinite(np.concatenate((q, dq, tau_ext, ref))).all():
            self._hint = None  # (as the C runtime's)
            return self._fallback(q, dq, STATUS_NONFINITE_INPUT, np.zeros(0))
        self._last_q = q.copy()  # (q may be a view of the caller's array, which it may reuse)
        data = self._evaluate(q, dq, tau_ext, ref, param)
        x, from_relaxation = np.zeros(0), False
        if self.nx:
            # H, f, A and the bounds are consecutive outputs: two checks instead of seven
            buffer = self._data_buffer
            finite = np.isfinite(buffer.span("H", "A")).all() and not np.isnan(buffer.span("lba", "ubx")).any()
            if finite:
                solution, from_relaxation = self._solve(data)
            else:
                solution, self._hint = None, None  # (as the C runtime's)
            if solution is None:
                return self._fallback(q, dq, STATUS_SOLVER_FAILED, np.zeros(0))
            x = solution
        status, relaxed, optimal = STATUS_OK, [], None
        if self.nx:
            check = check_bounds(self._structure.bound_rows, data["A"], data["lba"].ravel(), data["uba"].ravel(), x,
                                 data["bound_shift"].ravel())
            crossed = set(check.violated) | set(np.flatnonzero(data["excess"].ravel() > STATE_TOLERANCE).tolist())
            if crossed:
                names = self.bound_names
                status, relaxed = STATUS_LIMITS_RELAXED, [names[i] for i in sorted(crossed)]
            else:  # (relaxed, the answer is on widened bounds the data do not have)
                # the lowest level's optimum, checked, and reached where the cascade's last QP
                # missed it (solve/optimality.py); within the same rows, the levels held
                x, optimal = to_optimum(*self._qp(data), x, self._structure)
        tau = data["tau0"].ravel() + data["T"] @ x
        tau_max = self.torque_limit(param)
        tolerance = (TORQUE_TOLERANCE * np.maximum(1.0, np.where(np.isfinite(tau_max), tau_max, 1.0))
                     + FEASIBILITY_TOLERANCE * np.abs(data["tau0"].ravel()))
        out_of_limits = self.law.enforces_torque_limits and (np.abs(tau) > tau_max + tolerance).any()
        if not np.isfinite(tau).all() or out_of_limits:
            return self._fallback(q, dq, STATUS_INVALID_OUTPUT, x)
        ddq = data["ddq0"].ravel() + data["Q"] @ x
        # (np.minimum/np.maximum: np.clip's numbers, without its Python-level overhead)
        scaling = np.minimum(np.maximum(data["s0"].ravel() + data["S"] @ x, 0.0), 1.0)
        if self.law.least_squares_task is not None:
            scaling[-1] = self._least_squares_scaling(data, x)
        return StepResult(np.minimum(np.maximum(tau, -tau_max), tau_max), ddq, scaling, status, x, relaxed, optimal,
                          from_relaxation)


def build_controller(spec: Spec | str | Path, formulation: str | None = None) -> Controller:
    """Validate a spec (object or file) and compile it into a Python-runnable controller."""
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    report = validate_spec(spec)
    return Controller(spec, report.robot, formulation)


def compile_check(report: ValidationReport) -> dict[str, dict]:
    """Build the spec's control law with every formulation: QP size, expression size, or why it fails.

    The operations are those of the QP-data function before common-subexpression elimination
    (CSE): the generated code's are a few percent fewer. CSE is what takes the time: for the
    projector's closed form at 28 joints, 17 s and 1 GB, where counting without it takes 1 s."""
    problem = build_problem(report.spec, report.robot)
    out: dict[str, dict] = {}
    for name in FORMULATIONS:
        try:
            law = control_law(report.spec, problem, name)
        except (ValueError, SpecError) as error:
            out[name] = {"ok": False, "error": str(error), "summary": f"cannot compile: {error}"}
            continue
        operations, looped = qp_data_operations(problem, law), False
        if LOOPED_PRODUCTS_FROM <= operations <= LOOPING_GAIN_AT_MOST * MAX_QP_DATA_OPERATIONS:
            law, looped, operations = looped_law(report.spec, problem, name)
        na = 0 if law.qp is None else law.qp.na
        kind = f"QP {law.nx} variables × {na} constraints" if law.nx else "closed form"
        notes = law.notes + (["its large products as calls to looped kernels"] if looped else [])
        if operations > MAX_QP_DATA_OPERATIONS:
            unrolled = "" if looped or operations < LOOPED_PRODUCTS_FROM else ", looped or not (counted unrolled)"
            notes.append(f"more than the {MAX_QP_DATA_OPERATIONS:,} a C bundle takes{unrolled}: `dcts compile` refuses "
                         "it, the Python runtime runs it")
        out[name] = {
            "ok": True,
            "variables": law.nx,
            "constraints": na,
            "instructions": operations,
            "instructions_counted": "before common-subexpression elimination",
            "looped_products": looped,
            "notes": law.notes,
            "summary": f"{kind}, {operations} operations for the QP data (before CSE)"
                       + (f" ({'; '.join(notes)})" if notes else ""),
        }
    return out
