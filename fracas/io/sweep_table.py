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

import numpy as np

from fracas.errors import ResultsFileError
from fracas.io.atomic import atomic_path
from fracas.io.hdf5 import atomic_h5, attr_int, attr_strs, one_line, open_h5, read_str, set_attr, write, write_strings

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
    """Read a table written by :func:`write_sweep_table`; a one-line ResultsFileError if it
    is missing, damaged (integrity header, :func:`fracas.io.hdf5.verify_file`), unreadable,
    not a sweep table or incomplete."""
    p = Path(path)
    try:
        with open_h5(p, ResultsFileError, "sweep table") as f:
            kind = f.attrs.get("kind")
            kind = kind.decode() if isinstance(kind, bytes) else kind
            if kind != KIND:
                raise ResultsFileError(f"{p}: not a fracas sweep table (kind = {kind!r}, expected {KIND!r})")
            version = attr_int(f, "version")
            if version is None or not 1 <= version <= VERSION:
                raise ResultsFileError(
                    f"{p}: sweep table version = {version if version is not None else f.attrs.get('version')!r}, "
                    f"this fracas reads 1 to {VERSION}"
                )
            ins, outs = attr_strs(f, "input_columns"), attr_strs(f, "output_columns")
            units: dict[str, str] = {}
            inputs: dict[str, np.ndarray] = {}
            for n in ins:
                ds = f["inputs"][n]
                inputs[n] = np.array(read_str(ds), dtype=object) if ds.dtype.kind in "OS" else ds[()]
                units[n] = ds.attrs["units"]
            outputs = {}
            for n in outs:
                outputs[n] = f["outputs"][n][()]
                units[n] = f["outputs"][n].attrs["units"]
            attrs = {}
            for k in ("title", "base_hash", "study", "combine"):
                if k in f.attrs:
                    v = f.attrs[k]
                    attrs[k] = v.decode() if isinstance(v, bytes) else (str(v) if isinstance(v, str) else v)
            n = f["index"].shape[0]
            strs = lambda name: read_str(f[name]) if n else []  # noqa: E731
            return SweepTable(
                index=f["index"][()],
                key=list(strs("key")),
                inputs=inputs,
                outputs=outputs,
                status=list(strs("status")),
                error=list(strs("error")),
                wall_s=f["wall_s"][()],
                units={k: (v.decode() if isinstance(v, bytes) else str(v)) for k, v in units.items()},
                attrs=attrs,
            )
    except (OSError, KeyError) as exc:
        raise ResultsFileError(f"{p}: cannot read the sweep table ({type(exc).__name__}: {one_line(exc)})") from None
