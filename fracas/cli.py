"""The command line (click; thin).  ``fracas --help``, ``fracas --version``,
``fracas propagate DECK [-o OUT.h5] [--json] [--plot PNG] [--debug]``.

Imports only click and the package version at module import time, so help and version
answer without loading JAX, pydantic, h5py or matplotlib.  Every
:class:`fracas.errors.FracasError` becomes one line ``fracas: error: ...`` on stderr and
exit code 2; the traceback is shown only under ``--debug``.
"""

from __future__ import annotations

import json
import sys
from contextlib import contextmanager
from pathlib import Path

import click

from fracas import __version__


@contextmanager
def _errors(debug: bool):
    """Map FracasError to one line + exit 2 (re-raise under --debug)."""
    from fracas.errors import FracasError

    try:
        yield
    except FracasError as exc:
        if debug:
            raise
        click.echo(f"fracas: error: {exc}", err=True)
        sys.exit(exc.exit_code)
    except KeyboardInterrupt:
        click.echo("fracas: interrupted", err=True)
        sys.exit(130)
    except (click.exceptions.Exit, click.ClickException, SystemExit):
        raise
    except Exception as exc:  # a bug: say so briefly, the traceback is one flag away
        if debug:
            raise
        click.echo(
            f"fracas: internal error: {type(exc).__name__}: {exc} (rerun with --debug for the traceback)",
            err=True,
        )
        sys.exit(1)


@contextmanager
def _progress(enabled: bool):
    """Yield a ``stage(text)`` callback driving a rich spinner on stderr when it is a terminal."""
    if not enabled:
        yield lambda _text: None
        return
    from rich.console import Console

    console = Console(stderr=True)
    if not console.is_terminal:
        yield lambda _text: None
        return
    with console.status("starting", spinner="dots") as status:
        yield lambda text: status.update(f"{text} ...")


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, "--version", prog_name="fracas", message="%(prog)s %(version)s")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def main(ctx: click.Context, debug: bool) -> None:
    """fracas: low-thrust mission analysis (TOM, TEAM, TSIM) on an Encke/Nystrom core."""
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug


@main.command()
@click.argument("deck", type=click.Path(dir_okay=True, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Trajectory file to write (default out/<deck stem>.h5).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object with the final state instead of the table.")
@click.option("--plot", type=click.Path(dir_okay=False, path_type=Path), help="Also write a PNG plot of the trajectory.")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def propagate(ctx: click.Context, deck: Path, output: Path | None, as_json: bool, plot: Path | None, debug: bool) -> None:
    """Propagate the trajectory of a TOML DECK and write it to an HDF5 file."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        from fracas.errors import NumericalError
        from fracas.pipeline import propagate_deck

        with _progress(True) as stage:
            data, path = propagate_deck(deck, output, on_stage=stage)
            if plot is not None:
                stage("plotting")
                from fracas.report.trajectory import plot_trajectory

                plot_trajectory(data, plot)
        if as_json:
            out = data.summary_dict()
            out["file"] = str(path)
            if plot is not None:
                out["plot"] = str(plot)
            click.echo(json.dumps(out))
        else:
            from fracas.report.trajectory import print_summary

            print_summary(data, path)
        if data.status in (2, 3):
            hint = " (raise integrator.max_steps or c_nom)" if data.status == 2 else ""
            raise NumericalError(
                f"{deck}: propagation ended early at t = {data.t_final_s / 86400.0:.6g} days with status "
                f"{data.status} ({data.status_text}){hint}; partial results written to {path}"
            )


if __name__ == "__main__":  # python -m fracas.cli
    main()
