"""The stages in order, for every mode:

    deck -> validated config -> build (core objects, canonical units) -> core
         -> stage product -> file (trajectory, STM, results) -> report

``run(deck)`` dispatches on the deck's ``mode``; each command-line subcommand enters the
chain at its own stage.  Entry points take a path or an already validated config object
(so a sweep can vary a study in memory); ``on_stage(text)`` (optional) is told which stage
is running so the command line can show progress.  The core returns statuses; this is the
layer that turns a failed single run into the one-line error users see.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from fracas.build.trajectory import Problem, build_propagation
from fracas.config.modes import load_any
from fracas.config.trajectory import TrajectoryDeck, load_deck, trajectory_hash
from fracas.constants import DAY_S
from fracas.errors import NumericalError, StmFileError
from fracas.io.atomic import check_output_path
from fracas.io.hdf5 import provenance
from fracas.io.trajectory_file import SensitivityData, TrajectoryData, write_trajectory_file
from fracas.status import RunStatus

Stage = Callable[[str], None]

__all__ = [
    "run",
    "propagate_deck",
    "load_team",
    "build_stm",
    "run_team",
    "reference_from_stm",
    "stm_product",
    "default_output",
]


def _say(on_stage: Stage | None) -> Stage:
    return on_stage or (lambda _text: None)


def default_output(deck_path: str | Path | None, folder: str = "out") -> Path:
    """``out/<deck stem>.h5`` (relative to the working directory)."""
    return Path(folder) / f"{Path(deck_path or 'deck').stem}.h5"


def run(deck, **kw):
    """Run a deck (path or validated config) in the mode it names: ``propagate`` or ``team``."""
    cfg = load_any(deck) if isinstance(deck, (str, Path)) else deck
    if isinstance(cfg, TrajectoryDeck):
        return propagate_deck(cfg, kw.get("output"), kw.get("on_stage"), kw.get("plot"))
    return run_team(cfg, kw.get("stm"), kw.get("output"), kw.get("on_stage"), kw.get("plot"))


# ----------------------------------------------------------------------------- propagation
def run_propagation(problem: Problem):
    """Propagate ``problem`` (with STM and parameter matrices when it asks): (Trajectory, Sensitivities | None)."""
    from fracas.integrate.propagate import propagate, propagate_with_sensitivities

    args = (problem.model, problem.params, problem.ephem, problem.epoch_et_s, problem.x0, problem.t_out)
    if problem.sensitivities:
        traj, sens = propagate_with_sensitivities(*args, problem.param_labels)
    else:
        traj, sens = propagate(*args), None
    return traj, sens


def trajectory_data(problem: Problem, traj, sens) -> TrajectoryData:
    """Core outputs (JAX arrays) -> the :class:`TrajectoryData` product (numpy, names, provenance)."""
    from fracas.params import param_unit
    from fracas.timescales import et_to_calendar

    bodies = problem.model.bodies
    t = np.asarray(traj.t, dtype=np.float64)
    x = np.asarray(traj.x, dtype=np.float64)
    pidx = np.asarray(traj.primary).astype(int)
    name = lambda i, ok=True: bodies[i] if ok and 0 <= i < len(bodies) else ""  # noqa: E731
    sdata = None
    if sens is not None:
        sdata = SensitivityData(
            stm=np.asarray(sens.stm, np.float64),
            stm_step=np.asarray(sens.stm_step, np.float64),
            par=np.asarray(sens.par, np.float64),
            par_step=np.asarray(sens.par_step, np.float64),
            param_labels=problem.param_labels,
            param_units=tuple(param_unit(lab, problem.model) for lab in problem.param_labels),
        )
    xf = np.asarray(traj.x_final, dtype=np.float64)
    return TrajectoryData(
        epoch_et_s=float(problem.epoch_et_s),
        t_s=t,
        r_km=x[:, 0:3],
        v_km_s=x[:, 3:6],
        mass_kg=x[:, 6],
        primary=tuple(name(int(i), bool(np.isfinite(tk))) for i, tk in zip(pidx, t)),
        bodies=bodies,
        t_final_s=float(traj.t_final),
        r_final_km=xf[0:3],
        v_final_km_s=xf[3:6],
        mass_final_kg=float(xf[6]),
        primary_final=name(int(traj.primary_final)),
        status=int(traj.status),
        n_steps=int(traj.n_steps),
        n_rect=int(traj.n_rect),
        n_reject=int(traj.n_reject),
        integrator=describe_integrator(problem.model.integrator),
        centre=problem.centre,
        title=problem.title,
        epoch_tdb=et_to_calendar(problem.epoch_et_s),
        sensitivities=sdata,
        provenance=provenance(problem.source_text, problem.source_path),
    )


def describe_integrator(st) -> str:
    """One line naming the method, formulation and step control (the results file, the summary)."""
    rule = f"tolerance {st.tolerance:g}" if st.adaptive else f"c_nom {st.c_nom:g}"
    return f"{st.method}, {st.formulation}, {rule}"


def propagate_deck(
    deck, output: str | Path | None = None, on_stage: Stage | None = None, plot: str | Path | None = None
) -> tuple[TrajectoryData, Path]:
    """Trajectory deck (path or TrajectoryDeck) -> build -> propagate -> trajectory file.

    ``plot``: a PNG the caller will draw; checked with the outputs before any work starts."""
    say = _say(on_stage)
    say("reading the deck")
    cfg = load_deck(deck) if isinstance(deck, (str, Path)) else deck
    output = check_output_path(output or default_output(cfg.source_path), "trajectory file")
    if plot is not None:
        check_output_path(plot, "plot")
    say("building the force model and ephemeris")
    problem = build_propagation(cfg)
    say("compiling and propagating" + (" with sensitivities" if problem.sensitivities else ""))
    traj, sens = run_propagation(problem)
    data = trajectory_data(problem, traj, sens)
    say("writing the trajectory file")
    path = write_trajectory_file(output, data)
    return data, path


# ----------------------------------------------------------------------------- TEAM
def load_team(deck):
    """TEAM deck (path or TeamDeck) -> :class:`fracas.build.team.TeamCase` (with a punched
    a-priori when the deck names one)."""
    from fracas.build.team import build_case
    from fracas.config.team import TeamDeck, load_team_deck
    from fracas.io.team_results import read_punch

    cfg = deck if isinstance(deck, TeamDeck) else load_team_deck(deck)
    punched = None
    if cfg.a_priori is not None and cfg.a_priori.from_punch:
        punched = read_punch(cfg.resolve(cfg.a_priori.from_punch), cfg.source_path or "<deck>")
    return build_case(cfg, punched)


def _reference_failed(case, failed_at_s: float, integrator_status: int) -> NumericalError:
    return NumericalError(
        f"{case.traj_deck.source_path}: the reference trajectory stopped before t = {failed_at_s / DAY_S:.6g} d "
        f"(status {int(integrator_status)}); the study's times must lie on the trajectory"
    )


def stm_product(case):
    """STMGEN: integrate the case's reference once over every STM-file time with every
    parameter column -> :class:`fracas.products.ReferenceTrajectory`."""
    import dataclasses

    from fracas.build.reference import reference_product
    from fracas.build.team import stm_file_labels, stm_file_times
    from fracas.team.reference import run_reference

    study = case.study
    times = stm_file_times(case)
    labels = stm_file_labels(case)
    traj, sens, status, failed_at = run_reference(study.problem, times, labels)
    if status != RunStatus.OK:
        raise _reference_failed(case, failed_at, traj.status)
    sched = study.schedule
    ev = []
    for t in times:
        k = int(np.argmin(np.abs(sched.times_s - t)))
        ev.append("+".join(sched.events[k]) if abs(sched.times_s[k] - t) < 1e-6 else "grid")
    if ev and times[0] == 0.0 and "initial" not in ev[0]:
        ev[0] = "initial" if ev[0] == "grid" else "initial+" + ev[0]
    pr = dataclasses.replace(study.problem, t_out=times, param_labels=tuple(labels))
    tdeck = case.traj_deck
    return reference_product(pr, traj, sens, ev, tdeck.source_text or "", trajectory_hash(tdeck), tdeck.source_path)


def build_stm(deck, output: str | Path | None = None, on_stage: Stage | None = None, case=None):
    """``fracas stm build``: the reference product of a TEAM deck, written as an STM file.

    ``case``: the deck's already-built case (``run_team`` with ``errcon.build_stm``)."""
    from fracas.io.stm_file import write_stm_file

    say = _say(on_stage)
    if case is None:
        say("reading the deck")
        case = load_team(deck)
    if output is None:
        ec = case.deck.errcon
        output = case.deck.resolve(ec.stm_file) if ec.stm_file else default_output(case.deck.source_path, "stm_files")
    output = check_output_path(output, "STM file")
    say("integrating the reference and its sensitivities")
    data = stm_product(case)
    say("writing the STM file")
    write_stm_file(output, data)
    return Path(output), data


def reference_from_stm(study, stm_path: str | Path):
    """STMRDR: a study's columns and times from an STM file, checked against its trajectory."""
    return read_reference(study, stm_path)[0]


def read_reference(study, stm_path: str | Path):
    """STMRDR: (the study's Reference, the file's ReferenceTrajectory with the study's
    columns), checked against its trajectory; guidance reads cutoff and target times from it."""
    from fracas.io.stm_file import check_trajectory, read_stm_file
    from fracas.team.reference import reference_from_product

    data = read_stm_file(
        stm_path,
        labels=study.dynamic_labels,
        times_s=study.schedule.times_s,
        epoch_et_s=float(study.problem.epoch_et_s),
    )  # within 1e-6 s, absolute
    check_trajectory(data, study.trajectory_hash, stm_path, study.trajectory_source)
    return reference_from_product(study, data, str(stm_path)), data


def run_team(
    deck,
    stm: str | Path | None = None,
    output: str | Path | None = None,
    on_stage: Stage | None = None,
    plot: str | Path | None = None,
    write_results: bool = True,
):
    """``fracas run`` on a TEAM deck (path or TeamDeck): case -> reference (STM file or in
    line) -> filter -> TeamProduct -> results file (and punch file).  Every output (results,
    punch, an STM file to build, the ``plot`` the caller will draw) is checked before any work.

    ``write_results=False`` (sweeps, in-memory callers) returns the product without writing the
    results file (the path returned is then None); punch files are still written.

    Returns (TeamProduct or None when ``errcon.analysis = false``, results path, reference source).
    """
    from fracas.io.team_results import write_punch, write_team_results
    from fracas.team.engine import run_study
    from fracas.team.reference import integrate_reference
    from fracas.team.result import team_product

    say = _say(on_stage)
    t0 = time.perf_counter()
    say("reading the deck")
    case = load_team(deck)
    cfg, study = case.deck, case.study
    ec = cfg.errcon
    stm_path = Path(stm) if stm is not None else (cfg.resolve(ec.stm_file) if ec.stm_file else None)
    out = (
        Path(output)
        if output is not None
        else (cfg.resolve(cfg.output.results) if cfg.output.results else default_output(cfg.source_path))
    )
    if ec.analysis:
        if write_results:
            check_output_path(out, "results file")
        if cfg.punch is not None:
            check_output_path(cfg.resolve(cfg.punch.file), "punch file")
        if plot is not None:
            check_output_path(plot, "plot")
    build = stm is None and (
        ec.build_stm is True or (ec.build_stm == "if_missing" and stm_path is not None and not stm_path.exists())
    )
    if build and stm_path is not None:
        check_output_path(stm_path, "STM file")
    t1 = time.perf_counter()
    if build:
        stm_path, _ = build_stm(cfg, stm_path, on_stage, case=case)
    if stm_path is not None:
        if not stm_path.exists():
            raise StmFileError(
                f"{stm_path}: no such STM file (build it with: fracas stm build "
                f"{cfg.source_path or 'DECK'} -o {stm_path})"
            )
        say("reading the STM file")
        ref, product = read_reference(study, stm_path)
    else:
        product = None
        say("integrating the reference and its sensitivities")
        ref = integrate_reference(study)
        if ref.status != RunStatus.OK:
            raise _reference_failed(case, ref.failed_at_s, ref.integrator_status)
    t2 = time.perf_counter()
    if not ec.analysis:
        return None, None, ref.source
    res = run_study(study, ref, say, product=product)
    failed = [
        (k, t_to)
        for k, stats in res.prediction_status.items()
        for t_to, s in zip(study.schedule.predict_to_s[k], stats)
        if s
    ]
    t3 = time.perf_counter()
    res.timing.update({"setup_s": t1 - t0, "reference_s": t2 - t1, "analysis_s": t3 - t2})
    tdeck = case.traj_deck
    product = team_product(
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
        provenance=provenance(cfg.source_text, study.source),
    )
    if write_results:
        say("writing the results file")
        write_team_results(out, product)
    else:
        out = None
    if cfg.punch is not None:
        write_punch(cfg.resolve(cfg.punch.file), product)
    product.timing["total_s"] = time.perf_counter() - t0
    if failed:  # the run and its file stand; the failed prediction is the user's one-line error
        k, t_to = failed[0]
        written = f"; results written to {out}" if out is not None else ""
        raise NumericalError(
            f"{study.source}: prediction from {res.times_s[k] / DAY_S:.6g} d to {t_to / DAY_S:.6g} d: the "
            f"integration stopped before the target (status {int(RunStatus.OUTSIDE_TRAJECTORY)}){written}"
        )
    return product, out, ref.source
