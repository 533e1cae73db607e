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

import os
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
    "run_tom",
    "reference_from_stm",
    "stm_product",
    "default_output",
    "beside",
    "tom_outputs",
]


def _say(on_stage: Stage | None) -> Stage:
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


def run(deck, **kw):
    """Run a deck (path or validated config) in the mode it names: ``propagate``, ``team`` or ``tom``."""
    from fracas.config.tom import TomDeck

    cfg = load_any(deck) if isinstance(deck, (str, Path)) else deck
    if isinstance(cfg, TomDeck):
        return run_tom(cfg, kw.get("output"), kw.get("on_stage"), kw.get("plot"))
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
    output_dir: str | Path | None = None,
):
    """``fracas run`` on a TEAM deck (path or TeamDeck): case -> reference (STM file or in
    line) -> filter -> TeamProduct -> results file (and punch file).  Every output (results,
    punch, an STM file to build, the ``plot`` the caller will draw) is checked before any work.
    With ``output`` (or ``output_dir``), the punch file and an STM file the deck does not name
    go into that folder (:func:`beside`); an STM file the deck names stays where it says.

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
    where = Path(output) if output is not None else (Path(output_dir) / "-" if output_dir is not None else None)
    punch = beside(where, cfg.resolve(cfg.punch.file), None) if cfg.punch is not None else None
    if ec.analysis:
        if write_results:
            check_output_path(out, "results file")
        if punch is not None:
            check_output_path(punch, "punch file")
        if plot is not None:
            check_output_path(plot, "plot")
    build = stm is None and (
        ec.build_stm is True or (ec.build_stm == "if_missing" and stm_path is not None and not stm_path.exists())
    )
    if build and stm_path is None:
        stem = Path(cfg.source_path or "deck").stem
        stm_path = (
            where.parent / f"{stem}_stm.h5" if where is not None else default_output(cfg.source_path, "stm_files")
        )
    if build:
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


# ----------------------------------------------------------------------------- TOM
def tom_outputs(cfg, output, plot, reference_deck):
    """(results, reference deck, plot) of a TOM run: each given path; else, with ``output``
    (-o), in its folder (:func:`beside`); else the deck's ``[tom]`` paths, else ``out/``."""
    stem = Path(cfg.source_path or "deck").stem
    ts = cfg.tom
    named = lambda p: cfg.resolve(p) if p else None  # noqa: E731
    res = (
        Path(output)
        if output is not None
        else (cfg.resolve(ts.results) if ts.results else Path("out") / f"{stem}_tom.h5")
    )
    ref = (
        Path(reference_deck)
        if reference_deck is not None
        else beside(output, named(ts.reference_deck), Path("out") / f"{stem}_reference.toml")
    )
    png = Path(plot) if plot is not None else (beside(output, named(ts.plot), None) if ts.plot else None)
    norm = lambda p: Path(os.path.normpath(p)) if p is not None else None  # noqa: E731
    return norm(res), norm(ref), norm(png)


def _grid_tables(case, say):
    """GRID (FRACAS GRID): E over single increments of each control and over every pair,
    all trajectories in one batched core call."""
    prob = case.problem
    steps = case.deck.grid.steps
    gammas = np.arange(-steps, steps + 1, dtype=float)
    m = len(case.u0)
    du = case.grid_increments
    lanes = []
    for j in range(m):
        for g in gammas:
            u = case.u0.copy()
            u[j] += g * du[j]
            lanes.append(u)
    pairs = [(a, b) for a in range(m) for b in range(a + 1, m)] if case.deck.grid.pairs else []
    for a, b in pairs:
        for ga in gammas:
            for gb in gammas:
                u = case.u0.copy()
                u[a] += ga * du[a]
                u[b] += gb * du[b]
                lanes.append(u)
    lanes = np.clip(np.array(lanes), case.lower, case.upper)
    say(f"GRID: {len(lanes)} trajectories in one batch")
    t0 = time.perf_counter()
    vals, _, ok = prob.evaluate_batch(lanes, progress=lambda done, total: say(f"GRID: {done}/{total} trajectories"))
    dt = time.perf_counter() - t0
    err = prob.targets.error(vals) / prob.targets.tolerance
    e_idx = np.where(ok, np.sum(err**2, axis=1), np.inf)
    g_n = len(gammas)
    single = e_idx[: m * g_n].reshape(m, g_n)
    tables = {}
    pos = m * g_n
    for a, b in pairs:
        tables[(a, b)] = e_idx[pos : pos + g_n * g_n].reshape(g_n, g_n)
        pos += g_n * g_n
    return {"single": single, "gammas": gammas, "pairs": tables}, len(lanes), dt


def run_tom(
    deck,
    output: str | Path | None = None,
    on_stage: Stage | None = None,
    plot: str | Path | None = None,
    on_iteration: Callable | None = None,
    reference_deck: str | Path | None = None,
):
    """``fracas run`` on a TOM deck: build -> search (projected gradient, or the NLP
    cross-check) -> verification by re-propagation -> TomProduct -> results file, the
    optimized reference deck (for TEAM's [ertraj] and ``fracas propagate``) and the plot.

    "Converged" is declared only when the plain core, re-run at the final controls, puts
    every target within its tolerance and (when optimizing) the search's own optimality
    test passed; the search's flag alone is never taken.  Returns (TomProduct, results
    path, reference-deck path or None).  A failure at the starting controls (nothing usable)
    raises NumericalError; any later failure ends the search with the best iterate written.
    """
    from fracas.build.tom import build_tom, reference_deck_text
    from fracas.config.tom import load_tom_deck
    from fracas.io.atomic import atomic_path
    from fracas.io.tom_results import write_tom_results
    from fracas.products import TomProduct
    from fracas.tom import search

    say = _say(on_stage)
    t0 = time.perf_counter()
    cfg = load_tom_deck(deck) if isinstance(deck, (str, Path)) else deck
    out, ref_path, png = tom_outputs(cfg, output, plot, reference_deck)
    check_output_path(out, "results file")
    submode = cfg.tom.submode
    if submode != "grid":
        check_output_path(ref_path, "reference deck")
    if png is not None:
        check_output_path(png, "plot")
    say("building the TOM problem")
    first_note = ""
    if cfg.tom.first_guess is not None:
        case, first_note = _tom_first_guess(cfg, say, on_iteration)
    else:
        case = build_tom(cfg)
    prob = case.problem
    tg = prob.targets
    say("propagating the starting trajectory")
    start, sp = _tom_start(cfg, case)
    grid = None
    t1 = time.perf_counter()
    timing: dict[str, float] = {}
    if submode == "grid":
        grid, n_lanes, dt = _grid_tables(case, say)
        timing["grid_s"] = dt
        timing["grid_trajectories_per_s"] = n_lanes / dt if dt > 0 else float("nan")
        res = search.SearchResult(
            u=case.u0,
            evaluation=start.evaluation,
            history=[],
            stop_reason=f"GRID: {n_lanes} trajectories tabulated (choose the next start from the tables)",
            search_converged=False,
            n_evaluations=n_lanes + 1,
            n_sensitivity_evaluations=0,
            time_sensitivities_s=0.0,
            time_line_search_s=0.0,
            time_bookkeeping_s=0.0,
        )
    elif submode == "nominal":
        res = search.SearchResult(
            u=case.u0,
            evaluation=start.evaluation,
            history=[],
            stop_reason="nominal: the starting controls evaluated (no search)",
            search_converged=False,
            n_evaluations=1,
            n_sensitivity_evaluations=0,
            time_sensitivities_s=0.0,
            time_line_search_s=0.0,
            time_bookkeeping_s=0.0,
        )
    else:
        say(f"searching ({cfg.tom.optimizer}, {cfg.tom.sensitivities} sensitivities)")
        res = _tom_search(cfg, case, sp, on_iteration)
        if first_note:
            res.stop_reason = f"{res.stop_reason} [{first_note}]"
    t2 = time.perf_counter()

    # ---- verification: the plain core at the final controls, afresh
    say("verifying: re-propagating the final controls")
    final = prob.fresh_outcome(res.u)
    u_final = np.asarray(res.u, float)
    ev = final.evaluation
    err = tg.error(ev.targets) if ev.ok else np.full(tg.n_targets, np.nan)
    targets_met = bool(ev.ok and np.all(np.abs(err) <= tg.tolerance))
    optimizing = submode in ("target_optimize", "optimize", "auto")
    reason = res.stop_reason
    if submode in ("grid", "nominal"):
        converged = False
    else:
        converged = bool(res.search_converged and targets_met)
        if res.search_converged and not targets_met:
            worst = int(np.nanargmax(np.abs(err) / tg.tolerance)) if ev.ok else 0
            reason = (
                f"{reason}; but re-propagation misses {tg.names[worst]} by "
                f"{abs(err[worst]) / tg.tolerance[worst]:.3g} tolerances: NOT converged"
            )
        elif not res.search_converged and targets_met and optimizing:
            reason = f"{reason} (targets are met; the optimality test was not)"
    s_deck = g_deck = None
    if ev.ok and submode != "grid":
        say("sensitivities at the final controls")
        _, s_mat, g_vec = prob.sensitivities(u_final)  # the deck's method (FEGS runs compile no AD)
        s_deck = s_mat * case.control_factor[None, :] / case.target_factor[:, None]
        g_deck = g_vec * case.control_factor
    t3 = time.perf_counter()

    # ---- product and files
    hist = res.history
    fac_u, fac_t = case.control_factor, case.target_factor
    ref_written = ""
    if submode != "grid":
        text = reference_deck_text(case, u_final)
        with atomic_path(ref_path) as tmp:
            tmp.write_text(text)
        ref_written = str(ref_path)
    timing.update(
        {
            "setup_s": t1 - t0,
            "search_s": t2 - t1,
            "sensitivities_s": res.time_sensitivities_s,
            "line_search_s": res.time_line_search_s,
            "bookkeeping_s": res.time_bookkeeping_s,
            "verification_s": t3 - t2,
            # what the core actually flew (the search's own counts leave FEGS's differences out)
            "core_propagations": float(prob.n_trajectories),
            "core_sensitivity_runs": float(prob.n_sensitivity_runs),
        }
    )
    product = TomProduct(
        title=cfg.title or case.trajectory.title,
        source=cfg.source_path or "",
        submode=submode,
        optimizer=cfg.tom.optimizer,
        sensitivities=cfg.tom.sensitivities,
        control_names=list(case.control_names),
        control_units=list(case.control_units),
        control_factor=fac_u,
        u_start=case.u0 / fac_u,
        u_final=u_final / fac_u,
        lower=case.lower / fac_u,
        upper=case.upper / fac_u,
        target_names=list(tg.names),
        target_bodies=list(case.target_bodies),
        target_units=list(case.target_units),
        target_factor=fac_t,
        desired=tg.desired / fac_t,
        tolerance=tg.tolerance / fac_t,
        achieved_start=start.evaluation.targets / fac_t,
        achieved=(ev.targets if ev.ok else np.full(tg.n_targets, np.nan)) / fac_t,
        initial_mass_kg=float(case.base.x0[6]),
        start_mass_kg=float(start.x_final[6]),
        final_mass_kg=float(final.x_final[6]) if ev.ok else float("nan"),
        performance_name=case.performance_name,
        performance_unit=case.performance_unit,
        performance_start=_deck_performance(case, start.evaluation.performance),
        performance_final=_deck_performance(case, ev.performance) if ev.ok else float("nan"),
        stop_reason=reason,
        converged=converged,
        search_converged=bool(res.search_converged),
        targets_met=targets_met,
        iteration=np.array([r.iteration for r in hist], np.int64),
        submodes=[r.submode for r in hist],
        performance_kg=np.array([r.performance for r in hist], float),
        error_rms=np.array([r.error_rms for r in hist], float),
        angle_rad=np.array([r.angle_rad for r in hist], float),
        gamma=np.array([r.gamma for r in hist], float),
        n_trajectories=np.array([r.n_evaluations for r in hist], np.int64),
        controls=np.array([r.u / fac_u for r in hist], float).reshape(len(hist), len(fac_u)),
        targets=np.array([r.targets / fac_t for r in hist], float).reshape(len(hist), len(fac_t)),
        s_matrix=s_deck,
        g_vector=g_deck,
        grid=grid,
        trials=np.array(
            [[r.iteration, t.gamma, t.cost, t.performance, t.error_index, float(t.ok)] for r in hist for t in r.trials],
            float,
        ).reshape(-1, 6),
        reference_deck=ref_written,
        timing=timing,
        provenance=provenance(cfg.source_text, cfg.source_path),
    )
    say("writing the results file")
    write_tom_results(out, product)
    if cfg.tom.stm_file and ref_written:
        say("building the STM file of the optimum")
        _tom_stm_file(cfg, ref_path)
    product.timing["total_s"] = time.perf_counter() - t0
    return product, out, (ref_path if ref_written else None)


def _tom_start(cfg, case):
    """The starting trajectory (NumericalError when it fails: nothing to optimize from) and the
    search's :class:`fracas.tom.search.Problem` of a TOM case."""
    from fracas.tom import search

    prob = case.problem
    tg = prob.targets
    start = prob.outcome(case.u0)
    if not start.evaluation.ok:
        from fracas.status import status_text

        raise NumericalError(
            f"{cfg.source_path}: the trajectory at the starting controls failed ({status_text(start.status)}, "
            f"stopped at {start.t_final / DAY_S:.6g} d): nothing usable to optimize from"
        )
    sp = search.Problem(
        u0=case.u0,
        desired=tg.desired,
        tolerance=tg.tolerance,
        scale=case.scale,
        lower=case.lower,
        upper=case.upper,
        floor=case.floor,
        evaluate=prob.evaluate,
        sensitivities=prob.sensitivities,
        target_error=tg.error,
        given_S=case.given_s,
        given_G=case.given_g,
        labels=case.control_names,
        target_labels=tg.names,
        value_weighted=np.array([u not in ("deg", "days") for u in case.control_units]),
        ineq_matrix=case.ineq_matrix,
        ineq_bound=case.ineq_bound,
        periodic=case.periodic,
    )
    return start, sp


def _tom_search(cfg, case, sp, on_iteration, optimizer: str | None = None):
    """One search with the deck's optimizer, or ``optimizer`` (a malformed problem or a missing
    IPOPT: a one-line FracasError)."""
    from fracas.errors import FracasError
    from fracas.tom import nlp, search

    optimizer = optimizer or cfg.tom.optimizer
    try:
        if optimizer == "projected_gradient":
            return search.projected_gradient(sp, case.settings, on_iteration)
        if optimizer == "ipopt":
            from fracas.tom.ipopt import solve_ipopt

            return solve_ipopt(sp, case.settings, on_iteration)
        return nlp.solve_nlp(sp, optimizer, case.settings, on_iteration)
    except ValueError as exc:
        raise FracasError(f"{cfg.source_path}: {exc}") from None
    except ImportError as exc:
        raise FracasError(f"{cfg.source_path}: tom.optimizer = {optimizer!r}: {exc}") from None


_FIRST_GUESS_TARGETING = 30  # iterations of the targeting between the first guess's two passes


def _tom_first_guess(cfg, say, on_iteration):
    """[tom.first_guess] (:mod:`fracas.tom.first_guess`): pass 1 on throttle segments, its burns
    as arcs with Legendre pointing laws; returns the pass-2 case (its start) and a one-line note."""
    import dataclasses
    import math

    from fracas.build.tom import build_tom, first_guess_burns, first_guess_segments
    from fracas.config.tom import tom_trajectory_deck
    from fracas.tom import search
    from fracas.tom.first_guess import burns_from_segments

    fg = cfg.tom.first_guess
    traj = tom_trajectory_deck(cfg)
    deck1, traj1 = first_guess_segments(cfg, traj)
    n_segments = len(traj1.thrust_arc)
    # pass 1 (tens of controls, far from the targets) needs an NLP solver: the projected gradient
    # stopped there at E_rms 1e6 on the Earth-Mars rendezvous; a deck that chose it gets IPOPT here
    optimizer1 = "ipopt" if cfg.tom.optimizer == "projected_gradient" else cfg.tom.optimizer
    say(f"first guess, pass 1: {n_segments} segments ({optimizer1})")
    case1 = build_tom(deck1, trajectory=traj1)
    _, sp1 = _tom_start(cfg, case1)
    res1 = _tom_search(cfg, case1, sp1, on_iteration, optimizer1)
    prm = case1.problem.params_at(res1.u)
    edges = np.append(np.asarray(prm.arc_t_on, float), float(np.asarray(prm.arc_t_off)[-1]))
    burns = burns_from_segments(
        edges,
        np.asarray(prm.arc_throttle, float),
        np.asarray(prm.arc_alpha, float),
        np.asarray(prm.arc_beta, float),
        degree=fg.degree,
        max_fit_error_rad=math.radians(fg.max_fit_error_deg),
        max_arcs=fg.max_arcs_per_burn,
    )
    if not burns:
        raise NumericalError(
            f"{cfg.source_path}: tom.first_guess: pass 1 left every segment coasting (no burn to refine); "
            f"its search stopped: {res1.stop_reason}"
        )
    n_arcs = sum(len(b) for b in burns)
    spans = ", ".join(f"{b[0].start_s / DAY_S:.1f}-{b[-1].stop_s / DAY_S:.1f} d" for b in burns)
    say(f"first guess, pass 2: {len(burns)} burns ({spans}) in {n_arcs} arcs")
    deck2, traj2 = first_guess_burns(cfg, traj, burns)
    case2 = dataclasses.replace(build_tom(deck2, trajectory=traj2), arcs_rewritten=True)
    # the fitted laws miss the targets that pass 1 met: restore them first with the projected-gradient
    # targeting (minimum-norm Newton steps keep the burn structure), then optimize from there; an
    # optimizer started off the target surface with L-BFGS wandered into other structures (Earth-Mars:
    # 563.6 kg from the fitted start, 603.94 kg from the targeted one)
    say("first guess, pass 2: targeting the fitted burns")
    _, sp2 = _tom_start(cfg, case2)
    targeted = search.projected_gradient(
        sp2, dataclasses.replace(case2.settings, submode="target", max_iterations=_FIRST_GUESS_TARGETING)
    )
    case2 = dataclasses.replace(case2, u0=targeted.u)
    perf = res1.evaluation.performance / case1.performance_factor
    note = (
        f"first guess: {n_segments} segments, {len(res1.history)} iterations to F = {perf:.6g} "
        f"{case1.performance_unit}; {len(burns)} burns ({spans}) in {n_arcs} arcs, targeted in "
        f"{len(targeted.history)} iterations"
    )
    return case2, note


def _deck_performance(case, value: float) -> float:
    """F in the performance's deck unit, its sign undone (F = -value when minimizing)."""
    sign = -1.0 if (case.performance_name != "final_mass" and not case.deck.tom.maximize) else 1.0
    return sign * float(value) / case.performance_factor


def _tom_stm_file(cfg, ref_path: Path) -> Path:
    """[tom] stm_file: the optimized reference's STM file (STMGEN), as ``fracas stm build``
    writes it for a TEAM deck naming the reference deck (every thrust-noise column, a 1 h
    grid besides the trajectory's own times), for later TEAM studies with ``--stm``."""
    import json

    from fracas.config.team import parse_team_deck

    ref_path = Path(ref_path).resolve()
    text = (
        'mode = "team"\n[errcon]\nbuild_stm = true\nanalysis = false\n'
        f"[ertraj]\ndeck = {json.dumps(str(ref_path))}\n[stm]\ngrid_hours = 1.0\n"
    )
    team = parse_team_deck(text, str(ref_path.with_suffix(".team.toml")))
    path, _ = build_stm(team, cfg.resolve(cfg.tom.stm_file))
    return path


# ----------------------------------------------------------------------------- two vehicles
def _check_runs_size(cfg, study) -> None:
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


def run_rendezvous(
    deck,
    output: str | Path | None = None,
    on_stage: Stage | None = None,
    plot: str | Path | None = None,
    write_results: bool = True,
):
    """``fracas run`` on a rendezvous deck (path or RendezvousDeck): both references ->
    the two-vehicle covariance analysis for every target role -> single runs -> maneuver
    uncertainties -> RendezvousProduct -> results file.  Outputs are checked before any
    work.  Returns (RendezvousProduct, results path or None)."""
    from fracas.build.rendezvous import build_rendezvous
    from fracas.config.rendezvous import RendezvousDeck, load_rendezvous_deck
    from fracas.io.rendezvous_results import write_rendezvous_results
    from fracas.products import RendezvousProduct
    from fracas.team.two_vehicle import (
        envelope_rates,
        nonlinear_single_runs,
        rms_histories,
        run_rendezvous_study,
        sample_rms,
        single_runs,
    )

    say = _say(on_stage)
    t0 = time.perf_counter()
    say("reading the deck")
    cfg = deck if isinstance(deck, RendezvousDeck) else load_rendezvous_deck(deck)
    out = (
        Path(output)
        if output is not None
        else (cfg.resolve(cfg.output.results) if cfg.output.results else default_output(cfg.source_path))
    )
    if write_results:
        check_output_path(out, "results file")
    if plot is not None:
        check_output_path(plot, "plot")
    say("integrating both references and their STMs")
    study = build_rendezvous(cfg)
    _check_runs_size(cfg, study)
    t1 = time.perf_counter()
    say(f"covariance analysis ({', '.join(study.roles)})")
    res = run_rendezvous_study(study)
    t2 = time.perf_counter()
    sr = cfg.single_runs
    errs = men = env1 = env3 = se1 = se3 = rms = None
    nonlinear = False
    if sr.runs > 0:
        nonlinear = sr.dynamics == "two_body" or (sr.dynamics == "auto" and study.two_body)
        say(f"{sr.runs} single runs per role ({'on the conics' if nonlinear else 'linear'})")
        e = (nonlinear_single_runs if nonlinear else single_runs)(res, sr.runs, sr.seed)
        (env1, se1), (env3, se3) = envelope_rates(res, e, 1.0), envelope_rates(res, e, 3.0)
        errs = e[:, : sr.keep]
        rms = sample_rms(e)
        J = len(study.maneuvers)
        men = np.zeros((len(study.roles), sr.runs, J, 3))
        for j, m in enumerate(study.maneuvers):
            men[:, :, j] = np.einsum("ij,rnj->rni", np.asarray(m.M), e[:, :, m.k, :12])
    t3 = time.perf_counter()
    J = len(study.maneuvers)
    product = RendezvousProduct(
        title=study.title,
        source=study.source,
        epoch_et_s=study.epoch_et_s,
        centre=study.centre,
        chaser_name=study.chaser_name,
        target_name=study.target_name,
        roles=list(study.roles),
        labels=study.labels,
        units=study.units,
        times_s=study.times_s,
        marks=study.marks,
        x_chaser=study.x_chaser,
        x_target=study.x_target,
        P_true=res.P_true,
        P_assumed=res.P_assumed,
        P_true_minus=res.P_true_minus,
        P_assumed_minus=res.P_assumed_minus,
        maneuver_names=[m.name for m in study.maneuvers],
        maneuver_time_s=np.array([m.time_s for m in study.maneuvers], dtype=np.float64),
        maneuver_arrival_s=np.array([m.arrival_s for m in study.maneuvers], dtype=np.float64),
        maneuver_dv_km_s=np.array([m.dv_km_s for m in study.maneuvers], dtype=np.float64).reshape(J, 3),
        maneuver_status=np.array([m.status for m in study.maneuvers], dtype=np.int64),
        maneuver_cov_true=res.maneuver_cov_true,
        maneuver_cov_assumed=res.maneuver_cov_assumed,
        reset_times_s=np.array([study.times_s[r.k] for r in study.resets], dtype=np.float64),
        n_runs=int(sr.runs),
        seed=int(sr.seed),
        run_errors=errs,
        run_maneuver_errors=men,
        envelope_1sigma=env1,
        envelope_3sigma=env3,
        envelope_1sigma_se=se1,
        run_rms=rms,
        reference_sources=list(study.reference_sources),
        team_rms=np.stack(list(rms_histories(res, "true").values()), axis=-1),
        assumed_rms=np.stack(list(rms_histories(res, "assumed").values()), axis=-1),
        envelope_3sigma_se=se3,
        length_unit=study.length_unit,
        km_per_unit=study.km_per_unit,
        timing={"build_s": t1 - t0, "analysis_s": t2 - t1, "single_runs_s": t3 - t2},
        run_dynamics=("two_body" if nonlinear else "linear") if sr.runs > 0 else "",
        provenance=provenance(cfg.source_text, cfg.source_path),
    )
    path = None
    if write_results:
        say("writing the results file")
        path = write_rendezvous_results(out, product)
    return product, path
