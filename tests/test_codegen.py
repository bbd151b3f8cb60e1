"""The generated C bundle: build, golden vectors, agreement with the Python runtime, safety, failures.

The fast core (default) builds two bundles; the slow tests (-m slow) add sanitizers, valgrind,
every formulation, DAQP from source, CMake, and the Cortex-M7 build on qemu.
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from dcts_spec.cli import app
from dcts_spec.codegen import CodegenError, compile_bundle, compile_c, load_bundle
from dcts_spec.codegen.states import StateSampler
from dcts_spec.controller import (
    STATUS_INVALID_OUTPUT,
    STATUS_LIMITS_RELAXED,
    STATUS_NONFINITE_INPUT,
    build_controller,
)
from dcts_spec.spec import SpecError

ROOT = Path(__file__).resolve().parents[1]
MINIMAL = ROOT / "specs" / "minimal.yaml"
BENCH = ROOT / "specs" / "bench_iiwa14.yaml"

# Three priority levels on the iiwa14 with joint limits (the relaxation is in play near them).
THREE_LEVELS = """\
version: 1
name: three_levels
robot: {model: iiwa14}
limits:
  joint_position: {min: [-165, -115, -165, -115, -165, -115, -170], max: [165, 115, 165, 115, 165, 115, 170], unit: deg}
  joint_velocity: {max: [100, 110, 100, 130, 130, 180, 180], unit: deg/s}
  joint_torque: {max: 100}
tasks:
  - {name: pos, type: position, frame: tool, priority: 1, gains: {kp: 100, kd: 20}, reference: {input: true}}
  - {name: ori, type: orientation, frame: tool, axes: [rx, ry], priority: 2, gains: {kp: 50, kd: 14},
     reference: {rpy: [180, 0, 0], unit: deg}}
  - {name: post, type: joint, priority: 3, gains: {kp: 10, kd: 6}, reference: {q: [0, 0.5, 0, -1, 0, 1, 0]}}
"""


def relative_difference(a: np.ndarray, b: np.ndarray) -> float:
    if a.size == 0:
        return 0.0
    return float(np.max(np.abs(a - b) / np.maximum(1.0, np.abs(a))))


@pytest.fixture(scope="module")
def three_levels_spec(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("specs") / "three_levels.yaml"
    path.write_text(THREE_LEVELS)
    return path


@pytest.fixture(scope="module")
def built(three_levels_spec, tmp_path_factory):
    """The three-level spec compiled and built once: (bundle directory, loaded C controller)."""
    out = tmp_path_factory.mktemp("bundles") / "three_levels"
    compiled = compile_c(three_levels_spec, out)
    yield out, compiled
    compiled.close()


# -- the bundle ------------------------------------------------------------------------------------


def test_bundle_is_complete_and_self_describing(built, three_levels_spec):
    out, compiled = built
    name = "three_levels"
    for f in (f"{name}.h", f"{name}.c", f"{name}_casadi.c", f"{name}_casadi.h", f"{name}_golden.c",
              f"{name}_golden.h", f"{name}_test.c", "Makefile", "CMakeLists.txt", "manifest.json", "golden.json",
              "spec.yaml", "firmware/startup.c", "firmware/mps2_an500.ld", f"lib{name}.so"):
        assert (out / f).is_file(), f
    assert not list(out.parent.glob(".three_levels.*")), "no temporary directory left next to the bundle"
    manifest = json.loads((out / "manifest.json").read_text())
    digest = hashlib.sha256(three_levels_spec.read_bytes()).hexdigest()
    assert manifest["spec_sha256"] == digest and manifest["built"]
    assert manifest["golden"]["count"] >= 100
    assert set(manifest["golden"]["statuses"]) >= {str(STATUS_NONFINITE_INPUT), "0"}

    header = (out / f"{name}.h").read_text()
    nq, nref, nx, na, levels = (manifest[k] for k in ("nq", "nref", "nx", "na", "nlevels"))
    for macro, value in (("NQ", nq), ("NREF", nref), ("NX", nx), ("NA", na), ("NLEVELS", levels)):
        assert re.search(rf"#define THREE_LEVELS_{macro} {value}\b", header), macro
    assert f'#define THREE_LEVELS_SPEC_SHA256 "{digest}"' in header
    assert "#define THREE_LEVELS_VERSION" in header and "#define THREE_LEVELS_WORKSPACE_BYTES" in header
    assert "#define THREE_LEVELS_STATUS_LIMITS_RELAXED 1" in header
    assert "ref[0..2]" in header and "#define THREE_LEVELS_REF_POS_POSITION 0" in header  # the layout
    assert "malloc" in header  # what init allocates is documented
    assert compiled.workspace_bytes == manifest["workspace_bytes_host"]


def test_golden_vectors_replay(built):
    """The C test program replays the golden vectors (exit code 0) and counts heap calls."""
    out, _ = built
    done = subprocess.run(["make", "-s", "check", "heapcheck"], cwd=out, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "PASS" in done.stdout
    heap = re.search(r"heap: init (\d+) calls (\d+) bytes; steps (\d+) calls", done.stdout)
    assert heap and int(heap.group(2)) > 0 and int(heap.group(3)) == 0, "the steps must not allocate"


def test_golden_test_fails_on_mismatch(built, tmp_path):
    """The replay is a real check: corrupt one golden torque and it exits non-zero."""
    out, _ = built
    copy = tmp_path / "bundle"
    shutil.copytree(out, copy, ignore=shutil.ignore_patterns("build", "*.so", "*_test", "*_test_heap"))
    golden = copy / "three_levels_golden.c"
    text = golden.read_text()
    start = text.index("three_levels_golden_tau[")
    first = re.compile(r"\{(-?0x[0-9a-f.p+-]+)").search(text, start)
    golden.write_text(text[: first.start(1)] + "0x1.0p+5" + text[first.end(1):])
    done = subprocess.run(["make", "-s", "check"], cwd=copy, capture_output=True, text=True)
    assert done.returncode != 0 and "mismatch" in done.stdout


def test_c_agrees_with_python_on_1000_states(built, three_levels_spec):
    _, compiled = built
    controller = build_controller(three_levels_spec)
    compiled.reset()
    states = StateSampler(controller, seed=11).mixed(1000, limit_fraction=0.2)
    worst, statuses = 0.0, {}
    for s in states:
        a = controller.step(s.q, s.dq, s.tau_ext, s.ref)
        b = compiled.step(s.q, s.dq, s.tau_ext, s.ref)
        assert a.status == b.status
        statuses[a.status] = statuses.get(a.status, 0) + 1
        for u, v in ((a.tau, b.tau), (a.ddq, b.ddq), (a.scaling, b.scaling), (a.x, b.x)):
            assert u.shape == v.shape
            worst = max(worst, relative_difference(u, v))
    assert worst <= 1e-8, worst
    assert statuses.get(0, 0) > 900


def test_same_surface_as_python_runtime(built, three_levels_spec):
    _, compiled = built
    controller = build_controller(three_levels_spec)
    assert compiled.n == controller.n and compiled.nx == controller.nx and compiled.na == controller.na
    assert compiled.priorities == controller.priorities
    assert compiled.ref_layout == controller.ref_layout
    with pytest.raises(ValueError):
        compiled.step(np.zeros(7), np.zeros(7))  # this controller needs ref
    with pytest.raises(ValueError):
        compiled.step(np.zeros(6), np.zeros(7), ref=np.zeros(3))


@pytest.mark.parametrize("where", ["q", "dq", "tau_ext", "ref", "q_inf", "all"])
def test_nonfinite_inputs_give_the_fallback(built, three_levels_spec, where):
    _, compiled = built
    controller = build_controller(three_levels_spec)
    sampler = StateSampler(controller, seed=3)
    s = sampler.random()
    q, dq, tau_ext, ref = (v.copy() for v in s.as_tuple())
    compiled.reset()
    first = compiled.step(q, dq, tau_ext, ref)  # a finite q first: the fallback uses its gravity
    assert first.ok
    q2, dq2 = sampler.random_q(), sampler.random_dq()
    {"q": lambda: q2.__setitem__(0, np.nan), "dq": lambda: dq2.__setitem__(3, np.inf),
     "tau_ext": lambda: tau_ext.__setitem__(6, np.nan), "ref": lambda: ref.__setitem__(1, -np.inf),
     "q_inf": lambda: q2.__setitem__(2, np.inf),
     "all": lambda: (q2.fill(np.nan), dq2.fill(np.nan), tau_ext.fill(np.inf), ref.fill(np.nan))}[where]()
    result = compiled.step(q2, dq2, tau_ext, ref)
    assert result.status == STATUS_NONFINITE_INPUT
    assert np.all(np.isfinite(result.tau)) and np.all(np.abs(result.tau) <= compiled.tau_max)
    assert result.x.size == 0 and not result.ddq.any()
    # exactly the Python runtime's fallback, with the same history
    controller._last_gravity = np.zeros(controller.n)
    controller.step(q, dq, tau_ext if where != "tau_ext" and where != "all" else s.tau_ext, s.ref)
    expected = controller.step(q2, dq2, tau_ext, ref)
    assert expected.status == STATUS_NONFINITE_INPUT
    np.testing.assert_allclose(result.tau, expected.tau, rtol=1e-12, atol=1e-12)


def test_torque_always_within_limits(built, three_levels_spec):
    """Extreme states (limits hit hard, huge external torques): finite torque within the limits."""
    _, compiled = built
    controller = build_controller(three_levels_spec)
    sampler = StateSampler(controller, seed=5)
    compiled.reset()
    for _ in range(200):
        s = sampler.heavy_load() if sampler.rng.random() < 0.5 else sampler.near_limit()
        s.tau_ext *= 3.0
        r = compiled.step(s.q, s.dq, s.tau_ext, s.ref)
        assert np.all(np.isfinite(r.tau)) and np.all(np.abs(r.tau) <= compiled.tau_max)
        if r.status in (STATUS_INVALID_OUTPUT,):
            assert not r.ddq.any()


def test_closed_form_formulation(tmp_path):
    """A closed form (osc: no QP) builds without DAQP and matches the Python runtime."""
    out = tmp_path / "osc"
    report = compile_bundle(MINIMAL, out, formulation="osc")
    assert report.manifest["nx"] == 0 and report.manifest["host"]["init_heap_bytes"] == 0
    assert "NEEDS_DAQP = 0" in (out / "Makefile").read_text()
    with load_bundle(out) as compiled:
        controller = build_controller(MINIMAL, formulation="osc")
        for s in StateSampler(controller, seed=2).mixed(100):
            a, b = controller.step(s.q, s.dq, s.tau_ext), compiled.step(s.q, s.dq, s.tau_ext)
            assert a.status == b.status and relative_difference(a.tau, b.tau) <= 1e-8
            assert b.x.size == 0


# -- atomic output ------------------------------------------------------------------------------


def test_no_build_writes_sources_only(tmp_path):
    out = tmp_path / "src_only"
    report = compile_bundle(MINIMAL, out, build=False)
    assert not report.built
    assert (out / "minimal.c").is_file() and (out / "minimal_casadi.c").is_file() and (out / "Makefile").is_file()
    assert not (out / "build").exists() and not list(out.glob("*.so")) and not (out / "minimal_test").exists()
    assert json.loads((out / "manifest.json").read_text())["built"] is False


def test_broken_spec_leaves_nothing(tmp_path):
    broken = tmp_path / "broken.yaml"
    broken.write_text(MINIMAL.read_text().replace("priority: 1", "priority: 0"))
    out = tmp_path / "out" / "bundle"
    with pytest.raises(SpecError):
        compile_bundle(broken, out)
    assert not (tmp_path / "out").exists()


def test_failing_build_leaves_nothing_and_keeps_the_old_bundle(tmp_path):
    out = tmp_path / "bundle"
    compile_bundle(MINIMAL, out, build=False)
    before = (out / "manifest.json").read_text()
    with pytest.raises(CodegenError, match="host build failed"):
        compile_bundle(MINIMAL, out, cc="false")  # the compiler fails
    assert (out / "manifest.json").read_text() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bundle"]  # no temporary directory left
    fresh = tmp_path / "new" / "deeper"
    with pytest.raises(CodegenError):
        compile_bundle(MINIMAL, fresh, cc="false")
    assert not (tmp_path / "new").exists()  # parents created for it are removed too


def test_invalid_output_paths(tmp_path):
    a_file = tmp_path / "file.txt"
    a_file.write_text("x")
    with pytest.raises(CodegenError):
        compile_bundle(MINIMAL, a_file, build=False)  # a file, not a directory
    with pytest.raises(CodegenError):
        compile_bundle(MINIMAL, a_file / "sub", build=False)  # below a file
    assert a_file.read_text() == "x"
    foreign = tmp_path / "home"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep me")
    with pytest.raises(CodegenError, match="refusing"):
        compile_bundle(MINIMAL, foreign, build=False)
    assert (foreign / "notes.txt").read_text() == "keep me"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.txt", "home"]


def test_cli_compile(tmp_path):
    runner = CliRunner()
    out = tmp_path / "cli"
    result = runner.invoke(app, ["compile", str(MINIMAL), "-o", str(out), "--no-build"])
    assert result.exit_code == 0, result.output
    assert "sources only" in result.output and (out / "minimal.h").is_file()
    broken = tmp_path / "broken.yaml"
    broken.write_text("version: 1\nname: x\n")
    result = runner.invoke(app, ["compile", str(broken), "-o", str(tmp_path / "nope")])
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert not (tmp_path / "nope").exists()
    result = runner.invoke(app, ["compile", str(MINIMAL), "-o", str(tmp_path / "x"), "--formulation", "nope"])
    assert result.exit_code == 1 and "unknown formulation" in result.output


# -- compilers and tools ---------------------------------------------------------------------------


def _make(out: Path, *targets: str, **variables: str) -> subprocess.CompletedProcess:
    command = ["make", "-s", "-j4", *targets, *(f"{k}={v}" for k, v in variables.items())]
    return subprocess.run(command, cwd=out, capture_output=True, text=True, timeout=900)


def _fresh_copy(out: Path, tmp_path: Path) -> Path:
    copy = tmp_path / out.name
    shutil.copytree(out, copy, ignore=shutil.ignore_patterns("build", "*.so", "*_test", "*_test_*"))
    return copy


@pytest.mark.skipif(shutil.which("clang") is None, reason="clang not installed")
def test_clang_werror(built, tmp_path):
    copy = _fresh_copy(built[0], tmp_path)
    done = _make(copy, "all", "check", CC="clang")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "PASS" in done.stdout


@pytest.mark.slow
def test_address_sanitizer(built, tmp_path):
    copy = _fresh_copy(built[0], tmp_path)
    done = _make(copy, "asan")
    if done.returncode != 0 and "sanitizer" in (done.stderr + done.stdout).lower() and "PASS" not in done.stdout:
        if "cannot find" in done.stderr or "unrecognized" in done.stderr:
            pytest.skip("the toolchain has no AddressSanitizer")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "PASS" in done.stdout


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind not installed")
def test_valgrind_memcheck(built, tmp_path):
    copy = _fresh_copy(built[0], tmp_path)
    done = _make(copy, "valgrind")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "ERROR SUMMARY: 0 errors" in done.stderr and "definitely lost" not in done.stderr


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("cmake") is None, reason="cmake not installed")
def test_cmake_build(built, tmp_path):
    copy = _fresh_copy(built[0], tmp_path)
    build = tmp_path / "cmake-build"
    for command in (["cmake", "-S", str(copy), "-B", str(build)], ["cmake", "--build", str(build), "-j4"],
                    ["ctest", "--test-dir", str(build), "--output-on-failure"]):
        done = subprocess.run(command, capture_output=True, text=True, timeout=900)
        assert done.returncode == 0, done.stdout + done.stderr


@pytest.mark.slow
@pytest.mark.parametrize("formulation", ["dcts", "osc", "projector", "qp_mt", "qp_md"])
def test_every_formulation_builds_and_replays(three_levels_spec, tmp_path, formulation):
    report = compile_bundle(three_levels_spec, tmp_path / formulation, formulation=formulation)  # runs the replay
    assert report.manifest["built"] and "golden vectors" in report.manifest["host"]["test_summary"]
    assert report.manifest["host"]["step_heap_calls"] == 0


@pytest.mark.slow
def test_warm_start_stays_within_tolerance(built, three_levels_spec):
    """Warm starting DAQP from the previous step lands on the same optimum (up to tolerances)."""
    _, compiled = built
    controller = build_controller(three_levels_spec)
    compiled.set_warm_start(True)
    try:
        worst = 0.0
        for s in StateSampler(controller, seed=12).mixed(1000, limit_fraction=0.2):
            a = controller.step(s.q, s.dq, s.tau_ext, s.ref)
            b = compiled.step(s.q, s.dq, s.tau_ext, s.ref)
            assert a.status == b.status
            worst = max(worst, relative_difference(a.tau, b.tau), relative_difference(a.x, b.x))
        assert worst <= 1e-6, worst
    finally:
        compiled.set_warm_start(False)


def _daqp_sources_or_skip() -> Path:
    from dcts_spec.codegen import daqp_sources

    try:
        return daqp_sources()
    except CodegenError as error:
        pytest.skip(f"DAQP sources unavailable: {error}")


@pytest.mark.slow
def test_daqp_from_source_compat_layer(built, three_levels_spec, tmp_path):
    """The newer DAQP API (PyPI source distribution) through the compatibility layer: same statuses,
    same solutions (relaxed QPs, which are badly conditioned, to 1e-4)."""
    csrc = _daqp_sources_or_skip()
    copy = _fresh_copy(built[0], tmp_path)
    done = _make(copy, "lib", "check", "valgrind", DAQP_SRC=str(csrc))
    out = done.stdout + done.stderr
    assert "ERROR SUMMARY: 0 errors" in out, out  # no suppression needed with this DAQP
    with load_bundle(copy) as compiled:
        controller = build_controller(three_levels_spec)
        for s in StateSampler(controller, seed=4).mixed(300, limit_fraction=0.3):
            a = controller.step(s.q, s.dq, s.tau_ext, s.ref)
            b = compiled.step(s.q, s.dq, s.tau_ext, s.ref)
            assert a.status == b.status
            tolerance = 1e-4 if a.status == STATUS_LIMITS_RELAXED else 1e-8
            assert relative_difference(a.tau, b.tau) <= tolerance


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("arm-none-eabi-gcc") is None, reason="arm-none-eabi-gcc not installed")
def test_cortex_m7_firmware_and_qemu(three_levels_spec, tmp_path):
    csrc = _daqp_sources_or_skip()
    report = compile_bundle(three_levels_spec, tmp_path / "fw", target="cortex-m7", daqp_src=csrc,
                            qemu=shutil.which("qemu-system-arm") is not None)
    fw = report.firmware
    assert fw["flash_bytes"] > 10000 and fw["ram_bytes"] >= fw["workspace_bytes"] > 0
    assert (tmp_path / "fw" / "firmware" / "three_levels_fw.elf").is_file()
    if shutil.which("qemu-system-arm"):
        assert fw["qemu"].endswith("PASS") and fw["step_heap_calls"] == 0


@pytest.mark.slow
def test_bench_runs(tmp_path):
    from dcts_spec.codegen.bench import bench, format_report

    result = bench(MINIMAL, states=300, python_states=20, callgrind_states=20)
    text = format_report(result)
    assert result["c_step"]["trajectory_warm"]["step"]["median_us"] > 0
    assert "Pinocchio" in text and "qp_data" in text

