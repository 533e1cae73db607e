"""TSIM results file and TSIM checkpoint file (HDF5, atomic).

Serialises a :class:`fracas.products.TsimProduct` and reads it back for reports and for
a-priori merging (:func:`tsim_statistics`); no numerics.  The checkpoint file holds the
per-mission arrays of the completed blocks of a run so that a killed run can resume.

Results layout (every dataset carries ``units`` and ``data_sha256``)::

    /                         file_kind = "fracas-tsim-results", schema_version, provenance
    /tsim                     attrs: title, source, epoch_et_s (s past J2000, TDB), n_state,
                              kind = "fracas-tsim-results", version (= schema_version)
      labels (n,)             the augmented state (r, v, m, then parameters)
      counts                  JSON text: missions, ok, near, hopeless, failed, a_priori
      settings, timing,       JSON text: the run's settings (seed, first_mission, missions,
      provenance_extra          scale, sampling, grid step, block, workers), timings (s), and
                                the provenance items /provenance cannot hold as attributes
      consistency             JSON text: a list of rows, one per compared output, each with
                              output, names, units, count, ratio (per axis, sigma_TSIM /
                              sigma_TEAM), se, chi2, dof, p_value, mean_chi2, mean_p_value,
                              coverage ([k, observed, expected, se] per k), verdict
                              ("consistent" | "nonlinear" | "biased" | "not compared"), message
      missions/<field>        attr fields (the field names, in order); the per-mission
                              table, mission axis first (N missions, J
                              maneuvers, n = len(labels), M_max controls, m final targets):
        mission (N,)                 int, mission index
        status (N,)                  int, 0 ok, 1 near success, 2 hopeless maneuver,
                                     3 integration failed
        failed_maneuver (N,)         int, index of the maneuver that ended it (-1: none)
        iterations (N, J)            int, guidance iterations per maneuver
        initial_deviation (N, n)     labels' units (km, km/s, kg, parameters)
        state_deviation (N, J, 7)    true state deviation at each maneuver (km, km/s, kg)
        knowledge_error (N, J, n)    navigation knowledge error at each maneuver (labels' units)
        correction (N, J, M_max)     commanded correction (each maneuver's control units)
        execution_error (N, J, M_max) execution error (each maneuver's control units)
        dv_km_s (N, J)               |dV| of each maneuver (km/s)
        dv_total_km_s (N,)           total |dV| (km/s)
        target_error (N, m)          final target error (final target units)
        maneuver_status (N, J)       per maneuver: 0 ok, 1 near success, 2 hopeless
        linear_design_miss (N, J, m_max)  impulsive: the linear design's miss on the estimated
                             trajectory (its target units)
        design_miss (N, J, m_max)  impulsive: the flown design's miss there
        final_mass_kg (N,)           kg
                              (any further field is stored the same way, units "1")
      maneuvers/<j>_<name>    one group per maneuver j (0, 1, ...):
        name, type, law       text ("impulsive" | "primary" | "vernier"; "linear" | "nonlinear")
        time_s, target_time_s (s); control_labels, control_units, target_names, target_units
        team_correction_cov (M, M)   TEAM's covariance of the commanded correction
        team_dv_mean_km_s, team_dv_99_km_s   TEAM's exact mean and 99 % |dV| (km/s)
        team_target_cov_after (m, m) TEAM's target dispersion after the event, at the target
                             time (the process noise from the cutoff on included)
        failures, near        int: missions it ended (hopeless), near successes
      statistics/<name>       attrs name (exact), order, count (int); mean (p,), covariance (p, p)
      percentiles/<name>      attrs name (exact), order; q (k,) (percent), value (k,)
      final/target_names, target_units, time_s (s), team_target_cov (m, m) (the last
                              maneuver's team_target_cov_after: what the final errors are judged by)

(the checkpoint file, :mod:`fracas.io.tsim_checkpoint`, is re-exported here; a "/" in a name
becomes "|" in a group's key; the exact name is the group's ``name`` attr)
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from fracas.errors import ResultsFileError
from fracas.io.hdf5 import (
    Checked,
    atomic_h5,
    attr_int,
    attr_strs,
    attr_text,
    one_line,
    open_h5,
    read_provenance,
    set_attr,
    write,
    write_provenance,
    write_strings,
)
from fracas.io.tsim_checkpoint import read_tsim_checkpoint, write_tsim_checkpoint
from fracas.io.tsim_schema import _FIELDS, _KIND, CHECKPOINT_SCHEMA, TSIM_SCHEMA, VERDICTS, _group, _json, _open_checked
from fracas.products import TsimManeuver, TsimProduct

__all__ = [
    "write_tsim_results",
    "read_tsim_results",
    "tsim_statistics",
    "write_tsim_checkpoint",
    "read_tsim_checkpoint",
    "TSIM_SCHEMA",
    "CHECKPOINT_SCHEMA",
]


def _key(name: str) -> str:
    return str(name).replace("/", "|") or "_"


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.floating):
        return float(x)
    if isinstance(x, Path):
        return str(x)
    return x


def _dumps(x: Any) -> str:
    return json.dumps(_jsonable(x), default=str)


def _simple(val: Any) -> bool:
    return isinstance(val, (str, bool, int, float, np.integer, np.floating)) and not isinstance(val, bytes)


# --------------------------------------------------------------------------- writing


def _provenance_parts(prov: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(the items /provenance holds as attributes, the rest: JSON text in tsim/provenance_extra)."""
    std = {
        k: v
        for k, v in prov.items()
        if (k == "deck_text" and isinstance(v, str))
        or (k == "libraries" and isinstance(v, dict) and all(isinstance(x, str) for x in v.values()))
        or (k not in ("deck_text", "libraries") and _simple(v))
    }
    extra = {k: v for k, v in prov.items() if k not in std}
    return std, extra


def _write_table(g: h5py.Group, product: TsimProduct) -> None:
    """tsim/missions: the per-mission table, one dataset per field."""
    t = g.create_group("missions")
    set_attr(t, "fields", [str(k) for k in product.table])
    for name, arr in product.table.items():
        units, _, desc = _FIELDS.get(name, ("1", False, ""))
        a = np.asarray(arr)
        if a.dtype.kind not in "iu":
            a = a.astype(np.float64)
        extra_attrs = {"description": desc} if desc else {}
        write(t, name, a, units, **extra_attrs)


def _write_maneuvers(g: h5py.Group, maneuvers: list[TsimManeuver]) -> None:
    """tsim/maneuvers/<j>_<name>: one group per maneuver."""
    mg = g.create_group("maneuvers")
    for j, m in enumerate(maneuvers):
        h = mg.create_group(f"{j}_{_key(m.name)}")
        h.attrs["index"] = j
        write(h, "name", str(m.name), "none")
        write(h, "type", str(m.type), "none")
        write(h, "law", str(m.law), "none")
        write(h, "time_s", np.float64(m.time_s), "s")
        write(h, "target_time_s", np.float64(m.target_time_s), "s")
        write_strings(h, "control_labels", m.control_labels)
        write_strings(h, "control_units", m.control_units)
        write_strings(h, "target_names", m.target_names)
        write_strings(h, "target_units", m.target_units)
        mc = len(m.control_labels)
        write(h, "team_correction_cov", np.asarray(m.team_correction_cov, float).reshape(mc, mc), "control units^2")
        write(h, "team_dv_mean_km_s", np.float64(m.team_dv_mean_km_s), "km/s")
        write(h, "team_dv_99_km_s", np.float64(m.team_dv_99_km_s), "km/s")
        mt = len(m.target_names)
        write(h, "team_target_cov_after", np.asarray(m.team_target_cov_after, float).reshape(mt, mt), "target units^2")
        write(h, "failures", np.int64(m.failures), "1", description="missions it ended (hopeless)")
        write(h, "near", np.int64(m.near), "1", description="designs accepted as near successes")


def _write_statistics(g: h5py.Group, product: TsimProduct) -> None:
    """tsim/statistics and tsim/percentiles: one group per output, in order."""
    sg = g.create_group("statistics")
    for i, (name, (count, mean, cov)) in enumerate(product.statistics.items()):
        h = sg.create_group(_key(name))
        h.attrs["name"] = str(name)
        h.attrs["order"] = i
        h.attrs["count"] = int(count)
        mean = np.atleast_1d(np.asarray(mean, float))
        write(h, "mean", mean, "output units")
        write(h, "covariance", np.asarray(cov, float).reshape(mean.size, mean.size), "output units^2")
    pg = g.create_group("percentiles")
    for i, (name, table) in enumerate(product.percentiles.items()):
        h = pg.create_group(_key(name))
        h.attrs["name"] = str(name)
        h.attrs["order"] = i
        write(h, "q", np.asarray([float(q) for q in table], float), "percent")
        write(h, "value", np.asarray([float(v) for v in table.values()], float), "output units")


def write_tsim_results(path: str | os.PathLike, product: TsimProduct) -> Path:
    """Write ``product`` to ``path`` atomically (a crash leaves any old file intact)."""
    p = Path(path)
    std, extra = _provenance_parts(dict(product.provenance))
    with atomic_h5(p) as f:
        f.attrs["file_kind"] = _KIND
        f.attrs["schema_version"] = TSIM_SCHEMA
        write_provenance(f, std)
        g = f.create_group("tsim")
        g.attrs["title"] = str(product.title)
        g.attrs["source"] = str(product.source)
        g.attrs["epoch_et_s"] = float(product.epoch_et_s)
        g.attrs["n_state"] = int(product.n_state)
        g.attrs["kind"] = _KIND
        g.attrs["version"] = TSIM_SCHEMA
        write_strings(g, "labels", product.labels)
        write(g, "counts", _dumps({k: int(v) for k, v in product.counts.items()}), "none")
        write(g, "settings", _dumps(product.settings), "none")
        write(g, "timing", _dumps(product.timing), "none", description="seconds")
        write(g, "provenance_extra", _dumps(extra), "none")
        write(g, "consistency", _dumps(list(product.consistency)), "none", description="JSON list of rows")
        _write_table(g, product)
        _write_maneuvers(g, product.maneuvers)
        _write_statistics(g, product)
        fg = g.create_group("final")
        write_strings(fg, "target_names", product.final_target_names)
        write_strings(fg, "target_units", product.final_target_units)
        write(fg, "time_s", np.float64(product.final_target_time_s), "s")
        m = len(product.final_target_names)
        write(fg, "team_target_cov", np.asarray(product.team_target_cov, float).reshape(m, m), "target units^2")
    return p


# --------------------------------------------------------------------------- reading


def _ordered(c: Checked, group: str) -> list[tuple[str, str]]:
    """(exact name, dataset path prefix) of the subgroups of ``group`` in their written order."""
    g = _group(c, group)
    rows = []
    for key in g:
        h = g[key]
        where = f"{group}/{key}"
        if not isinstance(h, h5py.Group):
            raise c.fail(where, "is a dataset, expected a group")
        name = attr_text(h, "name")
        if name is None:
            raise c.fail(where, "no text attribute 'name', expected the exact name")
        order = attr_int(h, "order", c.fail(where, "attribute 'order' is not an integer, expected one"))
        rows.append((order if order is not None else 0, name, where))
    rows.sort(key=lambda r: r[0])
    return [(name, where) for _, name, where in rows]


def _count(c: Checked, where: str) -> int:
    h = c.f[where]
    val = attr_int(h, "count", c.fail(where, "attribute 'count' is not an integer, expected the sample count"))
    if val is None or val < 0:
        raise c.fail(where, f"attribute 'count' = {h.attrs.get('count')!r}, expected a count >= 0")
    return val


def _statistics(c: Checked) -> dict[str, tuple[int, np.ndarray, np.ndarray]]:
    out = {}
    for name, where in _ordered(c, "tsim/statistics"):
        count = _count(c, where)
        mean = c.num(f"{where}/mean", (None,))
        cov = c.num(f"{where}/covariance", (mean.shape[0], mean.shape[0]))
        out[name] = (count, mean, cov)
    return out


def _counts(c: Checked) -> dict[str, int]:
    raw = _json(c, "tsim/counts", dict)
    for k, v in raw.items():
        if isinstance(v, bool) or not isinstance(v, int):
            raise c.fail("tsim/counts", f"{k} = {v!r}, expected an integer count")
    return raw


def _consistency(c: Checked) -> list[dict[str, Any]]:
    rows = _json(c, "tsim/consistency", list)
    for i, row in enumerate(rows):
        if not isinstance(row, dict):
            raise c.fail("tsim/consistency", f"row {i} is a JSON {type(row).__name__}, expected an object")
        for key in ("output", "verdict", "message"):
            if not isinstance(row.get(key), str):
                raise c.fail("tsim/consistency", f"row {i}: {key} = {row.get(key)!r}, expected a string")
        if row["verdict"] not in VERDICTS:
            raise c.fail("tsim/consistency", f"row {i}: verdict {row['verdict']!r}, expected one of {VERDICTS}")
    return rows


def _maneuvers(c: Checked) -> list[TsimManeuver]:
    g = _group(c, "tsim/maneuvers")
    keyed = []
    for key in g:
        head = key.split("_", 1)[0]
        if not head.isdigit():
            raise c.fail(
                f"tsim/maneuvers/{key}", "group name does not start with '<index>_', expected '<index>_<name>'"
            )
        keyed.append((int(head), key))
    keyed.sort()
    if [j for j, _ in keyed] != list(range(len(keyed))):
        raise c.fail("tsim/maneuvers", f"indices {[j for j, _ in keyed]}, expected 0..{len(keyed) - 1}")
    out = []
    for _, key in keyed:
        w = f"tsim/maneuvers/{key}"
        labels = c.strs(f"{w}/control_labels")
        mc = len(labels)
        names = c.strs(f"{w}/target_names")
        mt = len(names)
        out.append(
            TsimManeuver(
                name=c.text(f"{w}/name"),
                type=c.text(f"{w}/type"),
                law=c.text(f"{w}/law"),
                time_s=c.scalar(f"{w}/time_s"),
                control_labels=labels,
                control_units=c.strs(f"{w}/control_units", mc),
                target_names=names,
                target_units=c.strs(f"{w}/target_units", mt),
                target_time_s=c.scalar(f"{w}/target_time_s"),
                team_correction_cov=c.num(f"{w}/team_correction_cov", (mc, mc)),
                team_dv_mean_km_s=c.scalar(f"{w}/team_dv_mean_km_s", finite=False),
                team_dv_99_km_s=c.scalar(f"{w}/team_dv_99_km_s", finite=False),
                team_target_cov_after=c.num(f"{w}/team_target_cov_after", (mt, mt)),
                failures=c.scalar(f"{w}/failures", integer=True),
                near=c.scalar(f"{w}/near", integer=True),
            )
        )
    return out


def _table(c: Checked, j: int, n: int, m: int) -> dict[str, np.ndarray]:
    g = _group(c, "tsim/missions")
    if "fields" not in g.attrs:
        raise c.fail("tsim/missions", "no attribute 'fields', expected the list of the table's fields")
    fields = attr_strs(g, "fields") if g.attrs["fields"].size else []
    for req in ["mission", "status"] + [k for k in fields if k not in ("mission", "status")]:
        if req not in g:
            raise c.fail(f"tsim/missions/{req}", "missing, expected a dataset (incomplete file?)")
    nm = c.num("tsim/missions/mission", (None,), integer=True).shape[0]
    known = {
        "mission": (nm,),
        "status": (nm,),
        "failed_maneuver": (nm,),
        "iterations": (nm, j),
        "initial_deviation": (nm, n),
        "state_deviation": (nm, j, 7),
        "knowledge_error": (nm, j, n),
        "correction": (nm, j, None),
        "execution_error": (nm, j, None),
        "dv_km_s": (nm, j),
        "dv_total_km_s": (nm,),
        "target_error": (nm, m),
        "maneuver_status": (nm, j),
        "linear_design_miss": (nm, j, None),
        "design_miss": (nm, j, None),
        "final_mass_kg": (nm,),
    }
    out = {}
    for key in fields + sorted(k for k in g if k not in fields):
        where = f"tsim/missions/{key}"
        ds = c.dataset(where)
        if key in _FIELDS:
            integer = _FIELDS[key][1]
            shape = known[key]
        else:
            integer = ds.dtype.kind in "iu"
            shape = (nm,) + (None,) * max(ds.ndim - 1, 0)
            if ds.ndim == 0:
                raise c.fail(where, "a scalar, expected a mission axis first")
        out[key] = c.num(where, shape, integer=integer)
    return out


def read_tsim_results(path: str | os.PathLike, *, verify: bool = True) -> TsimProduct:
    """The :class:`TsimProduct` stored in a TSIM results file; a one-line ResultsFileError
    naming the file and the dataset for a missing or damaged file."""
    p = Path(path)
    try:
        with open_h5(p, ResultsFileError, "TSIM results file", checksum=verify) as f:
            c = _open_checked(p, f, _KIND, TSIM_SCHEMA, "TSIM results file", verify)
            g = _group(c, "tsim")
            attrs = {}
            for key in ("title", "source"):
                val = attr_text(g, key)
                if val is None:
                    raise c.fail("tsim", f"no text attribute {key!r}, expected one")
                attrs[key] = val
            try:
                epoch = float(g.attrs["epoch_et_s"])
            except (KeyError, TypeError, ValueError):
                raise c.fail("tsim", "attribute 'epoch_et_s' missing or not a number, expected seconds") from None
            n_state = attr_int(g, "n_state", c.fail("tsim", "attribute 'n_state' is not an integer, expected one"))
            if n_state is None:
                raise c.fail("tsim", "no attribute 'n_state', expected an integer")
            labels = c.strs("tsim/labels")
            names = c.strs("tsim/final/target_names")
            m = len(names)
            maneuvers = _maneuvers(c)
            table = _table(c, len(maneuvers), len(labels), m)
            percentiles = {}
            for name, where in _ordered(c, "tsim/percentiles"):
                q = c.num(f"{where}/q", (None,))
                v = c.num(f"{where}/value", (q.shape[0],))
                percentiles[name] = {float(a): float(b) for a, b in zip(q, v)}
            prov = read_provenance(f)
            prov.update(_json(c, "tsim/provenance_extra", dict))
            return TsimProduct(
                title=attrs["title"],
                source=attrs["source"],
                epoch_et_s=epoch,
                labels=labels,
                n_state=n_state,
                maneuvers=maneuvers,
                final_target_names=names,
                final_target_units=c.strs("tsim/final/target_units", m),
                final_target_time_s=c.scalar("tsim/final/time_s"),
                team_target_cov=c.num("tsim/final/team_target_cov", (m, m)),
                table=table,
                statistics=_statistics(c),
                percentiles=percentiles,
                consistency=_consistency(c),
                counts=_counts(c),
                settings=_json(c, "tsim/settings", dict),
                timing=_json(c, "tsim/timing", dict),
                provenance=prov,
            )
    except OSError as exc:
        raise ResultsFileError(f"{p}: cannot read as HDF5 ({one_line(exc)}), expected a TSIM results file") from None


def tsim_statistics(path: str | os.PathLike, *, verify: bool = True) -> tuple[int, dict]:
    """Only the statistics of an earlier TSIM results file (for a-priori merging):
    (the number of successful missions they cover -- ok + near + a_priori of its counts --,
    name -> (count, mean, covariance)).  See :func:`tsim_settings` for the run they came from."""
    p = Path(path)
    try:
        with open_h5(p, ResultsFileError, "TSIM results file", checksum=verify) as f:
            c = _open_checked(p, f, _KIND, TSIM_SCHEMA, "TSIM results file", verify)
            counts = _counts(c)
            ok = sum(int(counts.get(k, 0)) for k in ("ok", "near", "a_priori"))
            return ok, _statistics(c)
    except OSError as exc:
        raise ResultsFileError(f"{p}: cannot read as HDF5 ({one_line(exc)}), expected a TSIM results file") from None


def tsim_settings(path: str | os.PathLike, *, verify: bool = True) -> dict:
    """The settings of an earlier TSIM run (seed, first_mission, missions, ...) from its results file."""
    p = Path(path)
    try:
        with open_h5(p, ResultsFileError, "TSIM results file", checksum=verify) as f:
            c = _open_checked(p, f, _KIND, TSIM_SCHEMA, "TSIM results file", verify)
            return _json(c, "tsim/settings", dict)
    except OSError as exc:
        raise ResultsFileError(f"{p}: cannot read as HDF5 ({one_line(exc)}), expected a TSIM results file") from None
