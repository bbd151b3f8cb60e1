"""Independent reference for the strict lexicographic hierarchy that `dcts` promises.

Computed from Pinocchio numerics (tests/reference.py: tasks and dynamics) and the shaped bounds of
tests/formulation_cases.py, as a cascade of exact LPs/QPs solved with HiGHS. Nothing here uses
dcts_spec's symbolic layer, formulations or solver.

Semantics, with a the ACTUAL joint acceleration (τ = M a + ν + g − τ_ext, measured τ_ext):

  hard     |τ| ≤ τ_max, lo_j ≤ a_j ≤ hi_j, lo ≤ J_c a + J̇_c q̇ ≤ hi
  level i  (i.a) min ‖δ_i‖² with J_i a + J̇_i q̇ = s_i ẍ_d,i + δ_i, s_i ∈ [0, 1]
           (i.b) with δ_i fixed, max s_i; then J_i a + J̇_i q̇ is fixed for the levels below
  last     an over-constrained lowest level: min ‖J a + J̇q̇ − ẍ_d‖² (no scaling variable)
  energy   min ½(a − a0)ᵀM(a − a0), a0 = M⁻¹(τ_ext − ν)

Each stage works in the freedom the levels above leave: a = a_k + N_k z with N_k an orthonormal
basis of the null space of the stacked Jacobians of the fixed levels, so a fixed level stays
exactly fixed. A level is first tried with δ = 0 (an LP: the largest feasible s); only if that LP
is infeasible is the bend δ* found by a QP and the scaling maximized with δ pinned to δ* (within
a tolerance far below the test tolerances). Every stage's a is certified against the hard rows.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import highspy
import numpy as np
import pinocchio as pin

from formulation_cases import cartesian_accelerations, joint_acceleration_bounds
from reference import NumericTask, dynamics, task_terms

INF = highspy.kHighsInf
FEASIBILITY_TOLS = (1e-10, 1e-9, 1e-8)  # HiGHS primal/dual feasibility tolerances, tried in turn
CERTIFY_TOL = 1e-8  # a stage's a may break a hard row by at most this, relative to max(1, |bound|)
DELTA_PIN_TOL = 1e-9  # |δ − δ*| allowed when maximizing s on a bent level where δ = δ* exactly fails, relative to max(1, |ẍ_d|)
QP_TIME_LIMIT = 2.0  # s, per HiGHS solve
POLISH_ITERATIONS = 20000  # the active-set method from HiGHS's answer (exact_qp)
# A row that the freedom left by the levels does not touch, except by the round-off of its null
# basis, must not constrain the next step: a UR5 state's posture stopped 3.7e-5 rad/s² short of its
# optimum to keep a joint row, at its bound, from being crossed by 1.9e-10 rad/s², the null
# direction touching that row by 5e-13. (Widening every row by 1e-10 instead let a Panda state's
# posture gain 4e-3 rad/s² by crossing two active rows by 3e-10: too ill-conditioned for that.)
NULL_ROUNDOFF = 1e-11
NULL_TOL = 1e-9  # singular values below this (relative to max(1, σ_max)) span the null space


class ReferenceError(RuntimeError):
    """A stage of the reference failed (solver status or certification)."""


@dataclass
class HardRows:
    """lo ≤ G a ≤ hi: the torque, joint-acceleration and Cartesian rows, with names."""

    G: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    names: list[str]

    def margins(self, a: np.ndarray) -> np.ndarray:
        """Relative distance inside each row (< 0: violated), relative to max(1, |bound|)."""
        v = self.G @ a
        with np.errstate(invalid="ignore"):
            low = np.where(np.isfinite(self.lo), (v - self.lo) / np.maximum(1.0, np.abs(self.lo)), np.inf)
            high = np.where(np.isfinite(self.hi), (self.hi - v) / np.maximum(1.0, np.abs(self.hi)), np.inf)
        return np.minimum(low, high)

    def violation(self, a: np.ndarray) -> float:
        m = self.margins(a)
        return float(max(0.0, -m.min())) if m.size else 0.0


@dataclass
class Level:
    J: np.ndarray
    bias: np.ndarray  # J̇ q̇
    target: np.ndarray  # ẍ_d
    priority: int


@dataclass
class LexicographicSolution:
    feasible: bool  # the hard rows admit some a (else nothing below is computed)
    margin: float  # the largest uniform relative margin of the hard rows (LP); < 0: infeasible
    levels: list[Level]
    achieved: list[np.ndarray] = field(default_factory=list)  # J_i a + J̇_i q̇ per level
    scaling: list[float] = field(default_factory=list)  # s_i (nan for a least-squares level)
    bend: list[np.ndarray] = field(default_factory=list)  # δ_i (least-squares residual for the last)
    least_squares_last: bool = False
    a: np.ndarray | None = None  # actual joint acceleration
    tau: np.ndarray | None = None  # joint torque (gravity included)
    hard: HardRows | None = None
    a0: np.ndarray | None = None


# -- HiGHS ---------------------------------------------------------------------------------------


def solve_highs(c, A, lA, uA, lx, ux, Q=None, sense_max: bool = False):
    """min (or max) cᵀx + ½xᵀQx s.t. lA ≤ A x ≤ uA, lx ≤ x ≤ ux. Returns (x, status string).

    HiGHS's QP solver can stop with "Solve error" at degenerate vertices when its tolerances are
    very tight: retried with looser ones (QP solutions are polished on their active set after)."""
    status = ""
    for tol in FEASIBILITY_TOLS:
        x, status = _solve_highs(c, A, lA, uA, lx, ux, Q, sense_max, tol)
        if x is not None or status in ("Infeasible", "Time limit reached"):
            return x, status
    return None, status


def _solve_highs(c, A, lA, uA, lx, ux, Q, sense_max, tol):
    c = np.asarray(c, dtype=float)
    nx = c.size
    A = np.asarray(A, dtype=float).reshape(-1, nx)
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("primal_feasibility_tolerance", tol)
    h.setOptionValue("dual_feasibility_tolerance", tol)
    h.setOptionValue("presolve", "off")
    # HiGHS's QP solver was seen to cycle for ever on a degenerate bend stage (panda, 4 levels):
    # a bounded search, then the active-set method's answer stands alone (exact_qp)
    h.setOptionValue("time_limit", QP_TIME_LIMIT)
    lp = highspy.HighsLp()
    lp.num_col_ = nx
    lp.num_row_ = A.shape[0]
    lp.col_cost_ = -c if sense_max else c
    lp.col_lower_ = np.where(np.isfinite(lx), lx, -INF)
    lp.col_upper_ = np.where(np.isfinite(ux), ux, INF)
    lp.row_lower_ = np.where(np.isfinite(lA), lA, -INF)
    lp.row_upper_ = np.where(np.isfinite(uA), uA, INF)
    mat = lp.a_matrix_
    mat.format_ = highspy.MatrixFormat.kColwise
    starts, index, value = [0], [], []
    for j in range(nx):
        nz = np.flatnonzero(A[:, j])
        index.extend(nz.tolist())
        value.extend(A[nz, j].tolist())
        starts.append(len(index))
    mat.start_, mat.index_, mat.value_ = starts, index, value
    mat.num_col_, mat.num_row_ = nx, A.shape[0]
    model = highspy.HighsModel()
    model.lp_ = lp
    if Q is not None:
        Q = 0.5 * (Q + Q.T)
        hess = highspy.HighsHessian()
        hess.dim_ = nx
        hess.format_ = highspy.HessianFormat.kTriangular
        hs, hi, hv = [0], [], []
        for j in range(nx):  # lower triangle, column-wise
            rows = np.arange(j, nx)
            nz = rows[Q[j:, j] != 0.0]
            hi.extend(nz.tolist())
            hv.extend(Q[nz, j].tolist())
            hs.append(len(hi))
        hess.start_, hess.index_, hess.value_ = hs, hi, hv
        model.hessian_ = hess
    h.passModel(model)
    h.run()
    status = h.modelStatusToString(h.getModelStatus())
    if h.getModelStatus() != highspy.HighsModelStatus.kOptimal:
        return None, status
    return np.array(h.getSolution().col_value), status


def active_set_qp(H, f, C, lower, upper, x0, max_iter: int = 1000) -> np.ndarray:
    """min ½xᵀHx + fᵀx s.t. lower ≤ C x ≤ upper by a dense primal active-set method (H PSD).

    x0 must be feasible and the feasible set bounded (torque rows bound every acceleration). Each
    iterate solves the equality-constrained subproblem exactly by a null-space eigen-solve (a
    descent ray where the reduced Hessian is singular), so the result is exact to round-off —
    HiGHS's QP solver was found to report "Optimal" for points far outside the constraints.
    """
    H = 0.5 * (H + H.T)
    norms = np.maximum(np.linalg.norm(C, axis=1), 1e-300)
    C, lower, upper = C / norms[:, None], lower / norms, upper / norms  # unit rows
    x = np.array(x0, dtype=float)
    working: dict[int, int] = {}  # row -> -1 (at lower) | +1 (at upper)
    scale = max(1.0, np.abs(H).max(), np.abs(f).max())
    for _ in range(max_iter):
        g = H @ x + f
        rows = sorted(working)
        A_w = C[rows] if rows else np.zeros((0, x.size))
        Z = null_basis(A_w)
        ray = False
        if Z.shape[1]:
            Hr, gr = Z.T @ H @ Z, Z.T @ g
            ev, V = np.linalg.eigh(Hr)
            zero = ev <= 1e-11 * max(1.0, ev.max())
            gz = V[:, zero].T @ gr
            if zero.any() and np.linalg.norm(gz) > 1e-12 * scale:
                p, ray = -Z @ (V[:, zero] @ gz), True
            else:
                keep = ~zero
                p = -Z @ (V[:, keep] @ ((V[:, keep].T @ gr) / ev[keep]))
        else:
            p = np.zeros_like(x)
        if not ray and np.linalg.norm(p) <= 1e-13 * max(1.0, np.linalg.norm(x)):
            if not rows:
                return x
            lam = np.linalg.lstsq(A_w.T, g, rcond=None)[0]  # g = A_wᵀ λ
            # at a lower bound the gradient must point inside (λ ≥ 0), at an upper bound λ ≤ 0
            wrong = np.array([-lam[k] if working[r] < 0 else lam[k] for k, r in enumerate(rows)])
            k = int(np.argmax(wrong))
            if wrong[k] <= 1e-10 * max(1.0, np.linalg.norm(g)):
                return x
            del working[rows[k]]
            continue
        Cp, Cx = C @ p, C @ x
        alpha, block, side = (np.inf if ray else 1.0), None, 0
        for j in range(C.shape[0]):
            if j in working:
                continue
            if Cp[j] > 1e-14 * np.linalg.norm(p) and np.isfinite(upper[j]):
                t = max(0.0, (upper[j] - Cx[j]) / Cp[j])
                if t < alpha:
                    alpha, block, side = t, j, 1
            elif Cp[j] < -1e-14 * np.linalg.norm(p) and np.isfinite(lower[j]):
                t = max(0.0, (lower[j] - Cx[j]) / Cp[j])
                if t < alpha:
                    alpha, block, side = t, j, -1
        if not np.isfinite(alpha):
            raise ReferenceError("active-set QP: unbounded ray")
        x = x + alpha * p
        if block is not None:
            working[block] = side
    raise ReferenceError("active-set QP: no convergence")


def exact_qp(H, f, C, lower, upper, x0) -> np.ndarray:
    """min ½xᵀHx + fᵀx s.t. lower ≤ C x ≤ upper by two solvers, keeping the best answer that holds
    the rows (to CERTIFY_TOL): the active-set method above from x0, HiGHS's QP solver, and the
    active-set method from HiGHS's answer. Each was seen to fail where the others did not: HiGHS
    reporting "Optimal" outside the rows, or 2 × the least bend inside them (panda, two levels;
    the active-set method from there reached the least one in ~5,000 steps), or 3.7e-5 off in a
    direction the objective barely sees (UR5, three levels); the active-set method stopping at a
    bend 1.6 × the least one on a degenerate face (iiwa14, two levels, a bent level above)."""
    scale = np.maximum(1.0, np.minimum(np.abs(lower), np.abs(upper)))

    def holds(x) -> bool:
        return bool(np.all(np.maximum(lower - C @ x, C @ x - upper) <= CERTIFY_TOL * scale))

    candidates = []
    try:
        candidates.append(active_set_qp(H, f, C, lower, upper, x0))
    except ReferenceError:
        pass
    free = np.full(x0.size, np.inf)
    x, _ = solve_highs(f, C, lower, upper, -free, free, Q=H)
    if x is not None:
        candidates.append(x)
        if holds(x):
            try:
                candidates.append(active_set_qp(H, f, C, lower, upper, x, max_iter=POLISH_ITERATIONS))
            except ReferenceError:
                pass
    held = [x for x in candidates if holds(x)]
    if not held:
        raise ReferenceError("QP: neither solver found a point that holds the rows")
    return min(held, key=lambda x: 0.5 * x @ H @ x + f @ x)


# -- the problem data ----------------------------------------------------------------------------


def task_levels(model: pin.Model, tasks: list[NumericTask], q, dq) -> list[Level]:
    data = model.createData()
    pin.forwardKinematics(model, data, q, dq, np.zeros(model.nv))
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    levels = []
    for p in sorted({t.priority for t in tasks}):
        terms = [task_terms(model, data, t, q, dq) for t in tasks if t.priority == p]
        J = np.vstack([t[0] for t in terms])
        levels.append(Level(J, np.concatenate([t[1] for t in terms]), np.concatenate([t[2] for t in terms]), p))
    return levels


def cartesian_rows(robot, q, dq, dt: float):
    """(J_c, bias, lo, hi, names) of the Cartesian bounds (bounds from formulation_cases)."""
    model = robot.model
    n = model.nv
    shaped = cartesian_accelerations(robot, q, dq, np.zeros(n), dt)  # c̈(0) = bias
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    rows, bias, lo, hi, names = [], [], [], [], []
    for b, (name, lower, c0, upper) in zip(robot.cartesian_bounds, shaped):
        J = pin.getFrameJacobian(model, data, model.getFrameId(b.frame), pin.LOCAL_WORLD_ALIGNED)[b.axis]
        rows.append(J)
        bias.append(c0)
        lo.append(lower)
        hi.append(upper)
        names.append(name)
    return np.array(rows).reshape(-1, n), np.array(bias), np.array(lo), np.array(hi), names


def hard_rows(robot, q, dq, tau_ext, M, nu, g, dt: float) -> HardRows:
    n = robot.model.nv
    tau_max = np.asarray(robot.limits.tau_max, dtype=float)
    offset = nu + g - tau_ext  # τ = M a + offset
    G, lo, hi, names = [M], [-tau_max - offset], [tau_max - offset], [f"tau[{j}]" for j in range(n)]
    jl, ju = joint_acceleration_bounds(robot, q, dq, dt)
    G.append(np.eye(n))
    lo.append(jl)
    hi.append(ju)
    names += [f"ddq[{j}]" for j in range(n)]
    Jc, bc, lc, uc, cn = cartesian_rows(robot, q, dq, dt)
    if len(cn):
        G.append(Jc)
        lo.append(lc - bc)
        hi.append(uc - bc)
        names += cn
    return HardRows(np.vstack(G), np.concatenate(lo), np.concatenate(hi), names)


def null_basis(A: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the null space of A (columns)."""
    if A.shape[0] == 0:
        return np.eye(A.shape[1])
    _, sv, Vt = np.linalg.svd(A)
    rank = int(np.sum(sv > NULL_TOL * max(1.0, sv.max() if sv.size else 0.0)))
    return Vt[rank:].T.copy()


# -- the cascade ---------------------------------------------------------------------------------


def _certify(hard: HardRows, a: np.ndarray, stage: str) -> None:
    v = hard.violation(a)
    if v > CERTIFY_TOL:
        worst = hard.names[int(np.argmin(hard.margins(a)))]
        raise ReferenceError(f"stage {stage}: hard row {worst} violated by {v:.3g} (relative)")


def hard_margin(hard: HardRows) -> tuple[float, np.ndarray | None]:
    """max t s.t. lo + t·w ≤ G a ≤ hi − t·w, w = max(1, |bound|), t ≤ 1: the state's feasibility margin."""
    n = hard.G.shape[1]
    finite_lo, finite_hi = np.isfinite(hard.lo), np.isfinite(hard.hi)
    rows, lower, upper = [], [], []
    for i in range(hard.G.shape[0]):
        if finite_lo[i]:  # G a − t w ≥ lo
            rows.append(np.append(hard.G[i], -max(1.0, abs(hard.lo[i]))))
            lower.append(hard.lo[i])
            upper.append(np.inf)
        if finite_hi[i]:  # G a + t w ≤ hi
            rows.append(np.append(hard.G[i], max(1.0, abs(hard.hi[i]))))
            lower.append(-np.inf)
            upper.append(hard.hi[i])
    c = np.zeros(n + 1)
    c[-1] = 1.0
    lx = np.full(n + 1, -np.inf)
    ux = np.full(n + 1, np.inf)
    ux[-1] = 1.0
    lx[-1] = -1e6
    x, status = solve_highs(c, np.array(rows), np.array(lower), np.array(upper), lx, ux, sense_max=True)
    if x is None:
        raise ReferenceError(f"margin LP: {status}")
    return float(x[-1]), x[:n]


def lexicographic_solution(robot, tasks: list[NumericTask], q, dq, tau_ext, dt: float = 0.001) -> LexicographicSolution:
    """The strict lexicographic solution at a state (see the module docstring)."""
    model = robot.model
    n = model.nv
    q, dq = np.asarray(q, dtype=float), np.asarray(dq, dtype=float)
    tau_ext = np.zeros(n) if tau_ext is None else np.asarray(tau_ext, dtype=float)
    M, nu, g = dynamics(model, q, dq)
    levels = task_levels(model, tasks, q, dq)
    hard = hard_rows(robot, q, dq, tau_ext, M, nu, g, dt)
    a0 = np.linalg.solve(M, tau_ext - nu)
    margin, a_feasible = hard_margin(hard)
    sol = LexicographicSolution(margin >= -1e-12, margin, levels, hard=hard, a0=a0)
    if not sol.feasible:
        return sol
    a = a_feasible
    _certify(hard, a, "feasibility")
    N = np.eye(n)
    fixed: list[np.ndarray] = []
    free_after = n
    for i, lv in enumerate(levels):
        last = i == len(levels) - 1
        m = lv.J.shape[0]
        if last and m > free_after:  # over-constrained lowest level: plain least squares
            sol.least_squares_last = True
            a = _least_squares(hard, a, N, lv)
            _certify(hard, a, f"least squares {lv.priority}")
            sol.achieved.append(lv.J @ a + lv.bias)
            sol.scaling.append(float("nan"))
            sol.bend.append(sol.achieved[-1] - lv.target)
        else:
            a, s, delta = _exact_level(hard, a, N, lv)
            _certify(hard, a, f"level {lv.priority}")
            sol.achieved.append(lv.J @ a + lv.bias)
            sol.scaling.append(s)
            sol.bend.append(delta)
        fixed.append(lv.J)
        N = null_basis(np.vstack(fixed))
        free_after = N.shape[1]
    a = _energy(hard, a, N, M, a0)
    _certify(hard, a, "energy")
    sol.a = a
    sol.tau = M @ a + nu + g - tau_ext
    # the fixed levels are kept exactly by the null-space steps; recompute from the final a anyway
    sol.achieved = [lv.J @ a + lv.bias for lv in levels]
    return sol


def _z_rows(hard: HardRows, a: np.ndarray, N: np.ndarray):
    """Hard rows in the step z (a + N z): G N z ∈ [lo − G a, hi − G a]; entries of G N at the null
    basis's round-off (below NULL_ROUNDOFF of their row of G) are 0."""
    Ga = hard.G @ a
    GN = hard.G @ N
    GN[np.abs(GN) < NULL_ROUNDOFF * np.linalg.norm(hard.G, axis=1)[:, None]] = 0.0
    # z = 0 stays feasible despite the previous stage's round-off (certified ≤ CERTIFY_TOL)
    return GN, np.minimum(hard.lo - Ga, 0.0), np.maximum(hard.hi - Ga, 0.0)


def _exact_level(hard: HardRows, a: np.ndarray, N: np.ndarray, lv: Level):
    """(a_new, s*, δ*) of a level with a scaling variable. Variables w = (z, s)."""
    r = N.shape[1]
    A = lv.J @ N
    c = lv.J @ a + lv.bias  # task acceleration at z = 0
    xd = lv.target
    m = A.shape[0]
    Gz, lz, uz = _z_rows(hard, a, N)
    hard_w = np.hstack([Gz, np.zeros((Gz.shape[0], 1))])
    task_w = np.hstack([A, -xd[:, None]])  # task_w w + c = δ
    lx = np.concatenate([np.full(r, -np.inf), [0.0]])
    ux = np.concatenate([np.full(r, np.inf), [1.0]])
    obj = np.zeros(r + 1)
    obj[-1] = 1.0
    # (i.a) with δ = 0: the largest feasible s, if any
    w, _ = solve_highs(obj, np.vstack([hard_w, task_w]), np.concatenate([lz, -c]), np.concatenate([uz, -c]), lx, ux, sense_max=True)
    if w is None or r == 0:
        # (i.a) the smallest bend: min ‖task_w w + c‖²
        C = np.vstack([hard_w, np.eye(r + 1)[-1:]])  # hard rows and 0 ≤ s ≤ 1
        w = exact_qp(task_w.T @ task_w, task_w.T @ c, C, np.append(lz, 0.0), np.append(uz, 1.0), np.zeros(r + 1))
        delta = task_w @ w + c
        # (i.b) with δ pinned to δ*: the largest s; exactly first (pinned within DELTA_PIN_TOL, s
        # crept to 5.6e-6 where 0 is the answer, and the bent level moved by 6.4e-4 relative: an
        # xArm7, found from outside), within the tolerance where HiGHS finds the exact pin infeasible
        for eps in (0.0, DELTA_PIN_TOL * max(1.0, np.abs(xd).max())):
            w2, status = solve_highs(obj, np.vstack([hard_w, task_w]), np.concatenate([lz, delta - c - eps]),
                                     np.concatenate([uz, delta - c + eps]), lx, ux, sense_max=True)
            if w2 is not None:
                w = w2
                break
    delta = task_w @ w + c
    return a + N @ w[:r], float(w[-1]), delta if np.abs(delta).max() > 1e-12 * max(1.0, np.abs(xd).max()) else np.zeros(m)


def _least_squares(hard: HardRows, a: np.ndarray, N: np.ndarray, lv: Level) -> np.ndarray:
    r = N.shape[1]
    if r == 0:
        return a
    A = lv.J @ N
    c = lv.J @ a + lv.bias - lv.target  # residual at z = 0
    Gz, lz, uz = _z_rows(hard, a, N)
    z = exact_qp(A.T @ A, A.T @ c, Gz, lz, uz, np.zeros(r))
    return a + N @ z


def _energy(hard: HardRows, a: np.ndarray, N: np.ndarray, M: np.ndarray, a0: np.ndarray) -> np.ndarray:
    r = N.shape[1]
    if r == 0:
        return a
    Gz, lz, uz = _z_rows(hard, a, N)
    L = np.linalg.cholesky(M)  # ½‖Lᵀ(a + N z − a0)‖²
    T = L.T @ N
    c = L.T @ (a - a0)
    z = exact_qp(T.T @ T, T.T @ c, Gz, lz, uz, np.zeros(r))
    return a + N @ z
