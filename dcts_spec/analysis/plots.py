"""PNG plots of one run: joints with their limits, torques, task errors, scalings, energies, paths,
collision distances."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..controller import STATUS_LIMITS_RELAXED
from ..limits.naming import cartesian_row_name, joint_force_unit, joint_row_name, joint_unit
from .run import RunResult
from .units import per

LIMIT_COLOR = "#d62728"
RELAXED_COLOR = "#ff7f0e"
DPI = 110
PROJECTIONS = ((0, 1), (0, 2), (1, 2))  # x-y, x-z, y-z
# The external-torque axes span at least ±this: a model residual of a few hundredths of a Nm
# stays a flat line near 0 instead of being blown up to the height of a push.
MIN_TORQUE_RANGE = 1.0  # Nm (N for a prismatic joint)


def write_plots(run: RunResult, directory: Path) -> list[Path]:
    """Every plot of a run, as PNG files in `directory`; returns their paths."""
    log, lim = run.log, run.series.limits.joint  # (as run-time parameters set them)
    figures = {
        "joint_positions": joint_figure(run, log.q, lim.q_min, lim.q_max, "q", ""),
        "joint_velocities": joint_figure(run, log.dq, -lim.v_max, lim.v_max, "q̇", "s"),
        "torques": joint_figure(run, log.tau, -lim.tau_max, lim.tau_max, "τ", None),
        "external_torques": external_torque_figure(run),
        "task_errors": task_error_figure(run),
        "scalings": scaling_figure(run),
        "energies": energy_figure(run),
    }
    if run.series.frame_positions:
        figures["end_effector_path"] = path_figure([run])
    if run.collision.pairs:
        figures["collision_distances"] = distance_figure(run)
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


def shade_limits(ax: Axes, time: np.ndarray, lower: np.ndarray, upper: np.ndarray, values: np.ndarray) -> None:
    """Limit lines with the forbidden side shaded, following the limits in force at each sample
    (run-time parameters may narrow them); the view keeps both data and limits."""
    finite = [float(v) for v in (*lower, *upper) if np.isfinite(v)]
    lo = min([float(np.min(values))] + finite) if values.size else min(finite, default=-1.0)
    hi = max([float(np.max(values))] + finite) if values.size else max(finite, default=1.0)
    margin = 0.08 * (hi - lo) or 1.0
    bottom, top = lo - margin, hi + margin
    for limit, edge in ((upper, top), (lower, bottom)):
        if not limit.size or not np.isfinite(limit).all():
            continue  # (a limit is finite at every sample or at none: parameters only narrow one that exists)
        if np.all(limit == limit[0]):
            ax.axhspan(min(limit[0], edge), max(limit[0], edge), color=LIMIT_COLOR, alpha=0.12, lw=0)
            ax.axhline(limit[0], color=LIMIT_COLOR, lw=0.8, ls="--")
        else:
            ax.fill_between(time, limit, edge, step="post", color=LIMIT_COLOR, alpha=0.12, lw=0)
            ax.step(time, limit, where="post", color=LIMIT_COLOR, lw=0.8, ls="--")
    ax.set_ylim(bottom, top)


def joint_quantity_unit(run: RunResult, j: int, per_time: str | None) -> str:
    """Joint j's unit of position (per_time ""), of its rate (per_time "s"), or of force (None)."""
    if per_time is None:
        return joint_force_unit(run.robot, j)
    unit = joint_unit(run.robot, j)
    return per(unit, per_time) if per_time else unit


def mark_steps(ax: Axes, time: np.ndarray, mask: np.ndarray, label: str, color: str = RELAXED_COLOR) -> None:
    """Ticks along the bottom of the axes at the steps in `mask` (nothing if there are none)."""
    if mask.any():
        ax.plot(time[mask], np.full(int(mask.sum()), 0.03), "|", ms=7, color=color, label=label,
                transform=ax.get_xaxis_transform())


def relaxed_steps(run: RunResult, row_name: str) -> np.ndarray:
    """The steps at which the bound `row_name` gave way (none if the controller has no such row)."""
    log = run.log
    if row_name not in log.bound_names:
        return np.zeros(log.steps, dtype=bool)
    return log.relaxed[:, log.bound_names.index(row_name)]


def joint_figure(run: RunResult, values: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                 symbol: str, per_time: str | None) -> Figure:
    """One axes per joint with its limits shaded and the steps its bound gave way marked; `lower`,
    `upper` (samples, joints): the limits in force; `per_time` as in `joint_quantity_unit`."""
    names = run.robot.joint_names
    figure, axes = joint_grid(len(names), f"{symbol} per joint, limits shaded — {run.label}")
    for j, ax in enumerate(axes):
        ax.plot(run.log.time, values[:, j], lw=1.0)
        shade_limits(ax, run.log.time, lower[:, j], upper[:, j], values[:, j])
        ax.set_ylabel(f"{symbol} [{joint_quantity_unit(run, j, per_time)}]")
        ax.set_title(names[j], fontsize=9)
        mark_steps(ax, run.log.time, relaxed_steps(run, joint_row_name(names[j])), "bound relaxed")
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    return figure


def external_torque_figure(run: RunResult) -> Figure:
    """Applied external torque (disturbances and the payloads the controller does not know) and
    the τ_ext the controller used (0 when it ignores τ_ext), each joint on a scale of at least
    ±MIN_TORQUE_RANGE; the title gives how far that input was off (one step late, see metrics)."""
    names, t = run.robot.joint_names, run.log.time
    applied = run.log.tau_ext_true + run.series.payload_torque
    used = run.series.tau_ext_used
    title = f"external joint torque: applied (disturbances, payloads) vs the τ_ext the controller used — {run.label}"
    figure, axes = joint_grid(len(names), title)
    for j, ax in enumerate(axes):
        ax.plot(t, applied[:, j], lw=1.0, label="applied")
        if np.any(run.series.payload_torque[:, j]):
            ax.plot(t, run.series.payload_torque[:, j], lw=0.8, ls=":", label="of which payloads")
        ax.plot(t, used[:, j], lw=1.0, ls="--", label="controller input (τ_ext used)")
        ax.axhline(0.0, color="0.6", lw=0.5)
        both = np.concatenate([applied[:, j], used[:, j]])
        ax.set_ylim(min(1.08 * float(np.min(both, initial=0.0)), -MIN_TORQUE_RANGE),
                    max(1.08 * float(np.max(both, initial=0.0)), MIN_TORQUE_RANGE))
        unit = joint_quantity_unit(run, j, None)
        off = float(np.max(np.abs(used[1:, j] - applied[:-1, j]), initial=0.0))
        ax.set_ylabel(f"τ_ext [{unit}]")
        ax.set_title(f"{names[j]} (input off by ≤ {off:.2g} {unit})", fontsize=9)
    axes[0].legend(fontsize=8)
    return figure


def task_error_label(run: RunResult, name: str, symbol: str = "Δx", damping_symbol: str = "−ẋ") -> tuple[str, str]:
    """(title, y label) of a task's error axes: a damping task's is its velocity error."""
    unit = run.series.task_units[name]
    if name in run.series.damping:
        return f"{name} — damping (velocity error)", f"{damping_symbol} [{unit}]"
    return name, f"{symbol} [{unit}]"


def task_error_figure(run: RunResult) -> Figure:
    errors = {name: e for name, e in run.series.task_errors.items() if np.any(e != 0)}
    rows = max(len(errors), 1)
    figure = Figure(figsize=(9, 2.2 * rows + 0.6), layout="constrained")
    axes = figure.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
    figure.suptitle(f"task errors Δx (pure damping tasks: velocity error) — {run.label}")
    if not errors:
        axes[0].text(0.5, 0.5, "no task has a reference", ha="center", va="center", transform=axes[0].transAxes)
    relaxed = run.log.status == STATUS_LIMITS_RELAXED
    for ax, (name, error) in zip(axes, errors.items()):  # one axes even without errors
        for i, row in enumerate(run.row_names[name]):
            ax.plot(run.log.time, error[:, i], lw=1.0, label=row)
        title, ylabel = task_error_label(run, name)
        ax.set_title(title, fontsize=9)
        ax.set_ylabel(ylabel)
        mark_steps(ax, run.log.time, relaxed, "limits relaxed")
        ax.legend(fontsize=7, ncol=min(error.shape[1] + 1, 4))
    axes[-1].set_xlabel("time [s]")
    return figure


def scaling_figure(run: RunResult) -> Figure:
    figure = Figure(figsize=(9, 3.2), layout="constrained")
    ax = figure.subplots()
    for i, p in enumerate(run.priorities):
        never = " (never scaled)" if np.all(run.log.scaling[:, i] >= 1.0) else ""
        ax.plot(run.log.time, run.log.scaling[:, i], lw=1.0, label=f"priority {p}{never}")
    status = run.log.status
    mark_steps(ax, run.log.time, status < 0, "fallback torque", LIMIT_COLOR)
    mark_steps(ax, run.log.time, status == STATUS_LIMITS_RELAXED, "limits relaxed")
    ax.set_ylim(-0.1, 1.1)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("task scaling s [1]")
    ax.set_title(f"task scalings (1 = executed fully) — {run.label}")
    ax.legend(fontsize=8)
    return figure


# The collision plot names this many pairs, the closest; the others are thin grey lines.
LABELLED_PAIRS = 8


def distance_figure(run: RunResult) -> Figure:
    """Each watched pair's signed distance over time with its minimum (dashed, the forbidden side
    shaded): the pairs that came closest in colour and named, the others grey."""
    t, distances = run.log.time, run.distances
    figure = Figure(figsize=(9, 4.2), layout="constrained")
    ax = figure.subplots()
    margins = distances.min(axis=0) - np.array([p.min_distance for p in run.collision.pairs])
    closest = set(np.argsort(margins)[:LABELLED_PAIRS].tolist())
    for j, pair in enumerate(run.collision.pairs):
        if j in closest:
            ax.plot(t, distances[:, j], lw=1.1, label=f"{pair.a.name}–{pair.b.name}", zorder=3)
        else:
            ax.plot(t, distances[:, j], lw=0.5, color="0.75", zorder=2)
    lowest = min(p.min_distance for p in run.collision.pairs)
    for d_min in sorted({p.min_distance for p in run.collision.pairs}):
        ax.axhline(d_min, color=LIMIT_COLOR, lw=0.8, ls="--")
    top = min(float(np.max(distances)), 2.0 * run.collision.activation_distance)
    bottom = min(float(np.min(distances)), 0.0) - 0.05 * top
    ax.axhspan(bottom, lowest, color=LIMIT_COLOR, alpha=0.12, lw=0)
    ax.set_ylim(bottom, top)
    relaxed = np.any([relaxed_steps(run, p.name) for p in run.collision.pairs], axis=0)
    mark_steps(ax, t, relaxed, "a distance bound relaxed")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("signed distance [m]")
    ax.set_title(f"collision pairs: distance and minimum (dashed) — {run.label}")
    ax.legend(fontsize=7, ncol=2)
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
            for run in runs:
                relaxed = _frame_relaxed(run, frame)
                if relaxed.any():
                    p = run.series.frame_positions[frame][relaxed]
                    ax.plot(p[:, a], p[:, b], ".", ms=3, color=RELAXED_COLOR,
                            label="bound relaxed" if len(runs) == 1 else f"{run.label}: bound relaxed")
            limits = first.series.limits
            for i, bound in enumerate(first.robot.cartesian_bounds):
                if bound.frame == frame and bound.axis in (a, b):
                    draw = ax.axvline if bound.axis == a else ax.axhline
                    # as compiled (dashed) and, dotted, the narrowest a run-time parameter made it
                    for c, narrowest in ((bound.c_min, np.max(limits.c_min[:, i], initial=-np.inf)),
                                         (bound.c_max, np.min(limits.c_max[:, i], initial=np.inf))):
                        if np.isfinite(c):
                            draw(c, color=LIMIT_COLOR, ls="--", lw=0.8)
                        if narrowest != c:
                            draw(narrowest, color=LIMIT_COLOR, ls=":", lw=0.8)
            ax.set_xlabel(f"{'xyz'[a]} [m]")
            ax.set_ylabel(f"{'xyz'[b]} [m]")
            # One scale for the three views, so that their distances compare.
            ax.set_xlim(centre[a] - half, centre[a] + half)
            ax.set_ylim(centre[b] - half, centre[b] + half)
            ax.set_aspect("equal")
            ax.set_title(f"{frame}: {'xyz'[a]}-{'xyz'[b]}", fontsize=9)
        row[0].legend(fontsize=8)
    return figure


def _frame_relaxed(run: RunResult, frame: str) -> np.ndarray:
    """The steps at which a Cartesian bound of `frame` gave way."""
    mask = np.zeros(run.log.steps, dtype=bool)
    for bound in run.robot.cartesian_bounds:
        if bound.frame == frame:
            mask |= relaxed_steps(run, cartesian_row_name(bound))
    return mask


def _view_box(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and half-width of a cube around the points, with a margin."""
    finite = points[np.all(np.isfinite(points), axis=1)]
    if not finite.size:
        return np.zeros(3), 1.0
    low, high = finite.min(axis=0), finite.max(axis=0)
    return 0.5 * (low + high), 0.55 * float(np.max(high - low)) + 0.01
