"""Sweeps: one TEAM study run many times with some of its fields varied (docs/sweep.md).

``vary(deck, field, value)`` builds a study's TeamDeck in memory (no TOML written);
``run_sweep(cfg)`` runs every study (in this process, on a Dask LocalCluster or on an
existing Dask scheduler), appends each finished row to the table file (HDF5 + CSV, written
whole and atomically each time) and skips, on a restart, the studies already in it;
``sweep_main`` is the command line's ``fracas sweep``.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import tomllib

from fracas import pipeline
from fracas.config.modes import deck_mode
from fracas.config.sweep import (
    SweepDeck,
    guidance_output,
    is_numeric_field,
    load_sweep_deck,
    output_problems,
    output_unit,
    parse_field_path,
    study_label,
    sweep_problems,
    varied_deck,
)
from fracas.config.team import TeamDeck, load_team_deck
from fracas.config.trajectory import cut, deck_error, read_deck_text
from fracas.errors import DeckError, FracasError
from fracas.io.atomic import check_output_path

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
    "SweepResult",
]

Progress = Callable[[int, int], None]


# ----------------------------------------------------------------------------- varying a deck
def vary(deck: TeamDeck, field: str, value: Any) -> TeamDeck:
    """``deck`` with ``field`` (a dotted path, list entries by index: ``tracking[0].sigma``)
    set to ``value``, validated again (every validator runs); the base deck's
    ``source_path``/``source_text`` are kept so relative paths resolve as before.  A refused
    value is a one-line DeckError naming the field."""
    return vary_many(deck, {field: value})


def vary_many(deck: TeamDeck, values: dict[str, Any]) -> TeamDeck:
    """:func:`vary` for several fields at once (validated once, after all are set;
    :func:`fracas.config.sweep.varied_deck`)."""
    return varied_deck(deck, values)


# ----------------------------------------------------------------------------- keys, units, outputs
def base_hash(deck: TeamDeck) -> str:
    """SHA-256 (hex) of the base study's deck text and of its trajectory deck's text."""
    h = hashlib.sha256((deck.source_text or json.dumps(deck.model_dump(mode="json"), sort_keys=True)).encode())
    try:
        h.update(b"\0" + read_deck_text(deck.resolve(deck.ertraj.deck)).encode())
    except DeckError:
        pass
    return h.hexdigest()


def study_key(base: str, fields: tuple[str, ...], values: tuple) -> str:
    """16 hex digits naming one study: the base hash and the varied values."""
    text = json.dumps([base, list(fields), [_plain(v) for v in values]])
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _plain(v: Any) -> Any:
    return v.item() if isinstance(v, np.generic) else v


_SUFFIX_UNITS = (
    ("_km_s", "km/s"),
    ("_km", "km"),
    ("_kg", "kg"),
    ("_days", "d"),
    ("_hours", "h"),
    ("_deg", "deg"),
    ("_s", "s"),
)


def input_unit(deck: TeamDeck, field: str) -> str:
    """The unit of a varied field as the deck writes it (from its name; a tracking sigma from
    its type; "deck" where the unit is the parameter label's, e.g. a parameter sigma)."""
    from fracas.config.team import SIGMA_UNITS

    parts = parse_field_path(field)
    names = [p for p in parts if isinstance(p, str)]
    last = names[-1]
    if len(parts) >= 3 and parts[0] == "tracking" and last == "sigma" and isinstance(parts[1], int):
        if parts[1] < len(deck.tracking):
            return str(SIGMA_UNITS[deck.tracking[parts[1]].type][0])
    if len(names) >= 2 and names[-2] == "proportionality" and last == "sigma":
        return "1"
    for n in reversed(names):
        for suf, unit in _SUFFIX_UNITS:
            if n.endswith(suf):
                return unit
    return "deck"


def outputs_of(product, names: list[str]) -> tuple[dict[str, float], dict[str, str]]:
    """The named outputs of a TeamProduct (final values, guidance event results) and their units."""
    sig_t = None if product.true is None else product.true.sigma[-1]
    cov = [n for n in names if guidance_output(n) is None]
    vals, units = outputs_from(product.assumed.sigma[-1], sig_t, list(product.labels), list(product.units), cov)
    gv, gu = guidance_outputs(product.guidance, [n for n in names if guidance_output(n) is not None])
    vals.update(gv)
    units.update(gu)
    return {n: vals[n] for n in names}, {n: units[n] for n in names}


def guidance_outputs(events, names: list[str]) -> tuple[dict[str, float], dict[str, str]]:
    """The named guidance outputs (``NAME.dv_mean_m_s``, ...; :func:`fracas.config.sweep.guidance_output`)
    of a study's guidance events (:class:`fracas.products.GuidanceEvent`): (values, units)."""
    by_name = {e.name: e for e in (events or [])}
    vals, units = {}, {}
    for name in names:
        event, what, target = guidance_output(name)
        e = by_name.get(event)
        if e is None:
            have = ", ".join(by_name) or "none"
            raise FracasError(f"output {name}: the study has no guidance event {event!r} (its guidance events: {have})")
        if target is not None:
            if target not in e.target_names:
                raise FracasError(
                    f"output {name}: guidance event {event!r} has no target {target!r} "
                    f"(its targets: {', '.join(e.target_names)})"
                )
            j = list(e.target_names).index(target)
            vals[name] = float(math.sqrt(max(float(np.asarray(e.target_cov_after)[j, j]), 0.0)))
            units[name] = str(e.target_units[j])
        elif what == "propellant_sigma_kg":
            vals[name], units[name] = float(e.propellant_sigma_kg), "kg"
        else:
            vals[name] = float(getattr(e, what.replace("_m_s", "_km_s"))) * 1000.0
            units[name] = "m/s"
    return vals, units


def check_outputs(cfg: SweepDeck, base: TeamDeck) -> None:
    """Refuse (one-line DeckError naming the field) a guidance output the study cannot give:
    an event it does not have, a target not among the event's, the propellant of an
    impulsive event (:func:`fracas.config.sweep.output_problems`)."""
    problems = output_problems(cfg, base)
    if problems:
        raise deck_error(problems)


def outputs_from(sig_a, sig_t, labels: list[str], units: list[str], names: list[str]):
    """The named outputs from the final 1σ vectors (assumed, true or None) of a study whose
    covariance rows are ``labels`` (in ``units``): (values, units)."""
    vals, out_units = {}, {}
    for name in names:
        true = name.startswith("true_")
        sig = sig_t if true else sig_a
        if sig is None:
            raise FracasError(f"output {name}: the study has no generalized covariance ([gencov])")
        s = np.asarray(sig, dtype=np.float64)
        base = name[5:] if true else name
        if base == "position_rss_km":
            vals[name], out_units[name] = float(math.sqrt(float(np.sum(s[0:3] ** 2)))), "km"
        elif base == "velocity_rss_km_s":
            vals[name], out_units[name] = float(math.sqrt(float(np.sum(s[3:6] ** 2)))), "km/s"
        else:
            label = base[len("sigma[") : -1]
            if label not in labels:
                raise FracasError(
                    f"output sigma[{label}]: no covariance label {label!r} (the study has: {', '.join(labels)})"
                )
            vals[name] = float(s[labels.index(label)])
            out_units[name] = units[labels.index(label)]
    return vals, out_units


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, FracasError):
        text = str(exc)
    else:
        text = f"{type(exc).__name__}: {exc}"
    return " ".join(text.split())


# ----------------------------------------------------------------------------- one study (a task)
def study_deck(base: TeamDeck, fields: tuple[str, ...], values: tuple) -> TeamDeck:
    """The TeamDeck of one study: ``base`` with ``fields`` set to ``values``; studies share no
    side outputs (no per-study STM build, no punch file) and compute no error budget (the
    table has no budget output; it would cost one covariance pass per error source)."""
    cfg = vary_many(base, dict(zip(fields, values)))
    upd: dict[str, Any] = {}
    if cfg.budget.enabled:
        upd["budget"] = cfg.budget.model_copy(update={"enabled": False})
    if cfg.errcon.build_stm:
        upd["errcon"] = cfg.errcon.model_copy(update={"build_stm": False})
    if cfg.punch is not None:
        upd["punch"] = None
    if upd:
        src, text = cfg._source_path, cfg._source_text
        cfg = cfg.model_copy(update=upd)
        cfg._source_path, cfg._source_text = src, text
    return cfg


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
    row: dict[str, Any] = {"index": int(index), "key": key}
    row.update({f: _plain(v) for f, v in zip(fields, values)})
    row.update(dict.fromkeys(outputs, float("nan")))
    try:
        cfg = study_deck(base, fields, values)
        out = None if results is None else Path(results)
        product, _, _ = pipeline.run_team(cfg, stm=stm, output=out, write_results=out is not None)
        vals, units = outputs_of(product, outputs)
        row.update(vals)
        row.update(status="ok", error="", units=units)
    except Exception as exc:  # noqa: BLE001 - every failure becomes the study's row
        row.update(status="failed", error=_one_line(exc), units={})
    row["wall_s"] = time.perf_counter() - t0
    return row


# ----------------------------------------------------------------------------- a group of studies (a task)
_SETUPS: dict = {}  # group key -> (BatchSetup, prediction failures): kept by a worker between its chunks


def _setup_for(gkey: str, study, stm: str | None):
    """The group's shared reference, H and Φ_aug (cached in this process under ``gkey``)."""
    from fracas.team import batch

    hit = _SETUPS.get(gkey)
    if hit is not None:
        return hit
    if stm is not None:
        ref = pipeline.reference_from_stm(study, stm)
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
    built = []  # (index, values, key, study)

    def one(i, v, k):
        rows[i] = run_one(base, i, fields, v, outputs, k, stm)

    from fracas.build.vary import derivable, derive_study

    hit = _SETUPS.get(gkey)
    ref = hit[0].study if hit is not None else None  # the group's structure: built whole once
    numbers_only = _tables_exist(base, fields)
    for i, v, k in items:
        try:
            deck = study_deck(base, fields, v)
            if ref is not None and numbers_only and derivable(ref, deck):
                st = derive_study(ref, deck)
            else:
                st = pipeline.load_team(deck).study
                ref = st if ref is None else ref
            built.append((i, v, k, st))
        except Exception:  # noqa: BLE001 - run_one records the failure with its message
            one(i, v, k)
    setup = None
    if built:
        try:
            setup, failed_predictions = _setup_for(gkey, built[0][3], stm)
            if failed_predictions:
                setup = None
        except Exception:  # noqa: BLE001 - PDOT, a user gain, a reference that fails: one by one
            setup = None
    if setup is None:
        for i, v, k, _ in built:
            one(i, v, k)
        built = []
    keep = []
    for i, v, k, st in built:
        if batch.structure_mismatch(setup.study, st) is None:
            keep.append((i, v, k, st))
        else:
            one(i, v, k)
    if keep:
        t1 = time.perf_counter()
        studies = [st for *_, st in keep]
        Pa, Pt = batch.final_covariances(setup, studies, max_batch=max_batch, pad_to=pad_to)
        for b, (i, v, k, st) in enumerate(keep):
            row: dict[str, Any] = {"index": int(i), "key": k}
            row.update({f: _plain(x) for f, x in zip(fields, v)})
            row.update(dict.fromkeys(outputs, float("nan")))
            labels, units = st.state_labels + st.labels, st.state_units + st.units
            with np.errstate(invalid="ignore"):
                sa = np.sqrt(np.clip(np.diag(Pa[b]), 0, None))
                stt = None if Pt is None else np.sqrt(np.clip(np.diag(Pt[b]), 0, None))
            try:
                vals, u = outputs_from(sa, stt, labels, units, outputs)
                row.update(vals)
                row.update(status="ok", error="", units=u)
            except Exception as exc:  # noqa: BLE001
                row.update(status="failed", error=_one_line(exc), units={})
            rows[i] = row
        others = sum(r["wall_s"] for j, r in rows.items() if j not in {x[0] for x in keep})
        share = (time.perf_counter() - t0 - others) / len(keep)  # the batch's wall time, shared
        for i, *_ in keep:
            rows[i]["wall_s"] = share
        _ = t1
    return [rows[i] for i, _, _ in items]


def _tables_exist(base: TeamDeck, fields: tuple[str, ...]) -> bool:
    """Whether every numeric field of ``fields`` lies in a table (or list) the base study
    has, so that setting it changes a number and adds no table (a [gencov] or a thrust-noise
    component the study does not have would change its structure)."""
    cur0 = base.model_dump(mode="python")
    for f in fields:
        if not is_numeric_field(f):
            continue
        cur: Any = cur0
        for p in parse_field_path(f)[:-1]:
            try:
                cur = cur[p]
            except (KeyError, IndexError, TypeError):
                return False
            if cur is None:
                return False
    return True


# ----------------------------------------------------------------------------- the sweep
class SweepResult:
    """What :func:`run_sweep` did: ``rows`` (every row of the table, by index), ``ran``
    (indices run this time), ``skipped`` (already in the table), ``table`` (path or None),
    ``wall_s``."""

    def __init__(self, rows, ran, skipped, table, wall_s, fields, outputs, units):
        self.rows, self.ran, self.skipped, self.table = rows, ran, skipped, table
        self.wall_s, self.fields, self.outputs, self.units = wall_s, fields, outputs, units

    @property
    def failed(self) -> list[dict[str, Any]]:
        return [r for r in self.rows if r["status"] != "ok"]


class _WorkerSetup:
    """Dask worker plugin: one XLA host device per worker, before any task touches JAX."""

    name = "fracas-worker-setup"

    def setup(self, worker=None):
        from fracas._jax import worker_setup

        worker_setup(1)


def _plugin():
    from distributed import WorkerPlugin

    class FracasWorker(_WorkerSetup, WorkerPlugin):
        pass

    return FracasWorker()


def _table_path(cfg: SweepDeck) -> Path:
    if cfg.output.table:
        return cfg.resolve(cfg.output.table)
    return pipeline.default_output(cfg.source_path)


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
    from fracas.io.sweep_table import write_sweep_table

    t0 = time.perf_counter()
    sw = cfg.sweep
    base = base if base is not None else load_team_deck(cfg.resolve(sw.study))
    problems = sweep_problems(cfg, base)  # every study against the schema, before any work
    if problems:
        raise deck_error(problems)
    fields = cfg.fields
    outputs = list(sw.outputs)
    out = check_output_path(table if table is not None else _table_path(cfg), "sweep table")
    # -o decides where every output goes: with a table path given, the deck's plot and results
    # folder keep their names but go beside it (the STM file the deck names stays where it says)
    beside = (lambda p: out.parent / Path(p).name) if table is not None else cfg.resolve
    plot = check_output_path(beside(cfg.output.plot), "plot") if cfg.output.plot else None
    bh = base_hash(base)
    studies = cfg.studies()
    keys = [study_key(bh, fields, v) for v in studies]
    units: dict[str, str] = {f: input_unit(base, f) for f in fields}
    units.update({n: u for n in outputs if (u := output_unit(n)) is not None})
    rows: dict[int, dict[str, Any]] = {}
    if resume and out.exists():
        old_rows, old_units = resume_table(out, bh, fields, outputs)
        by_key = {r["key"]: r for r in old_rows if r["status"] == "ok"}
        units.update({k: v for k, v in old_units.items() if k in outputs})
        for i, k in enumerate(keys):
            if k in by_key:
                rows[i] = dict(by_key[k], index=i)
    skipped = sorted(rows)
    todo = [i for i in range(len(studies)) if i not in rows]

    stm = None
    if sw.stm_file:
        stm_path = cfg.resolve(sw.stm_file)
        if not stm_path.exists() and todo:
            pipeline.build_stm(base, stm_path)
        stm = str(stm_path)
    res_dir = None
    if sw.keep_results:
        res_dir = beside(sw.results_folder) if sw.results_folder else out.parent / f"{out.stem}_results"
        res_dir.mkdir(parents=True, exist_ok=True)
    attrs = {"title": cfg.title, "base_hash": bh, "study": str(base.source_path), "combine": sw.combine}

    def results_for(i: int) -> str | None:
        return None if res_dir is None else str(res_dir / f"study_{i:05d}_{keys[i]}.h5")

    def record(new: list[dict[str, Any]]) -> None:
        for row in new:
            units.update(row.pop("units", {}) or {})
            rows[row["index"]] = row
        write_sweep_table(out, list(rows.values()), list(fields), outputs, units, attrs)
        if progress is not None:
            done = len(rows) - len(skipped)
            for j in range(len(new)):
                progress(done - len(new) + j + 1, len(todo))

    # guidance and reset studies are not batched (fracas.team.batch.prepare): one by one from the start
    batchable = not base.guidance and not any(e.type == "reset" for e in base.event)
    group_of = _groups(studies, fields) if (batch and res_dir is None and batchable) else {}
    from fracas.team.batch import MAX_BATCH

    mb = int(max_batch or MAX_BATCH)
    ctx = _Context(base, fields, studies, outputs, keys, stm, results_for, group_of, f"{bh}|{stm}", mb)
    if todo and workers == 0 and scheduler is None:
        for task in ctx.tasks(todo, 1):
            record(ctx.run(task))
    elif todo:
        _run_dask(todo, ctx, record, workers, scheduler)
    elif rows:
        write_sweep_table(out, list(rows.values()), list(fields), outputs, units, attrs)
    ordered = [rows[i] for i in sorted(rows)]
    if plot is not None and ordered:
        from fracas.report.sweep import plot_sweep

        plot_sweep(out, plot)
    return SweepResult(ordered, todo, skipped, out, time.perf_counter() - t0, fields, outputs, units)


_KEY = re.compile(r"^[0-9a-f]{16}$")


def resume_table(
    path: Path, base_hash: str, fields: tuple[str, ...], outputs: list[str]
) -> tuple[list[dict[str, Any]], dict[str, str]]:
    """(rows, units) of the sweep table at ``path`` to resume from, read through the checked
    reader (:class:`fracas.io.hdf5.Checked`: the file's integrity header when it has one,
    then dtype, shape and the SHA-256 of every dataset); a one-line ResultsFileError naming
    the table and what is wrong: damaged, not a sweep table, written for another study
    (its ``base_hash``), with other columns, or rows that are not a sweep's (a status other
    than ok/failed, a malformed key, a repeated index)."""
    import h5py

    from fracas.errors import ResultsFileError
    from fracas.io import hdf5
    from fracas.io.sweep_table import KIND, VERSION

    src = str(path)
    again = "; rerun with --no-resume (or another -o) to start a new table"
    try:  # the file's integrity header checked before h5py decodes anything (fracas.io.hdf5.open_h5)
        with hdf5.open_h5(path, ResultsFileError, "sweep table") as f:
            kind = hdf5.attr_text(f, "kind")
            if kind != KIND:
                raise ResultsFileError(f"{src}: kind = {kind!r}, expected {KIND!r} (not a sweep table){again}")
            version = hdf5.attr_int(f, "version")
            if version is None or not 1 <= version <= VERSION:
                raise ResultsFileError(f"{src}: version = {f.attrs.get('version')!r}, expected 1 to {VERSION}{again}")
            got = hdf5.attr_text(f, "base_hash")
            if got != base_hash:
                raise ResultsFileError(
                    f"{src}: base_hash = {str(got)[:12]}...: written for another study or sweep deck (this "
                    f"sweep's {base_hash[:12]}...){again}"
                )
            ins, outs = hdf5.attr_strs(f, "input_columns"), hdf5.attr_strs(f, "output_columns")
            if ins != list(fields) or outs != list(outputs):
                raise ResultsFileError(
                    f"{src}: columns {ins} -> {outs}, expected this sweep's {list(fields)} -> {outputs}{again}"
                )
            c = hdf5.Checked(f, src, ResultsFileError)
            index = c.num("index", (None,), integer=True)
            n = int(index.shape[0])
            key, status, error = c.strs("key", n), c.strs("status", n), c.strs("error", n)
            wall = c.num("wall_s", (n,))
            cols: dict[str, Any] = {}
            units: dict[str, str] = {}
            for name in ins:
                ds = c.dataset(f"inputs/{name}")
                cols[name] = c.strs(ds.name, n) if h5py.check_string_dtype(ds.dtype) else c.num(ds.name, (n,))
            for name in outs:
                cols[name] = c.num(f"outputs/{name}", (n,))
                units[name] = hdf5.attr_text(f[f"outputs/{name}"], "units") or "none"
    except ResultsFileError:
        raise
    except Exception as exc:  # noqa: BLE001 - whatever a damaged file makes h5py or numpy raise
        why = f"{type(exc).__name__}: {cut(' '.join(str(exc).split()), 80)}"
        raise ResultsFileError(f"{src}: unreadable sweep table ({why}){again}") from None
    bad = next((k for k, s in enumerate(status) if s not in ("ok", "failed")), None)
    if bad is None:
        bad = next((k for k, s in enumerate(key) if not _KEY.match(s)), None)
    if bad is not None or len(set(index.tolist())) != n:
        row = bad if bad is not None else n - 1
        raise ResultsFileError(
            f"{src}: row {row}: status {status[row]!r}, key {key[row]!r} or a repeated index: expected a "
            f"sweep's rows (ok/failed, 16 hex digits, distinct indices){again}"
        )
    rows = []
    for k in range(n):
        row: dict[str, Any] = {"index": int(index[k]), "key": key[k]}
        row.update({name: _plain(col[k]) for name, col in cols.items()})
        row.update(status=status[k], error=error[k], wall_s=float(wall[k]))
        rows.append(row)
    return rows, units


def _groups(studies: list[tuple], fields: tuple[str, ...]) -> dict[int, str]:
    """Study index -> its group (the values of its structural fields), for the studies whose
    group has two or more members (the others run one by one)."""
    numeric = [is_numeric_field(f) for f in fields]
    if not any(numeric):
        return {}
    groups: dict[str, list[int]] = {}
    for i, v in enumerate(studies):
        groups.setdefault(json.dumps([_plain(x) for x, num in zip(v, numeric) if not num]), []).append(i)
    return {i: g for g, idx in groups.items() if len(idx) >= 2 for i in idx}


class _Context:
    """What every task of a sweep needs; ``tasks`` cuts the studies to run into tasks."""

    def __init__(self, base, fields, studies, outputs, keys, stm, results_for, group_of, prefix, max_batch):
        self.base, self.fields, self.studies, self.outputs, self.keys = base, fields, studies, outputs, keys
        self.stm, self.results_for, self.group_of, self.prefix = stm, results_for, group_of, prefix
        self.max_batch = max_batch

    def tasks(self, todo: list[int], n_workers: int) -> list[tuple]:
        """("group", indices, group, pad) chunks (about one per worker, at most max_batch
        studies each) and ("one", index) tasks, in the order of ``todo``."""
        from fracas.team.batch import batch_size

        by_group: dict[str, list[int]] = {}
        for i in todo:
            if i in self.group_of:
                by_group.setdefault(self.group_of[i], []).append(i)
        out: list[tuple] = []
        for g, idx in by_group.items():
            c = max(1, min(self.max_batch, math.ceil(len(idx) / max(1, n_workers))))
            pad = batch_size(c)
            out += [("group", idx[j : j + c], g, pad) for j in range(0, len(idx), c)]
        return out + [("one", i) for i in todo if i not in self.group_of]

    def call(self, task: tuple) -> tuple:
        """(function, args) of a task (run here, or submitted to a Dask worker)."""
        if task[0] == "one":
            i = task[1]
            return run_one, (
                self.base,
                i,
                self.fields,
                self.studies[i],
                self.outputs,
                self.keys[i],
                self.stm,
                self.results_for(i),
            )
        _, idx, g, pad = task
        items = [(i, self.studies[i], self.keys[i]) for i in idx]
        return run_group, (
            self.base,
            items,
            self.fields,
            self.outputs,
            f"{self.prefix}|{g}",
            self.stm,
            pad,
            self.max_batch,
        )

    def run(self, task: tuple) -> list[dict[str, Any]]:
        fn, a = self.call(task)
        got = fn(*a)
        return got if isinstance(got, list) else [got]

    def failed(self, task: tuple, exc: BaseException) -> list[dict[str, Any]]:
        """The rows of a task whose worker failed (a lost worker, a pickling error)."""
        idx = [task[1]] if task[0] == "one" else task[1]
        rows = []
        for i in idx:
            row = {"index": i, "key": self.keys[i], **dict(zip(self.fields, self.studies[i]))}
            row.update(dict.fromkeys(self.outputs, float("nan")))
            row.update(status="failed", error=_one_line(exc), wall_s=float("nan"))
            rows.append(row)
        return rows


def start_cluster(workers: int | None, n_tasks: int, scheduler: str | None, env: dict | None = None, timeout=None):
    """(LocalCluster or None, Client): a LocalCluster of single-threaded worker processes
    (``workers``, default one per core, at most ``n_tasks``; ``env`` set in each worker
    process), or a client of the running scheduler at ``scheduler``."""
    import os

    from distributed import Client, LocalCluster

    cluster = None
    if scheduler is None:
        n = workers if workers is not None else (os.cpu_count() or 1)
        extra = {"env": env} if env else {}
        cluster = LocalCluster(
            n_workers=max(1, min(n, n_tasks)),
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            **extra,
        )
    try:
        client = Client(cluster if cluster is not None else scheduler, **({"timeout": timeout} if timeout else {}))
    except Exception:
        if cluster is not None:
            cluster.close()
        raise
    return cluster, client


def _run_dask(todo, ctx: _Context, record, workers, scheduler) -> None:
    from distributed import as_completed

    cluster, client = start_cluster(workers, len(todo), scheduler)
    try:
        client.register_plugin(_plugin())
        n_workers = len(client.scheduler_info().get("workers", {})) or 1
        futures = {}
        for task in ctx.tasks(todo, n_workers):
            fn, a = ctx.call(task)
            futures[client.submit(fn, *a, pure=False)] = task
        for done in as_completed(futures).batches():  # results that arrive together: one table write
            new: list[dict[str, Any]] = []
            for fut in done:
                task = futures[fut]
                try:
                    got = fut.result()
                    new += got if isinstance(got, list) else [got]
                except Exception as exc:  # noqa: BLE001 - a lost worker, a pickling error
                    new += ctx.failed(task, exc)
            record(new)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


# ----------------------------------------------------------------------------- command line
def _value(text: str) -> Any:
    """One command-line value as TOML reads it (1e-3 -> float, true -> bool, "x" -> str);
    a bare word that is not TOML is a string."""
    try:
        return tomllib.loads(f"v = {text.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        return text.strip()


def parse_vary(spec: str) -> dict[str, Any]:
    """``FIELD=VALUES`` -> a ``[[sweep.vary]]`` table: ``a=1,2,3`` (values), ``a=0.1:1:5``
    (start:stop:num, linear), ``a=log:1e-3:1e-1:5`` (logarithmic).  DeckError if malformed."""
    if "=" not in spec:
        raise DeckError(f"--vary {spec!r}: expected FIELD=VALUES, e.g. thrust_noise.proportionality.sigma=0.01,0.02")
    field, _, rhs = spec.partition("=")
    field, rhs = field.strip(), rhs.strip()
    if not rhs:
        raise DeckError(f"--vary {spec!r}: no values after '='")
    if ":" in rhs and not rhs.startswith(("'", '"')):
        parts = rhs.split(":")
        spacing = "linear"
        if parts[0].strip().lower() in ("log", "lin", "linear"):
            spacing = "log" if parts[0].strip().lower() == "log" else "linear"
            parts = parts[1:]
        if len(parts) != 3:
            raise DeckError(f"--vary {spec!r}: a range is start:stop:num or log:start:stop:num")
        try:
            start, stop, num = float(parts[0]), float(parts[1]), int(parts[2])
        except ValueError:
            raise DeckError(f"--vary {spec!r}: start and stop must be numbers, num an integer") from None
        return {"field": field, "start": start, "stop": stop, "num": num, "spacing": spacing}
    return {"field": field, "values": [_value(v) for v in rhs.split(",") if v.strip()]}


def _with_vary(cfg: SweepDeck, specs: list[str]) -> SweepDeck:
    """``cfg`` with the command line's ``--vary`` entries (replacing entries of the same field)."""
    from pydantic import ValidationError

    from fracas.config.trajectory import deck_error, validation_problems

    if not specs:
        return cfg
    new = [parse_vary(s) for s in specs]
    named = {v["field"] for v in new}
    data = cfg.model_dump(mode="python", exclude_unset=True)
    data["sweep"]["vary"] = [v for v in data["sweep"].get("vary", []) if v["field"] not in named] + new
    src = f"{cfg.source_path or '<deck>'} (with --vary)"
    try:
        out = SweepDeck.model_validate(data)
    except ValidationError as exc:
        raise deck_error(validation_problems(exc, src, SweepDeck, data)) from None
    out._source_path, out._source_text = cfg._source_path, cfg._source_text
    return out


def _deck_for(deck_path: str | Path, specs: list[str]) -> SweepDeck:
    """The sweep deck of ``deck_path``: a sweep deck (``--vary`` adds or replaces fields) or a
    TEAM deck swept over the ``--vary`` fields (at least one)."""
    path = Path(deck_path)
    mode = deck_mode(read_deck_text(path), str(path))
    if mode == "sweep":
        return _with_vary(load_sweep_deck(path), specs)
    if mode != "team":
        raise DeckError(f'{path}: a sweep runs a TEAM deck or a sweep deck (mode = "sweep"), not mode = "{mode}"')
    if not specs:
        raise DeckError(f"{path}: a TEAM deck: give the fields to vary with --vary FIELD=VALUES")
    from pydantic import ValidationError

    from fracas.config.trajectory import deck_error, validation_problems

    data = {
        "mode": "sweep",
        "sweep": {"study": path.name, "vary": [parse_vary(s) for s in specs]},
        "output": {"table": f"out/{path.stem}_sweep.h5"},
    }
    src = f"{path} (--vary)"
    try:
        cfg = SweepDeck.model_validate(data)
    except ValidationError as exc:
        raise deck_error(validation_problems(exc, src, SweepDeck, data)) from None
    cfg._source_path = str(path)
    return cfg


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
    cfg = _deck_for(deck_path, list(vary))
    res = run_sweep(cfg, workers=workers, scheduler=scheduler, resume=resume, progress=progress, table=out)
    return Path(res.table), summary_text(res), len(res.failed)
