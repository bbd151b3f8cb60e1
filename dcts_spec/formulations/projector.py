"""Projector baseline: the paper's comparison for experiment 3 (its "SCS"): the closed-form
dynamically consistent hierarchy, joint limits by saturation in the null space with its task
scaling, naive torque clipping.

Joint position and velocity limits are shaped into joint acceleration bounds exactly as for the
other formulations (`limits/viability.py`). Saturation in the null space (SNS: Flacco, De Luca,
Khatib, "Control of redundant robots under hard joint constraints: saturation in the null
space", IEEE T-RO 31(3), 2015, its acceleration-level algorithm with task scaling) runs per
priority level, highest first, on the levels solved exactly:

    q̈(s) = b + a s: the hierarchy with this level's command s ẍ_d (levels above at their scales)
    if every free joint is within its bounds at s = 1: done, s = 1
    s_max: the largest s ∈ [0, 1] keeping every free joint within its bounds (0 if none);
      the joint limiting it most is the most critical one
    remember (s_max, locks) if s_max is the best so far
    lock the most critical joint at the bound it exceeds at s = 1, and repeat
    if this level lost rank with the new lock: done, with the best remembered scaling and locks

Like the paper's eq. (5), the scaling multiplies ẍ_d, not −J̇q̇. Locking keeps the dynamical
consistency of the rest: the metric is the mass matrix of the robot with the locked joints'
accelerations prescribed (Gauss's principle). Locks carry over to the levels below. An
over-constrained lowest level (met in least squares) is not scaled: its violating joints are
locked one by one, the most violating first, unless a lock would take rank from the levels above. Every loop is unrolled n + 1 times, so the
generated code has a fixed cost. As in the paper, each torque is finally clipped to its limit
without re-solving ("naive" saturation): SNS knows no torque limits, which is what breaks the
velocity limits.
"""

from __future__ import annotations

import casadi as ca

from ..symbolic.linalg import cholesky, spd_inverse
from .hierarchy import least_squares_step, level_structure, recursive_hierarchy
from .problem import ControlProblem
from .qp import Affine, ControlLaw

BIG = 1e6
RANK_LOST = 1e-9  # det(G)/mean eigenvalue^m below which a level has lost rank (~ λ_min < 1e-9 mean)
_TINY = 1e-12  # a joint's acceleration that does not depend on the scaling (|a_j| below this)


def _joint_bounds(problem: ControlProblem) -> tuple[ca.SX, ca.SX]:
    """Per-joint acceleration bounds, the problem's joint rows (±BIG for joints without limits),
    within the joint acceleration limits. The rows let the way back to a position or velocity
    bound brake beyond the acceleration limit (`limits/viability.py`); the baseline's own
    scheme, which the paper compares with, keeps every bound within it."""
    n = problem.n
    rows = problem.acceleration_rows
    lower, upper = -BIG * ca.SX.ones(n), BIG * ca.SX.ones(n)
    for r, name in enumerate(rows.names):
        if name.startswith("joint:"):
            j = problem.robot.joint_names.index(name.removeprefix("joint:"))
            limit = problem.acceleration_limit[j]
            lower[j], upper[j] = (ca.fmin(ca.fmax(bound, -limit), limit) for bound in (rows.lower[r], rows.upper[r]))
    return lower, upper


def _locked(problem: ControlProblem, free: ca.SX, locked_acceleration: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
    """(metric inverse, free acceleration, N₀) of the robot whose joints with free_j = 0 have their
    acceleration prescribed: Gauss's principle on the free joints, whose mass matrix is W M W (the
    identity on the locked joints keeps it invertible)."""
    W = ca.diag(free)
    M = problem.mass_matrix
    fixed = (1.0 - free) * locked_acceleration
    metric_inverse = ca.mtimes([W, spd_inverse(ca.mtimes([W, M, W]) + ca.diag(1.0 - free)), W])
    free_acceleration = fixed + ca.mtimes(
        metric_inverse, problem.external_torque - problem.coriolis - ca.mtimes(M, fixed))
    return metric_inverse, free_acceleration, W


def _rank_lost(problem: ControlProblem, level: int, metric_inverse: ca.SX, W: ca.SX) -> ca.SX:
    """1 where the levels down to `level`, stacked, have lost rank on the free joints:
    det(G) < RANK_LOST · mean eigenvalue^m for G = J W M⁻¹ W Jᵀ (a lock makes G exactly singular;
    a lock for a lower level may take a higher one's rank too).
    The determinant (the product of the Cholesky pivots²), not the smallest pivot: without
    pivoting the lost direction spreads over several pivots (a lock left the iiwa14's tool, on
    joint 7's axis, with joints 2, 4 and 7: pivots² 0.2, 1.3e-6, 8e-9 of a G with eigenvalues
    0.25, 0.08, 0)."""
    Jr = ca.mtimes(ca.vertcat(*[lv.jacobian for lv in problem.levels[: level + 1]]), W)
    gram = ca.mtimes([Jr, metric_inverse, Jr.T])
    m = gram.shape[0]
    mean = ca.trace(gram) / m + 1e-300
    determinant = ca.SX(1.0)
    for pivot in ca.vertsplit(ca.diag(cholesky(gram + 1e-12 * mean * ca.SX.eye(m)))):
        determinant = determinant * pivot**2
    return determinant < RANK_LOST * mean**m


def _one_hot_min(values: ca.SX) -> ca.SX:
    """The one-hot vector of the smallest entry (the first of equal ones)."""
    n = values.shape[0]
    pick = ca.SX.zeros(n)
    pick[0] = 1.0
    smallest = values[0]
    for j in range(1, n):
        one = ca.SX.zeros(n)
        one[j] = 1.0
        pick = ca.if_else(values[j] < smallest, one, pick)
        smallest = ca.fmin(smallest, values[j])
    return pick


def _select(mask: ca.SX, chosen: ca.SX, other: ca.SX) -> ca.SX:
    """chosen where mask_j = 1, else other, per joint. Not other + mask (chosen − other): chosen may
    be NaN where it is not chosen (the hierarchy once every joint that moves the level is locked)."""
    return ca.vertcat(*[ca.if_else(mask[j] > 0.5, chosen[j], other[j]) for j in range(mask.shape[0])])


def _task_scaling(a: ca.SX, b: ca.SX, free: ca.SX, lower: ca.SX, upper: ca.SX) -> tuple[ca.SX, ca.SX]:
    """SNS's task scaling factor of q̈(s) = b + a s over the free joints, and the most critical joint
    (one-hot): the largest s ∈ [0, 1] with lower ≤ q̈(s) ≤ upper, 0 when there is none."""
    n = a.shape[0]
    s_max, s_min = ca.SX.zeros(n), ca.SX.zeros(n)
    for j in range(n):
        inside = ca.logic_and(b[j] >= lower[j], b[j] <= upper[j])
        safe = ca.if_else(ca.fabs(a[j]) > _TINY, a[j], 1.0)
        to_upper, to_lower = (upper[j] - b[j]) / safe, (lower[j] - b[j]) / safe
        high = ca.if_else(a[j] > _TINY, to_upper, ca.if_else(a[j] < -_TINY, to_lower, ca.if_else(inside, BIG, -BIG)))
        low = ca.if_else(a[j] > _TINY, to_lower, ca.if_else(a[j] < -_TINY, to_upper, ca.if_else(inside, -BIG, BIG)))
        s_max[j] = ca.if_else(free[j] > 0.5, high, BIG)  # a locked joint is at its bound whatever s
        s_min[j] = ca.if_else(free[j] > 0.5, low, -BIG)
    critical = _one_hot_min(s_max)
    largest, smallest = ca.mmin(s_max), ca.mmax(s_min)
    infeasible = ca.logic_or(ca.logic_or(smallest > largest, largest < 0.0), smallest > 1.0)
    return ca.if_else(infeasible, 0.0, ca.fmin(largest, 1.0)), critical


def _scaled_level(problem: ControlProblem, level: int, commands: list[Affine], free: ca.SX, locked: ca.SX,
                  lower: ca.SX, upper: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
    """SNS on one exactly solved level below `commands` (the levels above, at their scales):
    its scaling, and the free joints and locked accelerations it leaves."""
    target = problem.levels[level].target
    command = Affine(ca.SX.zeros(target.shape[0]), target)  # s ẍ_d
    done, scale = ca.SX(0.0), ca.SX(1.0)
    best_scale, best_free, best_locked = ca.SX(-1.0), free, locked
    out_free, out_locked = free, locked
    just_locked = ca.SX(0.0)
    for _ in range(problem.n + 1):
        metric_inverse, a0, W = _locked(problem, free, locked)
        # a lock just made a level lose rank: take the best scaling remembered
        stop = (1.0 - done) * just_locked * _rank_lost(problem, level, metric_inverse, W)
        scale = ca.if_else(stop, ca.fmax(best_scale, 0.0), scale)
        out_free, out_locked = ca.if_else(stop, best_free, out_free), ca.if_else(stop, best_locked, out_locked)
        done = ca.fmax(done, stop)
        h, _ = recursive_hierarchy(problem, [*commands, command], 1, metric_inverse, a0, W)
        b, a = h.offset, h.matrix[:, 0]
        full = a + b
        exceeded = ca.mmax(free * ca.fmax(ca.fmax(full - upper, lower - full), 0.0)) > 0.0
        feasible = (1.0 - done) * (1.0 - exceeded)  # within every bound at s = 1
        scale = ca.if_else(feasible, 1.0, scale)
        out_free, out_locked = ca.if_else(feasible, free, out_free), ca.if_else(feasible, locked, out_locked)
        done = ca.fmax(done, feasible)
        active = (1.0 - done) * exceeded
        s, critical = _task_scaling(a, b, free, lower, upper)
        # ≥: on a tie (s = 0 once the state is already beyond a bound, which SNS assumes never
        # happens) keep the later locks, which hold more joints at their bounds
        better = active * (s >= best_scale)
        best_scale = ca.if_else(better, s, best_scale)
        best_free, best_locked = ca.if_else(better, free, best_free), ca.if_else(better, locked, best_locked)
        lock = active * critical
        locked = _select(lock, ca.fmin(ca.fmax(full, lower), upper), locked)
        free = free * (1.0 - lock)
        just_locked = active
    # every joint locked without a verdict: the best remembered
    scale = ca.if_else(done, scale, ca.fmax(best_scale, 0.0))
    return scale, ca.if_else(done, out_free, best_free), ca.if_else(done, out_locked, best_locked)


def _least_squares_level(problem: ControlProblem, commands: list[Affine], free: ca.SX, locked: ca.SX,
                         lower: ca.SX, upper: ca.SX) -> ca.SX:
    """The acceleration with an over-constrained lowest level met in least squares, its violating
    joints locked one by one (the most violating first). A lock that would take rank from the
    levels above is not made (that joint stays free and the next one is tried): the lowest level
    must not change what they get (locking every joint the tool needs once turned its
    acceleration around)."""
    def acceleration(free: ca.SX, locked: ca.SX) -> tuple[ca.SX, ca.SX]:
        """The least-squares acceleration with these locks, and 1 where they cost the levels above rank."""
        metric_inverse, a0, W = _locked(problem, free, locked)
        h, N = recursive_hierarchy(problem, commands, 1, metric_inverse, a0, W)
        lost = _rank_lost(problem, len(commands) - 1, metric_inverse, W) if commands else ca.SX(0.0)
        return least_squares_step(problem.levels[-1], h.offset, N, problem.mass_matrix), lost

    result, _ = acceleration(free, locked)
    kept = ca.SX.zeros(problem.n)  # joints whose lock was refused
    for _ in range(problem.n):
        violation = free * (1.0 - kept) * ca.fmax(ca.fmax(result - upper, lower - result), 0.0)
        worst = _one_hot_min(-violation) * (ca.mmax(violation) > 0)
        tried_locked = _select(worst, ca.fmin(ca.fmax(result, lower), upper), locked)
        tried_free = free * (1.0 - worst)
        tried, lost = acceleration(tried_free, tried_locked)
        refused = ca.mmax(worst) * lost
        kept = kept + refused * worst
        take = ca.mmax(worst) * (1.0 - lost)
        locked = ca.if_else(take, tried_locked, locked)
        free = ca.if_else(take, tried_free, free)
        result = ca.if_else(take, tried, result)
    return result


def projector(problem: ControlProblem) -> ControlLaw:
    n = problem.n
    lower, upper = _joint_bounds(problem)
    structure = level_structure(problem)
    free, locked = ca.SX.ones(n), ca.SX.zeros(n)
    commands: list[Affine] = []
    scales = []
    for i in range(structure.exact_levels):
        s, free, locked = _scaled_level(problem, i, commands, free, locked, lower, upper)
        scales.append(s)
        target = problem.levels[i].target
        commands.append(Affine(s * target, ca.SX.zeros(target.shape[0], 1)))
    if structure.least_squares_last:
        acceleration = _least_squares_level(problem, commands, free, locked, lower, upper)
        scales.append(ca.SX(1.0))
    else:
        metric_inverse, a0, W = _locked(problem, free, locked)
        acceleration = recursive_hierarchy(problem, commands, 1, metric_inverse, a0, W)[0].offset
    torque = Affine.constant(problem.torque(acceleration), 0)
    scaling = Affine.constant(ca.vertcat(*scales), 0)
    return ControlLaw(torque, scaling, enforces_torque_limits=False)
