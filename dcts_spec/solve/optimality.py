"""Is the lowest level's objective at its optimum? A check of the answer, after the solver.

The lexicographic solve checks every QP's answer against its rows, and each scaling against its
certificate, but the last QP's optimum (½xᵀHx + fᵀx over the variables no level owns: the
acceleration energy and a least-squares posture) was DAQP's word. On a 27-joint Romeo, 8 of 289
"ok" states ended up to 10 Nm away from it after a bend (docs/formulations.md, "The lowest
level's final QP on the face its scaling stage certifies"). This check says so in every step.

At the answer x, with the levels' variables held, x minimizes the objective over what the
levels leave free if and only if its gradient g there is a nonnegative combination of the
outward normals of the constraints active at x (KKT): −g ∈ cone{n_j}. The distance from −g to
that cone is a nonnegative least squares (Lawson–Hanson), on the active set read from x itself
(not from the solver's working set, which on a degenerate face depends on its path). The
generated C runs the same algorithm (`ctl_final_optimal`).
"""

from __future__ import annotations

import math

import numpy as np

from .lexicographic import Structure

# A constraint is active within this much of its bound (relative to max(1, |value|)), or beyond
# it: DAQP's answers sit on their working set's rows to rounding. Not the 1e-7 every answer is
# checked to: on Romeo's slivers a torque row 2e-8 (relative) inside its bound then certified an
# answer whose objective an exact QP solver (HiGHS, at its 1e-7) lowered by 40 %, 139 Nm away.
ACTIVE = 1e-9
# The answer is certified if the distance from −g to the cone is at most this much of the
# objective's scale, max(1, ‖(Hx)_free‖, ‖f_free‖). At optima it is ~1e-10 (bench spec, PR2 15,
# Romeo 27: scripts/optimality_scan.py), at the answers found off it 5e-3 to 0.44.
OPTIMALITY_TOLERANCE = 1e-6
# A passive set is singular where a column's part outside the span of those before it is below
# this (the columns have unit norm): two rows' normals 2e-6 from opposite (a PR2 torque row and
# a joint's bound, a sliver between them) are still two.
INDEPENDENT = 1e-10
# Lawson–Hanson adds the normal most aligned with the residual while that alignment is above
# this much of ‖g‖ (the normals have unit norm).
ALIGNED = 1e-12


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


def nonnegative_least_squares(N: np.ndarray, b: np.ndarray) -> float:
    """min ‖Nμ − b‖ over μ ≥ 0 (Lawson–Hanson; N's columns of unit norm): that distance. The
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
    return math.sqrt(residual.dot(residual))


def final_optimal(H: np.ndarray, f: np.ndarray, A: np.ndarray, lbx: np.ndarray, ubx: np.ndarray,
                  lba: np.ndarray, uba: np.ndarray, x: np.ndarray, structure: Structure) -> bool:
    """Does x minimize ½xᵀHx + fᵀx on the QP's set with the priority levels' variables held at
    x's values? (The bounds as the answer was meant to hold them: the QP data's for status "ok".)"""
    free = np.setdiff1d(np.arange(x.size), structure.levels_above[-1])
    if not free.size:
        return True
    gradient = (H @ x + f)[free]
    # the rows of A, then x's bounds, in the free variables; outward normals (−row at a lower
    # bound, +row at an upper one) of unit norm
    rows = np.vstack([A[:, free], np.eye(x.size)[free][:, free]])
    value = np.concatenate([A @ x, x[free]])
    lower, upper = np.concatenate([lba, lbx[free]]), np.concatenate([uba, ubx[free]])
    size = np.sqrt(np.einsum("ij,ij->i", rows, rows))
    band = ACTIVE * np.maximum(1.0, np.abs(value))
    seen = size > 0.0
    at_lower, at_upper = seen & (value - lower <= band), seen & (upper - value <= band)
    # (in the C's order: constraint by constraint, its lower bound first)
    ends = np.sort(np.concatenate([2 * np.flatnonzero(at_lower), 2 * np.flatnonzero(at_upper) + 1]))
    normals = rows[ends // 2] * (np.where(ends % 2, 1.0, -1.0) / size[ends // 2])[:, None]
    if normals.size:
        distance = nonnegative_least_squares(normals.T, -gradient)
    else:
        distance = math.sqrt(gradient.dot(gradient))
    scale = max(1.0, float(np.linalg.norm((H @ x)[free])), float(np.linalg.norm(f[free])))
    return distance is not None and distance <= OPTIMALITY_TOLERANCE * scale
