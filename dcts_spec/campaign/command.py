"""What `dcts sweep` does once its arguments are parsed: a campaign (or an optimization), its
summary on the terminal, and an exit code (1 for a bad input, with its location, or when no
sample ran; 130 when interrupted, the finished samples kept for the next run to resume from)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import typer

from ..codegen import CodegenError
from ..files import OutputFolderError
from ..sim.runtime import RuntimeUnavailable
from ..spec import SpecError
from .engine import ClusterUnreachable
from .optimize import tune
from .report import summary_lines
from .results import SAMPLES
from .sweep import Engine, SweepOptions, UnknownMetric, sweep

INTERRUPTED = 130


@dataclass(frozen=True)
class SweepCommand:
    spec: Path
    campaign: Path
    out: Path
    engine: Engine = "ray"
    address: str | None = None
    workers: int | None = None
    max_samples: int | None = None
    optimize: str | None = None  # the metric
    objective: str = "worst"
    trials: int = 20
    quiet: bool = False
    plots: bool = True


def sweep_command(c: SweepCommand) -> int:
    options = SweepOptions(c.engine, c.address, c.workers, not c.quiet, c.max_samples, c.plots)
    try:
        if c.optimize is None:
            result = sweep(c.spec, c.campaign, c.out, options)
        else:
            result = tune(c.spec, c.campaign, c.out, c.optimize, c.objective, c.trials, options)
    except SpecError as error:
        typer.echo(str(error), err=True)
        return 1
    except UnknownMetric as error:
        typer.echo(f"error: {error}", err=True)
        return 2
    except (OutputFolderError, RuntimeUnavailable, CodegenError, ClusterUnreachable) as error:
        typer.echo(f"error: {error}", err=True)
        return 1
    except ModuleNotFoundError as error:
        if error.name not in ("ray", "optuna"):
            raise
        typer.echo(f"error: dcts sweep{' --optimize' if error.name == 'optuna' else ''} needs {error.name}, which is "
                   "not installed: pip install 'dcts-spec[sweep]'" + (" (or run with --serial)" if error.name == "ray"
                                                                      else ""), err=True)
        return 1
    except KeyboardInterrupt:
        kept = f"the finished samples are in {c.out / SAMPLES}" if (c.out / SAMPLES).is_file() else \
            "no sample had finished"
        typer.echo(f"interrupted: {kept}; run the same command to resume", err=True)
        return INTERRUPTED
    if not c.quiet:
        typer.echo("\n".join(summary_lines(result.report)))
        best = result.report.get("optimize", {}).get("best")
        if best:
            typer.echo(f"  best of {result.report['optimize']['trials']} trials: {best['values']} "
                       f"({result.report['optimize']['objective']} {c.optimize} = {best['value']:.4g})")
        state = "" if result.complete else f" ({result.report['finished']} of {result.report['samples']} samples: " \
                                          "run the same command to go on)"
        written = [name for name in ("samples.jsonl", "report.json", "report.html", "trials.jsonl")
                   if (c.out / name).is_file()]
        written += [f"{name}/" for name, what in (("plots", "plots"), ("replays", "worst_cases")) if result.report[what]]
        typer.echo(f"wrote {c.out}/ ({', '.join(written)}){state}")
    rates = result.report["rates"]
    if rates["samples"] and not rates["ran"]:  # a report of nothing is no result: say so, also under -q
        typer.echo(f"error: no sample ran ({rates['invalid']} invalid, {rates['errors']} errors); each sample's "
                   f"reason is in {c.out / SAMPLES}", err=True)
        return 1
    return 0
