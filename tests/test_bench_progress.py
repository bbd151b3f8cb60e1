"""`dcts bench` says what it is doing after the build: one phase line per stage. The stages'
work is replaced by stand-ins (timing it for real is `dcts bench`'s job), except the Python
runtime's loop and Pinocchio's terms timed from Python, which take milliseconds here."""

from __future__ import annotations

import contextlib
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from command_line import MINIMAL
from dcts_spec.codegen import bench as bench_module
from dcts_spec.codegen.states import State
from dcts_spec.phases import reporting
from dcts_spec.robot.resolve import resolve_robot
from dcts_spec.spec import load_spec


def test_bench_announces_each_stage(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    robot, _ = resolve_robot(load_spec(MINIMAL))
    zeros = np.zeros(robot.nv)
    state = State(robot.neutral_configuration(), zeros, zeros, np.zeros(0))
    controller = SimpleNamespace(robot=robot, problem=SimpleNamespace(levels=[]), ref_size=0,
                                 step=lambda *args: None, reset=lambda: None)
    manifest = {"name": "minimal", "formulation": "dcts", "nq": robot.nv, "nref": 0, "nx": 0, "na": 0,
                "nlevels": 2, "workspace_bytes_host": 0, "qp_data_instructions": 0, "qp_data_looped_products": False,
                "host": {"compiler": "cc", "build_dir": "build"}}
    c_times = {"step": {"median_us": 1.0}}
    stand_ins = {
        "make_controller": lambda spec, formulation: controller,
        "compile_bundle": lambda spec, directory, formulation, build_timeout: SimpleNamespace(manifest=manifest,
                                                                                              cost=None),
        "load_bundle": lambda directory: contextlib.nullcontext(SimpleNamespace(step=lambda *args: None)),
        "trajectory_states": lambda controller, n, seed, step: [state] * n,
        "StateSampler": lambda controller, seed: SimpleNamespace(mixed=lambda n, limit_fraction: [state] * n),
        "build_c_harness": lambda *args: tmp_path / "harness",
        "run_c_harness": lambda *args, **kwargs: c_times,
        "run_c_once": lambda *args, **kwargs: b"",
        "c_times": lambda runs, count: c_times,
        "callgrind_instructions": lambda *args: 1.0,
        "object_sizes": lambda *args: {},
        "c_source_bytes": lambda *args: 0,
        "build_firmware": lambda *args, **kwargs: {"flash_bytes": 1},
        "_cmeel_prefix": lambda: None,  # Pinocchio timed from Python: no C++ harness to build
    }
    for name, stand_in in stand_ins.items():
        monkeypatch.setattr(bench_module, name, stand_in)

    said: list[str] = []
    with reporting(said.append):
        result = bench_module.bench(MINIMAL, states=4, python_states=2, callgrind_states=3)

    expected = ["generating 4 closed-loop states", "sampling 4 independent states",
                "timing the C step", "timing the Python runtime on 2 states"]
    if shutil.which("valgrind"):
        expected.append("counting the instructions of a step with callgrind (3 states)")
    assert len(said) == len(expected), said
    assert all(line.startswith(start) for line, start in zip(said, expected)), said
    assert "alternately with Pinocchio's dynamics terms" in said[2]  # (the ratio's two timings, in turn)
    assert not any("building" in line for line in said)
    assert result["python_step"]["states"] == 2 and result["pinocchio_terms"]["how"].startswith("timed from Python")
