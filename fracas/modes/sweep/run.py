"""Sweeps: one TEAM study run many times with some of its fields varied (docs/sweep.md).

``vary(deck, field, value)`` builds a study's TeamDeck in memory (no TOML written);
``run_sweep(cfg)`` runs every study (in this process, on a Dask LocalCluster or on an
existing Dask scheduler: :mod:`fracas.cluster`), appends each finished row to the table file
(HDF5 + CSV, written whole and atomically each time) and skips, on a restart, the studies
already in it; ``sweep_main`` is the command line's ``fracas sweep``.  The sweep's plan
(each study's deck and key, units, groups, tasks, the deck from ``--vary``) is in
:mod:`fracas.modes.sweep.plan`, the table's rows (a study's outputs, resuming from a table) in
:mod:`fracas.modes.sweep.rows`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fracas import cluster
from fracas.config.sweep import SweepDeck, study_label, sweep_problems
from fracas.config.team import TeamDeck, load_team_deck
from fracas.config.trajectory import deck_error
from fracas.errors import FracasError
from fracas.io.atomic import check_output_path
from fracas.io.inputs import reading_inputs
from fracas.modes import stm as stm_mode
from fracas.modes import team as team_mode
from fracas.modes.base import team_inputs
from fracas.modes.sweep.plan import (
    base_hash,
    batch_groups,
    parse_vary,
    plan_tasks,
    results_dir,
    stm_file,
    study_deck,
    study_key,
    sweep_deck_for,
    table_path,
    table_units,
    tables_exist,
    vary,
    vary_many,
)
from fracas.modes.sweep.rows import (
    check_outputs,
    guidance_outputs,
    one_line,
    outputs_from,
    outputs_of,
    resume_table,
    resumed_rows,
    study_row,
)

__all__ = [
    "vary",
    "vary_many",
    "run_sweep",
    "sweep_main",
    "summary_text",
    "parse_vary",
    "study_key",
    "base_hash",
    "outputs_of",
    "run_one",
    "run_group",
    "outputs_from",
    "guidance_outputs",
    "check_outputs",
    "study_deck",
    "resume_table",
    "SweepResult",
]

Progress = Callable[[int, int], None]


# ----------------------------------------------------------------------------- one study (a task)
def run_one(
    base: TeamDeck,
    index: int,
    fields: tuple[str, ...],
    values: tuple,
    outputs: list[str],
    key: str,
    stm: str | None = None,
    results: str | None = None,
) -> dict[str, Any]:
    """Run study ``index`` (``fields`` set to ``values``) and return its row; never raises:
    a failure is a row with status "failed", its one-line error and NaN outputs."""
    t0 = time.perf_counter()
    row = study_row(index, key, fields, values, outputs)
    try:
        cfg = study_deck(base, fields, values)
        out = None if results is None else Path(results)
        product, _, _ = team_mode.run_team(cfg, stm=stm, output=out, write_results=out is not None)
        vals, units = outputs_of(product, outputs)
        row.update(vals)
        row.update(status="ok", error="", units=units)
    except Exception as exc:  # noqa: BLE001 - every failure becomes the study's row
        row.update(status="failed", error=one_line(exc), units={})
    row["wall_s"] = time.perf_counter() - t0
    return row


# ----------------------------------------------------------------------------- a group of studies (a task)
_SETUPS: dict = {}  # group key -> (BatchSetup, prediction failures): kept by a worker between its chunks


def _setup_for(gkey: str, study: Any, stm: str | None) -> tuple[Any, Any]:
    """The group's shared reference, H and Φ_aug (cached in this process under ``gkey``)."""
    from fracas.team import batch

    hit = _SETUPS.get(gkey)
    if hit is not None:
        return hit
    if stm is not None:
        ref = stm_mode.reference_from_stm(study, stm)
    else:
        from fracas.team.reference import integrate_reference

        ref = integrate_reference(study)
        from fracas.status import RunStatus

        if ref.status != RunStatus.OK:
            raise FracasError("the reference stopped early")  # run_one gives the user's message
    got = (batch.prepare(study, ref), batch.prediction_failures(study, ref))
    _SETUPS.clear()  # one group at a time: a worker moves on to the next group
    _SETUPS[gkey] = got
    return got


def run_group(
    base: TeamDeck,
    items: list[tuple[int, tuple, str]],
    fields: tuple[str, ...],
    outputs: list[str],
    gkey: str,
    stm: str | None = None,
    pad_to: int = 1,
    max_batch: int | None = None,
) -> list[dict[str, Any]]:
    """Run the studies ``items`` ((index, values, key) each), which differ only in numeric
    fields (:func:`fracas.config.sweep.is_numeric_field`), as batched computations
    (:mod:`fracas.team.batch`): one reference, H and Φ_aug for all of them, P0, R and Q per
    study, one vmapped filter scan per ``max_batch`` studies padded to at least ``pad_to``.
    Each study's deck is made and validated as in a single run (:func:`study_deck`); the
    group's first study is built whole (``build_case``), the others are derived from it
    (:func:`fracas.build.vary.derive_study`: the same arrays, no trajectory load or schedule
    build) unless a varied field would add a table the base study lacks.
    Returns their rows; never raises.  A study whose deck fails gets its error; a study
    whose structure differs from the group's, or a group that cannot be batched (PDOT, a
    user gain, a reference or prediction that fails), runs through :func:`run_one`."""
    from fracas.team import batch

    t0 = time.perf_counter()
    max_batch = max_batch or batch.MAX_BATCH
    rows: dict[int, dict[str, Any]] = {}

    def one(i: int, v: tuple, k: str) -> None:
        rows[i] = run_one(base, i, fields, v, outputs, k, stm)

    built = _build_studies(base, items, fields, gkey, one)
    setup = _group_setup(gkey, built, stm)
    keep = []
    for i, v, k, st in built:  # without a setup, or of another structure: one by one
        if setup is not None and batch.structure_mismatch(setup.study, st) is None:
            keep.append((i, v, k, st))
        else:
            one(i, v, k)
    if keep:
        studies = [st for *_, st in keep]
        Pa, Pt = batch.final_covariances(setup, studies, max_batch=max_batch, pad_to=pad_to)
        for b, (i, v, k, st) in enumerate(keep):
            rows[i] = _batched_row(i, v, k, st, Pa, Pt, b, fields, outputs)
        others = sum(r["wall_s"] for j, r in rows.items() if j not in {x[0] for x in keep})
        share = (time.perf_counter() - t0 - others) / len(keep)  # the batch's wall time, shared
        for i, *_ in keep:
            rows[i]["wall_s"] = share
    return [rows[i] for i, _, _ in items]


def _build_studies(
    base: TeamDeck,
    items: list[tuple[int, tuple, str]],
    fields: tuple[str, ...],
    gkey: str,
    one: Callable[[int, tuple, str], None],
) -> list[tuple[int, tuple, str, Any]]:
    """(index, values, key, study) of each of ``items`` whose deck and study build: the
    group's structure built whole once, the others derived from it where they can be; a
    study that fails to build goes to ``one`` (:func:`run_one` records its failure)."""
    from fracas.build.vary import derivable, derive_study

    built = []  # (index, values, key, study)
    hit = _SETUPS.get(gkey)
    ref = hit[0].study if hit is not None else None  # the group's structure: built whole once
    numbers_only = tables_exist(base, fields)
    for i, v, k in items:
        try:
            deck = study_deck(base, fields, v)
            if ref is not None and numbers_only and derivable(ref, deck):
                st = derive_study(ref, deck)
            else:
                st = stm_mode.load_team(deck).study
                ref = st if ref is None else ref
            built.append((i, v, k, st))
        except Exception:  # noqa: BLE001 - run_one records the failure with its message
            one(i, v, k)
    return built


def _group_setup(gkey: str, built: list[tuple[int, tuple, str, Any]], stm: str | None) -> Any:
    """The group's batch setup (:func:`_setup_for` of its first built study), or None where
    it cannot be batched (nothing built, prediction failures, PDOT, a user gain, a
    reference that fails)."""
    if not built:
        return None
    try:
        setup, failed_predictions = _setup_for(gkey, built[0][3], stm)
    except Exception:  # noqa: BLE001 - PDOT, a user gain, a reference that fails: one by one
        return None
    return None if failed_predictions else setup


def _batched_row(
    i: int, v: tuple, k: str, st: Any, Pa: Any, Pt: Any, b: int, fields: tuple[str, ...], outputs: list[str]
) -> dict[str, Any]:
    """The row of study ``i`` (lane ``b`` of the batch's final covariances ``Pa``, ``Pt``)."""
    row = study_row(i, k, fields, v, outputs)
    labels, units = st.state_labels + st.labels, st.state_units + st.units
    with np.errstate(invalid="ignore"):
        sa = np.sqrt(np.clip(np.diag(Pa[b]), 0, None))
        stt = None if Pt is None else np.sqrt(np.clip(np.diag(Pt[b]), 0, None))
    try:
        vals, u = outputs_from(sa, stt, labels, units, outputs)
        row.update(vals)
        row.update(status="ok", error="", units=u)
    except Exception as exc:  # noqa: BLE001
        row.update(status="failed", error=one_line(exc), units={})
    return row


# ----------------------------------------------------------------------------- the sweep
@dataclass
class SweepResult:
    """What :func:`run_sweep` did: ``rows`` (every row of the table, by index), ``ran``
    (indices run this time), ``skipped`` (already in the table), ``table`` (path or None),
    ``wall_s``."""

    rows: list[dict[str, Any]]
    ran: list[int]
    skipped: list[int]
    table: Path | None
    wall_s: float
    fields: tuple[str, ...]
    outputs: list[str]
    units: dict[str, str]

    @property
    def failed(self) -> list[dict[str, Any]]:
        return [r for r in self.rows if r["status"] != "ok"]


@dataclass
class _Context:
    """What every task of a sweep needs; ``call`` gives a task's function and arguments."""

    base: TeamDeck
    fields: tuple[str, ...]
    studies: list[tuple]
    outputs: list[str]
    keys: list[str]
    stm: str | None
    results_for: Callable[[int], str | None]
    group_of: dict[int, str]
    prefix: str
    max_batch: int

    def call(self, task: tuple) -> cluster.Call:
        """(function, args) of a task (:func:`fracas.modes.sweep.plan.plan_tasks`)."""
        if task[0] == "one":
            i = task[1]
            args = (self.base, i, self.fields, self.studies[i], self.outputs, self.keys[i], self.stm)
            return run_one, (*args, self.results_for(i))
        _, idx, g, pad = task
        items = [(i, self.studies[i], self.keys[i]) for i in idx]
        gkey = f"{self.prefix}|{g}"
        return run_group, (self.base, items, self.fields, self.outputs, gkey, self.stm, pad, self.max_batch)

    def rows(self, task: tuple, done: cluster.Done) -> list[dict[str, Any]]:
        """The rows of a finished task."""
        if done.error is not None:
            return self.failed(task, done.error)
        got = done.result
        return got if isinstance(got, list) else [got]

    def failed(self, task: tuple, exc: BaseException) -> list[dict[str, Any]]:
        """The rows of a task whose worker failed (a lost worker, a pickling error)."""
        idx = [task[1]] if task[0] == "one" else task[1]
        rows = []
        for i in idx:
            row = {"index": i, "key": self.keys[i], **dict(zip(self.fields, self.studies[i]))}
            row.update(dict.fromkeys(self.outputs, float("nan")))
            row.update(status="failed", error=one_line(exc), wall_s=float("nan"))
            rows.append(row)
        return rows


@dataclass
class _Table:
    """The sweep table being written: its rows by study index (those already in it first),
    units and attributes; :meth:`record` adds finished rows."""

    path: Path
    rows: dict[int, dict[str, Any]]
    fields: tuple[str, ...]
    outputs: list[str]
    units: dict[str, str]
    attrs: dict[str, Any]
    n_todo: int
    progress: Progress | None

    def __post_init__(self) -> None:
        self.n_skipped = len(self.rows)

    def write(self) -> None:
        """Write the whole table (HDF5 + CSV, atomically)."""
        from fracas.io.sweep_table import write_sweep_table

        write_sweep_table(self.path, list(self.rows.values()), list(self.fields), self.outputs, self.units, self.attrs)

    def record(self, new: list[dict[str, Any]]) -> None:
        """Add the rows ``new``, write the table, then ``progress(done, total)`` per row."""
        for row in new:
            self.units.update(row.pop("units", {}) or {})
            self.rows[row["index"]] = row
        self.write()
        if self.progress is not None:
            done = len(self.rows) - self.n_skipped
            for j in range(len(new)):
                self.progress(done - len(new) + j + 1, self.n_todo)


def _run_tasks(todo: list[int], ctx: _Context, table: _Table, workers: int | None, scheduler: str | None) -> None:
    """Run the studies ``todo``: in this process (``workers=0``, no scheduler), on a Dask
    LocalCluster or on the scheduler at ``scheduler``; the rows that finish together are
    recorded (one table write).  In this process a task's exception stops the sweep; on a
    cluster a failed task (a lost worker, a pickling error) is its studies' failed rows."""
    with cluster.open_pool(workers, len(todo), scheduler) as pool:
        tasks = plan_tasks(todo, ctx.group_of, ctx.max_batch, pool.n_workers)
        calls = [ctx.call(task) for task in tasks]
        for batch in pool.completed_batches(calls, catch=not pool.in_process):
            record = [row for done in batch for row in ctx.rows(tasks[done.index], done)]
            table.record(record)


@reading_inputs
def span_problems(cfg: SweepDeck, base: TeamDeck) -> list[str]:
    """Every study's times against its reference trajectory's span, before any work, as
    ``fracas validate`` checks each study (:func:`fracas.config.team.span.team_span_problems`):
    a varied ``stop_days`` past the trajectory's end is refused here, not left to fail as a
    row.  At most :data:`MAX_LISTED_STUDIES` studies are named.  A trajectory deck that does
    not load is left to the run's own build, which says why."""
    from fracas.config.sweep import MAX_LISTED_STUDIES, varied_deck
    from fracas.config.team.span import team_span_problems
    from fracas.config.trajectory import load_deck

    try:
        tdeck = load_deck(base.resolve(base.ertraj.deck))
    except (FracasError, OSError):
        return []
    src = cfg.source_path or "<deck>"
    out: list[str] = []
    failing = 0
    for i, values in enumerate(cfg.studies()):
        found = team_span_problems(varied_deck(base, dict(zip(cfg.fields, values)), base.source_path), tdeck)
        if found:
            failing += 1
            if failing <= MAX_LISTED_STUDIES:
                out += [f"{src}: {study_label(i, cfg.fields, values)}: {p}" for p in found]
    if failing > MAX_LISTED_STUDIES:
        out.append(f"{src}: and {failing - MAX_LISTED_STUDIES} more studies past the end of the trajectory")
    return out


def run_sweep(
    cfg: SweepDeck,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    resume: bool = True,
    progress: Progress | None = None,
    table: str | Path | None = None,
    base: TeamDeck | None = None,
    batch: bool = True,
    max_batch: int | None = None,
) -> SweepResult:
    """Run every study of the sweep ``cfg``; returns a :class:`SweepResult`.

    ``workers=0``: in this process, one study after another (no Dask); ``workers=N`` (default:
    the CPU count): a Dask LocalCluster of N processes with one thread and one XLA host device
    each; ``scheduler="tcp://host:port"``: an existing Dask cluster (``workers`` ignored).
    ``resume``: studies already in the table file with status "ok" (same key: base deck hash
    and varied values) are skipped; failed ones run again.  ``progress(done, total)`` after
    each study (total: the studies to run this time).  ``table``: the table path (default the
    deck's ``[output] table``, else ``out/<deck stem>.h5``); ``base``: the study TeamDeck
    (default: read ``sweep.study``).  A failed study is a row with its one-line error.

    ``batch`` (default): studies that differ only in numeric fields
    (:func:`fracas.config.sweep.is_numeric_field`: sigmas, noise levels and times) form
    groups that run as batched computations (:func:`run_group`, at most ``max_batch``
    studies per compiled call, default :data:`fracas.team.batch.MAX_BATCH`), split into
    about one chunk per worker; other studies (and every study with ``keep_results``, which
    needs each study's whole product) run one by one (:func:`run_one`).
    """

    t0 = time.perf_counter()
    sw = cfg.sweep
    from fracas.team.batch import MAX_BATCH

    t0 = time.perf_counter()
    sw = cfg.sweep
    base = base if base is not None else load_team_deck(cfg.resolve(sw.study))
    problems = sweep_problems(cfg, base)  # every study against the schema, before any work
    problems = problems or span_problems(cfg, base)
    if problems:
        raise deck_error(problems)
    fields = cfg.fields
    outputs = list(sw.outputs)
    ins = (cfg.source_path, *team_inputs(base), *((cfg.resolve(sw.stm_file),) if sw.stm_file else ()))
    out = check_output_path(table if table is not None else table_path(cfg), "sweep table", ins)
    check_output_path(out.with_suffix(".csv"), "sweep table (CSV)", ins)  # its CSV twin (io.sweep_table)
    # -o decides where every output goes: with a table path given, the deck's plot and results
    # folder keep their names but go beside it (the STM file the deck names stays where it says)
    beside = (lambda p: out.parent / Path(p).name) if table is not None else cfg.resolve
    plot = check_output_path(beside(cfg.output.plot), "plot", ins) if cfg.output.plot else None
    bh = base_hash(base)
    studies = cfg.studies()
    keys = [study_key(bh, fields, v) for v in studies]
    units = table_units(base, fields, outputs)
    rows = resumed_rows(out, bh, fields, outputs, keys, units) if resume and out.exists() else {}
    skipped = sorted(rows)
    todo = [i for i in range(len(studies)) if i not in rows]
    stm = stm_file(cfg, base, todo)
    res_dir = results_dir(cfg, beside, out)
    attrs = {"title": cfg.title, "base_hash": bh, "study": str(base.source_path), "combine": sw.combine}
    written = _Table(out, rows, fields, outputs, units, attrs, len(todo), progress)

    def results_for(i: int) -> str | None:
        return None if res_dir is None else str(res_dir / f"study_{i:05d}_{keys[i]}.h5")

    group_of = batch_groups(base, studies, fields, batch and res_dir is None)
    mb = int(max_batch or MAX_BATCH)
    ctx = _Context(base, fields, studies, outputs, keys, stm, results_for, group_of, f"{bh}|{stm}", mb)
    if todo:
        _run_tasks(todo, ctx, written, workers, scheduler)
    elif rows:
        written.write()
    ordered = [rows[i] for i in sorted(rows)]
    if plot is not None and ordered:
        from fracas.report.sweep import plot_sweep

        plot_sweep(out, plot)
    return SweepResult(ordered, todo, skipped, out, time.perf_counter() - t0, fields, outputs, units)


# ----------------------------------------------------------------------------- command line
#: the width of the summary's lines (a terminal's 80 columns)
WIDTH = 80
#: at most this many failed studies are listed in the summary (every one is in the table)
MAX_LISTED_FAILURES = 10


def _wrap(text: str, indent: str = "", more: str = "    ") -> list[str]:
    """``text`` as lines of at most :data:`WIDTH` columns (a word longer than a line, such as
    a long path, stays whole on its own line, so that it can be copied)."""
    import textwrap

    return textwrap.wrap(
        text,
        WIDTH,
        initial_indent=indent,
        subsequent_indent=indent + more,
        break_on_hyphens=False,
        break_long_words=False,
    ) or [indent]


def summary_text(res: SweepResult) -> str:
    """A few lines of at most 80 columns: how many studies ran, skipped and failed, the
    table, each failure (at most :data:`MAX_LISTED_FAILURES`, then a count)."""
    n_ok = sum(r["status"] == "ok" for r in res.rows)
    lines = _wrap(
        f"sweep: {len(res.rows)} studies ({len(res.ran)} run, {len(res.skipped)} already in the table), "
        f"{n_ok} ok, {len(res.failed)} failed, {res.wall_s:.1f} s"
    )
    lines += _wrap(f"table: {res.table} (and {Path(res.table).with_suffix('.csv')})")
    for r in res.failed[:MAX_LISTED_FAILURES]:
        label = study_label(r["index"], tuple(res.fields), tuple(r[f] for f in res.fields))
        lines += _wrap(f"{label}: {r['error']}", indent="  ")
    extra = len(res.failed) - MAX_LISTED_FAILURES
    if extra > 0:
        lines += _wrap(
            f"and {extra} more failed stud{'ies' if extra > 1 else 'y'}: their errors are in the table", "  "
        )
    return "\n".join(lines)


def sweep_main(
    deck_path: str | Path,
    vary: list[str] | tuple[str, ...] = (),
    workers: int | None = None,
    scheduler: str | None = None,
    resume: bool = True,
    out: str | Path | None = None,
    progress: Progress | None = None,
) -> tuple[Path, str, int]:
    """``fracas sweep DECK [--vary FIELD=VALUES ...]``: everything; returns (table path,
    summary text, number of failed studies).  Every study is validated before any work
    (:func:`fracas.config.sweep.sweep_problems`: a one-line DeckError).  ``out``: the table
    path (default the deck's ``[output] table``, else ``out/<deck stem>.h5``; for a TEAM deck
    ``out/<stem>_sweep.h5`` next to it)."""
    cfg = sweep_deck_for(deck_path, list(vary))
    res = run_sweep(cfg, workers=workers, scheduler=scheduler, resume=resume, progress=progress, table=out)
    return Path(res.table), summary_text(res), len(res.failed)
