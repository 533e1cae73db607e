"""The rows of a sweep table (:mod:`fracas.modes.sweep.run`; docs/sweep.md): a study's outputs from
its TEAM product or its final 1σ vectors (:func:`outputs_of`, :func:`outputs_from`,
:func:`guidance_outputs`), the row a study starts as (:func:`study_row`) and the rows a
table already holds, read back to resume a sweep (:func:`resume_table`, :func:`resumed_rows`).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from fracas.config.sweep import SweepDeck, guidance_output, output_problems
from fracas.config.team import TeamDeck
from fracas.config.trajectory import cut, deck_error
from fracas.errors import FracasError
from fracas.modes.sweep.plan import plain

__all__ = [
    "outputs_of",
    "guidance_outputs",
    "check_outputs",
    "outputs_from",
    "one_line",
    "study_row",
    "resume_table",
    "resumed_rows",
]


# ----------------------------------------------------------------------------- a study's outputs
def outputs_of(product: Any, names: list[str]) -> tuple[dict[str, float], dict[str, str]]:
    """The named outputs of a TeamProduct (final values, guidance event results) and their units."""
    sig_t = None if product.true is None else product.true.sigma[-1]
    cov = [n for n in names if guidance_output(n) is None]
    vals, units = outputs_from(product.assumed.sigma[-1], sig_t, list(product.labels), list(product.units), cov)
    gv, gu = guidance_outputs(product.guidance, [n for n in names if guidance_output(n) is not None])
    vals.update(gv)
    units.update(gu)
    return {n: vals[n] for n in names}, {n: units[n] for n in names}


def guidance_outputs(events: Any, names: list[str]) -> tuple[dict[str, float], dict[str, str]]:
    """The named guidance outputs (``NAME.dv_mean_m_s``, ...; :func:`fracas.config.sweep.guidance_output`)
    of a study's guidance events (:class:`fracas.products.GuidanceEvent`): (values, units)."""
    by_name = {e.name: e for e in (events or [])}
    vals: dict[str, float] = {}
    units: dict[str, str] = {}
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


def outputs_from(
    sig_a: Any, sig_t: Any, labels: list[str], units: list[str], names: list[str]
) -> tuple[dict[str, float], dict[str, str]]:
    """The named outputs from the final 1σ vectors (assumed, true or None) of a study whose
    covariance rows are ``labels`` (in ``units``): (values, units)."""
    vals: dict[str, float] = {}
    out_units: dict[str, str] = {}
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


def one_line(exc: BaseException) -> str:
    """``exc`` as one line (a FracasError's text; any other error with its type's name)."""
    if isinstance(exc, FracasError):
        text = str(exc)
    else:
        text = f"{type(exc).__name__}: {exc}"
    return " ".join(text.split())


def study_row(index: int, key: str, fields: tuple[str, ...], values: tuple, outputs: list[str]) -> dict[str, Any]:
    """The row a study starts as: its index, key and varied values, NaN outputs."""
    row: dict[str, Any] = {"index": int(index), "key": key}
    row.update({f: plain(v) for f, v in zip(fields, values)})
    row.update(dict.fromkeys(outputs, float("nan")))
    return row


# ----------------------------------------------------------------------------- the rows already in a table
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
        row.update({name: plain(col[k]) for name, col in cols.items()})
        row.update(status=status[k], error=error[k], wall_s=float(wall[k]))
        rows.append(row)
    return rows, units


def resumed_rows(
    path: Path, base_hash: str, fields: tuple[str, ...], outputs: list[str], keys: list[str], units: dict[str, str]
) -> dict[int, dict[str, Any]]:
    """Study index -> its row from the table at ``path`` (:func:`resume_table`), for the
    studies (``keys``) that table has with status "ok"; ``units`` takes the table's units of
    the outputs."""
    rows: dict[int, dict[str, Any]] = {}
    old_rows, old_units = resume_table(path, base_hash, fields, outputs)
    by_key = {r["key"]: r for r in old_rows if r["status"] == "ok"}
    units.update({k: v for k, v in old_units.items() if k in outputs})
    for i, k in enumerate(keys):
        if k in by_key:
            rows[i] = dict(by_key[k], index=i)
    return rows
