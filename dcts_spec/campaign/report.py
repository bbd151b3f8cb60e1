"""The campaign's report: rates over the samples, the worst cases (each written as a spec that
`dcts simulate` replays), plots of each metric against each swept value, one HTML page.

Rates count the samples that ran (status ok): with a violation (any joint position, velocity,
torque, Cartesian (position or speed) or collision bound crossed by more than
`violation_tolerance`), with a fallback step (status < 0: the fallback torque was applied), with a
relaxed step (status 1), and not converged (diverged, or a task's final error above its
`convergence` tolerance).
"""

from __future__ import annotations

import html
import json
import re
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure

from ..analysis.metrics import json_ready
from .document import ReportSettings
from .results import REPLAYS
from .units import labelled, with_unit

VIOLATIONS = ("max_joint_position_violation", "max_joint_velocity_violation", "max_torque_violation",
              "max_cartesian_violation", "max_cartesian_velocity_violation", "max_collision_violation")
LOWER_IS_WORSE = {"min_scaling", "waypoints_reached", "realtime_factor"}


def rates(rows: list[dict[str, Any]], settings: ReportSettings) -> dict[str, Any]:
    """Counts and fractions of the samples that ran (see the module docstring)."""
    ran = [r for r in rows if r["status"] == "ok"]
    tolerance = settings.violation_tolerance

    def violated(r: dict[str, Any]) -> bool:
        return any((r.get(k) or 0.0) > tolerance for k in VIOLATIONS)

    def converged(r: dict[str, Any]) -> bool:
        return bool(r["completed"]) and all((r.get(f"task_final_error.{task}") or 0.0) <= limit
                                            for task, limit in settings.convergence.items())

    counts = {
        "violation": sum(violated(r) for r in ran),
        "fallback": sum((r.get("solver_failures") or 0) > 0 for r in ran),
        "relaxed": sum((r.get("limits_relaxed") or 0) > 0 for r in ran),
        "not_converged": sum(not converged(r) for r in ran),
    }
    out: dict[str, Any] = {"samples": len(rows), "ran": len(ran),
                           "invalid": sum(r["status"] == "invalid" for r in rows),
                           "errors": sum(r["status"] == "error" for r in rows)}
    for name, count in counts.items():
        out[name] = {"samples": count, "rate": count / len(ran) if ran else None}
    return out


def first_not_run(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The first invalid sample and the first that hit an error, each with its reason: what a
    user reads first when samples did not run (every row keeps its own)."""
    out = {}
    for status in ("invalid", "error"):
        first = next((r for r in rows if r["status"] == status), None)
        if first is not None:
            out[status] = {"index": first["index"], "error": first["error"]}
    return out


def worst_cases(rows: list[dict[str, Any]], metric: str, count: int, tolerance: float) -> list[dict[str, Any]]:
    """The `count` samples with the worst value of `metric` (highest; lowest for a scaling or a
    rate), among those that ran and have it; a violation only beyond `tolerance` (the report's
    violation_tolerance: one within it is no violation in the rates either)."""
    have = [r for r in rows if r["status"] == "ok" and r.get(metric) is not None
            and not (metric in VIOLATIONS and r[metric] <= tolerance)]  # a bound that held is no worst case
    return sorted(have, key=lambda r: (r[metric] if metric in LOWER_IS_WORSE else -r[metric], r["index"]))[:count]


def replay_name(index: int) -> str:
    return f"{REPLAYS}/sample_{index:06d}.yaml"


def summarize_metrics(rows: list[dict[str, Any]], metrics: list[str]) -> dict[str, dict[str, float | None]]:
    """Mean and worst of each metric over the samples that ran."""
    out = {}
    for metric in metrics:
        values = [r[metric] for r in rows if r["status"] == "ok" and r.get(metric) is not None]
        worst = (min if metric in LOWER_IS_WORSE else max)(values) if values else None
        out[metric] = {"mean": sum(values) / len(values) if values else None, "worst": worst}
    return out


def write_plots(rows: list[dict[str, Any]], swept: list[str], metrics: list[str], units: dict[str, str],
                folder: Path) -> list[str]:
    """plots/<value>.png: each metric against one swept value (a point per sample; a per-joint
    value by its norm over the joints), each axis with its unit (`units`: column → unit); the
    names, relative to the campaign folder."""
    ran = [r for r in rows if r["status"] == "ok"]
    written = []
    (folder / "plots").mkdir(exist_ok=True)
    for column in _numeric_columns(ran, swept):
        # No layout engine: constrained layout was most of the time of a report (a second a figure).
        fig = Figure(figsize=(3.3 * len(metrics), 2.8))
        fig.subplots_adjust(left=1.0 / (3.3 * len(metrics)), right=0.98, bottom=0.17, top=0.95, wspace=0.6)
        for ax, metric in zip(fig.subplots(1, len(metrics), squeeze=False)[0], metrics):
            points = [(r[column], r[metric]) for r in ran if r.get(metric) is not None and r.get(column) is not None]
            if points:
                xs, ys = zip(*points)
                ax.scatter(xs, ys, s=6, alpha=0.6, linewidths=0)
            ax.set_xlabel(labelled(column, units), fontsize=8)
            ax.set_ylabel(labelled(metric, units), fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
        name = f"plots/{_file_name(column)}.png"
        fig.savefig(folder / name, dpi=80)
        written.append(name)
    return written


def _numeric_columns(rows: list[dict[str, Any]], swept: list[str]) -> list[str]:
    """The columns of the swept values that vary (a per-joint value: its norm, name.norm)."""
    columns = []
    for name in swept:
        column = name if rows and name in rows[0] else f"{name}.norm"
        values = {r.get(column) for r in rows}
        if len(values) > 1 and all(isinstance(v, (int, float)) for v in values):
            columns.append(column)
    return columns


def _file_name(column: str) -> str:
    """pushes[0].force.magnitude -> pushes_0.force.magnitude"""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", re.sub(r"\[(\d+)\]", r"_\1", column)).strip("_")


def write_html(report: dict[str, Any], plots: list[str], path: Path) -> None:
    """report.html: the rates, the worst cases with their replay commands, the plots."""
    e = html.escape
    rate_rows = "".join(
        f"<tr><td>{e(name)}</td><td>{v['samples']}</td><td>{_percent(v['rate'])}</td></tr>"
        for name, v in report["rates"].items() if isinstance(v, dict))
    units = report["units"]
    worst_rows = "".join(
        f"<tr><td>{e(w['metric'])}</td><td>{e(with_unit(format(w['value'], '.6g'), w['metric'], units))}</td>"
        f"<td>{w['index']}</td><td>{w['seed']}</td><td><code>{e(w['command'])}</code></td></tr>"
        for w in report["worst_cases"])
    metric_rows = "".join(
        f"<tr><td>{e(m)}</td><td>{_g(v['mean'])}</td><td>{_g(v['worst'])}</td><td>{e(units.get(m, ''))}</td></tr>"
        for m, v in report["metrics"].items())
    r = report["rates"]
    t = report["throughput"]
    images = "".join(f'<figure><img src="{e(p)}" alt="{e(p)}"></figure>' for p in plots)
    not_run = "".join(f"<p>First {status} sample ({first['index']}):</p><pre>{e(first['error'].strip())}</pre>"
                      for status, first in report["first_not_run"].items())
    tuned = ""
    if "optimize" in report:
        o = report["optimize"]
        trials = "".join(f"<tr><td>{t['trial']}</td><td>{e(json.dumps(t['values']))}</td><td>{_g(t['value'])}</td></tr>"
                         for t in o["history"])
        tuned = (f"<h2>Tuning: {e(o['objective'])} {e(o['metric'])} ({e(o['direction'])})</h2><p>Best of {o['trials']} "
                 f"trials: <code>{e(json.dumps(o['best']['values']))}</code>, {_g(o['best']['value'])}; the samples "
                 f"below ran with it.</p><table><tr><th>trial</th><th>values</th><th>{e(o['objective'])}</th></tr>"
                 f"{trials}</table>")
    path.write_text(f"""<!doctype html>
<html><head><meta charset="utf-8"><title>{e(report['title'])}</title>
<style>body{{font-family:sans-serif;margin:2em}} table{{border-collapse:collapse;margin:1em 0}}
td,th{{border:1px solid #ccc;padding:.3em .6em;text-align:left}} img{{max-width:100%}}</style></head>
<body><h1>{e(report['title'])}</h1>
<p>{r['samples']} samples: {r['ran']} ran, {r['invalid']} invalid, {r['errors']} errors.
Engine: {e(t['engine'])} ({workers(t['workers'])}), {_g(t['samples_per_second'])} samples/s this run.</p>
{not_run}{tuned}
<h2>Rates (of the samples that ran)</h2><table><tr><th>samples with</th><th>count</th><th>rate</th></tr>{rate_rows}</table>
<h2>Metrics</h2><table><tr><th>metric</th><th>mean</th><th>worst</th><th>unit</th></tr>{metric_rows}</table>
<h2>Worst cases</h2><p>Each replays as a plain <code>dcts simulate</code> (run from the folder the campaign ran in).</p>
<table><tr><th>metric</th><th>value</th><th>sample</th><th>seed</th><th>replay</th></tr>{worst_rows}</table>
<h2>Metrics against the swept values</h2>{images}
</body></html>
""", encoding="utf-8")


def workers(count: int) -> str:
    return f"{count} worker{'' if count == 1 else 's'}"


def _percent(rate: float | None) -> str:
    return "–" if rate is None else f"{100 * rate:.1f} %"


def _g(value: float | None) -> str:
    return "–" if value is None else f"{value:.6g}"


def summary_lines(report: dict[str, Any]) -> list[str]:
    """The report in a few lines for the terminal."""
    r, t = report["rates"], report["throughput"]
    lines = [f"{report['title']}: {report['finished']} of {report['samples']} samples ({r['ran']} ran, "
             f"{r['invalid']} invalid, {r['errors']} errors)"]
    lines += [f"  {name:<14} {v['samples']:>6}  {_percent(v['rate'])}" for name, v in r.items() if isinstance(v, dict)]
    if t["samples"]:
        lines.append(f"  {t['engine']} engine, {workers(t['workers'])}: {t['samples']} samples in {t['seconds']:.1f} s, "
                     f"{t['samples_per_second']:.2f} samples/s (startup {t['startup_seconds']:.1f} s)")
    for status, first in report["first_not_run"].items():
        reason = first["error"].strip().splitlines()
        # a spec error's first line locates it; a traceback's last line says what it was
        lines.append(f"  first {status} sample ({first['index']}): {reason[0] if status == 'invalid' else reason[-1]}")
    for w in report["worst_cases"][:5]:
        value = with_unit(format(w["value"], ".4g"), w["metric"], report["units"])
        lines.append(f"  worst {w['metric']} = {value} (sample {w['index']}): {w['command']}")
    return lines


def save_json(report: dict[str, Any], path: Path) -> None:
    """JSON without NaN or Infinity (a trial scored worst possible): null there, as in the rows."""
    path.write_text(json.dumps(json_ready(report), indent=2, allow_nan=False) + "\n", encoding="utf-8")
