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


# ----------------------------------------------------------------------------- TEAM
@main.group()
def stm() -> None:
    """STM files: build one from a TEAM deck (STMGEN), describe one."""


@stm.command("build")
@click.argument("deck", type=click.Path(dir_okay=True, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="STM file to write (default: errcon.stm_file, else stm_files/<deck stem>.h5).")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def stm_build(ctx: click.Context, deck: Path, output: Path | None, debug: bool) -> None:
    """Integrate the reference of a TEAM DECK once and store its transition matrices."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        from fracas.pipeline import build_stm

        with _progress(True) as stage:
            path, data = build_stm(deck, output, on_stage=stage)
        click.echo(f"written: {path} ({data.n_times} times, {len(data.param_labels)} parameters: "
                   f"{', '.join(data.param_labels)})")


@stm.command("info")
@click.argument("file", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def stm_info(ctx: click.Context, file: Path, debug: bool) -> None:
    """Describe an STM FILE: trajectory, times, parameters, versions."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        from fracas.io.stm_file import describe

        click.echo(describe(file))


@main.command()
@click.argument("deck", type=click.Path(dir_okay=True, path_type=Path))
@click.option("--stm", "stm_file", type=click.Path(dir_okay=False, path_type=Path),
              help="Read the reference and transition matrices from this STM file instead of integrating.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Results file to write (default: the deck's [output] results, else out/<deck stem>.h5).")
@click.option("--plot", type=click.Path(dir_okay=False, path_type=Path), help="Also write a PNG plot.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON summary instead of the tables.")
@click.option("--quiet", is_flag=True, help="Print only the one-line summary.")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def run(ctx: click.Context, deck: Path, stm_file: Path | None, output: Path | None, plot: Path | None,
        as_json: bool, quiet: bool, debug: bool) -> None:
    """Run a DECK in the mode it describes: a TEAM study ([ertraj] table) or a propagation."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        from fracas.config.team import is_team_text
        from fracas.errors import DeckError

        try:
            text = Path(deck).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise DeckError(f"{deck}: cannot read: {getattr(exc, 'strerror', None) or exc}") from None
        if not is_team_text(text):
            if stm_file is not None:
                raise DeckError(f"{deck}: --stm is for TEAM decks (with an [ertraj] table); this is a trajectory deck")
            ctx.invoke(propagate, deck=deck, output=output, as_json=as_json, plot=plot, debug=debug)
            return
        from fracas.pipeline import run_team

        with _progress(not as_json) as stage:
            res, path, source = run_team(deck, stm_file, output, on_stage=stage)
            if res is None:
                click.echo(f"reference ready ({source}); errcon.analysis = false: no analysis run")
                return
            png = plot or (res.study.deck.resolve(res.study.deck.output.plot) if res.study.deck.output.plot else None)
            if png is not None:
                stage("plotting")
                from fracas.report.team import plot_team

                plot_team(res, png)
        from fracas.report.team import print_team, summary_dict

        if as_json:
            out = summary_dict(res, path, source)
            if png is not None:
                out["plot"] = str(png)
            click.echo(json.dumps(out))
        elif quiet:
            s = summary_dict(res, path, source)
            click.echo(f"{s['events']} events, {s['measurements_used']} measurements; final assumed RSS "
                       f"{s['assumed']['position_rss_km']:.4g} km, {s['assumed']['velocity_rss_km_s'] * 1e6:.4g} mm/s; "
                       f"written: {path}")
        else:
            print_team(res, path, source)


if __name__ == "__main__":  # python -m fracas.cli
    main()
