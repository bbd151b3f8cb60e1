"""The controller in the loop: anything with the Controller's `step` API, from Python or compiled C."""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import numpy as np

from ..controller import Controller, StepResult
from ..robot.model import Robot
from ..spec import Spec
from ..tasks import ReferenceInput

RUNTIMES = ("c", "python")


class Runtime(Protocol):
    """What the simulation needs from a compiled controller."""

    @property
    def n(self) -> int: ...

    @property
    def ref_layout(self) -> list[ReferenceInput]: ...

    @property
    def priorities(self) -> list[int]: ...

    def step(self, q: np.ndarray, dq: np.ndarray, tau_ext: np.ndarray | None = None,
             ref: np.ndarray | None = None) -> StepResult: ...


class RuntimeUnavailable(RuntimeError):
    """The requested runtime cannot run this simulation here (no C compiler, model mismatch in C)."""


def make_runtime(
    spec: Spec,
    kind: str = "c",
    formulation: str | None = None,
    robot: Robot | None = None,
    work_dir: str | Path | None = None,
) -> Runtime:
    """The spec's controller as a runtime.

    Args:
        spec: A validated spec.
        kind: "python" (CasADi function and QP solver called from Python) or "c" (the
            generated C bundle, built in `work_dir`).
        formulation: Overrides `controller.formulation`.
        robot: The controller's model; default: the spec's robot. A different robot (e.g.
            with scaled masses) is how model mismatch is simulated.
        work_dir: Where the C bundle is generated and built (kind "c" only).
    """
    if kind not in RUNTIMES:
        raise ValueError(f"unknown runtime {kind!r}; choose one of {', '.join(RUNTIMES)}")
    if kind == "python":
        return Controller(spec, robot or _spec_robot(spec), formulation)
    return _c_runtime(spec, formulation, robot, work_dir)


def _c_runtime(spec: Spec, formulation: str | None, robot: Robot | None, work_dir: str | Path | None) -> Runtime:
    from ..codegen import CodegenError, compile_c  # here: the Python runtime does not need it

    if robot is not None and robot.model != _spec_robot(spec).model:
        raise RuntimeUnavailable(
            "the C code generator compiles the spec's own robot, so it cannot simulate model_mismatch; "
            "run with --runtime python"
        )
    if work_dir is None:
        raise ValueError("the C runtime needs a work_dir to generate and build the bundle in")
    try:
        return compile_c(spec, Path(work_dir) / "bundle", formulation=formulation)
    except CodegenError as error:
        raise RuntimeUnavailable(f"cannot build the C runtime: {error}; run with --runtime python") from error


def _spec_robot(spec: Spec) -> Robot:
    from ..validate import validate_spec

    return validate_spec(spec).robot
