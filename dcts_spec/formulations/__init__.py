"""Formulations: each turns the same tasks and limits into a QP or a closed form."""

from __future__ import annotations

from collections.abc import Callable

from .dcts import dcts
from .osc import osc
from .problem import ControlProblem, build_problem
from .projector import projector
from .qp import QP, Affine, ControlLaw
from .qp_md import qp_md
from .qp_mt import qp_mt

FORMULATIONS: dict[str, Callable[[ControlProblem], ControlLaw]] = {
    "dcts": dcts,
    "osc": osc,
    "projector": projector,
    "qp_mt": qp_mt,
    "qp_md": qp_md,
}

__all__ = ["FORMULATIONS", "QP", "Affine", "ControlLaw", "ControlProblem", "build_problem"]
