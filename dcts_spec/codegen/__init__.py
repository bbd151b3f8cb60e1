"""Firmware-grade C code for a compiled controller: generation, build, ctypes loader, benchmark.

    compile_c(spec, out_dir)   write and build the bundle, return the loaded C controller
    load_bundle(out_dir)       load a built bundle
    BundleCache()              built bundles, reused across runs (`dcts simulate`, `dcts compare`)
    compiled_controller(spec)  the spec's C controller from that cache: Python at firmware speed
"""

from __future__ import annotations

from pathlib import Path

from ..robot.model import Robot
from ..spec import Spec
from .build import BuildReport, GoldenMismatch, compile_bundle, daqp_sources
from .bundle import CodegenError
from .cache import BundleCache, default_cache_dir
from .loader import CompiledController, load_bundle
from .model import model_digest


def compile_c(
    spec: Spec | str | Path,
    out_dir: str | Path,
    formulation: str | None = None,
    build: bool = True,
    robot: Robot | None = None,
    model_changes: dict | None = None,
    **options,
) -> CompiledController | BuildReport:
    """Generate the C bundle of a spec (a Spec or a file) into out_dir.

    With build=True (the default) the host library is built and checked against the golden
    vectors, and the loaded CompiledController is returned (same `step` as the Python runtime).
    With build=False only the sources are written and the BuildReport is returned.

    `robot` compiles the controller for another model than the spec's robot (model mismatch,
    e.g. `sim.mismatch.scaled_robot(robot, 1.2)`), `model_changes` says how it differs (e.g.
    {"mass_scale": 1.2}); the manifest and the header record it. Other options are passed to
    `compile_bundle` (target, cc, daqp_src, warm_start, golden_count, qemu).
    """
    report = compile_bundle(spec, out_dir, formulation=formulation, build=build, robot=robot,
                            model_changes=model_changes, **options)
    return load_bundle(report.directory) if build else report


def compiled_controller(spec: Spec | str | Path, formulation: str | None = None,
                        cache: BundleCache | None = None) -> CompiledController:
    """The spec's generated C controller, for Python programs that step it in a loop: built into the
    bundle cache on first use (a few seconds; `cache`: default `BundleCache()`, i.e.
    $DCTS_CACHE_DIR or ~/.cache/dcts/bundles), loaded from it afterwards. It has the same `step`
    and `StepResult` as `build_controller`'s Python runtime, and the same answers (the golden
    vectors of every build check that), at the firmware's cost plus a ctypes call: ~10 µs a step
    on the bench spec, where the Python runtime, which runs the lexicographic cascade in the
    interpreter as the independent reference of the C, takes ~0.7 ms."""
    return (cache or BundleCache()).load(spec, formulation)


__all__ = ["BuildReport", "BundleCache", "CodegenError", "CompiledController", "GoldenMismatch", "compile_bundle",
           "compile_c", "compiled_controller", "daqp_sources", "default_cache_dir", "load_bundle", "model_digest"]
