"""Mode ``sweep``: a TEAM study run with fields varied (parametric sweeps).

A sweep deck (or a TEAM deck with ``--vary``) -> every study validated -> groups of studies
sharing a reference, on Dask through :mod:`fracas.cluster` -> the sweep table (HDF5 + CSV),
resumable -> the summary.  The orchestrator is :func:`fracas.modes.sweep.run.sweep_main`."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from fracas.config.sweep import parse_sweep_deck
from fracas.config.trajectory import cut
from fracas.modes.base import Console, Mode, ReportOptions, RunOptions
from fracas.modes.sweep.run import sweep_main

__all__ = ["MODE", "SWEEP_FAILED_EXIT", "sweep_problems"]

#: exit status of a sweep whose table is written but some studies failed
SWEEP_FAILED_EXIT = 3


def command(deck: Path, opts: RunOptions, console: Console) -> None:
    """``fracas sweep DECK`` / ``fracas run`` on a sweep deck: the studies, the summary, and
    exit status 3 when some studies failed (the table is written)."""
    with console.progress(True) as stage:

        def progress(done: int, total: int) -> None:
            stage(f"running {total} studies")
            stage.count(done, total)

        stage("preparing the sweep (the first study compiles)")
        table, summary, failed = sweep_main(
            deck, list(opts.vary), opts.workers, opts.scheduler, opts.resume, opts.output, progress=progress
        )
    console.echo(summary)
    console.say(f"written: {table}")
    if failed:  # the table is written; the exit status says not every study ran
        console.error(f"fracas: error: sweep: {failed} stud{'ies' if failed > 1 else 'y'} failed")
        raise SystemExit(SWEEP_FAILED_EXIT)


def report(file: Path, opts: ReportOptions, console: Console) -> None:
    """``fracas report`` on a sweep table: its studies, how many ran, each failure."""
    from fracas.io.sweep_table import csv_path, read_sweep_table

    t = read_sweep_table(file)
    ok = sum(s == "ok" for s in t.status)
    if opts.plot is not None:
        from fracas.report.sweep import plot_sweep

        plot_sweep(file, opts.plot)
    if opts.as_json:
        out = {"file": str(file), "studies": len(t.status), "ok": ok, "failed": len(t.status) - ok}
        out.update({"inputs": list(t.inputs), "outputs": list(t.outputs)})
        console.echo(json.dumps(out | ({"plot": str(opts.plot)} if opts.plot else {})))
        return
    if t.attrs.get("title"):
        console.say(str(t.attrs["title"]))
    console.say(
        f"sweep: {len(t.status)} studies, {ok} ok, {len(t.status) - ok} failed, {float(sum(t.wall_s)):.1f} s of work"
    )
    console.say(f"varied: {', '.join(t.inputs) or '-'}")
    console.say(f"outputs: {', '.join(t.outputs) or '-'}")
    for i, (s, e) in enumerate(zip(t.status, t.error)):
        if s != "ok":
            console.echo(console.fill(f"study {int(t.index[i])}: {e}", indent="  "))
    if opts.plot is not None:
        console.say(f"plot: {opts.plot}")
    console.say(f"sweep table: {file} (and {csv_path(file)})")


def _structural_problems(deck: Any, base: Any, seen: set[str]) -> list[str]:
    """The checks of a TEAM deck that depend on the swept values (the trajectory's span,
    sizes, files) on one study of each set of structural values (studies that differ only
    in sigmas and noise levels share them)."""
    from fracas.config.sweep import is_numeric_field, study_label, varied_deck
    from fracas.validate import team_problems

    src = deck.source_path or "<deck>"
    fields = deck.fields
    structural = [k for k, f in enumerate(fields) if not is_numeric_field(f)]
    if not structural:
        return []
    out: list[str] = []
    groups: set[str] = set()
    for i, values in enumerate(deck.studies()):
        key = repr([values[k] for k in structural])
        if key in groups:
            continue
        groups.add(key)
        head = f"{src}: {study_label(i, fields, values)}: "
        for line in team_problems(varied_deck(base, dict(zip(fields, values)))):
            if line not in seen:
                seen.add(line)
                out.append(head + line)
    return out


def _output_problems(deck: Any) -> list[str]:
    """The files the sweep writes that its deck names (the table, the plot, the results
    folder), checked as :func:`fracas.modes.sweep.run.run_sweep` checks them."""
    from pathlib import Path

    from fracas.errors import OutputPathError
    from fracas.io.atomic import check_output_path
    from fracas.validate import output_problems

    out = output_problems(deck, [("output.table", deck.output.table), ("output.plot", deck.output.plot)])
    folder = deck.sweep.results_folder
    if deck.sweep.keep_results and folder:
        where = deck.resolve(folder)
        src = deck.source_path or "<deck>"
        try:
            if where.exists() and not where.is_dir():
                raise OutputPathError("", reason=f"is a file ({where}); expected a folder")
            check_output_path(Path(where) / "study_00000.h5", "results file")
        except OutputPathError as exc:
            out.append(f'{src}: sweep.results_folder = "{cut(folder)}": {exc.reason}')
    return out


def sweep_problems(deck: Any) -> list[str]:
    """A sweep deck: its study deck (every check of a TEAM deck), then what the sweep refuses
    before any work (:func:`fracas.config.sweep.sweep_problems`: every generated study
    against TeamDeck's schema), then the checks that depend on the swept values, and the
    files it writes (as the run checks them)."""
    return _study_problems(deck) + _output_problems(deck)


def _study_problems(deck: Any) -> list[str]:
    """:func:`sweep_problems` but the outputs."""
    from fracas.config.sweep import sweep_problems as refused
    from fracas.config.team import load_team_deck
    from fracas.errors import FracasError
    from fracas.modes import check_path, mode

    src = deck.source_path or "<deck>"
    study = deck.resolve(deck.sweep.study)
    if not study.is_file():
        return [f'{src}: sweep.study = "{cut(deck.sweep.study)}": no such TEAM deck ({cut(str(study))})']
    name, base_problems = check_path(study)
    if name is None or not mode(name).sweep_study:
        return base_problems or [
            f'{src}: sweep.study = "{cut(deck.sweep.study)}": is a {name} deck, expected a TEAM deck'
        ]
    try:
        base = load_team_deck(study)
    except FracasError as exc:
        return base_problems or list(exc.problems)
    problems = refused(deck, base)
    if problems:
        return list(base_problems) + problems
    return list(base_problems) + _structural_problems(deck, base, set(base_problems))


MODE = Mode(
    name="sweep",
    noun="sweep",
    summary="a TEAM study run with fields varied (parametric sweep table)",
    parse=parse_sweep_deck,
    run=sweep_main,
    command=command,
    results_kinds=("fracas sweep table",),
    report=report,
    problems=sweep_problems,
    run_options=frozenset({"workers", "scheduler"}),
)
