"""TEAM results file and punched knowledge covariances (HDF5, atomic; layout in docs/team_results.md).

Serialises a :class:`fracas.products.TeamProduct` and reads results files back for reports;
no numerics here."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from fracas.errors import DeckError, ResultsFileError
from fracas.io.hdf5 import (
    Checked,
    atomic_h5,
    attr_int,
    attr_text,
    one_line,
    open_h5,
    write,
    write_provenance,
    write_strings,
)
from fracas.products import CovarianceHistory, GuidanceEvent, TeamProduct
from fracas.status import status_text

__all__ = ["write_team_results", "read_team_results", "write_punch", "read_punch", "RESULTS_SCHEMA", "PUNCH_SCHEMA"]

RESULTS_SCHEMA = 2  # 2: every dataset carries data_sha256; 1 (no checksums) is still read
PUNCH_SCHEMA = 2
# groups and measurement fields every results file has had (schema 1 included) and the report reads
_TEAM_GROUPS = ("team", "team/labels", "team/measurements", "team/assumed", "team/assumed/eigenvector_events")
_MEASUREMENT_FIELDS = (
    "index",
    "tracking",
    "type",
    "stations",
    "value",
    "elevation_deg",
    "used",
    "sigma",
    "innovation_sigma",
)


def _write_history(h: h5py.Group, c: CovarianceHistory) -> None:
    write(h, "P_minus", c.P_minus, "labels/units x labels/units", description="covariance before the event")
    write(h, "P_plus", c.P_plus, "labels/units x labels/units", description="covariance after the event")
    write(
        h,
        "process_noise",
        c.process_noise,
        "state units^2",
        description="effective process noise over the interval ending here",
    )
    write(h, "sigma", c.sigma, "labels/units", description="1-sigma after each event")
    write(h, "a_priori_sigma", c.a_priori_sigma, "labels/units", description="1-sigma of the a-priori covariance")
    if c.event_status is not None:
        write(
            h,
            "event_status",
            np.asarray(c.event_status, dtype=np.int64),
            "1",
            description="fracas.status.RunStatus of P_plus at each event (0 OK, 6 not positive-definite, 7 non-finite)",
        )
    e = c.eigen
    eg = h.create_group("eigenvector_events")
    write(eg, "index", np.asarray(e.index, dtype=np.int64), "1")
    if len(e.index):
        write(eg, "position_eigenvalues", e.position_eigenvalues, "km^2")
        write(eg, "position_eigenvectors", e.position_eigenvectors, "1", description="columns")
        write(eg, "velocity_eigenvalues", e.velocity_eigenvalues, "km^2/s^2")
        write(eg, "velocity_eigenvectors", e.velocity_eigenvectors, "1", description="columns")
        write(eg, "correlations", e.correlations, "1")


_GUIDANCE_MATRICES = (
    ("psi", "targets x labels/units", "target variation matrix at the cutoff (TARMAT)"),
    ("gamma", "controls x labels/units", "guidance law: correction = -gamma @ estimated deviation"),
    ("target_cov_before", "target units^2", "target covariance of the dispersion before the correction"),
    ("target_cov_after", "target units^2", "target covariance after the correction"),
    ("target_cov_knowledge", "target units^2", "knowledge covariance mapped to the target"),
    ("correction_cov", "control units^2", "covariance of the correction (dV km^2/s^2, or controls)"),
    ("execution_cov", "control units^2", "execution-error covariance"),
)
_GUIDANCE_SCALARS = ("dv_mean_km_s", "dv_99_km_s", "dv_rms_km_s", "propellant_sigma_kg", "dv_variance_km2_s2")
_SCALAR_UNITS = {"propellant_sigma_kg": "kg", "dv_variance_km2_s2": "km^2/s^2"}


def _write_guidance(g: h5py.Group, events: list[GuidanceEvent]) -> None:
    gg = g.create_group("guidance")
    for i, e in enumerate(events):
        q = gg.create_group(f"{i:03d}")
        for k in ("name", "type", "target_body", "estimate_model"):
            q.attrs[k] = getattr(e, k)
        q.attrs["index"] = int(e.index)
        q.attrs["rank"] = int(e.rank)
        q.attrs["status"] = int(e.status)
        for k in ("time_s", "cutoff_s", "target_time_s"):
            write(q, k, float(getattr(e, k)), "s")
        write_strings(q, "target_names", e.target_names)
        write_strings(q, "target_units", e.target_units)
        write_strings(q, "control_labels", e.control_labels)
        write_strings(q, "control_units", e.control_units)
        for k, units, desc in _GUIDANCE_MATRICES:
            write(q, k, np.asarray(getattr(e, k), dtype=np.float64), units, description=desc)
        for k in _GUIDANCE_SCALARS:
            write(q, k, float(getattr(e, k)), _SCALAR_UNITS.get(k, "km/s"))


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
            "correction_cov": (mc, mc),
            "execution_cov": (mc, mc),
        }
        for k, _, _ in _GUIDANCE_MATRICES:
            d[k] = c.num(f"{base}/{k}", shapes[k])
        for k in _GUIDANCE_SCALARS:
            d[k] = c.scalar(f"{base}/{k}", finite=False)
        out.append(d)
    return out


def write_team_results(path: str | os.PathLike, res: TeamProduct) -> None:
    """Write the full event history of a TEAM run (a :class:`fracas.products.TeamProduct`)
    atomically; an OS failure is a one-line ResultsFileError, the previous file untouched."""
    try:
        _write_team_results(path, res)
    except OSError as exc:
        raise ResultsFileError(f"{path}: cannot write the results file: {exc.strerror or exc}") from None


def _write_team_results(path: str | os.PathLike, res: TeamProduct) -> None:
    st = res.settings
    with atomic_h5(path) as f:
        f.attrs["file_kind"] = "fracas-team-results"
        f.attrs["schema_version"] = RESULTS_SCHEMA
        g = f.create_group("team")
        for k, v in (
            ("title", res.title),
            ("filter", st["filter"]),
            ("propagation", st["propagation"]),
            ("square_root", int(st["square_root"])),
            ("generalized_covariance", int(st["generalized_covariance"])),
            ("reference", st["reference"]),
            ("trajectory_deck", st.get("trajectory_deck", "")),
        ):
            g.attrs[k] = v
        g.attrs["epoch_et_s"] = res.epoch_et_s
        g.attrs["source"] = res.source
        g.attrs["status"] = int(res.status)
        g.attrs["status_text"] = status_text(res.status)
        g.attrs["n_state"] = int(res.n_state)
        g.attrs["min_elevation_deg"] = float(st.get("min_elevation_deg", 0.0))
        g.attrs["trajectory_hash"] = st.get("trajectory_hash", "")
        g.attrs["process_noise"] = str(st.get("process_noise", ""))
        g.attrs["noise_cells"] = str(st.get("noise_cells", ""))
        g.attrs["noise_cell_s"] = float(st.get("noise_cell_s", float("nan")))
        if "guidance_model" in st:
            g.attrs["guidance_model"] = str(st["guidance_model"])
        # the process noise applied (assumed model): Gauss-Markov thrust noise per component,
        # white acceleration noise, PDOT's RK4 steps (docs/team_results.md)
        for key in ("thrust_noise_sigma", "thrust_noise_tau_s"):
            if key in st:
                g.attrs[key] = np.asarray(st[key], np.float64)
        for key in ("white_noise_km2_s3", "pdot_step_min_s", "pdot_step_max_s"):
            if key in st:
                g.attrs[key] = float(st[key])
        if "white_noise_direction" in st:
            g.attrs["white_noise_direction"] = str(st["white_noise_direction"])
        pr = g.create_group("print")
        for k, v in st.get("print", {}).items():
            pr.attrs[k] = v
        tg = g.create_group("timing")
        for k, v in res.timing.items():
            tg.attrs[k] = float(v)
        write(g, "times_s", res.times_s, "s", description="schedule times from the trajectory epoch")
        write_strings(g, "event_types", res.event_types, description="events at each time, in order")
        write(g, "states", res.states, "km, km/s, kg", description="reference r, v, m rel. primary (ICRF)")
        write_strings(g, "primary", res.primary)
        lab = g.create_group("labels")
        write_strings(lab, "names", res.labels)
        write_strings(lab, "units", res.units)
        write_strings(lab, "roles", res.roles)
        tr = g.create_group("tracking")
        write_strings(tr, "type", [t for t, _ in res.tracking], description="[[tracking]] entries in deck order")
        write_strings(tr, "stations", [s for _, s in res.tracking])
        for which, c in (("assumed", res.assumed), ("true", res.true)):
            if c is not None:
                _write_history(g.create_group(which), c)
        m = g.create_group("measurements")
        ml = res.measurements
        write(m, "index", ml.index, "1", description="schedule index")
        write(m, "tracking", ml.tracking, "1", description="[[tracking]] entry")
        write_strings(m, "type", ml.kind)
        write_strings(m, "stations", ml.stations)
        write(m, "value", ml.value, "km | km/s | rad", description="computed observable")
        write(m, "elevation_deg", ml.elevation_deg, "deg")
        write(m, "used", ml.used.astype(np.int8), "1", description="0: below the horizon")
        write(m, "sigma", ml.sigma, "km | km/s | rad", description="assumed noise")
        write(m, "innovation_sigma", ml.innovation_sigma, "km | km/s | rad", description="sqrt(H P- H^T + R), assumed")
        if res.predictions:
            pg = g.create_group("predictions")
            for i, p in enumerate(res.predictions):
                q = pg.create_group(f"{i:03d}")
                q.attrs["from_index"] = p.from_index
                q.attrs["status"] = int(p.status)
                write(q, "time_from_s", p.time_from_s, "s")
                write(q, "time_to_s", p.time_to_s, "s")
                write(q, "assumed", p.assumed, "labels/units x labels/units")
                if p.true is not None:
                    write(q, "true", p.true, "labels/units x labels/units")
        if res.psd_problems:
            write_strings(
                g, "psd_problems", [f"{res.times_s[k]:.3f} s {ev} {w} {e:.3g}" for k, ev, w, e in res.psd_problems]
            )
            pp = g.create_group("psd_events")
            write(pp, "index", np.array([k for k, _, _, _ in res.psd_problems], dtype=np.int64), "1")
            write_strings(pp, "event", [e for _, e, _, _ in res.psd_problems])
            write_strings(pp, "which", [w for _, _, w, _ in res.psd_problems])
            write(pp, "min_eigenvalue", np.array([e for _, _, _, e in res.psd_problems]), "mixed")
        if res.guidance:
            _write_guidance(g, res.guidance)
        if res.control is not None:
            cg = g.create_group("control")
            ct = res.control
            write(
                cg, "P_plus", ct.P_plus, "labels/units x labels/units", description="control covariance after the event"
            )
            write(cg, "sigma", ct.sigma, "labels/units", description="1-sigma of the control covariance")
            write(cg, "epoch_index", np.asarray(ct.epoch_index, dtype=np.int64), "1", description="last reset")
            write(cg, "a_priori", ct.a_priori, "labels/units x labels/units", description="initial control covariance")
        if res.budget is not None:
            b = res.budget
            bg = g.create_group("budget")
            write_strings(bg, "outputs", b.outputs)
            write_strings(bg, "units", b.units)
            write_strings(bg, "sources", b.sources)
            write(bg, "variance", np.asarray(b.variance, dtype=np.float64), "units^2", description="outputs x sources")
            write(bg, "total", np.asarray(b.total, dtype=np.float64), "units^2", description="the full run's variance")
            bg.attrs["sum_check"] = float(b.sum_check)
        write_provenance(f, res.provenance)


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


def _version(f: h5py.File, p: Path, latest: int, err: type[Exception], what: str, prefix: str = "") -> int:
    raw = f.attrs.get("schema_version")
    version = attr_int(
        f,
        "schema_version",
        err(f"{prefix}{p}: attribute schema_version is {type(raw).__name__} ({raw!r}), expected an integer"),
    )
    if version is None or not 1 <= version <= latest:
        raise err(f"{prefix}{p}: {what} schema_version = {version}, this fracas reads 1 to {latest}")
    return version


def read_team_results(path: str | os.PathLike, *, verify: bool = True) -> dict[str, Any]:
    """Everything a report needs from a results file (``docs/team_results.md``), as a dict.

    Every dataset is checked (dtype, shapes consistent with the schedule and the labels,
    finite times and states) and, with ``verify`` and a schema-2 file, its SHA-256
    checksum.  A missing file, another kind of file or a damaged one: one-line
    ResultsFileError naming the file and the dataset."""
    p = Path(path)
    try:
        with open_h5(p, ResultsFileError, "TEAM results file", checksum=verify) as f:
            kind = attr_text(f, "file_kind")
            if kind != "fracas-team-results":
                raise ResultsFileError(
                    f"{p}: not a fracas TEAM results file (file_kind = {f.attrs.get('file_kind')!r}, "
                    "expected 'fracas-team-results')"
                )
            version = _version(f, p, RESULTS_SCHEMA, ResultsFileError, "results file")
            c = Checked(f, p, ResultsFileError, verify=verify, require_checksum=version >= 2)
            for group in _TEAM_GROUPS:
                if not isinstance(f.get(group), h5py.Group):
                    raise c.fail(group, "missing, expected a group (incomplete file?)")
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
            mb = "team/measurements"
            k = c.num(f"{mb}/index", (None,), integer=True).shape[0]
            meas: dict[str, Any] = {}
            for name in dict.fromkeys([*_MEASUREMENT_FIELDS, *g["measurements"]]):  # the written ones first
                full = f"{mb}/{name}"
                if name in ("type", "stations"):
                    meas[name] = c.strs(full, k)
                else:
                    meas[name] = c.num(full, (k,), integer=name in ("index", "tracking", "used"))
            out["measurements"] = meas
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
            out["predictions"] = preds
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
            out["psd_problems"] = psd
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
                outs = c.strs("team/budget/outputs")
                srcs = c.strs("team/budget/sources")
                out["budget"] = {
                    "outputs": outs,
                    "units": c.strs("team/budget/units", len(outs)),
                    "sources": srcs,
                    "variance": c.num("team/budget/variance", (len(outs), len(srcs))),
                    "total": c.num("team/budget/total", (len(outs),)),
                    "sum_check": float(g["budget"].attrs.get("sum_check", float("nan"))),
                }
        return out
    except ResultsFileError:
        raise
    except KeyError as exc:
        raise ResultsFileError(f"{p}: incomplete TEAM results file: {one_line(exc)} is missing") from None
    except (OSError, ValueError, TypeError) as exc:
        raise ResultsFileError(f"{p}: unreadable or incomplete TEAM results file: {one_line(exc)}") from None


def write_punch(path: str | os.PathLike, res: TeamProduct, indices: list[int] | None = None) -> None:
    """Punch knowledge covariances at schedule ``indices`` (default: the punch events) for a
    later TEAM run (or TSIM), atomically; an OS failure is a one-line ResultsFileError."""
    try:
        _write_punch(path, res, indices)
    except OSError as exc:
        raise ResultsFileError(f"{path}: cannot write the punch file: {exc.strerror or exc}") from None


def _write_punch(path: str | os.PathLike, res: TeamProduct, indices: list[int] | None) -> None:
    idx = res.punch_indices if indices is None else indices
    n = sum(r != "noise_state" for r in res.roles)  # PDOT's noise states are not punched
    nx = res.n_state
    with atomic_h5(path) as f:
        f.attrs["file_kind"] = "fracas-punch"
        f.attrs["schema_version"] = PUNCH_SCHEMA
        f.attrs["trajectory_deck"] = res.settings.get("trajectory_deck", "")
        f.attrs["trajectory_hash"] = res.settings.get("trajectory_hash", "")
        f.attrs["epoch_et_s"] = res.epoch_et_s
        for i, k in enumerate(idx):
            g = f.create_group(f"punch_{i:03d}")
            write(g, "time_s", res.times_s[k], "s")
            write(g, "state", res.states[k], "km, km/s, kg")
            write_strings(g, "labels", res.labels[nx:n])
            write_strings(g, "state_labels", res.labels[:nx])
            write(g, "assumed", res.assumed.P_plus[k][:n, :n], "labels/units x labels/units")
            if res.true is not None:
                write(g, "true", res.true.P_plus[k][:n, :n], "labels/units x labels/units")
            if res.control is not None:
                write(g, "control", res.control.P_plus[k][:n, :n], "labels/units x labels/units")
            if len(res.roles) > n:  # the Gauss-Markov noise states (exact PHI, PDOT): punched too,
                # so a restart carries their correlations with the state (issue 24)
                unit = "labels/units + eta x same"
                write(g, "assumed_with_noise_states", res.assumed.P_plus[k], unit)
                if res.true is not None:
                    write(g, "true_with_noise_states", res.true.P_plus[k], unit)
                if res.control is not None:
                    write(g, "control_with_noise_states", res.control.P_plus[k], unit)
        write_provenance(f, res.provenance)


def read_punch(path: str | os.PathLike, source: str = "<deck>", *, verify: bool = True) -> dict[str, Any]:
    """The last punched covariance of a punch file.

    Checked like the results file: dtypes, the covariance square over the state and
    parameter labels, finite and symmetric, and (``verify``, schema 2) SHA-256 checksums.
    DeckError (one line naming the deck, the file and the dataset) if missing, not a punch
    file or damaged."""
    p = Path(path)
    head = f'{source}: a_priori.from_punch = "{path}"'

    class _PunchError(DeckError):
        def __init__(self, msg: str):
            super().__init__(f"{source}: a_priori.from_punch: {msg}")

    def _refuse(msg: str) -> DeckError:  # verify_file's "<path>: why" after the deck's field
        return DeckError(f"{head}: {msg.removeprefix(f'{p}: ')}")

    try:
        with open_h5(p, _refuse, "punch file", checksum=verify) as f:
            if attr_text(f, "file_kind") != "fracas-punch":
                raise DeckError(f"{head}: not a fracas punch file")
            version = _version(f, p, PUNCH_SCHEMA, _PunchError, "punch file")
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
