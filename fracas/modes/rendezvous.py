"""Mode ``rendezvous``: two-vehicle navigation (the relative-navigation filter of the seeds).

deck -> both references and their STMs (build) -> the two-vehicle covariance analysis for
every target role -> single runs -> maneuver uncertainties -> RendezvousProduct -> results
file -> the report."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from fracas.config.rendezvous import parse_rendezvous_deck, rendezvous_problems
from fracas.io.atomic import check_output_path
from fracas.io.inputs import reading_inputs
from fracas.modes.base import (
    Console,
    Mode,
    ReportOptions,
    RunOptions,
    Stage,
    plot_path,
    print_results,
    results_path,
    say_to,
)

__all__ = ["MODE", "run_rendezvous"]


def _check_runs_size(cfg: Any, study: Any) -> None:
    """One line naming single_runs.runs when the runs' error histories (roles x runs x
    events x states float64, held at once, and about as much again while they are flown)
    would take over a quarter of the machine's memory."""
    runs = cfg.single_runs.runs
    try:
        mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # not on this platform: no check
        return
    need = 2 * len(study.roles) * runs * len(study.times_s) * study.n * 8
    if runs and need > mem / 4:
        from fracas.errors import DeckError

        raise DeckError(
            f"{cfg.source_path}: single_runs.runs = {runs}: the runs' error histories would take "
            f"{need / 2**30:.1f} GiB of this machine's {mem / 2**30:.1f} GiB (expected at most a quarter); "
            "use fewer runs or fewer roles"
        )


def single_run_arrays(cfg: Any, study: Any, res: Any, say: Stage) -> dict[str, Any]:
    """The single runs (linear, or on the conics) and what they give: kept error histories,
    maneuver errors, 1- and 3-sigma envelope rates with their standard errors, sample RMS."""
    from fracas.team.two_vehicle import envelope_rates, nonlinear_single_runs, sample_rms, single_runs

    sr = cfg.single_runs
    out: dict[str, Any] = dict.fromkeys(("errors", "maneuver_errors", "env1", "env3", "se1", "se3", "rms"))
    out["nonlinear"] = False
    if sr.runs <= 0:
        return out
    nonlinear = sr.dynamics == "two_body" or (sr.dynamics == "auto" and study.two_body)
    say(f"{sr.runs} single runs per role ({'on the conics' if nonlinear else 'linear'})")
    e = (nonlinear_single_runs if nonlinear else single_runs)(res, sr.runs, sr.seed)
    (out["env1"], out["se1"]), (out["env3"], out["se3"]) = envelope_rates(res, e, 1.0), envelope_rates(res, e, 3.0)
    out["errors"] = e[:, : sr.keep]
    out["rms"] = sample_rms(e)
    men = np.zeros((len(study.roles), sr.runs, len(study.maneuvers), 3))
    for j, m in enumerate(study.maneuvers):
        men[:, :, j] = np.einsum("ij,rnj->rni", np.asarray(m.M), e[:, :, m.k, :12])
    out["maneuver_errors"] = men
    out["nonlinear"] = nonlinear
    return out


def _inputs(cfg: Any) -> tuple:
    """The files a rendezvous run reads: its deck, each vehicle's trajectory deck and STM file."""
    named = [rel for v in (cfg.chaser, cfg.target) for rel in (v.trajectory, v.stm_file) if rel]
    return (cfg.source_path, *(cfg.resolve(rel) for rel in named))


@reading_inputs
def run_rendezvous(
    deck: Any,
    output: str | Path | None = None,
    on_stage: Stage | None = None,
    plot: str | Path | None = None,
    write_results: bool = True,
) -> tuple[Any, Path | None]:
    """``fracas run`` on a rendezvous deck (path or RendezvousDeck): both references ->
    the two-vehicle covariance analysis for every target role -> single runs -> maneuver
    uncertainties -> RendezvousProduct -> results file.  Outputs are checked before any
    work.  Returns (RendezvousProduct, results path or None)."""
    from fracas.build.rendezvous import build_rendezvous
    from fracas.build.rendezvous_product import rendezvous_product
    from fracas.config.rendezvous import RendezvousDeck, load_rendezvous_deck
    from fracas.io.hdf5 import provenance
    from fracas.io.rendezvous_results import write_rendezvous_results
    from fracas.team.two_vehicle import run_rendezvous_study

    say = say_to(on_stage)
    t0 = time.perf_counter()
    say("reading the deck")
    cfg = deck if isinstance(deck, RendezvousDeck) else load_rendezvous_deck(deck)
    out = results_path(cfg, output)
    ins = _inputs(cfg)
    if write_results:
        check_output_path(out, "results file", ins)
    if plot is not None:
        check_output_path(plot, "plot", ins)
    say("integrating both references and their STMs")
    study = build_rendezvous(cfg)
    _check_runs_size(cfg, study)
    t1 = time.perf_counter()
    say(f"covariance analysis ({', '.join(study.roles)})")
    res = run_rendezvous_study(study)
    t2 = time.perf_counter()
    runs = single_run_arrays(cfg, study, res, say)
    t3 = time.perf_counter()
    timing = {"build_s": t1 - t0, "analysis_s": t2 - t1, "single_runs_s": t3 - t2}
    product = rendezvous_product(study, res, runs, cfg, timing, provenance(cfg.source_text, cfg.source_path))
    path = None
    if write_results:
        say("writing the results file")
        path = write_rendezvous_results(out, product)
    return product, path


# ----------------------------------------------------------------------------- the terminal
def command(deck: Path, opts: RunOptions, console: Console) -> None:
    """``fracas run`` on a rendezvous deck: stages, the summary, the plot."""
    from fracas.config.rendezvous import load_rendezvous_deck
    from fracas.report.rendezvous import plot_rendezvous, summary_text

    cfg = load_rendezvous_deck(deck)
    png = plot_path(opts.plot, opts.output, cfg.output.plot and cfg.resolve(cfg.output.plot))
    with console.progress(not (opts.as_json or opts.quiet)) as stage:
        product, path = run_rendezvous(cfg, opts.output, on_stage=stage, plot=png)
    written = plot_rendezvous(product, png) if png is not None else []
    if opts.as_json:
        console.echo(json.dumps({"results": str(path), "roles": product.roles, "plots": [str(w) for w in written]}))
        return
    if opts.quiet:
        console.say(f"{len(product.roles)} roles, {int(product.marks.sum())} marks; results: {path}")
        return
    console.echo(summary_text(product, width=opts.width or 80))
    console.say(f"results: {path}")
    for w in written:
        console.say(f"plot: {w}")


def report(file: Path, opts: ReportOptions, console: Console) -> None:
    """``fracas report`` on a rendezvous results file."""
    from fracas.io.rendezvous_results import read_rendezvous_results
    from fracas.report.rendezvous import plot_rendezvous, summary_text

    res = read_rendezvous_results(file)
    summary = {"file": str(file), "roles": res.roles, "n_runs": res.n_runs}
    print_results(
        file,
        opts,
        console,
        "rendezvous results",
        lambda w: summary_text(res, width=w),
        summary,
        lambda png: plot_rendezvous(res, png),
    )


def rendezvous_deck_problems(deck: Any) -> list[str]:
    """``fracas validate`` on a rendezvous deck: :func:`fracas.config.rendezvous.
    rendezvous_problems`, then the files the run writes that the deck names."""
    from fracas.validate import output_problems

    named = [("output.results", deck.output.results), ("output.plot", deck.output.plot)]
    return rendezvous_problems(deck) + output_problems(deck, named)


MODE = Mode(
    name="rendezvous",
    noun="rendezvous",
    summary="two-vehicle relative navigation and rendezvous maneuvers",
    parse=parse_rendezvous_deck,
    run=run_rendezvous,
    command=command,
    results_kinds=("fracas-rendezvous-results",),
    report=report,
    problems=rendezvous_deck_problems,
)
