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

from collections.abc import Callable

import numpy as np

from .lexicographic import Structure, solve_lexicographic

ROUNDING = 1e-14  # relative change of each entry of the QP data, about what separates the runtimes


def _changed(values: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return values * (1.0 + ROUNDING * rng.standard_normal(values.shape))


def rounding_spread(H, f, A, lbx, ubx, lba, uba, structure: Structure, x: np.ndarray,
                    outputs: Callable[[np.ndarray], np.ndarray], samples: int, enough: float,
                    seed: int = 0) -> float:
    """The largest relative change of outputs(x) (|Δ| / max(1, |value|), entry by entry) over
    `samples` solves of the QP with every entry of its data changed by ~ROUNDING relative (H
    symmetrically; both bounds of a variable or a row by the same factor, so that a variable fixed
    stays fixed and an equality stays one); it stops as soon as a change exceeds `enough`, and is
    ∞ if a solve fails."""
    rng = np.random.default_rng(seed)
    reference = outputs(x)
    scale = np.maximum(1.0, np.abs(reference))
    spread = 0.0
    for _ in range(samples):
        E = ROUNDING * rng.standard_normal(H.shape)
        variables, rows = _changed(np.ones(lbx.size), rng), _changed(np.ones(lba.size), rng)
        changed = solve_lexicographic(H * (1.0 + 0.5 * (E + E.T)), _changed(f, rng), _changed(A, rng),
                                      lbx * variables, ubx * variables, lba * rows, uba * rows, structure)
        if changed is None:
            return np.inf
        spread = max(spread, float(np.max(np.abs(outputs(changed) - reference) / scale)))
        if spread > enough:
            break
    return spread
