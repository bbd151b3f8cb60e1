"""Build a bundle: atomic output directory, host library and test, firmware images.

`compile_bundle` writes into a temporary directory next to the requested one and renames it
into place only when everything succeeded: the output directory is complete or not there.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import resource
import shlex
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from ..choices import TARGETS
from ..solve.sensitivity import available_cpus
from ..files import OutputFolderError, check_writable, install, mark_staging, remove_stale_staging
from ..phases import building_controller, phase
from ..controller import Controller
from ..robot.model import Robot
from ..spec import Spec, load_spec
from ..spec.loader import recorded_bytes
from .bundle import (DAQP_VERSION, GENERATOR, GOLDEN_COUNT, RECHECK_SAMPLES, BundleSources, CodegenError,
                     generate_sources, golden_coverage, recheck_golden)
from .model import model_record
from .process import Step, build_timeout as checked_timeout, run, start, tail


def cache_root() -> Path:
    """`$XDG_CACHE_HOME/dcts`, else `~/.cache/dcts`: what dcts keeps between commands."""
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg and Path(xdg).is_absolute() else Path.home() / ".cache") / "dcts"


# DAQP's C sources and objects, the bench's Pinocchio harness (built bundles: cache.default_cache_dir)
CACHE_DIR = Path(os.environ.get("DCTS_CACHE") or cache_root()).expanduser()

# What the golden-vector test prints (templates/test.c.in): its summary line and, built with
# heap counting (the Cortex-M7 test on qemu), the heap calls of init and of the steps.
GOLDEN_SUMMARY = "golden vectors"
HEAP_LINE = re.compile(r"heap: init (\d+) calls (\d+) bytes; steps (\d+) calls")
FLASH_OVERFLOW = re.compile(r"region `FLASH' overflowed by (\d+) bytes")
FIRMWARE_FLASH_BYTES = 4 * 1024 * 1024  # the flash the image is linked for (firmware/mps2_an500.ld)


class GoldenMismatch(RuntimeError):
    """The built C does not reproduce the Python runtime on its golden vectors: a defect of dcts,
    not of the spec or the machine, so not a CodegenError (exit code 1, "bad spec or input") but an
    internal error (exit code 3). Found from outside: a Centauro spec that validates clean made
    `dcts simulate --runtime c` exit 1 with the golden test's mismatches. `vectors`: the ones the
    test listed."""

    def __init__(self, message: str, vectors: list[int]):
        super().__init__(message)
        self.vectors = vectors


MISMATCHING_VECTORS = re.compile(r"mismatching vectors:([ \d]*)")


# -- toolchain -------------------------------------------------------------------------------------


def check_daqp_source(path: Path) -> None:
    """A --daqp-src folder must hold DAQP's C sources as its csrc/ does (include/, src/): an empty
    or wrong folder gave a bundle without them, and a build error about api.h."""
    if not ((path / "include" / "api.h").is_file() and (path / "src" / "api.c").is_file()):
        raise CodegenError(f"--daqp-src {path}: not DAQP's C sources (expected include/api.h and src/api.c, as in "
                           "the csrc/ folder of DAQP's source distribution)")


def daqp_sources(cache: Path | None = None, version: str = DAQP_VERSION) -> Path:
    """DAQP's C sources (csrc/ with include/ and src/) from its PyPI source distribution,
    downloaded once into the cache with pip (never into the project). Downloaded and unpacked in
    a private folder, then renamed into place: parallel compiles (pytest-xdist on a fresh machine)
    never see another's half-written sources."""
    cache = (cache or CACHE_DIR) / "daqp"
    csrc = cache / f"daqp-{version}" / "csrc"
    if (csrc / "src" / "api.c").is_file():
        return csrc
    cache.mkdir(parents=True, exist_ok=True)
    private = Path(tempfile.mkdtemp(prefix=".tmp-", dir=cache))
    try:
        archive = private / f"daqp-{version}.tar.gz"
        phase(f"downloading DAQP {version}'s C sources with pip")
        # --no-binary daqp, not :all:, which also builds DAQP's build tools (Cython) from source
        # to read its metadata: minutes on a machine whose pip cache is empty
        command = [sys.executable, "-m", "pip", "download", "--no-binary", "daqp", "--no-deps",
                   f"daqp=={version}", "-d", str(private)]
        done = subprocess.run(command, capture_output=True, text=True)
        if done.returncode != 0 or not archive.is_file():
            raise CodegenError(f"could not download DAQP {version}'s sources with pip:\n{tail(done.stdout + done.stderr)}")
        with tarfile.open(archive) as tar:
            members = [m for m in tar.getmembers() if (m.name.startswith(f"daqp-{version}/csrc/") or m.name == f"daqp-{version}/LICENSE")
                       and (m.isfile() or m.isdir())]
            tar.extractall(private, members=members, filter="data")
        if not (private / f"daqp-{version}" / "csrc" / "src" / "api.c").is_file():
            raise CodegenError(f"DAQP's source distribution has no csrc/src/api.c ({archive})")
        try:
            os.rename(private / f"daqp-{version}", cache / f"daqp-{version}")
        except OSError:
            if not (csrc / "src" / "api.c").is_file():  # not another process's copy: a real failure
                raise
    finally:
        shutil.rmtree(private, ignore_errors=True)
    return csrc


def _make_command(directory: Path, targets: list[str], variables: dict[str, str] | None) -> list[str]:
    command = ["make", "-C", str(directory), f"-j{min(available_cpus(), 8)}", *targets]
    return command + [f"{k}={v}" for k, v in (variables or {}).items()]


def make(directory: Path, targets: list[str], what: str, variables: dict[str, str] | None = None,
         timeout: float | None = None) -> str:
    """Run make in the bundle (`timeout`: see process.build_timeout)."""
    return run(_make_command(directory, targets, variables), directory, what, timeout=timeout)


# -- output directory ------------------------------------------------------------------------------


def _is_bundle(directory: Path) -> bool:
    try:
        return json.loads((directory / "manifest.json").read_text()).get("generator") == GENERATOR
    except (OSError, ValueError):
        return False


def _check_output(out_dir: Path) -> None:
    try:  # (a bundle from before the OWNED file is known by its manifest)
        check_writable(out_dir, "bundle", allow_unmarked=_is_bundle)
    except OutputFolderError as error:
        raise CodegenError(str(error)) from None


def _make_parents(directory: Path) -> list[Path]:
    """Create missing parent folders; return those created (deepest last)."""
    missing = []
    for parent in [directory, *directory.parents]:
        if parent.exists():
            break
        missing.append(parent)
    created = []
    for parent in reversed(missing):
        try:
            parent.mkdir()
        except OSError as exc:
            _remove_created(created)
            raise CodegenError(f"cannot create {parent}: {exc.strerror}") from None
        created.append(parent)
    return created


def _remove_created(created: list[Path]) -> None:
    for parent in reversed(created):
        try:
            parent.rmdir()
        except OSError:
            pass


# -- compile ---------------------------------------------------------------------------------------


@dataclass
class BuildCost:
    """What compiling the host library and test (`make lib`, then `make all`) took: its wall time
    from the library's start (the golden vectors are computed meanwhile), and the peak resident
    memory of any child process of this process so far (getrusage(RUSAGE_CHILDREN); in a fresh
    process, as `scripts/bench_sizes.py` runs it, that of the compiler)."""

    seconds: float
    peak_rss_bytes: int

    def to_dict(self) -> dict:
        return {"seconds": self.seconds, "peak_rss_bytes": self.peak_rss_bytes}


@dataclass
class BuildReport:
    """What compile_bundle did; `lines()` is what `dcts compile` prints."""

    directory: Path
    manifest: dict
    built: bool
    test_output: str = ""
    firmware: dict | None = None
    notes: list[str] = field(default_factory=list)
    cost: BuildCost | None = None

    def lines(self) -> list[str]:
        m = self.manifest
        out = [
            f"wrote {self.directory} — {m['name']}: {m['formulation']}, NQ={m['nq']} NREF={m['nref']} "
            f"NX={m['nx']} NA={m['na']} NLEVELS={m['nlevels']}",
        ]
        if self.built:
            host = m.get("host", {})
            out.append(f"  host library   {m['library']} ({host.get('text_bytes', '?')} bytes .text), "
                       f"workspace {m['workspace_bytes_host']} bytes (DAQP's {m['daqp_workspace_bytes']} included), "
                       f"no heap (`make nomalloc` passed)")
            out.append(f"  golden test    {host.get('test_summary', '')}")
            if self.cost:
                out.append(f"  compile        {self.cost.seconds:.0f} s (make), peak memory of a build process "
                           f"{self.cost.peak_rss_bytes / 1e6:.0f} MB")
        else:
            out.append("  sources only (--no-build): run `make && make check` in the directory")
        if self.firmware:
            fw = self.firmware
            out.append(f"  cortex-m7      flash {fw['flash_bytes']} bytes (text+data), RAM {fw['ram_bytes']} bytes "
                       f"(data+bss, workspace {fw['workspace_bytes']} included), heap calls "
                       f"{fw.get('heap_calls', '? (no qemu run)')}")
            if fw.get("flash_breakdown"):
                out.append(f"                 flash by part: {flash_breakdown_text(fw['flash_breakdown'])}")
            if "stack_bytes" in fw:
                out.append(f"                 largest stack frames: {fw['stack_bytes']}")
            if fw.get("qemu"):
                out.append(f"  qemu           {fw['qemu']}")
        out.extend(f"  note: {n}" for n in self.notes)
        return out


def _load(spec: Spec | str | Path) -> tuple[Spec, bytes | None]:
    if isinstance(spec, Spec):
        return spec, recorded_bytes(spec)
    path = Path(spec)
    return load_spec(path), path.read_bytes() if path.is_file() else None


def make_controller(spec: Spec, formulation: str | None = None, robot: Robot | None = None) -> Controller:
    """Validate and compile the spec for the Python runtime (SpecError on a broken spec).

    `robot` replaces the spec's robot as the controller's model (model mismatch)."""
    return _controller_and_model(spec, formulation, robot)[0]


def _controller_and_model(spec: Spec, formulation: str | None, robot: Robot | None,
                          changes: dict | None = None) -> tuple[Controller, dict]:
    """The controller and the manifest's record of its model (see model.model_record)."""
    from ..validate import validate_spec

    report = validate_spec(spec)
    model = robot if robot is not None else report.robot
    if model.nv != report.robot.nv or model.joint_names != report.robot.joint_names:
        raise CodegenError(f"the robot model ({model.nv} joints: {', '.join(model.joint_names)}) does not have the "
                           f"spec's joints ({', '.join(report.robot.joint_names)})")
    building_controller(spec.name, formulation or spec.controller.formulation)
    try:
        controller = Controller(spec, model, formulation)
    except ValueError as exc:
        raise CodegenError(str(exc)) from None
    return controller, model_record(model, report.robot, changes)


def section_size(path: Path, section: str = ".text") -> int:
    """Bytes of one section of an object or library (`size -A`; 0 if it has none)."""
    output = run(["size", "-A", str(path)], path.parent, "size")
    for line in output.splitlines():
        parts = line.split()
        if parts and parts[0] == section:
            return int(parts[1])
    return 0


def make_products(name: str) -> tuple[str, ...]:
    """What the bundle's Makefile builds and `make clean` removes (templates/Makefile.in), by name
    (fnmatch patterns): a compile into the folder replaces them, whoever ran `make`. Any other
    file there is a user's, and refuses the compile (a user's notes in build/ and a board's .elf
    in firmware/ were deleted by patterns as wide as build/* and firmware/*.elf: found from outside)."""
    configurations = ("build/[0-9]*[0-9]", "build/arm-[0-9]*[0-9]")  # build/<id>: `config_id`, cksum's digits
    below = [f"{c}/{folder}" for c in configurations for folder in ("daqp", "heap", "nomalloc", "asan")]
    objects = [f"{c[:-len('*[0-9]')]}*.{ext}" for c in configurations for ext in ("o", "su")]  # (* spans folders)
    programs = [f"{name}_test{suffix}" for suffix in ("", "_heap", "_nomalloc", "_asan")]
    firmware = [f"firmware/{name}_{stem}" for stem in ("fw.elf", "fw.map", "fw.size", "test.elf")] + ["firmware/size.txt"]
    return ("build", "build/config", *configurations, *below, *objects, f"lib{name}.so", *programs, *firmware)


def _golden_summary(output: str) -> str:
    return next((line.strip() for line in output.splitlines() if GOLDEN_SUMMARY in line), "")


@lru_cache(maxsize=8)
def compiler_identity(cc: str) -> dict:
    """The compiler a command names: its resolved path and the first line of `--version`."""
    words = shlex.split(cc) or ["cc"]
    path = shutil.which(words[0])
    identity = {"command": cc, "path": os.path.realpath(path) if path else None, "version": None}
    if path:
        try:
            done = subprocess.run([path, *words[1:], "--version"], capture_output=True, text=True, timeout=30)
            identity["version"] = (done.stdout or done.stderr).strip().splitlines()[0] if done.returncode == 0 else None
        except (OSError, subprocess.SubprocessError, IndexError):
            pass
    return identity


def build_dirs(directory: Path, variables: dict[str, str]) -> tuple[str, str]:
    """The bundle's object folders for these make variables, relative to it (host, Cortex-M7):
    its Makefile keeps objects per compiler and flags (`make print-build`)."""
    words = make(directory, ["-s", "print-build"], "make print-build", variables).split()
    if len(words) != 2:
        raise CodegenError(f"make print-build printed {' '.join(words)!r}, not two folders")
    return words[0], words[1]


def _daqp_objects(directory: Path, build: str) -> Path:
    """Where DAQP's objects for this configuration (the host build folder's name: a checksum of the
    compiler and the flags) are kept between builds: every bundle compiles the same DAQP sources
    the same way, ~5 s a bundle on two cores."""
    flags = next((line for line in (directory / "Makefile").read_text().splitlines()
                  if line.startswith("DAQP_FLAGS")), "")
    key = hashlib.sha256(json.dumps([DAQP_VERSION, flags, Path(build).name]).encode()).hexdigest()[:20]
    return CACHE_DIR / "daqp-objects" / key


def _reuse_daqp_objects(directory: Path, build: str) -> None:
    """Put the kept DAQP objects into the bundle's build folder (newer than its sources: make keeps them)."""
    kept = _daqp_objects(directory, build)
    if kept.is_dir() and (directory / "daqp").is_dir():
        (directory / build / "daqp").mkdir(parents=True, exist_ok=True)
        for obj in kept.glob("*.o"):
            shutil.copyfile(obj, directory / build / "daqp" / obj.name)


def _keep_daqp_objects(directory: Path, build: str) -> None:
    kept = _daqp_objects(directory, build)
    built = sorted((directory / build / "daqp").glob("*.o"))
    if kept.is_dir() or not built:
        return
    kept.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=".tmp-", dir=kept.parent))
    for obj in built:
        shutil.copyfile(obj, staging / obj.name)
    try:
        os.rename(staging, kept)
    except OSError:  # another build kept them first
        shutil.rmtree(staging, ignore_errors=True)


@dataclass
class LibraryBuild:
    """The host library's build, started (`start_library`): its make step and its object folder."""

    step: Step
    build: str


def start_library(directory: Path, cc: str | None = None, timeout: float | None = None) -> LibraryBuild:
    """Start building the host library (`make lib`: it needs no golden vector), for `build_host`
    to finish: compile_bundle computes the golden vectors meanwhile."""
    variables = {"CC": cc} if cc else {}
    build, _ = build_dirs(directory, variables)
    _reuse_daqp_objects(directory, build)
    phase("compiling C (and computing the golden vectors meanwhile)")
    step = start(_make_command(directory, ["lib"], variables), directory, "host build", timeout=timeout)
    return LibraryBuild(step, build)


def build_host(directory: Path, manifest: dict, cc: str | None = None,
               timeout: float | None = None, library: LibraryBuild | None = None) -> tuple[dict, BuildCost]:
    """Build the host library (or finish `library`, its build started by `start_library`) and the
    test with `make`, run the test, and again linked with a malloc that aborts (`make nomalloc`:
    neither init nor step may reach the heap). Returns the manifest's `host` record and what the
    build took (from the library's start)."""
    variables = {"CC": cc} if cc else {}
    compiler = cc or os.environ.get("CC", "cc")
    library = library or start_library(directory, cc, timeout)
    library.step.wait()
    phase("compiling the golden-vector test and running it")
    make(directory, ["all"], "host build", variables, timeout)
    build = library.build
    cost = BuildCost(time.monotonic() - library.step.start,
                     resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024)
    _keep_daqp_objects(directory, build)
    try:  # (`make all` built the test: `check` only runs it)
        test = make(directory, ["check"], "golden-vector test", variables, timeout)
    except CodegenError as error:
        listed = MISMATCHING_VECTORS.search(str(error))
        raise GoldenMismatch(f"{error}. The generated C does not reproduce the Python runtime: a bug of dcts, "
                             "not of the spec (--runtime python runs it)",
                             [int(k) for k in listed.group(1).split()] if listed else []) from None
    make(directory, ["nomalloc"], "golden-vector test with a malloc that aborts", variables, timeout)
    lib = directory / manifest["library"]
    return {
        "compiler": compiler,
        "build_dir": build,
        "test_summary": _golden_summary(test),
        # `make nomalloc` passed: no heap call, in init or in the steps
        "init_heap_calls": 0,
        "init_heap_bytes": 0,
        "step_heap_calls": 0,
        "text_bytes": section_size(lib),
        "library_bytes": lib.stat().st_size,
    }, cost


def _build_and_test(controller: Controller, sources: BundleSources, cc: str | None, timeout: float | None, library: LibraryBuild,
                    notes: list[str]) -> tuple[dict, BuildCost]:
    """`build_host`; where the golden test fails, the vectors it lists measured again
    (`recheck_golden`): a vector whose own answer rounding moves, which the golden vectors' few
    samples missed, is no test of the C, and is compared less (a note says so); any other mismatch
    stands."""
    try:
        return build_host(sources.directory, sources.manifest, cc, timeout, library)
    except GoldenMismatch as mismatch:
        phase(f"the golden test failed on vectors {mismatch.vectors}: measuring how far their data determine the "
              "Python runtime's answers")
        again = recheck_golden(controller, sources.golden, mismatch.vectors)
        if not again:
            raise
        sources.manifest["golden"]["undetermined_on_a_second_look"] = again
        sources.write_golden()
        notes.append(f"golden vectors {again}: their answers moved by rounding-size changes of their data "
                     f"({RECHECK_SAMPLES} samples; the C took one of the other answers), so the test compares less "
                     "of them")
        host, cost = build_host(sources.directory, sources.manifest, cc, timeout)
        return host, BuildCost(time.monotonic() - library.step.start, cost.peak_rss_bytes)


def build_firmware(directory: Path, manifest: dict, qemu: bool = True, timeout: float | None = None) -> dict:
    """Cross-compile for Cortex-M7 (double FPU), report flash/RAM, run the golden test on qemu."""
    if shutil.which("arm-none-eabi-gcc") is None:
        raise CodegenError("arm-none-eabi-gcc not found: install gcc-arm-none-eabi and libnewlib-arm-none-eabi")
    phase("cross-compiling for cortex-m7")
    variables: dict[str, str] = {}
    try:
        make(directory, ["firmware"], "firmware build", variables, timeout)
    except CodegenError as error:
        overflows = [int(n) for n in FLASH_OVERFLOW.findall(str(error))]
        if not overflows:
            raise
        raise FirmwareTooLarge(FIRMWARE_FLASH_BYTES + max(overflows)) from None
    name = manifest["name"]
    sections = _arm_sections(directory / "firmware" / f"{name}_fw.size")
    text, data, bss = sections.get("text", 0), sections.get("data", 0), sections.get("bss", 0)
    result = {
        "cpu": "cortex-m7 fpv5-d16 hard-float",
        "flash_bytes": text + data,
        "ram_bytes": data + bss,
        "text_bytes": text,
        "data_bytes": data,
        "bss_bytes": bss,
        # what the flash holds, by where it comes from (the linker's map of the image)
        "flash_breakdown": flash_breakdown(directory / "firmware" / f"{name}_fw.map", name, text + data),
        "workspace_bytes": _arm_symbol_size(directory / "firmware" / f"{name}_fw.elf", "ws"),
        "stack_bytes": _stack_usage(directory / build_dirs(directory, variables)[1], name),
    }
    if qemu and shutil.which("qemu-system-arm"):
        output = make(directory, ["qemu-check"], "golden-vector test on qemu (cortex-m7)", variables, timeout)
        summary = _golden_summary(output)
        heap = HEAP_LINE.search(output)
        if heap:
            result["heap_calls"] = int(heap.group(1)) + int(heap.group(3))
            result["step_heap_calls"] = int(heap.group(3))
        result["qemu"] = f"{summary} — PASS" if "PASS" in output else summary
    return result


class FirmwareTooLarge(CodegenError):
    """The Cortex-M7 image does not fit the flash it is linked for."""

    def __init__(self, flash_bytes: int):
        self.flash_bytes = flash_bytes  # what the image needs, at least (the linker's overflow)
        super().__init__(
            f"the Cortex-M7 image needs at least {flash_bytes / 1e6:.1f} MB of flash, more than the "
            f"{FIRMWARE_FLASH_BYTES / 2**20:.0f} MB of the board it is linked for (qemu's mps2-an500; a "
            "microcontroller has 64 kB to 2 MB): fewer joints (robot.locked_joints) or tasks")


def _arm_sections(size_file: Path) -> dict[str, int]:
    """Group `size -A` sections of the image into text (flash only), data and bss."""
    out = {"text": 0, "data": 0, "bss": 0}
    for line in size_file.read_text().splitlines():
        parts = line.split()
        if len(parts) < 3 or not parts[1].isdigit():
            continue
        section, size = parts[0], int(parts[1])
        if section in (".text", ".ARM.extab", ".ARM.exidx", ".rodata"):
            out["text"] += size
        elif section == ".data":
            out["data"] += size
        elif section == ".bss":
            out["bss"] += size
    return out


# The parts of the image's flash (flash_part: which input files each is made of), as reports name them
FLASH_PARTS = {"qp_data": "QP data", "controller": "controller", "daqp": "DAQP", "libm": "libm",
               "libc": "libc-nano", "startup": "start-up and main", "other": "padding"}
FLASH_SECTIONS = (".text", ".ARM.extab", ".ARM.exidx", ".data")  # (.rodata is in .text)
MAP_INPUT = re.compile(r"^ (\S+)?\s+0x([0-9a-f]+)\s+0x([0-9a-f]+)\s+(\S.*)$")


def flash_part(file: str, name: str) -> str:
    """Which part of the flash an input file of the image's link is (a path from the linker's map)."""
    base = file.replace("\\", "/").rsplit("/", 1)[-1]
    if base == f"{name}_casadi.o":
        return "qp_data"
    if base == f"{name}.o":
        return "controller"
    if "/daqp/" in f"/{file}" or base == "daqp_plain.o":
        return "daqp"
    if base.startswith("libm.a(") or base.startswith("libm_nano.a("):
        return "libm"
    if ".a(" in base:  # libc_nano, libnosys, libgcc
        return "libc"
    if base in ("startup.o", "fw_main.o"):
        return "startup"
    return "other"


def flash_breakdown(map_file: Path, name: str, flash_bytes: int) -> dict[str, int] | None:
    """Bytes of the image's flash per part (FLASH_PARTS), from GNU ld's map (-Wl,-Map) of it: the
    input sections kept in its output sections that are loaded from flash."""
    if not map_file.is_file():
        return None
    parts = dict.fromkeys(FLASH_PARTS, 0)
    output = None
    pending = None  # an input section whose name filled its line (its address and size on the next)
    text = map_file.read_text(errors="replace").split("Linker script and memory map", 1)[-1]
    for line in text.splitlines():
        if line and not line[0].isspace():
            output = line.split()[0]
            continue
        match = MAP_INPUT.match(line)
        if match is None:
            words = line.split()
            pending = words[0] if len(words) == 1 and line.startswith(" .") else None
            continue
        section = match.group(1) or pending
        pending = None
        if output not in FLASH_SECTIONS or section is None or section == "*fill*" or not section.startswith("."):
            continue
        parts[flash_part(match.group(4).strip(), name)] += int(match.group(3), 16)
    parts["other"] += flash_bytes - sum(parts.values())
    return parts


def flash_breakdown_text(parts: dict[str, int]) -> str:
    return ", ".join(f"{FLASH_PARTS[k]} {v}" for k, v in parts.items())


def _arm_symbol_size(elf: Path, symbol: str) -> int | None:
    output = run(["arm-none-eabi-nm", "-S", str(elf)], elf.parent, "nm")
    for line in output.splitlines():
        parts = line.split()
        if len(parts) == 4 and parts[3] == symbol:
            return int(parts[1], 16)
    return None


def _stack_usage(build: Path, name: str) -> dict[str, int]:
    """The largest stack frames (-fstack-usage) of the controller's own functions."""
    frames: dict[str, int] = {}
    for su in (build / f"{name}.su", build / f"{name}_casadi.su"):
        if not su.is_file():
            continue
        for line in su.read_text().splitlines():
            parts = line.split("\t")
            if len(parts) >= 2 and parts[1].isdigit():
                frames[parts[0].split(":")[-1]] = int(parts[1])
    return dict(sorted(frames.items(), key=lambda kv: -kv[1])[:4])


def compile_bundle(
    spec: Spec | str | Path,
    out_dir: str | Path,
    formulation: str | None = None,
    build: bool = True,
    target: str = "host",
    cc: str | None = None,
    daqp_src: str | Path | None = None,
    golden_count: int = GOLDEN_COUNT,
    qemu: bool = True,
    robot: Robot | None = None,
    model_changes: dict | None = None,
    build_timeout: float | None = None,
) -> BuildReport:
    """Generate (and build) the C bundle of a spec into out_dir, atomically.

    `robot` is the controller's model when it is not the spec's own (model mismatch, e.g.
    `sim.mismatch.scaled_robot`); `model_changes` says how it differs (e.g. {"mass_scale": 1.2}).
    The manifest (`model`, `model_sha256`) and the header then say that the bundle was
    generated for a modified model; the spec's SHA-256 stays that of the spec.
    `build_timeout` bounds each make step, in s (default: $DCTS_BUILD_TIMEOUT, else 600 s).

    Raises SpecError for a broken spec and CodegenError for everything else; in both cases
    nothing is left at out_dir (an older bundle there stays untouched)."""
    if target not in TARGETS:
        raise CodegenError(f"unknown target {target!r}; choose one of {', '.join(TARGETS)}")
    build_timeout = checked_timeout(build_timeout)  # a bad $DCTS_BUILD_TIMEOUT: before minutes of building
    out_dir = Path(out_dir).expanduser().absolute()
    if out_dir.name in ("", ".", ".."):
        raise CodegenError(f"invalid output directory {out_dir}")
    _check_output(out_dir)
    if daqp_src:
        check_daqp_source(Path(daqp_src))
    spec_obj, spec_bytes = _load(spec)
    controller, model = _controller_and_model(spec_obj, formulation, robot, model_changes)

    created = _make_parents(out_dir.parent)
    remove_stale_staging(out_dir.parent, f".{out_dir.name}.tmp-")
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.tmp-", dir=out_dir.parent))
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes it private; the bundle is an ordinary folder
        mark_staging(tmp)
    except OSError as exc:
        _remove_created(created)
        raise CodegenError(f"cannot write into {out_dir.parent}: {exc.strerror}") from None
    library: list[LibraryBuild] = []  # (the library's build, started while the golden vectors are computed)
    try:
        source = (Path(daqp_src) if daqp_src else daqp_sources()) if controller.nx else None
        phase("generating C")
        sources = generate_sources(controller, tmp, spec_bytes=spec_bytes, golden_count=golden_count,
                                   daqp_source=source, model=model,
                                   library_written=(lambda: library.append(start_library(tmp, cc, build_timeout)))
                                   if build else None)
        manifest = sources.manifest
        report = BuildReport(out_dir, manifest, build, notes=golden_coverage(manifest))
        if build:
            manifest["host"], report.cost = _build_and_test(controller, sources, cc, build_timeout, library[0],
                                                            report.notes)
            manifest["built"] = True
        if target == "cortex-m7":
            report.firmware = manifest["cortex_m7"] = build_firmware(tmp, manifest, qemu=qemu, timeout=build_timeout)
        (tmp / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n")
        install(tmp, out_dir, "bundle", make_products(manifest["name"]))  # (files a user added to an older bundle stay)
    except BaseException as exc:
        for started in library:  # (before its folder goes: a golden-vector error, Ctrl-C, SIGTERM)
            started.step.end()
        shutil.rmtree(tmp, ignore_errors=True)
        _remove_created(created)
        if isinstance(exc, OSError):
            raise CodegenError(f"writing the bundle failed: {exc}") from None
        if isinstance(exc, OutputFolderError):  # (a user's file where the bundle goes: found by install)
            raise CodegenError(str(exc)) from None
        raise
    return report
