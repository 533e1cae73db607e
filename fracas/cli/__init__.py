"""The command line (click; thin).  ``fracas --help``, ``fracas --version``, ``fracas run
DECK``, ``fracas report FILE``, ``fracas validate DECKS``, ``fracas sweep DECK``, ``fracas
propagate DECK``, ``fracas stm build|info`` and the exchange-file commands.

Every mode's work is the registry's (:mod:`fracas.modes`): ``run`` reads the deck's mode and
calls its command, ``report`` finds the mode by the file's kind, ``validate`` asks the mode
for its checks.  Imports only click and the package version at module import time, so help
and version answer without loading JAX, pydantic, h5py or matplotlib.  Every
:class:`fracas.errors.FracasError` becomes one line ``fracas: error: ...`` on stderr and
exit code 2; the traceback is shown only under ``--debug``.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from fracas import __version__
from fracas.cli.console import (
    FracasGroup,
    InputFile,
    OutputFile,
    TerminalConsole,
    _error_line,
    _errors,
    _fit_block,
    _progress,
    _say,
)
from fracas.cli.exchange import compare_oem, export, import_namelist_command

#: exit status of a sweep whose table is written but some studies failed
SWEEP_FAILED_EXIT = 3


def _debug(ctx: click.Context, debug: bool) -> bool:
    return debug or bool((ctx.obj or {}).get("debug"))


def _host_devices(ctx: click.Context, _param, value: int | None) -> int | None:
    """Choose the XLA host-device count before anything imports jax (the command line's
    default stays one device per core, so batches shard over the machine's cores)."""
    import os

    if value is not None:
        os.environ["FRACAS_HOST_DEVICES"] = str(value)
    elif not os.environ.get("FRACAS_HOST_DEVICES") and "xla_force_host_platform_device_count" not in os.environ.get(
        "XLA_FLAGS", ""
    ):
        os.environ["FRACAS_HOST_DEVICES"] = str(os.cpu_count() or 1)
    return value


@click.group(cls=FracasGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, "--version", prog_name="fracas", message="%(prog)s %(version)s")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.option(
    "--host-devices",
    type=click.IntRange(1, 1024),
    default=None,
    callback=_host_devices,
    expose_value=False,
    is_eager=True,
    help="XLA host devices for batched work (default: one per CPU core; env FRACAS_HOST_DEVICES).",
)
@click.pass_context
def main(ctx: click.Context, debug: bool) -> None:
    """fracas: low-thrust mission analysis (TOM, TEAM, TSIM) on an Encke/Nystrom core."""
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug


@main.command()
@click.argument("deck", type=InputFile())
@click.option(
    "-o",
    "--output",
    type=OutputFile("trajectory file"),
    help="Trajectory file to write (default out/<deck stem>.h5).",
)
@click.option(
    "--json", "as_json", is_flag=True, help="Print one JSON object with the final state instead of the table."
)
@click.option("--plot", type=OutputFile("plot"), help="Also write a PNG plot of the trajectory.")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def propagate(
    ctx: click.Context, deck: Path, output: Path | None, as_json: bool, plot: Path | None, debug: bool
) -> None:
    """Propagate the trajectory of a TOML DECK and write it to an HDF5 file."""
    with _errors(_debug(ctx, debug)):
        from fracas.modes import mode
        from fracas.modes.base import RunOptions

        mode("propagate").command(deck, RunOptions(output=output, plot=plot, as_json=as_json), TerminalConsole())


# ----------------------------------------------------------------------------- TEAM
@main.group()
def stm() -> None:
    """STM files: build one from a TEAM deck (STMGEN), describe one."""


@stm.command("build")
@click.argument("deck", type=InputFile())
@click.option(
    "-o",
    "--output",
    type=OutputFile("STM file"),
    help="STM file to write (default: errcon.stm_file, else stm_files/<deck stem>.h5).",
)
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def stm_build(ctx: click.Context, deck: Path, output: Path | None, debug: bool) -> None:
    """Integrate the reference of a TEAM DECK once and store its transition matrices."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        from fracas.modes.stm import build_stm

        with _progress(True) as stage:
            path, data = build_stm(deck, output, on_stage=stage)
        _say(
            f"written: {path} ({data.n_times} times, {len(data.param_labels)} parameters: "
            f"{', '.join(data.param_labels)})"
        )


@stm.command("info")
@click.argument("file", type=InputFile())
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def stm_info(ctx: click.Context, file: Path, debug: bool) -> None:
    """Describe an STM FILE: trajectory, times, parameters, versions."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        from fracas.io.stm_file import describe

        click.echo(_fit_block(describe(file)))


def _print_options(f):
    """--verbose, --velocity-unit, --width: how much of a printout, in which units, how wide."""
    f = click.option(
        "--width",
        type=click.IntRange(60, 400),
        default=None,
        help="Columns of the printout (default: the terminal's, 160 when piped).",
    )(f)
    f = click.option(
        "--velocity-unit",
        type=click.Choice(["km/s", "m/s", "mm/s"]),
        default="mm/s",
        show_default=True,
        help="One unit for every velocity in the printout.",
    )(f)
    f = click.option(
        "--verbose",
        is_flag=True,
        help="Print everything: every eigenvector event with its correlations, the whole event log.",
    )(f)
    return f


def _run_only_options(f: Any) -> Any:
    """The options only ``fracas run`` has: where the reference comes from, TOM's and TEAM's
    reference decks, and where TSIM's and a sweep's work runs."""
    for decorator in reversed(
        (
            click.option(
                "--stm",
                "stm_file",
                type=InputFile(),
                help="Read the reference and transition matrices from this STM file instead of integrating.",
            ),
            click.option(
                "--reference-deck",
                type=OutputFile("reference deck"),
                help="TOM: the optimized trajectory deck to write (default: beside -o, else the deck's [tom] "
                "reference_deck).",
            ),
            click.option(
                "--trajectory-deck",
                type=InputFile(),
                help="TEAM: the reference trajectory deck to use instead of the one [ertraj] deck names.",
            ),
            click.option(
                "--workers",
                type=click.IntRange(0, 256),
                default=None,
                help="TSIM and sweep decks: Dask LocalCluster worker processes (TSIM default, 0 or 1: in this "
                "process; a sweep's default is one worker per core, 0 in this process).",
            ),
            click.option(
                "--scheduler",
                metavar="ADDRESS",
                default=None,
                help="TSIM and sweep decks: run on an existing Dask cluster (tcp://...).",
            ),
        )
    ):
        f = decorator(f)
    return f


@main.command()
@click.argument("deck", type=InputFile())
@_run_only_options
@click.option(
    "-o",
    "--output",
    type=OutputFile("results file"),
    help="Results file to write (default: the deck's [output] results, else out/<deck stem>.h5).",
)
@click.option("--plot", type=OutputFile("plot"), help="Also write a PNG plot.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON summary instead of the tables.")
@click.option("--quiet", is_flag=True, help="Print only the one-line summary.")
@_print_options
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def run(ctx: click.Context, deck: Path, debug: bool, **options: Any) -> None:
    """Run a DECK in the mode it names (mode = "team": a TEAM study; mode = "tom": targeting and
    optimization; mode = "tsim": a Monte Carlo with guidance; mode = "rendezvous": two-vehicle
    navigation; mode = "sweep": a parametric sweep; a trajectory deck: a propagation).  Every
    file the run writes goes beside -o when it is given (files the deck names keep their
    names); an STM file the deck names stays where it says."""
    with _errors(_debug(ctx, debug)):
        from fracas.modes import mode_of_deck, modes
        from fracas.modes.base import RunOptions

        opts = RunOptions(**options)
        mode = mode_of_deck(deck)  # the registry: the deck's mode, its options checked, its command
        mode.check_run_options(deck, opts, modes())
        mode.command(deck, opts, TerminalConsole())


@main.command()
@click.argument("file", type=InputFile())
@click.option("--plot", type=OutputFile("plot"), help="Also write a PNG plot.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON summary instead of the tables.")
@click.option("--quiet", is_flag=True, help="Print only the one-line summary.")
@_print_options
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def report(
    ctx: click.Context,
    file: Path,
    plot: Path | None,
    as_json: bool,
    quiet: bool,
    verbose: bool,
    velocity_unit: str,
    width: int | None,
    debug: bool,
) -> None:
    """Print the report of a results FILE: a trajectory, TEAM, TOM, TSIM, sweep or rendezvous
    results file (its kind is named on the last line, ``<kind> file: FILE``; an STM file is
    described as by ``fracas stm info``)."""
    with _errors(_debug(ctx, debug)):
        from fracas.errors import ResultsFileError
        from fracas.io.hdf5 import read_kind
        from fracas.modes import mode_for_kind
        from fracas.modes.base import ReportOptions, verbosity

        kind = read_kind(file, ResultsFileError, "results file")  # integrity checked before decoding
        if plot is not None:
            from fracas.io.atomic import check_output_path

            check_output_path(plot, "plot", (file,))
        if kind == "fracas-stm":
            from fracas.io.stm_file import describe

            if plot is not None or as_json:
                raise ResultsFileError(f"{file}: an STM file: --plot and --json are for results files")
            click.echo(_fit_block(describe(file)))
            return
        if kind == "fracas-punch":
            raise ResultsFileError(
                f"{file}: a TEAM punch file (knowledge covariances for a later deck's a_priori.from_punch), "
                "not a results file"
            )
        mode = mode_for_kind(kind)
        if mode is None or mode.report is None:
            raise ResultsFileError(
                f"{file}: file kind {kind!r}: expected a trajectory, TEAM, TOM, TSIM, sweep or rendezvous results file"
            )
        opts = ReportOptions(
            plot=plot, as_json=as_json, quiet=quiet, verbose=verbose, velocity_unit=velocity_unit, width=width
        )
        verbosity(opts)
        mode.report(file, opts, TerminalConsole())


@main.command()
@click.argument("deck", type=InputFile())
@click.option(
    "--vary",
    multiple=True,
    metavar="FIELD=VALUES",
    help="Vary a TEAM-deck field: F=1,2,3 | F=start:stop:num | F=log:start:stop:num (repeatable).",
)
@click.option(
    "--workers",
    type=click.IntRange(0, 256),
    default=None,
    help="Dask LocalCluster worker processes (0: in this process; default: one per core).",
)
@click.option("--scheduler", metavar="ADDRESS", default=None, help="Run on an existing Dask cluster (tcp://...).")
@click.option("--resume/--no-resume", default=True, show_default=True, help="Skip the studies already in the table.")
@click.option(
    "-o",
    "--output",
    type=OutputFile("sweep table"),
    help="Sweep table to write (HDF5, with a CSV beside it).",
)
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def sweep(
    ctx: click.Context,
    deck: Path,
    vary: tuple[str, ...],
    workers: int | None,
    scheduler: str | None,
    resume: bool,
    output: Path | None,
    debug: bool,
) -> None:
    """Run a parametric sweep: a sweep DECK (mode = "sweep"), or a TEAM DECK with --vary."""
    with _errors(_debug(ctx, debug)):
        from fracas.modes import mode
        from fracas.modes.base import RunOptions

        opts = RunOptions(output=output, workers=workers, scheduler=scheduler, resume=resume, vary=tuple(vary))
        mode("sweep").command(deck, opts, TerminalConsole())


@main.command()
@click.argument("decks", nargs=-1, required=True, type=InputFile())
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def validate(ctx: click.Context, decks: tuple[Path, ...], debug: bool) -> None:
    """Check DECKS and everything they name (trajectory decks, STM and punch files, user gains,
    output folders, sizes) without integrating anything; every problem on its own line, exit 2
    if there is any."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        from fracas.modes import check_path

        bad = 0
        for deck in decks:
            kind, problems = check_path(deck)
            if problems:
                bad += 1
                for line in problems:
                    _error_line(f"fracas: error: {line}")
            else:
                _say(f"ok: {deck} ({kind})")
        if bad:
            sys.exit(2)


main.add_command(export)
main.add_command(compare_oem)
main.add_command(import_namelist_command)

if __name__ == "__main__":  # python -m fracas.cli
    main()
