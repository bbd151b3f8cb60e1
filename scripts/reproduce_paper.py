#!/usr/bin/env python3
"""Reproduce the paper's five experiments with dcts and check its claims by numbers.

    .venv/bin/python scripts/reproduce_paper.py [--out DIR] [--runtime c|python] [--short]
                                                [--docs DIR | --no-docs] [--only exp1,exp3]

Runs every comparison of the paper on the specs of `specs/paper/` (through the package API,
the same closed loop as `dcts compare`):

    exp1  null-space energy, no force          osc, qp_mt, qp_md
    exp2  10 N push while holding the drill     osc, qp_mt, qp_md, dcts (+ the same runs without
                                                the push, to isolate the push's effect)
    exp3  octagon under joint/torque limits     projector (SNS, with its joint acceleration limit
          at the text's 0.85 m/s (Table II)      of 20 rad/s²), dcts, dcts with the same limit
    exp4  hand guiding toward the limits        dcts with τ_ext measured / ignored (two spec files)
    exp5  unmodelled 4.1 kg payload, 1 s        dcts, osc, qp_md (each claim judged over [0, t] for
                                                every t, and over the whole second)

and, on full runs, the sensitivity studies the doc discusses (the baseline's acceleration limit,
v_sat = 0.4 m/s, MuJoCo's default integrator, the payload's centre of mass).

Writes:
- DIR/<experiment>/: `dcts compare`'s output per experiment (comparison.md/json, overlay
  plots, one folder per run with summary.json and log.npz); for the octagon runs also
  DIR/<experiment>/<run>/table2.npz, the per-sample series Table II's numbers are means of
  (dcts_spec/analysis/paper_metrics.py);
- the docs directory (default docs/paper_reproduction/ on full runs, DIR/docs with --short):
  results.json (every figure and claim verdict), the PNG plots the doc links to, tables.md;
  on full runs the generated blocks of docs/paper_reproduction.md (between
  `<!-- BEGIN GENERATED: key -->` and `<!-- END GENERATED: key -->`) are rewritten.

The analysis functions (`analyze_exp1` … `analyze_exp5`) take {label: RunResult} and return
{"metrics": …, "claims": [...]}; tests/test_paper_claims.py runs shortened experiments through
the same functions.
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import shutil
import subprocess
import sys
import time
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import yaml
from matplotlib.figure import Figure

from dcts_spec.analysis.compare import write_comparison
from dcts_spec.analysis.metrics import json_ready
from dcts_spec.analysis.paper_metrics import SaturatedLaw, path_samples, table2_series
from dcts_spec.analysis.run import RunResult, analyze
from dcts_spec.sim.runner import prepare_simulation
from dcts_spec.sim.runtime import RuntimeUnavailable
from dcts_spec.spec import load_spec
from dcts_spec.spec.loader import load_spec_text

ROOT = Path(__file__).resolve().parents[1]
SPECS = ROOT / "specs" / "paper"
DOCS_DIR = ROOT / "docs" / "paper_reproduction"
DOC = ROOT / "docs" / "paper_reproduction.md"
DPI = 100

# -- what is run ---------------------------------------------------------------------------------



@dataclass(frozen=True)
class Run:
    """One closed-loop run: a spec of specs/paper/, a formulation, optional changes to the spec."""

    label: str
    spec: str
    formulation: str | None = None
    overrides: tuple[tuple[tuple[Any, ...], Any], ...] = ()  # ((key path), value) applied to the YAML data


def _no_push() -> tuple:
    return ((("scenario", "disturbances"), []),)


def _without_gravity() -> tuple:
    """QP-MT's other reading: minimize ‖τ − g‖² instead of ‖τ‖²."""
    return ((("controller", "minimized_torque"), "without_gravity"),)


# The projector baseline's joint acceleration limit, rad/s²: SNS (Flacco et al. 2015) saturates
# joint accelerations within a box that includes its own |q̈| ≤ A_max; with Table I's limits alone
# nothing in that box reflects the torque limits and the baseline diverges at the first vertex.
SNS_ACCELERATION_LIMIT = 20.0


def _acceleration_limit(value: float) -> tuple:
    return ((("limits", "joint_acceleration"), {"max": value, "unit": "rad/s^2"}),)


def _octagon_runs(extra: tuple = ()) -> list[Run]:
    """Experiment 3's comparison: the baseline with its acceleration limit, DCTS with Table I's
    limits only, and DCTS with the baseline's acceleration limit too."""
    sns = _acceleration_limit(SNS_ACCELERATION_LIMIT)
    return [Run("projector", "exp3_octagon.yaml", "projector", sns + extra),
            Run("dcts", "exp3_octagon.yaml", "dcts", extra),
            Run("dcts_a20", "exp3_octagon.yaml", "dcts", sns + extra)]


EXPERIMENTS: dict[str, dict[str, Any]] = {
    "exp1": {
        "title": "Experiment 1: null-space energy without external force",
        "runs": [Run(f, "exp1_null_space_energy.yaml", f) for f in ("osc", "qp_mt", "qp_md")]
        + [Run("qp_mt_without_gravity", "exp1_null_space_energy.yaml", "qp_mt", _without_gravity())],
        "short": 1.0,
    },
    "exp2": {
        "title": "Experiment 2: 10 N push while holding the drill perpendicular to the table",
        "runs": [Run(f, "exp2_push.yaml", f) for f in ("osc", "qp_mt", "qp_md", "dcts")]
        + [Run(f"{f}_no_push", "exp2_push.yaml", f, _no_push()) for f in ("osc", "qp_mt", "qp_md", "dcts")],
        "short": 1.4,  # the push is [0.5, 0.9) s; the analysis looks until 0.5 s after it (or the end)
    },
    "exp3": {
        "title": "Experiment 3: octagon tracking under joint and torque limits",
        "runs": _octagon_runs(),
        # centre → vertex 1 → centre; the first turn at vertex 1 already saturates torques
        "short": {"duration": 2.5, "points": 3},
    },
    "exp4": {
        "title": "Experiment 4: hand guiding toward the limits, τ_ext measured vs ignored",
        "runs": [Run("measured", "exp4_hand_guiding.yaml", "dcts"),
                 Run("ignored", "exp4_hand_guiding_ignored.yaml", "dcts")],
        "short": 1.3,  # the first push only (joint 5 to its minimum, joint 2 to its maximum)
    },
    "exp5": {
        "title": "Experiment 5: unmodelled 4.1 kg payload",
        "runs": [Run(f, "exp5_payload.yaml", f) for f in ("dcts", "osc", "qp_md")],
        # no shortened version: the claims are about the whole second (3 × 1 s runs, ~6 s in Python)
    },
}


def _vsat(value: float) -> tuple:
    return ((("tasks", 0, "gains", "max_velocity"), value),)


def _payload_com(com: list[float]) -> tuple:
    return ((("scenario", "payloads"), [{"frame": "tool", "mass": 4.1, "com": com}]),)


SENSITIVITY: dict[str, dict[str, Any]] = {
    "exp3_acceleration_limit": {
        "title": "Experiment 3: the baseline without its acceleration limit (Table I only), and 40 rad/s² for both",
        "runs": [Run("projector_table_i", "exp3_octagon.yaml", "projector"),
                 Run("projector_a40", "exp3_octagon.yaml", "projector", _acceleration_limit(40.0)),
                 Run("dcts_a40", "exp3_octagon.yaml", "dcts", _acceleration_limit(40.0))],
        "short": {"duration": 1.6, "points": 3},  # the baseline without the limit blows up leaving vertex 1
    },
    "exp3_vsat_0.4": {
        "title": "Experiment 3 with v_sat = 0.4 m/s (the value the text gives for v_sat)",
        "runs": _octagon_runs(_vsat(0.4) + ((("scenario", "duration"), 16.0),))
        + [Run("projector_table_i", "exp3_octagon.yaml", "projector", _vsat(0.4) + ((("scenario", "duration"), 16.0),))],
    },
    "exp4_semi_implicit": {
        "title": "Experiment 4 with MuJoCo's default semi-implicit integrator (one step per control period)",
        "runs": [Run("measured", "exp4_hand_guiding.yaml", "dcts", ((("scenario", "integrator"), "implicitfast"),)),
                 Run("ignored", "exp4_hand_guiding_ignored.yaml", "dcts",
                     ((("scenario", "integrator"), "implicitfast"),))],
    },
    "exp1_semi_implicit": {
        "title": "Experiment 1, QP-MT with MuJoCo's default semi-implicit integrator",
        "runs": [Run("qp_mt", "exp1_null_space_energy.yaml", "qp_mt", ((("scenario", "integrator"), "implicitfast"),))],
    },
    "exp5_payload_com": {
        "title": "Experiment 5 with the payload's centre of mass 0.1 m off the tool point (0.3 s)",
        "runs": [Run(f"{f}_com_{name}", "exp5_payload.yaml", f,
                     _payload_com(com) + ((("scenario", "duration"), 0.3),))
                 for name, com in (("+x", [0.1, 0, 0]), ("-x", [-0.1, 0, 0]), ("+y", [0, 0.1, 0]), ("-y", [0, -0.1, 0]))
                 for f in ("qp_md", "dcts")],
    },
}
SHORT_SENSITIVITY = ("exp3_acceleration_limit",)  # also run by --short: the baseline's divergence


def study(key: str) -> dict[str, Any]:
    """An experiment or a sensitivity study by its key."""
    return EXPERIMENTS.get(key) or SENSITIVITY[key]


# -- running ---------------------------------------------------------------------------------------

def _apply(data: dict, overrides: Iterable[tuple[tuple[Any, ...], Any]]) -> dict:
    data = copy.deepcopy(data)
    for path, value in overrides:
        node = data
        for key in path[:-1]:
            node = node.setdefault(key, {}) if isinstance(node, dict) else node[key]
        node[path[-1]] = copy.deepcopy(value)
    return data


def load_run_spec(run: Run, extra: Iterable[tuple[tuple[Any, ...], Any]] = ()):
    """The run's spec: the file itself, or the file's data with the run's overrides."""
    path = SPECS / run.spec
    overrides = tuple(run.overrides) + tuple(extra)
    if not overrides:
        return load_spec(path)
    data = _apply(yaml.safe_load(path.read_text(encoding="utf-8")), overrides)
    return load_spec_text(yaml.safe_dump(data, sort_keys=False, allow_unicode=True), str(path))


def simulate(run: Run, runtime: str = "c", duration: float | None = None,
             extra: Iterable[tuple[tuple[Any, ...], Any]] = ()) -> RunResult:
    """Simulate one run (C runtime falls back to Python when it cannot be built here)."""
    spec = load_run_spec(run, extra)
    try:
        sim = prepare_simulation(spec, runtime=runtime, formulation=run.formulation, duration=duration)
    except RuntimeUnavailable as error:
        warnings.warn(f"{run.spec} {run.formulation}: {error}; using the Python runtime", stacklevel=2)
        sim = prepare_simulation(spec, runtime="python", formulation=run.formulation, duration=duration)
    return analyze(sim, sim.run(), label=run.label)


def short_settings(key: str) -> tuple[float | None, tuple]:
    """(duration, spec changes) of a shortened experiment: a duration, and for the octagon its
    first points only."""
    short = study(key).get("short")
    if not isinstance(short, dict):
        return short, ()
    data = yaml.safe_load((SPECS / "exp3_octagon.yaml").read_text(encoding="utf-8"))
    points = data["scenario"]["waypoints"]["points"][: short["points"]]
    return short["duration"], ((("scenario", "waypoints", "points"), points),)


def run_experiment(key: str, runtime: str, short: bool, runs: list[Run] | None = None) -> dict[str, RunResult]:
    """Simulate an experiment's (or a sensitivity study's) runs; `short`: the shortened version."""
    duration, extra = short_settings(key) if short else (None, ())
    return {r.label: simulate(r, runtime, duration, extra) for r in (runs or study(key)["runs"])}


# -- small helpers -----------------------------------------------------------------------------------

def _norms(a: np.ndarray) -> np.ndarray:
    return np.linalg.norm(a, axis=1)


def _task_error(run: RunResult) -> np.ndarray:
    """‖Δx‖ per sample of the run's first task (the one each experiment is about)."""
    return _norms(next(iter(run.series.task_errors.values())))


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float | None:
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na < 1e-12 or nb < 1e-12:
        return None
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b) / (na * nb), -1.0, 1.0))))


def _index(run: RunResult, t: float) -> int:
    return int(np.clip(round(t / run.log.period), 0, run.log.steps - 1))


def _tool(run: RunResult) -> np.ndarray:
    return run.series.frame_positions["tool"]


def _tau_at_limit(run: RunResult, tol: float = 1e-3) -> np.ndarray:
    """Samples where some applied torque is at its limit (within tol Nm)."""
    return np.any(np.abs(run.log.tau) >= run.robot.limits.tau_max - tol, axis=1)


def _recently(mask: np.ndarray, steps: int) -> np.ndarray:
    """mask, widened to the `steps` samples after each True sample."""
    out = mask.copy()
    for k in range(1, steps + 1):
        out[k:] |= mask[:-k]
    return out


def claim(cid: str, statement: str, paper: str, measured: str, holds: bool, criterion: str) -> dict[str, Any]:
    return {"id": cid, "statement": statement, "paper": paper, "measured": measured, "holds": bool(holds),
            "criterion": criterion}


def common_metrics(run: RunResult) -> dict[str, Any]:
    s = run.summary
    return {
        "formulation": s["formulation"],
        "runtime": s["runtime"],
        "duration": s["duration"],
        "completed": s["completed"],
        "max_joint_position_violation": s["max_joint_position_violation"],
        "max_joint_velocity_violation_ratio": s["max_joint_velocity_violation_ratio"],
        "max_torque_violation": s["max_torque_violation"],
        "solver_failures": s["solver_failures"],
        "limits_relaxed": s["limits_relaxed"],
        "min_scaling": s["min_scaling"],
        "acceleration_energy_integral": s["acceleration_energy_integral"],
        "kinetic_energy_peak": s["kinetic_energy_peak"],
        "task_space_kinetic_energy_peak": s["task_space_kinetic_energy_peak"],
        "null_space_kinetic_energy_peak": s["null_space_kinetic_energy_peak"],
    }


# -- experiment 1 --------------------------------------------------------------------------------------

def analyze_exp1(runs: dict[str, RunResult]) -> dict[str, Any]:
    metrics = {}
    for label, r in runs.items():
        t, T = r.log.time, r.log.duration
        span = min(1.0, T / 3)
        null, task = r.series.null_kinetic_energy, r.series.task_kinetic_energy
        err = _task_error(r)
        first, last = t < span, t >= T - span
        tool = _tool(r)
        transient = t < 0.3
        metrics[label] = common_metrics(r) | {
            "window_s": span,
            "task_space_ke_peak_first_0.3s": float(task[transient].max()),
            "null_space_ke_first_window_mean": float(null[first].mean()),
            "null_space_ke_last_window_mean": float(null[last].mean()),
            "null_space_ke_peak_time": float(t[np.argmax(null)]),
            "null_space_ke_at_0.1s": float(null[_index(r, 0.1)]),
            "task_error_initial": float(err[0]),
            "task_error_final": float(err[-1]),
            "task_error_max": float(err.max()),
            "tool_displacement_final": (tool[-1] - tool[0]).tolist(),
        }
    osc, md = metrics["osc"], metrics["qp_md"]
    claims = []
    ratio_osc = osc["null_space_kinetic_energy_peak"] / max(osc["task_space_kinetic_energy_peak"], 1e-12)
    claims.append(claim(
        "exp1.osc_null_space_zero", "OSC's null-space kinetic energy stays ≈ 0",
        "OSC shows 0 null-space energy",
        f"OSC null-space KE peak {osc['null_space_kinetic_energy_peak']:.2e} J = {100 * ratio_osc:.2g} % of its "
        f"task-space KE peak ({osc['task_space_kinetic_energy_peak']:.2e} J); mean over the first / last "
        f"{osc['window_s']:.2g} s: {osc['null_space_ke_first_window_mean']:.1e} / "
        f"{osc['null_space_ke_last_window_mean']:.1e} J "
        "(a residual drift from the discretization, then constant: the null space is passive)",
        ratio_osc <= 0.02,
        "null-space KE peak ≤ 2 % of the task-space KE peak"))
    damped = md["null_space_ke_last_window_mean"] / max(md["null_space_kinetic_energy_peak"], 1e-30)
    claims.append(claim(
        "exp1.qp_md_damps_at_higher_energy",
        "QP-MD dissipates its null-space energy, at a higher acceleration energy than OSC",
        "QP-MD reduces the null-space kinetic energy, but the total energy spent is much higher",
        f"QP-MD null-space KE peak {md['null_space_kinetic_energy_peak']:.3g} J, last-window mean "
        f"{md['null_space_ke_last_window_mean']:.1e} J; ∫acceleration energy QP-MD "
        f"{md['acceleration_energy_integral']:.3g}, OSC {osc['acceleration_energy_integral']:.3g}",
        damped <= 0.01 and md["acceleration_energy_integral"] > 2 * osc["acceleration_energy_integral"],
        "last-window mean ≤ 1 % of the peak, ∫acceleration energy > 2 × OSC's"))
    for label in (k for k in QP_MT_READINGS if k in metrics):
        claims += _qp_mt_claims(metrics, label)
    return {"metrics": metrics, "claims": claims}


# QP-MT's two readings: r = ‖τ‖² (eq. (3) as written, gravity included) and r = ‖τ − g‖²
QP_MT_READINGS = {"qp_mt": ("", "‖τ‖²"), "qp_mt_without_gravity": ("_without_gravity", "‖τ − g‖²")}


def _qp_mt_claims(metrics: dict[str, Any], label: str) -> list[dict[str, Any]]:
    """The claims that involve QP-MT, for one reading of its regularization."""
    suffix, norm = QP_MT_READINGS[label]
    osc, mt, md = metrics["osc"], metrics[label], metrics["qp_md"]
    name = f"QP-MT (r = {norm})"
    ratio_mt = mt["null_space_kinetic_energy_peak"] / max(osc["null_space_kinetic_energy_peak"], 1e-12)
    task_peaks = {k: metrics[k]["task_space_ke_peak_first_0.3s"] for k in ("osc", label, "qp_md")}
    spread = max(task_peaks.values()) / max(min(task_peaks.values()), 1e-12)
    converged = {k: metrics[k]["task_error_final"] / max(metrics[k]["task_error_initial"], 1e-12) for k in task_peaks}
    return [
        claim(f"exp1.qp_mt{suffix}_null_space_grows", f"{name}'s null-space kinetic energy grows (OSC's does not)",
              "QP-MT shows an energy that increases over time",
              f"{name} null-space KE rises from 0 to {mt['null_space_ke_at_0.1s']:.2g} J at 0.1 s and peaks at "
              f"{mt['null_space_kinetic_energy_peak']:.3g} J (t = {mt['null_space_ke_peak_time']:.2f} s), "
              f"{ratio_mt:.3g}× OSC's peak and "
              f"{mt['null_space_kinetic_energy_peak'] / max(mt['task_space_kinetic_energy_peak'], 1e-12):.2g}× its "
              f"own task-space KE peak; last/first window mean "
              f"{mt['null_space_ke_last_window_mean'] / max(mt['null_space_ke_first_window_mean'], 1e-30):.2g}; "
              f"tool z at the end {mt['tool_displacement_final'][2]:+.3f} m",
              ratio_mt >= 100 and mt["null_space_kinetic_energy_peak"] >= 10 * mt["task_space_kinetic_energy_peak"],
              "null-space KE peak ≥ 100 × OSC's and ≥ 10 × its own task-space KE peak"),
        claim(f"exp1.same_task_energy{suffix}",
              f"OSC, {name} and QP-MD reach the target with about the same task-space kinetic energy",
              "all three solve the task (error → 0); task-space KE approximately the same, converging to 0",
              "task-space KE peaks during the rotation (first 0.3 s) "
              + ", ".join(f"{k} {v:.3g} J" for k, v in task_peaks.items())
              + f" (max/min {spread:.2f}); final/initial task error "
              + ", ".join(f"{k} {v:.1e}" for k, v in converged.items()),
              spread <= 1.25 and max(converged.values()) <= 0.05,
              "task-space KE peaks of the first 0.3 s within a factor 1.25, final task error ≤ 5 % of the initial one"),
        claim(f"exp1.qp_md_energy_above_qp_mt{suffix}", f"QP-MD spends more energy than {name}",
              "the total energy spent [by QP-MD] is much higher than minimizing the norm of the torque",
              f"∫acceleration energy QP-MD {md['acceleration_energy_integral']:.3g} vs {name} "
              f"{mt['acceleration_energy_integral']:.3g}; kinetic energy peak QP-MD {md['kinetic_energy_peak']:.3g} J "
              f"vs {mt['kinetic_energy_peak']:.3g} J",
              md["acceleration_energy_integral"] > mt["acceleration_energy_integral"],
              f"QP-MD's ∫acceleration energy > {name}'s"),
    ]


# -- experiment 2 --------------------------------------------------------------------------------------

def push_of(spec_file: str = "exp2_push.yaml") -> dict[str, Any]:
    data = yaml.safe_load((SPECS / spec_file).read_text(encoding="utf-8"))
    d = data["scenario"]["disturbances"][0]
    return {"start": float(d["start"]), "end": float(d["start"] + d["duration"]), "force": np.array(d["force"], float),
            "body": d["body"], "point": np.array(d.get("point", [0, 0, 0]), float)}


def mobility(run: RunResult, q: np.ndarray, frame: str = "tool", held_rotations: tuple[int, ...] = ()) -> np.ndarray:
    """Translational mobility of a frame's origin (world axes) at q, on the simulated robot's model.

    Without `held_rotations`: Λ_v⁻¹ = J_v M⁻¹ J_vᵀ, the tool's response ẍ = Λ_v⁻¹ f to a force f
    when nothing else acts. With the world rotation axes the task holds (0, 1 for rx, ry): the
    response when those rotations are held exactly (the task as an ideal constraint, Gauss's
    principle), the Schur complement A − B C⁻¹ Bᵀ of J M⁻¹ Jᵀ = [[A, B], [Bᵀ, C]] with
    J = [J_v; J_ω,held].
    """
    model = run.robot.model
    data = model.createData()
    fid = model.getFrameId(frame)
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    J6 = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
    J = np.vstack([J6[:3], J6[[3 + i for i in held_rotations]]])
    M = pin.crba(model, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    inverse = J @ np.linalg.solve(M, J.T)
    A, B, C = inverse[:3, :3], inverse[:3, 3:], inverse[3:, 3:]
    return A - B @ np.linalg.solve(C, B.T) if held_rotations else A


def analyze_exp2(runs: dict[str, RunResult], push: dict[str, Any] | None = None) -> dict[str, Any]:
    push = push or push_of()
    t0, t1, f = push["start"], push["end"], push["force"]
    labels = [k for k in ("osc", "qp_mt", "qp_md", "dcts") if k in runs]
    ref = runs[labels[0]]
    q0 = ref.log.q[_index(ref, t0)]
    free = mobility(ref, q0) @ f
    held = mobility(ref, q0, held_rotations=(0, 1)) @ f
    metrics: dict[str, Any] = {"push": {"start": t0, "end": t1, "force": f.tolist()},
                               "lambda_v_inverse": mobility(ref, q0).tolist(),
                               "expected_acceleration": free.tolist(),
                               "expected_direction": (free / np.linalg.norm(free)).tolist(),
                               "angle_force_vs_expected_deg": _angle_deg(f, free),
                               "held_expected_acceleration": held.tolist(),
                               "held_expected_direction": (held / np.linalg.norm(held)).tolist(),
                               "angle_free_vs_held_deg": _angle_deg(free, held)}
    early = 0.05
    for label in labels:
        r = runs[label]
        base = runs.get(f"{label}_no_push")
        end = min(t1 + 0.5, r.log.duration - r.log.period)
        ks, ke, k1, kend = _index(r, t0), _index(r, t0 + early), _index(r, min(t1, end)), _index(r, end)
        ke_total = r.series.kinetic_energy
        m = common_metrics(r)
        m["kinetic_energy_at_push_start"] = float(ke_total[ks])
        m["kinetic_energy_injected"] = float(ke_total[ks:kend + 1].max() - ke_total[ks])
        m["null_space_ke_injected"] = float(r.series.null_kinetic_energy[ks:kend + 1].max()
                                            - r.series.null_kinetic_energy[ks])
        m["acceleration_energy_push_window"] = float(r.series.acceleration_energy[ks:kend + 1].sum() * r.log.period)
        err = _task_error(r)
        m["task_error_max"] = float(err.max())
        m["task_error_final"] = float(err[-1])
        tool = _tool(r)
        if base is not None:
            btool = _tool(base)
            n = min(len(tool), len(btool))
            d = tool[:n] - btool[:n]  # the push's effect: with minus without
            m["kinetic_energy_injected_vs_no_push"] = float(
                (ke_total[ks:kend + 1] - base.series.kinetic_energy[ks:kend + 1]).max())
        else:  # without the no-push run: remove the motion the tool had at the push start
            v0 = (tool[ks + 1] - tool[ks]) / r.log.period
            d = tool - tool[ks] - np.outer(r.log.time - r.log.time[ks], v0)
        d_early, d_end = d[ke] - d[ks], d[k1] - d[ks]
        m["displacement_early"] = d_early.tolist()
        m["displacement_push_end"] = d_end.tolist()
        m["angle_early_deg"] = _angle_deg(d_early, free)
        m["angle_push_end_deg"] = _angle_deg(d_end, free)
        m["angle_held_early_deg"] = _angle_deg(d_early, held)
        m["angle_held_push_end_deg"] = _angle_deg(d_end, held)
        # a free body in the translational null space: ½ Λ⁻¹ f t²
        m["displacement_early_vs_newton_held"] = float(
            np.linalg.norm(d_early) / (0.5 * np.linalg.norm(held) * early**2))
        m["displacement_push_end_vs_newton_held"] = float(
            np.linalg.norm(d_end) / (0.5 * np.linalg.norm(held) * (r.log.time[k1] - t0) ** 2))
        metrics[label] = m
    claims = []
    low = {k: metrics[k]["kinetic_energy_injected"] for k in ("osc", "dcts") if k in metrics}
    high = {k: metrics[k]["kinetic_energy_injected"] for k in ("qp_mt", "qp_md") if k in metrics}
    claims.append(claim(
        "exp2.energy_injected", "Under the push, OSC and DCTS inject less kinetic energy than QP-MT and QP-MD",
        "the external force injected more kinetic energy in the robot using QP-MT and QP-MD",
        "kinetic energy gained from the push start to 0.5 s after it: " + ", ".join(
            f"{k} {metrics[k]['kinetic_energy_injected']:.3g} J" for k in labels)
        + (f" (QP-MT already had {metrics['qp_mt']['kinetic_energy_at_push_start']:.3g} J at the push start: it falls "
           "under gravity in its null space)" if "qp_mt" in metrics else ""),
        max(low.values()) < min(high.values()),
        "max(OSC, DCTS) < min(QP-MT, QP-MD), kinetic energy ½q̇ᵀMq̇ gained in [push start, push end + 0.5 s]"))
    held_end = {k: metrics[k]["angle_held_push_end_deg"] for k in labels}
    held_early = {k: metrics[k]["angle_held_early_deg"] for k in labels}
    free_early = {k: metrics[k]["angle_early_deg"] for k in labels}
    free_end = {k: metrics[k]["angle_push_end_deg"] for k in labels}
    worst_intuitive = max(held_end[k] for k in ("osc", "dcts") if k in held_end)
    others = [held_end[k] for k in ("qp_mt", "qp_md") if k in held_end]
    claims.append(claim(
        "exp2.newton_direction",
        "The end effector moves along the Newton direction Λ⁻¹f of the translational null space with OSC and DCTS, "
        "not with QP-MT / QP-MD",
        "only OSC has an intuitive motion: ẍ = Λ⁻¹f_ext in the null space (translation)",
        "angle between the push's tool displacement and Λ⁻¹f with the task's rotations held: after 50 ms "
        + ", ".join(f"{k} {held_early[k]:.1f}°" for k in labels) + "; at the push end "
        + ", ".join(f"{k} {held_end[k]:.1f}°" for k in labels) + ". Against the free Λ_v⁻¹f (J_v M⁻¹ J_vᵀ f, "
        f"{metrics['angle_free_vs_held_deg']:.0f}° away from it): after 50 ms "
        + ", ".join(f"{k} {free_early[k]:.1f}°" for k in labels) + "; at the push end "
        + ", ".join(f"{k} {free_end[k]:.1f}°" for k in labels),
        worst_intuitive <= 10 and all(a > 2 * worst_intuitive for a in others),
        "OSC's and DCTS's angles to Λ⁻¹f (rotations held) ≤ 10° at the push end, QP-MT's and QP-MD's more "
        "than twice as large"))
    return {"metrics": metrics, "claims": claims}


# -- experiment 3 --------------------------------------------------------------------------------------

PAPER_TABLE2 = {"projector": {"position_error": 0.018, "acceleration_error": 0.0294},
                "dcts": {"position_error": 0.016, "acceleration_error": 0.0248}}
MAGNITUDE_FACTOR = 1.5  # "of the paper's magnitude": within a factor 1.5 either way


def octagon_law(key: str = "exp3") -> SaturatedLaw:
    """The saturated law of a study's octagon task (gains and v_sat of its first run's spec)."""
    gains = load_run_spec(study(key)["runs"][0]).tasks[0].gains
    return SaturatedLaw(float(gains.kp), float(gains.kd), float(gains.max_velocity))


def path_phase(run: RunResult) -> int:
    """Samples of the path: up to the step the last point is reached (all, if it is not)."""
    return path_samples(run.log.waypoint_times, run.log.period, run.log.steps)


def table2_of(run: RunResult, law: SaturatedLaw):
    """The run's Table II series over its path phase (dcts_spec/analysis/paper_metrics.py)."""
    n = path_phase(run)
    return table2_series(run.robot.model, "tool", run.log.time[:n], run.log.q[:n], run.log.dq[:n], _tool(run)[:n],
                         run.log.ref[:n, :3], run.log.period, law)


def table2_errors(run: RunResult, law: SaturatedLaw) -> dict[str, float]:
    """Table II's errors and the alternative readings (definitions: docs/paper_reproduction.md):
    position_error to the reference point moving at v_sat, acceleration_error from the tool velocity
    differentiated centrally (primary); backward difference, distance to the segment, to the target,
    and the acceleration error with the simulator's joint acceleration beside them."""
    n = path_phase(run)
    means = table2_of(run, law).means()
    model = _norms(run.series.acceleration_errors[run.priorities[0]][:n])
    return {"position_error": means["position_error"], "acceleration_error": means["acceleration_error_central"],
            "acceleration_error_backward": means["acceleration_error_backward"],
            "path_error": means["path_error"], "target_error": means["target_error"],
            "acceleration_error_model": float(model.mean()), "path_phase_s": float(n * run.log.period)}


def write_table2_series(runs: dict[str, RunResult], law: SaturatedLaw, directory: Path) -> None:
    """DIR/<run>/table2.npz: the per-sample series of the path phase, to check the means against."""
    for label, r in runs.items():
        t2 = table2_of(r, law)
        np.savez_compressed(directory / label / "table2.npz", time=r.log.time[: len(t2.reference)],
                            **{k: v for k, v in vars(t2).items()}, kp=law.kp, kv=law.kv, v_sat=law.v_sat)


def exp3_metrics(r: RunResult, law: SaturatedLaw) -> dict[str, Any]:
    """Limits, scaling and Table II errors of one octagon run."""
    v_ratio = np.abs(r.log.dq) / r.robot.limits.v_max
    violating = np.any(v_ratio > 1.0 + 1e-3, axis=1)  # more than 0.1 % over
    sat = _tau_at_limit(r)
    scaled = np.min(r.log.scaling, axis=1) < 1.0 - 1e-3
    s = r.summary
    acc = _norms(r.series.acceleration_errors[r.priorities[0]])
    return common_metrics(r) | table2_errors(r, law) | {
        "diverged_at": None if s["completed"] else float(r.log.duration),
        "waypoints_reached": s["waypoints_reached"], "waypoints_total": s["waypoints_total"],
        "last_waypoint_time": s["waypoint_times"][-1] if s["waypoint_times"] else None,
        "velocity_violation_samples": int(violating.sum()),
        "velocity_violation_worst_joint": int(np.argmax(v_ratio.max(axis=0))) + 1,
        "torque_at_limit_samples": int(sat.sum()),
        # a violation follows the saturation that caused it: count saturation up to 20 ms before
        "velocity_violations_with_torque_saturation": float(
            (violating & _recently(sat, 20)).sum() / violating.sum()) if violating.any() else None,
        "scaled_samples": int(scaled.sum()),
        "scaled_samples_with_torque_at_limit": float((scaled & sat).sum() / scaled.sum()) if scaled.any() else None,
        "scaled_samples_with_velocity_at_limit": float(
            (scaled & np.any(v_ratio >= 1 - 1e-3, axis=1)).sum() / scaled.sum()) if scaled.any() else None,
        "acceleration_error_scaled": float(acc[scaled].mean()) if scaled.any() else None,
        "acceleration_error_unscaled": float(acc[~scaled].mean()) if (~scaled).any() else None,
    }


def _within(value: float, paper: float, factor: float = MAGNITUDE_FACTOR) -> bool:
    return paper / factor <= value <= paper * factor


def _table2_order(d: dict[str, Any], p: dict[str, Any], cid: str, who: str) -> dict[str, Any]:
    return claim(
        cid, f"{who} has smaller average position and acceleration errors than the baseline (Table II)",
        "baseline 0.018 m, 0.0294 m/s²; DCTS 0.016 m, 0.0248 m/s²",
        f"position error (moving reference) baseline {1000 * p['position_error']:.3g} mm, {who} "
        f"{1000 * d['position_error']:.3g} mm; acceleration error (central difference) baseline "
        f"{p['acceleration_error']:.3g} m/s², {who} {d['acceleration_error']:.3g} m/s²",
        d["position_error"] < p["position_error"] and d["acceleration_error"] < p["acceleration_error"],
        "both of DCTS's errors < the baseline's (definitions in the doc)")


def _table2_magnitude(d: dict[str, Any], p: dict[str, Any], key: str, what: str, unit: str,
                      factor: float) -> dict[str, Any]:
    paper_d, paper_p = PAPER_TABLE2["dcts"][key], PAPER_TABLE2["projector"][key]
    return claim(
        f"exp3.table2_{key.removesuffix('_error')}_magnitude", f"Table II's {what} have the paper's magnitude",
        f"baseline {factor * paper_p:g} {unit}, DCTS {factor * paper_d:g} {unit}",
        f"baseline {factor * p[key]:.3g} {unit} ({p[key] / paper_p:.2g}× the paper's), DCTS {factor * d[key]:.3g} "
        f"{unit} ({d[key] / paper_d:.2g}×)",
        _within(p[key], paper_p) and _within(d[key], paper_d),
        f"each within a factor {MAGNITUDE_FACTOR:g} of the paper's value")


def analyze_exp3(runs: dict[str, RunResult], law: SaturatedLaw | None = None) -> dict[str, Any]:
    law = law or octagon_law()
    metrics = {label: exp3_metrics(r, law) for label, r in runs.items()}
    d, p = metrics["dcts"], metrics["projector"]
    claims = [
        claim("exp3.dcts_keeps_limits", "DCTS keeps every limit",
              "all limitations were respected",
              f"DCTS worst excess: position {d['max_joint_position_violation']:.1e} rad, velocity "
              f"{100 * d['max_joint_velocity_violation_ratio']:.2g} % of its limit, torque "
              f"{d['max_torque_violation']:.1e} Nm; "
              f"{d['limits_relaxed']} relaxed steps, {d['solver_failures']} solver failures",
              d["max_joint_position_violation"] <= 1e-3 and d["max_joint_velocity_violation_ratio"] <= 1e-3
              and d["max_torque_violation"] <= 1e-6 and d["solver_failures"] == 0,
              "position excess ≤ 1e-3 rad, velocity excess ≤ 0.1 % of the limit, torque excess ≤ 1e-6 Nm, "
              "no failure"),
        claim("exp3.dcts_scales_only_at_torque_limits",
              "DCTS scales the task (s < 1) only while the torque limits conflict with it",
              "the acceleration error only increased when the task had to be scaled ... when the torque limits were "
              "in conflict with the task",
              f"{d['scaled_samples']} samples with s < 0.999 (min s {d['min_scaling']:.3g}); "
              + (f"{100 * d['scaled_samples_with_torque_at_limit']:.3g} % of them with a torque at its limit, "
                 f"{100 * d['scaled_samples_with_velocity_at_limit']:.3g} % with a joint at its velocity limit; "
                 f"mean ‖J q̈ + J̇q̇ − ẍ_d‖ {d['acceleration_error_scaled']:.3g} m/s² while scaled, "
                 f"{d['acceleration_error_unscaled']:.3g} m/s² otherwise"
                 if d["scaled_samples"] else "no scaling at all: the claim is not exercised")
              + f"; samples with a torque at its limit: {d['torque_at_limit_samples']}",
              d["scaled_samples"] == 0 or d["scaled_samples_with_torque_at_limit"] >= 0.9,
              "≥ 90 % of the samples with s < 0.999 have a torque at its limit (±1e-3 Nm); no scaling at all counts "
              "as holding (not exercised)"),
        claim("exp3.projector_follows_path", "The baseline follows the path despite the limits",
              "the desired path in position is followed despite the limitation of joint positions, velocities and "
              "torques",
              f"baseline (acceleration limit {SNS_ACCELERATION_LIMIT:g} rad/s²): {p['waypoints_reached']}/"
              f"{p['waypoints_total']} points"
              + (f", the last at {p['last_waypoint_time']:.3g} s" if p["last_waypoint_time"] is not None else "")
              + ("" if p["completed"] else f"; MuJoCo stopped it at {p['duration']:.3g} s (unstable)"),
              p["completed"] and p["waypoints_reached"] == p["waypoints_total"],
              "every point reached, the run completed"),
        claim("exp3.projector_violates_velocity",
              "The projector baseline violates velocity limits, when torque saturation conflicts with them",
              "when the torque to limit the joint velocities is bigger than the maximal allowed torque, the velocity "
              "limit is not respected",
              f"baseline: worst velocity {100 * (1 + p['max_joint_velocity_violation_ratio']):.3g} % of its limit "
              f"(joint {p['velocity_violation_worst_joint']}), {p['velocity_violation_samples']} samples > 100.1 %"
              + (f", {100 * p['velocity_violations_with_torque_saturation']:.3g} % of them within 20 ms of a saturated "
                 "torque" if p["velocity_violations_with_torque_saturation"] is not None else ""),
              p["max_joint_velocity_violation_ratio"] > 0.01
              and (p["velocity_violations_with_torque_saturation"] or 0) >= 0.5,
              "velocity excess > 1 % of the limit, ≥ 50 % of the violating samples within 20 ms of a saturated "
              "torque"),
        _table2_order(d, p, "exp3.table2", "DCTS"),
    ]
    if "dcts_a20" in metrics:
        claims.append(_table2_order(metrics["dcts_a20"], p, "exp3.table2_same_limits",
                                    "DCTS with the baseline's acceleration limit"))
    claims += [_table2_magnitude(d, p, "position_error", "position errors", "mm", 1000),
               _table2_magnitude(d, p, "acceleration_error", "acceleration errors", "m/s²", 1)]
    return {"metrics": metrics, "claims": claims}


def analyze_acceleration_limit(runs: dict[str, RunResult], law: SaturatedLaw | None = None) -> dict[str, Any]:
    """The baseline without its acceleration limit and both with 40 rad/s²: metrics, and Table II's
    order when both have that limit."""
    law = law or octagon_law()
    metrics = {label: exp3_metrics(r, law) for label, r in runs.items()}
    claims = [_table2_order(metrics["dcts_a40"], metrics["projector_a40"], "exp3.table2_same_limits_a40",
                            "DCTS with 40 rad/s², as the baseline,")] if {"dcts_a40", "projector_a40"} <= set(metrics) \
        else []
    return {"metrics": metrics, "claims": claims}


# -- experiment 4 --------------------------------------------------------------------------------------

def analyze_exp4(runs: dict[str, RunResult], joint: int = 5) -> dict[str, Any]:
    metrics = {}
    for label, r in runs.items():
        v_ratio = np.abs(r.log.dq) / r.robot.limits.v_max
        excess = np.maximum(v_ratio - 1.0, 0.0)
        q = r.log.q
        lim = r.robot.limits
        margin = np.minimum(lim.q_max - q, q - lim.q_min)
        metrics[label] = common_metrics(r) | {
            "velocity_excess_per_joint": excess.max(axis=0).tolist(),
            f"joint{joint}_velocity_excess": float(excess[:, joint - 1].max()),
            f"joint{joint}_time_over_1pct_s": float(np.count_nonzero(excess[:, joint - 1] > 0.01) * r.log.period),
            "worst_velocity_excess": float(excess.max()),
            "closest_position_margin_per_joint_deg": np.degrees(margin.min(axis=0)).tolist(),
            "joint_range_deg": [np.degrees(q.min(axis=0)).tolist(), np.degrees(q.max(axis=0)).tolist()],
        }
    m, i = metrics["measured"], metrics["ignored"]
    key = f"joint{joint}_velocity_excess"
    ratio = i[key] / max(m[key], 1e-9)
    claims = [
        claim("exp4.tau_ext_reduces_velocity_violation",
              f"Using τ_ext in the limits reduces the worst velocity-limit violation (joint {joint} and overall)",
              "the violation of the velocity limit was reduced for joint 5 from circa 40 % to less than 1 %",
              f"joint {joint}: {100 * i[key]:.3g} % over its limit with τ_ext ignored, {100 * m[key]:.2g} % with "
              f"it measured ({ratio:.3g}×); all joints: {100 * i['worst_velocity_excess']:.3g} % vs "
              f"{100 * m['worst_velocity_excess']:.2g} %",
              m[key] < i[key] and m["worst_velocity_excess"] < i["worst_velocity_excess"] and m[key] <= 0.01,
              "measured < ignored for joint 5 and for the worst joint, and measured ≤ 1 % for joint 5"),
        claim("exp4.positions_within_limits", "Positions stay within their limits either way",
              "there was not a significant change in the position limit avoidance ... the joint values stayed "
              "between their limits",
              f"worst position excess: measured {np.degrees(m['max_joint_position_violation']):.2g}°, ignored "
              f"{np.degrees(i['max_joint_position_violation']):.2g}°",
              max(m["max_joint_position_violation"], i["max_joint_position_violation"]) <= np.radians(0.5),
              "position excess ≤ 0.5° in both runs"),
    ]
    return {"metrics": metrics, "claims": claims}


# -- experiment 5 --------------------------------------------------------------------------------------

EXP5_STEP = 0.01  # s: the claims are judged over [0, t] for t every 10 ms


def exp5_window(runs: dict[str, RunResult], steps: int) -> dict[str, Any]:
    """Experiment 5's metrics and claims over the first `steps` samples (the window [0, steps·T))."""
    metrics = {}
    for label, r in runs.items():
        k = min(steps, r.log.steps)
        tool = _tool(r)[:k]
        d = tool - tool[0]
        err = _task_error(r)[:k]
        v_ratio = np.abs(r.log.dq[:k]) / r.robot.limits.v_max
        metrics[label] = {
            "window_s": float(k * r.log.period),
            "tool_displacement_final": d[-1].tolist(),
            "tool_z_min": float(d[:, 2].min()),
            "task_error_max_deg": float(np.degrees(err.max())),
            "task_error_rms_deg": float(np.degrees(np.sqrt(np.mean(err**2)))),
            "acceleration_energy_integral": float(r.series.acceleration_energy[:k].sum() * r.log.period),
            "kinetic_energy_peak": float(r.series.kinetic_energy[:k].max()),
            "max_joint_velocity_violation_ratio": float(max(v_ratio.max() - 1.0, 0.0)),
        }
    a, b = runs["dcts"], runs["osc"]
    n = min(steps, a.log.steps, b.log.steps)
    gap = _norms(_tool(a)[:n] - _tool(b)[:n])
    fall = max(abs(metrics["dcts"]["tool_displacement_final"][2]), 1e-9)
    apart = np.flatnonzero(_norms(a.log.tau[:n] - b.log.tau[:n]) > 1.0)
    metrics["dcts_osc_torques_differ_from_s"] = float(a.log.time[apart[0]]) if apart.size else None
    metrics["dcts_vs_osc_path_gap_max"] = float(gap.max())
    dc, os_, md = metrics["dcts"], metrics["osc"], metrics["qp_md"]
    dz = {k: metrics[k]["tool_displacement_final"][2] for k in ("dcts", "osc", "qp_md")}
    window = dc["window_s"]
    claims = [
        claim("exp5.falls_holding_orientation",
              "With DCTS and OSC the end effector falls while the orientation is held",
              "the end effector is expected to fall following Newton's law, while holding the orientation",
              f"tool z after {window:.2g} s: DCTS {dz['dcts']:+.3f} m, OSC {dz['osc']:+.3f} m; "
              "worst orientation "
              f"error DCTS {dc['task_error_max_deg']:.2g}°, OSC {os_['task_error_max_deg']:.2g}°",
              dz["dcts"] < -0.05 and dz["osc"] < -0.05
              and max(dc["task_error_max_deg"], os_["task_error_max_deg"]) <= 3.0,
              "tool z drops by > 5 cm with both; worst orientation error ≤ 3°"),
        claim("exp5.dcts_like_osc", "DCTS and OSC move alike",
              "the OSC and the DCTS delivered similar results",
              f"tool paths differ by at most {1000 * metrics['dcts_vs_osc_path_gap_max']:.3g} mm "
              f"({100 * metrics['dcts_vs_osc_path_gap_max'] / fall:.2g} % of DCTS's fall); "
              "their torques are equal until "
              + (f"{metrics['dcts_osc_torques_differ_from_s']:.3f} s (DCTS's first active limit)"
                 if metrics["dcts_osc_torques_differ_from_s"] is not None else "the end"),
              metrics["dcts_vs_osc_path_gap_max"] <= 0.25 * fall,
              "max distance between the two tool paths ≤ 25 % of DCTS's fall"),
        claim("exp5.qp_md_up_and_backwards", "With QP-MD the end effector moves up and backwards instead of falling",
              "the end effector starts to move up and backwards instead of falling down",
              f"QP-MD tool displacement {np.round(md['tool_displacement_final'], 3).tolist()} m (x, y, z) "
              f"vs DCTS {np.round(dc['tool_displacement_final'], 3).tolist()} m",
              dz["qp_md"] > 0 and md["tool_displacement_final"][0] < 0,
              "QP-MD's tool ends higher than it started (z > 0) and behind it (x < 0, toward the robot's base)"),
        claim("exp5.qp_md_falls_differently", "QP-MD does not fall the way DCTS and OSC do",
              "(weaker reading of the above)",
              f"QP-MD's tool drops {abs(dz['qp_md']):.3f} m, {100 * dz['qp_md'] / min(dz['dcts'], -1e-9):.3g} % of "
              "DCTS's drop",
              dz["qp_md"] > 0.75 * dz["dcts"],
              "QP-MD's drop < 75 % of DCTS's"),
        claim("exp5.qp_md_more_acceleration_energy", "QP-MD spends more acceleration energy than DCTS and OSC",
              "the QP-MD uses more acceleration energy",
              f"∫½(τ−g)ᵀM⁻¹(τ−g)dt: QP-MD {md['acceleration_energy_integral']:.3g}, DCTS "
              f"{dc['acceleration_energy_integral']:.3g}, OSC {os_['acceleration_energy_integral']:.3g}",
              md["acceleration_energy_integral"] > max(dc["acceleration_energy_integral"],
                                                       os_["acceleration_energy_integral"]),
              "QP-MD's integral > DCTS's and OSC's"),
    ]
    return {"metrics": metrics, "claims": claims}


def _intervals(times: np.ndarray, holds: np.ndarray) -> list[list[float]]:
    """[first, last] window ends of each run of consecutive windows where a claim holds."""
    return [[float(times[k0]), float(times[k1 - 1])] for k0, k1 in _runs_of(holds)]


def analyze_exp5(runs: dict[str, RunResult], step: float = EXP5_STEP) -> dict[str, Any]:
    """The claims over the whole run (the verdicts), and for every window [0, t], t = step, 2·step, …:
    the windows over which each holds and when it stops holding."""
    period = runs["dcts"].log.period
    steps = min(r.log.steps for r in runs.values())
    ends = np.unique(np.append(np.arange(max(int(round(step / period)), 1), steps, max(int(round(step / period)), 1)),
                               steps))
    verdicts = np.array([[c["holds"] for c in exp5_window(runs, int(k))["claims"]] for k in ends])
    result = exp5_window(runs, steps)
    for label in ("dcts", "osc", "qp_md"):
        result["metrics"][label] = common_metrics(runs[label]) | result["metrics"][label]
    times = ends * period
    for c, holds in zip(result["claims"], verdicts.T, strict=True):
        c["holds_over_windows_ending"] = _intervals(times, holds)
        c["stops_holding_after_s"] = c["holds_over_windows_ending"][-1][1] \
            if c["holds_over_windows_ending"] and not holds[-1] else None
        c["measured"] += "; " + _window_text(c["holds_over_windows_ending"], float(times[-1]))
    return result


def _window_text(intervals: list[list[float]], end: float) -> str:
    if not intervals:
        return f"holds over no window [0, t], t ≤ {end:.2g} s"
    spans = ", ".join(f"{a:.2f}–{b:.2f} s" if b > a else f"{a:.2f} s" for a, b in intervals)
    return f"holds over [0, t] for t in {spans}"


ANALYSES: dict[str, Callable[[dict[str, RunResult]], dict[str, Any]]] = {
    "exp1": analyze_exp1, "exp2": analyze_exp2, "exp3": analyze_exp3, "exp4": analyze_exp4, "exp5": analyze_exp5,
}


def _prefixed(key: str, result: dict[str, Any]) -> dict[str, Any]:
    for c in result["claims"]:
        c["id"] = f"{key}:{c['id']}"
    return result


def analyze_sensitivity(key: str, runs: dict[str, RunResult]) -> dict[str, Any]:
    """The analysis of a sensitivity study; its claims' ids are prefixed with the study."""
    if key == "exp3_vsat_0.4":
        return _prefixed(key, analyze_exp3(runs, octagon_law(key)))
    if key == "exp3_acceleration_limit":
        return _prefixed(key, analyze_acceleration_limit(runs))
    if key == "exp4_semi_implicit":
        return _prefixed(key, analyze_exp4(runs))
    if key == "exp1_semi_implicit":
        r = runs["qp_mt"]
        return {"metrics": {"qp_mt": common_metrics(r) | {"task_error_final": float(_task_error(r)[-1])}},
                "claims": []}
    if key == "exp5_payload_com":
        return {"metrics": {label: {"tool_displacement_final": (_tool(r)[-1] - _tool(r)[0]).tolist(),
                                    "acceleration_energy_integral": r.summary["acceleration_energy_integral"],
                                    "task_error_max_deg": float(np.degrees(_task_error(r).max()))}
                            for label, r in runs.items()}, "claims": []}
    raise KeyError(key)


# -- figures -------------------------------------------------------------------------------------------

COLORS = {"osc": "#1f77b4", "qp_mt": "#d62728", "qp_md": "#2ca02c", "dcts": "#9467bd", "projector": "#ff7f0e",
          "measured": "#9467bd", "ignored": "#d62728", "qp_mt_without_gravity": "#ff9896", "dcts_a20": "#8c564b",
          "dcts_a40": "#17becf", "projector_table_i": "#e377c2", "projector_a40": "#bcbd22"}


def _color(label: str) -> str:
    return COLORS.get(label.split("_no_push")[0], "#333333")


def figures_exp1(runs: dict[str, RunResult]) -> dict[str, Figure]:
    fig = Figure(figsize=(9, 6.5), layout="constrained")
    task, null, err = fig.subplots(3, 1, sharex=True)
    for label, r in runs.items():
        t = r.log.time
        task.plot(t, r.series.task_kinetic_energy, color=_color(label), lw=1.2, label=label)
        null.semilogy(t, np.maximum(r.series.null_kinetic_energy, 1e-12), color=_color(label), lw=1.2, label=label)
        err.semilogy(t, np.maximum(np.degrees(_task_error(r)), 1e-6), color=_color(label), lw=1.2, label=label)
    task.set_ylabel("task-space KE [J]")
    null.set_ylabel("null-space KE [J]")
    null.set_ylim(1e-8, None)
    err.set_ylabel("orientation error [°]")
    err.set_xlabel("time [s]")
    task.set_title("Experiment 1: kinetic energy in task space and null space "
                   "(½ẋᵀΛẋ and the rest of ½q̇ᵀMq̇)")
    task.legend(fontsize=8)
    return {"exp1_energies": fig}


def figures_exp2(runs: dict[str, RunResult], analysis: dict[str, Any]) -> dict[str, Figure]:
    push = analysis["metrics"]["push"]
    expected = np.array(analysis["metrics"]["expected_direction"])
    held = np.array(analysis["metrics"]["held_expected_direction"])
    labels = [k for k in ("osc", "qp_mt", "qp_md", "dcts") if k in runs]
    fig = Figure(figsize=(9, 5.5), layout="constrained")
    ke, ae = fig.subplots(2, 1, sharex=True)
    for label in labels:
        r = runs[label]
        ke.semilogy(r.log.time, np.maximum(r.series.kinetic_energy, 1e-8), color=_color(label), lw=1.2, label=label)
        ae.semilogy(r.log.time, np.maximum(r.series.acceleration_energy, 1e-8), color=_color(label), lw=1.0,
                    label=label)
    for ax in (ke, ae):
        ax.axvspan(push["start"], push["end"], color="#2ca02c", alpha=0.12, lw=0)
    ke.set_ylabel("kinetic energy ½q̇ᵀMq̇ [J]")
    ke.set_ylim(1e-5, None)
    ae.set_ylabel("acceleration energy\n½(τ−g)ᵀM⁻¹(τ−g)")
    ae.set_ylim(1e-4, None)
    ae.set_xlabel("time [s] (green: the 10 N push)")
    ke.set_title("Experiment 2: energies (QP-MT falls under gravity in its null space from the start)")
    ke.legend(fontsize=8)

    motion = Figure(figsize=(10, 4.6), layout="constrained")
    axes = motion.subplots(1, 2)
    for ax, (i, j), view in zip(axes, ((0, 1), (0, 2)), ("x-y (top view)", "x-z (side view)"), strict=True):
        scale = 0.0
        for label in labels:
            r, base = runs[label], runs.get(f"{label}_no_push")
            tool = _tool(r)
            k0, k1 = _index(r, push["start"]), _index(r, min(push["end"] + 0.3, r.log.duration - r.log.period))
            d = tool - (_tool(base)[: len(tool)] if base is not None else tool[k0])
            d = d[k0:k1 + 1] - d[k0]
            ax.plot(d[:, i] * 1000, d[:, j] * 1000, color=_color(label), lw=1.3, label=label)
            kp = _index(r, push["end"]) - k0
            if 0 <= kp < len(d):
                ax.plot(d[kp, i] * 1000, d[kp, j] * 1000, "o", color=_color(label), ms=4)
            scale = max(scale, np.abs(d[:, [i, j]]).max() * 1000)
        for direction, name, style in ((held, "Λ⁻¹f (rotations held)", "-"), (expected, "free Λ_v⁻¹f", "--")):
            arrow = direction[[i, j]] * 0.8 * scale
            ax.annotate("", xy=(arrow[0], arrow[1]), xytext=(0, 0),
                        arrowprops={"arrowstyle": "->", "color": "black", "lw": 1.3, "ls": style})
            ax.text(arrow[0], arrow[1], f" {name}", fontsize=7)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x [mm]")
        ax.set_ylabel(f"{'xyz'[j]} [mm]")
        ax.set_title(view, fontsize=9)
        ax.legend(fontsize=8)
    motion.suptitle("Experiment 2: the push's effect on the tool (run with push − run without), push start to "
                    "0.3 s after it; dots: push end")
    return {"exp2_energies": fig, "exp2_motion": motion}


def figures_exp3(runs: dict[str, RunResult], prefix: str = "exp3") -> dict[str, Figure]:
    labels = list(runs)
    path = Figure(figsize=(5.2 * len(labels), 5.2), layout="constrained")
    axes = path.subplots(1, len(labels), squeeze=False)[0]
    for ax, label in zip(axes, labels, strict=True):
        r = runs[label]
        n = path_phase(r)
        tool = _tool(r)[:n]
        if r.waypoint_positions is not None:
            w = r.waypoint_positions
            ax.plot(w[:, 1], w[:, 2], "k--", lw=0.6)
            ax.plot(w[:, 1], w[:, 2], "ks", ms=3)
        ax.plot(tool[:, 1], tool[:, 2], color=_color(label), lw=1.0)
        ax.set_aspect("equal")
        ax.set_xlabel("y [m]")
        ax.set_ylabel("z [m]")
        reached = f"{r.summary['waypoints_reached']}/{r.summary['waypoints_total']}"
        ax.set_title(f"{label}: tool path (y-z), {reached} points", fontsize=9)
    fig = Figure(figsize=(10, 8.5), layout="constrained")
    vel, tau, scale, acc = fig.subplots(4, 1, sharex=True)
    for label in labels:
        r = runs[label]
        t = r.log.time
        vel.plot(t, np.max(np.abs(r.log.dq) / r.robot.limits.v_max, axis=1), color=_color(label), lw=0.8, label=label)
        tau.plot(t, np.max(np.abs(r.log.tau) / r.robot.limits.tau_max, axis=1), color=_color(label), lw=0.8,
                 label=label)
        scale.plot(t, np.min(r.log.scaling, axis=1), color=_color(label), lw=0.8, label=label)
        acc.semilogy(t, np.maximum(_norms(r.series.acceleration_errors[r.priorities[0]]), 1e-6),
                     color=_color(label), lw=0.6, label=label)
        sat = _tau_at_limit(r)
        for k0, k1 in _runs_of(sat):
            vel.axvspan(t[k0], t[min(k1, len(t) - 1)], color=_color(label), alpha=0.25, lw=0)
    vel.axhline(1.0, color="k", ls="--", lw=0.7)
    vel.set_ylabel("max_j |q̇_j| / q̇_max,j")
    vel.set_ylim(0, min(3.0, vel.get_ylim()[1]))
    vel.set_title("velocity relative to the limit (worst joint; shaded: a torque at its limit), torque, "
                  "scaling, acceleration error", fontsize=9)
    tau.set_ylabel("max_j |τ_j| / τ_max")
    scale.set_ylabel("task scaling s")
    acc.set_ylabel("‖ẍ − ẍ_d‖ [m/s²]")
    acc.set_xlabel("time [s]")
    vel.legend(fontsize=8)
    return {f"{prefix}_paths": path, f"{prefix}_limits": fig}


def _runs_of(mask: np.ndarray) -> list[tuple[int, int]]:
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return list(zip(edges[::2], edges[1::2], strict=True))


def figures_exp4(runs: dict[str, RunResult], joint: int = 5, prefix: str = "exp4") -> dict[str, Figure]:
    fig = Figure(figsize=(10, 7.5), layout="constrained")
    vel, pos, tau = fig.subplots(3, 1, sharex=True)
    j = joint - 1
    for label, r in runs.items():
        t = r.log.time
        vel.plot(t, r.log.dq[:, j] / r.robot.limits.v_max[j], color=_color(label), lw=1.0,
                 label=f"joint {joint}, τ_ext {label}")
        pos.plot(t, np.degrees(r.log.q[:, j]), color=_color(label), lw=1.0, label=f"joint {joint}, τ_ext {label}")
        pos.plot(t, np.degrees(r.log.q[:, 1]), color=_color(label), lw=0.8, ls=":", label=f"joint 2, τ_ext {label}")
    r = next(iter(runs.values()))
    tau.plot(r.log.time, r.log.tau_ext_true[:, j], color="k", lw=1.0, label=f"joint {joint}")
    tau.plot(r.log.time, r.log.tau_ext_true[:, 1], color="k", lw=0.8, ls=":", label="joint 2")
    for v in (-1, 1):
        vel.axhline(v, color="k", ls="--", lw=0.7)
    lim = r.robot.limits
    for v in (lim.q_min[j], lim.q_max[j], lim.q_min[1], lim.q_max[1]):
        pos.axhline(np.degrees(v), color="#888888", ls="--", lw=0.6)
    vel.set_ylabel(f"q̇_{joint} / q̇_max")
    vel.set_title(f"Experiment 4: the person drives joints {joint} and 2 to their limits (dashed)", fontsize=9)
    pos.set_ylabel("q [°]")
    tau.set_ylabel("person's torque [Nm]")
    tau.set_xlabel("time [s]")
    for ax in (vel, pos, tau):
        ax.legend(fontsize=7, ncol=2)
    return {f"{prefix}_joint{joint}": fig}


def figures_exp5(runs: dict[str, RunResult], prefix: str = "exp5") -> dict[str, Figure]:
    fig = Figure(figsize=(10, 7.5), layout="constrained")
    (px, py), (pz, err), (acc, ke) = fig.subplots(3, 2, sharex=True)
    for label, r in runs.items():
        t, d = r.log.time, _tool(r) - _tool(r)[0]
        for ax, i in ((px, 0), (py, 1), (pz, 2)):
            ax.plot(t, d[:, i] * 1000, color=_color(label), lw=1.2, label=label)
        err.plot(t, np.degrees(_task_error(r)), color=_color(label), lw=1.2, label=label)
        acc.plot(t, np.cumsum(r.series.acceleration_energy) * r.log.period, color=_color(label), lw=1.2, label=label)
        ke.plot(t, r.series.kinetic_energy, color=_color(label), lw=1.2, label=label)
    for ax, name in ((px, "Δx"), (py, "Δy"), (pz, "Δz")):
        ax.set_ylabel(f"tool {name} [mm]")
    err.set_ylabel("orientation error [°]")
    acc.set_ylabel("∫½(τ−g)ᵀM⁻¹(τ−g)dt")
    ke.set_ylabel("kinetic energy [J]")
    acc.set_xlabel("time [s]")
    ke.set_xlabel("time [s]")
    px.set_title("Experiment 5: tool displacement after release of the unmodelled 4.1 kg payload", fontsize=9)
    px.legend(fontsize=8)
    return {f"{prefix}_motion": fig}


def make_figures(key: str, runs: dict[str, RunResult], analysis: dict[str, Any]) -> dict[str, Figure]:
    if key == "exp1":
        return figures_exp1(runs)
    if key == "exp2":
        return figures_exp2(runs, analysis)
    if key == "exp3":
        return figures_exp3(runs)
    if key == "exp4":
        return figures_exp4(runs)
    if key == "exp5":
        return figures_exp5(runs)
    if key == "exp3_vsat_0.4":
        return figures_exp3(runs, "exp3_vsat04")
    if key == "exp3_acceleration_limit":
        return figures_exp3(runs, "exp3_acceleration_limit")
    if key == "exp4_semi_implicit":
        return figures_exp4(runs, prefix="exp4_semi_implicit")
    return {}


# -- tables --------------------------------------------------------------------------------------------

def _fmt(v: Any, digits: int = 3) -> str:
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if v == 0:
            return "0"
        if math.isfinite(v) and (abs(v) >= 1e4 or abs(v) < 1e-3):
            return f"{v:.2e}"
        return f"{v:.{digits}g}"
    if isinstance(v, list):
        return "(" + ", ".join(_fmt(x) for x in v) + ")"
    return str(v)


def metrics_table(metrics: dict[str, Any], rows: list[tuple[str, str, float]], labels: list[str]) -> str:
    """Rows (name, key, factor) of the metric tables, one column per run."""
    out = ["| | " + " | ".join(labels) + " |", "|---|" + "---:|" * len(labels)]
    for name, key, factor in rows:
        values = []
        for label in labels:
            v = metrics[label].get(key)
            if isinstance(v, (int, float)) and not isinstance(v, bool) and factor != 1:
                v = float(v) * factor
            elif isinstance(v, list) and factor != 1:
                v = [x * factor for x in v]
            values.append(_fmt(v))
        out.append(f"| {name} | " + " | ".join(values) + " |")
    return "\n".join(out)


def claims_table(claims: list[dict[str, Any]]) -> str:
    out = ["| claim | paper | measured here | criterion | verdict |", "|---|---|---|---|---|"]
    for c in claims:
        out.append(f"| {c['statement']} | {c['paper']} | {c['measured']} | {c['criterion']} | "
                   f"**{'holds' if c['holds'] else 'does not hold'}** |")
    return "\n".join(out)


ROWS = {
    "exp1": [("task-space KE peak [J]", "task_space_kinetic_energy_peak", 1),
             ("task-space KE peak during the rotation (first 0.3 s) [J]", "task_space_ke_peak_first_0.3s", 1),
             ("null-space KE peak [J]", "null_space_kinetic_energy_peak", 1),
             ("null-space KE at 0.1 s [J]", "null_space_ke_at_0.1s", 1),
             ("null-space KE, mean of the first window [J]", "null_space_ke_first_window_mean", 1),
             ("null-space KE, mean of the last window [J]", "null_space_ke_last_window_mean", 1),
             ("initial orientation error [°]", "task_error_initial", 180 / math.pi),
             ("final orientation error [°]", "task_error_final", 180 / math.pi),
             ("∫ acceleration energy", "acceleration_energy_integral", 1),
             ("tool displacement at the end [m]", "tool_displacement_final", 1),
             ("worst velocity excess [% of limit]", "max_joint_velocity_violation_ratio", 100),
             ("worst position excess [rad]", "max_joint_position_violation", 1),
             ("steps with relaxed limits", "limits_relaxed", 1)],
    "exp2": [("KE at the push start [J]", "kinetic_energy_at_push_start", 1),
             ("KE gained, push start → 0.5 s after [J]", "kinetic_energy_injected", 1),
             ("same, minus the run without push [J]", "kinetic_energy_injected_vs_no_push", 1),
             ("null-space KE gained [J]", "null_space_ke_injected", 1),
             ("∫ acceleration energy, push window + 0.5 s", "acceleration_energy_push_window", 1),
             ("tool displacement by the push after 50 ms [mm]", "displacement_early", 1000),
             ("angle to Λ⁻¹f (rotations held) after 50 ms [°]", "angle_held_early_deg", 1),
             ("angle to the free Λ_v⁻¹f after 50 ms [°]", "angle_early_deg", 1),
             ("displacement / ½‖Λ⁻¹f‖t² after 50 ms (rotations held)", "displacement_early_vs_newton_held",
              1),
             ("tool displacement by the push at its end [mm]", "displacement_push_end", 1000),
             ("angle to Λ⁻¹f (rotations held) at the push end [°]", "angle_held_push_end_deg", 1),
             ("angle to the free Λ_v⁻¹f at the push end [°]", "angle_push_end_deg", 1),
             ("displacement / ½‖Λ⁻¹f‖t², push end (rotations held)", "displacement_push_end_vs_newton_held",
              1),
             ("max orientation error [°]", "task_error_max", 180 / math.pi),
             ("worst velocity excess [% of limit]", "max_joint_velocity_violation_ratio", 100),
             ("worst position excess [rad]", "max_joint_position_violation", 1)],
    "exp3": [("points reached", "waypoints_reached", 1),
             ("last point reached at [s]", "last_waypoint_time", 1),
             ("MuJoCo stopped the run (unstable) at [s]", "diverged_at", 1),
             ("**position error to the moving reference [mm]**", "position_error", 1000),
             ("**acceleration error, central difference [m/s²]**", "acceleration_error", 1),
             ("acceleration error, backward difference [m/s²]", "acceleration_error_backward", 1),
             ("distance to the segment [mm]", "path_error", 1000),
             ("distance to the current target [mm]", "target_error", 1000),
             ("‖J q̈ + J̇q̇ − ẍ_d‖ with the simulator's q̈ [m/s²]", "acceleration_error_model", 1),
             ("worst velocity excess [% of limit]", "max_joint_velocity_violation_ratio", 100),
             ("samples over a velocity limit (> 0.1 %)", "velocity_violation_samples", 1),
             ("… of them within 20 ms of a saturated torque [%]", "velocity_violations_with_torque_saturation", 100),
             ("worst position excess [rad]", "max_joint_position_violation", 1),
             ("worst torque excess [Nm]", "max_torque_violation", 1),
             ("samples with a torque at its limit", "torque_at_limit_samples", 1),
             ("samples with s < 0.999", "scaled_samples", 1),
             ("… of them with a torque at its limit [%]", "scaled_samples_with_torque_at_limit", 100),
             ("… of them with a joint at its velocity limit [%]", "scaled_samples_with_velocity_at_limit", 100),
             ("min scaling", "min_scaling", 1),
             ("steps with relaxed limits", "limits_relaxed", 1),
             ("solver failures / invalid outputs (fallback torque)", "solver_failures", 1),
             ("kinetic energy peak [J]", "kinetic_energy_peak", 1)],
    "exp4": [("joint 5 worst velocity excess [% of limit]", "joint5_velocity_excess", 100),
             ("time joint 5 is > 1 % over [s]", "joint5_time_over_1pct_s", 1),
             ("worst velocity excess, any joint [% of limit]", "worst_velocity_excess", 100),
             ("velocity excess per joint [%]", "velocity_excess_per_joint", 100),
             ("worst position excess [rad]", "max_joint_position_violation", 1),
             ("closest approach to a position limit per joint [°]", "closest_position_margin_per_joint_deg", 1),
             ("steps with relaxed limits", "limits_relaxed", 1),
             ("solver failures", "solver_failures", 1)],
    "exp5": [("tool displacement at the end (x, y, z) [mm]", "tool_displacement_final", 1000),
             ("lowest tool z [mm]", "tool_z_min", 1000),
             ("max orientation error [°]", "task_error_max_deg", 1),
             ("RMS orientation error [°]", "task_error_rms_deg", 1),
             ("∫ acceleration energy", "acceleration_energy_integral", 1),
             ("kinetic energy peak [J]", "kinetic_energy_peak", 1),
             ("worst velocity excess [% of limit]", "max_joint_velocity_violation_ratio", 100),
             ("worst position excess [rad]", "max_joint_position_violation", 1),
             ("steps with relaxed limits", "limits_relaxed", 1)],
}

RUN_NAMES = {  # no "|" in them: they go into Markdown tables
    "projector": f"baseline (SNS), joint accelerations within ±{SNS_ACCELERATION_LIMIT:g} rad/s²",
    "dcts": "DCTS, Table I limits",
    "dcts_a20": f"DCTS, within ±{SNS_ACCELERATION_LIMIT:g} rad/s² too",
    "projector_table_i": "baseline, Table I limits only",
    "projector_a40": "baseline, within ±40 rad/s²",
    "dcts_a40": "DCTS, within ±40 rad/s²",
}


def table2(groups: list[tuple[str, dict[str, Any]]]) -> str:
    """Table II: the paper's numbers, the primary reading and the alternatives, one row per run of
    each (speed, analysis) group."""
    out = ["| run | v_sat | points | worst velocity [× limit] | **position error** (moving reference) | "
           "**acceleration error** (central) | acceleration error (backward) | distance to the segment | "
           "distance to the target | ‖J q̈ + J̇q̇ − ẍ_d‖ (simulator's q̈) |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for label, p in PAPER_TABLE2.items():
        out.append(f"| paper, {'DCTS' if label == 'dcts' else 'baseline'} | 0.85 or 0.4 | | | "
                   f"**{1000 * p['position_error']:g} mm** | **{p['acceleration_error']} m/s²** | | | | |")
    for speed, analysis in groups:
        for label, m in analysis["metrics"].items():
            points = f"{m['waypoints_reached']}/{m['waypoints_total']}" + (
                "" if m["completed"] else f", unstable at {m['duration']:.3g} s")
            out.append(f"| {RUN_NAMES.get(label, label)} | {speed} | {points} | "
                       f"{1 + m['max_joint_velocity_violation_ratio']:.3g} | "
                       f"**{1000 * m['position_error']:.3g} mm** | **{m['acceleration_error']:.3g} m/s²** | "
                       f"{m['acceleration_error_backward']:.3g} m/s² | {1000 * m['path_error']:.3g} mm | "
                       f"{1000 * m['target_error']:.3g} mm | {m['acceleration_error_model']:.3g} m/s² |")
    return "\n".join(out)


SENSITIVITY_ROWS = {
    "exp3_acceleration_limit": ROWS["exp3"],
    "exp3_vsat_0.4": ROWS["exp3"],
    "exp4_semi_implicit": ROWS["exp4"],
    "exp1_semi_implicit": [("null-space KE peak [J]", "null_space_kinetic_energy_peak", 1),
                           ("final orientation error [°]", "task_error_final", 180 / math.pi),
                           ("worst velocity excess [% of limit]", "max_joint_velocity_violation_ratio", 100),
                           ("steps with relaxed limits", "limits_relaxed", 1),
                           ("∫ acceleration energy", "acceleration_energy_integral", 1)],
    "exp5_payload_com": [("tool displacement at the end (x, y, z) [mm]", "tool_displacement_final", 1000),
                         ("max orientation error [°]", "task_error_max_deg", 1),
                         ("∫ acceleration energy", "acceleration_energy_integral", 1)],
}


def sensitivity_markdown(key: str, result: dict[str, Any]) -> str:
    """The study's metrics, one column per run, and its claims if it has any."""
    m = result["metrics"]
    labels = [label for label, value in m.items() if isinstance(value, dict)]  # the runs, not run-pair figures
    parts = [metrics_table(m, SENSITIVITY_ROWS[key], labels)]
    if result["claims"]:
        parts.append(claims_table(result["claims"]))
    return "\n\n".join(parts)


def experiment_markdown(key: str, result: dict[str, Any]) -> str:
    metrics = result["metrics"]
    labels = [k for k in metrics if isinstance(metrics[k], dict) and "formulation" in metrics[k]
              and not k.endswith("_no_push")]
    parts = [metrics_table(result["metrics"], ROWS[key], labels)]
    if key == "exp2":
        m = result["metrics"]
        parts.append(f"Push: {m['push']['force']} N on the tool during [{m['push']['start']}, {m['push']['end']}) s. "
                     f"At the push start, the free Λ_v⁻¹f = J_v M⁻¹ J_vᵀ f = "
                     f"{np.round(np.array(m['expected_acceleration']), 3).tolist()} m/s² "
                     f"({m['angle_force_vs_expected_deg']:.1f}° from f); with the task's two rotations held, "
                     f"Λ⁻¹f = {np.round(np.array(m['held_expected_acceleration']), 3).tolist()} m/s² "
                     f"({m['angle_free_vs_held_deg']:.1f}° from the free one).")
    parts.append(claims_table(result["claims"]))
    return "\n\n".join(parts)


def summary_markdown(results: dict[str, Any]) -> str:
    """The verdicts: the paper's claims on our specs, then the sensitivity variants."""
    def rows(claims: list[dict[str, Any]]) -> list[str]:
        return [f"| `{c['id']}` | {c['statement']} | **{'holds' if c['holds'] else 'does not hold'}** |"
                for c in claims]

    head = ["| claim | statement | verdict |", "|---|---|---|"]
    main = [c for a in results["experiments"].values() for c in a["claims"]]
    out = [f"The paper's claims on the specs of `specs/paper/` ({sum(c['holds'] for c in main)} of {len(main)} hold):",
           "", *head, *rows(main)]
    variants = [c for a in results["sensitivity"].values() for c in a["claims"]]
    if variants:
        out += ["", "The same claims on the sensitivity variants (how a setting changes the answer; not verdicts on "
                "the paper):", "", *head, *rows(variants)]
    return "\n".join(out)


def replace_generated(text: str, blocks: dict[str, str]) -> str:
    for key, body in blocks.items():
        begin, end = f"<!-- BEGIN GENERATED: {key} -->", f"<!-- END GENERATED: {key} -->"
        if begin not in text or end not in text:
            continue
        head, rest = text.split(begin, 1)
        _, tail = rest.split(end, 1)
        text = f"{head}{begin}\n{body.rstrip()}\n{end}{tail}"
    return text


# -- main ------------------------------------------------------------------------------------------------

def _git_commit() -> str | None:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                             timeout=10, check=False)
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "specs/paper", "scripts", "dcts_spec"], cwd=ROOT,
                               capture_output=True, text=True, timeout=10, check=False)
        return out.stdout.strip() + ("+changes" if dirty.stdout.strip() else "") if out.returncode == 0 else None
    except (OSError, subprocess.SubprocessError):
        return None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "paper_reproduction",
                        help="where the runs go (one `dcts compare`-style folder per experiment)")
    parser.add_argument("--runtime", choices=("c", "python"), default="c")
    parser.add_argument("--short", action="store_true",
                        help="shortened runs (the CI tests' durations); of the sensitivity studies only the baseline's acceleration limit")
    parser.add_argument("--docs", type=Path, default=None,
                        help=f"results.json, plots and tables (default: {DOCS_DIR.relative_to(ROOT)} on full runs, "
                             "OUT/docs with --short); a full run into the default also rewrites the generated "
                             "blocks of docs/paper_reproduction.md")
    parser.add_argument("--no-docs", action="store_true", help="only the runs")
    parser.add_argument("--only", default=None, help="comma-separated experiments (exp1,…,exp5)")
    parser.add_argument("--no-sensitivity", action="store_true", help="skip the sensitivity studies of full runs")
    args = parser.parse_args(argv)

    keys = list(EXPERIMENTS) if not args.only else [k.strip() for k in args.only.split(",")]
    unknown = [k for k in keys if k not in EXPERIMENTS]
    if unknown:
        parser.error(f"unknown experiment {unknown[0]!r}; choose from {', '.join(EXPERIMENTS)}")
    docs = None if args.no_docs else (args.docs or (args.out / "docs" if args.short else DOCS_DIR))
    update_doc = docs is not None and docs.resolve() == DOCS_DIR.resolve() and not args.short and not args.only
    if args.no_sensitivity:
        sensitivity = []
    elif args.only:  # only what the chosen experiments' claims need
        sensitivity = [k for k in SHORT_SENSITIVITY if k.split("_")[0] in keys]
    else:
        sensitivity = list(SHORT_SENSITIVITY if args.short else SENSITIVITY)

    started = time.perf_counter()
    results: dict[str, Any] = {"generated": {
        "script": "scripts/reproduce_paper.py", "runtime": args.runtime, "short": args.short,
        "commit": _git_commit(), "date": time.strftime("%Y-%m-%d %H:%M:%S %Z")}, "experiments": {}, "sensitivity": {}}
    figures: dict[str, Figure] = {}
    blocks: dict[str, str] = {}
    args.out.mkdir(parents=True, exist_ok=True)
    for group, items in (("experiments", keys), ("sensitivity", sensitivity)):
        for key in items:
            info = study(key)
            print(f"{key}: {info['title']} …", flush=True)
            tic = time.perf_counter()
            runs = run_experiment(key, args.runtime, args.short)
            analysis = ANALYSES[key](runs) if group == "experiments" else analyze_sensitivity(key, runs)
            analysis["title"] = info["title"]
            analysis["runtimes"] = sorted({r.summary["runtime"] for r in runs.values()})
            analysis["wall_time_s"] = round(time.perf_counter() - tic, 1)
            results[group][key] = analysis
            target = args.out / key
            if target.exists():
                shutil.rmtree(target)
            write_comparison(list(runs.values()), target, f"{info['title']} ({args.runtime} runtime"
                             f"{', shortened' if args.short else ''})")
            if key.startswith("exp3"):
                write_table2_series(runs, octagon_law(key), target)
            figures |= make_figures(key, runs, analysis)
            blocks[key] = experiment_markdown(key, analysis) if group == "experiments" else \
                sensitivity_markdown(key, analysis)
            for c in analysis["claims"]:
                print(f"  {'HOLDS       ' if c['holds'] else 'DOES NOT HOLD'} {c['id']}: {c['measured']}", flush=True)
    if "exp3" in results["experiments"]:
        groups = [(f"{octagon_law(key).v_sat:g} m/s", results[group][key])
                  for group, key in (("experiments", "exp3"), ("sensitivity", "exp3_acceleration_limit"),
                                     ("sensitivity", "exp3_vsat_0.4")) if key in results[group]]
        blocks["table2"] = table2(groups)
    main = [c for a in results["experiments"].values() for c in a["claims"]]
    variants = [c for a in results["sensitivity"].values() for c in a["claims"]]
    results["summary"] = {"paper_claims": len(main), "hold": sum(c["holds"] for c in main),
                          "do_not_hold": [c["id"] for c in main if not c["holds"]],
                          "sensitivity_claims": len(variants), "sensitivity_hold": sum(c["holds"] for c in variants),
                          "wall_time_s": round(time.perf_counter() - started, 1)}
    blocks["summary"] = summary_markdown(results)
    if docs is not None:
        docs.mkdir(parents=True, exist_ok=True)
        for name, figure in figures.items():
            figure.savefig(docs / f"{name}.png", dpi=DPI)
        (docs / "results.json").write_text(json.dumps(json_ready(results), indent=2, ensure_ascii=False) + "\n",
                                           encoding="utf-8")
        (docs / "tables.md").write_text("\n\n".join(f"## {key}\n\n{body}" for key, body in blocks.items()) + "\n",
                                        encoding="utf-8")
        if update_doc and DOC.exists():
            DOC.write_text(replace_generated(DOC.read_text(encoding="utf-8"), blocks), encoding="utf-8")
        print(f"wrote {docs}/ (results.json, tables.md, {len(figures)} plots)"
              + (f" and the generated blocks of {DOC.relative_to(ROOT)}" if update_doc else ""))
    summary = results["summary"]
    print(f"{summary['hold']}/{summary['paper_claims']} of the paper's claims hold"
          + (f" ({summary['sensitivity_hold']}/{summary['sensitivity_claims']} on the sensitivity variants)"
             if variants else "") + f"; {summary['wall_time_s']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
