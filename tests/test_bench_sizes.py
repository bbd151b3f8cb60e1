"""scripts/bench_sizes.py, the README's scaling table: its specs of example-robot-data models
validate with the joints the table names, and (DCTS_SLOW) it measures the smallest model."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from command_line import ROOT
from dcts_spec.validate import validate_file

sys.path.insert(0, str(ROOT / "scripts"))
import bench_sizes  # noqa: E402  (a script, not a package)

DOF = {"baxter14": 14, "talos16": 16, "talos28": 28, "pr2_15": 15, "romeo27": 27}


@pytest.mark.parametrize("model", bench_sizes.MODELS, ids=lambda m: m.key)
def test_specs_validate_with_the_named_joints(model: bench_sizes.Model, tmp_path: Path) -> None:
    spec = tmp_path / f"{model.key}.yaml"
    spec.write_text(bench_sizes.model_spec(model))
    report = validate_file(spec)
    assert report.robot.nv == DOF[model.key]
    assert all(name.startswith(model.keep) for name in report.robot.joint_names)
    levels = [[t.name for t in report.spec.tasks if t.priority == p] for p in (1, 2)]
    assert levels == [[f"{frame}_pose" for frame in model.arm_frames], ["posture"]]


def test_the_chain_spec_validates_with_every_joint_and_away_from_its_singularity(tmp_path: Path) -> None:
    """The generated serial chain (the worst case: every task sees every joint) validates, and its
    tip's pose task has full rank at the start (straight up, the chain would be singular)."""
    urdf, spec = tmp_path / "chain.urdf", tmp_path / "chain.yaml"
    urdf.write_text(bench_sizes.chain_urdf(bench_sizes.CHAIN_JOINTS))
    spec.write_text(bench_sizes.chain_spec(bench_sizes.CHAIN_JOINTS, urdf))
    report = validate_file(spec)
    assert report.robot.nv == bench_sizes.CHAIN_JOINTS and not report.diagnostics
    assert [(lv.dimension, lv.rank) for lv in report.levels] == [(6, 6), (32, 26)]


def test_table_row() -> None:
    row = {"model": "m", "dof": 7, "qp_data_operations": 8300, "looped_products": False, "c_source_bytes": 190_000,
           "text_bytes": 146_000, "compile_s": 4.2, "compile_peak_rss_bytes": 2.4e8, "validate_check_s": 1.2, "step_median_us": 3.04,
           "step_p99_us": 6.2, "ratio_to_pinocchio": 1.13, "cortex_m7_flash_bytes": None}
    assert bench_sizes.markdown([row]).splitlines()[-1] == \
        "| m | 7 | 8.3 k | 0.19 MB | 146 kB | 4 s (0.24 GB) | 1 s | 3.0 / 6 µs | 1.13 | — |"
    row["looped_products"] = True
    assert "| 8.3 k looped |" in bench_sizes.markdown([row])


@pytest.mark.skipif(not os.environ.get("DCTS_SLOW"), reason="runs dcts bench on bench_iiwa14 (~1-2 min): set "
                    "DCTS_SLOW=1 to run it")
def test_table_of_the_smallest_model(tmp_path: Path) -> None:
    out, rows = tmp_path / "table.md", tmp_path / "rows.json"
    done = subprocess.run([sys.executable, str(ROOT / "scripts" / "bench_sizes.py"), "iiwa14", "--states", "300",
                           "--out", str(out), "--json", str(rows)], capture_output=True, text=True, timeout=1200)
    assert done.returncode == 0, done.stderr
    (row,) = json.loads(rows.read_text())
    assert row["dof"] == 7 and row["qp_data_operations"] > 1000 and row["step_median_us"] > 0
    assert row["compile_s"] > 0 and row["compile_peak_rss_bytes"] > 1e6 and row["validate_check_s"] > 0
    table = out.read_text().splitlines()
    assert table[0].startswith("| model | DOF |") and table[2].startswith("| iiwa14 (bench spec) | 7 |")
