"""The command line (click; thin).  ``fracas --help``, ``fracas --version``,
``fracas propagate DECK [-o OUT.h5] [--json] [--plot PNG] [--debug]``.

Imports only click and the package version at module import time, so help and version
answer without loading JAX, pydantic, h5py or matplotlib.  Every
:class:`fracas.errors.FracasError` becomes one line ``fracas: error: ...`` on stderr and
exit code 2; the traceback is shown only under ``--debug``.
"""

from __future__ import annotations

import json
import re
import sys
import textwrap
from contextlib import contextmanager
from pathlib import Path

import click

from fracas import __version__

# ----------------------------------------------------------------------------- 80 columns
# Terminal text wraps at word boundaries, never mid-word; a word longer than a line (a long
# path) stays whole on a line of its own, so it can be copied.  (textwrap only: an error
# must not wait for numpy or rich to import.)
WIDTH = 80


def _wrap(text: str, width: int = WIDTH, indent: str = "", more: str = "    ") -> list[str]:
    """``text`` as lines of at most ``width`` columns; continuation lines indented by
    ``indent + more``."""
    lines = textwrap.wrap(
        text,
        width,
        initial_indent=indent,
        subsequent_indent=indent + more,
        break_on_hyphens=False,
        break_long_words=False,
    )
    return [s if len(s) <= width else s.lstrip() for s in lines] or [indent.rstrip()]  # a long word: no indent


def _fill(text: str, width: int = WIDTH, indent: str = "", more: str = "    ") -> str:
    """:func:`_wrap` joined by newlines."""
    return "\n".join(_wrap(text, width, indent, more))


_VALUE_COLUMN = re.compile(r"^(\s*\S.*?\s{2,})\S")


def _fit_block(text: str, width: int = WIDTH) -> str:
    """Every line of ``text`` that is wider than ``width`` wrapped at word boundaries, its
    continuation lines indented under its value column (``label    value``: under
    ``value``; else 4 spaces past the line's own indentation).  Lines that fit are kept."""
    out = []
    for line in text.splitlines():
        if len(line) <= width:
            out.append(line)
            continue
        lead = line[: len(line) - len(line.lstrip())]
        m = _VALUE_COLUMN.match(line)
        hang = " " * len(m.group(1)) if m and len(m.group(1)) <= width // 2 else lead + "    "
        wrapped = textwrap.wrap(
            line.strip(),
            width,
            initial_indent=lead,
            subsequent_indent=hang,
            break_on_hyphens=False,
            break_long_words=False,
        )
        out += [s if len(s) <= width else s.lstrip() for s in wrapped]
    return "\n".join(out)


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def _stdout_is_terminal() -> bool:
    return _is_terminal(sys.stdout)


def _stderr_is_terminal() -> bool:
    return _is_terminal(sys.stderr)


def _say(text: str) -> None:
    """A line of the printout on stdout ("written: PATH", a one-line summary): wrapped to 80
    columns at word boundaries on a terminal; one line when piped (logs and scripts grep it)."""
    click.echo(_fill(text) if _stdout_is_terminal() else text)


def _error_line(text: str) -> None:
    """An error on stderr: one line when stderr is not a terminal (logs, scripts: one line
    per problem to grep), wrapped to 80 columns with indented continuation lines on one."""
    if _stderr_is_terminal():
        text = _fill(text)
    click.echo(text, err=True)


@contextmanager
def _errors(debug: bool):
    """Map FracasError to one line + exit 2 (re-raise under --debug)."""
    from fracas.errors import FracasError

    try:
        yield
    except FracasError as exc:
        if debug:
            raise
        _error_line(f"fracas: error: {exc}")
        sys.exit(exc.exit_code)
    except KeyboardInterrupt:
        click.echo("fracas: interrupted", err=True)
        sys.exit(130)
    except (click.exceptions.Exit, click.ClickException, SystemExit):
        raise
    except Exception as exc:  # a bug: say so briefly, the traceback is one flag away
        if debug:
            raise
        _error_line(f"fracas: internal error: {type(exc).__name__}: {exc} (rerun with --debug for the traceback)")
        sys.exit(1)


def _duration(seconds: float) -> str:
    """12.3 s, 3 min 05 s, 1 h 02 min."""
    if seconds < 60:
        return f"{seconds:.1f} s"
    m, s = divmod(int(round(seconds)), 60)
    if m < 60:
        return f"{m} min {s:02d} s"
    h, m = divmod(m, 60)
    return f"{h} h {m:02d} min"


class _Stages:
    """The ``stage(text)`` callback of a command, as a rich progress display on stderr.

    Each call starts a new step: a spinner, what it is doing, a bar and ``done/total``
    once a count is known (``stage.count(done, total)``), and the step's elapsed time.  A
    step that took 2 s or more leaves a line with its duration.  While a step runs, every
    JAX compilation shows on its own line as ``compiling <function> (first run; cached
    afterwards)`` with its elapsed time (driven by JAX's compile log, which is captured
    here, never printed, and switched back off afterwards).  Off when ``enabled`` is false
    or stderr is not a terminal; ``plain`` then prints each step as one line on stderr.
    """

    LEAVE_S = 2.0

    def __init__(self, enabled: bool, plain: bool = False):
        self.progress = None
        self.task = None
        self.text = ""
        self.plain = False
        self._started = 0.0
        self._compile = None
        self._handler = None
        self._saved: dict = {}
        if not enabled:
            return
        from rich.console import Console

        console = Console(stderr=True)
        if not console.is_terminal:
            self.plain = plain
            return
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn
        from rich.table import Column

        class _IfCounted:
            def render(self, task):
                return super().render(task) if task.total is not None else ""

        class _Count(_IfCounted, MofNCompleteColumn):
            pass

        class _Bar(_IfCounted, BarColumn):
            pass

        self.progress = Progress(
            SpinnerColumn(),
            TextColumn("{task.description}", table_column=Column(no_wrap=True, overflow="ellipsis", ratio=1)),
            _Bar(bar_width=16),
            _Count(),
            TimeElapsedColumn(),
            console=console,
            transient=True,
            expand=True,
        )

    # -- steps
    def __call__(self, text: str) -> None:
        if self.plain:
            click.echo(text, err=True)
            return
        if self.progress is None:
            return
        self._watch_compiles()
        if text == self.text and self.task is not None:
            return
        import time

        self._finish_compile()
        self._finish()
        self.text = text
        self._started = time.monotonic()
        self.task = self.progress.add_task(text, total=None)

    def count(self, done: int, total: int | None) -> None:
        """The current step's count (``done`` of ``total``; None: not known yet)."""
        if self.progress is not None and self.task is not None:
            self.progress.update(self.task, completed=done, total=total)

    def _leave(self, text: str) -> None:
        from rich.text import Text

        self.progress.console.print(Text(text, style="dim"))

    def _finish(self) -> None:
        import time

        if self.task is None:
            return
        took = time.monotonic() - self._started
        self.progress.remove_task(self.task)
        self.task = None
        if took >= self.LEAVE_S:
            self._leave(f"{self.text} ({_duration(took)})")

    # -- JAX compilations (jax_log_compiles: "Compiling jit(f) ...", "Finished XLA compilation ...")
    def _compile_event(self, message: str) -> None:
        import re
        import time

        if self.progress is None:
            return
        m = re.match(r"Compiling (\w+)\(([^)]*)\)", message)
        if m:
            self._finish_compile()
            name = m.group(2) or m.group(1)
            task = self.progress.add_task(f"  compiling {name} (first run; cached afterwards)", total=None)
            self._compile = (task, name, time.monotonic())
        elif message.startswith("Finished XLA compilation"):
            self._finish_compile()

    def _finish_compile(self) -> None:
        import time

        if self._compile is None or self.progress is None:
            return
        task, name, t0 = self._compile
        self._compile = None
        self.progress.remove_task(task)
        took = time.monotonic() - t0
        if took >= self.LEAVE_S:
            self._leave(f"  compiled {name} ({_duration(took)}; cached for later runs)")

    def _watch_compiles(self) -> None:
        """Once JAX is imported: capture its compile log (not before: importing JAX here
        would slow commands that never use it; an environment variable would reach Dask
        workers, which would print the log)."""
        if self._handler is not None or "jax" not in sys.modules:
            return
        import logging

        import jax

        stages = self

        class _Handler(logging.Handler):
            def emit(self, record):
                try:
                    stages._compile_event(record.getMessage())
                except Exception:  # noqa: BLE001  (a display never breaks a run)
                    pass

        log = logging.getLogger("jax")
        self._handler = _Handler(level=logging.WARNING)
        self._saved = {"propagate": log.propagate, "log_compiles": bool(jax.config.jax_log_compiles)}
        log.addHandler(self._handler)
        log.propagate = False  # the compile log drives the display; it is not printed
        jax.config.update("jax_log_compiles", True)

    def __enter__(self):
        if self.progress is not None:
            self.progress.__enter__()
        return self

    def __exit__(self, *exc):
        if self.progress is None:
            return False
        self._finish_compile()
        self._finish()
        self.progress.__exit__(*exc)
        if self._handler is not None:
            import logging

            import jax

            log = logging.getLogger("jax")
            log.removeHandler(self._handler)
            log.propagate = self._saved["propagate"]
            jax.config.update("jax_log_compiles", self._saved["log_compiles"])
            self._handler = None
        return False


@contextmanager
def _progress(enabled: bool, plain: bool = False):
    """Yield a :class:`_Stages` callback (``stage(text)``, ``stage.count(done, total)``)."""
    with _Stages(enabled, plain) as stages:
        yield stages


def _plot_path(plot: Path | None, output: Path | None, named: Path | None) -> Path | None:
    """Where a run's plot goes: ``--plot``; else, when the deck names a plot, beside ``-o``
    (``<output stem>.png``: every output of a run goes where ``-o`` says) or, without
    ``-o``, where the deck names it; else no plot."""
    if plot is not None:
        return plot
    if not named:
        return None
    return Path(output).with_suffix(".png") if output is not None else Path(named)


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


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
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
@click.argument("deck", type=click.Path(dir_okay=True, path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Trajectory file to write (default out/<deck stem>.h5).",
)
@click.option(
    "--json", "as_json", is_flag=True, help="Print one JSON object with the final state instead of the table."
)
@click.option(
    "--plot", type=click.Path(dir_okay=False, path_type=Path), help="Also write a PNG plot of the trajectory."
)
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def propagate(
    ctx: click.Context, deck: Path, output: Path | None, as_json: bool, plot: Path | None, debug: bool
) -> None:
    """Propagate the trajectory of a TOML DECK and write it to an HDF5 file."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        from fracas.errors import NumericalError
        from fracas.io.trajectory_file import read_trajectory_file
        from fracas.pipeline import propagate_deck

        with _progress(True) as stage:
            _, path = propagate_deck(deck, output, on_stage=stage, plot=plot)
            data = read_trajectory_file(path)  # the report reads the file it describes
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
        from fracas.constants import DAY_S
        from fracas.status import RunStatus

        if data.status in (RunStatus.MAX_STEPS, RunStatus.NONFINITE):
            hint = (
                " (raise integrator.max_steps, or loosen integrator.tolerance / raise c_nom)"
                if data.status == RunStatus.MAX_STEPS
                else ""
            )
            raise NumericalError(
                f"{deck}: propagation ended early at t = {data.t_final_s / DAY_S:.6g} days with status "
                f"{data.status} ({data.status_text}){hint}; partial results written to {path}"
            )


# ----------------------------------------------------------------------------- TEAM
@main.group()
def stm() -> None:
    """STM files: build one from a TEAM deck (STMGEN), describe one."""


@stm.command("build")
@click.argument("deck", type=click.Path(dir_okay=True, path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    help="STM file to write (default: errcon.stm_file, else stm_files/<deck stem>.h5).",
)
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def stm_build(ctx: click.Context, deck: Path, output: Path | None, debug: bool) -> None:
    """Integrate the reference of a TEAM DECK once and store its transition matrices."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        from fracas.pipeline import build_stm

        with _progress(True) as stage:
            path, data = build_stm(deck, output, on_stage=stage)
        _say(
            f"written: {path} ({data.n_times} times, {len(data.param_labels)} parameters: "
            f"{', '.join(data.param_labels)})"
        )


@stm.command("info")
@click.argument("file", type=click.Path(dir_okay=False, path_type=Path))
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


@main.command()
@click.argument("deck", type=click.Path(dir_okay=True, path_type=Path))
@click.option(
    "--stm",
    "stm_file",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Read the reference and transition matrices from this STM file instead of integrating.",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Results file to write (default: the deck's [output] results, else out/<deck stem>.h5).",
)
@click.option("--plot", type=click.Path(dir_okay=False, path_type=Path), help="Also write a PNG plot.")
@click.option(
    "--reference-deck",
    type=click.Path(dir_okay=False, path_type=Path),
    help="TOM: the optimized trajectory deck to write (default: beside -o, else the deck's [tom] reference_deck).",
)
@click.option(
    "--trajectory-deck",
    type=click.Path(dir_okay=False, path_type=Path),
    help="TEAM: the reference trajectory deck to use instead of the one [ertraj] deck names.",
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON summary instead of the tables.")
@click.option("--quiet", is_flag=True, help="Print only the one-line summary.")
@_print_options
@click.option(
    "--workers",
    type=click.IntRange(0, 256),
    default=None,
    help="TSIM and sweep decks: Dask LocalCluster worker processes (TSIM default, 0 or 1: in this "
    "process; a sweep's default is one worker per core, 0 in this process).",
)
@click.option(
    "--scheduler",
    metavar="ADDRESS",
    default=None,
    help="TSIM and sweep decks: run on an existing Dask cluster (tcp://...).",
)
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def run(
    ctx: click.Context,
    deck: Path,
    stm_file: Path | None,
    output: Path | None,
    plot: Path | None,
    reference_deck: Path | None,
    trajectory_deck: Path | None,
    as_json: bool,
    quiet: bool,
    verbose: bool,
    velocity_unit: str,
    width: int | None,
    workers: int | None,
    scheduler: str | None,
    debug: bool,
) -> None:
    """Run a DECK in the mode it names (mode = "team": a TEAM study; mode = "tom": targeting and
    optimization; mode = "tsim": a Monte Carlo with guidance; mode = "rendezvous": two-vehicle
    navigation; a trajectory deck: a propagation).  Every file the run writes goes beside -o
    when it is given (files the deck names keep their names); an STM file the deck names
    stays where it says."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        from fracas.config.modes import deck_mode
        from fracas.config.trajectory import read_deck_text
        from fracas.errors import DeckError

        mode = deck_mode(read_deck_text(deck), str(deck))
        if reference_deck is not None and mode != "tom":
            raise DeckError(f'{deck}: --reference-deck is for TOM decks (mode = "tom"); this is a {mode} deck')
        if trajectory_deck is not None and mode != "team":
            raise DeckError(f'{deck}: --trajectory-deck is for TEAM decks (mode = "team"); this is a {mode} deck')
        if mode == "sweep":  # --workers / --scheduler choose where its studies run, as for fracas sweep
            _run_sweep(deck, (), workers, scheduler, True, output)
            return
        if mode == "tom":
            if stm_file is not None:
                raise DeckError(f'{deck}: --stm is for TEAM decks (mode = "team"); this is a TOM deck')
            _run_tom(deck, output, plot, as_json, quiet, reference_deck)
            return
        if mode == "rendezvous":
            if stm_file is not None or workers is not None or scheduler is not None:
                raise DeckError(
                    f"{deck}: --stm, --workers and --scheduler are not for rendezvous decks "
                    "(each vehicle's trajectory deck gives its reference)"
                )
            _run_rendezvous(deck, output, plot, as_json, quiet, width)
            return
        if mode == "tsim":
            if stm_file is not None:
                raise DeckError(f'{deck}: --stm is for TEAM decks (mode = "team"); this is a TSIM deck')
            _run_tsim(deck, output, plot, as_json, quiet, workers, scheduler)
            return
        if workers is not None or scheduler is not None:
            raise DeckError(
                f'{deck}: --workers and --scheduler are for TSIM decks (mode = "tsim"); this is a {mode} deck'
            )
        if mode == "propagate":
            if stm_file is not None:
                raise DeckError(f'{deck}: --stm is for TEAM decks (mode = "team"); this is a trajectory deck')
            ctx.invoke(propagate, deck=deck, output=output, as_json=as_json, plot=plot, debug=debug)
            return
        from fracas.config.team import load_team_deck
        from fracas.pipeline import run_team

        cfg = load_team_deck(deck)
        if trajectory_deck is not None:
            from fracas.config.sweep import varied_deck

            if not trajectory_deck.is_file():
                raise DeckError(f"{trajectory_deck}: --trajectory-deck: no such trajectory deck")
            cfg = varied_deck(
                cfg, {"ertraj.deck": str(trajectory_deck.resolve())}, f"{deck} (--trajectory-deck {trajectory_deck})"
            )
        png = _plot_path(plot, output, cfg.output.plot and cfg.resolve(cfg.output.plot))
        verbosity = _verbosity(quiet, verbose)
        with _progress(not (as_json or quiet)) as stage:
            product, path, source = run_team(cfg, stm_file, output, on_stage=stage, plot=png)
            if product is None:
                _say(f"reference ready ({source}); errcon.analysis = false: no analysis run")
                return
            _team_report(path, png, as_json, verbosity, stage, product.timing, velocity_unit, width)


def _run_rendezvous(deck: Path, output: Path | None, plot: Path | None, as_json: bool, quiet: bool, width) -> None:
    """``fracas run`` on a rendezvous deck: stages, the summary, the plot."""
    from fracas.config.rendezvous import load_rendezvous_deck
    from fracas.pipeline import run_rendezvous
    from fracas.report.rendezvous import plot_rendezvous, summary_text

    cfg = load_rendezvous_deck(deck)
    png = _plot_path(plot, output, cfg.output.plot and cfg.resolve(cfg.output.plot))
    with _progress(not (as_json or quiet)) as stage:
        product, path = run_rendezvous(cfg, output, on_stage=stage, plot=png)
    written = plot_rendezvous(product, png) if png is not None else []
    if as_json:
        click.echo(json.dumps({"results": str(path), "roles": product.roles, "plots": [str(w) for w in written]}))
        return
    if quiet:
        _say(f"{len(product.roles)} roles, {int(product.marks.sum())} marks; results: {path}")
        return
    click.echo(summary_text(product, width=width or 80))
    _say(f"results: {path}")
    for w in written:
        _say(f"plot: {w}")


def _run_tsim(
    deck: Path, output: Path | None, plot: Path | None, as_json: bool, quiet: bool, workers, scheduler
) -> None:
    """``fracas run`` on a TSIM deck: stages, a progress bar over the missions, the summary."""
    from fracas.config.tsim import load_tsim_deck
    from fracas.montecarlo import missions_per_second, run_tsim
    from fracas.report.tsim import plot_tsim, summary_text

    cfg = load_tsim_deck(deck)
    png = _plot_path(plot, output, cfg.output.plot and cfg.resolve(cfg.output.plot))
    if png is not None:
        from fracas.io.atomic import check_output_path

        check_output_path(png, "plot")
    with _progress(not (as_json or quiet), plain=True) as stage:
        product, path = run_tsim(
            cfg, output, workers=workers, scheduler=scheduler, on_stage=stage, progress=stage.count
        )
    written = plot_tsim(product, png) if png is not None else []
    if as_json:
        click.echo(
            json.dumps(
                {
                    "results": str(path),
                    "counts": product.counts,
                    "missions_per_s": missions_per_second(product),
                    "verdicts": [r["verdict"] for r in product.consistency],
                    "plots": [str(w) for w in written],
                }
            )
        )
        return
    if quiet:
        bad = sum(r["verdict"] not in ("consistent", "not compared") for r in product.consistency)
        _say(f"{product.counts['missions']} missions, {bad} outputs flagged; results: {path}")
        return
    click.echo(summary_text(product))
    _say(f"results: {path}  ({missions_per_second(product):.1f} missions/s)")
    for w in written:
        _say(f"plot: {w}")


def _run_tom(
    deck: Path, output: Path | None, plot: Path | None, as_json: bool, quiet: bool, reference_deck: Path | None = None
) -> None:
    """``fracas run`` on a TOM deck: a progress line per iteration, then the summary."""
    from fracas.config.tom import load_tom_deck
    from fracas.io.tom_results import read_tom_results
    from fracas.pipeline import run_tom, tom_outputs
    from fracas.report.tom import PROGRESS_HEADER, plot_tom, progress_line, summary_text

    cfg = load_tom_deck(deck)
    talk = not (as_json or quiet)
    header = [False]

    with _progress(talk) as stage:

        def on_iteration(rec) -> None:
            stage(f"TOM iterations (at most {cfg.tom.max_iterations})")
            stage.count(int(rec.iteration), int(cfg.tom.max_iterations))
            if talk:
                if not header[0]:
                    click.echo(PROGRESS_HEADER)
                    header[0] = True
                click.echo(progress_line(rec))

        product, path, ref = run_tom(
            cfg, output, on_stage=stage, plot=plot, on_iteration=on_iteration, reference_deck=reference_deck
        )
        png = tom_outputs(cfg, output, plot, reference_deck)[2]
        res = read_tom_results(path)
        written = plot_tom(res, png) if png is not None else []
    if as_json:
        click.echo(
            json.dumps(
                {
                    "file": str(path),
                    "reference_deck": str(ref) if ref else None,
                    "converged": bool(product.converged),
                    "stop_reason": product.stop_reason,
                    "final_mass_kg": product.final_mass_kg,
                    "controls": dict(zip(product.control_names, map(float, product.u_final))),
                    "targets": dict(zip(product.target_names, map(float, product.achieved))),
                }
            )
        )
        return
    if quiet:
        verdict = "converged" if product.converged else "NOT converged"
        _say(f"TOM {verdict}: final mass {product.final_mass_kg:.6f} kg; {product.stop_reason}")
    else:
        click.echo(summary_text(res))
    _say(f"results: {path}")
    for w in written:
        _say(f"plot: {w}")


def _sweep_report(file: Path, plot: Path | None, as_json: bool) -> None:
    """``fracas report`` on a sweep table: its studies, how many ran, each failure."""
    from fracas.io.sweep_table import csv_path, read_sweep_table

    t = read_sweep_table(file)
    ok = sum(s == "ok" for s in t.status)
    if plot is not None:
        from fracas.report.sweep import plot_sweep

        plot_sweep(file, plot)
    if as_json:
        out = {"file": str(file), "studies": len(t.status), "ok": ok, "failed": len(t.status) - ok}
        out.update({"inputs": list(t.inputs), "outputs": list(t.outputs)})
        click.echo(json.dumps(out | ({"plot": str(plot)} if plot else {})))
        return
    if t.attrs.get("title"):
        _say(str(t.attrs["title"]))
    _say(f"sweep: {len(t.status)} studies, {ok} ok, {len(t.status) - ok} failed, {float(sum(t.wall_s)):.1f} s of work")
    _say(f"varied: {', '.join(t.inputs) or '-'}")
    _say(f"outputs: {', '.join(t.outputs) or '-'}")
    for i, (s, e) in enumerate(zip(t.status, t.error)):
        if s != "ok":
            click.echo(_fill(f"study {int(t.index[i])}: {e}", indent="  "))
    if plot is not None:
        _say(f"plot: {plot}")
    _say(f"sweep table: {file} (and {csv_path(file)})")


def _verbosity(quiet: bool, verbose: bool) -> str:
    from fracas.errors import FracasError

    if quiet and verbose:
        raise FracasError("--quiet and --verbose: choose one")
    return "quiet" if quiet else ("verbose" if verbose else "normal")


def _team_report(
    path: Path,
    png: Path | None,
    as_json: bool,
    verbosity: str = "normal",
    stage=None,
    extra_timing=None,
    velocity_unit: str = "mm/s",
    width: int | None = None,
    written: bool = True,
) -> None:
    """Print (and plot) a TEAM results file: tables at a verbosity, --json, or --quiet's one line.
    ``written``: the run wrote the file ("written: PATH"); else ``fracas report`` read it
    ("TEAM results file: PATH").

    With ``png``: every plot of the file (:func:`fracas.report.team.plot_all`: ``png`` and the
    B-plane, correlation, error-budget and ΔV plots beside it where they apply), each path
    printed after the tables ("plot: PATH"; --json: ``plot`` and the list ``plots``)."""
    from fracas.report.team import load, plot_all, print_team, quiet_line, summary_dict

    r = load(path)
    plots = []
    if png is not None:
        if stage is not None:
            stage("plotting")
        plots = plot_all(r, png, velocity_unit)  # the printout's units (ΔV in m/s in both)
    if as_json:
        out = summary_dict(r)
        out["timing_s"].update({k: round(float(v), 4) for k, v in (extra_timing or {}).items()})
        if png is not None:
            out["plot"] = str(png)
            out["plots"] = [str(p) for p in plots]
        click.echo(json.dumps(out))
        return
    label = "written" if written else "TEAM results file"
    if verbosity == "quiet":
        _say(quiet_line(r, velocity_unit, label))
    else:
        print_team(r, verbosity=verbosity, velocity_unit=velocity_unit, width=width, file_label=label)
    for p in plots:
        _say(f"plot: {p}")


@main.command()
@click.argument("file", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--plot", type=click.Path(dir_okay=False, path_type=Path), help="Also write a PNG plot.")
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
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        from fracas.errors import ResultsFileError
        from fracas.io.hdf5 import read_kind

        kind = read_kind(file, ResultsFileError, "results file")  # integrity checked before decoding
        if plot is not None:
            from fracas.io.atomic import check_output_path

            check_output_path(plot, "plot")
        if kind == "fracas-team-results":
            _team_report(
                file, plot, as_json, _verbosity(quiet, verbose), None, None, velocity_unit, width, written=False
            )
            return
        if kind == "fracas sweep table":
            _sweep_report(file, plot, as_json)
            return
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
        if kind not in (
            "fracas-rendezvous-results",
            "fracas-tsim-results",
            "fracas-tom-results",
            "fracas-trajectory",
            "",
        ):
            raise ResultsFileError(
                f"{file}: file kind {kind!r}: expected a trajectory, TEAM, TOM, TSIM, sweep or rendezvous results file"
            )
        if kind == "fracas-rendezvous-results":
            from fracas.io.rendezvous_results import read_rendezvous_results
            from fracas.report.rendezvous import plot_rendezvous
            from fracas.report.rendezvous import summary_text as rendezvous_summary

            res = read_rendezvous_results(file)
            if as_json:
                click.echo(json.dumps({"file": str(file), "roles": res.roles, "n_runs": res.n_runs}))
            else:
                click.echo(rendezvous_summary(res, width=width or 80))
            for w in plot_rendezvous(res, plot) if plot is not None else []:
                _say(f"plot: {w}")
            if not as_json:
                _say(f"rendezvous results file: {file}")
            return
        if kind == "fracas-tsim-results":
            from fracas.io.tsim_results import read_tsim_results
            from fracas.report.tsim import plot_tsim
            from fracas.report.tsim import summary_text as tsim_summary

            res = read_tsim_results(file)
            if as_json:
                click.echo(json.dumps({"file": str(file), "counts": res.counts}))
            else:
                click.echo(tsim_summary(res, width=width or 80))
            for w in plot_tsim(res, plot) if plot is not None else []:
                _say(f"plot: {w}")
            if not as_json:
                _say(f"TSIM results file: {file}")
            return
        if kind == "fracas-tom-results":
            from fracas.io.tom_results import read_tom_results
            from fracas.report.tom import plot_tom, summary_text

            res = read_tom_results(file)
            if as_json:
                click.echo(json.dumps({"file": str(file), "attrs": {k: str(v) for k, v in res["attrs"].items()}}))
            else:
                click.echo(summary_text(res, width=width or 80))
            for w in plot_tom(res, plot) if plot is not None else []:
                _say(f"plot: {w}")
            if not as_json:
                _say(f"TOM results file: {file}")
            return
        from fracas.io.trajectory_file import read_trajectory_file
        from fracas.report.trajectory import plot_trajectory, print_summary

        data = read_trajectory_file(file)
        if plot is not None:
            plot_trajectory(data, plot)
        if as_json:
            click.echo(json.dumps({**data.summary_dict(), "file": str(file), **({"plot": str(plot)} if plot else {})}))
        else:
            print_summary(data, None, width=width or 80)
            if plot is not None:
                _say(f"plot: {plot}")
            _say(f"trajectory file: {file}")


@main.command()
@click.argument("deck", type=click.Path(dir_okay=True, path_type=Path))
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
    type=click.Path(dir_okay=False, path_type=Path),
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
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        _run_sweep(deck, vary, workers, scheduler, resume, output)


#: exit status of a sweep whose table is written but some studies failed
SWEEP_FAILED_EXIT = 3


def _run_sweep(deck: Path, vary, workers, scheduler, resume: bool, output: Path | None) -> None:
    from fracas.sweep import sweep_main

    with _progress(True) as stage:

        def progress(done: int, total: int) -> None:
            stage(f"running {total} studies")
            stage.count(done, total)

        stage("preparing the sweep (the first study compiles)")
        table, summary, failed = sweep_main(deck, list(vary), workers, scheduler, resume, output, progress=progress)
    click.echo(summary)
    _say(f"written: {table}")
    if failed:  # the table is written; the exit status says not every study ran
        _error_line(f"fracas: error: sweep: {failed} stud{'ies' if failed > 1 else 'y'} failed")
        sys.exit(SWEEP_FAILED_EXIT)


@main.command()
@click.argument("decks", nargs=-1, required=True, type=click.Path(dir_okay=True, path_type=Path))
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def validate(ctx: click.Context, decks: tuple[Path, ...], debug: bool) -> None:
    """Check DECKS and everything they name (trajectory decks, STM and punch files, user gains,
    output folders, sizes) without integrating anything; every problem on its own line, exit 2
    if there is any."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        from fracas.validate import check_path

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


# ----------------------------------------------------------------------------- exchange files
@main.command()
@click.argument("file", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--oem", "oem_out", type=click.Path(dir_okay=False, path_type=Path), help="Write a CCSDS OEM.")
@click.option(
    "--team",
    "team_file",
    type=click.Path(dir_okay=False, path_type=Path),
    help="With a trajectory FILE: a TEAM results file whose covariances go into the OEM.",
)
@click.option(
    "--covariance",
    type=click.Choice(["true", "assumed", "none"]),
    default=None,
    help="Which knowledge covariance (default: true when the file has it, else assumed; none: states only).",
)
@click.option("--before-update", is_flag=True, help="The covariance before each event's update (P-), not after.")
@click.option(
    "--covariance-at",
    "events",
    multiple=True,
    metavar="EVENT_OR_TIME",
    help="TEAM events for --opm/--csv: an event name (final, eigenvector, ...), days from the epoch, "
    "an ISO TDB epoch, #index or all (repeatable).",
)
@click.option("--opm", "opm_out", type=click.Path(dir_okay=False, path_type=Path), help="Write CCSDS OPM(s).")
@click.option("--csv", "csv_out", type=click.Path(dir_okay=False, path_type=Path), help="Write the covariances as CSV.")
@click.option("--xml", is_flag=True, help="OEM/OPM in XML instead of KVN.")
@click.option("--object-name", default=None, help="OBJECT_NAME (default: the file's title).")
@click.option("--object-id", default="UNKNOWN", show_default=True, help="OBJECT_ID.")
@click.option("--originator", default="FRACAS", show_default=True, help="ORIGINATOR.")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def export(
    ctx: click.Context,
    file: Path,
    oem_out: Path | None,
    team_file: Path | None,
    covariance: str | None,
    before_update: bool,
    events: tuple[str, ...],
    opm_out: Path | None,
    csv_out: Path | None,
    xml: bool,
    object_name: str | None,
    object_id: str,
    originator: str,
    debug: bool,
) -> None:
    """Export FILE (a trajectory or TEAM results file) as CCSDS exchange files (docs/exchange.md):
    --oem a trajectory with covariances; --covariance-at EVENT with --opm and/or --csv the
    covariances of chosen TEAM events."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        from fracas.errors import FracasError
        from fracas.io import ccsds
        from fracas.io.atomic import check_output_path

        if oem_out is None and opm_out is None and csv_out is None:
            raise FracasError(f"{file}: nothing to export: give --oem, --opm or --csv")
        if (opm_out is not None or csv_out is not None) and not events:
            raise FracasError(f"{file}: --opm and --csv need --covariance-at EVENT_OR_TIME (e.g. final, all)")
        if events and opm_out is None and csv_out is None:
            raise FracasError(f"{file}: --covariance-at is for --opm or --csv")
        for out, what in ((oem_out, "OEM"), (opm_out, "OPM"), (csv_out, "CSV")):
            if out is not None:
                check_output_path(out, what)
        entries, team = [], None
        if events:  # everything checked and selected before any file is written
            if ccsds.file_kind(file) != "team":
                raise FracasError(f"{file}: --covariance-at needs a TEAM results file")
            if covariance == "none":
                raise FracasError(f"{file}: --covariance none: --opm and --csv write covariances")
            from fracas.io.team_results import read_team_results

            team = read_team_results(file)
            picked = ccsds.select_events(team, list(events))
            entries = [ccsds.covariance_at(team, k, covariance, before_update) for k in picked]
        if oem_out is not None:
            ccsds.write_oem(
                oem_out,
                file,
                team=team_file,
                covariance=covariance,
                before_update=before_update,
                xml=xml,
                object_name=object_name,
                object_id=object_id,
                originator=originator,
            )
            _say(f"written: {oem_out}")
        if entries:
            if opm_out is not None:
                name = object_name or str(team["attrs"].get("title", "")) or "SPACECRAFT"
                for c in entries:
                    out = opm_out
                    if len(entries) > 1:
                        out = opm_out.with_name(f"{opm_out.stem}_{c['index']:04d}{opm_out.suffix}")
                    ccsds.write_opm(
                        out, c, xml=xml, object_name=name, object_id=object_id, originator=originator, source=file.name
                    )
                    _say(f"written: {out} (event #{c['index']} {c['event']})")
            if csv_out is not None:
                ccsds.write_covariance_csv(csv_out, entries)
                _say(f"written: {csv_out} ({len(entries)} events x {len(entries[0]['labels'])} labels)")


@main.command("compare-oem")
@click.argument("trajectory", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("oem_file", metavar="FILE.oem", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print one JSON summary instead of the table.")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def compare_oem(ctx: click.Context, trajectory: Path, oem_file: Path, as_json: bool, debug: bool) -> None:
    """Position/velocity differences (fracas - OEM) between a TRAJECTORY file and an OEM at
    their common epochs (within 1 µs, same centre)."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        import numpy as np

        from fracas.io.ccsds import compare_oem as compare
        from fracas.timescales import et_to_calendar

        d = compare(trajectory, oem_file)
        dr = np.linalg.norm(d["dr_km"], axis=1)
        dv = np.linalg.norm(d["dv_km_s"], axis=1)
        summary = {
            "trajectory": str(trajectory),
            "oem": str(oem_file),
            "common_epochs": int(dr.size),
            "trajectory_epochs": d["n_trajectory"],
            "oem_epochs": d["n_oem"],
            "other_centre": d["other_centre"],
            "max_dr_km": float(dr.max()),
            "rms_dr_km": float(np.sqrt(np.mean(dr**2))),
            "max_dv_km_s": float(dv.max()),
            "rms_dv_km_s": float(np.sqrt(np.mean(dv**2))),
        }
        if as_json:
            click.echo(json.dumps(summary))
            return
        click.echo(f"{'epoch (TDB)':<27} {'t (d)':>10} {'centre':<8} {'|dr| km':>12} {'|dv| km/s':>12}")
        for k in range(dr.size):
            click.echo(
                f"{et_to_calendar(d['et_s'][k], 6):<27} {d['t_s'][k] / 86400.0:>10.5f} {d['centre'][k]:<8} "
                f"{dr[k]:>12.4e} {dv[k]:>12.4e}"
            )
        _say(
            f"{dr.size} common epochs ({d['n_trajectory']} in the trajectory, {d['n_oem']} in the OEM"
            + (f", {d['other_centre']} with another centre" if d["other_centre"] else "")
            + f"): max |dr| {summary['max_dr_km']:.4e} km, RMS {summary['rms_dr_km']:.4e} km; "
            f"max |dv| {summary['max_dv_km_s']:.4e} km/s, RMS {summary['rms_dv_km_s']:.4e} km/s"
        )


@main.command("import-namelist")
@click.argument("namelist", type=click.Path(dir_okay=True, path_type=Path))
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="TOML deck to write (sub-decks it names are written beside it).",
)
@click.option(
    "--mode",
    type=click.Choice(["propagate", "tom", "team", "tsim", "sweep"]),
    default=None,
    help="Read the deck as this mode (default: the deck's mode label, else its namelists).",
)
@click.option("--force", is_flag=True, help="Overwrite output decks that exist.")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def import_namelist_command(
    ctx: click.Context, namelist: Path, output: Path, mode: str | None, force: bool, debug: bool
) -> None:
    """Import a legacy FRACAS NAMELIST deck ($DATA, $ERTRAJ, $INSIM, ...) as a TOML deck; every
    field that could not be mapped is listed (docs/namelist.md)."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        import textwrap

        from fracas.config.namelist import import_namelist
        from fracas.errors import OutputPathError
        from fracas.io.atomic import atomic_path, check_output_path

        out = check_output_path(output, "TOML deck")
        result = import_namelist(namelist, str(namelist), mode=mode, name=out.stem)
        files = {out: result.toml, **{out.parent / name: text for name, text in result.companions.items()}}
        for path in files:
            check_output_path(path, "TOML deck")
            if path.exists() and not force:
                raise OutputPathError(f"{path}: exists; use --force to overwrite it")
        for path, text in files.items():
            with atomic_path(path) as tmp:
                tmp.write_text(text, encoding="utf-8")

        def say(text: str, indent: str = "") -> None:
            click.echo(
                textwrap.fill(
                    text,
                    80,
                    initial_indent=indent,
                    subsequent_indent=indent + "    ",
                    break_long_words=False,
                    break_on_hyphens=False,
                )
            )

        n_un = len(result.unmapped)
        say(f"imported {namelist} -> {out} ({result.mode} mode): {result.mapped} field(s) mapped, {n_un} not mapped")
        for path in list(files)[1:]:
            say(f"also written: {path}")
        if result.unmapped:
            click.echo("not mapped:")
            for u in result.unmapped:
                say(str(u), "  ")
        if result.notes:
            click.echo("notes:")
            for note in result.notes:
                say(note, "  ")
        from fracas.validate import check_path

        _, problems = check_path(out)
        for line in problems:
            _error_line(f"fracas: error: {line}")
        if problems:
            sys.exit(2)
        say(f"ok: {out} validates")


if __name__ == "__main__":  # python -m fracas.cli
    main()
