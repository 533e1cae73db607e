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
from fracas.io.hdf5 import (
    Checked,
    atomic_h5,
    attr_text,
    open_h5,
    read_provenance,
    schema_version,
    write,
    write_provenance,
    write_strings,
)
from fracas.products import RendezvousProduct

__all__ = ["RENDEZVOUS_SCHEMA", "write_rendezvous_results", "read_rendezvous_results", "FILE_KIND"]

RENDEZVOUS_SCHEMA = 1
FILE_KIND = "fracas-rendezvous-results"
_COVARIANCES = ("P_true", "P_assumed", "P_true_minus", "P_assumed_minus")
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
        for name in _COVARIANCES:
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


def _check_kind_and_version(f: h5py.File, src: str) -> None:
    """ResultsFileError unless ``f`` is a rendezvous results file of a schema this fracas reads."""
    kind = attr_text(f, "file_kind")
    if kind != FILE_KIND:
        raise ResultsFileError(
            f"{src}: not a fracas rendezvous results file (file_kind = {f.attrs.get('file_kind')!r}, "
            f"expected {FILE_KIND!r})"
        )
    schema_version(f, src, RENDEZVOUS_SCHEMA, ResultsFileError, "rendezvous results file")


def read_rendezvous_results(path: str | os.PathLike, *, verify: bool = True) -> RendezvousProduct:
    """Read a rendezvous results file; ResultsFileError (one line, naming the file and the
    dataset) when it is missing, not HDF5, damaged (integrity header), another kind, of
    another schema_version or incomplete.  ``verify=False`` skips the checksums only."""
    src = str(path)
    if not os.path.exists(path):
        raise ResultsFileError(f"{src}: no such results file")
    with open_h5(path, ResultsFileError, "rendezvous results file", checksum=verify) as f:
        _check_kind_and_version(f, src)
        c = Checked(f, src, ResultsFileError, verify=verify)
        if not isinstance(f.get("rendezvous"), h5py.Group):
            raise c.fail("rendezvous", "missing, expected the rendezvous group (incomplete file?)")
        a = f["rendezvous"].attrs
        try:
            roles = c.strs("rendezvous/roles")
            labels = c.strs("rendezvous/labels")
            R, n = len(roles), len(labels)
            times = c.num("rendezvous/times_s", (None,), finite=True)
            K = times.shape[0]
            names = c.strs("rendezvous/maneuvers/names")
            J = len(names)
            pr = {k: c.num(f"rendezvous/{k}", (R, K, n, n)) for k in _COVARIANCES}
            rms = {k: c.num(f"rendezvous/{k}", (R, K, 6)) for k in ("team_rms", "assumed_rms")}
            m = "rendezvous/maneuvers/"
            runs = "rendezvous/single_runs/"
            has_runs = "single_runs" in f["rendezvous"]
            run = (lambda k, shape: c.num(runs + k, shape)) if has_runs else (lambda k, shape: None)  # noqa: E731
            return RendezvousProduct(
                title=str(a["title"]),
                source=str(a["source"]),
                epoch_et_s=float(a["epoch_et_s"]),
                centre=str(a["centre"]),
                chaser_name=str(a["chaser"]),
                target_name=str(a["target"]),
                roles=roles,
                reference_sources=c.strs("rendezvous/reference_sources", 2),
                labels=labels,
                units=c.strs("rendezvous/units", n),
                times_s=times,
                marks=c.num("rendezvous/marks", (K, 4), integer=True).astype(bool),
                x_chaser=c.num("rendezvous/x_chaser", (K, 6), finite=True),
                x_target=c.num("rendezvous/x_target", (K, 6), finite=True),
                **pr,
                maneuver_names=names,
                maneuver_time_s=c.num(m + "time_s", (J,)),
                maneuver_arrival_s=c.num(m + "arrival_s", (J,)),
                maneuver_dv_km_s=c.num(m + "dv_km_s", (J, 3)),
                maneuver_status=c.num(m + "status", (J,), integer=True),
                maneuver_cov_true=c.num(m + "cov_true", (R, J, 3, 3)),
                maneuver_cov_assumed=c.num(m + "cov_assumed", (R, J, 3, 3)),
                reset_times_s=c.num("rendezvous/reset_times_s", (None,)),
                **rms,
                n_runs=int(a["n_runs"]),
                seed=int(a["seed"]),
                run_dynamics=str(a.get("run_dynamics", "")),
                run_errors=run("errors", (R, None, K, n)),
                run_maneuver_errors=run("maneuver_errors", (R, None, J, 3)),
                envelope_1sigma=run("envelope_1sigma", (R,)),
                envelope_3sigma=run("envelope_3sigma", (R,)),
                envelope_1sigma_se=run("envelope_1sigma_se", (R,)),
                envelope_3sigma_se=run("envelope_3sigma_se", (R,)),
                run_rms=run("rms", (R, K, 6)),
                length_unit=str(a["length_unit"]),
                km_per_unit=float(a["km_per_unit"]),
                timing=json.loads(c.text("rendezvous/timing")),
                provenance=read_provenance(f),
            )
        except (KeyError, ValueError, TypeError) as exc:  # an attribute missing or of the wrong type
            raise ResultsFileError(
                f"{src}: rendezvous: attribute {exc}: missing or unreadable (incomplete file?)"
            ) from None
