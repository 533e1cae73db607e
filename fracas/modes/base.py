"""What a mode declares (:class:`Mode`), what the command line hands it (:class:`RunOptions`,
:class:`ReportOptions`, a :class:`Console`), and the path rules every orchestrator shares.

The stages of every mode, in order::

    deck -> validated config -> build (core objects, canonical units) -> core
         -> stage product -> file (trajectory, STM, results) -> report

An orchestrator takes a path or an already validated config object (so a sweep can vary a
study in memory); ``on_stage(text)`` (optional) is told which stage is running so the
command line can show progress.  The core returns statuses; the orchestrators are the layer
that turns a failed single run into the one-line error users see.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from fracas.errors import DeckError

Stage = Callable[[str], None]

#: the ``fracas run`` options a mode may take, with the flag users type
RUN_OPTION_FLAGS: dict[str, str] = {
    "stm_file": "--stm",
    "reference_deck": "--reference-deck",
    "trajectory_deck": "--trajectory-deck",
    "workers": "--workers",
    "scheduler": "--scheduler",
}


class Progress(Protocol):
    """``stage(text)`` starts a step; ``stage.count(done, total)`` counts within it."""

    def __call__(self, text: str) -> None: ...

    def count(self, done: int, total: int | None) -> None: ...


class Console(Protocol):
    """The terminal, as the command line gives it to a mode's commands."""

    def echo(self, text: str) -> None:
        """A block of the report on stdout, as is."""

    def say(self, text: str) -> None:
        """One line on stdout, wrapped at 80 columns on a terminal."""

    def fill(self, text: str, indent: str = "") -> str:
        """``text`` wrapped at word boundaries (80 columns)."""

    def error(self, text: str) -> None:
        """One line on stderr (``fracas: error: ...``)."""

    def progress(self, enabled: bool, plain: bool = False) -> AbstractContextManager[Progress]:
        """A progress display for the steps of a run (off when not ``enabled``)."""


@dataclass(frozen=True)
class ReportOptions:
    """What ``fracas report`` was asked, beyond the file (and what ``fracas run`` shares)."""

    plot: Path | None = None
    as_json: bool = False
    quiet: bool = False
    verbose: bool = False
    velocity_unit: str = "mm/s"
    width: int | None = None


@dataclass(frozen=True)
class RunOptions(ReportOptions):
    """What ``fracas run`` (and ``fracas sweep``) was asked, beyond the deck."""

    output: Path | None = None
    stm_file: Path | None = None
    reference_deck: Path | None = None
    trajectory_deck: Path | None = None
    workers: int | None = None
    scheduler: str | None = None
    resume: bool = True
    vary: tuple[str, ...] = ()


@dataclass(frozen=True)
class Mode:
    """One mode, declared once (its module's ``MODE``; :data:`fracas.modes.REGISTRY` names it).

    name: the deck's ``mode`` value.  noun: how messages name its decks ("TEAM", "trajectory").
    parse: deck text, source -> the validated config.  run: the orchestrator (config or path
    -> product and files).  command: ``fracas run DECK`` (the orchestrator, then the terminal
    report).  results_kinds: the ``file_kind`` of the results files it writes.  report:
    ``fracas report FILE`` on such a file.  problems: ``fracas validate``'s checks beyond
    parsing (everything the deck names), one line each.  run_options: the ``fracas run``
    options it takes (keys of :data:`RUN_OPTION_FLAGS`).  sweep_study: a sweep may vary a
    deck of this mode.
    """

    name: str
    noun: str
    summary: str
    parse: Callable[[str, str], Any]
    run: Callable[..., Any]
    command: Callable[[Path, RunOptions, Console], None]
    results_kinds: tuple[str, ...] = ()
    report: Callable[[Path, ReportOptions, Console], None] | None = None
    problems: Callable[[Any], list[str]] = field(default=lambda _deck: [])
    run_options: frozenset[str] = frozenset()
    sweep_study: bool = False

    def check_run_options(self, deck: Path, opts: RunOptions, all_modes: Sequence[Mode]) -> None:
        """DeckError naming the first option given that this mode does not take (and which
        modes take it)."""
        for key, flag in RUN_OPTION_FLAGS.items():
            if getattr(opts, key) is None or key in self.run_options:
                continue
            owners = [m for m in all_modes if key in m.run_options]
            nouns = " and ".join(m.noun for m in owners)
            labels = ", ".join(f'mode = "{m.name}"' for m in owners)
            raise DeckError(f"{deck}: {flag} is for {nouns} decks ({labels}), not for {self.noun} decks")


def say_to(on_stage: Stage | None) -> Stage:
    """``on_stage``, or a callback that ignores the stages."""
    return on_stage or (lambda _text: None)


def default_output(deck_path: str | Path | None, folder: str = "out") -> Path:
    """``out/<deck stem>.h5`` (relative to the working directory)."""
    return Path(folder) / f"{Path(deck_path or 'deck').stem}.h5"


def beside(output: str | Path | None, named: str | Path | None, default: str | Path | None) -> Path | None:
    """Where a run writes one of its files.  With ``output`` (-o, the run's results file):
    in output's folder, under the name the deck gives it (``named``, already resolved
    against the deck) or else ``default``'s name -- every file a run writes goes where -o
    says.  Without: ``named``, else ``default``."""
    if output is not None:
        name = Path(named or default or "").name
        return Path(output).parent / name if name else None
    if named:
        return Path(named)
    return Path(default) if default is not None else None


def plot_path(plot: Path | None, output: Path | None, named: Path | None) -> Path | None:
    """Where a run's plot goes: ``--plot``; else, when the deck names a plot, beside ``-o``
    (``<output stem>.png``: every output of a run goes where ``-o`` says) or, without
    ``-o``, where the deck names it; else no plot."""
    if plot is not None:
        return plot
    if not named:
        return None
    return Path(output).with_suffix(".png") if output is not None else Path(named)


def results_path(cfg: Any, output: str | Path | None) -> Path:
    """A run's results file: ``-o``; else the deck's ``[output] results``; else ``out/``."""
    if output is not None:
        return Path(output)
    return cfg.resolve(cfg.output.results) if cfg.output.results else default_output(cfg.source_path)


def team_inputs(team: Any) -> tuple[Path | str | None, ...]:
    """The files a TEAM deck reads (for the output checks of the runs that stand on one): the
    deck, its trajectory deck, its STM file and the punch file of its a-priori."""
    named = (
        team.ertraj.deck,
        team.errcon.stm_file,
        team.a_priori.from_punch if team.a_priori is not None else None,
    )
    return (team.source_path, *(team.resolve(rel) for rel in named if rel))


def verbosity(opts: RunOptions | ReportOptions) -> str:
    """ "quiet", "normal" or "verbose" (a FracasError for both flags)."""
    from fracas.errors import FracasError

    if opts.quiet and opts.verbose:
        raise FracasError("--quiet and --verbose: choose one")
    return "quiet" if opts.quiet else ("verbose" if opts.verbose else "normal")


def print_results(
    file: Path,
    opts: ReportOptions,
    console: Console,
    label: str,
    summary: Callable[[int], str],
    as_json: dict[str, Any],
    plot: Callable[[Path], Sequence[Path]],
) -> None:
    """``fracas report``'s common shape: the summary at ``opts.width`` (or one JSON object),
    each plot written (``plot: PATH``), then ``<label> file: FILE``."""
    import json

    if opts.as_json:
        console.echo(json.dumps(as_json))
    else:
        console.echo(summary(opts.width or 80))
    for w in plot(opts.plot) if opts.plot is not None else []:
        console.say(f"plot: {w}")
    if not opts.as_json:
        console.say(f"{label} file: {file}")
