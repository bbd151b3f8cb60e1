"""The `dcts` command line: validate, schema, compile, bench, simulate, compare."""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
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


def _print_version(value: bool) -> None:
    """`--version`: dcts and the libraries whose versions decide its numbers (for bug reports)."""
    if not value:
        return
    from importlib.metadata import PackageNotFoundError, version

    def of(package: str) -> str:
        try:
            return version(package)
        except PackageNotFoundError:
            return "not installed"

    libraries = ", ".join(f"{name} {of(package)}" for name, package in
                          (("casadi", "casadi"), ("daqp", "daqp"), ("pinocchio", "pin"), ("mujoco", "mujoco")))
    typer.echo(f"dcts {of('dcts-spec')} ({libraries})")
    raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[bool, typer.Option("--version", callback=_print_version, is_eager=True,
                                          help="print the versions of dcts and its solvers, and exit")] = False,
) -> None:
    """Prioritized torque control of redundant arms from one YAML spec."""


@contextmanager
def _exit_1_on_errors() -> Iterator[None]:
    """A broken spec or a bundle that cannot be generated or built: one message, exit code 1."""
    from .codegen import CodegenError

    try:
        yield
    except SpecError as error:
        typer.echo(str(error), err=True)
        raise typer.Exit(1) from None
    except CodegenError as error:
        typer.echo(f"error: {error}", err=True)
        raise typer.Exit(1) from None


@app.command()
def validate(
    files: Annotated[list[Path], typer.Argument(help="spec files")],
    as_json: Annotated[bool, typer.Option("--json", help="machine-readable output")] = False,
    check: Annotated[bool, typer.Option("--check", help="also compile every formulation and report QP sizes")] = False,
) -> None:
    """Check spec files and summarize them; exit 1 if any has an error."""
    from .controller import compile_check
    from .validate import validate_file

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
        return
    try:
        output.write_text(text, encoding="utf-8")
    except OSError as error:
        typer.echo(f"error: cannot write {output}: {error.strerror}", err=True)
        raise typer.Exit(1) from None
    typer.echo(f"wrote {output}")


_RUNTIME_HELP = "controller in the loop: c (the generated C bundle) or python (CasADi from Python)"
_CACHE_HELP = ("c runtime: reuse the built bundle from the cache ($DCTS_CACHE_DIR or ~/.cache/dcts/bundles); "
               "--no-cache builds it afresh and leaves the cache alone")


@app.command()
def simulate(
    file: Annotated[Path, typer.Argument(help="spec file with a `scenario` section")],
    out: Annotated[Optional[Path], typer.Option("--out", "-o", help="output directory (default: runs/<name>)")] = None,
    runtime: Annotated[str, typer.Option(help=_RUNTIME_HELP)] = "c",
    formulation: Annotated[Optional[str], typer.Option(help="override controller.formulation")] = None,
    duration: Annotated[Optional[float], typer.Option(help="override scenario.duration, in s")] = None,
    plots: Annotated[bool, typer.Option("--plots/--no-plots", help="write the PNG plots")] = True,
    viewer: Annotated[bool, typer.Option("--viewer", help="watch the run in MuJoCo's viewer (needs a display)")] = False,
    video: Annotated[Optional[Path], typer.Option(help="render the run offscreen to this MP4 file")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="no progress bar, no summary")] = False,
    cache: Annotated[bool, typer.Option("--cache/--no-cache", help=_CACHE_HELP)] = True,
) -> None:
    """Run the compiled controller against MuJoCo through the spec's scenario; write log, summary, plots."""
    from .sim.display import choose_gl_backend

    if video is not None:
        choose_gl_backend()  # before MuJoCo is imported
    from .sim.commands import RunOptions, simulate_command

    options = RunOptions(runtime=runtime, duration=duration, quiet=quiet, cache=cache)
    raise typer.Exit(simulate_command(file, out, options, formulation, plots, viewer, video))


@app.command()
def compare(
    file: Annotated[Path, typer.Argument(help="spec file with a `scenario` section")],
    formulations: Annotated[str, typer.Option(help="comma-separated formulations to run")] = "dcts,osc,qp_md",
    out: Annotated[Optional[Path], typer.Option("--out", "-o", help="output directory (default: runs/<name>-compare)")] = None,
    runtime: Annotated[str, typer.Option(help=_RUNTIME_HELP)] = "c",
    duration: Annotated[Optional[float], typer.Option(help="override scenario.duration, in s")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="no progress bar, no table")] = False,
    cache: Annotated[bool, typer.Option("--cache/--no-cache", help=_CACHE_HELP)] = True,
) -> None:
    """Run the same scenario with several formulations; write a metrics table and overlay plots."""
    from .sim.commands import RunOptions, compare_command

    names = [f.strip() for f in formulations.split(",") if f.strip()]
    options = RunOptions(runtime=runtime, duration=duration, quiet=quiet, cache=cache)
    raise typer.Exit(compare_command(file, out, options, names))


@app.command("compile")
def compile_(
    file: Annotated[Path, typer.Argument(help="spec file")],
    output: Annotated[Path, typer.Option("-o", "--output", help="bundle directory (written atomically)")],
    formulation: Annotated[Optional[str], typer.Option(help="override controller.formulation")] = None,
    no_build: Annotated[bool, typer.Option("--no-build", help="write the sources only")] = False,
    target: Annotated[str, typer.Option(help="host, or cortex-m7: also cross-compile and report flash/RAM")] = "host",
    daqp_src: Annotated[Optional[Path], typer.Option(help="DAQP C sources (csrc/) for the firmware; default: "
                                                     "PyPI's source distribution, cached")] = None,
    qemu: Annotated[bool, typer.Option("--qemu/--no-qemu", help="cortex-m7: run the golden test on qemu")] = True,
    as_json: Annotated[bool, typer.Option("--json", help="print the bundle's manifest")] = False,
) -> None:
    """Generate the C bundle of a spec (QP data, DAQP solve, header, build files, golden test) and build it."""
    from .codegen import compile_bundle

    with _exit_1_on_errors():
        report = compile_bundle(file, output, formulation=formulation, build=not no_build, target=target,
                                daqp_src=daqp_src, qemu=qemu)
    typer.echo(json.dumps(report.manifest, indent=2) if as_json else "\n".join(report.lines()))


@app.command()
def bench(
    file: Annotated[Path, typer.Argument(help="spec file")],
    as_json: Annotated[bool, typer.Option("--json", help="machine-readable output")] = False,
    formulation: Annotated[Optional[str], typer.Option(help="override controller.formulation")] = None,
    states: Annotated[int, typer.Option(help="states timed in C (per state set)")] = 10000,
    python_states: Annotated[int, typer.Option(help="states timed in the Python runtime")] = 500,
) -> None:
    """Time the generated C step (data and solve), the Python runtime and Pinocchio's dynamics terms."""
    from .codegen.bench import bench as run_bench
    from .codegen.bench import format_report

    with _exit_1_on_errors():
        result = run_bench(file, formulation=formulation, states=states, python_states=python_states)
    typer.echo(json.dumps(result, indent=2) if as_json else format_report(result))


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
