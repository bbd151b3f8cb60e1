"""The lowest level's optimum checked at the answer (solve/optimality.py, StepResult.optimal)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import nnls

import dcts_spec
from dcts_spec.codegen.states import StateSampler, trajectory_states
from dcts_spec.controller import STATUS_NONFINITE_INPUT, STATUS_OK
from dcts_spec.solve import final_optimal, solve_lexicographic, to_optimum
from dcts_spec.solve.optimality import nonnegative_least_squares
from saved_qp import saved_qp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))
from optimality_scan import kkt_residual  # noqa: E402  (a script, not a package)

SPECS = Path(__file__).resolve().parent.parent / "specs"
BENCH = SPECS / "bench_iiwa14.yaml"
MINIMAL = SPECS / "minimal.yaml"  # (four variables no level owns: the bench spec's active rows fix both of its two)


def _normals(rng: np.random.Generator, m: int, k: int) -> np.ndarray:
    """k unit columns in R^m, some of them repeated or opposite (a row active at both ends, a
    bound and a row alike): the degenerate cones the check meets."""
    N = rng.normal(size=(m, k))
    for j in range(1, k):
        draw = rng.random()
        if draw < 0.15:
            N[:, j] = -N[:, rng.integers(0, j)]
        elif draw < 0.25:
            N[:, j] = N[:, rng.integers(0, j)]
    return N / np.linalg.norm(N, axis=0)


def test_nonnegative_least_squares_is_scipys_distance():
    """Lawson–Hanson on 3,000 random cones, against scipy's NNLS (an independent implementation):
    the same distance from b to the cone, to 1e-9 of |b|."""
    rng = np.random.default_rng(11)
    worst = 0.0
    for _ in range(3000):
        m, k = int(rng.integers(1, 10)), int(rng.integers(1, 16))
        N = _normals(rng, m, k)
        b = rng.normal(size=m) * 10.0 ** rng.uniform(-3, 3)
        distance = np.linalg.norm(nonnegative_least_squares(N, b)[1])
        worst = max(worst, abs(distance - nnls(N, b)[1]) / max(1.0, np.linalg.norm(b)))
    assert worst < 1e-9, worst


def test_two_nearly_opposite_normals_are_still_two():
    """A sliver between two rows whose normals are 2e-6 from opposite (found on a 15-joint PR2):
    −g lies in their cone with multipliers ~3e8. By the normal equations (condition 1e12) the
    distance came out 5e-3 of |g| and a KKT point was called off its optimum; by QR, ~1e-9."""
    n = np.array([1.0, 0.0, 0.0])
    other = np.array([-1.0, 2e-6, 0.0])
    N = np.column_stack([n, other / np.linalg.norm(other), [0.0, 0.0, 1.0]])
    b = 3e8 * N[:, 0] + 3e8 * N[:, 1] + 5.0 * N[:, 2]  # (in the cone: the distance is 0)
    assert np.linalg.norm(nonnegative_least_squares(N, b)[1]) < 1e-6 * np.linalg.norm(b)


def test_the_check_sees_a_final_answer_off_its_optimum():
    """A golden state of a 27-joint Romeo (test_lexicographic's saved state): the answer the C
    runtime once gave, 5 % above the least objective with every row held, is not certified; the
    solve's answer now, the optimum (an interior-point solve finds nothing lower), is."""
    args, structure = saved_qp("lowest_final_qp_certified_face")
    saved = np.load(Path(__file__).parent / "data" / "lowest_final_qp_certified_face.npz")
    x = solve_lexicographic(*args, structure, saved["Q"])
    assert final_optimal(*args, x, structure)
    assert not final_optimal(*args, saved["former_c"], structure)


def test_an_answer_off_the_optimum_is_taken_to_it():
    """The saved Romeo state's former C answer (its KKT residual 0.57 of the gradient):
    `to_optimum` takes it, within the same rows and with the levels held, to a point an
    independent check certifies (scipy's NNLS on the rows active there), 2 % lower in objective.
    (The cascade's answer is 3 % lower still: in this state a row that sees the free variables
    at 3e-7 of its size, and another nearly opposite it there, carry multipliers of 1e12, and
    which side of the first a point is on is a matter of rounding; both points are certified.)"""
    args, structure = saved_qp("lowest_final_qp_certified_face")
    saved = np.load(Path(__file__).parent / "data" / "lowest_final_qp_certified_face.npz")
    H, f, A, lbx, ubx, lba, uba = args
    former = saved["former_c"]
    x, certified = to_optimum(*args, former, structure)
    levels = structure.levels_above[-1]
    assert certified and np.array_equal(x[levels], former[levels])
    value = A @ x
    assert (np.maximum(lba - value, value - uba) <= 1e-9 * np.maximum(1.0, np.abs(value))).all()
    objective = lambda y: 0.5 * y @ H @ y + f @ y  # noqa: E731
    assert objective(x) < objective(former) - 0.01 * abs(objective(former))
    free = np.setdiff1d(np.arange(x.size), levels)
    residual, gradient = kkt_residual(H, f, A, lba, uba, free, x)
    assert residual < 1e-6 * gradient


def test_a_point_moved_off_a_well_posed_optimum_comes_back_to_it():
    """The minimal spec near its start (strictly convex, its optimum unique and well posed): its
    answers moved along their free variables (within every row) are taken back by `to_optimum`
    to the same answer, to 1e-9 of its size."""
    controller = dcts_spec.build_controller(MINIMAL)
    structure = controller._structure
    free = np.setdiff1d(np.arange(controller.nx), structure.levels_above[-1])
    rng = np.random.default_rng(8)
    home = np.radians([0, 30, 0, -60, 0, 60, 0])
    back = 0
    for _ in range(20):
        q, dq = home + rng.normal(0, 0.2, 7), rng.normal(0, 0.3, 7)
        result = controller.step(q, dq, np.zeros(7))
        if result.status != STATUS_OK:
            continue
        data = controller.evaluate_data(q, dq, np.zeros(7))
        args = (data["H"], data["f"].ravel(), data["A"], data["lbx"].ravel(), data["ubx"].ravel(),
                data["lba"].ravel(), data["uba"].ravel())
        moved = result.x.copy()
        moved[free] += 1e-3 * rng.normal(size=free.size) * max(1.0, np.abs(result.x).max())
        value = args[2] @ moved
        if ((value < args[5]) | (value > args[6])).any():
            continue
        x, certified = to_optimum(*args, moved, structure)
        assert certified and np.abs(x - result.x).max() <= 1e-9 * max(1.0, np.abs(result.x).max())
        back += 1
    assert back >= 10, back


def test_an_answer_off_its_minimum_along_a_flat_direction_is_polished():
    """A Panda (a 5-axis pose, joint 3, joint damping over every joint in least squares: one
    direction left to the damping), joint 3's level scaled by its velocity limit (found from
    outside against the independent reference). The cascade's answer came from finish_lowest's
    weighted QP (min ½xᵀHx + fᵀx − K s, K ~1e6 × the data), whose rounding left the damping
    1.1e-4 rad/s² from its minimum along that direction (4.6e-6 of the level, relative), in both
    runtimes: an answer whose gradient passes the check (7e-8 of the scale, within
    OPTIMALITY_TOLERANCE). Such an answer (the minimizer moved by that much along the direction,
    the levels' variables as solved) is polished to the minimizer (one Newton step on its face)."""
    from saved_qp import saved_acceleration_map

    args, structure = saved_qp("least_squares_after_the_weighted_qp")
    Q = saved_acceleration_map("least_squares_after_the_weighted_qp")
    H, f, A, lbx, ubx, lba, uba = args
    answer = solve_lexicographic(*args, structure, Q)
    levels = structure.levels_above[-1]
    free = np.setdiff1d(np.arange(answer.size), levels)
    y = answer.copy()  # with the levels' variables as solved, the rest minimizes the objective
    y[free] = -np.linalg.solve(H[np.ix_(free, free)], f[free] + H[np.ix_(free, levels)] @ answer[levels])
    seen = np.abs(A[:, free]).max(axis=1) > 1e-12 * np.abs(A).max(axis=1)  # (the others are fixed with the levels)
    margin = np.minimum(A @ y - lba, uba - A @ y)[seen]
    assert free.size == 1 and margin.min() > 1e-3, "the premise: one direction, its minimizer inside every row it moves"
    off = y.copy()
    off[free] += 1.1e-4 / np.linalg.norm(Q[:, free])  # (1.1e-4 rad/s² along it, as the weighted QP left it)
    assert final_optimal(*args, off, structure), "the premise: the gradient's check passes it"
    x, certified = to_optimum(*args, off, structure)
    assert certified and np.linalg.norm(Q @ (x - y)) <= 1e-9 * (1.0 + np.linalg.norm(Q @ y))


def test_an_optimal_answer_is_left_as_it_is():
    controller = dcts_spec.build_controller(BENCH)
    for s in StateSampler(controller, 2).mixed(20, limit_fraction=0.3):
        result = controller.step(s.q, s.dq, s.tau_ext, s.ref)
        if result.status != STATUS_OK:
            continue
        data = controller.evaluate_data(s.q, s.dq, s.tau_ext, s.ref)
        args = (data["H"], data["f"].ravel(), data["A"], data["lbx"].ravel(), data["ubx"].ravel(),
                data["lba"].ravel(), data["uba"].ravel())
        x, certified = to_optimum(*args, result.x, controller._structure)
        assert certified and np.array_equal(x, result.x)


def test_an_answer_moved_along_its_face_is_seen():
    """The minimal spec's answers near its start are certified; each moved along its face (a direction of
    the free variables that keeps its active rows active, and small enough to cross no other) has a
    larger objective, and is not certified."""
    controller = dcts_spec.build_controller(MINIMAL)
    structure = controller._structure
    free = np.setdiff1d(np.arange(controller.nx), structure.levels_above[-1])
    checked = moved = 0
    rng = np.random.default_rng(4)
    home = np.radians([0, 30, 0, -60, 0, 60, 0])  # (its scenario's start: torques well within their limits)
    for _ in range(40):
        q, dq, tau_ext = home + rng.normal(0, 0.2, 7), rng.normal(0, 0.3, 7), np.zeros(7)
        result = controller.step(q, dq, tau_ext)
        if result.status != STATUS_OK:
            assert result.optimal is None
            continue
        data = controller.evaluate_data(q, dq, tau_ext)
        args = (data["H"], data["f"].ravel(), data["A"], data["lbx"].ravel(), data["ubx"].ravel(),
                data["lba"].ravel(), data["uba"].ravel())
        assert result.optimal is True and final_optimal(*args, result.x, structure)
        checked += 1
        H, f, A, _, _, lba, uba = args
        x, value = result.x, A @ result.x
        band = 1e-9 * np.maximum(1.0, np.abs(value))
        active = (value - lba <= band) | (uba - value <= band)
        _, sv, vt = np.linalg.svd(A[active][:, free]) if active.any() else (None, np.zeros(0), np.eye(free.size))
        face = vt[int((sv > 1e-9).sum()):]  # (orthonormal rows spanning the face's directions)
        if not face.size:
            continue
        y = x.copy()
        y[free] += 1e-2 * max(1.0, float(np.abs(x).max())) * face[0]
        moved_value = A @ y
        if ((moved_value < lba - band) | (moved_value > uba + band)).any():
            continue
        assert 0.5 * y @ H @ y + f @ y > 0.5 * x @ H @ x + f @ x
        assert not final_optimal(*args, y, structure)
        moved += 1
    assert checked >= 30 and moved >= 5, (checked, moved)


def test_a_fallback_or_a_closed_form_is_not_checked():
    controller = dcts_spec.build_controller(BENCH)
    s = trajectory_states(controller, 1, seed=3)[0]
    result = controller.step(np.full(controller.n, np.nan), s.dq, s.tau_ext, s.ref)
    assert result.status == STATUS_NONFINITE_INPUT and result.optimal is None
    osc = dcts_spec.build_controller(BENCH, formulation="osc")
    assert osc.step(s.q, s.dq, s.tau_ext, s.ref).optimal is None


@pytest.mark.parametrize("seed", [5])
def test_random_states_of_the_bench_spec_are_at_their_optimum(seed):
    """Random states with bounds active (the golden tests' sampler): every "ok" answer certified."""
    controller = dcts_spec.build_controller(BENCH)
    flags = [controller.step(s.q, s.dq, s.tau_ext, s.ref).optimal
             for s in StateSampler(controller, seed).mixed(60, limit_fraction=0.3)]
    assert flags.count(True) >= 20 and False not in flags, flags
