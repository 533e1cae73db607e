"""TEAM results file and punched knowledge covariances (HDF5, atomic; layout in docs/team_results.md).

Serialises a :class:`fracas.products.TeamProduct` and reads results files back for reports;
no numerics here.  The readers (:func:`read_team_results`, :func:`read_punch`) live in
:mod:`fracas.io.team_results_read`, the layout both sides share in
:mod:`fracas.io.team_layout`; both are re-exported here."""

from __future__ import annotations

import os

import h5py
import numpy as np

from fracas.errors import ResultsFileError
from fracas.io.hdf5 import atomic_h5, write, write_provenance, write_strings
from fracas.io.team_layout import _GUIDANCE_MATRICES, _GUIDANCE_SCALARS, _SCALAR_UNITS, PUNCH_SCHEMA, RESULTS_SCHEMA
from fracas.io.team_results_read import read_punch, read_team_results
from fracas.products import (
    ControlHistory,
    CovarianceHistory,
    ErrorBudget,
    GuidanceEvent,
    MeasurementLog,
    Prediction,
    TeamProduct,
)
from fracas.status import status_text

__all__ = ["write_team_results", "read_team_results", "write_punch", "read_punch", "RESULTS_SCHEMA", "PUNCH_SCHEMA"]


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


def write_team_results(path: str | os.PathLike, res: TeamProduct) -> None:
    """Write the full event history of a TEAM run (a :class:`fracas.products.TeamProduct`)
    atomically; an OS failure is a one-line ResultsFileError, the previous file untouched."""
    try:
        _write_team_results(path, res)
    except OSError as exc:
        raise ResultsFileError(f"{path}: cannot write the results file: {exc.strerror or exc}") from None


def _write_settings(g: h5py.Group, res: TeamProduct) -> None:
    """team's attributes: the run's settings, status and the process noise applied; print, timing."""
    st = res.settings
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


def _write_measurements(g: h5py.Group, ml: MeasurementLog) -> None:
    m = g.create_group("measurements")
    write(m, "index", ml.index, "1", description="schedule index")
    write(m, "tracking", ml.tracking, "1", description="[[tracking]] entry")
    write_strings(m, "type", ml.kind)
    write_strings(m, "stations", ml.stations)
    write(m, "value", ml.value, "km | km/s | rad", description="computed observable")
    write(m, "elevation_deg", ml.elevation_deg, "deg")
    write(m, "used", ml.used.astype(np.int8), "1", description="0: below the horizon")
    write(m, "sigma", ml.sigma, "km | km/s | rad", description="assumed noise")
    write(m, "innovation_sigma", ml.innovation_sigma, "km | km/s | rad", description="sqrt(H P- H^T + R), assumed")


def _write_predictions(g: h5py.Group, predictions: list[Prediction]) -> None:
    pg = g.create_group("predictions")
    for i, p in enumerate(predictions):
        q = pg.create_group(f"{i:03d}")
        q.attrs["from_index"] = p.from_index
        q.attrs["status"] = int(p.status)
        write(q, "time_from_s", p.time_from_s, "s")
        write(q, "time_to_s", p.time_to_s, "s")
        write(q, "assumed", p.assumed, "labels/units x labels/units")
        if p.true is not None:
            write(q, "true", p.true, "labels/units x labels/units")


def _write_psd_problems(g: h5py.Group, res: TeamProduct) -> None:
    write_strings(g, "psd_problems", [f"{res.times_s[k]:.3f} s {ev} {w} {e:.3g}" for k, ev, w, e in res.psd_problems])
    pp = g.create_group("psd_events")
    write(pp, "index", np.array([k for k, _, _, _ in res.psd_problems], dtype=np.int64), "1")
    write_strings(pp, "event", [e for _, e, _, _ in res.psd_problems])
    write_strings(pp, "which", [w for _, _, w, _ in res.psd_problems])
    write(pp, "min_eigenvalue", np.array([e for _, _, _, e in res.psd_problems]), "mixed")


def _write_control(g: h5py.Group, ct: ControlHistory) -> None:
    cg = g.create_group("control")
    write(cg, "P_plus", ct.P_plus, "labels/units x labels/units", description="control covariance after the event")
    write(cg, "sigma", ct.sigma, "labels/units", description="1-sigma of the control covariance")
    write(cg, "epoch_index", np.asarray(ct.epoch_index, dtype=np.int64), "1", description="last reset")
    write(cg, "a_priori", ct.a_priori, "labels/units x labels/units", description="initial control covariance")


def _write_budget(g: h5py.Group, b: ErrorBudget) -> None:
    bg = g.create_group("budget")
    write_strings(bg, "outputs", b.outputs)
    write_strings(bg, "units", b.units)
    write_strings(bg, "sources", b.sources)
    write(bg, "variance", np.asarray(b.variance, dtype=np.float64), "units^2", description="outputs x sources")
    write(bg, "total", np.asarray(b.total, dtype=np.float64), "units^2", description="the full run's variance")
    bg.attrs["sum_check"] = float(b.sum_check)


def _write_team_results(path: str | os.PathLike, res: TeamProduct) -> None:
    with atomic_h5(path) as f:
        f.attrs["file_kind"] = "fracas-team-results"
        f.attrs["schema_version"] = RESULTS_SCHEMA
        g = f.create_group("team")
        _write_settings(g, res)
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
        _write_measurements(g, res.measurements)
        if res.predictions:
            _write_predictions(g, res.predictions)
        if res.psd_problems:
            _write_psd_problems(g, res)
        if res.guidance:
            _write_guidance(g, res.guidance)
        if res.control is not None:
            _write_control(g, res.control)
        if res.budget is not None:
            _write_budget(g, res.budget)
        write_provenance(f, res.provenance)


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
