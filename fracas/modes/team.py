"""Mode ``team``: TEAM linear covariance analysis (FRACAS TEAM).

deck -> :class:`TeamCase` (build) -> reference (an STM file, or integrated in line) ->
the event schedule's filter (:func:`fracas.team.engine.run_study`) -> TeamProduct ->
results file (and punch file) -> the report."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from fracas.config.team import parse_team_deck
from fracas.constants import DAY_S
from fracas.errors import NumericalError, StmFileError
from fracas.io.atomic import check_output_path
from fracas.io.inputs import reading_inputs
from fracas.modes.base import (
    Console,
    Mode,
    ReportOptions,
    RunOptions,
    Stage,
    beside,
    default_output,
    plot_path,
    results_path,
    say_to,
    verbosity,
)
from fracas.modes.stm import build_stm, load_team, read_reference, reference_failed
from fracas.status import RunStatus
from fracas.validate import team_problems

__all__ = ["MODE", "run_team", "team_report"]


def _check_outputs(
    cfg: Any, out: Path, punch: Path | None, plot: str | Path | None, write_results: bool, stm_in: Path | None
) -> None:
    """Every file the analysis writes, checked before any work: none may be a file the run
    reads (the deck, the files it names, the STM file ``stm_in`` it is about to read)."""
    if not cfg.errcon.analysis:
        return
    ins = (cfg.source_path, stm_in)
    if write_results:
        check_output_path(out, "results file", ins)
    if punch is not None:
        check_output_path(punch, "punch file", ins)
    if plot is not None:
        check_output_path(plot, "plot", ins)


def _stm_to_build(cfg: Any, stm: str | Path | None, where: Path | None) -> tuple[Path | None, bool]:
    """(the STM file to read or build, whether to build it): --stm, else errcon.stm_file; a
    file to build the deck does not name goes beside -o, else into stm_files/."""
    ec = cfg.errcon
    stm_path = Path(stm) if stm is not None else (cfg.resolve(ec.stm_file) if ec.stm_file else None)
    build = stm is None and (
        ec.build_stm is True or (ec.build_stm == "if_missing" and stm_path is not None and not stm_path.exists())
    )
    if build and stm_path is None:
        stem = Path(cfg.source_path or "deck").stem
        stm_path = (
            where.parent / f"{stem}_stm.h5" if where is not None else default_output(cfg.source_path, "stm_files")
        )
    if build:
        check_output_path(stm_path, "STM file", (cfg.source_path,))
    return stm_path, build


def _reference(case: Any, stm_path: Path | None, build: bool, on_stage: Stage | None) -> tuple[Any, Any]:
    """(the study's Reference, the STM file's product or None): built and read, read, or
    integrated in line."""
    from fracas.team.reference import integrate_reference

    say = say_to(on_stage)
    cfg, study = case.deck, case.study
    if build:
        stm_path, _ = build_stm(cfg, stm_path, on_stage, case=case)
    if stm_path is not None:
        if not stm_path.exists():
            raise StmFileError(
                f"{stm_path}: no such STM file (build it with: fracas stm build "
                f"{cfg.source_path or 'DECK'} -o {stm_path})"
            )
        say("reading the STM file")
        return read_reference(study, stm_path)
    say("integrating the reference and its sensitivities")
    ref = integrate_reference(study)
    if ref.status != RunStatus.OK:
        raise reference_failed(case, ref.failed_at_s, ref.integrator_status)
    return ref, None


def _failed_predictions(study: Any, res: Any) -> list[tuple[int, float]]:
    """(event index, target time) of each prediction whose integration stopped short."""
    return [
        (k, t_to)
        for k, stats in res.prediction_status.items()
        for t_to, s in zip(study.schedule.predict_to_s[k], stats)
        if s
    ]


def _product(case: Any, res: Any, ref: Any) -> Any:
    """The run's :class:`TeamProduct` (its settings and provenance)."""
    from fracas.config.trajectory import trajectory_hash
    from fracas.io.hdf5 import provenance
    from fracas.team.result import team_product

    cfg, tdeck = case.deck, case.traj_deck
    return team_product(
        res,
        reference_source=ref.source,
        settings={
            "trajectory_deck": tdeck.source_path or "",
            "trajectory_hash": trajectory_hash(tdeck),
            "print": {
                "every": int(cfg.print.every),
                "process_noise": int(cfg.print.process_noise),
                "correlations": int(cfg.print.correlations),
            },
        },
        provenance=provenance(cfg.source_text, case.study.source),
    )


@reading_inputs
def run_team(
    deck: Any,
    stm: str | Path | None = None,
    output: str | Path | None = None,
    on_stage: Stage | None = None,
    plot: str | Path | None = None,
    write_results: bool = True,
    output_dir: str | Path | None = None,
    case: Any = None,
) -> tuple[Any, Path | None, str]:
    """``fracas run`` on a TEAM deck (path or TeamDeck): case -> reference (STM file or in
    line) -> filter -> TeamProduct -> results file (and punch file).  Every output (results,
    punch, an STM file to build, the ``plot`` the caller will draw) is checked before any work.
    With ``output`` (or ``output_dir``), the punch file and an STM file the deck does not name
    go into that folder (:func:`beside`); an STM file the deck names stays where it says.

    ``write_results=False`` (sweeps, in-memory callers) returns the product without writing the
    results file (the path returned is then None); punch files are still written.

    ``case``: the deck's case when the caller has built it already (:func:`load_team`; TSIM
    keeps it for its plan, so a TEAM case is built once).

    Returns (TeamProduct or None when ``errcon.analysis = false``, results path, reference source).
    """
    from fracas.io.team_results import write_punch, write_team_results
    from fracas.team.engine import run_study

    say = say_to(on_stage)
    t0 = time.perf_counter()
    say("reading the deck")
    case = case if case is not None else load_team(deck)
    cfg, study = case.deck, case.study
    out: Path | None = results_path(cfg, output)
    where = Path(output) if output is not None else (Path(output_dir) / "-" if output_dir is not None else None)
    punch = beside(where, cfg.resolve(cfg.punch.file), None) if cfg.punch is not None else None
    stm_path, build = _stm_to_build(cfg, stm, where)
    _check_outputs(cfg, out, punch, plot, write_results, None if build else stm_path)
    t1 = time.perf_counter()
    ref, product = _reference(case, stm_path, build, on_stage)
    t2 = time.perf_counter()
    if not cfg.errcon.analysis:
        return None, None, ref.source
    res = run_study(study, ref, say, product=product)
    failed = _failed_predictions(study, res)
    t3 = time.perf_counter()
    res.timing.update({"setup_s": t1 - t0, "reference_s": t2 - t1, "analysis_s": t3 - t2})
    product = _product(case, res, ref)
    if write_results:
        say("writing the results file")
        write_team_results(out, product)
    else:
        out = None
    if punch is not None:
        write_punch(punch, product)
    product.timing["total_s"] = time.perf_counter() - t0
    if failed:  # the run and its file stand; the failed prediction is the user's one-line error
        k, t_to = failed[0]
        written = f"; results written to {out}" if out is not None else ""
        raise NumericalError(
            f"{study.source}: prediction from {res.times_s[k] / DAY_S:.6g} d to {t_to / DAY_S:.6g} d: the "
            f"integration stopped before the target (status {int(RunStatus.OUTSIDE_TRAJECTORY)}){written}"
        )
    return product, out, ref.source


# ----------------------------------------------------------------------------- the terminal
def team_report(
    path: Path,
    png: Path | None,
    opts: RunOptions | ReportOptions,
    console: Console,
    stage: Any = None,
    extra_timing: dict[str, float] | None = None,
    written: bool = True,
) -> None:
    """Print (and plot) a TEAM results file: tables at a verbosity, --json, or --quiet's one line.
    ``written``: the run wrote the file ("written: PATH"); else ``fracas report`` read it
    ("TEAM results file: PATH").

    With ``png``: every plot of the file (:func:`fracas.report.team.plot_all`: ``png`` and the
    B-plane, correlation, error-budget and ΔV plots beside it where they apply), each path
    printed after the tables ("plot: PATH"; --json: ``plot`` and the list ``plots``)."""
    from fracas.report.team import load, plot_all, print_team, quiet_line, summary_dict

    level = verbosity(opts)
    r = load(path)
    plots = []
    if png is not None:
        if stage is not None:
            stage("plotting")
        plots = plot_all(r, png, opts.velocity_unit)  # the printout's units (ΔV in m/s in both)
    if opts.as_json:
        out = summary_dict(r)
        out["timing_s"].update({k: round(float(v), 4) for k, v in (extra_timing or {}).items()})
        if png is not None:
            out["plot"] = str(png)
            out["plots"] = [str(p) for p in plots]
        console.echo(json.dumps(out))
        return
    label = "written" if written else "TEAM results file"
    if level == "quiet":
        console.say(quiet_line(r, opts.velocity_unit, label))
    else:
        print_team(r, verbosity=level, velocity_unit=opts.velocity_unit, width=opts.width, file_label=label)
    for p in plots:
        console.say(f"plot: {p}")


def _with_trajectory_deck(cfg: Any, deck: Path, trajectory_deck: Path) -> Any:
    """``--trajectory-deck``: the study on another reference trajectory deck."""
    from fracas.config.sweep import varied_deck
    from fracas.errors import DeckError

    if not trajectory_deck.is_file():
        raise DeckError(f"{trajectory_deck}: --trajectory-deck: no such trajectory deck")
    return varied_deck(
        cfg, {"ertraj.deck": str(trajectory_deck.resolve())}, f"{deck} (--trajectory-deck {trajectory_deck})"
    )


def command(deck: Path, opts: RunOptions, console: Console) -> None:
    """``fracas run`` on a TEAM deck: the stages, then the tables (or --json / --quiet)."""
    from fracas.config.team import load_team_deck

    cfg = load_team_deck(deck)
    if opts.trajectory_deck is not None:
        cfg = _with_trajectory_deck(cfg, deck, opts.trajectory_deck)
    png = plot_path(opts.plot, opts.output, cfg.output.plot and cfg.resolve(cfg.output.plot))
    verbosity(opts)
    with console.progress(not (opts.as_json or opts.quiet)) as stage:
        product, path, source = run_team(cfg, opts.stm_file, opts.output, on_stage=stage, plot=png)
        if product is None:
            console.say(f"reference ready ({source}); errcon.analysis = false: no analysis run")
            return
        team_report(path, png, opts, console, stage, product.timing)


def report(file: Path, opts: ReportOptions, console: Console) -> None:
    """``fracas report`` on a TEAM results file."""
    team_report(file, opts.plot, opts, console, written=False)


MODE = Mode(
    name="team",
    noun="TEAM",
    summary="TEAM linear covariance analysis along a reference trajectory",
    parse=parse_team_deck,
    run=run_team,
    command=command,
    results_kinds=("fracas-team-results",),
    report=report,
    problems=team_problems,
    run_options=frozenset({"stm_file", "trajectory_deck"}),
    sweep_study=True,
)
