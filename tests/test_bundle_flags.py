"""The flags a bundle ships with are the ones `dcts bench` times: its Makefile's OPT, its CMake
Release flags and the bench harness all come from codegen/flags.py, and the harness links the
bundle's own objects instead of compiling the sources again."""

from __future__ import annotations

import re
import shlex
import subprocess
from pathlib import Path

import pytest

from command_line import MINIMAL
from dcts_spec.codegen import bench as bench_module
from dcts_spec.codegen import compile_bundle
from dcts_spec.codegen import CodegenError
from dcts_spec.codegen import bundle as bundle_module
from dcts_spec.codegen.flags import (C_WARNINGS, DAQP_OPTIMIZATION, FIRMWARE_CONTROLLER_OPTIMIZATION, HOST_OPTIMIZATION,
                                    QP_DATA_O0_FROM, QP_DATA_O1_FROM, QP_DATA_OPTIMIZATION, qp_data_optimization)


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
    # the same warnings, -Werror (CMake sets the standard itself); every bundle built in the tests
    # compiles under them, -Wmissing-prototypes and -Wdouble-promotion included
    warnings = re.search(r"^set\(WARNINGS (.*?)\)", cmake, re.M).group(1).split()
    assert warnings == [flag for flag in C_WARNINGS if not flag.startswith("-std=")]
    assert {"-Werror", "-Wmissing-prototypes", "-Wdouble-promotion"} <= set(warnings)
    # DAQP as its Python package builds it, by both (CMake built it with the Release flags alone)
    assert re.search(r"^DAQP_FLAGS = (.*)$", makefile, re.M).group(1).split() == list(DAQP_OPTIMIZATION)
    assert f'"$<$<CONFIG:Release>:{";".join(DAQP_OPTIMIZATION)}>"' in cmake


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


def _compile_commands(bundle: Path, *variables: str, target: str = "lib") -> dict[str, list[str]]:
    """The compiler command make would run for each of the controller's sources (dry run)."""
    done = subprocess.run(["make", "-n", "-B", target, *variables], cwd=bundle, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    commands = {}
    for line in done.stdout.splitlines():
        words = shlex.split(line)
        if "-c" in words and words[words.index("-c") + 1].startswith("minimal"):
            commands[words[words.index("-c") + 1]] = words
    return commands


def test_the_qp_data_get_o1_from_a_size_on(sources: Path) -> None:
    """The QP data, one unrolled function, are compiled with -O1 from QP_DATA_O1_FROM operations on
    (TALOS's 28 joints: 13 s and 0.5 GB instead of 36 s and 1 GB, for 1.4 % more instructions a
    step); smaller ones with QP_DATA_OPTIMIZATION, and the rest of the bundle with HOST_OPTIMIZATION. The
    Makefile says so for its own size, takes QP_DATA_OPT, and an OPT given on the command line applies to all."""
    assert qp_data_optimization(QP_DATA_O1_FROM - 1) == QP_DATA_OPTIMIZATION
    assert qp_data_optimization(QP_DATA_O1_FROM) == ("-O1",)
    assert qp_data_optimization(QP_DATA_O0_FROM - 1) == ("-O1",)
    assert qp_data_optimization(QP_DATA_O0_FROM) == ("-O0",)  # (-O1 took minutes from there)
    makefile = (sources / "Makefile").read_text()
    assert re.search(r"^QP_DATA_OPT \?= (.*)$", makefile, re.M).group(1).split() == list(QP_DATA_OPTIMIZATION)  # (small)
    commands = _compile_commands(sources, "QP_DATA_OPT=-O1")
    assert "-O1" in commands["minimal_casadi.c"] and "-O2" not in commands["minimal_casadi.c"]
    assert HOST_OPTIMIZATION[0] in commands["minimal.c"] and "-O1" not in commands["minimal.c"]
    commands = _compile_commands(sources, "QP_DATA_OPT=-O1", "OPT=-Os")
    assert all("-Os" in words and "-O1" not in words for words in commands.values())


def test_the_firmware_compiles_the_qp_data_as_the_host_does(sources: Path) -> None:
    """The Cortex-M7 build gives the QP data the same size-chosen flags (a 32-joint chain's QP data
    at the firmware's -O2 took arm-none-eabi-gcc more than 8 minutes and 1.5 GB); the last -O wins."""
    makefile = (sources / "Makefile").read_text()
    assert re.search(r"^ARM_QP_DATA_OPT \?= (.*)$", makefile, re.M).group(1).split() == list(QP_DATA_OPTIMIZATION)
    commands = _compile_commands(sources, "ARM_QP_DATA_OPT=-O0", target="firmware")
    optimization = {source: [w for w in words if w.startswith("-O")][-1] for source, words in commands.items()}
    assert optimization["minimal_casadi.c"] == "-O0"
    assert optimization["minimal.c"] == FIRMWARE_CONTROLLER_OPTIMIZATION[-1]  # (-Os, for flash)
    assert optimization["minimal_test.c"] == "-O2"


def _firmware_commands(bundle: Path, *variables: str) -> list[list[str]]:
    done = subprocess.run(["make", "-n", "-B", "firmware", *variables], cwd=bundle, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return [shlex.split(line) for line in done.stdout.splitlines() if line.startswith("arm-none-eabi-gcc")]


def test_the_firmware_links_daqp_for_plain_qps(sources: Path) -> None:
    """The Cortex-M7 images take DAQP's branch and bound, hierarchical, AVI, presolve and
    equality-elimination entry points from firmware/daqp_plain.c (-Wl,--wrap), so that the linker
    leaves that code out (on the bench spec DAQP's part of the flash went from 58.5 kB to 28.7 kB,
    the same answers bit for bit). Both images, the one measured and the golden test run on qemu,
    are linked so; DAQP's own objects are compiled as before (-O2: its fused operations differ at
    -Os), the controller's at -Os; ARM_DAQP_PLAIN=0 links all of DAQP."""
    wrapped = bundle_module.daqp_plain_wrapped()
    assert {"daqp_bnb", "daqp_bnb_prox", "daqp_hiqp", "daqp_solve_avi", "daqp_presolve", "daqp_eq_update",
            "daqp_eq_wanted"} <= set(wrapped)
    stub = (sources / "firmware" / "daqp_plain.c").read_text()
    assert all(f"__wrap_{name}(" in stub for name in wrapped)
    flag = "-Wl," + ",".join(f"--wrap={name}" for name in wrapped)
    commands = _firmware_commands(sources)
    links = {words[words.index("-o") + 1]: words for words in commands if "-c" not in words}
    assert set(links) == {"firmware/minimal_fw.elf", "firmware/minimal_test.elf"}
    for words in links.values():
        assert flag in words and any(w.endswith("/daqp_plain.o") for w in words)
        assert any(w.endswith("/daqp/bnb.o") for w in words)  # (DAQP's objects as they are: the linker drops the code)
    compiled = {words[words.index("-c") + 1]: words for words in commands if "-c" in words}
    assert "firmware/daqp_plain.c" in compiled
    daqp = [words for source, words in compiled.items() if source.startswith("daqp/src/")]
    assert daqp and all([w for w in words if w.startswith("-O")][-1] == "-O2" for words in daqp)
    plain_off = _firmware_commands(sources, "ARM_DAQP_PLAIN=0")
    assert not any(flag in words or "firmware/daqp_plain.c" in words for words in plain_off)
    with pytest.raises(CodegenError, match="eq_reduction"):  # (what daqp_plain.c's eq_* rely on)
        bundle_module.daqp_plain_wrap_flag({"eq_reduction": 0})


def test_the_flash_is_broken_down_by_part_from_the_linker_map(tmp_path: Path) -> None:
    """The image's flash per part (QP data, controller, DAQP, libm, libc, start-up; the rest is the
    linker's padding), from its map: the input sections kept in the sections loaded from flash, a
    long section name on a line of its own, the data's initial values (in flash) counted too."""
    from dcts_spec.codegen.build import flash_breakdown, flash_breakdown_text

    (tmp_path / "m_fw.map").write_text(
        "Discarded input sections\n\n .text.daqp_bnb 0x00000000 0x200 build/arm-1/daqp/bnb.o\n\n"
        "Linker script and memory map\n\n"
        ".text           0x00000000     0x2000\n"
        " *(.vectors)\n"
        " .vectors       0x00000000       0x40 build/arm-1/startup.o\n"
        " .text.m_casadi_f0.constprop.0\n"
        "                0x00000040      0x800 build/arm-1/m_casadi.o\n"
        "                0x00000041                m_casadi_f0\n"
        " .text.m_step   0x00000840      0x100 build/arm-1/m.o\n"
        " *fill*         0x00000940        0x4 \n"
        " .text.daqp_ldp 0x00000944      0x300 build/arm-1/daqp/daqp.o\n"
        " .text.__wrap_daqp_bnb\n"
        "                0x00000c44        0x4 build/arm-1/daqp_plain.o\n"
        " .text          0x00000c48       0x80 /usr/lib/arm-none-eabi/lib/thumb/libm.a(lib_a-s_sin.o)\n"
        " .text          0x00000cc8       0x20 /usr/lib/arm-none-eabi/lib/thumb/libc_nano.a(lib_a-memcpy.o)\n"
        ".data           0x20000000       0x68 load address 0x00002000\n"
        " .data          0x20000000       0x68 /usr/lib/arm-none-eabi/lib/thumb/libc_nano.a(lib_a-impure.o)\n"
        ".bss            0x20000068     0x1000\n"
        " .bss.ws        0x20000068     0x1000 build/arm-1/fw_main.o\n")
    parts = flash_breakdown(tmp_path / "m_fw.map", "m", 0xce8 + 0x68)
    assert parts == {"qp_data": 0x800, "controller": 0x100, "daqp": 0x304, "libm": 0x80, "libc": 0x20 + 0x68,
                     "startup": 0x40, "other": 4}
    assert flash_breakdown_text(parts).startswith("QP data 2048, controller 256, DAQP 772, libm 128")
    assert flash_breakdown(tmp_path / "none.map", "m", 1) is None


def test_outputs_are_checked_once_not_at_every_store(sources: Path) -> None:
    """The generated functions check their output pointers at their start (the wrapper passes them
    all): no `if (res[i]!=0)` before each of the thousands of stores (codegen/bundle.py,
    checks_at_the_ends)."""
    text = (sources / "minimal_casadi.c").read_text()
    assert "if (res[" not in text and re.search(r"^  if \(!res\[0\] \|\| !res\[1\].*\) return 1;$", text, re.M)
    assert re.search(r"^  res\[0\]\[0\]=a\d+;$", text, re.M)


@pytest.mark.parametrize("formulation", ["dcts", "projector"])
def test_qp_data_too_large_for_a_compiler_are_refused_before_any_c(
        formulation: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """QP data beyond MAX_QP_DATA_OPERATIONS (the projector baseline on a 21-joint human model:
    ~3 M operations, 74 MB of C, more memory than gcc had; dcts's unrolled QP data on a 48-joint serial
    chain: 620 k, before they took looped products)
    are refused before any C is written, with what to do instead (dcts, whose QP data are the
    smallest, only for another formulation); nothing is left at the output path."""
    monkeypatch.setattr(bundle_module, "MAX_QP_DATA_OPERATIONS", 100)
    out = tmp_path / "bundle"
    with pytest.raises(CodegenError) as refused:
        compile_bundle(MINIMAL, out, formulation=formulation, build=False)
    message = str(refused.value)
    assert "operations for its QP data" in message and "more than the 100" in message
    assert ("--formulation dcts" in message) == (formulation != "dcts") and "--runtime python" in message
    assert not out.exists()


def test_an_image_beyond_the_flash_is_reported_with_the_flash_it_needs(
        sources: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A firmware image larger than the 4 MB it is linked for (a 32-joint chain's) is a result, not a
    build failure: FirmwareTooLarge says how much flash it needs (the linker's largest overflow)."""
    from dcts_spec.codegen import build as build_module

    linker = ("ld: firmware/m_fw.elf section `.text' will not fit in region `FLASH'\n"
              "ld: region `FLASH' overflowed by 7347384 bytes\n"
              "ld: region `FLASH' overflowed by 7576976 bytes\ncollect2: error: ld returned 1 exit status")

    def failing_make(*args, **kwargs):
        raise CodegenError(f"firmware build failed (exit code 2):\n{linker}")

    monkeypatch.setattr(build_module.shutil, "which", lambda name: f"/usr/bin/{name}")
    monkeypatch.setattr(build_module, "make", failing_make)
    with pytest.raises(build_module.FirmwareTooLarge) as too_large:
        build_module.build_firmware(sources, {"name": "minimal"}, qemu=False)
    assert too_large.value.flash_bytes == 4 * 2**20 + 7576976
    assert "at least 11.8 MB of flash" in str(too_large.value)

    def other_failure(*args, **kwargs):
        raise CodegenError("firmware build failed (exit code 2):\nerror: unknown type name")

    monkeypatch.setattr(build_module, "make", other_failure)
    with pytest.raises(CodegenError) as failed:
        build_module.build_firmware(sources, {"name": "minimal"}, qemu=False)
    assert not isinstance(failed.value, build_module.FirmwareTooLarge)
