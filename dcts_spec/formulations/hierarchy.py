"""The recursive dynamically consistent task hierarchy (Khatib/Sentis, restricted Jacobians).

For levels i = 1..k, with N₀ = I and the actual acceleration a₀ = M⁻¹(τ_ext − ν):

    J_i|prev = J_i N_{i−1}                         restricted Jacobian
    J̄_i      = M⁻¹ J_i|prevᵀ (J_i|prev M⁻¹ J_i|prevᵀ)⁻¹   dynamically consistent pseudo-inverse
    a_i      = a_{i−1} + J̄_i (v_i − J̇_i q̇ − J_i a_{i−1})
    N_i      = N_{i−1} − J̄_i J_i|prev              N_iᵀ = I − J_iᵀ J̄_iᵀ … (torque projector)

so J_i a_k = v_i − J̇_i q̇ for every level (v_i is the commanded task acceleration) as long as
it does not conflict with the levels above, and a_k − a₀ is the smallest correction in the
M-metric: the Gauss-principle solution, which moves the remaining null space passively.
Each v_i is affine in the QP variable x, so the recursion is carried out on affine maps.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..symbolic.linalg import cholesky, cholesky_solve, spd_inverse
from .problem import ControlProblem, Level
from .qp import Affine

# Damping λ² of (J M⁻¹ Jᵀ + λ² I)⁻¹: negligible away from singularities (its effect is
# λ²/σ_min² relative), it keeps the inverse bounded at a singular configuration.
SINGULARITY_DAMPING = 1e-10
RANK_TOLERANCE = 1e-6
RANK_SAMPLES = 12
# Least-squares levels: the acceleration energy only breaks ties (weight relative to the task).
LEAST_SQUARES_ENERGY_RATIO = 1e-10
NULL_SPACE_REGULARIZATION = 1.0


def recursive_hierarchy(problem: ControlProblem, commands: list[Affine], nx: int) -> Affine:
    """The acceleration a(x) after the first len(commands) levels; commands[i] = v_i(x)."""
    n = problem.n
    Minv = problem.mass_matrix_inverse
    offset = problem.free_acceleration
    matrix = ca.SX(n, nx)
    N = ca.SX.eye(n)
    for level, v in zip(problem.levels, commands):
        J = level.jacobian
        Jr = ca.mtimes(J, N)
        Minv_JrT = ca.mtimes(Minv, Jr.T)
        Lambda = spd_inverse(ca.mtimes(Jr, Minv_JrT) + SINGULARITY_DAMPING * ca.SX.eye(level.dim))
        Jbar = ca.mtimes(Minv_JrT, Lambda)
        offset = offset + ca.mtimes(Jbar, v.offset - level.bias - ca.mtimes(J, offset))
        matrix = matrix + ca.mtimes(Jbar, v.matrix - ca.mtimes(J, matrix))
        N = N - ca.mtimes(Jbar, Jr)
    return Affine(offset, matrix)


def least_squares_objective(
    level: Level, acceleration: ca.SX, basis: ca.SX, mass: ca.SX, weight: float
) -> tuple[ca.SX, ca.SX]:
    """Hessian and gradient in z of  w‖J(a + B z) + J̇q̇ − ẍ_d‖² + ε w ½‖B z‖²_M.

    B spans the freedom left (a basis, or a projector N). The minimizer is the closed-form step
    with a pseudo-inverse, a + J̄⁺(ẍ_d − J̇q̇ − J a), also when J B has lost rank: the task is met
    in least squares, the rest at minimum energy. A damped task-space inverse
    (J N M⁻¹ NᵀJᵀ + λ²I)⁻¹ would be hopelessly ill-conditioned there instead.
    """
    JB = ca.mtimes(level.jacobian, basis)
    residual = level.target - level.bias - ca.mtimes(level.jacobian, acceleration)
    hessian = 2.0 * weight * ca.mtimes(JB.T, JB) + LEAST_SQUARES_ENERGY_RATIO * weight * ca.mtimes([basis.T, mass, basis])
    return hessian, -2.0 * weight * ca.mtimes(JB.T, residual)


def least_squares_step(level: Level, acceleration: ca.SX, N: ca.SX, mass: ca.SX) -> tuple[ca.SX, ca.SX]:
    """One level of the hierarchy in least squares: the new acceleration and null-space projector."""
    hessian, gradient = least_squares_objective(level, acceleration, N, mass, 1.0)
    # z and N z are redundant along null(N); γ‖(I − N)z‖² fixes those components without biasing N z.
    complement = ca.SX.eye(N.shape[0]) - N
    factor = cholesky(hessian + NULL_SPACE_REGULARIZATION * ca.mtimes(complement.T, complement))
    z = cholesky_solve(factor, -gradient)
    # Δa = N H⁻¹ 2(J N)ᵀ r is linear in the residual r; its restriction to J N gives N_i.
    JN = ca.mtimes(level.jacobian, N)
    gain = ca.mtimes(N, cholesky_solve(factor, 2.0 * JN.T))
    return acceleration + ca.mtimes(N, z), N - ca.mtimes(gain, JN)


@dataclass(frozen=True)
class LevelStructure:
    """How many levels the exact recursion handles, and what freedom is left after them."""

    exact_levels: int  # levels whose restricted Jacobian has full row rank
    least_squares_last: bool  # the last level is over-constrained: solved in least squares
    free_dimension: int  # joint-space freedom left after the exact levels


def level_structure(problem: ControlProblem, seed: int = 0) -> LevelStructure:
    """Classify the levels from their restricted ranks at random configurations.

    Only the lowest level may be over-constrained (e.g. a posture task taking whatever freedom
    the tasks above leave); an over-constrained level above it is a spec error.
    """
    levels = problem.levels
    f = ca.Function("jacobians", [problem.q], [*[lv.jacobian for lv in levels], problem.mass_matrix])
    robot = problem.robot
    rng = np.random.default_rng(seed)
    lo = np.where(np.isfinite(robot.limits.q_min), robot.limits.q_min, -np.pi)
    hi = np.where(np.isfinite(robot.limits.q_max), robot.limits.q_max, np.pi)
    deficient = np.zeros(len(levels), dtype=bool)
    free = problem.n
    for _ in range(RANK_SAMPLES):
        out = [np.array(o) for o in f(rng.uniform(lo, hi))]
        jacobians, M = out[:-1], out[-1]
        N = np.eye(problem.n)
        Minv = np.linalg.inv(M)
        for i, J in enumerate(jacobians):
            Jr = J @ N
            rank = np.linalg.matrix_rank(Jr, RANK_TOLERANCE * max(1.0, np.abs(J).max()))
            if rank < J.shape[0]:
                deficient[i] = True
                break
            Jbar = Minv @ Jr.T @ np.linalg.inv(Jr @ Minv @ Jr.T)
            N = N - Jbar @ Jr
        exact = int(np.argmax(deficient)) if deficient.any() else len(levels)
        free = min(free, problem.n - sum(lv.dim for lv in levels[:exact]))
    bad = [i for i in range(len(levels) - 1) if deficient[i]]
    if bad:
        p = levels[bad[0]].priority
        raise ValueError(
            f"priority {p} is over-constrained: its tasks conflict with the higher priorities at every "
            "configuration tried; only the lowest priority level may ask for more than the freedom left"
        )
    exact = len(levels) - 1 if deficient[-1] else len(levels)
    return LevelStructure(exact, bool(deficient[-1]), problem.n - sum(lv.dim for lv in levels[:exact]))
