"""The spec language: pydantic models, located YAML loading, JSON Schema."""

from .document import Spec
from .errors import Diagnostic, SpecError
from .loader import check_structure, load_spec, load_spec_text

__all__ = ["Diagnostic", "Spec", "SpecError", "check_structure", "load_spec", "load_spec_text"]
