"""Reading a TEAM results file and a punch file (``docs/team_results.md``): every dataset
checked (dtype, shapes consistent with the schedule and the labels, finiteness where it
matters) and, in schema-2 files, its SHA-256 checksum.  No numerics here.

Re-exported by :mod:`fracas.io.team_results`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from fracas.errors import DeckError, ResultsFileError
from fracas.io.hdf5 import Checked, attr_text, one_line, open_h5, schema_version
from fracas.io.inputs import note_input
from fracas.io.team_layout import (
    _GUIDANCE_MATRICES,
    _GUIDANCE_OPTIONAL,
    _GUIDANCE_SCALARS,
    _MEASUREMENT_FIELDS,
    _TEAM_GROUPS,
    PUNCH_SCHEMA,
    RESULTS_SCHEMA,
)


def _read_guidance(c: Checked, g: h5py.Group, n: int) -> list[dict[str, Any]]:
    out = []
    for name in sorted(g["guidance"]):
        q = g["guidance"][name]
        base = f"team/guidance/{name}"
        d: dict[str, Any] = {k: str(q.attrs[k]) for k in ("name", "type", "target_body", "estimate_model")}
        d.update(index=int(q.attrs["index"]), rank=int(q.attrs["rank"]), status=int(q.attrs.get("status", 0)))
        for k in ("time_s", "cutoff_s", "target_time_s"):
            d[k] = c.scalar(f"{base}/{k}")
        for k in ("target_names", "target_units", "control_labels", "control_units"):
            d[k] = c.strs(f"{base}/{k}")
        m, mc = len(d["target_names"]), len(d["control_labels"])
        shapes = {
            "psi": (m, n),
            "gamma": (mc, n),
            "target_cov_before": (m, m),
            "target_cov_after": (m, m),
            "target_cov_knowledge": (m, m),
            "target_noise_cov": (m, m),
            "correction_cov": (mc, mc),
            "execution_cov": (mc, mc),
        }
        for k, _, _ in _GUIDANCE_MATRICES:
            if k in _GUIDANCE_OPTIONAL and f"{base}/{k}" not in c.f:
                d[k] = None  # an older file: its before/after lack the noise after the cutoff
                continue
            d[k] = c.num(f"{base}/{k}", shapes[k])
        for k in _GUIDANCE_SCALARS:
            d[k] = c.scalar(f"{base}/{k}", finite=False)
        out.append(d)
    return out


def _history(c: Checked, base: str, n: int, m: int, nx: int) -> dict[str, Any]:
    out: dict[str, Any] = {}
    shapes = {
        "P_minus": (n, m, m),
        "P_plus": (n, m, m),
        "sigma": (n, m),
        "process_noise": (n, nx, nx),
        "a_priori_sigma": (m,),
    }
    for k, shape in shapes.items():  # every one is read by the report: a missing one is refused here
        out[k] = c.num(f"{base}/{k}", shape)  # NaN allowed: a run that lost its covariance
    if f"{base}/event_status" in c.f:
        out["event_status"] = c.num(f"{base}/event_status", (n,), integer=True)
    eg = f"{base}/eigenvector_events"
    idx = c.num(f"{eg}/index", (None,), integer=True)
    k = idx.shape[0]
    ev = {"index": idx}
    if f"{eg}/position_eigenvalues" in c.f or k:
        for name, shape in (
            ("position_eigenvalues", (k, 3)),
            ("position_eigenvectors", (k, 3, 3)),
            ("velocity_eigenvalues", (k, 3)),
            ("velocity_eigenvectors", (k, 3, 3)),
            ("correlations", (k, m, m)),
        ):
            ev[name] = c.num(f"{eg}/{name}", shape)
    out["eigenvector_events"] = ev
    return out


def _read_measurements(c: Checked, g: h5py.Group) -> dict[str, Any]:
    mb = "team/measurements"
    k = c.num(f"{mb}/index", (None,), integer=True).shape[0]
    meas: dict[str, Any] = {}
    for name in dict.fromkeys([*_MEASUREMENT_FIELDS, *g["measurements"]]):  # the written ones first
        full = f"{mb}/{name}"
        if name in ("type", "stations"):
            meas[name] = c.strs(full, k)
        else:
            meas[name] = c.num(full, (k,), integer=name in ("index", "tracking", "used"))
    return meas


def _read_predictions(c: Checked, g: h5py.Group) -> list[dict[str, Any]]:
    preds = []
    if "predictions" in g:
        for name in sorted(g["predictions"]):
            q = g["predictions"][name]
            base = f"team/predictions/{name}"
            preds.append(
                {
                    "from_index": int(q.attrs["from_index"]),
                    "status": int(q.attrs.get("status", 0)),
                    "time_from_s": c.scalar(f"{base}/time_from_s"),
                    "time_to_s": c.scalar(f"{base}/time_to_s"),
                    "assumed": c.num(f"{base}/assumed", (None, None)),
                    "true": c.num(f"{base}/true", (None, None)) if "true" in q else None,
                }
            )
    return preds


def _read_psd(c: Checked, g: h5py.Group) -> list[tuple[int, str, str, float]]:
    psd = []
    if "psd_events" in g:
        idx = c.num("team/psd_events/index", (None,), integer=True)
        j = idx.shape[0]
        psd = list(
            zip(
                idx.tolist(),
                c.strs("team/psd_events/event", j),
                c.strs("team/psd_events/which", j),
                c.num("team/psd_events/min_eigenvalue", (j,)).tolist(),
            )
        )
    return psd


def _read_budget(c: Checked, g: h5py.Group) -> dict[str, Any]:
    outs = c.strs("team/budget/outputs")
    srcs = c.strs("team/budget/sources")
    return {
        "outputs": outs,
        "units": c.strs("team/budget/units", len(outs)),
        "sources": srcs,
        "variance": c.num("team/budget/variance", (len(outs), len(srcs))),
        "total": c.num("team/budget/total", (len(outs),)),
        "sum_check": float(g["budget"].attrs.get("sum_check", float("nan"))),
    }


def _checked_results(f: h5py.File, p: Path, verify: bool) -> Checked:
    """The file's kind and schema_version checked, and its groups present: a :class:`Checked` of it."""
    kind = attr_text(f, "file_kind")
    if kind != "fracas-team-results":
        raise ResultsFileError(
            f"{p}: not a fracas TEAM results file (file_kind = {f.attrs.get('file_kind')!r}, "
            "expected 'fracas-team-results')"
        )
    version = schema_version(f, p, RESULTS_SCHEMA, ResultsFileError, "results file")
    c = Checked(f, p, ResultsFileError, verify=verify, require_checksum=version >= 2)
    for group in _TEAM_GROUPS:
        if not isinstance(f.get(group), h5py.Group):
            raise c.fail(group, "missing, expected a group (incomplete file?)")
    return c


def read_team_results(path: str | os.PathLike, *, verify: bool = True) -> dict[str, Any]:
    """Everything a report needs from a results file (``docs/team_results.md``), as a dict.

    Every dataset is checked (dtype, shapes consistent with the schedule and the labels,
    finite times and states) and, with ``verify`` and a schema-2 file, its SHA-256
    checksum.  A missing file, another kind of file or a damaged one: one-line
    ResultsFileError naming the file and the dataset."""
    p = Path(path)
    try:
        with open_h5(p, ResultsFileError, "TEAM results file", checksum=verify) as f:
            c = _checked_results(f, p, verify)
            g = f["team"]
            times = c.num("team/times_s", (None,), finite=True)
            n = times.shape[0]
            labels = c.strs("team/labels/names")
            m = len(labels)
            states = c.num("team/states", (n, 7), finite=True)
            nx = int(g.attrs.get("n_state", 7))
            out = {
                "path": str(p),
                "attrs": dict(g.attrs),
                "times_s": times,
                "event_types": c.strs("team/event_types", n),
                "labels": labels,
                "units": c.strs("team/labels/units", m),
                "roles": c.strs("team/labels/roles", m),
                "states": states,
                "primary": c.strs("team/primary", n),
                "print": dict(g["print"].attrs) if "print" in g else {},
                "timing": dict(g["timing"].attrs) if "timing" in g else {},
            }
            if "tracking" in g:
                types = c.strs("team/tracking/type")
                out["tracking"] = list(zip(types, c.strs("team/tracking/stations", len(types))))
            else:
                out["tracking"] = []
            for which in ("assumed", "true"):
                if which in g:
                    out[which] = _history(c, f"team/{which}", n, m, nx)
            out["measurements"] = _read_measurements(c, g)
            out["predictions"] = _read_predictions(c, g)
            out["psd_problems"] = _read_psd(c, g)
            if "guidance" in g:
                out["guidance"] = _read_guidance(c, g, m)
            if "control" in g:
                out["control"] = {
                    "P_plus": c.num("team/control/P_plus", (n, m, m)),
                    "sigma": c.num("team/control/sigma", (n, m)),
                    "epoch_index": c.num("team/control/epoch_index", (n,), integer=True),
                    "a_priori": c.num("team/control/a_priori", (m, m)),
                }
            if "budget" in g:
                out["budget"] = _read_budget(c, g)
        return out
    except ResultsFileError:
        raise
    except KeyError as exc:
        raise ResultsFileError(f"{p}: incomplete TEAM results file: {one_line(exc)} is missing") from None
    except (OSError, ValueError, TypeError) as exc:
        raise ResultsFileError(f"{p}: unreadable or incomplete TEAM results file: {one_line(exc)}") from None


def read_punch(path: str | os.PathLike, source: str = "<deck>", *, verify: bool = True) -> dict[str, Any]:
    """The last punched covariance of a punch file.

    Checked like the results file: dtypes, the covariance square over the state and
    parameter labels, finite and symmetric, and (``verify``, schema 2) SHA-256 checksums.
    DeckError (one line naming the deck, the file and the dataset) if missing, not a punch
    file or damaged."""
    p = Path(path)
    head = f'{source}: a_priori.from_punch = "{path}"'
    note_input(p)  # an input of the run: no output may replace it

    class _PunchError(DeckError):
        def __init__(self, msg: str) -> None:
            super().__init__(f"{source}: a_priori.from_punch: {msg}")

    def _refuse(msg: str) -> DeckError:  # verify_file's "<path>: why" after the deck's field
        return DeckError(f"{head}: {msg.removeprefix(f'{p}: ')}")

    try:
        with open_h5(p, _refuse, "punch file", checksum=verify) as f:
            if attr_text(f, "file_kind") != "fracas-punch":
                raise DeckError(f"{head}: not a fracas punch file")
            version = schema_version(f, p, PUNCH_SCHEMA, _PunchError, "punch file")
            c = Checked(f, p, _PunchError, verify=verify, require_checksum=version >= 2)
            keys = sorted(k for k in f if k.startswith("punch_"))
            if not keys:
                raise DeckError(f"{head}: holds no punched covariance")
            k = keys[-1]
            labels = c.strs(f"{k}/labels")
            n = len(labels)
            if f"{k}/state_labels" in f:
                n += len(c.strs(f"{k}/state_labels"))
            else:
                n += 7
            out = {
                "time_s": c.scalar(f"{k}/time_s"),
                "labels": labels,
                "assumed": c.num(f"{k}/assumed", (n, n), finite=True),
                "trajectory_hash": attr_text(f, "trajectory_hash") or "",
            }
            if f"{k}/state" in f:
                c.num(f"{k}/state", (7,), finite=True)
            if "true" in f[k]:
                out["true"] = c.num(f"{k}/true", (n, n), finite=True)
            if "control" in f[k]:
                out["control"] = c.num(f"{k}/control", (n, n), finite=True)
            for which in ("assumed", "true", "control"):
                name = f"{which}_with_noise_states"
                if name in f[k]:
                    out[name] = c.num(f"{k}/{name}", (n + 3, n + 3), finite=True)
            for which in (
                "assumed",
                "true",
                "control",
                "assumed_with_noise_states",
                "true_with_noise_states",
                "control_with_noise_states",
            ):
                if which in out and not np.allclose(out[which], out[which].T, rtol=1e-10, atol=0.0):
                    raise c.fail(f"{k}/{which}", "not symmetric, expected a covariance matrix")
            return out
    except DeckError:
        raise
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise DeckError(f"{head}: cannot read ({one_line(exc)})") from None
