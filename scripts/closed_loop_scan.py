"""Many closed-loop steps of the compiled controller: how many end in each status.

Issue 9's check "10⁶ smooth in-limit states in C: 0 fallbacks". The spec's bundle is built
(`dcts compile`, golden test included) and its step, called through ctypes, drives the robot's
forward dynamics (`trajectory_states`: semi-implicit Euler at the control period from random
starts inside the Cartesian bounds, external torque pulses of 15 % of the torque limits, reference
jumps; q and q̇ kept within their limits) for N steps, in episodes of 1,000. Counted: each status
of those steps. A step that falls back (status < 0) is saved with its episode's states up to it
(`--out`), so it can be replayed: the controller's answer depends on the steps before it (the
hint and DAQP's warm start).

    python scripts/closed_loop_scan.py specs/bench_iiwa14.yaml --states 1000000
    python scripts/closed_loop_scan.py SPEC --states 100000 --seed 3 --out fallbacks.npz
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

from dcts_spec.codegen.build import compile_bundle, make_controller
from dcts_spec.codegen.loader import load_bundle
from dcts_spec.codegen.states import trajectory_states
from dcts_spec.controller import STATUS_NAMES
from dcts_spec.spec import load_spec

EPISODE = 1000  # steps from one start (trajectory_states' episodes)
CHUNK = 100 * EPISODE  # states generated and counted at a time (memory)


def scan(spec_file: str, states: int, seed: int, out: Path | None) -> Counter:
    """Build the spec's bundle and count the statuses of `states` closed-loop steps of its step."""
    spec = load_spec(spec_file)
    controller = make_controller(spec)
    with tempfile.TemporaryDirectory(prefix="dcts-scan-") as tmp:
        compile_bundle(spec, Path(tmp) / "bundle")
        with load_bundle(Path(tmp) / "bundle") as compiled:
            return count_statuses(controller, compiled.step, compiled.reset, states, seed, out)


def count_statuses(controller, step, reset, states: int, seed: int, out: Path | None) -> Counter:
    """The statuses of `states` closed-loop steps of `step` (q, dq, tau_ext, ref) → StepResult,
    `reset()` before each chunk of episodes; the episodes of the steps that fell back saved to
    `out` (one array per fallback: its episode's rows of q, dq, tau_ext, ref up to that step)."""
    counts: Counter = Counter()
    fallbacks: list[np.ndarray] = []
    statuses: list[int] = []

    def counted(q, dq, tau_ext, ref):
        result = step(q, dq, tau_ext, ref)
        statuses.append(result.status)
        return result

    start = time.perf_counter()
    for chunk in range(0, states, CHUNK):
        statuses.clear()
        reset()
        chunk_states = trajectory_states(controller, min(CHUNK, states - chunk), seed=seed + chunk, step=counted)
        counts.update(statuses)
        for k in np.flatnonzero(np.array(statuses) < 0):
            first = k - k % EPISODE  # (the controller's answer depends on the steps before it)
            fallbacks.append(np.array([np.concatenate(s.as_tuple()) for s in chunk_states[first:k + 1]]))
        print(f"{chunk + len(chunk_states):,} steps, {time.perf_counter() - start:.0f} s: {_format(counts)}", flush=True)
    if out is not None and fallbacks:
        np.savez(out, *fallbacks)
        print(f"{len(fallbacks)} fallback episodes saved to {out} (rows of q, dq, tau_ext, ref)")
    return counts


def _format(counts: Counter) -> str:
    return ", ".join(f"{STATUS_NAMES.get(s, s)} {n:,}" for s, n in sorted(counts.items(), reverse=True))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("spec")
    parser.add_argument("--states", type=int, default=1_000_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, help="where to save the episodes of steps that fell back (.npz)")
    args = parser.parse_args()
    counts = scan(args.spec, args.states, args.seed, args.out)
    fell_back = sum(n for s, n in counts.items() if s < 0)
    print(f"{args.spec}: {sum(counts.values()):,} closed-loop steps in C, {fell_back:,} fell back")


if __name__ == "__main__":
    main()
