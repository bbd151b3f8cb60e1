"""Symbolic (CasADi SX) rigid-body dynamics and linear algebra for code generation."""

from dcts_spec.symbolic.dynamics import SymbolicRobot

__all__ = ["SymbolicRobot"]
