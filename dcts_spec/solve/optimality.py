"""The lowest level's optimum: checked at the answer after the solver, and reached from it.

The lexicographic solve checks every QP's answer against its rows, and each scaling against its
certificate, but the last QP's optimum (½xᵀHx + fᵀx over the variables no level owns: the
acceleration energy and a least-squares posture) was DAQP's word. On a 27-joint Romeo, 11 of 289
"ok" answers were off it, after a bend, up to 85 Nm (docs/formulations.md, "The lowest level's
optimum, checked at the answer and reached from it").

At the answer x, with the levels' variables held, x minimizes the objective over what the
levels leave free if and only if its gradient g there is a nonnegative combination of the
outward normals of the constraints active at x (KKT): −g ∈ cone{n_j}. The distance from −g to
that cone is a nonnegative least squares (Lawson–Hanson), on the active set read from x itself
(not from the solver's working set, which on a degenerate face depends on its path). Where x is
off the optimum, `to_optimum` takes it there by a primal active-set method within the same rows.
Every answer is first polished by one Newton step on its active face (`_polished`): the check's
tolerance is on the gradient, and along a direction of little curvature an answer can pass it
far from the minimum (the least squares below a scaled level, after the cascade's weighted QP).
The generated C runs the same algorithms (`ctl_to_optimum`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .lexicographic import Structure
from .stage_qp import constant_rows, row_sizes

# A constraint is active within this much of its bound, relative to max(1, the sum of the
# magnitudes of the terms its value adds up: its rounding's scale), or beyond it. DAQP's answers
# sit on their working set's rows to rounding. At 1e-7 relative to the value (the tolerance every
# answer is checked to), a Romeo answer with a torque row 2e-8 inside its bound was certified
# while the optimum was 139 Nm away.
ACTIVE = 1e-12
# The answer is certified if the distance from −g to the cone is at most this much of the
# objective's scale, max(1, ‖(Hx)_free‖, ‖f_free‖). At optima it is ~1e-10 (bench spec, PR2 15,
# Romeo 27: scripts/optimality_scan.py), at the answers found off it 5e-3 to 0.44.
OPTIMALITY_TOLERANCE = 1e-6
# A passive set is singular where a column's part outside the span of those before it is below
# this (the columns have unit norm): two rows' normals 2e-6 from opposite (a PR2 torque row and
# a joint's bound, a sliver between them) are still two.
INDEPENDENT = 1e-10
# to_optimum: at most this many steps (Romeo's 11 answers off the optimum took 1–3), and a Newton
# step this small (relative to max(1, ‖g‖)) is none: the NNLS residual's direction instead.
POLISH_STEPS = 20
SMALL_STEP = 1e-14
# Lawson–Hanson adds the normal most aligned with the residual while that alignment is above
# this much of ‖g‖ (the normals have unit norm).
ALIGNED = 1e-12
# The polish (`_polished`) is taken where it stays within every constraint and raises the
# objective by no more than this much of its terms' size (its rounding: on its face the Newton
# step is the minimizer, and it lowers the objective by as little as its square where it corrects
# an answer along a direction of little curvature).
POLISH_ROUNDING = 1e-12


def _least_squares(N: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """z minimizing ‖Nz − b‖ for N of independent columns, by Householder QR (the normal
    equations square N's condition: at the PR2 sliver of INDEPENDENT's note, to 1e12, and the
    distance came out at 5e-3 of ‖b‖ where it is 5e-10); None if a column is within INDEPENDENT
    of the others' span."""
    if not N.shape[1]:
        return np.zeros(0)
    Q, R = np.linalg.qr(N)
    if not (np.abs(np.diag(R)) > INDEPENDENT).all():
        return None
    return np.linalg.solve(R, Q.T @ b)


def nonnegative_least_squares(N: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """min ‖Nμ − b‖ over μ ≥ 0 (Lawson–Hanson; N's columns of unit norm): μ and the residual
    b − Nμ (the part of b off the cone, a direction N's columns do not point into). The
    passive set's least squares by QR, as in the C. A column that would join a singular set
    (within INDEPENDENT of the passive span: a row active at both ends, a bound and a row alike)
    or with a coefficient ≤ 0 (rounding; in exact arithmetic it is positive) cannot shorten the
    residual from there: it is passed over until the set changes."""
    m, k = N.shape
    mu = np.zeros(k)
    passive = np.zeros(k, dtype=bool)
    passed = np.zeros(k, dtype=bool)
    residual = b.copy()
    threshold = ALIGNED * math.sqrt(b.dot(b))
    for _ in range(3 * k + 3):  # (a bound on the steps, whatever the rounding)
        w = N.T @ residual
        w[passive | passed] = -np.inf
        j = int(np.argmax(w)) if k else 0
        if not k or not w[j] > threshold or passive.sum() == m:
            break
        passive[j] = True
        P = np.flatnonzero(passive)
        z = _least_squares(N[:, P], b)
        if z is None or not z[np.searchsorted(P, j)] > 0.0:
            passive[j], passed[j] = False, True
            continue
        passed[:] = False
        while not (z > 0.0).all():  # step from μ towards z until a coefficient reaches 0; it leaves
            blocking = np.flatnonzero(z <= 0.0)  # (μ > 0 there: j's z is > 0, the others' μ were)
            ratios = mu[P][blocking] / (mu[P][blocking] - z[blocking])
            first = blocking[int(np.argmin(ratios))]
            mu[P] += ratios.min() * (z - mu[P])
            leaving = P[(mu[P] <= 0.0) | (np.arange(P.size) == first)]
            mu[leaving] = 0.0
            passive[leaving] = False
            P = np.flatnonzero(passive)
            z = _least_squares(N[:, P], b)  # (regular: a subset of a regular set)
            if z is None or not P.size:
                break
        mu[:] = 0.0
        if z is not None:
            mu[P] = z
        residual = b - N @ mu
    return mu, residual


@dataclass
class _Constraints:
    """The QP's rows and the free variables' bounds, over the variables no level owns."""

    free: np.ndarray  # those variables' indices
    rows: np.ndarray  # coefficients in them: A's rows, then the identity (their bounds)
    lower: np.ndarray
    upper: np.ndarray
    size: np.ndarray  # each row's norm (0: it sees no free variable)

    @classmethod
    def of(cls, A, lbx, ubx, lba, uba, structure: Structure) -> _Constraints:
        owned = np.zeros(lbx.size, dtype=bool)
        owned[structure.levels_above[-1]] = True
        free = np.flatnonzero(~owned)
        rows = np.vstack([A[:, free], np.eye(free.size)])
        size = np.sqrt(np.einsum("ij,ij->i", rows, rows))
        # a row that sees no free variable but through rounding (as the cascade's `constant_rows`)
        # is no constraint on them: its "normal" is noise (a Romeo row of norm 1.6e-18 in them
        # carried a multiplier, and its slack over that norm, 35, a duality gap of 2e4)
        size[: A.shape[0]][constant_rows(A[:, free], row_sizes(A))] = 0.0
        return cls(free, rows, np.concatenate([lba, lbx[free]]), np.concatenate([uba, ubx[free]]), size)

    def values(self, A: np.ndarray, x: np.ndarray) -> np.ndarray:
        return np.concatenate([A @ x, x[self.free]])


@dataclass
class _Stationarity:
    """KKT at x: the active constraints' outward unit normals (columns of N; `which` their rows),
    NNLS's multipliers μ, the residual r = −g − Nμ, and whether ‖r‖ is within tolerance."""

    N: np.ndarray
    which: np.ndarray
    mu: np.ndarray
    residual: np.ndarray
    optimal: bool


def _stationarity(H, f, A, c: _Constraints, x: np.ndarray) -> _Stationarity:
    gradient = (H @ x + f)[c.free]
    value = c.values(A, x)
    # (the band scales with the terms the value sums, the size of its rounding: a row that barely
    # sees the free variables is 1e-16 from its bound in value and 1e-6 in distance)
    band = ACTIVE * np.maximum(1.0, np.concatenate([np.abs(A) @ np.abs(x), np.abs(x[c.free])]))
    seen = c.size > 0.0
    at_lower, at_upper = seen & (value - c.lower <= band), seen & (c.upper - value <= band)
    # (in the C's order: constraint by constraint, its lower bound first)
    ends = np.sort(np.concatenate([2 * np.flatnonzero(at_lower), 2 * np.flatnonzero(at_upper) + 1]))
    which = ends // 2
    N = (c.rows[which] * (np.where(ends % 2, 1.0, -1.0) / c.size[which])[:, None]).T
    mu, residual = nonnegative_least_squares(N, -gradient) if which.size else (np.zeros(0), -gradient)
    scale = max(1.0, float(np.linalg.norm((H @ x)[c.free])), float(np.linalg.norm(f[c.free])))
    return _Stationarity(N, which, mu, residual, math.sqrt(residual.dot(residual)) <= OPTIMALITY_TOLERANCE * scale)


def final_optimal(H: np.ndarray, f: np.ndarray, A: np.ndarray, lbx: np.ndarray, ubx: np.ndarray,
                  lba: np.ndarray, uba: np.ndarray, x: np.ndarray, structure: Structure) -> bool:
    """Does x minimize ½xᵀHx + fᵀx on the QP's set with the priority levels' variables held at
    x's values? (The bounds as the answer was meant to hold them: the QP data's for status "ok".)"""
    c = _Constraints.of(A, lbx, ubx, lba, uba, structure)
    return not c.free.size or _stationarity(H, f, A, c, x).optimal


def to_optimum(H: np.ndarray, f: np.ndarray, A: np.ndarray, lbx: np.ndarray, ubx: np.ndarray,
               lba: np.ndarray, uba: np.ndarray, x: np.ndarray, structure: Structure) -> tuple[np.ndarray, bool]:
    """x, or where it is off the optimum (`final_optimal`), the optimum reached from it by a
    primal active-set method on the variables no level owns (the levels' held): x and whether it
    is now certified. x must hold the rows; each step keeps them (a ratio test), and lowers the
    objective. A step is Newton's on the face of the active constraints that carry a multiplier
    (and of those it would otherwise cross): p = −Z(ZᵀHZ)⁻¹Zᵀg, Z a basis of that face's
    directions; where that face leaves no descent, the NNLS residual r, the steepest direction
    that crosses no active constraint, with an exact line search. See docs/formulations.md."""
    c = _Constraints.of(A, lbx, ubx, lba, uba, structure)
    if not c.free.size:
        return x, True
    H_free = H[np.ix_(c.free, c.free)]
    kkt = _stationarity(H, f, A, c, x)
    polished = _polished(H, f, A, c, H_free, x, kkt)
    if polished is not x:
        x, kkt = polished, _stationarity(H, f, A, c, polished)
    if kkt.optimal:  # (the usual case: the cascade's answer)
        return x, True
    x = x.copy()
    for k in range(POLISH_STEPS):
        if k:
            kkt = _stationarity(H, f, A, c, x)
            if kkt.optimal:
                return x, True
        gradient = (H @ x + f)[c.free]
        d, length = _newton_on_face(H_free, gradient, kkt), 1.0
        if d is None:  # (the residual r: r'(−g) = |r|², the exact line search's length)
            d = kkt.residual
            length = d.dot(d) / max(float(d @ H_free @ d), np.finfo(float).tiny)
        t = min(length, _room(c, A, x, d))
        if not t > 0.0:
            break
        y = x.copy()
        y[c.free] += t * d
        if not 0.5 * y @ H @ y + f @ y < 0.5 * x @ H @ x + f @ x:
            break
        x = y
    return x, _stationarity(H, f, A, c, x).optimal


def _polished(H, f, A, c: _Constraints, H_free: np.ndarray, x: np.ndarray, kkt: _Stationarity) -> np.ndarray:
    """x after one Newton step on its active face (`_newton_on_face`), or x itself where there is
    none, it would cross a constraint, or it raises the objective beyond POLISH_ROUNDING. The
    cascade's answers carry the rounding of their QPs: finish_lowest's weighted QP (min ½xᵀHx +
    fᵀx − K s, K ~1e6 × the data) left a Panda's least-squares damping below a scaled level
    1.1e-4 rad/s² (4.6e-6 of the level) from its minimum along the one direction left to it, an
    answer whose gradient passed the check (found from outside against the reference)."""
    d = _newton_on_face(H_free, (H @ x + f)[c.free], kkt)
    if d is None or _room(c, A, x, d) < 1.0:
        return x
    y = x.copy()
    y[c.free] += d
    hx, hy = H @ x, H @ y
    terms = float(np.abs(x) @ np.abs(hx)) * 0.5 + float(np.abs(f) @ np.abs(x))
    if 0.5 * y @ hy + f @ y > 0.5 * x @ hx + f @ x + POLISH_ROUNDING * max(1.0, terms):
        return x
    return y


def _newton_on_face(H_free: np.ndarray, gradient: np.ndarray, kkt: _Stationarity) -> np.ndarray | None:
    """Newton's step on the face of the active constraints with μ > 0, joined by each active one
    the step would cross (the most crossed first), or None if that face has no room left, is
    singular (a normal within INDEPENDENT of the others' span), or the step is ~0 there."""
    m = gradient.size
    face = list(np.flatnonzero(kkt.mu > 0.0))
    while len(face) < m:
        if face:
            Q, R = np.linalg.qr(kkt.N[:, face], mode="complete")
            if not (np.abs(np.diag(R)) > INDEPENDENT).all():  # (a singular face, as in the C)
                return None
        else:
            Q = np.eye(m)
        Z = Q[:, len(face):]
        p = -Z @ np.linalg.solve(Z.T @ H_free @ Z, Z.T @ gradient)
        size = math.sqrt(p.dot(p))
        if not size > SMALL_STEP * max(1.0, math.sqrt(gradient.dot(gradient))):
            return None
        crossing = kkt.N.T @ p
        crossing[face] = -np.inf
        j = int(np.argmax(crossing)) if crossing.size else -1
        if j < 0 or crossing[j] <= ALIGNED * size:
            return p
        face.append(j)
    return None


def _room(c: _Constraints, A: np.ndarray, x: np.ndarray, d: np.ndarray) -> float:
    """The largest t with x + t d (d over the free variables) within every constraint: the ratio
    test; a constraint d moves along (to rounding: an active one it keeps) does not stop it."""
    value, rate = c.values(A, x), c.rows @ d
    size = math.sqrt(d.dot(d))
    moving = (c.size > 0.0) & (np.abs(rate) > ALIGNED * c.size * size)
    room = np.full(rate.size, np.inf)
    down, up = moving & (rate < 0.0), moving & (rate > 0.0)
    room[down] = np.maximum(value[down] - c.lower[down], 0.0) / -rate[down]
    room[up] = np.maximum(c.upper[up] - value[up], 0.0) / rate[up]
    return float(room.min()) if room.size else np.inf
