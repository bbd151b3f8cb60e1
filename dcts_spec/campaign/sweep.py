"""`dcts sweep` as a Python function: check the campaign, build each bundle once, run the
samples not yet in the folder on the engine, write the report."""

from __future__ import annotations

import shlex
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..codegen.cache import default_cache_dir
from ..phases import phase
from ..spec import load_spec
from ..spec.errors import Diagnostic, SpecError, did_you_mean
from .document import MAX_SAMPLES, Campaign, load_campaign
from .engine import Pool, RayPool, SerialPool, Throughput, check_address, ray_session
from .progress import sample_progress
from .report import first_not_run, rates, replay_name, save_json, summarize_metrics, workers, worst_cases, write_html, write_plots
from .results import REPLAYS, ResultsFolder
from .runner import CampaignInputs, SampleRunner
from .scenario import replay_yaml
from .units import column_units

Engine = Literal["ray", "serial"]
TASK_METRICS = ("task_rms_error", "task_mean_error", "task_final_error")
# Per-run numbers a report may rank (besides the task metrics and primary_rms_error).
RUN_METRICS = ("max_joint_position_violation", "max_joint_velocity_violation", "max_joint_velocity_violation_ratio",
               "max_torque_violation", "max_cartesian_violation", "max_cartesian_velocity_violation",
               "max_collision_violation", "solver_failures",
               "limits_relaxed", "min_scaling", "primary_mean_acceleration_error", "acceleration_energy_integral",
               "kinetic_energy_peak", "task_space_kinetic_energy_peak", "null_space_kinetic_energy_peak",
               "max_disturbance_torque", "max_external_torque_estimate_error", "wall_time")


class UnknownMetric(ValueError):
    """--optimize names no per-run metric of this spec."""


@dataclass(frozen=True)
class SweepOptions:
    engine: Engine = "ray"
    address: str | None = None  # a Ray cluster's; None: a local session with every core
    workers: int | None = None  # at most this many (default: one per CPU Ray has)
    progress: bool = True
    max_samples: int | None = None  # run at most this many new samples, then report (and stop)
    plots: bool = True  # the PNGs of the metrics against the swept values (a second or so each)


@dataclass
class SweepResult:
    folder: Path
    report: dict[str, Any]
    complete: bool  # every sample of the campaign has a row


def sweep(spec_file: str | Path, campaign_file: str | Path, out: str | Path,
          options: SweepOptions = SweepOptions()) -> SweepResult:
    """Run the campaign's samples of the spec not yet in `out`/samples.jsonl; write the report.

    Raises SpecError (located in the spec or the campaign file) for a bad input or a folder
    started with other files, OutputFolderError for a folder dcts did not write."""
    with campaign_session(spec_file, campaign_file, out, {"mode": "sweep"}, options) as session:
        session.run(session.todo())
        return session.finish()


class CampaignSession:
    """A campaign's checked inputs, its folder and its pool, for a sweep or an optimization."""

    def __init__(self, spec_file: Path, campaign_file: Path, out: Path, settings: dict[str, Any],
                 options: SweepOptions, check: Callable[[CampaignSession], Any] | None = None):
        self.options = options
        self.spec_file, self.campaign_file = spec_file, campaign_file
        self.campaign: Campaign = load_campaign(campaign_file)  # its errors before the spec's
        load_spec(spec_file)  # a missing or unreadable spec: a located error, as for every command
        self.inputs = CampaignInputs(str(spec_file), spec_file.read_text(encoding="utf-8"), str(campaign_file),
                                     campaign_file.read_text(encoding="utf-8"), str(default_cache_dir()))
        self.driver = SampleRunner(self.inputs)
        self.folder = ResultsFolder(out, spec_file, campaign_file, settings)
        check_campaign(self.driver)
        metric = settings.get("metric")  # an optimization's, checked before anything is written
        allowed = allowed_metrics(self.driver)
        if metric is not None and metric not in allowed:
            raise UnknownMetric(f"--optimize: unknown metric {metric!r}{did_you_mean(metric, allowed)}; allowed: "
                                f"{', '.join(allowed)}")
        self.folder.check()
        if options.engine == "ray" and options.address:  # (before anything is built or written)
            check_address(options.address)
        self.parameter_units = check_parameters(self.driver)  # (before the build: a refusal at once)
        phase(f"building the C controller{'s' if len(self._bundles()) > 1 else ''} (once)")
        for formulation, mass_scale in self._bundles():
            self.driver.bundle(formulation, mass_scale)
        if check is not None:  # (the caller's own check of the inputs: an optimization's search space)
            check(self)
        self.rows = self.folder.open(self.driver.sampler.count)  # (only now: a refused campaign leaves no folder)
        self.pool: Pool | None = None
        self.parameters: dict[str, Any] | None = None  # the optimizer's best, for the campaign's rows
        self._stack = ExitStack()  # the Ray session, once a pool is wanted

    def _bundles(self) -> list[tuple[str | None, float]]:
        sampler = self.driver.sampler
        return [(f, s) for f in sampler.formulations for s in sampler.mass_scales()]

    def todo(self) -> list[int]:
        todo = [i for i in range(self.driver.sampler.count) if i not in self.rows]
        return todo[: self.options.max_samples] if self.options.max_samples is not None else todo

    def forget_rows(self) -> None:
        """Start the campaign's rows afresh (samples.jsonl emptied)."""
        self.folder.samples_file.unlink(missing_ok=True)
        self.rows = {}

    def start_pool(self) -> Pool:
        """The engine's pool, started on first use (Ray only once the inputs proved good)."""
        if self.pool is None and self.options.engine == "serial":
            self.pool = SerialPool(self.driver)
        elif self.pool is None:
            phase("starting Ray" + (f" at {self.options.address}" if self.options.address else " on this machine"))
            self._stack.enter_context(ray_session(self.options.address, quiet=not self.options.progress))
            self.pool = RayPool(self.inputs, self.options.workers)
        return self.pool

    def run(self, indices: list[int], trial: dict[str, Any] | None = None) -> list[dict[str, Any]]:
        """Run samples on the pool. The campaign's rows go to samples.jsonl as they finish; an
        optimization `trial`'s (its controller values) are only returned."""
        if not indices:
            return []
        pool = self.start_pool()
        phase(f"running {len(indices)} samples on {pool.throughput.engine} ({workers(pool.throughput.workers)})"
              + (f" with {trial}" if trial else ""))
        out = []
        total, done = (len(indices), 0) if trial else (self.driver.sampler.count, len(self.rows))
        with sample_progress(total, done, "samples", self.options.progress) as advance:
            for row in pool.map(indices, trial or self.parameters):
                if not trial:
                    self.folder.append([row])
                    self.rows[row["index"]] = row
                out.append(row)
                advance()
        return out

    def finish(self, extra: dict[str, Any] | None = None) -> SweepResult:
        """Write the report of the rows so far."""
        phase("writing the report")
        report = self.report(extra or {})
        return SweepResult(self.folder.folder, report, len(self.rows) == self.driver.sampler.count)

    def report(self, extra: dict[str, Any]) -> dict[str, Any]:
        rows = [self.rows[i] for i in sorted(self.rows)]
        settings = self.campaign.report
        with self.folder.report_staging() as staging:
            (staging / REPLAYS).mkdir()
            worst = []
            for metric in settings.metrics:
                for row in worst_cases(rows, metric, settings.worst, settings.violation_tolerance):
                    worst.append(self._replay(metric, row, staging))
            d = self.driver
            units = column_units(d.sampler.variables, list(settings.metrics), d.robot, d.campaign, d.problem,
                                 self.parameter_units, d.primary_task)
            plots = write_plots(rows, d.sampler.swept(), list(settings.metrics), units, staging) \
                if self.options.plots else []
            throughput = self.pool.throughput if self.pool else Throughput(self.options.engine, 0)
            report = {
                "title": f"{self.driver.spec.name}: campaign {self.campaign_file.name}",
                "spec": str(self.spec_file), "campaign": str(self.campaign_file),
                "samples": self.driver.sampler.count, "finished": len(rows),
                "rates": rates(rows, settings), "first_not_run": first_not_run(rows),
                "metrics": summarize_metrics(rows, list(settings.metrics)),
                "worst_cases": worst, "plots": plots, "throughput": throughput.to_dict(), "units": units, **extra,
            }
            save_json(report, staging / "report.json")
            write_html(report, plots, staging / "report.html")
        return report

    def _replay(self, metric: str, row: dict[str, Any], staging: Path) -> dict[str, Any]:
        """The worst case's spec, written for `dcts simulate` (the sample's own data) into the
        report's `staging` folder, for its place in the campaign's folder."""
        index = row["index"]
        name = replay_name(index)
        path = self.folder.folder / name
        data = self.driver.spec_data(self.driver.sample(index, self.parameters))
        comment = (f"Sample {index} (seed {row['seed']}) of the campaign {self.campaign_file} on {self.spec_file}: "
                   f"replay with\n  dcts simulate {path}")
        if not (staging / name).exists():  # (a sample worst by several metrics)
            (staging / name).write_text(replay_yaml(data, self.spec_file, path, comment), encoding="utf-8")
        command = f"dcts simulate {shlex.quote(str(path))} -o {shlex.quote(str(path.with_suffix('')))}"
        return {"metric": metric, "value": row[metric], "index": index, "seed": row["seed"], "replay": name,
                "command": command}

    def close(self) -> None:
        if isinstance(self.pool, RayPool):
            self.pool.close()
        self._stack.close()


@contextmanager
def campaign_session(spec_file: str | Path, campaign_file: str | Path, out: str | Path, settings: dict[str, Any],
                     options: SweepOptions, check: Callable[[CampaignSession], Any] | None = None
                     ) -> Iterator[CampaignSession]:
    session = CampaignSession(Path(spec_file), Path(campaign_file), Path(out), settings, options, check)
    try:
        yield session
    finally:
        session.close()


def allowed_metrics(driver: SampleRunner) -> list[str]:
    """The per-run numbers a report ranks and an optimization optimizes."""
    tasks = [t.name for t in driver.spec.tasks]
    return [*RUN_METRICS, "primary_rms_error", *(f"{m}.{t}" for m in TASK_METRICS for t in tasks)]


def check_campaign(driver: SampleRunner) -> None:
    """What the campaign file names exists in the spec: pushed bodies, payload frames, the
    tasks and metrics of the report, a duration when the spec has no scenario."""
    campaign, robot, spec = driver.campaign, driver.robot, driver.spec
    src = campaign.source
    diagnostics: list[Diagnostic] = []
    sampler = driver.sampler
    if sampler.count > MAX_SAMPLES:  # (listing the samples to run would take gigabytes)
        diagnostics.append(src.diagnostic(("samples",), (
            f"{campaign.samples:,} samples at each of the {sampler.grid_points:,} grid points are {sampler.count:,} "
            f"samples; a campaign has at most {MAX_SAMPLES:,}: fewer samples or grid values")))
    frames = [f.name for f in robot.model.frames]
    for kind, key, entries in (("pushes", "body", campaign.pushes), ("payloads", "frame", campaign.payloads)):
        for i, entry in enumerate(entries):
            name = getattr(entry, key)
            if not robot.has_frame(name):
                diagnostics.append(src.diagnostic((kind, i, key), f"no frame {name!r} in the robot"
                                                  f"{did_you_mean(name, frames)}"))
    tasks = [t.name for t in spec.tasks]
    allowed = allowed_metrics(driver)
    for i, metric in enumerate(campaign.report.metrics):
        if metric not in allowed:
            diagnostics.append(src.diagnostic(("report", "metrics", i), f"unknown metric {metric!r}"
                                              f"{did_you_mean(metric, allowed)}; allowed: {', '.join(allowed)}"))
    for task in campaign.report.convergence:
        if task not in tasks:
            diagnostics.append(src.diagnostic(("report", "convergence", task), f"no task {task!r} in the spec"
                                              f"{did_you_mean(task, tasks)}; tasks: {', '.join(tasks)}"))
    per_joint = [(("external_torque", "bias"), campaign.external_torque and campaign.external_torque.bias),
                 (("initial_state", "offset"), campaign.initial_state and campaign.initial_state.offset)]
    for at, value in per_joint:
        if isinstance(value, list) and len(value) != robot.nv:
            diagnostics.append(src.diagnostic(at, f"{len(value)} values for {robot.nv} joints: give one value per "
                                              "joint, or one value drawn for each"))
    state = campaign.initial_state
    unbounded = [j for j, lo, hi in zip(robot.joint_names, robot.limits.q_min, robot.limits.q_max)
                 if not (np.isfinite(lo) and np.isfinite(hi))]
    if state is not None and state.within_limits is not None and unbounded:
        diagnostics.append(src.diagnostic(("initial_state", "within_limits"), f"joint {unbounded[0]} has no finite "
                                          "position limits to draw within: give an offset instead"))
    if spec.scenario is None and campaign.duration is None:
        diagnostics.append(src.diagnostic((), "the spec has no scenario: give the runs' `duration` here"))
    if diagnostics:
        raise SpecError(diagnostics)


def check_parameters(driver: SampleRunner) -> dict[str, str]:
    """The swept run-time parameters exist in the spec's controller and their values stay in
    its ranges (its parameter layout, the compiled bundle's too, from the symbolic problem: a
    campaign refused before the C build); returns their units."""
    controller = driver.campaign.controller
    if controller is None or not controller.parameters:
        return {}
    src = driver.campaign.source
    layout = driver.problem.param_layout
    known = [e.name for e in layout.entries]
    diagnostics = []
    for name, value in controller.parameters.items():
        at = ("controller", "parameters", name)
        if name not in known:
            hint = ("the spec declares none: add a `parameters:` section to it (e.g. parameters: {tasks: "
                    "{<task>: [kp, kd]}})" if not known else f"the spec's are: {', '.join(known)}")
            diagnostics.append(src.diagnostic(at, f"{name!r} is not a run-time parameter of the spec"
                                              f"{did_you_mean(name, known)}; {hint}"))
            continue
        entry = layout.entry(name)
        values = value if isinstance(value, list) else [value]
        if isinstance(value, list) and len(value) != entry.size:
            diagnostics.append(src.diagnostic(at, f"{len(value)} values; {name} takes {entry.size} "
                                              f"({', '.join(entry.components)}) or one for all"))
            continue
        for k, d in enumerate(values):
            bounds = d.bounds
            # one distribution for all components: the range every one of them allows
            components = [k] if isinstance(value, list) else range(entry.size)
            low, high = max(entry.lower[c] for c in components), min(entry.upper[c] for c in components)
            below = bounds is not None and (bounds[0] < low or (entry.lower_open and bounds[0] == low))
            if bounds is not None and (below or bounds[1] > high):
                where = at + ((k,) if isinstance(value, list) else ())
                which = f" ({entry.components[k]})" if isinstance(value, list) else \
                    (" (what all its components allow)" if entry.size > 1 else "")
                diagnostics.append(src.diagnostic(where, f"values from {bounds[0]:g} to {bounds[1]:g} leave the "
                                                  f"allowed range {'(' if entry.lower_open else '['}{low:g}, "
                                                  f"{high:g}] {entry.unit}{which}"))
    if diagnostics:
        raise SpecError(diagnostics)
    return {name: layout.entry(name).unit for name in controller.parameters}
