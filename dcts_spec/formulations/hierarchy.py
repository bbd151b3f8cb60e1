"""The recursive dynamically consistent task hierarchy (Khatib/Sentis, restricted Jacobians).

For levels i = 1..k, with N₀ = I and the actual acceleration a₀ = M⁻¹(τ_ext − ν):

    J_i|prev = J_i N_{i−1}                         restricted Jacobian
    J̄_i      = M⁻¹ J_i|prevᵀ (J_i|prev M⁻¹ J_i|prevᵀ)⁻¹   dynamically consistent pseudo-inverse
    a_i      = a_{i−1} + J̄_i (v_i − J̇_i q̇ − J_i a_{i−1})
    N_i      = N_{i−1} − J̄_i J_i|prev              null-space projector (N_iᵀ acts on torques)

so J_i a_k = v_i − J̇_i q̇ for every level (v_i is the commanded task acceleration) as long as
it does not conflict with the levels above, and a_k − a₀ is the smallest correction in the
M-metric: the Gauss-principle solution, which moves the remaining null space passively.
Each v_i is affine in the QP variable x, so the recursion is carried out on affine maps.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..symbolic.linalg import cholesky, cholesky_solve, product, spd_inverse, symmetric_product
from .problem import ControlProblem, Level
from .qp import Affine

# Near a singularity the level's inverse is damped (λ² D added, D = diag(J M⁻¹ Jᵀ)), the more the
# closer: damping starts when the smallest Cholesky pivot of J M⁻¹ Jᵀ with its rows scaled to a unit
# diagonal (D^(-1/2) J M⁻¹ Jᵀ D^(-1/2): how dependent the rows are, in the M⁻¹ metric) falls below
# SINGULAR_PIVOT, and λ² reaches MAX_DAMPING at the singularity. Away from singularities λ = 0
# exactly, so the hierarchy is exact and no level leaks into a higher one. The inverse is then at
# most ~1.3e4 / D: with damping only below 1e-8 (at most 1e-6), an iiwa14 stretched toward an
# unreachable target (pivot ratios 1e-8–1e-5) was commanded ~1e8 rad/s², and DAQP called 31 of 10⁶
# closed-loop states infeasible. No random in-limit state of that arm comes within 1e-4 (20,000
# sampled; 0.05 % within 1e-3). (The pivot was once judged against the mean eigenvalue instead,
# which also counts how much the rows' sizes differ: an SO-100's wrist roll of 1e-4 kg·m² made the
# second row of an orientation [rx, ry] look singular, its Jacobian's smallest singular value 0.015,
# and the damped level was missed by 5 % with its scaling 1 where the strict answer meets it; found
# from outside against the lexicographic reference.)
SINGULAR_PIVOT = 1e-4
MAX_DAMPING = 1e-4
# A level's J M⁻¹ Jᵀ restricted by the levels above counts as having lost rank entirely where its
# mean eigenvalue falls below this fraction of the unrestricted one (`damped_inverse`).
RANK_LOST_SCALE = 1e-8
RANK_TOLERANCE = 1e-6
RANK_SAMPLES = 12
# Least-squares levels: the acceleration energy only breaks ties (weight relative to the task).
LEAST_SQUARES_ENERGY_RATIO = 1e-10
NULL_SPACE_REGULARIZATION = 1.0
# A least-squares level whose tasks are all switched off (activation 0) minimizes the acceleration
# energy with this weight (its task rows weigh ~1 per unit of acceleration when on).
RELEASED_ENERGY_WEIGHT = 1.0


def damped_inverse(a: ca.SX, unrestricted: ca.SX) -> ca.SX:
    """(A + λ²D)⁻¹ of a positive semi-definite A, D its diagonal, with λ > 0 only near a singularity.

    `unrestricted`: the mean eigenvalue the level would have with no level above it (an
    estimate). A level the levels above leave no direction at all has an A of rounding noise
    (~1e-33), whose pivots are no smaller than its diagonal: judged against itself it looked regular,
    its inverse was ~1e33 and the QP data ~1e16 (a Panda whose elbow joint task lost its one
    direction to the tool's pose at the initial configuration: every step fell back). A row whose
    diagonal is below RANK_LOST_SCALE of what the level has unrestricted is singular, damping the
    level, and takes no part in it: its row and column of the inverse are 0. (Damped at that floor
    only, its inverse was ~1e12, and the rounding of its restricted Jacobian gave its variables an
    effect on the levels above: a Panda's scaling stage pushed them to 1e12 to meet a joint limit of
    level 1 with s = 1, found from outside against the reference.)"""
    m = a.shape[0]
    floor = RANK_LOST_SCALE * unrestricted  # a diagonal below it: no direction left
    d = ca.fmax(ca.diag(a), floor) + 1e-300
    inverse_root = 1.0 / ca.sqrt(d)
    unit = a * ca.mtimes(inverse_root, inverse_root.T)  # (unit diagonal)
    # min pivot² ≥ λ_min, and det = Π pivots², so a vanishing eigenvalue shows in a pivot
    pivots = ca.diag(cholesky(unit + 1e-12 * ca.SX.eye(m))) ** 2
    smallest = pivots[0]
    for j in range(1, m):
        smallest = ca.fmin(smallest, pivots[j])
    closeness = ca.fmax(0.0, 1.0 - smallest / SINGULAR_PIVOT)
    # a row with no direction left (its diagonal below the floor) takes no part: its row and column
    # of the inverse, and so its column of J̄, are 0 (a 0/1 comparison, not a branch: straight-line
    # code)
    kept = ca.diag(a) >= floor
    return spd_inverse(a + MAX_DAMPING * closeness**2 * ca.diag(d)) * ca.mtimes(kept, kept.T)


def recursive_hierarchy(
    problem: ControlProblem,
    commands: list[Affine],
    nx: int,
    metric_inverse: ca.SX | None = None,
    free_acceleration: ca.SX | None = None,
    projector: ca.SX | None = None,
) -> tuple[Affine, ca.SX]:
    """The acceleration a(x) after the first len(commands) levels (commands[i] = v_i(x)), and N.

    The metric M⁻¹, the free acceleration a₀ and N₀ = I can be replaced (the projector baseline
    locks joints: it passes the metric and a₀ of the locked robot, and N₀ = its free joints).

    A level whose rows have run-time activations a ∈ [0, 1] applies the fraction a of each row's
    correction, J̄ diag(a) (v − J̇q̇ − J a), and takes the same fraction of its directions from the
    levels below, N − J̄ diag(a) J N. At a = 1 this is the level itself (exact); at a = 0 the row
    has no effect at all: it neither moves the robot nor takes any direction from the levels below,
    as if the task were not in the spec. In between this map moves smoothly (the level's own share
    linearly); the levels below see a blend of the projectors, stay exact themselves (J̄ below),
    and may move a half-active task along the directions it leaves them. (Where a bound binds,
    the lexicographic solve over it jumps as an activation leaves or reaches 1: README, parameters.)
    """
    n = problem.n
    Minv = problem.mass_matrix_inverse if metric_inverse is None else metric_inverse
    offset = problem.free_acceleration if free_acceleration is None else free_acceleration
    matrix = ca.SX(n, nx)
    N = ca.SX.eye(n) if projector is None else projector
    projector_above = True  # N is a projector: no level above has a run-time activation
    for level, v in zip(problem.levels, commands):
        J = level.jacobian
        Jr = product(J, N)
        Minv_JrT = product(Minv, Jr.T)
        # (its unrestricted scale from diag(M⁻¹): m·n operations, where J M⁻¹ Jᵀ would take m·n²)
        unrestricted = ca.dot(ca.sum1(J * J).T, ca.diag(Minv)) / J.shape[0]
        if projector_above:
            gram = symmetric_product(Jr.T, Minv_JrT)
        else:
            # Below a partly active level N is a blend, no projector, and with J N M⁻¹ Nᵀ Jᵀ the
            # level would get J J̄ ≠ I: not exact, and J N_k ≠ 0, the freedom below moving its task
            # (found from outside: an iiwa14's position level read s = 0.77 with its orientation
            # level above at activation 1e-3, where it is 0 at activation 0, its task moved by a
            # null-space variable of 1.6e5; the torque jumped 55 Nm as the activation left 0).
            # J M⁻¹ Nᵀ Jᵀ gives J J̄ = I and J N_k = 0; with N a projector the two are the same.
            # (Symmetric where the levels above have one activation each; its symmetric part else.)
            gram = ca.mtimes(J, Minv_JrT)
            gram = 0.5 * (gram + gram.T)
        Jbar = product(Minv_JrT, damped_inverse(gram, unrestricted))
        if level.activation is not None:
            Jbar = ca.mtimes(Jbar, ca.diag(level.activation))
            projector_above = False
        offset = offset + ca.mtimes(Jbar, v.offset - level.bias - ca.mtimes(J, offset))
        matrix = matrix + product(Jbar, v.matrix - product(J, matrix))
        N = N - product(Jbar, Jr)
    return Affine(offset, matrix), N


def least_squares_objective(level: Level, acceleration: Affine, mass_acceleration: ca.SX) -> tuple[ca.SX, ca.SX]:
    """Hessian and gradient in x of  ½‖J a(x) + J̇q̇ − ẍ_d‖² + ½ε‖a(x) − a(0)‖²_M  (a(x) affine),
    each row's square weighted by its run-time activation if it has one (and the energy weighted
    up as the most active row fades out). `mass_acceleration`: M times a(x)'s matrix (the caller's,
    which the torque rows share).

    The energy breaks the ties where J restricted to a(x)'s freedom has lost rank; a constant J
    of full column rank (a posture over every joint) has none, and goes without it.

    Over the freedom a(x) leaves, the minimizer is the closed-form step with a pseudo-inverse,
    a + J̄⁺(ẍ_d − J̇q̇ − J a), also where J restricted to that freedom has lost rank: the task is
    met in least squares, the rest at minimum energy. A damped task-space inverse
    (J N M⁻¹ NᵀJᵀ + λ²I)⁻¹ would be hopelessly ill-conditioned there instead.
    """
    G = product(level.jacobian, acceleration.matrix)
    residual = ca.mtimes(level.jacobian, acceleration.offset) + level.bias - level.target
    energy_weight = LEAST_SQUARES_ENERGY_RATIO
    if level.activation is not None:
        # each row's square weighted by its activation; as the last active row fades out, the
        # acceleration energy takes over (with nothing left to fit, the level's freedom moves at
        # minimum energy, as below a level that is met exactly, and the QP stays well posed)
        root = ca.sqrt(level.activation)
        G, residual = ca.mtimes(ca.diag(root), G), root * residual
        strongest = level.activation[0]
        for j in range(1, level.dim):
            strongest = ca.fmax(strongest, level.activation[j])
        energy_weight = energy_weight + (1.0 - strongest) * RELEASED_ENERGY_WEIGHT
    if level.activation is None and _constant_full_column_rank(level.jacobian):
        # (a posture over every joint: GᵀG is positive definite on whatever freedom a(x) leaves, so
        # there is no tie for the energy to break; at 28 joints its product was 22 % of the QP data)
        return symmetric_product(G, G), ca.mtimes(G.T, residual)
    energy = symmetric_product(acceleration.matrix, mass_acceleration)
    return symmetric_product(G, G) + energy_weight * energy, ca.mtimes(G.T, residual)


def _constant_full_column_rank(jacobian: ca.SX) -> bool:
    """Is J a constant matrix whose columns are independent (J a = 0 only for a = 0)?"""
    if not jacobian.is_constant():
        return False
    J = np.array(ca.DM(jacobian))
    return bool(np.linalg.matrix_rank(J) == J.shape[1])


def least_squares_step(level: Level, acceleration: ca.SX, N: ca.SX, mass: ca.SX) -> ca.SX:
    """The acceleration after a level solved in least squares within range(N)."""
    hessian, gradient = least_squares_objective(level, Affine(acceleration, N), product(mass, N))
    # z and N z are redundant along null(N); γ‖(I − N)z‖² fixes those components without biasing N z.
    complement = ca.SX.eye(N.shape[0]) - N
    z = cholesky_solve(cholesky(hessian + NULL_SPACE_REGULARIZATION * symmetric_product(complement, complement)),
                       -gradient)
    return acceleration + ca.mtimes(N, z)


class OverConstrainedLevel(ValueError):
    """A priority level above the lowest whose tasks conflict with the higher ones, or whose own
    rows are dependent (with no level above them), everywhere."""

    def __init__(self, priority: int, own_rows: bool = False):
        why = ("its task rows are dependent, or ask for a direction no joint moves (a frame no joint moves, "
               "tasks sharing rows), at every configuration tried" if own_rows else
               "its tasks conflict with the higher priorities at every configuration tried")
        super().__init__(f"priority {priority} is over-constrained: {why}; only the lowest priority level may ask "
                         "for more than the freedom left")
        self.priority = priority


@dataclass(frozen=True)
class LevelStructure:
    """How many levels the exact recursion handles, and what freedom is left after them."""

    exact_levels: int  # levels whose restricted Jacobian has full row rank
    least_squares_last: bool  # the last level is over-constrained: solved in least squares
    free_dimension: int  # joint-space freedom left after the exact levels


def level_structure(problem: ControlProblem) -> LevelStructure:
    """Classify the levels from their restricted ranks at random configurations.

    Only the lowest level may be over-constrained (e.g. a posture task taking whatever freedom
    the tasks above leave); an over-constrained level above it is a spec error.
    """
    levels = problem.levels
    # (a twist task's Jacobian is its error's gradient, which depends on a run-time target: sampled too)
    f = ca.Function("jacobians", [problem.q, problem.ref, problem.param],
                    [*[lv.jacobian for lv in levels], problem.mass_matrix])
    robot = problem.robot
    rng = np.random.default_rng(0)  # seeded: a spec always compiles to the same structure
    lo = np.where(np.isfinite(robot.limits.q_min), robot.limits.q_min, -np.pi)
    hi = np.where(np.isfinite(robot.limits.q_max), robot.limits.q_max, np.pi)
    deficient = np.zeros(len(levels), dtype=bool)
    own_rows = np.zeros(len(levels), dtype=bool)  # deficient without the levels above too
    for _ in range(RANK_SAMPLES):
        out = [np.array(o) for o in f(rng.uniform(lo, hi), rng.uniform(-1.0, 1.0, problem.ref.shape[0]),
                                      problem.param_layout.defaults)]
        jacobians, M = out[:-1], out[-1]
        N = np.eye(problem.n)
        Minv = np.linalg.inv(M)
        for i, J in enumerate(jacobians):
            Jr = J @ N
            tolerance = RANK_TOLERANCE * max(1.0, np.abs(J).max())
            if np.linalg.matrix_rank(Jr, tolerance) < J.shape[0]:
                deficient[i] = True
                # (a frame no joint moves at priority 3 was said to conflict with priorities 1 and 2)
                own_rows[i] |= np.linalg.matrix_rank(J, tolerance) < J.shape[0]
                break
            Jbar = Minv @ Jr.T @ np.linalg.inv(Jr @ Minv @ Jr.T)
            N = N - Jbar @ Jr
    bad = [i for i in range(len(levels) - 1) if deficient[i]]
    if bad:
        raise OverConstrainedLevel(levels[bad[0]].priority, own_rows=bad[0] == 0 or bool(own_rows[bad[0]]))
    exact = len(levels) - 1 if deficient[-1] else len(levels)
    return LevelStructure(exact, bool(deficient[-1]), problem.n - sum(lv.dim for lv in levels[:exact]))
