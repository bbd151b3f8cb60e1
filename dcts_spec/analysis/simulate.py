"""The closed loop from Python: what `dcts simulate` runs and writes, without the command line."""

from __future__ import annotations

from pathlib import Path

from ..sim.runner import prepare_simulation
from ..spec import Spec
from .outputs import atomic_directory, write_run
from .run import RunResult, analyze


def simulate(spec: Spec | str | Path, runtime: str = "c", formulation: str | None = None,
             duration: float | None = None, out: str | Path | None = None, plots: bool = True) -> RunResult:
    """Run the spec's scenario against MuJoCo with the compiled controller (`runtime="c"`, from
    the bundle cache) or the Python runtime; return the run (`.summary` as in summary.json,
    `.log` and `.series` as in log.npz). With `out`, also write the folder `dcts simulate -o out`
    writes (refused, before the run, where dcts did not write it).

    Raises SpecError for a broken spec, RuntimeUnavailable where the C runtime cannot be built,
    OutputFolderError for an `out` it may not write into."""
    if out is not None:
        with atomic_directory(Path(out), "run") as staging:  # (checked before the run)
            run = simulate(spec, runtime, formulation, duration)
            write_run(run, staging, plots=plots)
        return run
    sim = prepare_simulation(spec, runtime, formulation, duration)
    return analyze(sim, sim.run())
