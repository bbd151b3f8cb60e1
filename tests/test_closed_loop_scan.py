"""scripts/closed_loop_scan.py, issue 9's 10⁶-step check: the statuses it counts and the episodes
it saves to replay a fallback."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

import dcts_spec
from command_line import ROOT
from dcts_spec.codegen.states import trajectory_states

sys.path.insert(0, str(ROOT / "scripts"))
import closed_loop_scan  # noqa: E402  (a script, not a package)

MINIMAL = ROOT / "specs" / "minimal.yaml"


def test_a_fallback_is_counted_and_saved_with_its_episode(tmp_path: Path) -> None:
    """A step made to fall back (status −2 at the 1,034th step) is counted, and its episode up to
    it is saved: the states of steps 1,000–1,034 of the same closed-loop motion, in order."""
    controller = dcts_spec.build_controller(MINIMAL)
    calls = []

    def step(q, dq, tau_ext, ref):
        result = controller.step(q, dq, tau_ext, ref)
        calls.append(1)
        return dataclasses.replace(result, status=-2) if len(calls) == 1035 else result

    out = tmp_path / "fallbacks.npz"
    counts = closed_loop_scan.count_statuses(controller, step, controller.reset, 1100, 7, out)
    assert sum(counts.values()) == 1100 and counts[-2] == 1 and counts[0] == 1099
    saved = np.load(out)
    episode = saved[saved.files[0]]
    controller.reset()
    again = trajectory_states(controller, 1035, seed=7)  # (the same motion: the fallback changed no state)
    expected = np.array([np.concatenate(s.as_tuple()) for s in again[1000:1035]])
    assert episode.shape == expected.shape and np.array_equal(episode, expected)
