"""``fracas run`` on a TSIM deck: the Monte Carlo driver (FRACAS TSIM, digest C.3; docs/tsim.md).

deck -> TEAM run of the deck it stands on (guidance model ``tsim``: P̃ = P_c + P_k, the
estimate TSIM's independent knowledge sampling makes) -> :class:`fracas.tsim.plan.TsimPlan`
-> blocks of missions (:func:`fracas.tsim.engine.simulate_block`) in this process, on a
Dask ``LocalCluster`` (``workers``) or on a running scheduler (``scheduler``) -> statistics,
consistency -> results file.

* Work is cut into blocks of 32 missions (fixed: mission i always flies in the same lane of
  the same compiled program), and blocks into tasks of ``batch_missions``.  Every finished
  task's blocks are written, atomically, to their own file in the checkpoint folder
  (``<results>.partial/task_<first block>.h5``: the cost stays linear in the missions, where
  rewriting one growing file made it quadratic); a run killed mid-way and started again
  with the same deck resumes from them and ends with the same bits.  The folder is removed
  once the results file is written.
* Each Dask worker is one process with one XLA host device (``fracas._jax.worker_setup``),
  so N workers share N cores without oversubscribing them; the plan is sent to every worker
  once (``scatter``), each compiles the flight programs once.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from fracas import cluster
from fracas.config.trajectory import deck_error
from fracas.config.tsim import TsimDeck, load_tsim_deck, tsim_problems, tsim_team_deck
from fracas.errors import DeckError
from fracas.io.atomic import check_output_path
from fracas.io.inputs import reading_inputs
from fracas.modes import team as team_mode
from fracas.modes.base import default_output, team_inputs

__all__ = ["run_tsim", "checkpoint_path", "plan_key", "fly_blocks", "assemble"]

Progress = Callable[[int, int], None]


def checkpoint_path(results: Path) -> Path:
    """The checkpoint folder of a results file: one small file per completed task."""
    return results.with_name(results.name + ".partial")


def _read_checkpoints(folder: Path, key: str) -> dict[int, dict[str, np.ndarray]]:
    from fracas.errors import ResultsFileError
    from fracas.io.tsim_results import read_tsim_checkpoint

    if not folder.exists():
        return {}
    if not folder.is_dir():
        raise ResultsFileError(f"{folder}: expected the TSIM checkpoint folder of this run (a file is in the way)")
    done: dict[int, dict[str, np.ndarray]] = {}
    for f in sorted(folder.glob("task_*.h5")):
        done.update(read_tsim_checkpoint(f, key))
    return done


def _write_checkpoint(folder: Path, key: str, blocks: dict[int, dict[str, np.ndarray]]) -> None:
    from fracas.io.tsim_results import write_tsim_checkpoint

    folder.mkdir(parents=True, exist_ok=True)
    write_tsim_checkpoint(folder / f"task_{min(blocks):08d}.h5", key, blocks)  # atomic, this task only


def _remove_checkpoints(folder: Path) -> None:
    if folder.is_dir():
        for f in folder.glob("task_*.h5"):
            f.unlink(missing_ok=True)
        try:
            folder.rmdir()
        except OSError:
            pass  # something else is in it: leave it


def plan_key(cfg: TsimDeck, team_text: str) -> str:
    """What a checkpoint must match to be resumed: the TSIM deck's text, ``team_text`` (pass
    :func:`_team_key` of the TEAM deck: its text, its trajectory deck's and its STM file's
    identity, so a changed reference is never resumed into) and the fracas version."""
    from fracas import __version__

    h = hashlib.sha256()
    for part in (cfg.source_text or "", team_text or "", __version__):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()[:32]


def fly_blocks(plan, blocks: list[int]) -> dict[int, dict[str, np.ndarray]]:
    """Fly the given blocks of ``plan`` (one task)."""
    from fracas.tsim.engine import simulate_block

    return {b: simulate_block(plan, b) for b in blocks}


def assemble(plan, done: dict[int, dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """The per-mission table in mission order, trimmed to the run's missions."""
    keys = sorted(done)
    table = {k: np.concatenate([done[b][k] for b in keys], axis=0) for k in done[keys[0]]}
    return {k: v[: plan.missions] for k, v in table.items()}


_TEAM_RUNS: dict[str, tuple] = {}  # this process's TEAM runs, by the texts that made them


def _team_key(team_deck) -> str:
    from fracas.config.trajectory import read_deck_text

    h = hashlib.sha256((team_deck.source_text or "").encode())
    traj = team_deck.resolve(team_deck.ertraj.deck) if team_deck.ertraj.deck else None
    if traj is not None and traj.exists():
        h.update(read_deck_text(traj).encode())
    if team_deck.errcon.stm_file:
        stm = team_deck.resolve(team_deck.errcon.stm_file)
        if stm.exists():
            st = stm.stat()
            h.update(f"{stm.resolve()}:{st.st_size}:{st.st_mtime_ns}".encode())
    return h.hexdigest()


def _inputs(cfg: TsimDeck) -> tuple:
    """The files a TSIM run reads: its deck, the TEAM deck's (:func:`team_inputs`), the earlier
    statistics (no output may replace one)."""
    from fracas.config.tsim import tsim_team_deck

    earlier = tuple(cfg.resolve(f) for f in cfg.insim.a_priori_statistics)
    return (cfg.source_path, *team_inputs(tsim_team_deck(cfg)), *earlier)


def _team_for(cfg: TsimDeck, say, output_dir: Path | None = None):
    """The TEAM run TSIM stands on (guidance model ``tsim``), once per process for the same
    TEAM deck, trajectory deck and STM file (a second TSIM run on them, e.g. the other half
    of a split run, reuses it)."""
    from fracas.modes.stm import load_team
    from fracas.modes.sweep.plan import vary_many

    team_deck = tsim_team_deck(cfg)
    changes = {**cfg.insim.team_changes, "errcon.guidance_model": "tsim"}
    try:
        team_deck = vary_many(team_deck, changes)
    except DeckError as exc:
        raise DeckError(f"{cfg.source_path}: insim.team_changes: {exc}") from None
    key = _team_key(team_deck) + repr(sorted(changes.items()))
    if key in _TEAM_RUNS:
        return _TEAM_RUNS[key]
    say("running TEAM (guidance model tsim) for the knowledge and guidance matrices")
    case = load_team(team_deck)  # built once: the TEAM run and TSIM's plan share it
    prod, _, _ = team_mode.run_team(team_deck, write_results=False, on_stage=say, output_dir=output_dir, case=case)
    if prod is None or not prod.guidance:
        raise DeckError(f"{cfg.source_path}: insim.team_deck: the TEAM run made no guidance events")
    _TEAM_RUNS[key] = (team_deck, case, prod)
    return _TEAM_RUNS[key]


def _fly(
    plan: Any,
    todo: list[list[int]],
    record: Callable[[dict[int, dict[str, np.ndarray]]], None],
    workers: int | None,
    scheduler: str | None,
    force_dask: bool,
) -> int:
    """Fly the tasks ``todo`` (lists of blocks), recording each as it completes: in this
    process (``workers`` None or 1, no scheduler, not ``force_dask``), else on a Dask
    LocalCluster of single-threaded workers or the scheduler at ``scheduler``
    (:mod:`fracas.cluster`; the plan sent to every worker once).  Returns the workers used."""
    local = scheduler is None and not force_dask and (workers is None or workers <= 1)
    if local:
        pool = cluster.Pool()
    else:
        pool = cluster.start(workers, len(todo), scheduler, env=cluster.SINGLE_THREAD_ENV, timeout="10s", one_line=True)
    with pool:
        shared = pool.share(plan)
        for done in pool.as_completed([(fly_blocks, (shared, task)) for task in todo], catch=False):
            record(done.result)
        return pool.n_workers


@reading_inputs
def run_tsim(
    deck: str | Path | TsimDeck,
    output: str | Path | None = None,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    on_stage: Callable[[str], None] | None = None,
    progress: Progress | None = None,
    stop_after_tasks: int | None = None,
    batch_missions: int | None = None,
    force_dask: bool = False,
) -> tuple[Any, Path]:
    """Run a TSIM deck (path or TsimDeck); returns (TsimProduct, results path).

    ``workers``: None or 1 runs in this process; N ≥ 2 starts a Dask LocalCluster of N
    single-threaded worker processes; ``scheduler``: the address of a running Dask
    scheduler (overrides workers).  ``progress(done, total)`` after every task (missions).
    ``stop_after_tasks`` (tests: a run killed mid-way) stops after that many tasks, leaving
    the checkpoint.  ``batch_missions`` overrides the deck's.  ``force_dask``: a LocalCluster
    even for one worker (the scaling benchmark's 1-worker row).
    """
    from fracas.build.tsim import build_plan
    from fracas.io.tsim_results import tsim_statistics, write_tsim_results

    say = on_stage or (lambda s: None)
    t0 = time.perf_counter()
    cfg = deck if isinstance(deck, TsimDeck) else load_tsim_deck(deck)
    problems = tsim_problems(cfg)
    if problems:
        raise deck_error(problems)
    out = _results_path(cfg, output)
    ins = _inputs(cfg)
    check_output_path(out, "results file", ins)
    ckpt = checkpoint_path(out)
    check_output_path(ckpt / "task_00000000.h5", "checkpoint file", ins)
    earlier = []
    for f in cfg.insim.a_priori_statistics:
        earlier.append(tsim_statistics(cfg.resolve(f)))
    team_deck, case, team = _team_for(cfg, say, out.parent if output is not None else None)
    t1 = time.perf_counter()
    say("building the Monte Carlo plan (reference through the noise grid)")
    plan = build_plan(cfg, case, team)
    _check_table_size(cfg, plan)
    _check_a_priori(cfg, plan, earlier)
    key = plan_key(cfg, _team_key(team_deck))
    done = _read_checkpoints(ckpt, key)
    per_task = max(1, -(-(batch_missions or cfg.insim.batch_missions) // plan.block))
    remaining = [b for b in range(plan.n_blocks) if b not in done]
    todo = [remaining[i : i + per_task] for i in range(0, len(remaining), per_task)]
    if stop_after_tasks is not None:
        todo = todo[:stop_after_tasks]
    if done:
        say(f"resuming: {len(done)} of {plan.n_blocks} blocks already in {ckpt}")
    say(f"flying {plan.missions} missions in {plan.n_blocks} blocks of {plan.block}")
    total = plan.missions
    t2 = time.perf_counter()

    def record(blocks: dict[int, dict[str, np.ndarray]]) -> None:
        done.update(blocks)
        _write_checkpoint(ckpt, key, blocks)
        if progress is not None:
            progress(min(len(done) * plan.block, total), total)

    if progress is not None:
        progress(min(len(done) * plan.block, total), total)
    n_workers = 1
    if todo:
        n_workers = _fly(plan, todo, record, workers, scheduler, force_dask)
    t3 = time.perf_counter()
    if len(done) < plan.n_blocks:
        return None, ckpt
    table = assemble(plan, done)
    timing = {"team_s": t1 - t0, "plan_s": t2 - t1, "missions_s": t3 - t2}
    product = _product(cfg, plan, team, table, earlier, n_workers, timing)
    say("writing the results file")
    write_tsim_results(out, product)
    _remove_checkpoints(ckpt)
    product.timing["total_s"] = time.perf_counter() - t0
    return product, out


def _results_path(cfg: TsimDeck, output: str | Path | None) -> Path:
    """``output``, else the deck's ``[output] results``, else ``out/<deck stem>_tsim.h5``."""
    out = Path(output) if output is not None else (
        cfg.resolve(cfg.output.results) if cfg.output.results else default_output(cfg.source_path)
    )  # fmt: skip
    if output is None and not cfg.output.results:
        out = out.with_name(out.stem + "_tsim.h5")
    return out


def _product(
    cfg: TsimDeck,
    plan: Any,
    team: Any,
    table: dict[str, np.ndarray],
    earlier: list,
    n_workers: int,
    timing: dict[str, float],
) -> Any:
    """The TsimProduct of a finished run: the per-mission ``table``, its statistics (merged
    with the ``earlier`` runs'), percentiles, consistency and counts, each maneuver's
    figures against TEAM's, the settings and ``timing``."""
    from fracas.io.hdf5 import provenance
    from fracas.products import TsimManeuver, TsimProduct
    from fracas.tsim import summary
    from fracas.tsim.plan import STATUS_HOPELESS, STATUS_NEAR

    stats = summary.merge_a_priori(summary.statistics_of(plan, table), [s for _, s in earlier])
    counts = summary.counts_of(plan, table)
    counts["a_priori"] = int(sum(c for c, _ in earlier))
    mans = []
    for j, m in enumerate(plan.maneuvers):
        fm = table["failed_maneuver"]
        mans.append(
            TsimManeuver(
                name=m.name, type=m.type, law=m.law, time_s=m.time_s, control_labels=list(m.control_labels),
                control_units=list(m.control_units), target_names=list(m.target.names),
                target_units=list(m.target.units), target_time_s=m.target.t_s,
                team_correction_cov=np.asarray(m.team["correction_cov"]),
                team_dv_mean_km_s=float(m.team["dv_mean_km_s"]), team_dv_99_km_s=float(m.team["dv_99_km_s"]),
                team_target_cov_after=np.asarray(m.team["target_cov_after"]),
                failures=int(np.sum((fm == j) & (table["status"] == STATUS_HOPELESS))),
                near=int(np.sum(table["maneuver_status"][:, j] == STATUS_NEAR)),
            )
        )  # fmt: skip
    return TsimProduct(
        title=cfg.title or team.title,
        source=str(cfg.source_path),
        epoch_et_s=float(plan.epoch_et_s),
        # TSIM's augmented state: TEAM's without the exact model's noise states (issue 24)
        labels=[lab for lab, role in zip(team.labels, team.roles) if role != "noise_state"],
        n_state=int(plan.nx),
        maneuvers=mans,
        final_target_names=list(plan.final.names),
        final_target_units=list(plan.final.units),
        final_target_time_s=float(plan.final.t_s),
        team_target_cov=np.asarray(plan.final_team["target_cov"]),
        table=table,
        statistics={k: (int(v.count), np.asarray(v.mean), _cov(v)) for k, v in stats.items()},
        percentiles=summary.percentiles_of(plan, table),
        consistency=summary.consistency(plan, table),
        counts=counts,
        settings={
            "seed": plan.seed,
            "first_mission": plan.first_mission,
            "missions": plan.missions,
            "scale": float(cfg.insim.scale),
            "sampling": plan.info.get("sampling"),
            "noise_step_s": plan.info.get("grid_step_s"),
            "block": plan.block,
            "workers": n_workers,
            "team_deck": str(cfg.insim.team_deck),
            "guidance_model": "tsim",
            "laws": {m.name: m.law for m in plan.maneuvers},
        },  # fmt: skip
        timing=timing,
        provenance=provenance(cfg.source_text, cfg.source_path),
    )


def table_bytes(plan) -> int:
    """Bytes of the per-mission table the run holds (and writes)."""
    from fracas.tsim.engine import block_fields

    per = sum(int(np.prod(shape, dtype=np.int64)) * np.dtype(dt).itemsize for shape, dt in block_fields(plan).values())
    return int(per) * plan.n_blocks * plan.block


def _statistic_shapes(plan) -> dict[str, tuple[int, ...]]:
    """The mean's shape of every statistic this plan's run makes (fracas.tsim.summary)."""
    out = {"target_error": (len(plan.final.names),), "dv_total_km_s": (1,), "final_mass_kg": (1,)}
    for m in plan.maneuvers:
        out[f"dv_km_s[{m.name}]"] = (1,)
        out[f"correction[{m.name}]"] = (m.n_controls,)
        out[f"state_deviation[{m.name}]"] = (plan.nx,)
    return out


def _check_a_priori(cfg: TsimDeck, plan, earlier: list) -> None:
    """Before any mission flies: one line naming insim.a_priori_statistics[j] when an earlier
    file's statistics cannot be merged with this run's: a statistic of another shape (another
    TEAM deck or target set), or the same seed with overlapping mission ranges (the same
    missions counted twice)."""
    from fracas.io.tsim_results import tsim_settings

    src, shapes = cfg.source_path, _statistic_shapes(plan)
    lo, hi = plan.first_mission, plan.first_mission + plan.missions
    for j, (f, (_, prev)) in enumerate(zip(cfg.insim.a_priori_statistics, earlier)):
        where = f"{src}: insim.a_priori_statistics[{j}] = {f!r}"
        for name, (_, mean, _) in prev.items():
            if name in shapes and np.shape(mean) != shapes[name]:
                raise DeckError(
                    f"{where}: statistic {name} has shape {np.shape(mean)}, this run's {shapes[name]} "
                    "(expected a run of the same TEAM deck and targets)"
                )
        st = tsim_settings(cfg.resolve(f))
        a, n = int(st.get("first_mission", -1)), int(st.get("missions", 0))
        if int(st.get("seed", -1)) == cfg.insim.seed and a < hi and lo < a + n:
            raise DeckError(
                f"{where}: missions {a}..{a + n - 1} with seed {cfg.insim.seed} overlap this run's {lo}..{hi - 1} "
                "(expected disjoint missions: set insim.first_mission past them, or another seed)"
            )


def _check_table_size(cfg: TsimDeck, plan) -> None:
    """One line naming insim.missions when the table would take over a quarter of the memory."""
    import os

    try:
        mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # not on this platform: no check
        return
    need = table_bytes(plan)
    if need > mem / 4:
        raise DeckError(
            f"{cfg.source_path}: insim.missions = {plan.missions}: the per-mission table would take "
            f"{need / 2**30:.1f} GiB of this machine's {mem / 2**30:.1f} GiB (expected at most a quarter); "
            "split the run (first_mission, a_priori_statistics)"
        )


def _cov(m) -> np.ndarray:
    from fracas.tsim.statistics import covariance

    return np.asarray(covariance(m))


def missions_per_second(product: Any) -> float:
    t = product.timing.get("missions_s", float("nan"))
    return product.counts["missions"] / t if t > 0 else float("nan")
