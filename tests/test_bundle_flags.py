"""The flags a bundle ships with are the ones `dcts bench` times: its Makefile's OPT, its CMake
Release flags and the bench harness all come from codegen/flags.py, and the harness links the
bundle's own objects instead of compiling the sources again."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from command_line import MINIMAL
from dcts_spec.codegen import bench as bench_module
from dcts_spec.codegen import compile_bundle
from dcts_spec.codegen.flags import C_WARNINGS, HOST_OPTIMIZATION


@pytest.fixture(scope="module")
def sources(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("flags") / "bundle"
    compile_bundle(MINIMAL, out, build=False)
    return out


def test_makefile_and_cmake_ship_the_flags(sources: Path) -> None:
    makefile = (sources / "Makefile").read_text()
    assert re.search(r"^OPT \?= (.*)$", makefile, re.M).group(1).split() == list(HOST_OPTIMIZATION)
    assert re.search(r"^WARN = (.*)$", makefile, re.M).group(1).split() == list(C_WARNINGS)
    cmake = (sources / "CMakeLists.txt").read_text()
    assert shlex.split(re.search(r'set\(CMAKE_C_FLAGS_RELEASE (".*")\)', cmake).group(1)) == [" ".join(HOST_OPTIMIZATION)]
    assert "-march=native" not in HOST_OPTIMIZATION and "-ffast-math" not in HOST_OPTIMIZATION


def test_bench_harness_builds_like_the_makefile(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    bundle = tmp_path / "bundle"
    (bundle / "build" / "x" / "daqp").mkdir(parents=True)
    (bundle / "build" / "x" / "daqp" / "api.o").write_bytes(b"")
    manifest = {"name": "arm", "nx": 3, "casadi_work": {"qp_data": [1, 1, 1, 1], "fallback": [1, 1, 1, 1]},
                "host": {"compiler": "clang -fcolor-diagnostics", "build_dir": "build/x"}}
    monkeypatch.setattr(bench_module, "casadi_work_lengths", lambda work: {"iw": 1, "w": 1, "arg": 1, "res": 1})
    commands: list[list[str]] = []
    monkeypatch.setattr(bench_module, "run", lambda command, *args, **kwargs: commands.append(command))
    bench_module.build_c_harness(bundle, manifest, tmp_path)
    (command,) = commands
    objects = bundle / "build" / "x"
    assert command[:2] == ["clang", "-fcolor-diagnostics"]  # the compiler the bundle was built with
    assert command[2: 2 + len(C_WARNINGS) + len(HOST_OPTIMIZATION)] == [*C_WARNINGS, *HOST_OPTIMIZATION]
    assert str(objects / "arm.o") in command and str(objects / "arm_casadi.o") in command
    assert str(objects / "daqp" / "api.o") in command
    assert not any(word.endswith(("arm.c", "arm_casadi.c")) for word in command)  # no second build of the sources
