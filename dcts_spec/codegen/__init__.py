"""Firmware-grade C code for a compiled controller: generation, build, ctypes loader, benchmark.

    compile_c(spec, out_dir)   write and build the bundle, return the loaded C controller
    load_bundle(out_dir)       load a built bundle
"""

from __future__ import annotations

from pathlib import Path

from ..spec import Spec
from .build import BuildReport, compile_bundle, daqp_sources
from .bundle import CodegenError
from .loader import CompiledController, load_bundle


def compile_c(
    spec: Spec | str | Path,
    out_dir: str | Path,
    formulation: str | None = None,
    build: bool = True,
    **options,
) -> CompiledController | BuildReport:
    """Generate the C bundle of a spec (a Spec or a file) into out_dir.

    With build=True (the default) the host library is built and checked against the golden
    vectors, and the loaded CompiledController is returned (same `step` as the Python runtime).
    With build=False only the sources are written and the BuildReport is returned. Options are
    passed to `compile_bundle` (target, cc, daqp_src, warm_start, golden_count, qemu).
    """
    report = compile_bundle(spec, out_dir, formulation=formulation, build=build, **options)
    return load_bundle(report.directory) if build else report


__all__ = ["BuildReport", "CodegenError", "CompiledController", "compile_bundle", "compile_c", "daqp_sources",
           "load_bundle"]
