"""Mode ``propagate``: a trajectory deck -> build -> the core -> the trajectory file -> report.

``fracas propagate DECK`` and ``fracas run DECK`` on a trajectory deck (a deck without a
``mode`` line, or ``mode = "propagate"``) run :func:`propagate_deck`."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from fracas.config.trajectory import TrajectoryDeck, load_deck, parse_deck
from fracas.config.trajectory.plausible import state_warnings, warn
from fracas.io.atomic import check_output_path
from fracas.io.inputs import reading_inputs
from fracas.io.trajectory_file import TrajectoryData
from fracas.modes.base import Console, Mode, ReportOptions, RunOptions, Stage, default_output, say_to
from fracas.validate import trajectory_problems

__all__ = ["MODE", "propagate_deck", "run_propagation"]


def run_propagation(problem: Any) -> tuple[Any, Any]:
    """Propagate ``problem`` (with STM and parameter matrices when it asks): (Trajectory, Sensitivities | None)."""
    from fracas.integrate.propagate import propagate, propagate_with_sensitivities

    args = (problem.model, problem.params, problem.ephem, problem.epoch_et_s, problem.x0, problem.t_out)
    if problem.sensitivities:
        traj, sens = propagate_with_sensitivities(*args, problem.param_labels)
    else:
        traj, sens = propagate(*args), None
    return traj, sens


@reading_inputs
def propagate_deck(
    deck: str | Path | TrajectoryDeck,
    output: str | Path | None = None,
    on_stage: Stage | None = None,
    plot: str | Path | None = None,
) -> tuple[TrajectoryData, Path]:
    """Trajectory deck (path or TrajectoryDeck) -> build -> propagate -> trajectory file.

    ``plot``: a PNG the caller will draw; checked with the outputs before any work starts."""
    from fracas.build.trajectory import build_propagation
    from fracas.build.trajectory_product import trajectory_data
    from fracas.io.trajectory_file import write_trajectory_file

    say = say_to(on_stage)
    say("reading the deck")
    cfg = load_deck(deck) if isinstance(deck, (str, Path)) else deck
    ins = (cfg.source_path,)  # and every file it names, noted as it was read (fracas.io.inputs)
    output = check_output_path(output or default_output(cfg.source_path), "trajectory file", ins)
    if plot is not None:
        check_output_path(plot, "plot", ins)
    warn(state_warnings(cfg))  # a unit slip in the initial state, most likely (the run goes on)
    say("building the force model and ephemeris")
    problem = build_propagation(cfg)
    say("compiling and propagating" + (" with sensitivities" if problem.sensitivities else ""))
    traj, sens = run_propagation(problem)
    data = trajectory_data(problem, traj, sens)
    say("writing the trajectory file")
    path = write_trajectory_file(output, data)
    return data, path


def _ended_early(deck: Path, data: TrajectoryData, path: Path) -> None:
    """NumericalError when the propagation stopped short (the file stands, partial)."""
    from fracas.constants import DAY_S
    from fracas.errors import NumericalError
    from fracas.status import RunStatus

    if data.status not in (RunStatus.MAX_STEPS, RunStatus.NONFINITE):
        return
    hint = (
        " (raise integrator.max_steps, or loosen integrator.tolerance / raise c_nom)"
        if data.status == RunStatus.MAX_STEPS
        else " (a collision or a singularity, or integrator.tolerance tighter than this trajectory allows)"
    )
    raise NumericalError(
        f"{deck}: propagation ended early at t = {data.t_final_s / DAY_S:.6g} days with status "
        f"{data.status} ({data.status_text}){hint}; partial results written to {path}"
    )


def command(deck: Path, opts: RunOptions, console: Console) -> None:
    """``fracas propagate DECK`` / ``fracas run DECK``: propagate, then the summary (or JSON)."""
    from fracas.io.trajectory_file import read_trajectory_file

    with console.progress(True) as stage:
        _, path = propagate_deck(deck, opts.output, on_stage=stage, plot=opts.plot)
        data = read_trajectory_file(path)  # the report reads the file it describes
        if opts.plot is not None:
            stage("plotting")
            from fracas.report.trajectory import plot_trajectory

            plot_trajectory(data, opts.plot)
    if opts.as_json:
        out = data.summary_dict()
        out["file"] = str(path)
        if opts.plot is not None:
            out["plot"] = str(opts.plot)
        console.echo(json.dumps(out))
    else:
        from fracas.report.trajectory import print_summary

        print_summary(data, path)
    _ended_early(deck, data, path)


def report(file: Path, opts: ReportOptions, console: Console) -> None:
    """``fracas report`` on a trajectory file."""
    from fracas.io.trajectory_file import read_trajectory_file
    from fracas.report.trajectory import plot_trajectory, print_summary

    data = read_trajectory_file(file)
    if opts.plot is not None:
        plot_trajectory(data, opts.plot)
    if opts.as_json:
        extra = {"plot": str(opts.plot)} if opts.plot else {}
        console.echo(json.dumps({**data.summary_dict(), "file": str(file), **extra}))
        return
    print_summary(data, None, width=opts.width or 80)
    if opts.plot is not None:
        console.say(f"plot: {opts.plot}")
    console.say(f"trajectory file: {file}")


MODE = Mode(
    name="propagate",
    noun="trajectory",
    summary="propagate a trajectory deck (and its STMs when it asks)",
    parse=parse_deck,
    run=propagate_deck,
    command=command,
    results_kinds=("fracas-trajectory", ""),
    report=report,
    problems=trajectory_problems,
)
