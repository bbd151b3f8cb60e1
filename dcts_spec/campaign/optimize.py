"""`dcts sweep --optimize METRIC`: Optuna searches the campaign's controller values for the best
worst-case (or mean) METRIC over the campaign's samples.

Every trial runs the same samples (the same draws: common random numbers, so trials differ only
by the controller) on the campaign's engine, its swept run-time parameters and formulation
replaced by the trial's. The study lives in the output folder (an Optuna journal file), so an
interrupted optimization resumes with the trials it finished. The best values then run once more
as the campaign's samples, which the usual report describes.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from ..analysis.metrics import json_ready
from ..spec.errors import SpecError
from .document import Distribution
from .report import LOWER_IS_WORSE
from .results import JOURNAL, TRIALS
from .sampling import parameter_columns
from .sweep import CampaignSession, SweepOptions, SweepResult, campaign_session


# A search space: parameter name (or `formulation`) to its range, or to its components' (a
# parameter of several components, e.g. a position: the fixed ones as given, each varying one a
# dimension of the search of its own, `name[i]`)
Space = dict[str, Distribution | list[Distribution] | list[str]]


def search_space(session: CampaignSession) -> Space:
    """The campaign's controller values that vary (a range or a set; a normal distribution has no
    range and is refused at its line)."""
    controller = session.campaign.controller
    space: Space = {}
    src = session.campaign.source
    if controller is None:
        raise SpecError([src.diagnostic((), "--optimize needs controller values to tune: a `controller:` section "
                                         "with `parameters` (or several formulations)")])
    for name, value in controller.parameters.items():
        components = value if isinstance(value, list) else [value]
        for i, component in enumerate(components):
            if component.kind == "normal":
                where = ("controller", "parameters", name, *((i,) if isinstance(value, list) else ()))
                raise SpecError([src.diagnostic(where, "--optimize needs a range (uniform, loguniform) or a set "
                                                "(choice, grid), not normal")])
        if any(component.kind != "fixed" for component in components):
            space[name] = value
    formulations = session.driver.sampler.formulations
    if len(formulations) > 1:
        space["formulation"] = [str(f) for f in formulations]
    if not space:
        raise SpecError([src.diagnostic(("controller",), "--optimize: no controller value varies here: give a "
                                        "parameter a range or a set")])
    return space


def optimize(session: CampaignSession, metric: str, objective: str, trials: int) -> dict[str, Any]:
    """Run the study up to `trials` finished trials; return its record for the report."""
    import optuna
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    space = search_space(session)
    folder = session.folder.folder
    storage = JournalStorage(JournalFileBackend(str(folder / JOURNAL)))
    direction = "maximize" if metric in LOWER_IS_WORSE else "minimize"
    study = optuna.create_study(study_name="dcts-sweep", storage=storage, load_if_exists=True, direction=direction)
    state = optuna.trial.TrialState
    for trial in study.trials:  # (one an interrupted run was in: it never finishes)
        if trial.state == state.RUNNING:
            study.tell(trial.number, state=state.FAIL)
    # A resumed study's sampler continues from its trials: seeded as at the start, TPE proposed the
    # first trials' values again (its first trials are random draws from the seed).
    study.sampler = optuna.samplers.TPESampler(seed=session.campaign.seed + len(study.trials))
    indices = list(range(session.driver.sampler.count))
    finished = sum(t.state == state.COMPLETE for t in study.trials)
    for _ in range(max(0, trials - finished)):
        trial = study.ask()
        values = _suggest_all(trial, space)
        rows = session.run(indices, values)
        score = _objective(rows, metric, objective, direction)
        study.tell(trial, score)
        _append(folder / TRIALS, {"trial": trial.number, "values": values, objective: score})
    best = study.best_trial

    def values_of(t: Any) -> dict[str, Any]:  # (a finished trial's suggestions, as the samples ran them)
        return _suggest_all(optuna.trial.FixedTrial(t.params), space)

    history = [{"trial": t.number, "values": values_of(t), "value": t.value} for t in study.trials
               if t.state == state.COMPLETE]
    return {"metric": metric, "objective": objective, "direction": direction, "trials": len(history),
            "best": {"trial": best.number, "values": values_of(best), "value": best.value}, "history": history}


def _suggest_all(trial: Any, space: Space) -> dict[str, Any]:
    """The trial's controller values: a parameter's components a list (fixed ones as given)."""
    values: dict[str, Any] = {}
    for name, d in space.items():
        if isinstance(d, list) and d and isinstance(d[0], Distribution):
            values[name] = [c.fixed if c.kind == "fixed" else _suggest(trial, f"{name}[{i}]", c)
                            for i, c in enumerate(d)]
        else:
            values[name] = _suggest(trial, name, d)
    return values


def _suggest(trial: Any, name: str, d: Distribution | list[str]) -> Any:
    if isinstance(d, list):
        return trial.suggest_categorical(name, d)
    if d.uniform is not None:
        return trial.suggest_float(name, *d.uniform)
    if d.loguniform is not None:
        return trial.suggest_float(name, *d.loguniform, log=True)
    return trial.suggest_categorical(name, d.values)


def _objective(rows: list[dict[str, Any]], metric: str, objective: str, direction: str) -> float:
    """The worst (or mean) metric over the samples; a sample that did not run counts as the worst
    possible, so a controller that breaks any sample never wins."""
    bad = -math.inf if direction == "maximize" else math.inf
    values = [r.get(metric) if r["status"] == "ok" else None for r in rows]
    values = [bad if v is None else float(v) for v in values]
    if objective == "mean":
        return sum(values) / len(values)
    return min(values) if direction == "maximize" else max(values)


def _ran_with(row: dict[str, Any], values: dict[str, Any]) -> bool:
    """Whether a campaign row ran with these controller values."""
    return all(row.get("formulation") == value if name == "formulation"
               else all(row.get(column) == v for column, v in parameter_columns(name, value).items())
               for name, value in values.items())


def _append(path: Path, record: dict[str, Any]) -> None:
    with path.open("a", encoding="utf-8") as f:
        f.write(json.dumps(json_ready(record), allow_nan=False) + "\n")


def tune(spec_file: str | Path, campaign_file: str | Path, out: str | Path, metric: str, objective: str = "worst",
         trials: int = 20, options: SweepOptions = SweepOptions()) -> SweepResult:
    """Optimize the campaign's controller values for `metric` (see the module docstring), then
    run the campaign's samples with the best ones and write the report."""
    settings = {"mode": "optimize", "metric": metric, "objective": objective}
    with campaign_session(spec_file, campaign_file, out, settings, options, check=search_space) as session:
        record = optimize(session, metric, objective, trials)
        best = record["best"]["values"]
        if any(not _ran_with(row, best) for row in session.rows.values()):
            session.forget_rows()  # the rows of an earlier best (a resumed study found a better one)
        session.parameters = best
        session.run(session.todo())
        return session.finish({"optimize": record})
