"""The lexicographic solve: a cascade of ordinary QPs solved by DAQP, and the check of its bounds.

The QP's priority levels are groups of variables (`formulations/qp.py`): level i's scaling sᵢ
and bend δᵢ, its task acceleration being sᵢ ẍ_d,ᵢ + δᵢ whatever the other variables are. Fixing
a level therefore means fixing its variables (lb = ub), and the cascade is:

  1. every level above the lowest at its nominal value (s = 1, δ = 0), the lowest unbent, and
     ½xᵀHx + fᵀx − K s over the rest (`finish_lowest`): if this QP is feasible its answer has
     the lowest level's largest scaling, and is the lexicographic optimum. One solve when every
     level is met (the usual case), and also when the lowest is scaled if DAQP's active rows
     certify that its scaling is the largest (`stationary`); otherwise a second QP checks it.
  2. otherwise, for each level i, highest first, with the levels above fixed (starting at the
     lowest level that can be scaled with every level above it met, if there is one):
       scale:  max sᵢ with δᵢ fixed (0), the levels below free;
       bend:   only if no sᵢ ∈ [0, 1] is feasible: min ‖δᵢ‖², its split of the task acceleration
               into sᵢ and δᵢ made the one with the least bend (`smallest_bend`), then scale again;
     the level is then fixed, and the rows that certify its scaling is the largest are active in
     every answer below: they become equalities (`_hold_face`); then the remaining levels
     nominal: if feasible, done (for the lowest level, its scaling and this QP are
     `finish_lowest` again).
  3. if even the highest level cannot be bent into feasibility, the torque limits cannot hold the
     joint/Cartesian bounds: `relax` violates them as little as they allow (one slack per
     bound, min Σσ), those bounds are widened to what was achieved, and 1–2 run again.

In closed loop a step usually gives way where the last one did: given that step's `Hint`, steps
1–2 start at the level it names, the levels above nominal, and a level it says bent runs its bend
stage first. A stage the cascade runs anyway proves each shortcut (or shows the hint wrong, and
the cascade starts over), so the answer is the same, in fewer QPs (`Cascade.levels`).

A stage's objective is linear in its level (max sᵢ) or only sees it (min ‖δᵢ‖²); the other
variables just have to exist, and DAQP needs a positive definite Hessian. So each stage runs the
proximal-point method: a few QPs min φ(x)/ρ + ½‖x − c‖², each centred at the previous answer.
It converges to an exact minimizer of φ (for a linear φ in finitely many steps) while every QP
stays well conditioned (a tiny fixed weight on ‖x − c‖² instead would make the Hessian's
condition number ~1e8, and DAQP then returned "optimal" with a torque limit crossed by 0.09 Nm
and called feasible stages infeasible). Each QP is an ordinary one, which DAQP solves exactly
(it refines its primal solution); its hierarchical mode (`break_points`) was measured to miss
the largest feasible scaling and to cross hard rows in ill-conditioned states (see
docs/formulations.md). DAQP sees each QP with its fixed variables eliminated
(`stage_qp.FixedEliminated`): the variables a stage leaves free, 2–3 of the bench spec's 9.

The generated C code runs the same cascade on the same DAQP.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .stage_qp import (
    FixedEliminated,
    face_rows,
    cholesky_solve,
    clip_to_daqp,
    daqp_qp,
    outside_tolerance,
    stationary,
)

# The proximal-point stages (see Cascade._proximal): step ρ, at most this many solves, and when
# a step is small enough (relative) to stop. The scaling's objective is linear: its Hessian stays
# the identity whatever ρ, and a long step reaches the largest scaling at once. The bend's
# weight 1/ρ enters the Hessian: a moderate ρ keeps it well conditioned, at the price of a few
# more steps.
SCALE_STEP = 1e-8
BEND_STEP = 1e-5
MAX_EXTRAPOLATION = 1e6
# A scaling stage whose first QP DAQP fails is run again at these gentler steps (a shorter first
# step, the same maximum): on a Kinova's 4 levels, with two rows held by the level above
# (`_hold_face`), DAQP cycled at 1e-8, the stage counted as infeasible, and the level was bent to
# s = 0 where s = 0.924 holds every row (the independent reference's answer; found from outside,
# in 31 of 150 states around that one). Also where DAQP calls it infeasible: below two partly
# active levels of an xArm7 the Python runtime's DAQP did so at 1e-8 where HiGHS and the C
# runtime reach s = 1, and the level was bent to s = 0.26, the torques 0.85 Nm apart (found from
# outside). A stage that is infeasible runs two more QPs before its level bends.
SCALE_RETRY_STEPS = (1e-6, 1e-4)
# Relative: a relaxed bound is widened this much beyond what was achieved. The stages after the
# relaxation run on a sliver this wide around the least violation: at 1e-7, every one of them
# failed in 13 of 574 relaxed states of the TIAGo Pro spec above and 2 of 592 of a 24-joint G1's
# (the relaxed point became the answer, as DAQP's cold start and C's warm one happened to
# decide), at 1e-6 in 1 and 0 (with the sing_tol above).
RELAX_MARGIN = 1e-6
# A QP DAQP fails is solved once more with its rows widened by this much (relative,
# `FixedEliminated.widened`) after a relaxation, and where the caller has a point of its feasible
# set and no other way on (the final QPs after the lowest level's scaling; a proximal stage's
# failed step already backs off: a retry there too made the torques of 6 of an xArm7 spec's 126
# golden states move with rounding-level changes of their data).
# Once a level is bent on the relaxed sliver, the next stage's feasible set can be nearly a point
# where more rows are active than there are free variables, and they are dependent: 28 rows of
# rank 20 in 22 variables on a 27-joint Alex. DAQP then called that stage, and every stage after
# it, infeasible; the bend's iterate became the answer, and C and Python parted on a level's
# scaling (0.53 and 0.68). Widened, the stages solve: that scaling stage's answer is 1e-10
# (scaled) from HiGHS's on the unwidened rows, and every answer is still checked on its unwidened
# rows (FEASIBILITY_TOLERANCE). Not for every QP: a stage infeasible by a hair (a level that
# cannot be met) would then be feasible, and 943 of the bench spec's 3,000 closed-loop states
# changed, by up to 46 Nm.
SLIVER_WIDENING = 1e-10
# ... and if DAQP still fails it, once more at DAQP's own default primal tolerance (its answer is
# checked on the rows at FEASIBILITY_TOLERANCE all the same). After a relaxation a stage's held
# rows can be nearly dependent (ten equalities of condition 3e4 on a 29-joint human): DAQP called
# a third of the stages infeasible at 1e-8 where HiGHS found them feasible, and the answer
# depended on which ones, moving by up to 15 % of the torques with relative changes of 1e-13 in
# the data. Over the golden states that relax in seven 15–30-joint specs (386 states), those whose
# torques move by more than 1e-3 of their size that way went from 10 to 4 (3 of them a dual
# arm's, unchanged).
SLIVER_PRIMAL_TOL = 1e-6
# The relaxation is always feasible (every bound has its slack), so a failure is DAQP's, and the
# stage is run again at the next, gentler step. DAQP cycled at ρ = 1e-8 on a state of a spec with
# the same task at two levels (golden vector: the Python runtime fell back, the C one, warm,
# solved it), and solved it at 1e-7 and above. On a UR5 state 0.0005 rad beyond the elbow's limit
# and up to 1.14 × the velocity limits, it answered "optimal" with a slack at −6e6 (below its
# bound of 0) at ρ = 1e-8 and at −27.5 at 1e-6, the step fell back (status −2, first tried from
# outside: 1 in 100k random states), and it solves at 1e-4.
RELAX_STEPS = (SCALE_STEP, 1e-6, 1e-4, 1e-2, 1.0)
EXTRAPOLATION_MARGIN = 1e-9
# A step DAQP fails at the ρ of the last that worked is tried again at ten times that ρ (a better
# conditioned Hessian, a shorter step), up to this ρ, instead of ending the stage there: a bend
# stage ended after its first step in Python and went on in C, and the level's scaling that
# followed parted by 4e-4 (a 26-joint Centauro, a status-"ok" golden vector).
BACKOFF_LIMIT = 1.0
PROXIMAL_ITERATIONS = 30
# A proximal step never raises φ (the last iterate is in the QP's feasible set, and the step's
# optimum costs no more than it); an answer that raises φ by more than this (relative to
# max(1, |φ|)) was not solved on the stage's set (DAQP called it infeasible at every try but its
# loosest, SLIVER_PRIMAL_TOL), and counts as a failed step. On the relaxed sliver of a TIAGo arm
# (found from outside), C's bend stage of an [rz] level took three such answers, ‖δ‖ 101.0 → 116.7
# → 99.2 → 116.5, and ended 15 % above where Python's ended in one QP; the scaling stage after it
# then reported s = 0.15 against Python's 0, and `dcts compile` failed its golden test.
ASCENT_TOLERANCE = 1e-3
# The relaxation's LP may need more: its slacks start at 0 and the iterates climb a face of the
# torque polytope one active row at a time. On a 29-joint human under a heavy load (a free
# acceleration of 1.2e9 rad/s² on a light joint) the 30th iterate was still falling, Σwσ 0.94 %
# above the least, with bounds crossed by up to 1,455 rad/s² that could hold (HiGHS: 0); it
# reached the least at 60–100. It ends sooner wherever it converges (the golden states of four
# 7–29-joint specs: a median of 1–2 QPs, 4 of 144 relaxations at 30).
RELAX_ITERATIONS = 100
# (1e-10 was at DAQP's resolution: 5 % of the bench's closed-loop states ran a stage's 30 QPs
# with a variable its objective does not see moving 3e-10 each time, and no other change)
PROXIMAL_TOLERANCE = 1e-9
# A lowest level's scaling this close to a bound (relative to the level met, s = 1) is that bound
# up to the rounding of the QP that found it, and `Cascade._snapped` sets it there without the QP
# it runs for larger hairs. After the lowest level bends, its largest scaling is usually 0 and the
# final QP ends 1e-17-1e-16 (relative) from it: that QP was one of the 5-6 of every such step
# (bench spec, TALOS 16). The hairs the runtimes parted on were 2e-11 and more.
ROUNDING_HAIR = 1e-14
# The lowest level's scaling and the final QP in one (Cascade.finish_lowest): the weight of its
# scaling, relative to the largest entry of H and f, and a larger one where the check says it was
# too small. Below the exact-penalty threshold the answer's scaling is short of the largest, which
# the check catches; far above it, the weight's rounding moves the answer more than the check
# allows. Bench spec, 3,000 closed-loop states where the lowest level gives way: ×1e4 passed the
# check in 87 %, ×1e6 in 99 % (answers within 1.3e-10 relative of the two stages'), ×1e8 in 85 %;
# near-bound states of the reference tests' 3-level cases: ×1e4 in 9 of 20, ×1e6 in 19. A golden
# state of TALOS's 28 joints needed ×1e8.
FINISH_WEIGHTS = (1e6, 1e8)

# A final QP that DAQP fails although the caller has a point of its feasible set: after a bend,
# the rows the least bend holds active can make that set a face of lower dimension, dependent
# rows through one point (12 of rank 5 in 17 free variables on a 29-joint iCub), which DAQP, and
# HiGHS too, call infeasible. It is then solved on that face (`Cascade._on_face`): the rows within
# FACE_TOLERANCE (relative to max(1, |value|)) of a bound at the point held at their values, the
# ones whose coefficients in the free variables are within INDEPENDENT_ROW (relative) of the span
# of those before them dropped (on the face they are constant). Before, the stage's last iterate
# was the answer, arbitrary in the freedom the final QP is for: C and Python parted by 6 Nm.
# (1e-6 before: an xArm7's level held four rows independent only at ~1e-5 (`_hold_face`), DAQP's
# multipliers on them reached 1e11, its proximal QPs came back 1.6e-4 above their optimum and the
# bend below stalled 6.9e-5 above the least, status "ok"; found from outside against the
# reference. A row dropped this way that an answer then crosses is caught: `crosses_dropped`.)
FACE_TOLERANCE = 1e-9
INDEPENDENT_ROW = 1e-4

@dataclass(frozen=True)
class Hint:
    """Where a step's hierarchy gave way: the first level not met (s < 1 or bent) and the levels
    bent. In closed loop the next step usually gives way in the same place, and its solve starts
    there (`Cascade.levels`): 1–3 QPs fewer where a level bends, the answer the same."""

    first: int
    bent: tuple[bool, ...]
    steady: bool = False  # the step before gave way in the same place too

    def skips_stages(self, count: int) -> bool:
        """Does starting from it save a stage? Not where only the lowest level is scaled: its
        stage is the cascade's first QP anyway."""
        return len(self.bent) == count and (self.first < count - 1 or self.bent[self.first])


MISSED = object()  # `Cascade._descend`: a hint that was wrong


@dataclass(frozen=True)
class Structure:
    """Where the solve finds what it fixes: the rows of A that are joint/Cartesian bounds, and the
    (scaling, bend) variables of each priority level, highest first."""

    bound_rows: range
    priorities: tuple[tuple[int, tuple[int, ...]], ...]
    # Some variables after the levels' own are seen by no row, up to rounding (DCTS with a run-time
    # activation: N_k z, n variables for fewer directions); see Cascade._proximal_steps
    spare_variables: bool = False
    # what one unit of each bound row's slack weighs in the relaxation (limits/joint.py,
    # slack_weights); None: 1 each
    slack_weights: tuple[float, ...] | None = None

    @cached_property
    def _level_variables(self) -> list[np.ndarray]:
        return [np.array([s, *bend], dtype=int) for s, bend in self.priorities]

    @cached_property
    def levels_above(self) -> list[np.ndarray]:
        """[k]: the variables (s and δ) of the levels [0, k), as one index array."""
        return [np.concatenate([np.zeros(0, dtype=int), *self._level_variables[:k]])
                for k in range(len(self.priorities) + 1)]

    @cached_property
    def levels_from(self) -> list[np.ndarray]:
        """[k]: the variables of the levels [k, end), as one index array."""
        return [np.concatenate([np.zeros(0, dtype=int), *self._level_variables[k:]])
                for k in range(len(self.priorities) + 1)]




def nominal_point(ubx: np.ndarray, structure: Structure) -> np.ndarray:
    """Every level met (s = 1, scaled: its upper bound; δ = 0), the other variables 0."""
    nominal = np.zeros(ubx.size)
    for s, _ in structure.priorities:
        nominal[s] = ubx[s]
    return nominal


def unbounded_solution(H: np.ndarray, f: np.ndarray, ubx: np.ndarray, structure: Structure) -> np.ndarray:
    """The lexicographic solution when no row constrains, in closed form: every level met, and the
    other variables (DCTS: z, after the levels' own, with no bounds) minimizing ½xᵀHx + fᵀx:
    H_zz z = −(f_z + H_z,levels x_levels). What an over-constrained lowest level's scaling is
    reported against (`Controller`); one small Cholesky instead of a QP."""
    x = nominal_point(ubx, structure)
    levels = structure.levels_above[-1]
    free = np.ones(x.size, dtype=bool)  # (a mask: np.setdiff1d took a tenth of the Python step)
    free[levels] = False
    x[free] = -np.linalg.solve(H[free][:, free], f[free] + H[free][:, levels] @ x[levels])
    return x


class Cascade:
    """The stages of one lexicographic solve on numeric (scaled) QP data. `acceleration_map`: Q
    (q̈ = q̈₀ + Q x), from which a bent level's split into s and δ is made exact (`smallest_bend`);
    without it, the split is the bend stage's own."""

    def __init__(self, H, f, A, lbx, ubx, lba, uba, structure: Structure, acceleration_map: np.ndarray | None = None,
                 reopen: bool = False):
        self.H, self.f, self.A = H, f, A
        self.reopen = reopen  # `_hold_face`'s dependent rows keep their bounds (`solve_hinted`)
        self.acceleration_map = acceleration_map
        self.lbx, self.ubx = lbx.copy(), ubx.copy()
        self.lba, self.uba = lba.copy(), uba.copy()
        self.structure = structure
        self.relaxed_point: np.ndarray | None = None  # set by relax
        self.nominal = nominal_point(ubx, structure)
        # DAQP's bounds of [x; Ax], clipped: the rows' part is set once (and after `relax`), the
        # variables' part by each QP
        self._lower, self._upper = np.empty(lbx.size + lba.size), np.empty(lbx.size + lba.size)
        self._layouts: dict[bytes, tuple] = {}  # FixedEliminated.of's
        # the last QP, and DAQP's multipliers; None if it failed (or its answer did not hold)
        self._last_qp: tuple[FixedEliminated, np.ndarray] | None = None
        self._held = np.zeros(lba.size, dtype=bool)  # the rows `_hold_face` holds at their values
        self._dropped = np.zeros(lba.size, dtype=bool)  # and the ones it found dependent (`_hold_rows`)
        # each row's bounds when it is not held (what a dropped row is checked on, or gets back)
        self._open_lba, self._open_uba = self.lba.copy(), self.uba.copy()
        self.bent: list[bool] = []  # by level: did `levels` bend it
        self._set_row_bounds()

    def _set_row_bounds(self) -> None:
        nx = self.lbx.size
        clip_to_daqp(self.lba, self._lower[nx:])
        clip_to_daqp(self.uba, self._upper[nx:])

    def _solve(self, H, f, lbx, ubx, feasible: bool = False) -> np.ndarray | None:
        """One QP with the variable bounds lbx/ubx: DAQP's answer, if it holds on its own rows.
        `feasible`: the caller has a point of this QP's feasible set (see SLIVER_WIDENING)."""
        lower, upper = self._lower, self._upper
        clip_to_daqp(lbx, lower[: lbx.size])
        clip_to_daqp(ubx, upper[: ubx.size])
        qp = FixedEliminated.of(self.A, lower, upper, self._layouts)
        x, _, multipliers = daqp_qp(H, f, qp)
        if x is None and (feasible or self.relaxed_point is not None):  # (see SLIVER_WIDENING)
            qp = qp.widened(SLIVER_WIDENING)
            x, _, multipliers = daqp_qp(H, f, qp)
            if x is None:
                x, _, multipliers = daqp_qp(H, f, qp, SLIVER_PRIMAL_TOL)
        if x is not None and qp.faint.size and not self._holds(x):  # (see DAQP_ZERO_TOL)
            qp = FixedEliminated.of(self.A, lower, upper, self._layouts, faint_bounded=True)
            x, _, multipliers = daqp_qp(H, f, qp)
        self._last_qp = None
        if x is None or not self._holds(x):
            return None
        self._last_qp = qp, multipliers
        return x

    def _holds(self, x: np.ndarray) -> bool:
        """Does x hold the last QP's variable bounds and the rows' bounds as they are now, within
        FEASIBILITY_TOLERANCE (relative to max(1, |bound|))? On the clipped bounds: the same excess
        as on the infinite ones (x and Ax are far below 1e30), and no ∞ − ∞ to guard against."""
        return not outside_tolerance(np.concatenate([x, self.A @ x]), self._lower, self._upper).any()

    def final(self, upto: int, lbx, ubx) -> np.ndarray | None:
        """½xᵀHx + fᵀx with the levels [0, upto) as they are in lbx/ubx and the others nominal."""
        lo, hi = lbx.copy(), ubx.copy()
        below = self.structure.levels_from[upto]
        lo[below] = hi[below] = self.nominal[below]  # (s = 1, δ = 0)
        return self._solve(self.H, self.f, lo, hi)

    def _proximal(self, weights: np.ndarray, linear: np.ndarray, step: float, lbx, ubx,
                  iterations: int = PROXIMAL_ITERATIONS, feasible: bool = False) -> np.ndarray | None:
        """min φ(x) = ½Σwⱼxⱼ² + linearᵀx over the feasible set, by the proximal-point method:
        x = argmin φ(x)/ρ + ½‖x − c‖² (scaled variables), a fixed point of which minimizes φ.

        While the active set stays the same, consecutive iterates move along the same face, so the
        next centre is extrapolated along d = x − x_previous, up to the first constraint it meets or
        the minimum of φ on the ray: an active-set step, which ends the iteration in a few solves.
        A linear φ is done as soon as an iterate minimizes it over the variable bounds alone, and
        any φ as soon as DAQP's active rows certify an iterate (`stationary`): the QP that would
        only confirm it is not run.
        A quadratic φ makes the Hessian I + diag(w)/ρ ill-conditioned for a small ρ, and DAQP then
        may fail on the thin feasible sets the levels above leave: if it does at once, ρ starts
        again at 1 and shrinks tenfold per step down to `step`; a later failed solve is tried
        again at a larger ρ (`BACKOFF_LIMIT`), and past that the last iterate is the answer
        (feasible, and as close to the minimum as DAQP could go). At most `iterations` QPs a run.
        `feasible`: the caller has a point of the feasible set (`_solve`)."""
        x = self._proximal_steps(weights, linear, step, step, lbx, ubx, iterations, feasible)
        if x is None and weights.any():
            x = self._proximal_steps(weights, linear, 1.0, step, lbx, ubx, iterations, feasible)
        return x

    def _proximal_steps(self, weights, linear, rho, step, lbx, ubx,
                        iterations: int = PROXIMAL_ITERATIONS, feasible: bool = False) -> np.ndarray | None:
        center, x = self.nominal, None
        best_bounds = None if weights.any() else self._best_bounds(linear, lbx, ubx)
        seen = (weights != 0.0) | (linear != 0.0)
        hessian, hessian_rho = None, None
        floor, solved_rho = step, None  # ρ stays ≥ floor; the ρ of the last QP DAQP solved
        for _ in range(iterations):
            if rho != hessian_rho:  # (ρ stays at `step` once there: the same Hessian)
                hessian, hessian_rho = np.diag(1.0 + weights / rho), rho
            solved = self._solve(hessian, linear / rho - center, lbx, ubx, feasible)
            if solved is not None and x is not None and _ascends(solved, x, weights, linear):
                solved, self._last_qp = None, None  # (not a proximal step, a failed one: see ASCENT_TOLERANCE)
            if solved is None:
                if solved_rho is None or rho >= BACKOFF_LIMIT:
                    return x
                # DAQP failed at a smaller ρ than the last that worked (it called a feasible bend
                # stage on a barely relaxed bound infeasible at I + I/ρ of condition 100, then
                # the iterate stopped 2 steps short and C and Python differed by 0.5 %): go on at
                # that ρ, or if it failed at that ρ, at ten times it; the proximal-point method
                # converges at any fixed ρ, only more slowly
                floor = rho = solved_rho if rho < solved_rho else 10.0 * rho
                continue
            solved_rho = rho
            previous, x = x, solved
            if self._negligible(x - center, x) or stationary(*self._last_qp, weights * x + linear):
                return x
            if best_bounds is not None and self._at_best_bounds(x, *best_bounds):
                return x
            center = x
            # Two iterates on the same face: move along it. With spare variables, only while the
            # objective's variables move: the active rows' multipliers (~1/ρ) times their rounding
            # push the spare ones, and extrapolating that grew them ×1e6 a step to 1e8, after which
            # the last stage failed. (Elsewhere the rule costs optimality: extrapolating along the
            # other variables is what lets a slowly moving level gain, 28 of 3,000 closed-loop
            # states of the bench spec ended up to 3e-5 lower in their top level's scaling.)
            if previous is not None:
                d = x - previous
                if not (self.structure.spare_variables and self._negligible(d[seen], x)):
                    center = x + self._extrapolation(x, d, weights, linear, lbx, ubx) * d
            rho = max(0.1 * rho, floor)
        return x

    @staticmethod
    def _negligible(step: np.ndarray, x: np.ndarray) -> bool:
        # ‖·‖ as np.linalg.norm computes it (√(v·v)), without its Python-level overhead
        return math.sqrt(step.dot(step)) <= PROXIMAL_TOLERANCE * (1.0 + math.sqrt(x.dot(x)))

    @staticmethod
    def _best_bounds(linear, lbx, ubx) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """For a linear objective: the variables it pushes up and down, and how close to their
        upper and lower bounds they count as there (a stage's bounds stay the same)."""
        up, down = np.flatnonzero(linear < 0), np.flatnonzero(linear > 0)
        tol = PROXIMAL_TOLERANCE
        return up, ubx[up] - tol * (1.0 + np.abs(ubx[up])), down, lbx[down] + tol * (1.0 + np.abs(lbx[down]))

    @staticmethod
    def _at_best_bounds(x, up, upper, down, lower) -> bool:
        """Is x at the bound each variable of a linear objective is pushed toward?"""
        return bool((x[up] >= upper).all() and (x[down] <= lower).all())

    def _extrapolation(self, x, d, weights, linear, lbx, ubx) -> float:
        """The largest t ≥ 0 keeping x + t d feasible, capped at the minimum of φ along it. The
        rows x is on move along d up to rounding: they get a margin, or they would block at once
        (the centre need not be feasible: the next proximal step projects it), and a row x is
        beyond by rounding counts as on it: else its rounding, grown past the margin, blocked
        every step (a Tiago's scaling stage crept 1e-8 a QP and ended 1.2e-6 short)."""
        slope, curvature = float((weights * x + linear) @ d), float(weights * d @ d)
        t = -slope / curvature if curvature > 0 else MAX_EXTRAPOLATION
        t = min(max(t, 0.0), MAX_EXTRAPOLATION)
        for value, rate, lo, hi in ((x, d, lbx, ubx), (self.A @ x, self.A @ d, self.lba, self.uba)):
            value = np.minimum(np.maximum(value, lo), hi)
            margin = EXTRAPOLATION_MARGIN * np.maximum(1.0, np.minimum(np.abs(lo), np.abs(hi)))
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                up = np.where(rate > 0, (hi - value + margin) / rate, np.inf)
                down = np.where(rate < 0, (lo - value - margin) / rate, np.inf)
            t = min(t, float(np.min(up, initial=np.inf)), float(np.min(down, initial=np.inf)))
        return max(t, 0.0)

    def scale(self, level: int, lbx, ubx, feasible: bool = False) -> np.ndarray | None:
        """max s of `level` (its δ fixed in lbx/ubx), the levels below free; None if infeasible
        (or DAQP failed at every step of SCALE_RETRY_STEPS). `feasible`: the caller has a point
        of this stage's feasible set (`_solve`)."""
        s, _ = self.structure.priorities[level]
        linear = np.zeros(lbx.size)
        linear[s] = -1.0 / self.nominal[s]
        for step in (SCALE_STEP, *SCALE_RETRY_STEPS):  # (see SCALE_RETRY_STEPS)
            x = self._proximal(np.zeros(lbx.size), linear, step, lbx, ubx, feasible=feasible)
            if x is not None:
                break
        return x

    def bend(self, level: int, lbx, ubx) -> np.ndarray | None:
        """min ‖δ‖² of `level` (its s free in [0, 1]), the levels below free."""
        _, bend = self.structure.priorities[level]
        weights = np.zeros(lbx.size)
        weights[list(bend)] = 1.0
        return self._proximal(weights, np.zeros(lbx.size), BEND_STEP, lbx, ubx)

    def smallest_bend(self, level: int, x: np.ndarray, lbx, ubx) -> np.ndarray:
        """x with `level`'s task acceleration v = s ẍ_d + δ split into the s within lbx/ubx that
        leaves the least ‖δ‖, the rest of x as it is.

        Only v moves the arm: Q's column of s is Q_δ g for g = ẍ_d d_s/d_δ (the scaled variables),
        and every x + t(1, −g) along s and δ has the same rows, torques and accelerations. A bend
        stage on the sliver the levels above leave is where DAQP fails or stops early (active rows
        dependent along that line), and its answer's split was then arbitrary: on an xArm7 under
        a 15 % mass mismatch C and Python reported 0.17 and 0.61 for a level that got 0.006 of its
        target, and the golden test failed. Along the line, ‖w − g s‖² (w = δ + g s) is least at
        s = gᵀw/gᵀg: the bend stage's own answer where it converged."""
        s, bend = self.structure.priorities[level]
        Q = self.acceleration_map
        if Q is None or not bend:
            return x
        bend = list(bend)
        Q_bend = Q[:, bend]
        g = cholesky_solve(Q_bend.T @ Q_bend, Q_bend.T @ Q[:, s])
        if g is None or not g.dot(g) > 0.0:  # (a singular level; ẍ_d = 0: s moves nothing)
            return x
        w = x[bend] + g * x[s]
        out = x.copy()
        out[s] = min(max(g.dot(w) / g.dot(g), lbx[s]), ubx[s])
        out[bend] = w - g * out[s]
        return out

    def finish_lowest(self, lbx, ubx, witness: np.ndarray | None = None) -> np.ndarray | None:
        """The lowest level's stages (`_finish_lowest_stages`), its scaling then taken to the bound it
        is within the stages' tolerance of (`_snapped`)."""
        x = self._finish_lowest_stages(lbx, ubx, witness)
        return None if x is None else self._snapped(x, lbx, ubx)

    def _snapped(self, x: np.ndarray, lbx, ubx) -> np.ndarray:
        """x, or if the lowest level's scaling is within the stages' tolerance (PROXIMAL_TOLERANCE,
        as `_negligible`) of one of its bounds but not at it, the final QP with the scaling at that
        bound, where DAQP solves it. Such a scaling is the bound up to where a QP stopped, and the
        two runtimes' QPs stop in different places: after a bend on a 29-joint iCub, one found
        s = 2.3e-11, the other 4.3e-11 (and 0 against 2.5e-9 in another state), and with the
        level's large task acceleration their q̈ parted by 1.3e-6 and 7e-4 relative. Within
        ROUNDING_HAIR of the bound, x with the scaling set there (no QP)."""
        s, _ = self.structure.priorities[-1]
        for bound in (lbx[s], ubx[s]):
            if x[s] != bound and abs(x[s] - bound) <= ROUNDING_HAIR * self.nominal[s]:
                out = x.copy()  # (rounding: the final QP at the bound would move nothing it can resolve)
                out[s] = bound
                return out
            if x[s] != bound and self._negligible(x[s:s + 1] - bound, x):
                lo, hi = lbx.copy(), ubx.copy()
                lo[s] = hi[s] = bound
                final = self._solve(self.H, self.f, lo, hi)
                return x if final is None else final
        return x

    def _finish_lowest_stages(self, lbx, ubx, witness: np.ndarray | None = None) -> np.ndarray | None:
        """The lowest level's scaling stage and the final QP in one, its bend fixed in lbx/ubx and
        the levels above too: min ½xᵀHx + fᵀx − K s. A linear term large enough is an exact penalty:
        its answer has the largest feasible s, and minimizes ½xᵀHx + fᵀx with that s, as the two
        stages would. That s is certified by the rows DAQP holds active (`stationary` for max s:
        the usual case), or else checked by one proximal step in H's metric from the answer,
        argmin ½(y − x)ᵀH(y − x) − K s, which stays at x if and only if s is the largest (the same
        H, so the C code solves it from the same factorization and working set; from a scaling
        short of the largest it moves by about the gap or K/curvature, whichever is smaller, so
        K must be large for the check to see a small gap, as ρ must be small in `scale`); where
        it moves, K was too small: a larger one, then the two stages. One QP if s reaches 1 or is
        certified, two if it is checked, instead of three or more. None if no s ∈ [0, 1] is feasible.
        `witness`: a feasible point (the bend's answer), whose s the final QP takes if DAQP fails
        the stages."""
        if self.structure.spare_variables:
            # K's rounding, in the directions of the spare variables that H barely sees, moved
            # them by ~1e3 (scaled) and C and Python parted: the QPs as before (`levels` tries
            # every level nominal first), which leave them where the golden test has them agree
            return self._scale_and_final(lbx, ubx, witness)
        s, _ = self.structure.priorities[-1]
        size = max(1.0, float(np.abs(self.H).max()), float(np.abs(self.f).max())) / self.nominal[s]
        checked = None  # the last answer whose check moved
        for relative in FINISH_WEIGHTS:
            weight = relative * size
            linear = self.f.copy()
            linear[s] -= weight
            x = self._solve(self.H, linear, lbx, ubx)
            if x is None:
                break
            if x[s] >= ubx[s]:
                return x
            if stationary(*self._last_qp, -np.eye(1, x.size, s)[0]):
                return x
            linear = -(self.H @ x)
            linear[s] -= weight
            moved = self._solve(self.H, linear, lbx, ubx, feasible=True)
            if moved is not None and self._negligible(moved - x, x):
                return x
            checked = x
        if checked is None:  # infeasible, or with a witness, DAQP failed
            return None if witness is None else self._scale_and_final(lbx, ubx, witness)
        return self._scale_and_final(lbx, ubx, checked, finished=True)

    def _scale_and_final(self, lbx, ubx, witness: np.ndarray | None, finished: bool = False) -> np.ndarray | None:
        """The two stages `finish_lowest` stands for: max s of the lowest level, then ½xᵀHx + fᵀx
        with that s (or the witness's, if the scaling stage fails; None without one). `finished`:
        the witness is finish_lowest's answer, the least ½xᵀHx + fᵀx with its own s; if the stage
        finds no larger s, it stands (TALOS's 28 joints: its check moved by rounding, and the
        final QP at the same s, on a thin feasible set, failed in Python and not in C). Unless the
        stage meets the level (s at its bound): then the witness was short of it by rounding, and
        the final QP takes the level met (a 17-joint iCub's weighted QP stopped 3e-10 short of s = 1
        in C and reached it in Python, and their answers, amplified by the least-squares posture,
        parted by 1e-4)."""
        level = len(self.structure.priorities) - 1
        s, _ = self.structure.priorities[level]
        scaled = self.scale(level, lbx, ubx)
        if scaled is None:
            if witness is None:
                return None
            scaled = witness
        elif (finished and scaled[s] < ubx[s]
              and self._negligible(np.maximum(scaled[s:s + 1] - witness[s:s + 1], 0.0), witness)):
            return witness
        lo, hi = lbx.copy(), ubx.copy()
        lo[s] = hi[s] = min(max(scaled[s], lbx[s]), ubx[s])
        if self.structure.spare_variables and self._nominal_through(level + 1, lo, hi):
            return scaled  # every level nominal: the first QP of `levels`, which was infeasible
        # the rows the stage certifies active at that scaling held, as for a level above (on a
        # 27-joint Romeo DAQP called this QP infeasible without them in Python, and answered it
        # "optimal" in C at a point whose objective was 5 % above the least: the runtimes' torques
        # parted by 25 Nm; held, both give the least, which an interior-point solve confirms)
        self._hold_face(level, scaled, lo, hi)
        final = self._solve(self.H, self.f, lo, hi, feasible=True)
        if final is None:
            final = self._on_face(lo, hi, scaled)
        return scaled if final is None else final

    def _on_face(self, lbx, ubx, point: np.ndarray) -> np.ndarray | None:
        """½xᵀHx + fᵀx on the face of the feasible set that `point` (feasible) lies on (see
        FACE_TOLERANCE): its active rows equalities, the dependent ones among them dropped; the
        answer checked on every row as given. None if DAQP fails this QP too."""
        lba, uba = self.lba, self.uba
        value = self.A @ np.minimum(np.maximum(point, lbx), ubx)  # (at the fixed variables' values)
        active = np.minimum(np.abs(value - lba), np.abs(uba - value)) <= FACE_TOLERANCE * np.maximum(1.0, np.abs(value))
        self.lba, self.uba = lba.copy(), uba.copy()
        self._hold_rows(active, point, lbx, ubx)
        x = self._solve(self.H, self.f, lbx, ubx, feasible=True)
        self.lba, self.uba = lba, uba
        self._set_row_bounds()
        return None if x is None or not self._holds(x) else x

    def levels(self, hint: Hint | None = None) -> np.ndarray | None:
        """Steps 1–2 of the module docstring on the current bounds. `hint`: where the last step's
        hierarchy gave way (`Hint`); its stages are tried first, and the answer is the same."""
        count = len(self.structure.priorities)
        self.bent = [False] * count
        if not count or self.structure.spare_variables:  # (with spare variables, see finish_lowest)
            x = self.final(0, self.lbx, self.ubx)
            if x is not None or not count:
                return x
        tried = False  # the first QP, `finish_lowest` with every level above nominal
        if hint is not None and hint.skips_stages(count) and not self.structure.spare_variables:
            if hint.first == count - 1 and not hint.steady:
                # (the lowest level bent once: the first QP first, as where the level is met again
                # it is the only one, and the lowest level's bend flickers at its boundary; bent
                # for two steps, it is skipped)
                x = self.finish_lowest(*self._above_nominal(count - 1))
                if x is not None:
                    return x
                tried = True
            lbx, ubx = self.lbx.copy(), self.ubx.copy()
            above = self.structure.levels_above[hint.first]
            lbx[above] = ubx[above] = self.nominal[above]  # (s = 1, δ = 0)
            x = self._descend(hint.first, lbx, ubx, None, hint.bent)
            if x is not MISSED:
                return x
        if not tried:
            x = self.finish_lowest(*self._above_nominal(count - 1))
            if x is not None:
                return x
        return self._descend(*self._first_to_scale(), None)

    def _descend(self, start: int, lbx, ubx, witness: np.ndarray | None,
                 hinted_bends: tuple[bool, ...] | None) -> np.ndarray | None | object:
        """Step 2 from level `start`, the levels above it fixed in lbx/ubx. Without a hint, every
        stage `levels` and `_first_to_scale` found infeasible (the levels above nominal) is skipped;
        with one, the levels above `start` are met if `start`'s first stage is feasible (they are
        nominal in it, and nothing is above nominal), MISSED if it is not (start > 0: the hint was
        wrong), and a level the hint says bent tries its bend stage first: a bend that is not
        negligible means that no scaling of the level unbent is feasible, which is what its
        scaling stage would have found; a negligible one, that the level scales after all."""
        count = len(self.structure.priorities)
        hinted = hinted_bends is not None
        for i in range(start, count):
            s, bend = self.structure.priorities[i]
            bend = list(bend)
            lowest = i == count - 1
            if witness is None or i > start:  # (the first level to scale may be solved already)
                free_lo, free_hi = lbx.copy(), ubx.copy()
                lbx[bend] = ubx[bend] = 0.0
                x, bent = None, None
                if hinted and hinted_bends[i]:
                    bent = self.bend(i, free_lo, free_hi)
                    if bent is not None and self._negligible(bent[bend], bent):
                        bent = None  # (the level scales: its scaling stage below)
                    elif bent is None and i == start:
                        return MISSED if i > 0 else None  # (nothing is feasible if the top level's bend is not)
                # with every level above nominal, `_first_to_scale` (or for the lowest level, the
                # first QP, also when it is the only level) found this stage infeasible
                if bent is None and not (not hinted and (i > 0 or lowest) and self._nominal_through(i, lbx, ubx)):
                    x = self.finish_lowest(lbx, ubx) if lowest else self.scale(i, lbx, ubx)
                if x is None:
                    if bent is None:
                        bent = self.bend(i, free_lo, free_hi)
                    if bent is None:  # infeasible: only possible for the first level, else DAQP failed
                        if witness is None:
                            return MISSED if hinted and i > 0 else None
                        # on the sliver the levels above leave (see smallest_bend), whose point
                        # the witness is: its split made the bend's, the levels below solved on
                        bent = witness
                    self.bent[i] = True
                    x = self.smallest_bend(i, bent, free_lo, free_hi)
                    self._admit(x, lbx, ubx)
                    lbx[bend] = ubx[bend] = x[bend]
                    # (the bend's solution witnesses a scaling)
                    scaled = self.finish_lowest(lbx, ubx, x) if lowest else self.scale(i, lbx, ubx, feasible=True)
                    x = x if scaled is None else scaled
                if lowest:
                    return x
                witness = x
            # fixed exactly: a band would let the levels below move it within the band, and in
            # ill-conditioned states they gain far more than its width (a bend 40 % smaller for a
            # band of 1e-7, measured); a fixed variable leaves DAQP's QP (`FixedEliminated`)
            lbx[s] = ubx[s] = min(max(witness[s], self.lbx[s]), self.ubx[s])
            if lbx[s] != self.lbx[s] and self._negligible(lbx[s:s + 1] - self.lbx[s], witness):
                # scaled away but for a hair, which the runtimes' stages leave apart (as `_snapped`:
                # a 29-joint iCub's top level at s = 0 in Python and 1.6e-15 in C, its bend's split
                # at 0): scaled away
                lbx[s] = ubx[s] = self.lbx[s]
            self._hold_face(i, witness, lbx, ubx)
            if self._nominal_through(i + 1, lbx, ubx):
                continue  # every level so far nominal: the first QP, which was infeasible
            if i + 2 == count and not self.structure.spare_variables:
                continue  # the lowest level's first QP, `finish_lowest`, is this one where s can be 1
            x = self.final(i + 1, lbx, ubx)
            if x is not None:
                return x
        return witness

    def hint(self, x: np.ndarray) -> Hint | None:
        """Where this solve's answer x gave way, for the next step's solve (None: every level met)."""
        priorities = self.structure.priorities
        first = next((k for k, (s, _) in enumerate(priorities) if self.bent[k] or x[s] < self.nominal[s]), None)
        return None if first is None else Hint(first, tuple(self.bent))

    def _hold_face(self, level: int, witness: np.ndarray, lbx, ubx) -> None:
        """After `level`'s scaling stage, its variables now fixed in lbx/ubx: if the stage's last QP
        (whose answer is the witness) certifies a scaling below its bound (`certificate` of max s), the
        rows of that certificate are active in every answer with that scaling, and the stages below
        get them as equalities at their values: with the scaling fixed they are dependent in the
        free variables and pinch the feasible set to a face of lower dimension, on which DAQP
        called every QP infeasible (Baxter, a hand's level scaled to 0.43: the level below it was
        left short, 0.189 where 0.1999 was feasible, or bent where a scaling was, and C and Python
        parted by up to 30 Nm). The rows held so far are held again in the variables left free
        (`_hold_rows`): fixing a level can make some of them constant."""
        s, _ = self.structure.priorities[level]
        if self._last_qp is None or ubx[s] >= self.ubx[s]:
            return
        qp, multipliers = self._last_qp
        rows = None if s not in qp.free else face_rows(qp, multipliers, -np.eye(1, lbx.size, s)[0],
                                                        max(1.0, abs(float(witness[s]))))
        if rows is None:
            return
        rows = rows[rows >= qp.free.size] - qp.free.size
        if not rows.size:
            return
        self._held[rows] = True
        self._hold_rows(self._held, witness, lbx, ubx, face=True)

    def _hold_rows(self, rows: np.ndarray, point: np.ndarray, lbx, ubx, face: bool = False) -> None:
        """The rows of the mask `rows` as equalities at their values at `point` (within lbx/ubx), but
        the ones whose coefficients in the free variables are within INDEPENDENT_ROW (relative) of
        the span of those before them (Gram–Schmidt, in row order): on the face they are constant,
        and they are dropped (no bounds) and cleared from the mask. `face` (`_hold_face`'s holds):
        those dropped are noted, and with `reopen` keep their own bounds (see `solve_hinted`)."""
        value = self.A @ np.minimum(np.maximum(point, lbx), ubx)  # (at the fixed variables' values)
        free = lbx != ubx
        basis: list[np.ndarray] = []  # orthonormal, of the rows held so far (in the free variables)
        for i in np.flatnonzero(rows):
            rest = self.A[i, free].copy()
            for b in basis:
                rest -= b.dot(rest) * b
            size = math.sqrt(rest.dot(rest))
            if len(basis) < rest.size and size > INDEPENDENT_ROW * math.sqrt(self.A[i].dot(self.A[i])):
                basis.append(rest / size)
                self.lba[i] = self.uba[i] = value[i]
            else:
                rows[i] = False
                self._dropped[i] |= face
                reopened = face and self.reopen
                self.lba[i], self.uba[i] = (self._open_lba[i], self._open_uba[i]) if reopened else (-np.inf, np.inf)
        self._set_row_bounds()

    def crosses_dropped(self, x: np.ndarray) -> bool:
        """Does x cross, beyond FEASIBILITY_TOLERANCE, a row `_hold_face` dropped as dependent?"""
        if not self._dropped.any():
            return False
        return bool(outside_tolerance(self.A[self._dropped] @ x, self._open_lba[self._dropped], self._open_uba[self._dropped]).any())

    def _admit(self, x: np.ndarray, lbx: np.ndarray, ubx: np.ndarray) -> None:
        """Widen the rows and the variable bounds lbx/ubx that x crosses (by at most the check's
        FEASIBILITY_TOLERANCE) to x's values, so that the stages that fix a level at x's bend have
        x as an exactly feasible point (a bend's scaling came back 1e-10 above its largest).
        A bend leaves a thin feasible set (after `relax`, the widened bound and the torque limits
        that held it were 16 active rows of rank 5 on TALOS's 28 joints), and a point that crosses
        its rows by 1e-9 is no witness DAQP can use: it called the next stages infeasible, the
        bend's last iterate became the answer, and C and Python parted by up to 30 Nm."""
        np.minimum(lbx, x, out=lbx)
        np.maximum(ubx, x, out=ubx)
        value = self.A @ x
        np.minimum(self.lba, value, out=self.lba)
        np.maximum(self.uba, value, out=self.uba)
        # (a dropped row's own bounds as far as x crosses them within the check's tolerance only:
        # beyond it, x crossed a row the face had dropped, which `crosses_dropped` is to see)
        lower, upper = self._open_lba, self._open_uba
        within = ~outside_tolerance(value, lower, upper)
        np.minimum(lower, np.where(within, value, lower), out=lower)
        np.maximum(upper, np.where(within, value, upper), out=upper)
        self._set_row_bounds()

    def _above_nominal(self, level: int) -> tuple[np.ndarray, np.ndarray]:
        """The bounds with the levels above `level` fixed at their nominal values and its bend 0."""
        lbx, ubx = self.lbx.copy(), self.ubx.copy()
        above = self.structure.levels_above[level]
        lbx[above] = ubx[above] = self.nominal[above]  # (s = 1, δ = 0)
        bend = list(self.structure.priorities[level][1])
        lbx[bend] = ubx[bend] = 0.0
        return lbx, ubx

    def _nominal_through(self, upto: int, lbx, ubx) -> bool:
        """Are the levels [0, upto) fixed at their nominal values (s = 1, δ = 0)?"""
        above = self.structure.levels_above[upto]
        nominal = self.nominal[above]
        return bool((lbx[above] == nominal).all() and (ubx[above] == nominal).all())

    def _first_to_scale(self) -> tuple[int, np.ndarray, np.ndarray, np.ndarray | None]:
        """The lowest level i above the lowest that can be scaled (δᵢ = 0) with every level above
        it met (`levels` tried the lowest itself): then those levels are lexicographically optimal
        as they are, and the cascade starts at i. Usually a level near the bottom is the one that
        gives way, and this saves a stage per level above it. Returns i, the bounds with the
        levels above i fixed (and δᵢ = 0) and the scaling stage's solution, or (0, the bounds,
        None) to start from the top."""
        for i in range(len(self.structure.priorities) - 2, 0, -1):
            lbx, ubx = self._above_nominal(i)
            x = self.scale(i, lbx, ubx)
            if x is not None:
                return i, lbx, ubx, x
        return 0, self.lbx.copy(), self.ubx.copy(), None

    def relax(self) -> bool:
        """Widen the bound rows as little as the torque limits allow: one slack σᵣ ≥ 0 per bound,
        R x + σ ≥ lo and R x − σ ≤ hi, min Σwᵣσᵣ (a linear stage, as the scaling; w: the
        structure's slack weights, 1 but on a prismatic joint). Each σᵣ is solved for in its row's
        scale, σᵣ = sᵣσ̃ᵣ with sᵣ the largest |coefficient| of Rᵣ if above 1 (the same σ, the same
        minimum): with unit slack columns beside bound rows of 1e7 (a Panda's joint 1.5 rad beyond
        its limit after two 300 N pushes; found from outside) DAQP answered every QP of the
        relaxation "optimal, inexact", torque rows crossed by 1 %, and the step fell back. The
        sum, not the sum of squares: a least-squares relaxation spreads the violation, and bounds that could
        hold gave way a little to spare the one that cannot (a joint at rest pushed 1.65 % beyond
        its bound to gain 6e-5 on another). Each bound that gave way is then widened to what was
        achieved, plus RELAX_MARGIN (the next stages must not be left a degenerate feasible set)."""
        rows = self.structure.bound_rows
        nx, r = self.lbx.size, len(rows)
        if not r:
            return False
        R = self.A[rows.start : rows.stop]
        other = np.delete(self.A, np.s_[rows.start : rows.stop], axis=0)
        size = np.maximum(np.abs(R).max(axis=1, initial=0.0), 1.0)  # σ = size σ̃: each slack in its row's scale
        A = np.block([[other, np.zeros((other.shape[0], r))], [R, np.diag(size)], [R, -np.diag(size)]])
        lo, hi = self.lba[rows.start : rows.stop], self.uba[rows.start : rows.stop]
        lba = np.concatenate([np.delete(self.lba, np.s_[rows.start : rows.stop]), lo, np.full(r, -np.inf)])
        uba = np.concatenate([np.delete(self.uba, np.s_[rows.start : rows.stop]), np.full(r, np.inf), hi])
        slack = Cascade(np.eye(nx + r), np.zeros(nx + r), A, np.concatenate([self.lbx, np.zeros(r)]),
                        np.concatenate([self.ubx, np.full(r, np.inf)]), lba, uba,
                        Structure(range(0), (), self.structure.spare_variables))
        slack.nominal = np.concatenate([self.nominal, np.zeros(r)])
        weights = np.ones(r) if self.structure.slack_weights is None else np.asarray(self.structure.slack_weights)
        linear = np.concatenate([np.zeros(nx), weights * size])
        x = None
        for step in RELAX_STEPS:  # (see RELAX_STEPS)
            x = slack._proximal(np.zeros(nx + r), linear, step, slack.lbx, slack.ubx, RELAX_ITERATIONS)
            if x is not None:
                break
        if x is None:
            return False
        self.relaxed_point = x[:nx]
        value = R @ x[:nx]
        margin = RELAX_MARGIN * np.maximum(1.0, np.abs(value))
        # only the bounds that gave way are widened (a margin on a bound that held would let
        # the stages below cross it)
        self.lba[rows.start : rows.stop] = np.where(value < lo - margin, value - margin, lo)
        self.uba[rows.start : rows.stop] = np.where(value > hi + margin, value + margin, hi)
        self._open_lba, self._open_uba = self.lba.copy(), self.uba.copy()
        self._set_row_bounds()
        return True


def _ascends(x: np.ndarray, previous: np.ndarray, weights: np.ndarray, linear: np.ndarray) -> bool:
    """Does φ(x) = ½Σwⱼxⱼ² + linearᵀx exceed φ(previous) by more than ASCENT_TOLERANCE?"""
    phi_x = 0.5 * float(weights.dot(x * x)) + float(linear.dot(x))
    phi_previous = 0.5 * float(weights.dot(previous * previous)) + float(linear.dot(previous))
    return phi_x - phi_previous > ASCENT_TOLERANCE * max(1.0, abs(phi_previous))


def solve_lexicographic(H, f, A, lbx, ubx, lba, uba, structure: Structure,
                        acceleration_map: np.ndarray | None = None) -> np.ndarray | None:
    """The lexicographic solution of a QP's priority levels (None if DAQP failed); with the
    acceleration map Q, a bent level's split into s and δ the least bend (`Cascade.smallest_bend`).
    Whether the bounds had to be relaxed is for `check_bounds` to tell, on the original data."""
    return solve_hinted(H, f, A, lbx, ubx, lba, uba, structure, acceleration_map, None)[0]


def solve_hinted(H, f, A, lbx, ubx, lba, uba, structure: Structure, acceleration_map: np.ndarray | None,
                 hint: Hint | None) -> tuple[np.ndarray | None, Hint | None, bool]:
    """`solve_lexicographic` starting where the last step gave way (`hint`), and where this one did
    (steady if that is where the last one did too), and whether the answer is the relaxation's
    own point: DAQP failed the levels' stages on the relaxed bounds (`Cascade.relax`)."""
    cascade = Cascade(H, f, A, lbx, ubx, lba, uba, structure, acceleration_map)
    x = cascade.levels(hint)
    relaxed = x is None and cascade.relax()
    if relaxed:
        x = cascade.levels(hint)
    if x is not None and cascade.crosses_dropped(x):
        # a row dropped as dependent on a held face was not constant enough (held rows nearly
        # dependent themselves amplify DAQP's tolerance: docs/formulations.md, "A held row found
        # dependent"): once more with such rows keeping their bounds (after the same relaxation,
        # where the bounds gave way), kept if it holds them
        again = Cascade(H, f, A, lbx, ubx, lba, uba, structure, acceleration_map, reopen=True)
        if not relaxed or again.relax():
            y = again.levels(hint)
            if y is not None and not again.crosses_dropped(y):
                cascade, x = again, y
    if x is None and relaxed:
        # (the relaxation's own point meets the widened bounds: better than no answer, if DAQP fails)
        return cascade.relaxed_point, None, True
    new = None if x is None else cascade.hint(x)
    if new is not None and hint is not None and (new.first, new.bent) == (hint.first, hint.bent):
        new = Hint(new.first, new.bent, True)
    return x, new, False
