"""Mode ``tom``: targeting and optimization (FRACAS TOM).

deck -> the TOM case (build; with ``[tom.first_guess]``, its two passes) -> the starting
trajectory -> the search (projected gradient, an NLP solver, GRID or nominal) ->
verification by re-propagation -> TomProduct -> results file, the optimized reference deck
(for TEAM's [ertraj] and ``fracas propagate``), its STM file when asked -> the report."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from fracas.config.tom import parse_tom_deck, tom_problems
from fracas.io.atomic import check_output_path
from fracas.io.inputs import reading_inputs
from fracas.modes.base import Console, Mode, ReportOptions, RunOptions, Stage, beside, print_results, say_to
from fracas.modes.tom_search import first_guess, search_stage, start_problem

__all__ = ["MODE", "run_tom", "tom_outputs"]


def tom_outputs(
    cfg: Any, output: str | Path | None, plot: str | Path | None, reference_deck: str | Path | None
) -> tuple[Path, Path, Path | None]:
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


def _verify(case: Any, res: Any) -> tuple[Any, tuple[str, bool, bool]]:
    """The plain core at the final controls, afresh: (its outcome, (stop reason, converged,
    targets met)).  "Converged" needs the search's own test and every target met."""
    submode = case.deck.tom.submode
    tg = case.problem.targets
    final = case.problem.fresh_outcome(res.u)
    ev = final.evaluation
    err = tg.error(ev.targets) if ev.ok else np.full(tg.n_targets, np.nan)
    targets_met = bool(ev.ok and np.all(np.abs(err) <= tg.tolerance))
    optimizing = submode in ("target_optimize", "optimize", "auto")
    reason = res.stop_reason
    if submode in ("grid", "nominal"):
        return final, (reason, False, targets_met)
    converged = bool(res.search_converged and targets_met)
    if res.search_converged and not targets_met:
        worst = int(np.nanargmax(np.abs(err) / tg.tolerance)) if ev.ok else 0
        reason = (
            f"{reason}; but re-propagation misses {tg.names[worst]} by "
            f"{abs(err[worst]) / tg.tolerance[worst]:.3g} tolerances: NOT converged"
        )
    elif not res.search_converged and targets_met and optimizing:
        reason = f"{reason} (targets are met; the optimality test was not)"
    return final, (reason, converged, targets_met)


def _final_sensitivities(case: Any, final: Any, u_final: np.ndarray, say: Stage) -> tuple[Any, Any]:
    """S and G at the final controls in deck units (the deck's method: FEGS compiles no AD)."""
    if not final.evaluation.ok or case.deck.tom.submode == "grid":
        return None, None
    say("sensitivities at the final controls")
    _, s_mat, g_vec = case.problem.sensitivities(u_final)
    return s_mat * case.control_factor[None, :] / case.target_factor[:, None], g_vec * case.control_factor


def _write_reference_deck(case: Any, u_final: np.ndarray, ref_path: Path) -> str:
    """The optimized reference deck, written atomically; its path ("" for GRID: none)."""
    from fracas.build.tom import reference_deck_text
    from fracas.io.atomic import atomic_path

    if case.deck.tom.submode == "grid":
        return ""
    text = reference_deck_text(case, u_final)
    with atomic_path(ref_path) as tmp:
        tmp.write_text(text)
    return str(ref_path)


def _team_deck_for(ref_path: Path) -> Any:
    """The TEAM deck (validated, never text) that builds the STM file of a reference deck:
    every thrust-noise column, a 1 h grid besides the trajectory's own times, no analysis."""
    from fracas.config.team import TeamDeck
    from fracas.config.trajectory import validate_sourced

    source = str(ref_path.with_suffix(".team.toml"))
    data = {
        "mode": "team",
        "errcon": {"build_stm": True, "analysis": False},
        "ertraj": {"deck": str(ref_path)},
        "stm": {"grid_hours": 1.0},
    }
    return validate_sourced(data, source, TeamDeck)


def tom_stm_file(cfg: Any, ref_path: Path) -> Path:
    """[tom] stm_file: the optimized reference's STM file (STMGEN), as ``fracas stm build``
    writes it for a TEAM deck naming the reference deck, for later TEAM studies with ``--stm``."""
    from fracas.modes.stm import build_stm

    path, _ = build_stm(_team_deck_for(Path(ref_path).resolve()), cfg.resolve(cfg.tom.stm_file))
    return path


def _check_outputs(cfg: Any, out: Path, ref_path: Path, png: Path | None) -> None:
    """Every file a TOM run writes, checked before any work: none may be a file it reads
    (the deck, the files it names)."""
    ins = (cfg.source_path,)
    check_output_path(out, "results file", ins)
    if cfg.tom.submode != "grid":
        check_output_path(ref_path, "reference deck", ins)
        if cfg.tom.stm_file:
            check_output_path(cfg.resolve(cfg.tom.stm_file), "STM file", ins)
    if png is not None:
        check_output_path(png, "plot", ins)


def _build(cfg: Any, say: Stage, on_iteration: Callable | None) -> tuple[Any, str]:
    """The TOM case (the first guess's pass-2 case when the deck asks for one) and its note."""
    from fracas.build.tom import build_tom

    say("building the TOM problem")
    if cfg.tom.first_guess is not None:
        return first_guess(cfg, say, on_iteration)
    return build_tom(cfg), ""


@reading_inputs
def run_tom(
    deck: Any,
    output: str | Path | None = None,
    on_stage: Stage | None = None,
    plot: str | Path | None = None,
    on_iteration: Callable | None = None,
    reference_deck: str | Path | None = None,
) -> tuple[Any, Path, Path | None]:
    """``fracas run`` on a TOM deck: build -> search (projected gradient, or the NLP
    cross-check) -> verification by re-propagation -> TomProduct -> results file, the
    optimized reference deck (for TEAM's [ertraj] and ``fracas propagate``) and the plot.

    "Converged" is declared only when the plain core, re-run at the final controls, puts
    every target within its tolerance and (when optimizing) the search's own optimality
    test passed; the search's flag alone is never taken.  Returns (TomProduct, results
    path, reference-deck path or None).  A failure at the starting controls (nothing usable)
    raises NumericalError; any later failure ends the search with the best iterate written.
    """
    from fracas.build.tom_product import tom_product
    from fracas.config.tom import load_tom_deck
    from fracas.io.hdf5 import provenance
    from fracas.io.tom_results import write_tom_results

    say = say_to(on_stage)
    t0 = time.perf_counter()
    cfg = load_tom_deck(deck) if isinstance(deck, (str, Path)) else deck
    out, ref_path, png = tom_outputs(cfg, output, plot, reference_deck)
    _check_outputs(cfg, out, ref_path, png)
    case, first_note = _build(cfg, say, on_iteration)
    say("propagating the starting trajectory")
    start, sp = start_problem(cfg, case)
    t1 = time.perf_counter()
    res, grid, timing = search_stage(cfg, case, start, sp, say, on_iteration, first_note)
    t2 = time.perf_counter()
    say("verifying: re-propagating the final controls")
    final, verdict = _verify(case, res)
    u_final = np.asarray(res.u, float)
    sens = _final_sensitivities(case, final, u_final, say)
    t3 = time.perf_counter()
    ref_written = _write_reference_deck(case, u_final, ref_path)
    prob = case.problem
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
    prov = provenance(cfg.source_text, cfg.source_path)
    product = tom_product(case, res, start, final, verdict, sens, grid, ref_written, timing, prov)
    say("writing the results file")
    write_tom_results(out, product)
    if cfg.tom.stm_file and ref_written:
        say("building the STM file of the optimum")
        tom_stm_file(cfg, ref_path)
    product.timing["total_s"] = time.perf_counter() - t0
    return product, out, (ref_path if ref_written else None)


# ----------------------------------------------------------------------------- the terminal
def _json_summary(product: Any, path: Path, ref: Path | None) -> str:
    return json.dumps(
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


def command(deck: Path, opts: RunOptions, console: Console) -> None:
    """``fracas run`` on a TOM deck: a progress line per iteration, then the summary."""
    from fracas.config.tom import load_tom_deck
    from fracas.io.tom_results import read_tom_results
    from fracas.report.tom import PROGRESS_HEADER, plot_tom, progress_line, summary_text

    cfg = load_tom_deck(deck)
    talk = not (opts.as_json or opts.quiet)
    header = [False]
    with console.progress(talk) as stage:

        def on_iteration(rec: Any) -> None:
            stage(f"TOM iterations (at most {cfg.tom.max_iterations})")
            stage.count(int(rec.iteration), int(cfg.tom.max_iterations))
            if talk:
                if not header[0]:
                    console.echo(PROGRESS_HEADER)
                    header[0] = True
                console.echo(progress_line(rec))

        product, path, ref = run_tom(
            cfg,
            opts.output,
            on_stage=stage,
            plot=opts.plot,
            on_iteration=on_iteration,
            reference_deck=opts.reference_deck,
        )
        png = tom_outputs(cfg, opts.output, opts.plot, opts.reference_deck)[2]
        res = read_tom_results(path)
        written = plot_tom(res, png) if png is not None else []
    if opts.as_json:
        console.echo(_json_summary(product, path, ref))
        return
    if opts.quiet:
        verdict = "converged" if product.converged else "NOT converged"
        console.say(f"TOM {verdict}: final mass {product.final_mass_kg:.6f} kg; {product.stop_reason}")
    else:
        console.echo(summary_text(res))
    console.say(f"results: {path}")
    for w in written:
        console.say(f"plot: {w}")


def report(file: Path, opts: ReportOptions, console: Console) -> None:
    """``fracas report`` on a TOM results file."""
    from fracas.io.tom_results import read_tom_results
    from fracas.report.tom import plot_tom, summary_text

    res = read_tom_results(file)
    summary = {"file": str(file), "attrs": {k: str(v) for k, v in res["attrs"].items()}}
    print_results(
        file,
        opts,
        console,
        "TOM results",
        lambda w: summary_text(res, width=w),
        summary,
        lambda png: plot_tom(res, png),
    )


def tom_deck_problems(deck: Any) -> list[str]:
    """``fracas validate`` on a TOM deck: :func:`fracas.config.tom.tom_problems`, then the
    files the run writes that the deck names (as :func:`run_tom` checks them)."""
    from fracas.validate import output_problems

    t = deck.tom
    named = [("tom.results", t.results), ("tom.plot", t.plot), ("tom.stm_file", t.stm_file)]
    if t.submode != "grid":
        named.insert(1, ("tom.reference_deck", t.reference_deck))
    return tom_problems(deck) + output_problems(deck, named)


MODE = Mode(
    name="tom",
    noun="TOM",
    summary="targeting and optimization (injection, thrust arcs, pointing laws)",
    parse=parse_tom_deck,
    run=run_tom,
    command=command,
    results_kinds=("fracas-tom-results",),
    report=report,
    problems=tom_deck_problems,
    run_options=frozenset({"reference_deck"}),
)
