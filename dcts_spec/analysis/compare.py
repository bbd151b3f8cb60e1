"""Several runs of one scenario side by side: a metrics table (Markdown, JSON) and overlay plots."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from .metrics import json_ready
from .outputs import write_run
from .plots import DPI, path_figure, task_error_label
from .run import RunResult

# Rows of the table, in this order; nested metrics get one row per entry.
TABLE_METRICS = (
    "max_joint_position_violation",
    "max_joint_velocity_violation",
    "max_joint_velocity_violation_ratio",
    "max_torque_violation",
    "max_cartesian_violation",
    "solver_failures",
    "bounds_checked",
    "limits_relaxed",
    "min_scaling",
    "task_rms_error",
    "task_mean_error",
    "task_final_error",
    "primary_mean_acceleration_error",
    "acceleration_energy_integral",
    "kinetic_energy_peak",
    "task_space_kinetic_energy_peak",
    "null_space_kinetic_energy_peak",
    "max_disturbance_torque",
    "max_external_torque_estimate_error",
    "waypoints_reached",
    "realtime_factor",
)


def table_rows(runs: Sequence[RunResult]) -> list[tuple[str, str, list[Any]]]:
    """(metric, unit, one value per run) for every scalar and per-task metric."""
    units: dict[str, Any] = {}
    for run in runs:  # the same spec: a metric has the same unit in every run that has it
        units = {**run.summary.get("units", {}), **units}
    rows = []
    for key in TABLE_METRICS:
        values = [run.summary.get(key) for run in runs]
        unit = units.get(key)
        if any(isinstance(v, dict) for v in values):
            names = list(dict.fromkeys(k for v in values if isinstance(v, dict) for k in v))
            rows += [(f"{key}[{name}]", (unit or {}).get(name, ""), [(v or {}).get(name) for v in values])
                     for name in names]
        else:
            rows.append((key, unit or "", values))
    return rows


def markdown_table(runs: Sequence[RunResult]) -> str:
    header = "| metric | unit | " + " | ".join(run.label for run in runs) + " |"
    rule = "|---|---|" + "---:|" * len(runs)
    lines = [header, rule]
    for name, unit, values in table_rows(runs):
        lines.append(f"| {name} | {unit} | " + " | ".join(_format(v) for v in values) + " |")
    return "\n".join(lines) + "\n"


def _format(value: Any) -> str:
    if value is None:
        return "–"
    if isinstance(value, int):  # bool included
        return str(value)
    return f"{value:.4g}"


def write_comparison(runs: Sequence[RunResult], directory: Path, title: str, plots: bool = True) -> None:
    """comparison.md/json, overlay plots (unless `plots` is False), and each run's log and summary in a
    subdirectory."""
    for run in runs:
        write_run(run, directory / run.label, plots=False)
    (directory / "comparison.md").write_text(f"# {title}\n\n{markdown_table(runs)}", encoding="utf-8")
    table = {run.label: run.summary for run in runs}
    (directory / "comparison.json").write_text(json.dumps(json_ready(table), indent=2) + "\n", encoding="utf-8")
    if not plots:
        return
    figures = {
        "compare_task_errors": task_error_overlay(runs),
        "compare_scalings": scaling_overlay(runs),
        "compare_energies": energy_overlay(runs),
        "compare_joint_velocities": velocity_ratio_overlay(runs),
    }
    if runs[0].series.frame_positions:
        figures["compare_end_effector_path"] = path_figure(runs)
    for name, figure in figures.items():
        figure.savefig(directory / f"{name}.png", dpi=DPI)


def task_error_overlay(runs: Sequence[RunResult]) -> Figure:
    names = [n for n in runs[0].series.task_errors if any(np.any(r.series.task_errors[n] != 0) for r in runs)]
    figure = Figure(figsize=(9, 2.3 * max(len(names), 1) + 0.6), layout="constrained")
    axes = figure.subplots(max(len(names), 1), 1, sharex=True, squeeze=False)[:, 0]
    figure.suptitle("task error ‖Δx‖ (pure damping tasks: velocity error ‖ẋ‖)")
    if not names:
        axes[0].text(0.5, 0.5, "no task has a reference", ha="center", va="center", transform=axes[0].transAxes)
    for ax, name in zip(axes, names):  # one axes even without names
        for run in runs:
            ax.plot(run.log.time, np.linalg.norm(run.series.task_errors[name], axis=1), lw=1.0, label=run.label)
        title, ylabel = task_error_label(runs[0], name, "‖Δx‖", "‖ẋ‖")
        ax.set_title(title, fontsize=9)
        ax.set_ylabel(ylabel)
        ax.legend(fontsize=8)
    axes[-1].set_xlabel("time [s]")
    return figure


def scaling_overlay(runs: Sequence[RunResult]) -> Figure:
    priorities = runs[0].priorities
    figure = Figure(figsize=(9, 2.2 * len(priorities) + 0.6), layout="constrained")
    axes = figure.subplots(len(priorities), 1, sharex=True, squeeze=False)[:, 0]
    figure.suptitle("task scaling per priority level (1 = executed fully)")
    for i, (ax, p) in enumerate(zip(axes, priorities, strict=True)):
        for run in runs:
            scaling = run.log.scaling[:, i]
            if np.all(scaling >= 1.0):
                # No flat line at 1 to mistake for a formulation that could scale and did not need to.
                ax.plot([], [], " ", label=f"{run.label}: never scaled")
            else:
                ax.plot(run.log.time, scaling, lw=1.0, label=run.label)
        ax.set_ylim(-0.05, 1.05)
        ax.set_ylabel("s [1]")
        ax.set_title(f"priority {p}: {', '.join(runs[0].series.level_tasks.get(p, ()))}", fontsize=9)
        ax.legend(fontsize=8)
    axes[-1].set_xlabel("time [s]")
    return figure


def energy_overlay(runs: Sequence[RunResult]) -> Figure:
    figure = Figure(figsize=(9, 7.5), layout="constrained")
    task, null, effort = figure.subplots(3, 1, sharex=True)
    for run in runs:
        t, s = run.log.time, run.series
        task.plot(t, s.task_kinetic_energy, lw=1.0, label=run.label)
        null.plot(t, s.null_kinetic_energy, lw=1.0, label=run.label)
        effort.plot(t, np.cumsum(s.acceleration_energy) * run.log.period, lw=1.0, label=run.label)
    task.set_ylabel("task-space T [J]")
    null.set_ylabel("null-space T [J]")
    effort.set_ylabel("∫½(τ−g)ᵀM⁻¹(τ−g)dt [J/s]")
    effort.set_xlabel("time [s]")
    task.set_title("kinetic energy split (task / null space) and accumulated acceleration energy")
    task.legend(fontsize=8)
    return figure


def velocity_ratio_overlay(runs: Sequence[RunResult]) -> Figure:
    figure = Figure(figsize=(9, 3.2), layout="constrained")
    ax = figure.subplots()
    for run in runs:
        ax.plot(run.log.time, np.max(np.abs(run.log.dq) / run.series.limits.joint.v_max, axis=1), lw=1.0, label=run.label)
    ax.axhline(1.0, color="#d62728", ls="--", lw=0.8)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("max_j |q̇_j| / q̇_max,j [1]")
    ax.set_title("joint velocity relative to its limit (worst joint)")
    ax.legend(fontsize=8)
    return figure
