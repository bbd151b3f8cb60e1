"""One sample, run: the sample's spec through the spec's compiled C controller in MuJoCo.

A SampleRunner lives in each worker (a Ray actor, or the serial loop): it reads the spec and the
campaign once, loads each C bundle it needs from the bundle cache once (the driver built them),
and gives every sample a fresh controller workspace and MuJoCo model, as `dcts simulate` does,
so that a sample's numbers are the ones its replay spec gives.
"""

from __future__ import annotations

import math
import traceback
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

from ..analysis.run import analyze
from ..codegen import BundleCache
from ..codegen.loader import CompiledController
from ..files import stop_signal
from ..formulations import ControlProblem, build_problem
from ..sim.mismatch import scaled_robot
from ..sim.runner import Simulation
from ..sim.scenario import resolve_scenario
from ..spec import SpecError
from ..spec.loader import spec_from_data
from ..spec.source import read_yaml
from ..validate import initial_configuration, validate_spec
from .document import load_campaign_text
from .sampling import Sample, Sampler, parameter_columns
from .scenario import JointRange, sample_spec_data

# Summary entries that are not one number per run (or are about the machine, not the controller).
NOT_METRICS = {"units", "relaxed_bounds", "collision_violations", "min_scaling_at", "waypoint_times",
               "task_error_quantity", "mean_acceleration_error", "min_distances", "spec", "runtime", "period",
               "substeps", "integrator", "external_torque_sensing", "realtime_factor", "worst_joints"}


@dataclass(frozen=True)
class CampaignInputs:
    """What every worker needs, as text (a cluster's nodes need not share the files)."""

    spec_file: str
    spec_text: str
    campaign_file: str
    campaign_text: str
    cache_dir: str


class SampleRunner:
    """Runs samples of one campaign on one spec (one per worker)."""

    def __init__(self, inputs: CampaignInputs):
        self.inputs = inputs
        self.data, self.source = read_yaml(inputs.spec_text, inputs.spec_file)
        self.spec = spec_from_data(self.data, self.source)
        self.robot = validate_spec(self.spec).robot
        self.campaign = load_campaign_text(inputs.campaign_text, inputs.campaign_file)
        self.sampler = Sampler(self.campaign, self.robot.nv)
        limits = self.robot.limits
        self.joints = JointRange(initial_configuration(self.spec, self.robot), limits.q_min, limits.q_max,
                                 self.robot.prismatic)
        self.primary_task = min(self.spec.tasks, key=lambda t: t.priority).name
        self._bundles: dict[tuple[str | None, float], Path] = {}

    @cached_property
    def problem(self) -> ControlProblem:
        """The symbolic problem the analysis evaluates: the samples change the scenario (and perhaps
        the formulation), never the tasks, limits or robot it is built from."""
        return build_problem(self.spec, self.robot)

    def bundle(self, formulation: str | None, mass_scale: float) -> Path:
        """The built bundle of the spec's controller for this formulation and mass scale
        (from the cache; built into it if missing)."""
        key = (formulation, mass_scale)
        if key not in self._bundles:
            changes = {"mass_scale": mass_scale} if mass_scale != 1.0 else None
            controller = BundleCache(self.inputs.cache_dir).load(
                self.spec, formulation, robot=scaled_robot(self.robot, mass_scale), model_changes=changes)
            self._bundles[key] = controller.directory
            controller.close()
        return self._bundles[key]

    def spec_data(self, sample: Sample) -> dict[str, Any]:
        return sample_spec_data(self.data, self.campaign, sample, self.joints)

    def sample(self, index: int, parameters: dict[str, Any] | None = None) -> Sample:
        """Sample `index`; `parameters` (an optimizer's trial: run-time parameter values and
        perhaps `formulation`) replace the campaign's."""
        sample = self.sampler.sample(index)
        return _with_parameters(sample, parameters) if parameters else sample

    def run(self, index: int, parameters: dict[str, Any] | None = None) -> dict[str, Any]:
        """The sample's row: index, seed, its values, status (ok, invalid, error) and metrics."""
        sample = self.sample(index, parameters)
        row: dict[str, Any] = {"index": index, "seed": sample.seed, **sample.columns()}
        try:
            spec = spec_from_data(self.spec_data(sample), self.source)
            report = validate_spec(spec)
            scenario = resolve_scenario(spec, report.robot)
        except SpecError as error:
            return row | {"status": "invalid", "error": str(error)}
        formulation = spec.controller.formulation
        runtime = CompiledController(self.bundle(sample.formulation, scenario.mass_scale))
        try:
            sim = Simulation(spec, report.robot, scenario, runtime, scaled_robot(report.robot, scenario.mass_scale),
                             "c", formulation)
            log = sim.run()
            result = analyze(sim, log, problem=self.problem)
        except Exception:  # a bug: recorded with its traceback, the campaign goes on
            if (signum := stop_signal()) is not None:
                # a SIGTERM whose SystemExit landed in CasADi's C code arrives as a SystemError:
                # it was recorded as this sample's error, and the campaign ran to its end
                raise SystemExit(128 + signum) from None
            return row | {"status": "error", "error": traceback.format_exc(limit=8)}
        finally:
            runtime.close()
        return row | {"status": "ok", **metric_columns(result.summary, self.primary_task)}


def metric_columns(summary: dict[str, Any], primary_task: str) -> dict[str, Any]:
    """The run's summary as flat columns: every number, per-task numbers as name.task, and
    primary_rms_error (the first priority's first task)."""
    out: dict[str, Any] = {"formulation": summary["formulation"]}
    for key, value in summary.items():
        if key in NOT_METRICS:
            continue
        if isinstance(value, dict):
            out |= {f"{key}.{k}": _number(v) for k, v in value.items() if isinstance(v, (int, float))}
        elif isinstance(value, (bool, int, float)) or value is None:
            out[key] = _number(value)
    out["primary_rms_error"] = out.get(f"task_rms_error.{primary_task}")
    return out


def _number(value: float | int | bool | None) -> float | int | bool | None:
    """JSON has no NaN or infinity: None for them."""
    if value is None or isinstance(value, (bool, int)):
        return value
    return float(value) if math.isfinite(value) else None


def _with_parameters(sample: Sample, parameters: dict[str, Any]) -> Sample:
    values = dict(sample.values)
    for name, value in parameters.items():
        if name != "formulation":
            values |= parameter_columns(name, value)
    formulation = parameters.get("formulation", sample.formulation)
    return Sample(sample.index, sample.seed, values, formulation, sample.directions)
