"""DCTS — the paper's Dynamically-consistent Constrained Task hierarchy Solver, as a lexicographic QP.

The paper (section III-C) minimizes the acceleration energy ½(τ − g)ᵀM⁻¹(τ − g) plus
Σ wᵢ(1 − sᵢ)² under torque and acceleration bounds, with weights wᵢ ≫ wᵢ₊₁ standing for strict
priorities. Weights only emulate priorities: a ratio of 1e3 per level leaks ~1e-3 between
levels, and across four levels plus hard rows the QP's conditioning is beyond any solver's
tolerance. dcts solves it lexicographically instead (`qp.py`), in hierarchy coordinates
(`hierarchy.py`):

    a(x) = hierarchy(v₁ … v_k) + Z z,     vᵢ = sᵢ ẍ_d,ᵢ + δᵢ,     range(Z) = range(N_k)

so level i's task acceleration is exactly Jᵢ a + J̇ᵢq̇ = vᵢ, whatever the other levels do, and
x = (s, δ, z). The lexicographic solve (`solve/lexicographic.py`) then fixes, highest first:

    0      |τ(x)| ≤ τ_max and the joint/Cartesian bounds                       hard
    i      level i: the largest scaling sᵢ ∈ [0, 1] with δᵢ = 0; only if none is feasible,
           the smallest bend ‖δᵢ‖² (task units), then the largest scaling with it
    last   ½‖a − a₀‖²_M over the freedom left (z): the acceleration energy ½(τ − g)ᵀM⁻¹(τ − g);
           with an over-constrained lowest level (a posture), ½‖J a(x) + J̇q̇ − ẍ_d‖² first

So a level is first *scaled* (direction kept, sᵢ reported) and only bent when no scaling in
[0, 1] is feasible, and it is optimal given every level above it, exactly. With no bound active
the optimum is s = 1, δ = 0 and the energy-optimal z: the closed-form dynamically consistent
hierarchy (P2) with a passive null space (P3). The over-constrained lowest level aims at the
acceleration the levels above actually get, and has no scaling variable (a free s would be
chosen to fit its least squares and slow a posture down even in free motion).
"""

from __future__ import annotations

import casadi as ca

from ..symbolic.linalg import null_space_basis, product, symmetric_product
from .hierarchy import NULL_SPACE_REGULARIZATION, least_squares_objective, level_structure, recursive_hierarchy
from .problem import ControlProblem
from .qp import INF, Affine, ControlLaw, PriorityVariables, with_limits

# A level with a run-time activation leaves the freedom N_k z (z: a joint acceleration, n of them
# for fewer directions). Where a level is half active or damped, N_k is no projector: the levels
# below it leak into its directions with a gain as small as 1e-7. Unbounded, a stage could grow z
# to 1e9 along such a direction to win a few rad/s² of a level above (found from outside: an
# xArm7 with two half-active levels, its reach level at s = 1 in the C runtime and 0.135 in the
# Python one, the torques 40.7 Nm apart, both status "ok"; at 1e9 the tasks' model is rounding).
# So z is bounded at this many times the largest joint acceleration the torque limits can give,
# a bound no physical answer reaches, at which a leak of 1e-7 moves a task by ~1e-2 of its units.
RELEASED_REACH = 10.0


def released_bound(problem: ControlProblem) -> ca.SX:
    """RELEASED_REACH × max_j (|a₀ⱼ| + Σₖ |M⁻¹ⱼₖ| (τ_max,k + |gₖ|)): a bound on every |a_j| the
    torque limits allow (a = a₀ + M⁻¹(τ − g)), times the margin."""
    reach = ca.fabs(problem.free_acceleration) + ca.mtimes(
        ca.fabs(problem.mass_matrix_inverse), problem.torque_limit + ca.fabs(problem.gravity))
    return RELEASED_REACH * ca.mmax(reach)


def dcts(problem: ControlProblem) -> ControlLaw:
    """The DCTS lexicographic QP with torque, joint and Cartesian bounds."""
    structure = level_structure(problem)
    levels = problem.levels
    exact = levels[: structure.exact_levels]
    n, k = problem.n, len(exact)
    # A level with a run-time activation releases its directions as the activation falls: the
    # freedom left is range(N_k) of the activated recursion, which no fixed basis spans; it is
    # then N_k z with n variables (their part along null(N_k) held at 0 by a regularization).
    released = any(lv.activation is not None for lv in exact)
    nz = n if released else structure.free_dimension
    dims = [lv.dim for lv in exact]
    nx = k + sum(dims) + nz
    variables = [f"s[{lv.priority}]" for lv in exact]
    for lv in exact:
        variables += [f"delta[{lv.priority}][{j}]" for j in range(lv.dim)]
    variables += [f"z[{j}]" for j in range(nz)]
    z = list(range(nx - nz, nx))

    commands, priorities = [], []
    start = k
    for i, lv in enumerate(exact):
        matrix = ca.SX(lv.dim, nx)
        matrix[:, i] = lv.target
        matrix[:, start : start + lv.dim] = ca.SX.eye(lv.dim)
        commands.append(Affine(ca.SX.zeros(lv.dim), matrix))
        priorities.append(PriorityVariables(lv.priority, i, list(range(start, start + lv.dim))))
        start += lv.dim

    a, N = recursive_hierarchy(problem, commands, nx)
    matrix = a.matrix
    H = ca.SX(nx, nx)
    f = ca.SX(nx, 1)
    for i in range(k + sum(dims)):
        H[i, i] = 1.0  # s and δ are fixed by their levels before this objective: it only needs H ≻ 0
    f[:k] = -1.0
    notes = []
    mass_acceleration = None
    if nz:
        # The freedom left by the exact levels is null([J₁; …; J_k]) = range(N_k); a basis of it
        # keeps the QP small (N_k z would carry n variables for n − Σmᵢ directions).
        if released:
            Z = N
        else:
            Z = null_space_basis(ca.vertcat(*[lv.jacobian for lv in exact])) if k else ca.SX.eye(n)
        matrix[:, z] = Z
        if structure.least_squares_last:
            last = levels[-1]
            mass_acceleration = product(problem.mass_matrix, matrix)  # (the torque rows' too)
            Hx, fx = least_squares_objective(last, Affine(a.offset, matrix), mass_acceleration)
            H += Hx
            f += fx
            notes.append(f"priority {last.priority} is over-constrained: solved in least squares")
        else:
            H[z, z] = symmetric_product(Z, product(problem.mass_matrix, Z))
        if released:
            complement = ca.SX.eye(n) - N
            H[z, z] += NULL_SPACE_REGULARIZATION * symmetric_product(complement, complement)
    acceleration = Affine(a.offset, matrix)

    z_max = released_bound(problem) if released else INF
    lbx = [0.0] * k + [-INF] * (nx - k - nz) + [-z_max] * nz
    ubx = [1.0] * k + [INF] * (nx - k - nz) + [z_max] * nz
    qp, torque = with_limits(problem, acceleration, H, f, lbx, ubx, variables, priorities, mass_acceleration)
    scaling = Affine(ca.SX.zeros(len(levels)), ca.SX(len(levels), nx))
    for i in range(k):
        scaling.matrix[i, i] = 1.0
    law = ControlLaw(torque, scaling, qp, notes, acceleration=acceleration, spare_variables=released)
    if structure.least_squares_last:
        # its scaling is filled in after the solve (controller), from its task acceleration
        scaling.offset[-1] = 1.0
        law.least_squares_task = (product(levels[-1].jacobian, acceleration.matrix),
                                  ca.mtimes(levels[-1].jacobian, acceleration.offset) + levels[-1].bias)
    return law
