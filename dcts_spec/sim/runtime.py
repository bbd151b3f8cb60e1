"""The controller in the loop: anything with the Controller's `step` API, from Python or compiled C."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from ..choices import RUNTIMES
from ..controller import Controller, StepResult
from ..robot.model import Robot
from ..spec import Spec
from ..formulations.parameters import ParameterLayout
from ..tasks import ReferenceInput

if TYPE_CHECKING:
    from ..codegen import BundleCache


class Runtime(Protocol):
    """What the simulation needs from a compiled controller.

    A runtime may also have `step_into(q, dq, tau_ext, ref, tau, ddq, scaling) -> status`
    (the C runtime does), which writes its outputs into the given arrays; the simulation then
    uses it instead of `step`. `param_layout` and `set_params` are needed only by a scenario
    that schedules run-time parameters.
    """

    @property
    def n(self) -> int: ...

    @property
    def ref_layout(self) -> list[ReferenceInput]: ...

    @property
    def priorities(self) -> list[int]: ...

    @property
    def nx(self) -> int: ...  # QP variables: 0 for a closed form (osc, projector), which checks no bound

    @property
    def param_layout(self) -> ParameterLayout: ...

    def set_params(self, values: dict | np.ndarray) -> None: ...

    def step(self, q: np.ndarray, dq: np.ndarray, tau_ext: np.ndarray | None = None,
             ref: np.ndarray | None = None) -> StepResult: ...


class RuntimeUnavailable(RuntimeError):
    """The requested runtime cannot run this simulation here (e.g. no C compiler)."""


def make_runtime(
    spec: Spec,
    kind: str = "c",
    formulation: str | None = None,
    robot: Robot | None = None,
    work_dir: str | Path | None = None,
    *,
    cache: bool | BundleCache = True,
    model_changes: dict | None = None,
) -> Runtime:
    """The spec's controller as a runtime.

    Args:
        spec: A validated spec.
        kind: "python" (CasADi function and QP solver called from Python) or "c" (the
            generated C bundle).
        formulation: Overrides `controller.formulation`.
        robot: The controller's model; default: the spec's robot. A different robot (e.g.
            with scaled masses, `sim.mismatch.scaled_robot`) is how model mismatch is
            simulated; the C bundle is then generated for that model.
        work_dir: Where the C bundle is generated and built when the cache is not used.
        cache: C only. True (default): load the bundle from the bundle cache
            (`codegen.BundleCache`: `$DCTS_CACHE_DIR` or ~/.cache/dcts/bundles), building it
            there when it is missing; a BundleCache: that cache; False: build a fresh bundle in
            `work_dir`.
        model_changes: How `robot` differs from the spec's (e.g. {"mass_scale": 1.2}); recorded
            in the C bundle's manifest and header.
    """
    if kind not in RUNTIMES:
        raise ValueError(f"unknown runtime {kind!r}; choose one of {', '.join(RUNTIMES)}")
    if kind == "python":
        return Controller(spec, robot or _spec_robot(spec), formulation)
    return _c_runtime(spec, formulation, robot, work_dir, cache, model_changes)


def _c_runtime(spec: Spec, formulation: str | None, robot: Robot | None, work_dir: str | Path | None,
               cache: bool | BundleCache, model_changes: dict | None) -> Runtime:
    from ..codegen import BundleCache, CodegenError, compile_c  # here: the Python runtime does not need them

    if not cache and work_dir is None:
        raise ValueError("the C runtime needs a work_dir to generate and build the bundle in (or the cache)")
    try:
        if not cache:
            return compile_c(spec, Path(work_dir) / "bundle", formulation=formulation, robot=robot,
                             model_changes=model_changes)
        bundles = cache if isinstance(cache, BundleCache) else BundleCache()
        return bundles.load(spec, formulation, robot=robot, model_changes=model_changes)
    except CodegenError as error:
        raise RuntimeUnavailable(f"cannot build the C runtime: {error}; run with --runtime python") from error


def _spec_robot(spec: Spec) -> Robot:
    from ..validate import validate_spec

    return validate_spec(spec).robot
