"""PNG plots of one run: joints with their limits, torques, task errors, scalings, energies, paths."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..controller import STATUS_LIMITS_RELAXED
from .run import RunResult

LIMIT_COLOR = "#d62728"
DPI = 110
PROJECTIONS = ((0, 1), (0, 2), (1, 2))  # x-y, x-z, y-z


def write_plots(run: RunResult, directory: Path) -> list[Path]:
    """Every plot of a run, as PNG files in `directory`; returns their paths."""
    log, lim = run.log, run.robot.limits
    figures = {
        "joint_positions": joint_figure(run, log.q, lim.q_min, lim.q_max, "q", "rad"),
        "joint_velocities": joint_figure(run, log.dq, -lim.v_max, lim.v_max, "q̇", "rad/s"),
        "torques": joint_figure(run, log.tau, -lim.tau_max, lim.tau_max, "τ", "Nm"),
        "external_torques": external_torque_figure(run),
        "task_errors": task_error_figure(run),
        "scalings": scaling_figure(run),
        "energies": energy_figure(run),
    }
    if run.series.frame_positions:
        figures["end_effector_path"] = path_figure([run])
    paths = []
    for name, figure in figures.items():
        path = directory / f"{name}.png"
        figure.savefig(path, dpi=DPI)
        paths.append(path)
    return paths


def joint_grid(n: int, title: str) -> tuple[Figure, list[Axes]]:
    """One small axes per joint, two columns, shared time axis."""
    rows = math.ceil(n / 2)
    figure = Figure(figsize=(11, 1.9 * rows + 0.6), layout="constrained")
    axes = figure.subplots(rows, 2, sharex=True, squeeze=False).ravel()
    for ax in axes[n:]:
        ax.set_visible(False)
    for ax in axes[max(n - 2, 0): n]:
        # The lowest axes of each column, even above a hidden one, carry the time axis.
        ax.set_xlabel("time [s]")
        ax.xaxis.set_tick_params(labelbottom=True)
    figure.suptitle(title)
    return figure, list(axes[:n])


def shade_limits(ax: Axes, lower: float, upper: float, values: np.ndarray) -> None:
    """Limit lines with the forbidden side shaded; the view keeps both data and limits."""
    finite = [v for v in (lower, upper) if np.isfinite(v)]
    lo = min([float(np.min(values))] + finite) if values.size else min(finite, default=-1.0)
    hi = max([float(np.max(values))] + finite) if values.size else max(finite, default=1.0)
    margin = 0.08 * (hi - lo) or 1.0
    bottom, top = lo - margin, hi + margin
    if np.isfinite(upper):
        ax.axhspan(upper, top, color=LIMIT_COLOR, alpha=0.12, lw=0)
        ax.axhline(upper, color=LIMIT_COLOR, lw=0.8, ls="--")
    if np.isfinite(lower):
        ax.axhspan(bottom, lower, color=LIMIT_COLOR, alpha=0.12, lw=0)
        ax.axhline(lower, color=LIMIT_COLOR, lw=0.8, ls="--")
    ax.set_ylim(bottom, top)


def joint_figure(run: RunResult, values: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                 symbol: str, unit: str) -> Figure:
    names = run.robot.joint_names
    figure, axes = joint_grid(len(names), f"{symbol} per joint, limits shaded — {run.label}")
    for j, ax in enumerate(axes):
        ax.plot(run.log.time, values[:, j], lw=1.0)
        shade_limits(ax, lower[j], upper[j], values[:, j])
        ax.set_ylabel(f"{symbol} [{unit}]")
        ax.set_title(names[j], fontsize=9)
    return figure


def external_torque_figure(run: RunResult) -> Figure:
    names = run.robot.joint_names
    title = f"external joint torque: applied disturbance vs controller input — {run.label}"
    figure, axes = joint_grid(len(names), title)
    for j, ax in enumerate(axes):
        ax.plot(run.log.time, run.log.tau_ext_true[:, j], lw=1.0, label="disturbance")
        ax.plot(run.log.time, run.log.tau_ext_measured[:, j], lw=1.0, ls="--", label="measured")
        ax.set_ylabel("τ_ext [Nm]")
        ax.set_title(names[j], fontsize=9)
    axes[0].legend(fontsize=8)
    return figure


def task_error_figure(run: RunResult) -> Figure:
    errors = {name: e for name, e in run.series.task_errors.items() if np.any(e != 0)}
    rows = max(len(errors), 1)
    figure = Figure(figsize=(9, 2.2 * rows + 0.6), layout="constrained")
    axes = figure.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
    figure.suptitle(f"task errors Δx — {run.label}")
    if not errors:
        axes[0].text(0.5, 0.5, "no task has a reference", ha="center", va="center", transform=axes[0].transAxes)
    for ax, (name, error) in zip(axes, errors.items()):  # one axes even without errors
        for i, row in enumerate(run.row_names[name]):
            ax.plot(run.log.time, error[:, i], lw=1.0, label=row)
        ax.set_title(name, fontsize=9)
        ax.legend(fontsize=7, ncol=min(error.shape[1], 4))
    axes[-1].set_xlabel("time [s]")
    return figure


def scaling_figure(run: RunResult) -> Figure:
    figure = Figure(figsize=(9, 3.2), layout="constrained")
    ax = figure.subplots()
    for i, p in enumerate(run.priorities):
        ax.plot(run.log.time, run.log.scaling[:, i], lw=1.0, label=f"priority {p}")
    status = run.log.status
    for mask, color, label in ((status < 0, LIMIT_COLOR, "fallback torque"),
                               (status == STATUS_LIMITS_RELAXED, "#ff7f0e", "limits relaxed")):
        if mask.any():
            ax.plot(run.log.time[mask], np.full(mask.sum(), -0.05), "|", color=color, label=label)
    ax.set_ylim(-0.1, 1.1)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("task scaling s")
    ax.set_title(f"task scalings (1 = executed fully) — {run.label}")
    ax.legend(fontsize=8)
    return figure


def energy_figure(run: RunResult) -> Figure:
    s, t = run.series, run.log.time
    figure = Figure(figsize=(9, 5.5), layout="constrained")
    top, bottom = figure.subplots(2, 1, sharex=True)
    top.plot(t, s.acceleration_energy, lw=1.0)
    top.set_ylabel("½(τ−g)ᵀM⁻¹(τ−g) [J/s²]")
    top.set_title(f"acceleration energy — {run.label}")
    bottom.plot(t, s.kinetic_energy, lw=1.0, label="total ½q̇ᵀMq̇")
    bottom.plot(t, s.task_kinetic_energy, lw=1.0, label="task space ½ẋᵀΛẋ")
    bottom.plot(t, s.null_kinetic_energy, lw=1.0, label="null space")
    bottom.set_ylabel("kinetic energy [J]")
    bottom.set_xlabel("time [s]")
    bottom.legend(fontsize=8)
    return figure


def path_figure(runs: Sequence[RunResult]) -> Figure:
    """Frame paths in three world projections, with waypoints and Cartesian bounds (first run's)."""
    first = runs[0]
    frames = list(first.series.frame_positions)
    figure = Figure(figsize=(13, 4.2 * len(frames)), layout="constrained")
    axes = figure.subplots(len(frames), 3, squeeze=False)
    figure.suptitle("paths in the world (start ○, end ×)")
    for row, frame in zip(axes, frames, strict=True):
        points = [run.series.frame_positions[frame] for run in runs]
        if first.waypoint_frame == frame and first.waypoint_positions is not None:
            points.append(first.waypoint_positions)
        centre, half = _view_box(np.vstack(points))
        for ax, (a, b) in zip(row, PROJECTIONS, strict=True):
            for run in runs:
                p = run.series.frame_positions[frame]
                line, = ax.plot(p[:, a], p[:, b], lw=1.0, label=run.label if len(runs) > 1 else frame)
                ax.plot(p[:1, a], p[:1, b], "o", mfc="none", color=line.get_color())
                ax.plot(p[-1:, a], p[-1:, b], "x", color=line.get_color())
            if first.waypoint_frame == frame and first.waypoint_positions is not None:
                w = first.waypoint_positions
                ax.plot(w[:, a], w[:, b], "s", ms=4, color="k", mfc="none", label="waypoints")
            for bound in first.robot.cartesian_bounds:
                if bound.frame == frame and bound.axis in (a, b):
                    draw = ax.axvline if bound.axis == a else ax.axhline
                    for c in (bound.c_min, bound.c_max):
                        if np.isfinite(c):
                            draw(c, color=LIMIT_COLOR, ls="--", lw=0.8)
            ax.set_xlabel(f"{'xyz'[a]} [m]")
            ax.set_ylabel(f"{'xyz'[b]} [m]")
            # One scale for the three views, so that their distances compare.
            ax.set_xlim(centre[a] - half, centre[a] + half)
            ax.set_ylim(centre[b] - half, centre[b] + half)
            ax.set_aspect("equal")
            ax.set_title(f"{frame}: {'xyz'[a]}-{'xyz'[b]}", fontsize=9)
        row[0].legend(fontsize=8)
    return figure


def _view_box(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and half-width of a cube around the points, with a margin."""
    finite = points[np.all(np.isfinite(points), axis=1)]
    if not finite.size:
        return np.zeros(3), 1.0
    low, high = finite.min(axis=0), finite.max(axis=0)
    return 0.5 * (low + high), 0.55 * float(np.max(high - low)) + 0.01
