"""dcts: declare prioritized torque control of a redundant arm in YAML; validate, compile, simulate."""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

from .spec import Spec, SpecError, load_spec

if TYPE_CHECKING:
    from .codegen import compile_c, compiled_controller
    from .analysis.simulate import simulate
    from .controller import Controller, StepResult, build_controller
    from .validate import validate_spec

# Names whose modules import CasADi and Pinocchio (~0.7 s): loaded on first use (PEP 562), so
# that `import dcts_spec`, `dcts --help` and rejecting a broken spec stay fast.
_LAZY = {"compile_c": ".codegen", "compiled_controller": ".codegen", "Controller": ".controller", "StepResult": ".controller",
         "build_controller": ".controller", "simulate": ".analysis.simulate", "validate_spec": ".validate"}

__all__ = ["Controller", "Spec", "SpecError", "StepResult", "build_controller", "compile_c", "compiled_controller",
           "load_spec", "simulate", "validate_spec"]


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(_LAZY[name], __name__), name)
    globals()[name] = value  # later lookups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
