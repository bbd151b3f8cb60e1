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
    structure = Structure(range(*data["bound_rows"]), tuple(zip(data["scaling"].tolist(), bends)), spare)
    return [data[k] if k in ("H", "A") else data[k].ravel() for k in ("H", "f", "A", "lbx", "ubx", "lba", "uba")], structure
