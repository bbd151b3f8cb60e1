"""One QP of the lexicographic cascade: its fixed variables eliminated, solved by DAQP, its answer
checked on its own rows and, where DAQP's active rows allow, certified to minimize a stage's
objective (`certificate`). The cascade (`lexicographic.py`) decides which QPs to pose; this module
poses one. The generated C does the same (`ctl_daqp`, `ctl_stationary`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import daqp
import numpy as np

# Both runtimes: a primal tolerance tighter than DAQP's 1e-6, so that bounds hold to ~1e-8 in
# the scaled problem; a bounded iteration count; no elimination of equalities (it allocates);
# a working set called singular only where its pivot (of unit-norm rows, refined by DAQP from an
# explicit residual where rounding could dominate it) is below 1e-14, the accuracy DAQP's own
# branch and bound gives pivots, not 3.7e-11. After a relaxation the feasible set is a sliver
# around the least violation, whose active rows are nearly dependent: at the default, DAQP called
# a feasible bend stage infeasible from a cold start, and solved it from C's warm one (TIAGo Pro,
# 23 joints: C and Python parted by 0.81 on a golden vector); over 574 relaxed states of that
# spec, every stage after the relaxation failed in 45 states at the default, in 1 at 1e-14.
DAQP_SETTINGS = {"primal_tol": 1e-8, "iter_limit": 1000, "eq_reduction": -1, "sing_tol": 1e-14}
DAQP_INF = 1e30  # DAQP's "no bound"
# Every QP's answer is checked on its own rows (relative to max(1, |bound|)): DAQP's "optimal" flag
# is not evidence. A bend stage's Hessian I + I/ρ (condition 1e5) once came back "optimal" with a
# torque row crossed by 0.054 Nm; such an answer counts as a failed solve.
FEASIBILITY_TOLERANCE = 1e-7
# A row of a QP with fixed variables eliminated whose free coefficients are at most this times its
# largest one sees no free variable (FixedEliminated): its rounding residue is ~1e-16 with a null
# space basis, but up to ~1e-12 with a run-time activation's N_k z (N_k is formed from products of
# larger entries). At 1e-12, the acceleration bound of a joint the levels above fix kept free
# coefficients of 1.6e-12 and was crossed by 2.9e-10 through rounding; DAQP then called the
# final QP infeasible, and the lowest level's least squares was not applied (a 26-joint Centauro:
# 5.8 Nm from the same spec without the activation).
CONSTANT_ROW = 1e-10
# DAQP's zero_tol (its default; not set): a row of its LDP whose squared norm is below it is a "zero
# row", and DAQP calls the QP infeasible if 0 is outside the row's bounds by more than that. A row
# of a QP's free variables that small (not constant by CONSTANT_ROW) goes to DAQP without bounds, the
# check of every row on the answer deciding; where the answer crosses such a row, the QP is solved
# once more with those rows divided by their largest free coefficient, their bounds too (the same
# set, which DAQP then sees: `FixedEliminated.of`'s `faint_bounded`, `Cascade._solve`). A Kinova's
# Cartesian bound, its free coefficients 1.5e-9 after a bend fixed the level above, its shifted
# bound 1.4e-10 from 0, made DAQP call every stage below infeasible; the bend's iterate became the
# answer, and a level the reference scales to 0.111 got 0 (status "ok"; found from outside).
# Without the second solve, a 10-joint iCub (2026-11-29, from outside): a 0.3 Nm wrist's torque
# row, 1e-7 in the free variables of a bend stage below a bent and a scaled level, at its bound;
# DAQP's answer, not seeing it, crossed it by 5.4e-5 Nm, the check failed the stage, and the level
# was left bent by 4.8 rad/s² (status "ok", scaling 1) where the reference meets it exactly. (Given
# its bounds in every QP, such a row moved the final QP on a 29-joint iCub's thin face 0.4 % off
# its minimum: tests/test_lexicographic.py.)
DAQP_ZERO_TOL = 1e-11
# A row whose largest coefficient is below this goes to DAQP divided by it (its bounds too: the
# same set). DAQP takes a row of its LDP whose squared norm is below its zero_tol (1e-11) for a
# zero row, and calls the QP infeasible if 0 is outside the row's bounds: an SO-100 torque row of
# a 0.05 Nm wrist, 2.7e-6 in the scaled variables of a stage (H = I), 2.4e-3 from 0, made every
# QP of a feasible state infeasible, its relaxation's too, and the step fell back (status -2;
# found from outside). DAQP normalizes every other row itself.
ROW_FLOOR = 1e-4
# A stage's answer is certified optimal (`stationary`) if its KKT residual on DAQP's active rows is
# at most this much of the stage's gradient: rounding leaves ~1e-15, an iterate still moving more.
STATIONARY_TOLERANCE = 1e-10
# `face_rows`: a row of a scaling's certificate is held (`Cascade._hold_face`) only if freeing it
# across its whole range could raise the scaling by more than this much of max(1, s) (|μ| times
# the range's width, to first order). A Panda's row whose least-squares multiplier
# was 7.7e-9 of the binding one's (DAQP's own: the same), over a range of 1.8e-3 (in x), could
# gain 1.4e-11: held, it pinned a row that every answer at that scaling (to HiGHS's tolerance)
# leaves anywhere in its range, and the level below got s = 0.070 where the reference's 0.168 is
# feasible (found from outside; a Baxter likewise, 0.037 for 0.111). The weakest row a 27-joint
# Romeo's final QP needs held (its multiplier 2.4e-9 of the largest) could gain 2.2e-8.
HOLD_GAIN = 1e-9


def clip_to_daqp(values: np.ndarray, out: np.ndarray) -> None:
    """`values` within DAQP's ±DAQP_INF, written into `out`: np.clip's numbers without its
    Python-level overhead (the cascade clips the variable bounds of every QP)."""
    np.minimum(np.maximum(values, -DAQP_INF, out=out), DAQP_INF, out=out)


@dataclass(frozen=True)
class FixedEliminated:
    """A QP's rows and bounds with its fixed variables (equal bounds: the levels a stage holds)
    eliminated: DAQP solves for the free ones, min ½x_fᵀH_ff x_f + (f_f + H_fc x_c)ᵀx_f with the
    rows shifted by A_c x_c. The same solution (H is positive definite), but DAQP's setup (the
    Cholesky of H, A R⁻¹) and working set shrink from every variable to the 2–3 a stage leaves
    free, instead of holding the others (7 of the bench spec's 9) as equalities.

    A row that sees no free variable (`constant_rows`) has a value the QP cannot change: DAQP gets
    it without bounds, and the caller's check of every row on the answer decides whether it holds.
    Given to DAQP, such a row is a "zero row" it calls infeasible when 0 is outside its shifted
    bounds by more than 1e-11, absolute: after a bend, a row at its bound with fixed variables of
    ~1e5 is off by rounding more than that, and C and Python parted (one called the final QP
    infeasible, the other not; a 16-joint hand with 4 levels)."""

    free: np.ndarray  # indices of the free variables
    point: np.ndarray  # the fixed variables' values, 0 at the free ones
    A: np.ndarray  # A's columns of the free variables
    lower: np.ndarray  # DAQP's bounds: [x_f; A_f x_f]
    upper: np.ndarray
    hessian_index: tuple[np.ndarray, np.ndarray]  # H_ff = H[hessian_index]
    rows: np.ndarray  # [I; A_f]: DAQP's rows in the free variables, bounds first (`stationary`)
    row_norms: np.ndarray
    faint: np.ndarray  # the rows of A DAQP would take for zero rows (DAQP_ZERO_TOL)

    @classmethod
    def of(cls, A: np.ndarray, lower: np.ndarray, upper: np.ndarray,
           layouts: dict[bytes, tuple] | None = None, faint_bounded: bool = False) -> FixedEliminated:
        """`lower ≤ [x; Ax] ≤ upper` (within ±DAQP_INF, `clip_to_daqp`) with the fixed variables out.
        `layouts`: what depends only on which variables are fixed, kept across calls on the same A
        (a cascade's stages fix a few sets of variables over and over). `faint_bounded`: the rows
        DAQP would take for zero rows keep their bounds, at size 1 (see DAQP_ZERO_TOL)."""
        n = A.shape[1]
        fixed = lower[:n] == upper[:n]
        key = fixed.tobytes() + bytes([faint_bounded])
        layout = None if layouts is None else layouts.get(key)
        if layout is None:
            free = np.flatnonzero(~fixed)
            A_free = np.ascontiguousarray(A[:, free])
            row_size = row_sizes(A)
            rounding = rounding_entries(A_free, row_size)
            constant = rounding.all(axis=1)  # (`constant_rows`)
            row_scale = _row_scale(row_size, constant)  # (ROW_FLOOR: A_f and its bounds times it)
            if row_scale is not None:
                A_free = A_free * row_scale[:, None]
            faint = _daqp_zero_rows(A_free) & ~constant
            if faint_bounded and faint.any():  # (DAQP_ZERO_TOL: to DAQP at size 1 in the free variables)
                factor = 1.0 / np.abs(A_free[faint]).max(axis=1)
                A_free[faint] *= factor[:, None]
                row_scale = np.ones(A.shape[0]) if row_scale is None else row_scale
                row_scale[faint] *= factor
            else:  # (without bounds: the check on the answer decides)
                constant |= faint
            # (the certificate's rows: an entry that is rounding is 0 there, see `certificate`)
            rows = np.vstack((np.eye(free.size), np.where(rounding, 0.0, A_free)))
            layout = (free, A_free, np.ix_(free, free), np.flatnonzero(constant), rows,
                      np.sqrt((rows * rows).sum(axis=1)), row_scale, np.flatnonzero(faint))
            if layouts is not None:
                layouts[key] = layout
        free, A_free, index, constant, rows, row_norms, row_scale, faint = layout
        if free.size == n:
            point = np.zeros(n)
        else:
            point = np.where(fixed, lower[:n], 0.0)  # (0 at the free variables: A x sees the fixed ones only)
            shift = A @ point
            lower = np.concatenate((lower[free], lower[n:] - shift))
            upper = np.concatenate((upper[free], upper[n:] - shift))
        if row_scale is not None or constant.size:
            lower, upper = lower.copy(), upper.copy()
        if row_scale is not None:  # (a row's bounds in its units; beyond ±DAQP_INF: none)
            clip_to_daqp(lower[free.size:] * row_scale, lower[free.size:])
            clip_to_daqp(upper[free.size:] * row_scale, upper[free.size:])
        if constant.size:  # (rows of A; in DAQP's [x_f; A_f x_f] after the free variables)
            lower[free.size + constant], upper[free.size + constant] = -DAQP_INF, DAQP_INF
        return cls(free, point, A_free, lower, upper, index, rows, row_norms, faint)

    def widened(self, relative: float) -> FixedEliminated:
        """The same QP with every inequality row (not the variables' bounds, nor an equality)
        widened by `relative` × max(1, |bound|) at each end."""
        lower, upper = self.lower.copy(), self.upper.copy()
        rows = np.arange(self.free.size, lower.size)
        inequality = rows[lower[rows] != upper[rows]]
        margin = relative * np.maximum(1.0, np.minimum(np.abs(lower[inequality]), np.abs(upper[inequality])))
        lower[inequality] = np.maximum(lower[inequality] - margin, -DAQP_INF)
        upper[inequality] = np.minimum(upper[inequality] + margin, DAQP_INF)
        return FixedEliminated(self.free, self.point, self.A, lower, upper, self.hessian_index, self.rows, self.row_norms,
                               self.faint)


def _daqp_zero_rows(A_free: np.ndarray) -> np.ndarray:
    """The rows DAQP would take for zero rows: their free coefficients' squared norm below
    DAQP_ZERO_TOL (summed in row order, as the C sums it: a cumulative sum adds in that order,
    where NumPy's sum would add pairwise; a row of zeros is constant already)."""
    zero = np.zeros(A_free.shape[0], dtype=bool)
    small = np.flatnonzero((A_free * A_free).max(axis=1, initial=0.0) < DAQP_ZERO_TOL)
    if not A_free.shape[1]:
        zero[small] = True  # (no free variable: every norm is 0)
    elif small.size:
        rows = A_free[small]
        zero[small] = np.cumsum(rows * rows, axis=1)[:, -1] < DAQP_ZERO_TOL
    return zero


def _row_scale(size: np.ndarray, constant: np.ndarray) -> np.ndarray | None:
    """Each row's factor for DAQP: 1/(its largest |coefficient|, `size`) where that is below
    ROW_FLOOR (a row small as a whole: its units; not one that barely sees the free variables, whose
    small coefficients are partly rounding), 1 elsewhere and on the constant rows; None if all are 1."""
    small = (size < ROW_FLOOR) & (size > 0.0) & ~constant
    if not small.any():
        return None
    return np.where(small, 1.0 / np.where(small, size, 1.0), 1.0)


def outside_tolerance(value: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Which values cross their bounds by more than FEASIBILITY_TOLERANCE, relative to
    max(1, min(|lower|, |upper|)): the check of every answer (`Cascade._holds`)."""
    excess = np.maximum(lower - value, value - upper)
    return excess > FEASIBILITY_TOLERANCE * np.maximum(1.0, np.minimum(np.abs(lower), np.abs(upper)))


def row_sizes(A: np.ndarray) -> np.ndarray:
    """Each row's largest |coefficient|."""
    return np.abs(A).max(axis=1, initial=0.0)


def rounding_entries(A_free: np.ndarray, row_size: np.ndarray) -> np.ndarray:
    """The coefficients of the free variables (A_free) that are nothing but rounding: at most
    CONSTANT_ROW × their row's largest coefficient (`row_sizes` of the whole row; zero in exact
    arithmetic, ~1e-16 relative in the QP data)."""
    return np.abs(A_free) <= CONSTANT_ROW * row_size[:, None]


def constant_rows(A_free: np.ndarray, row_size: np.ndarray) -> np.ndarray:
    """The rows whose coefficients of the free variables are all rounding (`rounding_entries`)."""
    return rounding_entries(A_free, row_size).all(axis=1)


def daqp_qp(H: np.ndarray, f: np.ndarray, qp: FixedEliminated,
            primal_tol: float | None = None) -> tuple[np.ndarray | None, int, np.ndarray]:
    """One ordinary QP: min ½xᵀHx + fᵀx on the rows and bounds of `qp` (equal ends: an equality),
    solved by DAQP for the free variables. Returns x (None if DAQP found no solution), its exit
    flag and DAQP's multipliers of `qp`'s rows (`stationary` reads them); with no variable free,
    the fixed point, for the caller's check of the rows."""
    free = qp.free
    if free.size == f.size:
        return _daqp(H, f, qp, primal_tol)
    x = qp.point.copy()
    if not free.size:
        return x, 1, np.zeros(qp.lower.size)
    solved, flag, multipliers = _daqp(H[qp.hessian_index], (f + H @ x)[free], qp, primal_tol)
    if solved is None:
        return None, flag, multipliers
    x[free] = solved
    return x, flag, multipliers


def _daqp(H: np.ndarray, f: np.ndarray, qp: FixedEliminated,
          primal_tol: float | None) -> tuple[np.ndarray | None, int, np.ndarray]:
    # (no sense: DAQP takes the rows with equal ends for equalities itself, as in the C runtime)
    settings = DAQP_SETTINGS if primal_tol is None else {**DAQP_SETTINGS, "primal_tol": primal_tol}
    x, _, flag, info = daqp.solve(np.ascontiguousarray(H), np.ascontiguousarray(f), qp.A, qp.upper, qp.lower,
                                  **settings)
    if flag != 1 or not np.isfinite(x).all():
        return None, int(flag), info["lam"]
    return np.asarray(x, dtype=float), int(flag), info["lam"]


def stationary(qp: FixedEliminated, multipliers: np.ndarray, gradient: np.ndarray) -> bool:
    """Does the answer DAQP gave for `qp` minimize a convex φ (its `gradient` ∇φ there, over every
    variable) on the same set? A stage whose iterate passes needs no further QP to confirm it; one
    that does not goes on as before (the certificate can only be too strict: degenerate active
    rows, a multiplier DAQP left out)."""
    return certificate(qp, multipliers, gradient) is not None


def face_rows(qp: FixedEliminated, multipliers: np.ndarray, gradient: np.ndarray, scale: float) -> np.ndarray | None:
    """The rows of `certificate` whose freeing across its whole range could lower φ by more than
    HOLD_GAIN × `scale` (|μ| times the range's width, to first order), or None."""
    certified = _certificate(qp, multipliers, gradient)
    if certified is None:
        return None
    rows, mu = certified
    return rows[np.abs(mu) * (qp.upper[rows] - qp.lower[rows]) > HOLD_GAIN * scale]


def certificate(qp: FixedEliminated, multipliers: np.ndarray, gradient: np.ndarray) -> np.ndarray | None:
    """The rows of `qp` (its variables' bounds first, as DAQP numbers them) that certify its answer
    minimizes a convex φ (its `gradient` ∇φ there, over every variable), or None if DAQP's active
    rows (multipliers ≠ 0) do not: ∇φ + Cᵀμ = 0 in the free variables, with each inequality's μ on
    the side DAQP found it active (λ > 0 upper, λ < 0 lower). μ by least squares on those rows;
    STATIONARY_TOLERANCE bounds the residual relative to ∇φ, and a row is in the certificate if
    its |μ|‖row‖ is above that much of ∇φ and of the largest |μ|‖row‖ (smaller, it is the least
    squares' rounding: an iCub's row with 1.5e-9 beside others of ~300 was held by `_hold_face`,
    inactive at the stage's other answers, and the posture below ended 0.092 off its optimum).
    Every minimizer of φ has those rows active (complementary slackness: `Cascade._hold_face`).
    A row's free coefficients that are rounding (at most CONSTANT_ROW × its largest coefficient,
    as `constant_rows` measures a whole row) are 0 here: a 10-joint iCub's wrist torque row sees
    the levels below a 6-D hand task only through rounding (their motions leave the hand's
    acceleration as it is), 1e-11 of its size, and with its multiplier of 8e4 certifying a scaling
    those entries took four torque and acceleration rows into the certificate at 5e-10–2e-9 of
    it; held, they pinned a level below to a bend 32 % above the least (the C runtime, whose
    stage ended where those rows were active; found from outside)."""
    certified = _certificate(qp, multipliers, gradient)
    return None if certified is None else certified[0]


def _certificate(qp: FixedEliminated, multipliers: np.ndarray,
                 gradient: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """`certificate`'s rows and their multipliers μ."""
    g = gradient[qp.free]
    size = math.sqrt(g.dot(g))
    active = multipliers.nonzero()[0]
    if not active.size:
        return (active, np.zeros(0)) if size == 0.0 else None  # (the residual is ∇φ itself)
    if active.size > g.size:  # (dependent rows)
        return None
    C = qp.rows[active]
    mu = cholesky_solve(C @ C.T, -(C @ g))
    if mu is None:
        return None
    inequality = qp.lower[active] != qp.upper[active]
    terms = np.abs(mu) * qp.row_norms[active]
    significant = terms > STATIONARY_TOLERANCE * max(size, float(terms.max()))
    if (inequality & (mu * multipliers[active] < 0) & significant).any():  # (on the wrong side)
        return None
    residual = g + C.T @ mu
    if math.sqrt(residual.dot(residual)) > STATIONARY_TOLERANCE * size:
        return None
    return active[significant], mu[significant]


# Up to this many active rows the certificate's Cholesky runs in plain Python, as ctl_stationary
# does it: NumPy's Cholesky and solve cost ~15 µs each on the 2–6 rows a stage's certificate has,
# the loops a few µs. They grow as k³ in the interpreter: the relaxation's stages of a 27-joint
# robot hold ~50 rows active, and there the loops took 3/4 of a compile (its golden vectors).
PLAIN_CHOLESKY_ROWS = 12


def cholesky_solve(G: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """x with G x = b for a symmetric G, by its Cholesky factor (None if a pivot is not positive)."""
    k = len(b)
    if k > PLAIN_CHOLESKY_ROWS:
        try:
            low = np.linalg.cholesky(G)
        except np.linalg.LinAlgError:
            return None
        return np.linalg.solve(low.T, np.linalg.solve(low, b))
    G, b = G.tolist(), b.tolist()
    for j in range(k):
        pivot = G[j][j] - sum(G[j][c] * G[j][c] for c in range(j))
        if not pivot > 0.0:
            return None
        G[j][j] = math.sqrt(pivot)
        for i in range(j + 1, k):
            G[i][j] = (G[i][j] - sum(G[i][c] * G[j][c] for c in range(j))) / G[j][j]
    for j in range(k):  # L y = b, then Lᵀ x = y
        b[j] = (b[j] - sum(G[j][c] * b[c] for c in range(j))) / G[j][j]
    for j in reversed(range(k)):
        b[j] = (b[j] - sum(G[c][j] * b[c] for c in range(j + 1, k))) / G[j][j]
    return np.array(b)
