"""The distance rows in the generated C: like every other bound, nothing of their own."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from dcts_spec.codegen import compile_bundle

SPEC = """
version: 1
name: collision_bundle
robot: {model: iiwa14}
limits:
  joint_torque: {max: 100}
  collision:
    obstacles:
      ball: {type: sphere, center: [0.55, 0.0, 0.42], radius: 0.07}
      crate: {type: box, center: [0.2, 0.5, 0.2], size: [0.3, 0.3, 0.4]}
      floor: {type: plane, normal: [0, 0, 1]}
tasks:
  - {name: tool, type: position, frame: tool, priority: 1, gains: {kp: 100, kd: 20}, reference: {position: [0.42, 0.0, 0.25]}}
  - {name: posture, type: joint, priority: 2, gains: {kp: 10, kd: 6}, reference: {q: [0, 30, 0, -60, 0, 60, 0], unit: deg}}
scenario: {duration: 1.0, initial_q: [0, 30, 0, -60, 0, 60, 0], unit: deg}
"""


@pytest.mark.slow  # (the default tier generates its sources below; its rows are QP data like every bound's)
def test_a_spec_with_collisions_compiles_and_passes_its_golden_check(tmp_path: Path) -> None:
    spec = tmp_path / "collision.yaml"
    spec.write_text(SPEC)
    report = compile_bundle(spec, tmp_path / "bundle")  # builds it and replays the golden vectors
    host = report.manifest["host"]
    assert report.manifest["built"] and host["step_heap_calls"] == 0
    # 7 torque, 7 joint and 41 distance rows: 20 link pairs and 7 moving links against each obstacle
    assert report.manifest["na"] == 7 + 7 + 20 + 3 * 7
    assert sum(name.startswith("collision:") for name in report.manifest["bound_names"]) == 20 + 3 * 7
    counts = dict(re.findall(r"(ok|relaxed|solver failed|invalid) (\d+)", host["test_summary"]))
    assert int(counts["ok"]) > 0 and counts["solver failed"] == "0" and counts["invalid"] == "0", host["test_summary"]


def test_the_header_lists_the_pairs_and_the_order_of_relaxed(tmp_path: Path) -> None:
    """A firmware engineer reading info->relaxed[i] finds which bound i is, and each pair's
    minimum distance, in the header (they were in manifest.json only). An obstacle's name is free
    text: one with a comment's end in it stays inside the comment."""
    spec = tmp_path / "collision.yaml"
    spec.write_text(SPEC.replace("      floor:", "      'floor*/':"))
    report = compile_bundle(spec, tmp_path / "bundle", build=False)
    header = (tmp_path / "bundle" / "collision_bundle.h").read_text()
    assert " *   link7-ball: distance ≥ 0.02 m; braking at 5 m/s²" in header
    listed = re.search(r"info->relaxed\[i\], .*? in this order: (.*?)\.\n", header, re.S).group(1)
    entries = [e.strip() for e in listed.replace("\n *", " ").split(", ")]
    assert entries == [f"{i}:{name.split(':', 1)[1].replace('*/', '*' + chr(92) + '/')}"
                       for i, name in enumerate(report.manifest["bound_names"])]
    assert "7:link1-ball" in entries and "floor*" + chr(92) + "/" in header and "floor*/" not in header
