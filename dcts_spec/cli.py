"""The `dcts` command line: validate, schema, compile, bench, simulate, compare, sweep, robots, describe, init.

Conventions shared by every command (see EPILOG): `-o/--out` names what a command writes, with
one default rule; flags take no value; bad option values are usage errors (exit 2), bad specs
and inputs exit 1.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from functools import partial
from pathlib import Path
from typing import Annotated, Literal, Optional, get_args

import typer
from typer.core import TyperCommand, TyperGroup

from .choices import RUNTIMES, TARGETS
from .files import request_stop, stop_signal
from .phases import phase, reporting
from .spec import SpecError
from .spec.controller import Formulation

# Heavy modules (CasADi, Pinocchio, MuJoCo) are imported inside the commands that need them:
# `dcts --help`, `--version` and rejecting a broken spec take a fraction of a second.
FORMULATIONS: tuple[str, ...] = get_args(Formulation)

EPILOG = ("Outputs: every command that writes a folder takes -o/--out DIR; without it, compile writes "
          "build/<name>, simulate runs/<name> and compare runs/<name>-compare (<name>: the spec's `name`). "
          "dcts writes only into a folder that is empty or that the same command wrote, and replaces only its own files. "
          "Exit codes: 0 ok, 1 a bad spec or input (the message says where), 2 a usage error (unknown option, "
          "bad option value), 3 an internal error (a bug: DCTS_DEBUG=1 shows the traceback); validate and describe end "
          "by SIGPIPE (141 in the shell) when their reader stops early, as cat does.")
INTERNAL_ERROR = 3


class _FlagsTakeNoValue:
    """Help without a `<bool>` type after flags (typer shows one for every bool option)."""

    def get_params(self, ctx):  # type: ignore[no-untyped-def]
        params = super().get_params(ctx)  # type: ignore[misc]
        for param in params:
            if getattr(param, "is_flag", False):
                param.metavar = ""
        return params


class _Command(_FlagsTakeNoValue, TyperCommand):
    pass


class _Group(_FlagsTakeNoValue, TyperGroup):
    pass


app = typer.Typer(
    name="dcts",
    cls=_Group,
    help="Prioritized torque control of redundant arms from one YAML spec.",
    epilog=EPILOG,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
)
command = partial(app.command, cls=_Command)

# Choices, listed in the help and checked by the parser (a bad value is a usage error, exit 2).
Runtime = Literal[RUNTIMES]  # type: ignore[valid-type]
Target = Literal[TARGETS]  # type: ignore[valid-type]


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


def _say(message: str) -> None:
    typer.secho(f"{message} …", err=True, dim=True)


@contextmanager
def _feedback(quiet: bool) -> Iterator[None]:
    """Long phases (building, generating C, compiling, simulating, plotting) on stderr, unless quiet."""
    with reporting(None if quiet else _say):
        yield


def _positive(value: Optional[float]) -> Optional[float]:
    if value is not None and not value > 0:
        raise typer.BadParameter(f"must be positive, got {value:g}")
    return value


def _path(text: str) -> Path:
    """An output path option's value. An empty one (an unset shell variable: `-o "$OUT"`) would
    otherwise be the current folder."""
    if not text.strip():
        raise typer.BadParameter("an empty path; give a folder or file name")
    return Path(text)


def _duration(value: Optional[float]) -> Optional[float]:
    """`--duration`: the range `scenario.duration` has (inf or 1e9 s ran out of memory)."""
    from .spec.types import DURATION

    try:
        return DURATION.check(value)
    except ValueError as error:
        raise typer.BadParameter(str(error)) from None


def _formulation_list(value: str) -> list[str]:
    """`--formulations a,b`: the names, each checked (a callback, so an error names the option)."""
    names = [f.strip() for f in value.split(",") if f.strip()]
    if not names:
        raise typer.BadParameter("name at least one formulation")
    unknown = [f for f in names if f not in FORMULATIONS]
    if unknown:
        raise typer.BadParameter(f"unknown formulation {unknown[0]!r}; choose from {', '.join(FORMULATIONS)}")
    twice = [f for i, f in enumerate(names) if f in names[:i]]
    if twice:  # (it ran twice, and the comparison showed one of them twice)
        raise typer.BadParameter(f"{twice[0]} is named twice")
    return names


# Options shared by several commands: one spelling, one help text.
_OUT_DEFAULTS = {"compile": "build/<name>", "simulate": "runs/<name>", "compare": "runs/<name>-compare"}


def _out_help(command_name: str) -> str:
    return f"output folder (default: {_OUT_DEFAULTS[command_name]}, <name> being the spec's `name`)"


OldOutput = Annotated[Optional[Path], typer.Option("--output", hidden=True, parser=_path, metavar="PATH", help="old spelling of --out")]
FormulationOption = Annotated[Optional[Formulation], typer.Option(help="override controller.formulation")]
RuntimeOption = Annotated[Runtime, typer.Option(
    help="controller in the loop: c (the generated C bundle) or python (CasADi from Python)")]
DurationOption = Annotated[Optional[float], typer.Option(callback=_duration, help="override scenario.duration, in s")]
CacheOption = Annotated[bool, typer.Option(
    "--cache/--no-cache", help="c runtime: reuse the built bundle from the cache ($DCTS_CACHE_DIR, else "
    "$XDG_CACHE_HOME/dcts/bundles or ~/.cache/dcts/bundles); --no-cache builds it afresh and leaves the cache alone")]
JsonOption = Annotated[bool, typer.Option("--json", help="machine-readable output")]
QuietOption = Annotated[bool, typer.Option("--quiet", "-q", help="no progress messages on stderr")]
BuildTimeoutOption = Annotated[Optional[float], typer.Option(
    callback=_positive, metavar="SECONDS", help="time-out of each build step (make); on it the step's processes are "
    "ended (default: $DCTS_BUILD_TIMEOUT, else 600)")]


@command()
def validate(
    # (readable=False: an unreadable file is a located error of its own, exit 1, not a usage error)
    files: Annotated[list[Path], typer.Argument(help="spec files", readable=False)],
    as_json: Annotated[bool, typer.Option("--json", help="machine-readable output: a list, one report per file")]
    = False,
    check: Annotated[bool, typer.Option("--check", help="also compile every formulation and report QP sizes")] = False,
    quiet: QuietOption = False,
) -> None:
    """Check spec files and summarize them; exit 1 if any has an error."""
    from .spec import load_spec

    _end_like_a_filter_on_a_closed_pipe()

    results, failed = [], False
    for file in files:
        try:
            spec = load_spec(file)
            from .validate import validate_spec  # Pinocchio and CasADi: only once a spec has parsed

            report = validate_spec(spec)
        except SpecError as error:
            failed = True
            results.append({"file": str(file), "valid": False, "diagnostics": [d.to_dict() for d in error.diagnostics]})
            if not as_json:
                typer.echo(str(error), err=True)
            continue
        result = report.to_dict()
        if check:
            from .controller import compile_check

            with _feedback(quiet):
                phase(f"compiling {report.spec.name} with every formulation")
                result["formulations"] = compile_check(report)
            own = result["formulations"][report.spec.controller.formulation]
            if not own["ok"]:  # the spec's own formulation cannot build it: not a valid spec
                failed = True
                result["valid"] = False
        results.append(result)
        if not as_json:
            typer.echo(report.summary())
            for name, info in result.get("formulations", {}).items():
                typer.echo(f"  {name:<11} {info['summary']}")
    if as_json:
        typer.echo(json.dumps(results, indent=2))
    raise typer.Exit(1 if failed else 0)


@command()
def schema(
    out: Annotated[Optional[Path], typer.Option("--out", "-o", parser=_path, metavar="PATH", help="write the schema to this file instead of "
                                                "printing it (a file there is replaced only if it is a dcts "
                                                "schema)")] = None,
    output: OldOutput = None,
) -> None:
    """Print (or write) the JSON Schema of the spec language."""
    from .spec.schema import SCHEMA_ID, spec_json_schema_text

    text = spec_json_schema_text()
    out = out or output
    if out is None:
        typer.echo(text, nl=False)
        return
    if out.exists() and not _is_our_schema(out, SCHEMA_ID):
        typer.echo(f"error: {out} exists and is not a dcts schema: refusing to overwrite it (dcts schema replaces only "
                   "a schema it wrote); choose another file", err=True)
        raise typer.Exit(1)
    try:
        out.write_text(text, encoding="utf-8")
    except OSError as error:
        typer.echo(f"error: cannot write {out}: {error.strerror}", err=True)
        raise typer.Exit(1) from None
    typer.echo(f"wrote {out}")


def _is_our_schema(path: Path, schema_id: str) -> bool:
    """Is `path` a JSON Schema dcts wrote (any version: its $id)?"""
    try:
        return path.is_file() and json.loads(path.read_text(encoding="utf-8")).get("$id") == schema_id
    except (OSError, ValueError, AttributeError):
        return False


@command()
def simulate(
    file: Annotated[Path, typer.Argument(help="spec file with a `scenario` section", readable=False)],
    out: Annotated[Optional[Path], typer.Option("--out", "-o", parser=_path, metavar="PATH", help=_out_help("simulate"))] = None,
    runtime: RuntimeOption = "c",
    formulation: FormulationOption = None,
    duration: DurationOption = None,
    plots: Annotated[bool, typer.Option("--plots/--no-plots", help="write the PNG plots")] = True,
    viewer: Annotated[bool, typer.Option("--viewer", help="watch the run in MuJoCo's viewer (needs a display)")] = False,
    video: Annotated[Optional[Path], typer.Option(parser=_path, metavar="PATH", help="render the run offscreen to this MP4 file "
                                                                 "(needs ffmpeg, or pip install imageio-ffmpeg)")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="no progress messages or bar, no summary")] = False,
    cache: CacheOption = True,
) -> None:
    """Run the compiled controller against MuJoCo through the spec's scenario; write log, summary, plots."""
    from .sim.display import choose_gl_backend

    if video is not None:
        choose_gl_backend()  # before MuJoCo is imported
    from .sim_commands import RunOptions, simulate_command

    options = RunOptions(runtime=runtime, duration=duration, quiet=quiet, cache=cache)
    with _feedback(quiet):
        code = simulate_command(file, out, options, formulation, plots, viewer, video)
    raise typer.Exit(code)


@command()
def compare(
    file: Annotated[Path, typer.Argument(help="spec file with a `scenario` section", readable=False)],
    formulations: Annotated[str, typer.Option(
        callback=_formulation_list, help=f"comma-separated formulations to run, from {', '.join(FORMULATIONS)}")] = "dcts,osc,qp_md",
    out: Annotated[Optional[Path], typer.Option("--out", "-o", parser=_path, metavar="PATH", help=_out_help("compare"))] = None,
    runtime: RuntimeOption = "c",
    duration: DurationOption = None,
    plots: Annotated[bool, typer.Option("--plots/--no-plots", help="write the overlay plots")] = True,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="no progress messages or bar, no table")] = False,
    cache: CacheOption = True,
) -> None:
    """Run the same scenario with several formulations; write a metrics table and overlay plots."""
    from .sim_commands import RunOptions, compare_command

    options = RunOptions(runtime=runtime, duration=duration, quiet=quiet, cache=cache)
    names: list[str] = formulations  # type: ignore[assignment]  # (the callback split it)
    with _feedback(quiet):
        code = compare_command(file, out, options, names, plots)
    raise typer.Exit(code)


@command()
def sweep(
    file: Annotated[Path, typer.Argument(help="spec file", readable=False)],
    campaign: Annotated[Path, typer.Option("--campaign", "-c", help="campaign file: what is drawn or gridded, "
                                           "how many samples, the seed (see docs/sweep.md)")],
    out: Annotated[Path, typer.Option("--out", "-o", parser=_path, metavar="PATH", help="output folder; running the same command again resumes "
                                      "the campaign in it")],
    serial: Annotated[bool, typer.Option("--serial", help="run the samples in a plain loop in this process "
                                         "instead of Ray (the throughput baseline)")] = False,
    address: Annotated[Optional[str], typer.Option(help="a Ray cluster's address (default: a local Ray session "
                                                   "on every core of this machine)")] = None,
    workers: Annotated[Optional[int], typer.Option(min=1, help="at most this many Ray workers")] = None,
    max_samples: Annotated[Optional[int], typer.Option(min=0, help="run at most this many of the samples not yet "
                                                       "done, then write the report (resume later)")] = None,
    optimize: Annotated[Optional[str], typer.Option(help="tune the campaign's controller values for the best "
                                                    "METRIC over its samples (Optuna)", metavar="METRIC")] = None,
    objective: Annotated[Literal["worst", "mean"], typer.Option(help="--optimize: the worst or the mean METRIC "
                                                                "over the samples")] = "worst",
    trials: Annotated[int, typer.Option(min=1, help="--optimize: controller values tried")] = 20,
    plots: Annotated[bool, typer.Option("--plots/--no-plots", help="write the PNG plots of the metrics against "
                                        "the swept values")] = True,
    quiet: QuietOption = False,
) -> None:
    """Run a campaign of samples (pushes, payloads, mismatch, noise, start states, gains) on the compiled
    controller; write the samples, rates, worst cases with their replay specs, and plots."""
    from .campaign.command import SweepCommand, sweep_command

    command = SweepCommand(file, campaign, out, "serial" if serial else "ray", address, workers, max_samples,
                           optimize, objective, trials, quiet, plots)
    with _feedback(quiet):
        code = sweep_command(command)
    raise typer.Exit(code)


@command("compile")
def compile_(
    file: Annotated[Path, typer.Argument(help="spec file", readable=False)],
    out: Annotated[Optional[Path], typer.Option("--out", "-o", parser=_path, metavar="PATH", help=_out_help("compile"))] = None,
    output: OldOutput = None,
    formulation: FormulationOption = None,
    no_build: Annotated[bool, typer.Option("--no-build", help="write the sources only")] = False,
    target: Annotated[Target, typer.Option(help="host, or cortex-m7: also cross-compile and report flash/RAM")]
    = "host",
    daqp_src: Annotated[Optional[Path], typer.Option(help="DAQP C sources (csrc/) for the firmware; default: "
                                                     "PyPI's source distribution, cached")] = None,
    qemu: Annotated[bool, typer.Option("--qemu/--no-qemu", help="cortex-m7: run the golden test on qemu")] = True,
    as_json: Annotated[bool, typer.Option("--json", help="print the bundle's manifest")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="no progress messages, no summary")] = False,
    build_timeout: BuildTimeoutOption = None,
) -> None:
    """Generate the C bundle of a spec (QP data, DAQP solve, header, build files, golden test) and build it."""
    from .codegen import compile_bundle
    from .spec import load_spec

    with _exit_1_on_errors(), _feedback(quiet):
        spec = load_spec(file)
        directory = out or output or Path("build") / spec.name
        report = compile_bundle(spec, directory, formulation=formulation, build=not no_build, target=target,
                                daqp_src=daqp_src, qemu=qemu, build_timeout=build_timeout)
    if as_json:
        typer.echo(json.dumps(report.manifest, indent=2))
    elif not quiet:
        typer.echo("\n".join(report.lines()))


@command()
def bench(
    file: Annotated[Path, typer.Argument(help="spec file", readable=False)],
    as_json: JsonOption = False,
    formulation: FormulationOption = None,
    states: Annotated[int, typer.Option(min=1, help="states timed in C (per state set)")] = 10000,
    python_states: Annotated[int, typer.Option(min=1, help="states timed in the Python runtime")] = 500,
    quiet: QuietOption = False,
    build_timeout: BuildTimeoutOption = None,
) -> None:
    """Time the generated C step (data and solve), the Python runtime and Pinocchio's dynamics terms."""
    from .codegen.bench import bench as run_bench
    from .codegen.bench import format_report

    with _exit_1_on_errors(), _feedback(quiet):
        phase(f"benchmarking {file}: build the bundle, then time {states} states in C (twice), {python_states} "
              "in Python, Pinocchio's terms and an instruction count")
        result = run_bench(file, formulation=formulation, states=states, python_states=python_states,
                           build_timeout=build_timeout)
    typer.echo(json.dumps(result, indent=2) if as_json else format_report(result))


@command()
def robots(as_json: JsonOption = False) -> None:
    """List the built-in robots (for a spec's `robot: {model: NAME}`)."""
    from .robot.builtin import BUILTIN_ROBOTS
    from .robot.describe import DescribeError, describe

    found = []
    for name in BUILTIN_ROBOTS:
        try:
            found.append(describe(name))
        except DescribeError as error:  # (the Panda comes with example-robot-data)
            typer.echo(f"warning: {name}: {error}", err=True)
    if as_json:
        typer.echo(json.dumps([{k: r.to_dict()[k] for k in ("name", "dof", "mass", "tool_frame", "urdf",
                                                           "locked_joints")} for r in found], indent=2))
        return
    for r in found:
        locked = f", {len(r.locked_joints)} locked" if r.locked_joints else ""
        typer.echo(f"{r.name:<8} {len(r.joints)} joints{locked}, {r.mass:.3g} kg, tool frame {r.tool_frame!r}  "
                   f"({r.urdf})")
    typer.echo("`dcts describe NAME` lists a robot's joints, limits, frames and links; "
               "`dcts init FILE --robot NAME` writes a spec for it.")


@command()
def describe(
    robots: Annotated[list[str], typer.Argument(metavar="ROBOT|URDF|SPEC",
                                                help="a built-in robot, a URDF file or a spec file (its robot)")],
    as_json: Annotated[bool, typer.Option("--json", help="machine-readable output: a list, one robot per "
                                          "argument, SI units")] = False,
) -> None:
    """A robot's joints with position, velocity and torque limits, its frames, and its links with masses."""
    _end_like_a_filter_on_a_closed_pipe()
    from .robot.describe import DescribeError
    from .robot.describe import describe as describe_robot

    found, failed = [], False
    for target in robots:
        try:
            found.append(describe_robot(target))
        except SpecError as error:
            typer.echo(str(error), err=True)
            failed = True
        except DescribeError as error:
            typer.echo(f"error: {error}", err=True)
            failed = True
    if as_json:
        typer.echo(json.dumps([r.to_dict() for r in found], indent=2))
    elif found:
        typer.echo("\n\n".join(r.text() for r in found))
    raise typer.Exit(1 if failed else 0)


@command()
def init(
    file: Annotated[Path, typer.Argument(help="the spec file to write (never overwritten)")],
    robot: Annotated[str, typer.Option(help="a built-in robot (see `dcts robots`) or a URDF file")] = "iiwa14",
) -> None:
    """Write a commented spec to start from: the robot holds its tool at a point; it validates and simulates."""
    from .robot.describe import DescribeError
    from .starter import InitError, write_starter

    try:
        name = write_starter(file, robot)
    except SpecError as error:
        typer.echo(str(error), err=True)
        raise typer.Exit(1) from None
    except (InitError, DescribeError) as error:
        typer.echo(f"error: {error}", err=True)
        raise typer.Exit(1) from None
    typer.echo(f"wrote {file} (spec {name!r}, robot {robot}); next: dcts validate {file}, dcts simulate {file}")


def _end_like_a_filter_on_a_closed_pipe() -> None:
    """For a command that only prints: a reader that stops early (`dcts validate a.yaml b.yaml | head -1`)
    ends it as it ends `cat` (SIGPIPE, 141 in the shell). Click's handling exited 1, "a bad spec", for
    valid specs (found from outside). Not for the commands that write a folder: they finish it."""
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)


def _exit_on_sigterm(signum: int, _frame) -> None:
    # SIGTERM's default ends the process at once; as an exit, the staging folders of a compile
    # or a run are removed on the way out, as on Ctrl-C
    request_stop(signum)
    sys.exit(128 + signum)


def _interrupted(error: BaseException) -> bool:
    """Is a Ctrl-C behind this error? One that lands inside CasADi's C code reaches Python as a
    SystemError (a result with an exception set) whose context is the KeyboardInterrupt."""
    seen: BaseException | None = error
    while seen is not None:
        if isinstance(seen, KeyboardInterrupt):
            return True
        seen = seen.__cause__ or seen.__context__
    return False


def main() -> None:
    """Entry point: no Python traceback reaches the user unless DCTS_DEBUG is set."""
    signal.signal(signal.SIGTERM, _exit_on_sigterm)
    try:
        app()
    except SpecError as error:
        typer.echo(str(error), err=True)
        sys.exit(1)
    except Exception as error:  # a bug, or an environment problem: say what, not where
        if _interrupted(error):
            sys.exit(128 + signal.SIGINT)
        if os.environ.get("DCTS_DEBUG"):
            traceback.print_exc()  # (and still exit 3: re-raised, the interpreter exited 1, "bad spec")
        else:
            typer.echo(f"error: {type(error).__name__}: {error} (set DCTS_DEBUG=1 to see the traceback)", err=True)
        sys.exit(INTERNAL_ERROR)
    finally:
        if (signum := stop_signal()) is not None:  # even if the handler's SystemExit was lost
            sys.exit(128 + signum)
