"""The lowest level's optimality, checked from outside the solver.

Both runtimes check the final objective's optimum (½xᵀHx + fᵀx over what the levels leave free)
at every "ok" answer, and reach it where the cascade missed it (dcts_spec/solve/optimality.py).
This script is the independent check of that, with scipy's NNLS and its own active set: for
every "ok" step of the Python runtime, on closed-loop and random states, the KKT residual of
that objective at the answer, with the levels' variables held at the answer's values: the
gradient over the free variables fitted by a nonnegative combination of the outward normals of
the rows active there (NNLS), relative to the gradient's scale (max(1, ‖(Hx)_free‖, ‖f_free‖)). An optimum has ~1e-10; docs/formulations.md ("The lowest
level's optimum, checked at the answer and reached from it") has what it found.

    python scripts/optimality_scan.py specs/bench_iiwa14.yaml             # 300 + 300 states
    python scripts/optimality_scan.py SPEC --states 1000 --worst 10
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.optimize import nnls

import dcts_spec
from dcts_spec.codegen.states import StateSampler, trajectory_states

ACTIVE = 1e-9  # a row is active within this much of a bound (relative to max(1, |bound|)), or beyond it


def kkt_residual(H, f, A, lba, uba, free: np.ndarray, point: np.ndarray) -> tuple[float, float]:
    """(min ‖∇ + Σ μ n‖ over μ ≥ 0, ‖∇‖): ∇ the gradient of ½xᵀHx + fᵀx over the `free`
    variables at `point`, n the outward normals of the rows active there."""
    gradient, value = (H @ point + f)[free], A @ point
    # (or beyond it: an answer may cross a row by its check's tolerance, and is then at it)
    low = value - lba <= ACTIVE * np.maximum(1.0, np.abs(lba))
    high = uba - value <= ACTIVE * np.maximum(1.0, np.abs(uba))
    normals = np.vstack([-A[low][:, free], A[high][:, free]]).T
    residual = nnls(normals, -gradient)[1] if normals.size else float(np.linalg.norm(gradient))
    return float(residual), float(np.linalg.norm(gradient))


def scan(spec: str, states: int, seed: int = 5) -> list[tuple[float, int]]:
    """(relative residual, state index) of every "ok" step with free variables, worst first."""
    controller = dcts_spec.build_controller(spec)
    levels = controller._structure.levels_above[-1]
    samples = trajectory_states(controller, states, seed=seed) + \
        StateSampler(controller, seed + 1).mixed(states, limit_fraction=0.15)
    found = []
    for index, s in enumerate(samples):
        ref = s.ref if controller.ref_size else None
        result = controller.step(s.q, s.dq, s.tau_ext, ref)
        if result.status != 0 or not controller.nx:
            continue
        data = controller.evaluate_data(s.q, s.dq, s.tau_ext, ref)
        H, f, A = data["H"], data["f"].ravel(), data["A"]
        free = np.setdiff1d(np.arange(result.x.size), levels)
        if not free.size:
            continue
        residual, _ = kkt_residual(H, f, A, data["lba"].ravel(), data["uba"].ravel(), free, result.x)
        scale = max(1.0, np.linalg.norm((H @ result.x)[free]), np.linalg.norm(f[free]))
        found.append((residual / scale, index))
    return sorted(found, reverse=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("spec")
    parser.add_argument("--states", type=int, default=300, help="closed-loop states, and as many random ones")
    parser.add_argument("--worst", type=int, default=8, help="how many of the worst to list")
    args = parser.parse_args()
    found = scan(args.spec, args.states)
    print(f"{args.spec}: {len(found)} 'ok' states checked; worst relative KKT residuals (state):",
          ", ".join(f"{r:.2g} ({i})" for r, i in found[: args.worst]))
    print(f"above 1e-6: {sum(r > 1e-6 for r, _ in found)}, above 1e-4: {sum(r > 1e-4 for r, _ in found)}")


if __name__ == "__main__":
    main()
