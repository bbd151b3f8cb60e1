"""Is a lexicographic answer determined by its QP data? The same solve on copies of the data
changed at the level of their rounding.

The C bundle evaluates the QP data in another order of operations than CasADi's virtual
machine: the two runtimes' data differ by ~1e-15–1e-13 relative. Where the cascade's decisions
are degenerate (after a relaxation or a bend, the next stages see a thin feasible set, and DAQP
solves a stage or calls it infeasible depending on the last bits: docs/formulations.md), such
changes move the answer by far more than any tolerance, in either runtime. On such a state no
runtime can be compared with another, only on what both must guarantee (status, limits): the
golden-vector test (codegen/bundle.py) measures this spread for every vector it compares.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .bound_check import check_bounds
from .lexicographic import Structure, solve_lexicographic
from .optimality import to_optimum

ROUNDING = 1e-14  # relative change of each entry of the QP data, about what separates the runtimes
# ... and for an answer after a relaxation. There the stages run on the sliver the relaxed bounds
# and the rows held at a stage's answer leave, and what separates the runtimes is not the data's
# rounding but each stage's own precision, which the next stages take as bounds. HyQ's legs at
# twice their URDF torques (12 joints, found from outside; `dcts compile` refused the spec): at a
# relaxed golden vector the C's held rows sat up to 5e-9 relative from the Python's, its bend was
# 5e-4 lower (both feasible, HiGHS's own answer higher than either) and its torques 2.3e-3 apart.
# Changes of the data of 1e-14 moved the Python answer by less than 1e-4, of 1e-12 by 4e-2; of the
# 57 relaxed vectors there, 10 moved beyond 1e-4 at 1e-14, 13 at 1e-12 and 19 at 1e-11; of the
# bench spec's 10, none at any of the three.
RELAXED_ROUNDING = 1e-12


def _changed(values: np.ndarray, rng: np.random.Generator, rounding: float) -> np.ndarray:
    return values * (1.0 + rounding * rng.standard_normal(values.shape))


def rounding_spread(H, f, A, lbx, ubx, lba, uba, structure: Structure, x: np.ndarray,
                    outputs: Callable[[np.ndarray], Sequence[np.ndarray]], samples: int, enough: float,
                    seed: int = 0, acceleration_map: np.ndarray | None = None,
                    bound_shift: np.ndarray | None = None, rounding: float | None = None) -> np.ndarray:
    """For each group of outputs(x) (e.g. the torques, the QP solution), the largest relative
    change (|Δ| / max(1, |value|), entry by entry) over `samples` solves of the QP with every entry
    of its data changed by ~`rounding` relative (H symmetrically; both bounds of a variable or a row
    by the same factor, so that a variable fixed stays fixed and an equality stays one). Sampling
    stops as soon as every group's change exceeds `enough`; a group's spread is ∞ if a solve fails.
    Groups, because a level that no free direction can move leaves its own variables undetermined
    and the torques not (a degenerate level of a 7-joint arm: x moved by 1e2, τ by 2e-8).
    `acceleration_map`: as for `solve_lexicographic` (changed like the data); `bound_shift`: the
    bound rows' constant part, as for `check_bounds` (None: 0, the rows' bounds are in their units);
    `rounding`: that relative size (None: ROUNDING)."""
    rounding = ROUNDING if rounding is None else rounding
    rng = np.random.default_rng(seed)
    shift = np.zeros(len(structure.bound_rows)) if bound_shift is None else bound_shift
    reference = [np.asarray(group, dtype=float) for group in outputs(x)]
    scales = [np.maximum(1.0, np.abs(group)) for group in reference]
    spread = np.zeros(len(reference))
    for _ in range(samples):
        E = rounding * rng.standard_normal(H.shape)
        variables, rows = _changed(np.ones(lbx.size), rng, rounding), _changed(np.ones(lba.size), rng, rounding)
        data = (H * (1.0 + 0.5 * (E + E.T)), _changed(f, rng, rounding), _changed(A, rng, rounding), lbx * variables,
                ubx * variables, lba * rows, uba * rows)
        changed = solve_lexicographic(*data, structure,
                                      None if acceleration_map is None else _changed(acceleration_map, rng, rounding))
        if changed is None:
            return np.full(len(reference), np.inf)
        if check_bounds(structure.bound_rows, data[2], data[5], data[6], changed, shift).holds:
            changed, _ = to_optimum(*data, changed, structure)  # (as the step takes an "ok" answer)
        for i, (group, value, scale) in enumerate(zip(outputs(changed), reference, scales)):
            if group.size:
                spread[i] = max(spread[i], float(np.max(np.abs(group - value) / scale)))
        if (spread > enough).all():
            break
    return spread


@dataclass
class AnswerData:
    """An answer x of a step and what `rounding_spread` needs to measure it (arrays only, so that
    another process can): the QP's data H, f, A, lbx, ubx, lba, uba, and the command's maps
    τ = τ₀ + T x, q̈ = q̈₀ + Q x."""

    qp: tuple[np.ndarray, ...]
    structure: Structure
    x: np.ndarray
    tau0: np.ndarray
    T: np.ndarray
    ddq0: np.ndarray
    Q: np.ndarray
    bound_shift: np.ndarray
    rounding: float = ROUNDING  # the changes' size: RELAXED_ROUNDING for an answer after a relaxation

    def outputs(self, answer: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(the command (τ, q̈), the QP solution) of an answer."""
        return np.concatenate([self.tau0 + self.T @ answer, self.ddq0 + self.Q @ answer]), answer

    def spread(self, samples: int, enough: float) -> np.ndarray:
        """[the command's, the solution's] spread (`rounding_spread`)."""
        return rounding_spread(*self.qp, self.structure, self.x, self.outputs, samples, enough,
                               acceleration_map=self.Q, bound_shift=self.bound_shift, rounding=self.rounding)


def spreads(answers: Sequence[AnswerData], samples: int, enough: Sequence[float], workers: int) -> list[np.ndarray]:
    """Each answer's `AnswerData.spread` (with its own `enough`), shared out among `workers`
    processes when more than one (`spread_worker.py`): the samples of one answer depend on nothing
    else, and at 29 joints the golden vectors' spreads took 30–40 s of one core. Fresh
    interpreters, not copies of this process (which holds CasADi's and the build's state) nor
    re-runs of the caller's script (multiprocessing's spawn); the same numbers as in this one.
    The answers a worker does not return (it could not start, or died) are measured here."""
    jobs = [(answer, samples, limit) for answer, limit in zip(answers, enough)]
    results: list[np.ndarray | None] = [None] * len(jobs)
    if workers > 1 and len(jobs) > 1:
        shares = [list(range(w, len(jobs), workers)) for w in range(min(workers, len(jobs)))]
        for share, measured in zip(shares, run_workers([[jobs[k] for k in share] for share in shares])):
            for k, value in zip(share, measured or []):
                results[k] = value
    return [value if value is not None else job[0].spread(*job[1:]) for value, job in zip(results, jobs)]


def run_workers(shares: list[list[tuple[AnswerData, int, float]]]) -> list[list[np.ndarray] | None]:
    """Each share's spreads, measured by a `python -m dcts_spec.solve.spread_worker` of its own
    (the jobs pickled in, the spreads out); None for a share whose worker failed."""
    package_root = str(Path(__file__).resolve().parents[2])  # (where dcts_spec is, whatever sys.path said)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [package_root, os.environ.get("PYTHONPATH")])))
    command = [sys.executable, "-m", "dcts_spec.solve.spread_worker"]
    processes = []
    for share in shares:
        try:
            process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                       stderr=subprocess.DEVNULL, env=env)
        except OSError:
            process = None
        processes.append(process)
    payloads = [pickle.dumps(share) for share in shares]
    with ThreadPoolExecutor(len(processes)) as pool:  # (each pipe fed and drained at once: no deadlock)
        outputs = list(pool.map(_communicate, processes, payloads))
    return [_unpickled(out) for out in outputs]


def _unpickled(out: bytes | None) -> list[np.ndarray] | None:
    try:
        return None if out is None else pickle.loads(out)
    except (pickle.UnpicklingError, EOFError, ValueError):
        return None


def _communicate(process: subprocess.Popen | None, payload: bytes) -> bytes | None:
    if process is None:
        return None
    try:
        out, _ = process.communicate(payload)
    except OSError:
        process.kill()
        process.wait()
        return None
    return out if process.returncode == 0 else None


def available_cpus() -> int:
    """The CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # (not on Linux)
        return os.cpu_count() or 1
