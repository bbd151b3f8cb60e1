"""DCTS — the paper's Dynamically-consistent Constrained Task hierarchy Solver, in hierarchy coordinates.

The paper's QP (section III-C) minimizes ½τᵀM⁻¹τ + Σ wᵢ(1 − sᵢ)² over q̈ = Σ Nᵢ q̈ᵢ with the
block constraints Jᵢ q̈ᵢ = sᵢ ẍᵢ − J̇ᵢ q̇ − Jᵢ M⁻¹ τ_ext. As printed it does not enforce the
lower priorities: each block constraint leaves n − mᵢ directions of q̈₁ free and those can cancel
Nᵢ q̈ᵢ (Jᵢ N₁ … = 0 does not stop it), so a posture task had no effect and the null space drifted.

dcts keeps the paper's ingredients — acceleration energy with gravity compensated, task scaling
factors sᵢ ∈ [0, 1] maximized with weights wᵢ ≫ wᵢ₊₁, dynamically consistent projectors, measured
τ_ext in tasks and limits, torque and acceleration bounds — but parametrizes the acceleration by
the recursive dynamically consistent hierarchy instead (see `hierarchy.py`):

    a(x) = hierarchy(v₁ … v_k) + Z z,     vᵢ = sᵢ ẍ_d,ᵢ + δᵢ,     range(Z) = range(N_k)

so every level holds by construction, lower levels compensate for what higher levels do, and
the QP only chooses x = (s, δ, z):
  - sᵢ scales level i's desired acceleration (the paper's scaling, direction kept), penalized
    wᵢ(1 − sᵢ)²;
  - δᵢ changes its direction, penalized wᵢ κ/(‖ẍ_d,ᵢ‖² + 1)·‖δᵢ‖² so that scaling comes first;
    without it a level could only slow down, and a joint limit that needs the task to bend
    would make the QP infeasible;
  - z moves the null space left by all levels (in an orthonormal basis Z of it), penalized by
    its acceleration energy ½‖Z z‖²_M (the part of ½(τ − g)ᵀM⁻¹(τ − g) the tasks do not fix).
With no bound active the optimum is s = 1, δ = 0, z = 0: exactly the closed-form hierarchy,
i.e. the Gauss-principle (minimum acceleration energy) solution. The energy of the task part
is left out of the objective on purpose: it is the w → ∞ limit of the paper's trade-off, and
keeping it would bias every task by 1/w.

A lowest level that is over-constrained (typically a posture that asks for all joints) is solved
in least squares within the remaining freedom, as the closed form with a pseudo-inverse does,
against the acceleration the levels above command when they are not scaled.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from ..symbolic.linalg import cholesky, cholesky_solve, null_space_basis
from .hierarchy import LevelStructure, least_squares_objective, level_structure, recursive_hierarchy
from .problem import ControlProblem
from .qp import INF, Affine, ControlLaw, with_limits

SCALING_PREFERENCE = 10.0  # κ: changing a task's direction costs this much more than scaling it
SCALING_FLOOR = 1e-6  # (task acceleration)²: below this a least-squares level needs no correction


@dataclass
class HierarchyQP:
    """Variables, acceleration map and objective shared by dcts and osc."""

    structure: LevelStructure
    variables: list[str]
    acceleration: Affine  # a(x)
    nominal_acceleration: ca.SX  # a at s = 1, δ = 0, z = 0
    hessian: ca.SX
    gradient: ca.SX
    lbx: list[float]
    ubx: list[float]
    scaling_columns: list[int]  # x index of each exact level's s
    z_columns: list[int]

    @property
    def unconstrained_z(self) -> ca.SX:
        """z at the optimum without bounds (s = 1, δ = 0): H_zz z = −f_z."""
        z = self.z_columns
        return cholesky_solve(cholesky(self.hessian[z, z]), -self.gradient[z])


def hierarchy_qp(problem: ControlProblem) -> HierarchyQP:
    """The hierarchy parametrized by x = (s, δ, z) and the objective of dcts, without bounds."""
    structure = level_structure(problem)
    levels = problem.levels
    exact = levels[: structure.exact_levels]
    n, k = problem.n, len(exact)
    nz = structure.free_dimension
    dims = [lv.dim for lv in exact]
    nx = k + sum(dims) + nz
    variables = [f"s[{lv.priority}]" for lv in exact]
    for lv in exact:
        variables += [f"delta[{lv.priority}][{j}]" for j in range(lv.dim)]
    variables += [f"z[{j}]" for j in range(nz)]
    z_columns = list(range(nx - nz, nx))

    commands = []
    H = ca.SX(nx, nx)
    f = ca.SX(nx, 1)
    start = k
    for i, lv in enumerate(exact):
        matrix = ca.SX(lv.dim, nx)
        matrix[:, i] = lv.target
        matrix[:, start : start + lv.dim] = ca.SX.eye(lv.dim)
        commands.append(Affine(ca.SX.zeros(lv.dim), matrix))
        # w (1 − s)² = w − 2w s + w s²  →  H_ss = 2w, f_s = −2w
        H[i, i] = 2.0 * lv.weight
        f[i] = -2.0 * lv.weight
        direction_weight = lv.weight * SCALING_PREFERENCE / (ca.sumsqr(lv.target) + 1.0)
        H[start : start + lv.dim, start : start + lv.dim] = 2.0 * direction_weight * ca.SX.eye(lv.dim)
        start += lv.dim

    a, _ = recursive_hierarchy(problem, commands, nx)
    nominal = a.offset + sum((a.matrix[:, i] for i in range(k)), ca.SX.zeros(n))
    matrix = a.matrix
    if nz:
        # The freedom left by the exact levels is null([J₁; …; J_k]) = range(N_k); a basis of it
        # keeps the QP small (N_k z would carry n variables for n − Σmᵢ directions).
        Z = null_space_basis(ca.vertcat(*[lv.jacobian for lv in exact])) if k else ca.SX.eye(n)
        matrix[:, z_columns] = Z
        if structure.least_squares_last:
            last = levels[-1]
            Hz, fz = least_squares_objective(last, nominal, Z, problem.mass_matrix, last.weight, normalized=True)
            H[z_columns, z_columns] = Hz
            f[z_columns] = fz
        else:
            H[z_columns, z_columns] = ca.mtimes([Z.T, problem.mass_matrix, Z])
    acceleration = Affine(a.offset, matrix)

    lbx = [0.0] * k + [-INF] * (nx - k)
    ubx = [1.0] * k + [INF] * (nx - k)
    return HierarchyQP(structure, variables, acceleration, nominal, H, f, lbx, ubx, list(range(k)), z_columns)


def level_scaling(problem: ControlProblem, hqp: HierarchyQP) -> Affine:
    """One scaling per priority level: sᵢ for exact levels; for a least-squares lowest level, the
    share of its unconstrained correction that is achieved, ⟨J Z z, J Z z*⟩/‖J Z z*‖² (1 when the
    bounds leave it alone, less when they make it give in; 1 when it needs no correction)."""
    levels = problem.levels
    offset = ca.SX.ones(len(levels))
    matrix = ca.SX(len(levels), len(hqp.variables))
    for i, column in enumerate(hqp.scaling_columns):
        offset[i] = 0.0
        matrix[i, column] = 1.0
    z = hqp.z_columns
    if hqp.structure.least_squares_last and z:
        JZ = ca.mtimes(levels[-1].jacobian, hqp.acceleration.matrix[:, z])
        wanted = ca.mtimes(JZ, hqp.unconstrained_z)
        norm = ca.sumsqr(wanted) + SCALING_FLOOR
        offset[-1] = SCALING_FLOOR / norm
        matrix[-1, z] = ca.mtimes(wanted.T, JZ) / norm
    return Affine(offset, matrix)


def dcts(problem: ControlProblem) -> ControlLaw:
    """The DCTS QP with torque, joint and Cartesian bounds."""
    hqp = hierarchy_qp(problem)
    qp, torque = with_limits(problem, hqp.acceleration, hqp.hessian, hqp.gradient, hqp.lbx, hqp.ubx, hqp.variables)
    notes = []
    if hqp.structure.least_squares_last:
        notes.append(f"priority {problem.levels[-1].priority} is over-constrained: solved in least squares")
    return ControlLaw(torque, level_scaling(problem, hqp), qp, notes)
