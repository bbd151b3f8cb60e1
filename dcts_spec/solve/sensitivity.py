"""Is a lexicographic answer determined by its QP data? The same solve on copies of the data
changed at the level of their rounding.

The C bundle evaluates the QP data in another order of operations than CasADi's virtual
machine: the two runtimes' data differ by ~1e-15–1e-13 relative. Where the cascade's decisions
are degenerate (after a relaxation or a bend, the next stages see a thin feasible set, and DAQP
solves a stage or calls it infeasible depending on the last bits: docs/formulations.md), such
changes move the answer by far more than any tolerance, in either runtime. On such a state no
runtime can be compared with another, only on what both must guarantee (status, limits): the
golden-vector test (codegen/bundle.py) measures this spread for every vector it compares.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from .bound_check import check_bounds
from .lexicographic import Structure, solve_lexicographic
from .optimality import to_optimum

ROUNDING = 1e-14  # relative change of each entry of the QP data, about what separates the runtimes


def _changed(values: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return values * (1.0 + ROUNDING * rng.standard_normal(values.shape))


def rounding_spread(H, f, A, lbx, ubx, lba, uba, structure: Structure, x: np.ndarray,
                    outputs: Callable[[np.ndarray], Sequence[np.ndarray]], samples: int, enough: float,
                    seed: int = 0, acceleration_map: np.ndarray | None = None,
                    bound_shift: np.ndarray | None = None) -> np.ndarray:
    """For each group of outputs(x) (e.g. the torques, the QP solution), the largest relative
    change (|Δ| / max(1, |value|), entry by entry) over `samples` solves of the QP with every entry
    of its data changed by ~ROUNDING relative (H symmetrically; both bounds of a variable or a row
    by the same factor, so that a variable fixed stays fixed and an equality stays one). Sampling
    stops as soon as every group's change exceeds `enough`; a group's spread is ∞ if a solve fails.
    Groups, because a level that no free direction can move leaves its own variables undetermined
    and the torques not (a degenerate level of a 7-joint arm: x moved by 1e2, τ by 2e-8).
    `acceleration_map`: as for `solve_lexicographic` (changed like the data); `bound_shift`: the
    bound rows' constant part, as for `check_bounds` (None: 0, the rows' bounds are in their units)."""
    rng = np.random.default_rng(seed)
    shift = np.zeros(len(structure.bound_rows)) if bound_shift is None else bound_shift
    reference = [np.asarray(group, dtype=float) for group in outputs(x)]
    scales = [np.maximum(1.0, np.abs(group)) for group in reference]
    spread = np.zeros(len(reference))
    for _ in range(samples):
        E = ROUNDING * rng.standard_normal(H.shape)
        variables, rows = _changed(np.ones(lbx.size), rng), _changed(np.ones(lba.size), rng)
        data = (H * (1.0 + 0.5 * (E + E.T)), _changed(f, rng), _changed(A, rng), lbx * variables, ubx * variables,
                lba * rows, uba * rows)
        changed = solve_lexicographic(*data, structure,
                                      None if acceleration_map is None else _changed(acceleration_map, rng))
        if changed is None:
            return np.full(len(reference), np.inf)
        if check_bounds(structure.bound_rows, data[2], data[5], data[6], changed, shift).holds:
            changed, _ = to_optimum(*data, changed, structure)  # (as the step takes an "ok" answer)
        for i, (group, value, scale) in enumerate(zip(outputs(changed), reference, scales)):
            if group.size:
                spread[i] = max(spread[i], float(np.max(np.abs(group - value) / scale)))
        if (spread > enough).all():
            break
    return spread
