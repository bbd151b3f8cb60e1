"""What `dcts simulate` and `dcts compare` do once their arguments are parsed.

Both return an exit code: problems the user can fix (a broken spec, no scenario, a runtime,
viewer or encoder missing here) are one message and exit 1, never a traceback. Output
directories are written all or nothing.
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import typer

from .analysis.compare import markdown_table, write_comparison
from .analysis.outputs import atomic_directory, earlier_output, write_run
from .analysis.report import describe
from .analysis.run import RunResult, analyze
from .files import OutputFolderError, check_new_file, check_writable
from .formulations import FORMULATIONS
from .phases import building_controller, phase
from .sim.progress import ProgressBar
from .sim.runner import Hook, Simulation, prepare_simulation
from .sim.runtime import RUNTIMES, RuntimeUnavailable
from .sim.video import VideoRecorder, VideoUnavailable
from .sim.viewer import LiveViewer, ViewerUnavailable
from .spec import Spec, SpecError, load_spec
from .spec.scenario import run_steps_problem

RESULTS_DIR = Path("runs")


class CommandError(Exception):
    """A problem to tell the user in one message."""


@dataclass(frozen=True)
class RunOptions:
    runtime: str = "c"
    duration: float | None = None
    quiet: bool = False
    cache: bool = True  # C runtime: reuse built bundles (False: build afresh, bypassing the cache)


def simulate_command(file: Path, out: Path | None, options: RunOptions, formulation: str | None = None,
                     plots: bool = True, viewer: bool = False, video: Path | None = None) -> int:
    """`dcts simulate`: one run, its log, summary and plots in `out`."""
    return _guarded(lambda: _simulate(file, out, options, formulation, plots, viewer, video))


def compare_command(file: Path, out: Path | None, options: RunOptions, formulations: list[str],
                    plots: bool = True) -> int:
    """`dcts compare`: the same scenario with each formulation, a table and overlay plots in `out`."""
    return _guarded(lambda: _compare(file, out, options, formulations, plots))


def _guarded(command: Callable[[], None]) -> int:
    try:
        command()
    except SpecError as error:
        typer.echo(str(error), err=True)
        return 1
    except (CommandError, RuntimeUnavailable, VideoUnavailable, OutputFolderError) as error:
        typer.echo(f"error: {error}", err=True)
        return 1
    return 0


def _simulate(file: Path, out: Path | None, options: RunOptions, formulation: str | None,
              plots: bool, viewer: bool, video: Path | None) -> None:
    spec = _load(file, options, [formulation] if formulation else [])
    out = _output_directory(out, RESULTS_DIR / spec.name, "run")
    if video is not None:  # (before the run: a video over the spec itself was written after it)
        check_new_file(video, "the video")
    with ExitStack() as stack:
        sim = _prepare(spec, options, formulation, stack)
        hooks = []
        if viewer:
            try:
                live = LiveViewer(sim)
            except ViewerUnavailable as error:
                typer.echo(f"warning: {error}; running without the viewer", err=True)
            else:
                stack.callback(live.close)
                hooks.append(live.hook())
        recorder = VideoRecorder(sim, video) if video is not None else None
        try:
            run = _run(sim, options, hooks + ([recorder.hook()] if recorder else []))
        except BaseException:
            if recorder:
                recorder.close(keep=False)
            raise
        if recorder:
            recorder.close()
        phase(f"writing the log, summary{' and plots' if plots else ''}")
        with atomic_directory(out, "run") as staging:
            write_run(run, staging, plots=plots)
    if not options.quiet:
        typer.echo(describe(run))
        if video is not None:
            typer.echo(f"wrote {video}")
        typer.echo(f"wrote {out}/ (log.npz, summary.json{', plots' if plots else ''})")


def _compare(file: Path, out: Path | None, options: RunOptions, formulations: list[str], plots: bool) -> None:
    if not formulations:
        raise CommandError("--formulations needs at least one formulation")
    spec = _load(file, options, formulations)
    out = _output_directory(out, RESULTS_DIR / f"{spec.name}-compare", "comparison")
    runs = []
    with ExitStack() as stack:
        for formulation in formulations:
            sim = _prepare(spec, options, formulation, stack)
            runs.append(_run(sim, options, []))
            if not options.quiet:
                typer.echo(describe(runs[-1]))
    phase(f"writing the comparison{' and overlay plots' if plots else ''}")
    with atomic_directory(out, "comparison") as staging:
        write_comparison(runs, staging, f"{spec.name}: {', '.join(formulations)} ({options.runtime} runtime)",
                         plots=plots)
    if not options.quiet:
        typer.echo(markdown_table(runs), nl=False)
        typer.echo(f"wrote {out}/ (comparison.md, comparison.json{', overlay plots' if plots else ''}, "
                   "one folder per formulation)")


def _load(file: Path, options: RunOptions, formulations: list[str]) -> Spec:
    """The spec, after checking the options that do not need it."""
    if options.runtime not in RUNTIMES:
        raise CommandError(f"unknown runtime {options.runtime!r}; choose one of {', '.join(RUNTIMES)}")
    unknown = [f for f in formulations if f not in FORMULATIONS]
    if unknown:
        raise CommandError(f"unknown formulation {unknown[0]!r}; choose one of {', '.join(FORMULATIONS)}")
    if options.duration is not None and options.duration <= 0:
        raise CommandError(f"--duration must be positive, got {options.duration:g}")
    spec = load_spec(file)
    if options.duration is not None and (problem := run_steps_problem(options.duration, spec.controller.period)):
        raise CommandError(f"--duration {problem}")
    return spec


def _output_directory(out: Path | None, default: Path, kind: str) -> Path:
    """The output directory of an output of `kind` (files.KINDS), checked before a run rather than
    after it."""
    out = out or default
    try:
        check_writable(out, kind, allow_unmarked=earlier_output)
    except OutputFolderError as error:
        raise CommandError(f"--out {error}") from None
    return out


def _prepare(spec: Spec, options: RunOptions, formulation: str | None, stack: ExitStack) -> Simulation:
    work_dir = None
    if options.runtime == "python":  # (the C runtime's bundle build announces its own phases)
        building_controller(spec.name, formulation or spec.controller.formulation)
    if options.runtime == "c" and not options.cache:
        # Without the cache, the C bundle lives as long as the run that loads it.
        work_dir = stack.enter_context(tempfile.TemporaryDirectory(prefix="dcts-runtime-"))
    return prepare_simulation(spec, options.runtime, formulation, options.duration, work_dir, cache=work_dir is None)


def _run(sim: Simulation, options: RunOptions, hooks: list[Hook]) -> RunResult:
    label = f"{sim.spec.name}: {sim.formulation} ({sim.runtime_kind})"
    phase(f"simulating {label}: {sim.scenario.duration:g} s in {sim.scenario.steps} control steps")
    progress = ProgressBar(sim.scenario.steps, sim.scenario.period, label, enabled=not options.quiet)
    try:
        log = sim.run([*hooks, progress.hook()])
    finally:
        progress.close()
    return analyze(sim, log)
