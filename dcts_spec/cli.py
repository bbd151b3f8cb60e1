"""The `dcts` command line: validate, schema, compile, bench, simulate, compare."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from .spec import SpecError

app = typer.Typer(
    name="dcts",
    help="Prioritized torque control of redundant arms from one YAML spec.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _fail(error: SpecError, as_json: bool = False) -> None:
    if as_json:
        typer.echo(json.dumps({"valid": False, "diagnostics": [d.to_dict() for d in error.diagnostics]}, indent=2))
    else:
        typer.echo(str(error), err=True)
    raise typer.Exit(1)


@app.command()
def validate(
    files: Annotated[list[Path], typer.Argument(help="spec files")],
    as_json: Annotated[bool, typer.Option("--json", help="machine-readable output")] = False,
    check: Annotated[bool, typer.Option("--check", help="also compile every formulation and report QP sizes")] = False,
) -> None:
    """Check spec files and summarize them; exit 1 if any has an error."""
    from .validate import compile_check, validate_file

    results, failed = [], False
    for file in files:
        try:
            report = validate_file(file)
        except SpecError as error:
            failed = True
            results.append({"file": str(file), "valid": False, "diagnostics": [d.to_dict() for d in error.diagnostics]})
            if not as_json:
                typer.echo(str(error), err=True)
            continue
        result = report.to_dict()
        if check:
            result["formulations"] = compile_check(report)
        results.append(result)
        if not as_json:
            typer.echo(report.summary())
            for name, info in result.get("formulations", {}).items():
                typer.echo(f"  {name:<11} {info['summary']}")
    if as_json:
        typer.echo(json.dumps(results if len(results) > 1 else results[0], indent=2))
    raise typer.Exit(1 if failed else 0)


@app.command()
def schema(
    output: Annotated[Optional[Path], typer.Option("-o", "--output", help="write here instead of stdout")] = None,
) -> None:
    """Print (or write) the JSON Schema of the spec language."""
    from .spec.schema import spec_json_schema_text

    text = spec_json_schema_text()
    if output is None:
        typer.echo(text, nl=False)
    else:
        output.write_text(text, encoding="utf-8")
        typer.echo(f"wrote {output}")


def main() -> None:
    """Entry point: no Python traceback reaches the user unless DCTS_DEBUG is set."""
    try:
        app()
    except SpecError as error:
        typer.echo(str(error), err=True)
        sys.exit(1)
    except Exception as error:  # a bug, or an environment problem: say what, not where
        if os.environ.get("DCTS_DEBUG"):
            raise
        typer.echo(f"error: {type(error).__name__}: {error} (set DCTS_DEBUG=1 to see the traceback)", err=True)
        sys.exit(2)
