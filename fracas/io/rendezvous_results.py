"""Two-vehicle (rendezvous) results file (HDF5, atomic): serialises a
:class:`fracas.products.RendezvousProduct` and reads it back for reports; no numerics.

Layout (every dataset carries ``units`` and ``data_sha256``)::

    /                          file_kind = "fracas-rendezvous-results", schema_version, provenance
    /rendezvous                attrs: title, source, epoch_et_s (TDB s past J2000), centre,
                               chaser, target, length_unit, km_per_unit, n_runs, seed,
                               run_dynamics ("linear" | "two_body")
      roles (R,)               "solve_for" | "consider" | "ignore" (axis 0 of the per-role arrays)
      reference_sources (2,)   where the chaser's and the target's references came from
      labels, units (n,)       [chaser r, v; target r, v; biases] and their units
      times_s (K,)             s, events from the chaser's epoch
      marks (K, 4)             int 0/1: range, range_rate, los_beta, los_theta measured
      x_chaser, x_target (K, 6)  km, km/s about the centre (ICRF axes)
      P_true, P_assumed (R, K, n, n)              after each event's updates (labels' units^2)
      P_true_minus, P_assumed_minus (R, K, n, n)  before them
      team_rms, assumed_rms (R, K, 6)  km, km/s: RMS magnitudes of the true / assumed covariance
                               after each event: chaser, target and relative (E_R = E_A + E_T
                               - G - G') position and velocity (columns attr)
      reset_times_s (Q,)       s, assumed-covariance resets
      timing                   JSON text (s)
      maneuvers/               names (J,), time_s, arrival_s (J,) s, dv_km_s (J, 3) km/s,
                               status (J,) int (0 converged), cov_true, cov_assumed
                               (R, J, 3, 3) km^2/s^2
      single_runs/             (when runs were made) errors (R, keep, K, n), maneuver_errors
                               (R, N, J, 3) km/s, envelope_1sigma, envelope_3sigma (R,) and
                               their standard errors envelope_1sigma_se, envelope_3sigma_se, rms (R, K, 6)
                               the runs' sample RMS (km, km/s; columns attr)
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np

from fracas.errors import ResultsFileError
from fracas.io.hdf5 import atomic_h5, read_provenance, read_str, write, write_provenance, write_strings
from fracas.products import RendezvousProduct

__all__ = ["RENDEZVOUS_SCHEMA", "write_rendezvous_results", "read_rendezvous_results", "FILE_KIND"]

RENDEZVOUS_SCHEMA = 1
FILE_KIND = "fracas-rendezvous-results"
_RMS_COLUMNS = (
    "chaser_position",
    "chaser_velocity",
    "target_position",
    "target_velocity",
    "relative_position",
    "relative_velocity",
)


def write_rendezvous_results(path: str | os.PathLike, product: RendezvousProduct) -> Path:
    """Write ``product`` to ``path`` atomically (a crash leaves any old file intact)."""
    p = Path(path)
    with atomic_h5(p) as f:
        f.attrs["file_kind"] = FILE_KIND
        f.attrs["schema_version"] = RENDEZVOUS_SCHEMA
        write_provenance(f, dict(product.provenance))
        g = f.create_group("rendezvous")
        for key in ("title", "source", "centre", "length_unit"):
            g.attrs[key] = str(getattr(product, key))
        g.attrs["chaser"] = str(product.chaser_name)
        g.attrs["target"] = str(product.target_name)
        g.attrs["epoch_et_s"] = float(product.epoch_et_s)
        g.attrs["km_per_unit"] = float(product.km_per_unit)
        g.attrs["n_runs"] = int(product.n_runs)
        g.attrs["seed"] = int(product.seed)
        g.attrs["run_dynamics"] = str(product.run_dynamics)
        write_strings(g, "roles", product.roles)
        write_strings(g, "reference_sources", product.reference_sources)
        write_strings(g, "labels", product.labels)
        write_strings(g, "units", product.units)
        write(g, "times_s", np.asarray(product.times_s, np.float64), "s")
        write(g, "marks", np.asarray(product.marks, np.int64), "1", columns="range range_rate los_beta los_theta")
        write(g, "x_chaser", np.asarray(product.x_chaser, np.float64), "km, km/s")
        write(g, "x_target", np.asarray(product.x_target, np.float64), "km, km/s")
        for name in ("P_true", "P_assumed", "P_true_minus", "P_assumed_minus"):
            write(g, name, np.asarray(getattr(product, name), np.float64), "labels' units^2")
        for name in ("team_rms", "assumed_rms"):
            write(g, name, np.asarray(getattr(product, name), np.float64), "km, km/s", columns=" ".join(_RMS_COLUMNS))
        write(g, "reset_times_s", np.asarray(product.reset_times_s, np.float64).reshape(-1), "s")
        write(g, "timing", json.dumps(product.timing), "none", description="seconds")
        m = g.create_group("maneuvers")
        write_strings(m, "names", product.maneuver_names)
        write(m, "time_s", np.asarray(product.maneuver_time_s, np.float64).reshape(-1), "s")
        write(m, "arrival_s", np.asarray(product.maneuver_arrival_s, np.float64).reshape(-1), "s")
        write(m, "dv_km_s", np.asarray(product.maneuver_dv_km_s, np.float64).reshape(-1, 3), "km/s")
        write(m, "status", np.asarray(product.maneuver_status, np.int64).reshape(-1), "1")
        write(m, "cov_true", np.asarray(product.maneuver_cov_true, np.float64), "km^2/s^2")
        write(m, "cov_assumed", np.asarray(product.maneuver_cov_assumed, np.float64), "km^2/s^2")
        if product.n_runs > 0 and product.run_errors is not None:
            s = g.create_group("single_runs")
            write(s, "errors", np.asarray(product.run_errors, np.float64), "labels' units")
            write(s, "maneuver_errors", np.asarray(product.run_maneuver_errors, np.float64), "km/s")
            write(s, "envelope_1sigma", np.asarray(product.envelope_1sigma, np.float64), "1")
            write(s, "envelope_3sigma", np.asarray(product.envelope_3sigma, np.float64), "1")
            write(
                s,
                "rms",
                np.asarray(product.run_rms, np.float64),
                "km, km/s",
                columns=" ".join(_RMS_COLUMNS),
            )
            write(s, "envelope_1sigma_se", np.asarray(product.envelope_1sigma_se, np.float64), "1")
            write(s, "envelope_3sigma_se", np.asarray(product.envelope_3sigma_se, np.float64), "1")
    return p


def read_rendezvous_results(path: str | os.PathLike) -> RendezvousProduct:
    """Read a rendezvous results file; ResultsFileError (one line, naming the file and the
    dataset) when it is missing, not HDF5, another kind or incomplete."""
    src = str(path)
    try:
        f = h5py.File(path, "r")
    except FileNotFoundError:
        raise ResultsFileError(f"{src}: no such results file") from None
    except OSError as exc:
        raise ResultsFileError(f"{src}: not an HDF5 results file ({exc})") from None
    with f:
        kind = f.attrs.get("file_kind", "")
        kind = kind.decode() if isinstance(kind, bytes) else str(kind)
        if kind != FILE_KIND:
            raise ResultsFileError(f"{src}: file_kind = {kind!r}: expected {FILE_KIND!r}")
        try:
            g = f["rendezvous"]
            a = g.attrs
            m = g["maneuvers"]
            runs = g.get("single_runs")
            arr = lambda grp, k: np.array(grp[k])  # noqa: E731
            strs = lambda grp, k: [str(x) for x in read_str(grp[k])]  # noqa: E731
            return RendezvousProduct(
                title=str(a["title"]),
                source=str(a["source"]),
                epoch_et_s=float(a["epoch_et_s"]),
                centre=str(a["centre"]),
                chaser_name=str(a["chaser"]),
                target_name=str(a["target"]),
                roles=strs(g, "roles"),
                reference_sources=strs(g, "reference_sources") if "reference_sources" in g else [],
                labels=strs(g, "labels"),
                units=strs(g, "units"),
                times_s=arr(g, "times_s"),
                marks=arr(g, "marks").astype(bool),
                x_chaser=arr(g, "x_chaser"),
                x_target=arr(g, "x_target"),
                P_true=arr(g, "P_true"),
                P_assumed=arr(g, "P_assumed"),
                P_true_minus=arr(g, "P_true_minus"),
                P_assumed_minus=arr(g, "P_assumed_minus"),
                maneuver_names=strs(m, "names"),
                maneuver_time_s=arr(m, "time_s"),
                maneuver_arrival_s=arr(m, "arrival_s"),
                maneuver_dv_km_s=arr(m, "dv_km_s"),
                maneuver_status=arr(m, "status"),
                maneuver_cov_true=arr(m, "cov_true"),
                maneuver_cov_assumed=arr(m, "cov_assumed"),
                reset_times_s=arr(g, "reset_times_s"),
                team_rms=arr(g, "team_rms"),
                assumed_rms=arr(g, "assumed_rms"),
                n_runs=int(a["n_runs"]),
                seed=int(a["seed"]),
                run_dynamics=str(a.get("run_dynamics", "")),
                run_errors=arr(runs, "errors") if runs is not None else None,
                run_maneuver_errors=arr(runs, "maneuver_errors") if runs is not None else None,
                envelope_1sigma=arr(runs, "envelope_1sigma") if runs is not None else None,
                envelope_3sigma=arr(runs, "envelope_3sigma") if runs is not None else None,
                envelope_1sigma_se=arr(runs, "envelope_1sigma_se") if runs is not None else None,
                run_rms=arr(runs, "rms") if runs is not None else None,
                envelope_3sigma_se=arr(runs, "envelope_3sigma_se") if runs is not None else None,
                length_unit=str(a["length_unit"]),
                km_per_unit=float(a["km_per_unit"]),
                timing=json.loads(read_str(g["timing"])),
                provenance=read_provenance(f),
            )
        except (KeyError, ValueError, TypeError, OSError) as exc:
            raise ResultsFileError(f"{src}: incomplete rendezvous results file: {exc}") from None
