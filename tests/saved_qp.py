"""QP data saved by a test's author (tests/data/NAME.npz): the cascade's arguments and structure."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dcts_spec.solve import Structure


def saved_qp(name: str) -> tuple[list[np.ndarray], Structure]:
    """H, f, A, lbx, ubx, lba, uba and the Structure of tests/data/NAME.npz."""
    data = np.load(Path(__file__).parent / "data" / f"{name}.npz")
    bends = [tuple(data[f"bend{k}"].tolist()) for k in range(len(data["scaling"]))]
    spare = bool(data["spare_variables"]) if "spare_variables" in data else False
    weights = tuple(data["slack_weights"].tolist()) if "slack_weights" in data else None
    structure = Structure(range(*data["bound_rows"]), tuple(zip(data["scaling"].tolist(), bends)), spare, weights)
    return [data[k] if k in ("H", "A") else data[k].ravel() for k in ("H", "f", "A", "lbx", "ubx", "lba", "uba")], structure


def saved_acceleration_map(name: str) -> np.ndarray | None:
    """Q (q̈ = q̈₀ + Q x) of tests/data/NAME.npz, where it was saved."""
    data = np.load(Path(__file__).parent / "data" / f"{name}.npz")
    return data["Q"] if "Q" in data else None
