"""The sweep table: one row per study (inputs, outputs, status, error, wall time), as HDF5
and as CSV for spreadsheets; both written atomically.  Layout: docs/sweep.md.

HDF5: root attributes ``kind = "fracas sweep table"``, ``version``, ``title``,
``base_hash``, ``study``, ``combine``, ``input_columns``, ``output_columns``; datasets
(N,) ``index`` (int), ``key`` (str), ``status`` (str: "ok" | "failed"), ``error`` (str),
``wall_s`` (s); groups ``inputs/<field>`` and ``outputs/<name>``, each with ``units``.
Numeric inputs are float64, others strings.
"""

from __future__ import annotations

import csv
import io
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from fracas.errors import ResultsFileError
from fracas.io.atomic import atomic_path
from fracas.io.hdf5 import (
    Checked,
    atomic_h5,
    attr_int,
    attr_strs,
    attr_text,
    one_line,
    open_h5,
    set_attr,
    write,
    write_strings,
)

__all__ = ["SweepTable", "write_sweep_table", "read_sweep_table", "csv_path", "KIND", "VERSION"]

KIND = "fracas sweep table"
VERSION = 1


@dataclass
class SweepTable:
    """The rows of a sweep, column-wise.  ``inputs`` / ``outputs``: name -> (N,) array (inputs
    float64 or object strings); ``units``: column name -> unit; ``attrs``: title, base_hash,
    study, combine."""

    index: np.ndarray
    key: list[str]
    inputs: dict[str, np.ndarray]
    outputs: dict[str, np.ndarray]
    status: list[str]
    error: list[str]
    wall_s: np.ndarray
    units: dict[str, str] = field(default_factory=dict)
    attrs: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.key)

    def rows(self) -> list[dict[str, Any]]:
        """Each row as a dict: index, key, the inputs, the outputs, status, error, wall_s."""
        out = []
        for i in range(len(self)):
            row: dict[str, Any] = {"index": int(self.index[i]), "key": self.key[i]}
            row.update({k: _py(v[i]) for k, v in self.inputs.items()})
            row.update({k: float(v[i]) for k, v in self.outputs.items()})
            row.update(status=self.status[i], error=self.error[i], wall_s=float(self.wall_s[i]))
            out.append(row)
        return out


def _py(x: Any) -> Any:
    return x.item() if isinstance(x, np.generic) else x


def _input_array(vals: list[Any]) -> np.ndarray:
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
        return np.asarray(vals, dtype=np.float64)
    return np.array([str(v) for v in vals], dtype=object)


def csv_path(path: str | os.PathLike) -> Path:
    """The CSV twin of a table file: same name, ``.csv``."""
    return Path(path).with_suffix(".csv")


def write_sweep_table(
    path: str | os.PathLike,
    rows: list[dict[str, Any]],
    inputs: list[str],
    outputs: list[str],
    units: dict[str, str],
    attrs: dict[str, Any],
    csv: bool = True,
) -> Path:
    """Write ``rows`` (dicts with index, key, each input and output, status, error, wall_s),
    sorted by index, to the HDF5 table ``path`` and (``csv``) its CSV twin.  Returns the path."""
    rows = sorted(rows, key=lambda r: r["index"])
    with atomic_h5(path) as f:
        set_attr(f, "kind", KIND)
        f.attrs["version"] = VERSION
        for k, v in attrs.items():
            set_attr(f, k, v)
        set_attr(f, "input_columns", list(inputs))
        set_attr(f, "output_columns", list(outputs))
        write(f, "index", np.asarray([r["index"] for r in rows], dtype=np.int64), "1")
        write_strings(f, "key", [r["key"] for r in rows])
        write_strings(f, "status", [r["status"] for r in rows])
        write_strings(f, "error", [r["error"] for r in rows])
        write(f, "wall_s", np.asarray([r["wall_s"] for r in rows], dtype=np.float64), "s")
        gi, go = f.create_group("inputs"), f.create_group("outputs")
        for name in inputs:
            arr = _input_array([r[name] for r in rows])
            if arr.dtype == object:
                write_strings(gi, name, list(arr), units.get(name, "none"))
            else:
                write(gi, name, arr, units.get(name, "none"))
        for name in outputs:
            write(go, name, np.asarray([r[name] for r in rows], dtype=np.float64), units.get(name, "none"))
    if csv:
        _write_csv(csv_path(path), rows, inputs, outputs, units)
    return Path(path)


def _write_csv(path: Path, rows, inputs, outputs, units) -> None:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    head = lambda n: f"{n} [{units[n]}]" if units.get(n, "none") not in ("none", "") else n  # noqa: E731
    w.writerow(["index", "key", *map(head, inputs), *map(head, outputs), "status", "error", "wall_s [s]"])
    for r in rows:
        w.writerow(
            [r["index"], r["key"], *(r[n] for n in inputs), *(repr(float(r[n])) for n in outputs)]
            + [r["status"], r["error"], f"{r['wall_s']:.3f}"]
        )
    with atomic_path(path) as tmp:
        tmp.write_text(buf.getvalue(), encoding="utf-8")


def read_sweep_table(path: str | os.PathLike) -> SweepTable:
    """Read a table written by :func:`write_sweep_table` through the checked reader that
    ``--resume`` uses (:class:`fracas.io.hdf5.Checked`: the integrity header, then the dtype,
    shape and SHA-256 of every dataset); a one-line ResultsFileError if it is missing,
    damaged, unreadable, not a sweep table, incomplete, or holds rows that are not a sweep's
    (a status other than ok/failed, a repeated index)."""
    p = Path(path)
    try:
        with open_h5(p, ResultsFileError, "sweep table") as f:
            table = _read_checked(f, p)
    except ResultsFileError:
        raise
    except Exception as exc:  # noqa: BLE001 - whatever a damaged file makes h5py or numpy raise
        raise ResultsFileError(f"{p}: cannot read the sweep table ({type(exc).__name__}: {one_line(exc)})") from None
    _check_rows(table, p)
    return table


def _read_checked(f: Any, p: Path) -> SweepTable:
    kind = attr_text(f, "kind")
    if kind != KIND:
        raise ResultsFileError(f"{p}: not a fracas sweep table (kind = {kind!r}, expected {KIND!r})")
    version = attr_int(f, "version")
    if version is None or not 1 <= version <= VERSION:
        raise ResultsFileError(
            f"{p}: sweep table version = {version if version is not None else f.attrs.get('version')!r}, "
            f"this fracas reads 1 to {VERSION}"
        )
    c = Checked(f, str(p), ResultsFileError)
    ins, outs = attr_strs(f, "input_columns"), attr_strs(f, "output_columns")
    index = c.num("index", (None,), integer=True)
    n = int(index.shape[0])
    units: dict[str, str] = {}
    inputs: dict[str, np.ndarray] = {}
    for name in ins:
        ds = c.dataset(f"inputs/{name}")
        strings = h5py.check_string_dtype(ds.dtype) is not None
        inputs[name] = np.array(c.strs(ds.name, n), dtype=object) if strings else c.num(ds.name, (n,))
        units[name] = attr_text(ds, "units") or "none"
    outputs = {}
    for name in outs:
        outputs[name] = c.num(f"outputs/{name}", (n,))
        units[name] = attr_text(f[f"outputs/{name}"], "units") or "none"
    attrs = {}
    for k in ("title", "base_hash", "study", "combine"):
        if k in f.attrs:
            v = f.attrs[k]
            attrs[k] = v.decode() if isinstance(v, bytes) else v
    return SweepTable(
        index=index,
        key=c.strs("key", n),
        inputs=inputs,
        outputs=outputs,
        status=c.strs("status", n),
        error=c.strs("error", n),
        wall_s=c.num("wall_s", (n,)),
        units=units,
        attrs=attrs,
    )


def _check_rows(t: SweepTable, p: Path) -> None:
    """Rows a sweep writes: status ok or failed, distinct indices."""
    n = len(t)
    bad = next((k for k, s in enumerate(t.status) if s not in ("ok", "failed")), None)
    if bad is not None or len(set(t.index.tolist())) != n:
        row = bad if bad is not None else n - 1
        raise ResultsFileError(
            f"{p}: row {row}: status {t.status[row]!r} or a repeated index: expected a sweep's rows "
            "(ok/failed, distinct indices)"
        )
