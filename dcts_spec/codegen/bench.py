"""`dcts bench`: time the generated C controller, the Python runtime and Pinocchio's dynamics.

The C controller is timed by a C harness (no Python in the loop) linked with the bundle's own
objects, built as its Makefile builds them (codegen/flags.py), over states along closed-loop motions (the order a control loop sees, so the
history the workspace keeps is realistic) and over independent random states (each from a fresh controller:
`_reset` before it, untimed). Pinocchio's numeric dynamics
terms (computeAllTerms + the task frames' Jacobians) on the same states are the reference a
hand-written controller would start from.
"""

from __future__ import annotations

import hashlib
import os
import shlex
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import casadi
import numpy as np
import pinocchio

from ..controller import STATUS_NAMES
from ..phases import phase
from ..spec import load_spec
from ..tasks.cartesian import CartesianTask
from .build import (CACHE_DIR, FirmwareTooLarge, build_firmware, compile_bundle, flash_breakdown_text, make_controller,
                    section_size)
from .flags import C_WARNINGS, HOST_OPTIMIZATION, flags_text
from .process import run, tail
from .bundle import CodegenError, render, template, version
from .layout import casadi_work_lengths
from .loader import load_bundle
from .states import State, StateSampler, trajectory_states

def _write_states(path: Path, states: list[State]) -> None:
    rows = np.array([np.concatenate([s.q, s.dq, s.tau_ext, s.ref]) for s in states], dtype=np.float64)
    with open(path, "wb") as f:
        f.write(np.int32(len(states)).tobytes())
        f.write(rows.tobytes())


def _stats(ns: np.ndarray) -> dict[str, float]:
    us = np.asarray(ns, dtype=float) / 1e3
    return {"median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)), "max_us": float(us.max()),
            "mean_us": float(us.mean())}


def build_c_harness(bundle: Path, manifest: dict, work: Path) -> Path:
    """The bench harness, compiled as the bundle's Makefile compiles its sources and linked with
    the bundle's objects: the timed code is the code that ships."""
    name = manifest["name"]
    values = {
        "name": name, "NAME": name.upper(), "VERSION": version(),
        **{f"SZ_{key.upper()}": value for key, value in casadi_work_lengths(manifest["casadi_work"]).items()},
    }
    source = work / f"{name}_bench.c"
    source.write_text(render(template("bench.c.in"), values))
    exe = work / f"{name}_bench"
    objects = bundle / manifest["host"]["build_dir"]
    flags = [*C_WARNINGS, *HOST_OPTIMIZATION, f"-I{bundle}"]
    daqp = []
    if manifest["nx"]:
        flags.append(f"-I{bundle / 'daqp' / 'include'}")
        daqp = [str(o) for o in sorted((objects / "daqp").glob("*.o"))]
    run([*shlex.split(manifest["host"]["compiler"]), *flags, "-o", str(exe), str(source), str(objects / f"{name}.o"),
         str(objects / f"{name}_casadi.o"), *daqp, "-lm"], work, "bench harness build")
    return exe


REPEATS = 3  # each configuration runs this often; the run with the lowest median step counts


def run_c_once(exe: Path, states: list[State], work: Path, tag: str, independent: bool = False) -> bytes:
    """One run of the harness over the states, in order (`independent`: each from a fresh
    controller, reset before it outside the timed region, as the states do not follow one
    another); its raw output."""
    states_file, out = work / f"states_{tag}.bin", work / f"times_{tag}.bin"
    if not states_file.is_file():
        _write_states(states_file, states)
    command = [str(exe), str(states_file), str(out)] + (["independent"] if independent else [])
    run(command, work, "bench harness", timeout=1800)
    return out.read_bytes()


def _median_step(raw: bytes, count: int) -> float:
    return float(np.median(np.frombuffer(raw[: 8 * count], dtype=np.int64)))


def c_times(runs: list[bytes], count: int) -> dict:
    """The harness's timing from the least disturbed of its runs (a shared machine)."""
    raw = min(runs, key=lambda r: _median_step(r, count))
    i64 = np.frombuffer(raw[: 24 * count], dtype=np.int64).reshape(3, count)
    i32 = np.frombuffer(raw[24 * count:], dtype=np.int32).reshape(3, count)
    step, data, fallback = i64
    status, solves, iterations = i32
    solve = np.maximum(step - data, 0)
    return {
        "states": count,
        "runs": len(runs),
        "step": _stats(step),
        "qp_data": _stats(data),
        "solve_and_rest": _stats(solve),
        "fallback": _stats(fallback),
        "statuses": {STATUS_NAMES.get(int(s), str(int(s))): int((status == s).sum()) for s in np.unique(status)},
        "qp_solves_max": int(solves.max()),
        "qp_solves": {"mean": float(solves.mean()), "median": float(np.median(solves))},
        # where the median step's time goes: the median step of the states that took k solves,
        # for the counts of at least 5 % of the states
        "step_by_solves": [{"solves": int(k), "share": float((solves == k).mean()),
                            "median_us": float(np.median(step[solves == k])) / 1e3}
                           for k in np.unique(solves) if (solves == k).mean() >= 0.05],
        "qp_iterations": {"mean": float(iterations.mean()), "max": int(iterations.max()),
                          "p99": float(np.percentile(iterations, 99))},
    }


def run_c_harness(exe: Path, states: list[State], work: Path, tag: str, independent: bool = False) -> dict:
    """The harness's timing of the states, best of REPEATS runs."""
    return c_times([run_c_once(exe, states, work, tag, independent) for _ in range(REPEATS)], len(states))


def callgrind_instructions(exe: Path, states: list[State], work: Path, name: str) -> float | None:
    """Instructions per step (callgrind, counting only inside <name>_step; valgrind must be installed)."""
    states_file, out = work / "states_callgrind.bin", work / "times_callgrind.bin"
    _write_states(states_file, states)
    log = work / "callgrind.out"
    run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={log}", f"--toggle-collect={name}_step",
         str(exe), str(states_file), str(out)], work, "callgrind", timeout=1800)
    summary = next((line for line in log.read_text().splitlines() if line.startswith(("summary:", "totals:"))), None)
    if summary is None:
        return None
    return int(summary.split()[1]) / (2 * len(states))  # the harness runs the steps twice


@dataclass
class PinocchioHarness:
    """How Pinocchio's terms are timed on the states: the C++ harness's command, or why there is none."""
    frames: list[str]
    command: list[str] | None
    env: dict[str, str]
    error: str | None


def pinocchio_harness(controller, states: list[State], work: Path) -> PinocchioHarness:
    """computeAllTerms + frame Jacobians of the task frames: a C++ harness against the pip-installed
    Pinocchio, built (once per Pinocchio version) if it can be."""
    frames = sorted({t.frame for lv in controller.problem.levels for t in lv.tasks if isinstance(t, CartesianTask)})
    model_file = work / "model.bin"
    controller.robot.model.saveToBinary(str(model_file))
    prefix = _cmeel_prefix()
    eigen = Path(casadi.__file__).parent / "include" / "eigen3"
    cxx = os.environ.get("CXX") or ("g++" if shutil.which("g++") else "c++")
    source = template("pinocchio_bench.cpp")
    # The harness takes ~20 s to compile: keep it, keyed by its source and Pinocchio's version.
    key = hashlib.sha256(f"{source}{pinocchio.__version__}{prefix}{cxx}".encode()).hexdigest()[:16]
    exe = CACHE_DIR / "pinocchio_bench" / key / "pinocchio_bench"
    (work / "pinocchio_bench.cpp").write_text(source)
    env = dict(os.environ, DCTS_NREF=str(controller.ref_size))
    if prefix is None:
        return PinocchioHarness(frames, None, env, "Pinocchio's C++ headers not found")
    if not exe.is_file():
        phase("building Pinocchio's C++ harness (~20 s, once per Pinocchio version)")
        exe.parent.mkdir(parents=True, exist_ok=True)
        try:
            # The flags Pinocchio's CMake config exports; no -march=native: the harness must keep
            # the Eigen alignment of the prebuilt library (mixing them crashes in free()).
            defines = ["-DBOOST_MPL_LIMIT_LIST_SIZE=30", "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
                       "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS", "-DBOOST_FUSION_INVOKE_MAX_ARITY=12",
                       "-DPINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION", "-DNDEBUG"]
            partial = exe.with_name(f"{exe.name}.{os.getpid()}")
            run([cxx, "-std=c++17", "-O2", *defines, f"-I{prefix / 'include'}", f"-I{eigen}",
                 "-o", str(partial), str(work / "pinocchio_bench.cpp"), f"-L{prefix / 'lib'}",
                 "-lpinocchio_default", "-lboost_serialization", f"-Wl,-rpath,{prefix / 'lib'}"],
                work, "Pinocchio harness build", timeout=900)
            os.replace(partial, exe)
        except CodegenError as exc:
            return PinocchioHarness(frames, None, env, str(exc).splitlines()[0])
    states_file = work / "states_pin.bin"
    _write_states(states_file, states)
    return PinocchioHarness(frames, [str(exe), str(model_file), str(states_file), str(work / "times_pin.bin"), *frames],
                            env, None)


def run_pinocchio_once(harness: PinocchioHarness, work: Path) -> np.ndarray | None:
    """One run of the C++ harness (ns per state), None if it failed (`harness.error` says why)."""
    done = subprocess.run(harness.command, cwd=work, capture_output=True, text=True, env=harness.env, timeout=1800)
    if done.returncode != 0:
        harness.error = f"Pinocchio harness failed: {tail(done.stderr, 3)}"
        return None
    return np.frombuffer(Path(harness.command[3]).read_bytes(), dtype=np.int64)


def pinocchio_times(harness: PinocchioHarness, runs: list[np.ndarray], controller, states: list[State]) -> dict:
    """Pinocchio's timing: the C++ harness's least disturbed run, else timed from Python (binding
    overhead included, and said so)."""
    if runs:
        return {"how": "C++ harness calling the pip-installed Pinocchio "
                       f"{pinocchio.__version__} (its precompiled algorithms)", "frames": harness.frames,
                "runs": len(runs), **_stats(min(runs, key=np.median))}
    model = controller.robot.model
    data = model.createData()
    ids = [model.getFrameId(f) for f in harness.frames]
    ns = []
    for s in states[:2000]:
        t0 = time.perf_counter_ns()
        pinocchio.computeAllTerms(model, data, s.q, s.dq)
        for fid in ids:
            pinocchio.getFrameJacobian(model, data, fid, pinocchio.LOCAL_WORLD_ALIGNED)
        ns.append(time.perf_counter_ns() - t0)
    return {"how": f"timed from Python (binding overhead included; {harness.error})", "frames": harness.frames,
            **_stats(np.array(ns))}


def _cmeel_prefix() -> Path | None:
    for parent in Path(pinocchio.__file__).resolve().parents:
        candidate = parent / "cmeel.prefix"
        if (candidate / "include" / "pinocchio").is_dir():
            return candidate
        if parent.name == "site-packages":
            break
    import site

    for base in site.getsitepackages():
        candidate = Path(base) / "cmeel.prefix"
        if (candidate / "include" / "pinocchio").is_dir():
            return candidate
    return None


def _step_times(step, states: list[State], with_ref: bool) -> np.ndarray:
    ns = np.empty(len(states), dtype=np.int64)
    for i, s in enumerate(states):
        t0 = time.perf_counter_ns()
        step(s.q, s.dq, s.tau_ext, s.ref if with_ref else None)
        ns[i] = time.perf_counter_ns() - t0
    return ns


def python_runtime(controller, compiled, states: list[State]) -> dict:
    """The Python runtime's step (`Controller.step`) and the bundle's step called through ctypes
    (`CompiledController.step`, what a Python program using the firmware's code pays), on the
    same states, one after the other, best of REPEATS runs each: their ratio is what prototyping
    in Python costs."""
    runs = {"python": [], "ctypes": []}
    for _ in range(REPEATS):
        controller.reset()
        runs["python"].append(_step_times(controller.step, states, bool(controller.ref_size)))
        runs["ctypes"].append(_step_times(compiled.step, states, bool(controller.ref_size)))
    python, ctypes_step = (min(runs[key], key=np.median) for key in ("python", "ctypes"))
    return {"states": len(states), "runs": REPEATS, **_stats(python), "ctypes_step": _stats(ctypes_step),
            "ratio_to_ctypes": float(np.median(python) / np.median(ctypes_step))}


def object_sizes(bundle: Path, manifest: dict, work: Path) -> dict:
    """.text of the controller's objects (as the bundle builds them) and of the shared library."""
    name = manifest["name"]
    sizes = {}
    for stem in (name, f"{name}_casadi"):
        obj = bundle / manifest["host"]["build_dir"] / f"{stem}.o"
        if obj.is_file():
            sizes[f"{stem}.o"] = section_size(obj)
    lib = bundle / manifest["library"]
    sizes[lib.name] = section_size(lib)
    return sizes


def build_flags(manifest: dict) -> str:
    """The optimization flags the bundle's Makefile builds with: its own, and its QP data's."""
    qp_data = tuple(manifest.get("qp_data_optimization", HOST_OPTIMIZATION))
    own = flags_text(HOST_OPTIMIZATION)
    return own if qp_data == HOST_OPTIMIZATION else f"{own}, QP data {flags_text(qp_data)}"


def c_source_bytes(bundle: Path, manifest: dict) -> int:
    """Bytes of the controller's C sources (the step and the CasADi-generated QP data)."""
    return sum((bundle / f"{manifest['name']}{suffix}.c").stat().st_size for suffix in ("", "_casadi"))


def bench(spec_file: str | Path, formulation: str | None = None, states: int = 10000, python_states: int = 500,
          callgrind_states: int = 300, seed: int = 0, build_timeout: float | None = None) -> dict:
    """Run the whole benchmark; returns a JSON-able dict (see `format_report`). `build_timeout`
    bounds each build step, in s (see process.build_timeout)."""
    if states < 1:
        raise CodegenError("--states must be at least 1")
    if python_states < 1:
        raise CodegenError("--python-states must be at least 1")
    spec = load_spec(spec_file)
    controller = make_controller(spec, formulation)
    with tempfile.TemporaryDirectory(prefix="dcts-bench-") as tmp:
        work = Path(tmp)
        bundle = work / "bundle"
        built = compile_bundle(spec, bundle, formulation=formulation, build_timeout=build_timeout)
        manifest = built.manifest
        t0 = time.perf_counter()
        phase(f"generating {states} closed-loop states (the C step in the loop)")
        with load_bundle(bundle) as compiled:
            along = trajectory_states(controller, states, seed=seed, step=compiled.step)
        phase(f"sampling {states} independent states")
        independent = StateSampler(controller, seed + 1).mixed(states, limit_fraction=0.15)
        generation_s = time.perf_counter() - t0

        exe = build_c_harness(bundle, manifest, work)
        pin = pinocchio_harness(controller, along, work)
        phase(f"timing the C step (the bundle's build, {build_flags(manifest)}) on the closed-loop states "
              f"alternately with Pinocchio's dynamics terms, then on the independent states, best of {REPEATS} "
              "runs each")
        c_runs, pin_runs = [], []
        for _ in range(REPEATS):  # alternately: a change of the shared host's speed reaches both
            c_runs.append(run_c_once(exe, along, work, "trajectory"))
            ns = run_pinocchio_once(pin, work) if pin.command else None
            if ns is not None:
                pin_runs.append(ns)
        c_traj = c_times(c_runs, len(along))
        pin_ref = pinocchio_times(pin, pin_runs, controller, along)
        # the ratio within each pair of runs back to back: how far the host's speed moved it
        pair_ratios = [_median_step(c, len(along)) / float(np.median(p)) for c, p in zip(c_runs, pin_runs)]
        c_rand = run_c_harness(exe, independent, work, "random", independent=True)
        python_along = along[: min(python_states, len(along))]
        phase(f"timing the Python runtime on {len(python_along)} states, and the C step through ctypes on the "
              f"same, best of {REPEATS} runs each")
        with load_bundle(bundle) as compiled:
            py = python_runtime(controller, compiled, python_along)
        instructions = None
        if shutil.which("valgrind") is not None:
            counted = along[: min(callgrind_states, len(along))]
            phase(f"counting the instructions of a step with callgrind ({len(counted)} states)")
            instructions = callgrind_instructions(exe, counted, work, manifest["name"])
        sizes = object_sizes(bundle, manifest, work)
        source_bytes = c_source_bytes(bundle, manifest)
        firmware = None
        if shutil.which("arm-none-eabi-gcc") is not None:  # the flash a microcontroller needs (issue 16: <= 64 kB)
            try:
                firmware = build_firmware(bundle, manifest, qemu=False, timeout=build_timeout)
            except FirmwareTooLarge as error:  # (a result, not a failure of the benchmark)
                firmware = {"flash_bytes_at_least": error.flash_bytes}

    host = manifest.get("host", {})
    result = {
        "spec": str(spec_file),
        "name": manifest["name"],
        "formulation": manifest["formulation"],
        "sizes": {"nq": manifest["nq"], "nref": manifest["nref"], "nx": manifest["nx"], "na": manifest["na"],
                  "nlevels": manifest["nlevels"]},
        "compiler": f"{host['compiler']} {build_flags(manifest)} (the bundle's Makefile)",
        "build": built.cost.to_dict() if built.cost else None,
        "c_source_bytes": source_bytes,
        "cortex_m7": firmware,
        "c_step": {"trajectory": c_traj, "random": c_rand},
        "python_step": py,
        "pinocchio_terms": pin_ref,
        "ratio_c_step_to_pinocchio": c_traj["step"]["median_us"] / pin_ref["median_us"],
        "ratio_c_step_to_pinocchio_pairs": pair_ratios,
        "workspace_bytes": manifest["workspace_bytes_host"],
        "daqp_workspace_bytes": manifest.get("daqp_workspace_bytes"),
        "heap_calls": host.get("init_heap_calls", 0) + host.get("step_heap_calls", 0),
        "text_bytes": sizes,
        "instructions_per_step": instructions,
        "qp_data_instructions": manifest["qp_data_instructions"],
        "qp_data_looped_products": manifest["qp_data_looped_products"],
        "state_generation_s": generation_s,
    }
    return result


def format_report(r: dict) -> str:
    s = r["sizes"]
    lines = [
        f"{r['name']} ({r['formulation']}): NQ={s['nq']} NREF={s['nref']} NX={s['nx']} NA={s['na']} "
        f"NLEVELS={s['nlevels']}; C compiled with {r['compiler']}; best of "
        f"{r['c_step']['trajectory'].get('runs', 1)} runs per row",
        "",
        f"{'per step (µs)':<56}{'median':>9}{'p99':>9}{'max':>9}",
    ]

    def row(label: str, st: dict) -> None:
        lines.append(f"{label:<56}{st['median_us']:>9.2f}{st['p99_us']:>9.2f}{st['max_us']:>9.2f}")

    for key, label in (("trajectory", "closed-loop states"), ("random", "independent random states")):
        c = r["c_step"][key]
        row(f"C step, {label} ({c['states']})", c["step"])
    c = r["c_step"]["trajectory"]
    row("  of which qp_data (CasADi-generated)", c["qp_data"])
    row("  of which the lexicographic solve and the rest", c["solve_and_rest"])
    row("  fallback torque (only when needed)", c["fallback"])
    py = r["python_step"]
    row(f"Python runtime step ({py['states']} closed-loop states)", py)
    row("  the same bundle's C step through ctypes (compiled_controller)", py["ctypes_step"])
    row("Pinocchio computeAllTerms + frame Jacobians", r["pinocchio_terms"])
    data_share = c["qp_data"]["median_us"] / c["step"]["median_us"]
    lines += [
        f"  Pinocchio: {r['pinocchio_terms']['how']}; frames {', '.join(r['pinocchio_terms']['frames']) or '-'}",
        "",
        f"ratio C step (closed loop, default) / Pinocchio terms, medians: {r['ratio_c_step_to_pinocchio']:.2f} "
        f"(target 1.3)" + (f", in each pair of runs {', '.join(f'{x:.2f}' for x in r['ratio_c_step_to_pinocchio_pairs'])}"
                           if r.get("ratio_c_step_to_pinocchio_pairs") else "")
        + f"; its p99 / its median: {c['step']['p99_us'] / c['step']['median_us']:.1f} (target 2)",
        f"ratio Python runtime step / C step through ctypes, medians: {py['ratio_to_ctypes']:.1f}",
        f"the {'QP data' if data_share > 0.5 else 'QP solve'} dominates: qp_data is {100 * data_share:.0f}% of the median step",
        f"QP: {c['qp_iterations']['mean']:.1f} DAQP iterations on average, max {c['qp_iterations']['max']}, "
        f"at most {c['qp_solves_max']} solves per step; statuses {c['statuses']}",
        f"QP solves per step (closed loop): median {c['qp_solves']['median']:.0f}, mean {c['qp_solves']['mean']:.1f}; "
        "median step by solves: " + ", ".join(f"{b['solves']}: {b['median_us']:.2f} µs ({100 * b['share']:.0f} %)"
                                              for b in c["step_by_solves"]),
        f"workspace {r['workspace_bytes']} bytes (DAQP's arrays {r['daqp_workspace_bytes']} of them), "
        f"heap calls {r['heap_calls']} (init and step; `make nomalloc`)",
        ".text bytes: " + ", ".join(f"{k} {v}" for k, v in r["text_bytes"].items())
        + f"; C source {r['c_source_bytes']} bytes",
        "instructions per step (callgrind): "
        + (f"{r['instructions_per_step']:.0f} (the bundle's build)" if r["instructions_per_step"]
           else "valgrind not installed"),
    ]
    if r.get("build"):
        lines.append(f"compile (make): {r['build']['seconds']:.1f} s, peak memory of a build process "
                     f"{r['build']['peak_rss_bytes'] / 1e6:.0f} MB")
    fw = r.get("cortex_m7")
    if not fw:
        lines.append("cortex-m7: arm-none-eabi-gcc not installed")
    elif "flash_bytes_at_least" in fw:
        lines.append(f"cortex-m7 flash: the image does not fit the 4 MB it is linked for: at least "
                     f"{fw['flash_bytes_at_least']} bytes (target 65536)")
    else:
        lines.append(f"cortex-m7 flash {fw['flash_bytes']} bytes (text+data; target 65536), RAM {fw['ram_bytes']} bytes")
        if fw.get("flash_breakdown"):  # (the image: start-up, an init-and-step loop and what it links)
            lines.append(f"  flash by part: {flash_breakdown_text(fw['flash_breakdown'])}")
    return "\n".join(lines)

