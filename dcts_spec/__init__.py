"""dcts: declare prioritized torque control of a redundant arm in YAML; validate, compile, simulate."""

from .codegen import compile_c
from .controller import Controller, StepResult, build_controller
from .spec import Spec, SpecError, load_spec

__all__ = ["Controller", "Spec", "SpecError", "StepResult", "build_controller", "compile_c", "load_spec"]
