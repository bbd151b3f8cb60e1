"""Solving a formulation's QP: the lexicographic cascade and the checks that make a status a guarantee."""

from .lexicographic import (
    BOUND_TOLERANCE,
    DAQP_SETTINGS,
    BoundCheck,
    Hint,
    Structure,
    check_bounds,
    solve_hinted,
    solve_lexicographic,
    unbounded_solution,
)
from .optimality import final_optimal, to_optimum
from .sensitivity import rounding_spread

__all__ = ["BOUND_TOLERANCE", "DAQP_SETTINGS", "BoundCheck", "Hint", "Structure", "check_bounds", "final_optimal", "rounding_spread",
           "solve_hinted", "solve_lexicographic", "to_optimum", "unbounded_solution"]
