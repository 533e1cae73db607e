"""What the TSIM results file and the TSIM checkpoint file share (:mod:`fracas.io.tsim_results`,
:mod:`fracas.io.tsim_checkpoint`): schema versions, kind tags, the per-mission fields with
their units, and the checks a reader makes on opening either file.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import h5py

from fracas.errors import ResultsFileError
from fracas.io.hdf5 import Checked, attr_int, attr_text

TSIM_SCHEMA = 1
CHECKPOINT_SCHEMA = 1
_KIND = "fracas-tsim-results"
_CKPT_KIND = "fracas-tsim-checkpoint"
VERDICTS = ("consistent", "nonlinear", "biased", "not compared")

#: per-mission field -> (units, integer, description)
_FIELDS: dict[str, tuple[str, bool, str]] = {
    "mission": ("1", True, "mission index"),
    "status": ("1", True, "0 ok, 1 near success, 2 hopeless maneuver, 3 integration failed"),
    "failed_maneuver": ("1", True, "index of the maneuver that ended the mission (-1: none)"),
    "iterations": ("1", True, "guidance iterations per maneuver"),
    "initial_deviation": ("labels", False, "initial augmented-state deviation (units of /tsim/labels)"),
    "state_deviation": ("km, km/s, kg", False, "true state deviation (r, v, m) at each maneuver"),
    "knowledge_error": ("labels", False, "knowledge error at each maneuver (units of /tsim/labels)"),
    "correction": ("control units", False, "commanded correction per maneuver (its control units)"),
    "execution_error": ("control units", False, "execution error per maneuver (its control units)"),
    "dv_km_s": ("km/s", False, "|dV| of each maneuver"),
    "dv_total_km_s": ("km/s", False, "total |dV|"),
    "target_error": ("final target units", False, "final target error"),
    "maneuver_status": ("1", True, "per maneuver: 0 ok, 1 near success, 2 hopeless"),
    "linear_design_miss": ("target units", False, "impulsive: the linear design's miss on the estimated trajectory"),
    "design_miss": ("target units", False, "impulsive: the flown design's miss on the estimated trajectory"),
    "final_mass_kg": ("kg", False, "final mass"),
}


def _open_checked(p: Path, f: h5py.File, kind: str, schema: int, what: str, verify: bool) -> Checked:
    got = attr_text(f, "file_kind")
    if got != kind:
        raise ResultsFileError(
            f"{p}: not a fracas {what} (file_kind = {f.attrs.get('file_kind')!r}, expected {kind!r})"
        )
    version = attr_int(f, "schema_version")
    if version is None or version < 1 or version > schema:
        shown = version if version is not None else repr(f.attrs.get("schema_version"))
        raise ResultsFileError(f"{p}: schema_version = {shown}, this fracas reads 1 to {schema}")
    return Checked(f, p, ResultsFileError, verify=verify)


def _group(c: Checked, name: str) -> h5py.Group:
    if name not in c.f or not isinstance(c.f[name], h5py.Group):
        raise c.fail(name, "missing, expected a group (incomplete file?)")
    return c.f[name]


def _json(c: Checked, name: str, kind: type) -> Any:
    text = c.text(name)
    try:
        val = json.loads(text)
    except ValueError as exc:
        raise c.fail(name, f"not valid JSON ({exc}), expected JSON text") from None
    if not isinstance(val, kind):
        raise c.fail(name, f"JSON {type(val).__name__}, expected a JSON {'object' if kind is dict else 'list'}")
    return val
