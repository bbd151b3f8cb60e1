"""Solving a formulation's QP: the lexicographic cascade and the checks that make a status a guarantee."""

from .bound_check import BOUND_TOLERANCE, BoundCheck, check_bounds, marginal_rows
from .lexicographic import Hint, Structure, solve_hinted, solve_lexicographic, unbounded_solution
from .optimality import final_optimal, to_optimum
from .sensitivity import rounding_spread
from .stage_qp import DAQP_SETTINGS

__all__ = ["BOUND_TOLERANCE", "DAQP_SETTINGS", "BoundCheck", "Hint", "Structure", "check_bounds", "final_optimal",
           "marginal_rows", "rounding_spread", "solve_hinted", "solve_lexicographic", "to_optimum", "unbounded_solution"]
