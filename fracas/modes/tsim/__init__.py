"""Mode ``tsim``: the Monte Carlo (FRACAS TSIM): the TEAM study it stands on, blocks of
sampled missions with designed and executed guidance, statistics, consistency with the
linear analysis -> results file -> the report.  The orchestrator is
:func:`fracas.modes.tsim.run.run_tsim`; Dask through :mod:`fracas.cluster`."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from fracas.config.tsim import parse_tsim_deck
from fracas.modes.base import Console, Mode, ReportOptions, RunOptions, plot_path, print_results
from fracas.modes.tsim.run import missions_per_second, run_tsim

__all__ = ["MODE", "run_tsim"]


def _json_summary(product: Any, path: Path, written: list[Path]) -> str:
    return json.dumps(
        {
            "results": str(path),
            "counts": product.counts,
            "missions_per_s": missions_per_second(product),
            "verdicts": [r["verdict"] for r in product.consistency],
            "plots": [str(w) for w in written],
        }
    )


def command(deck: Path, opts: RunOptions, console: Console) -> None:
    """``fracas run`` on a TSIM deck: stages, a progress bar over the missions, the summary."""
    from fracas.config.tsim import load_tsim_deck
    from fracas.io.atomic import check_output_path
    from fracas.report.tsim import plot_tsim, summary_text

    cfg = load_tsim_deck(deck)
    png = plot_path(opts.plot, opts.output, cfg.output.plot and cfg.resolve(cfg.output.plot))
    if png is not None:
        check_output_path(png, "plot")
    with console.progress(not (opts.as_json or opts.quiet), plain=True) as stage:
        product, path = run_tsim(
            cfg, opts.output, workers=opts.workers, scheduler=opts.scheduler, on_stage=stage, progress=stage.count
        )
    written = plot_tsim(product, png) if png is not None else []
    if opts.as_json:
        console.echo(_json_summary(product, path, written))
        return
    if opts.quiet:
        bad = sum(r["verdict"] not in ("consistent", "not compared") for r in product.consistency)
        console.say(f"{product.counts['missions']} missions, {bad} outputs flagged; results: {path}")
        return
    console.echo(summary_text(product))
    console.say(f"results: {path}  ({missions_per_second(product):.1f} missions/s)")
    for w in written:
        console.say(f"plot: {w}")


def report(file: Path, opts: ReportOptions, console: Console) -> None:
    """``fracas report`` on a TSIM results file."""
    from fracas.io.tsim_results import read_tsim_results
    from fracas.report.tsim import plot_tsim, summary_text

    res = read_tsim_results(file)
    summary = {"file": str(file), "counts": res.counts}
    print_results(
        file,
        opts,
        console,
        "TSIM results",
        lambda w: summary_text(res, width=w),
        summary,
        lambda png: plot_tsim(res, png),
    )


def tsim_problems(deck: Any) -> list[str]:
    """``fracas validate`` on a TSIM deck: its own checks, then the TEAM deck it stands on,
    and the files the run writes that the deck names (as :func:`run_tsim` checks them)."""
    from fracas.config.tsim import tsim_problems as problems
    from fracas.modes import check_path
    from fracas.validate import output_problems

    named = [("output.results", deck.output.results), ("output.plot", deck.output.plot)]
    outputs = output_problems(deck, named)
    return (problems(deck) or check_path(deck.resolve(deck.insim.team_deck))[1]) + outputs


MODE = Mode(
    name="tsim",
    noun="TSIM",
    summary="Monte Carlo of sampled errors with designed and executed guidance",
    parse=parse_tsim_deck,
    run=run_tsim,
    command=command,
    results_kinds=("fracas-tsim-results",),
    report=report,
    problems=tsim_problems,
    run_options=frozenset({"workers", "scheduler"}),
)
