"""TOM's search stage (FRACAS TOM's SEARCH, GRID and the automatic first guess): the
starting trajectory and the search problem of a case, one search with the deck's
optimizer, GRID's tables, and ``[tom.first_guess]``'s two passes."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from fracas.constants import DAY_S
from fracas.errors import NumericalError
from fracas.modes.base import Stage

__all__ = ["start_problem", "run_search", "grid_tables", "first_guess", "search_stage"]

_FIRST_GUESS_TARGETING = 30  # iterations of the targeting between the first guess's two passes


def start_problem(cfg: Any, case: Any) -> tuple[Any, Any]:
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


def run_search(cfg: Any, case: Any, sp: Any, on_iteration: Any, optimizer: str | None = None) -> Any:
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


def _grid_lanes(case: Any, gammas: np.ndarray) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """GRID's control vectors: single increments of each control, then every pair's."""
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
    return np.clip(np.array(lanes), case.lower, case.upper), pairs


def grid_tables(case: Any, say: Stage) -> tuple[dict[str, Any], int, float]:
    """GRID (FRACAS GRID): E over single increments of each control and over every pair,
    all trajectories in one batched core call."""
    prob = case.problem
    steps = case.deck.grid.steps
    gammas = np.arange(-steps, steps + 1, dtype=float)
    m = len(case.u0)
    lanes, pairs = _grid_lanes(case, gammas)
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


def _no_search(case: Any, start: Any, stop_reason: str, n_evaluations: int) -> Any:
    """The result of a submode that searches nothing (GRID, nominal)."""
    from fracas.tom import search

    return search.SearchResult(
        u=case.u0,
        evaluation=start.evaluation,
        history=[],
        stop_reason=stop_reason,
        search_converged=False,
        n_evaluations=n_evaluations,
        n_sensitivity_evaluations=0,
        time_sensitivities_s=0.0,
        time_line_search_s=0.0,
        time_bookkeeping_s=0.0,
    )


def search_stage(
    cfg: Any, case: Any, start: Any, sp: Any, say: Stage, on_iteration: Any, first_note: str
) -> tuple[Any, Any, dict[str, float]]:
    """(the search's result, GRID's tables or None, timings): GRID, nominal, or the search."""
    submode = cfg.tom.submode
    timing: dict[str, float] = {}
    if submode == "grid":
        grid, n_lanes, dt = grid_tables(case, say)
        timing["grid_s"] = dt
        timing["grid_trajectories_per_s"] = n_lanes / dt if dt > 0 else float("nan")
        reason = f"GRID: {n_lanes} trajectories tabulated (choose the next start from the tables)"
        return _no_search(case, start, reason, n_lanes + 1), grid, timing
    if submode == "nominal":
        return _no_search(case, start, "nominal: the starting controls evaluated (no search)", 1), None, timing
    say(f"searching ({cfg.tom.optimizer}, {cfg.tom.sensitivities} sensitivities)")
    res = run_search(cfg, case, sp, on_iteration)
    if first_note:
        res.stop_reason = f"{res.stop_reason} [{first_note}]"
    return res, None, timing


def _pass1_burns(cfg: Any, case1: Any, res1: Any) -> list[Any]:
    """Pass 1's thrusting segments as burns, each a few arcs with a fitted Legendre law."""
    import math

    from fracas.tom.first_guess import burns_from_segments

    fg = cfg.tom.first_guess
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
    return burns


def first_guess(cfg: Any, say: Stage, on_iteration: Any) -> tuple[Any, str]:
    """[tom.first_guess] (:mod:`fracas.tom.first_guess`): pass 1 on throttle segments, its burns
    as arcs with Legendre pointing laws; returns the pass-2 case (its start) and a one-line note."""
    import dataclasses

    from fracas.build.tom import build_tom, first_guess_burns, first_guess_segments
    from fracas.config.tom import tom_trajectory_deck
    from fracas.tom import search

    traj = tom_trajectory_deck(cfg)
    deck1, traj1 = first_guess_segments(cfg, traj)
    n_segments = len(traj1.thrust_arc)
    # pass 1 (tens of controls, far from the targets) needs an NLP solver: the projected gradient
    # stopped there at E_rms 1e6 on the Earth-Mars rendezvous; a deck that chose it gets IPOPT here
    optimizer1 = "ipopt" if cfg.tom.optimizer == "projected_gradient" else cfg.tom.optimizer
    say(f"first guess, pass 1: {n_segments} segments ({optimizer1})")
    case1 = build_tom(deck1, trajectory=traj1)
    _, sp1 = start_problem(cfg, case1)
    res1 = run_search(cfg, case1, sp1, on_iteration, optimizer1)
    burns = _pass1_burns(cfg, case1, res1)
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
    _, sp2 = start_problem(cfg, case2)
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
