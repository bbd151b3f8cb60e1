"""What dcts is doing now: steps that can take seconds announce themselves here.

Library code calls `phase("generating C")` before such a step. The command line installs a
reporter that prints the message on stderr (none with --quiet); without one (the Python API,
tests) phases are silent. A module-level reporter rather than a parameter: the steps sit deep
in codegen and simulation, and threading a callback through every signature between them
and the command line would touch every layer for one line of output.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

Reporter = Callable[[str], None]

_reporter: Reporter | None = None


def phase(message: str) -> None:
    """Say that a step that may take a while starts now."""
    if _reporter is not None:
        _reporter(message)


def building_controller(spec_name: str, formulation: str) -> None:
    """The CasADi model and control law: what the C bundle and the Python runtime both start with."""
    phase(f"building the symbolic model and the {formulation} control law of {spec_name}")


@contextmanager
def reporting(reporter: Reporter | None) -> Iterator[None]:
    """Send the phases announced within the block to `reporter` (None: silence them)."""
    global _reporter
    previous, _reporter = _reporter, reporter
    try:
        yield
    finally:
        _reporter = previous
