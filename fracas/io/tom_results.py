"""TOM results file (HDF5, atomic; layout in docs/tom_results.md).

Serialises a :class:`fracas.products.TomProduct` and reads it back for reports; no numerics.

Layout (every dataset carries ``units`` and ``data_sha256``)::

    /                       file_kind = "fracas-tom-results", schema_version, provenance
    /tom                    attrs: title, source, submode, optimizer, sensitivities,
                            stop_reason, converged, search_converged, targets_met,
                            reference_deck, timing_* (s)
      controls/names, units, factor, start, final, lower, upper
      targets/names, bodies, units, factor, desired, tolerance, achieved_start, achieved
      mass/initial_kg, start_kg, final_kg
      history/iteration, submode, performance_kg, error_rms, angle_rad, gamma,
              n_trajectories, controls (K, M), targets (K, N), trials (T, 6: iteration,
              gamma, F(gamma), final mass kg, E, ok)
      sensitivities/S (N, M), G (M,)          (at the final controls, deck units)
      grid/single (M, G), gammas (G,), pair_<a>_<b> (G, G)   (GRID: G = 2 steps + 1)
"""

from __future__ import annotations

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
    attr_text,
    one_line,
    open_h5,
    write,
    write_provenance,
    write_strings,
)
from fracas.products import TomProduct

__all__ = ["write_tom_results", "read_tom_results", "TOM_SCHEMA"]

TOM_SCHEMA = 1
_KIND = "fracas-tom-results"


def write_tom_results(path: str | os.PathLike, product: TomProduct) -> Path:
    """Write ``product`` to ``path`` atomically (a crash leaves any old file intact)."""
    p = Path(path)
    with atomic_h5(p) as f:
        f.attrs["file_kind"] = _KIND
        f.attrs["schema_version"] = TOM_SCHEMA
        write_provenance(f, product.provenance)
        g = f.create_group("tom")
        for key in ("title", "source", "submode", "optimizer", "sensitivities", "stop_reason", "reference_deck"):
            g.attrs[key] = str(getattr(product, key))
        for key in ("converged", "search_converged", "targets_met"):
            g.attrs[key] = int(bool(getattr(product, key)))
        for key, val in product.timing.items():
            g.attrs[f"timing_{key}"] = float(val)
        g.attrs["performance"] = product.performance_name
        g.attrs["performance_unit"] = product.performance_unit
        g.attrs["performance_start"] = float(product.performance_start)
        g.attrs["performance_final"] = float(product.performance_final)
        c = g.create_group("controls")
        write_strings(c, "names", product.control_names)
        write_strings(c, "units", product.control_units)
        write(c, "factor", np.asarray(product.control_factor, float), "canonical per deck unit")
        for key, attr in (("start", "u_start"), ("final", "u_final"), ("lower", "lower"), ("upper", "upper")):
            write(c, key, np.asarray(getattr(product, attr), float), "controls/units")
        t = g.create_group("targets")
        write_strings(t, "names", product.target_names)
        write_strings(t, "bodies", product.target_bodies)
        write_strings(t, "units", product.target_units)
        write(t, "factor", np.asarray(product.target_factor, float), "canonical per deck unit")
        for key in ("desired", "tolerance", "achieved_start", "achieved"):
            write(t, key, np.asarray(getattr(product, key), float), "targets/units")
        m = g.create_group("mass")
        write(m, "initial_kg", np.float64(product.initial_mass_kg), "kg")
        write(m, "start_kg", np.float64(product.start_mass_kg), "kg", description="final mass at the start controls")
        write(m, "final_kg", np.float64(product.final_mass_kg), "kg", description="final mass at the final controls")
        h = g.create_group("history")
        write(h, "iteration", np.asarray(product.iteration, np.int64), "1")
        write_strings(h, "submode", product.submodes)
        write(h, "performance_kg", np.asarray(product.performance_kg, float), "kg")
        write(h, "error_rms", np.asarray(product.error_rms, float), "1", description="RMS of (T - T0)/tolerance")
        write(h, "angle_rad", np.asarray(product.angle_rad, float), "rad", description="TEST angle theta")
        write(h, "gamma", np.asarray(product.gamma, float), "1", description="accepted step fraction")
        write(h, "n_trajectories", np.asarray(product.n_trajectories, np.int64), "1")
        k = len(product.iteration)
        write(h, "controls", np.asarray(product.controls, float).reshape(k, len(product.control_names)), "controls")
        write(h, "targets", np.asarray(product.targets, float).reshape(k, len(product.target_names)), "targets")
        if product.trials is not None:
            write(
                h,
                "trials",
                np.asarray(product.trials, float).reshape(-1, 6),
                "1, 1, 1, kg, 1, 1",
                description="line-search trials: iteration, gamma, F(gamma), final mass, error index E, ok",
            )
        if product.s_matrix is not None:
            s = g.create_group("sensitivities")
            write(s, "S", np.asarray(product.s_matrix, float), "target unit / control unit")
            write(s, "G", np.asarray(product.g_vector, float), "kg / control unit")
        if product.grid is not None:
            gr = g.create_group("grid")
            write(gr, "single", np.asarray(product.grid["single"], float), "1", description="error index E")
            write(gr, "gammas", np.asarray(product.grid["gammas"], float), "increments")
            for (a, b), table in product.grid.get("pairs", {}).items():
                write(gr, f"pair_{a}_{b}", np.asarray(table, float), "1", description="E over (gamma_a, gamma_b)")
    return p


def read_tom_results(path: str | os.PathLike, *, verify: bool = True) -> dict[str, Any]:
    """Everything a report needs from a TOM results file, as a dict; one-line
    ResultsFileError naming the file and the dataset for a missing or damaged file."""
    p = Path(path)
    try:
        with open_h5(p, ResultsFileError, "TOM results file", checksum=verify) as f:
            if attr_text(f, "file_kind") != _KIND:
                raise ResultsFileError(
                    f"{p}: not a fracas TOM results file (file_kind = {f.attrs.get('file_kind')!r}, expected {_KIND!r})"
                )
            version = attr_int(f, "schema_version")
            if version is None or not 1 <= version <= TOM_SCHEMA:
                raise ResultsFileError(
                    f"{p}: schema_version = {version if version is not None else f.attrs.get('schema_version')!r}, "
                    f"this fracas reads 1 to {TOM_SCHEMA}"
                )
            c = Checked(f, p, ResultsFileError, verify=verify)
            if not isinstance(f.get("tom"), h5py.Group):
                raise c.fail("tom", "missing, expected a group")
            g = f["tom"]
            names = c.strs("tom/controls/names")
            tnames = c.strs("tom/targets/names")
            m, n = len(names), len(tnames)
            k = c.num("tom/history/iteration", (None,), integer=True).shape[0]
            out: dict[str, Any] = {
                "path": str(p),
                "attrs": {key: (v.decode() if isinstance(v, bytes) else v) for key, v in g.attrs.items()},
                "control_names": names,
                "control_units": c.strs("tom/controls/units", m),
                "u_start": c.num("tom/controls/start", (m,)),
                "u_final": c.num("tom/controls/final", (m,)),
                "lower": c.num("tom/controls/lower", (m,)),
                "upper": c.num("tom/controls/upper", (m,)),
                "target_names": tnames,
                "target_bodies": c.strs("tom/targets/bodies", n),
                "target_units": c.strs("tom/targets/units", n),
                "desired": c.num("tom/targets/desired", (n,)),
                "tolerance": c.num("tom/targets/tolerance", (n,)),
                "achieved_start": c.num("tom/targets/achieved_start", (n,)),
                "achieved": c.num("tom/targets/achieved", (n,)),
                "initial_mass_kg": c.scalar("tom/mass/initial_kg"),
                "start_mass_kg": c.scalar("tom/mass/start_kg", finite=False),
                "final_mass_kg": c.scalar("tom/mass/final_kg", finite=False),
                "iteration": c.num("tom/history/iteration", (k,), integer=True),
                "submode": c.strs("tom/history/submode", k),
                "performance_kg": c.num("tom/history/performance_kg", (k,)),
                "error_rms": c.num("tom/history/error_rms", (k,)),
                "angle_rad": c.num("tom/history/angle_rad", (k,)),
                "gamma": c.num("tom/history/gamma", (k,)),
                "n_trajectories": c.num("tom/history/n_trajectories", (k,), integer=True),
                "controls": c.num("tom/history/controls", (k, m)),
                "targets": c.num("tom/history/targets", (k, n)),
                "grid": None,
                "performance_name": str(g.attrs.get("performance", "final_mass")),
                "performance_unit": str(g.attrs.get("performance_unit", "kg")),
                "performance_start": float(g.attrs.get("performance_start", np.nan)),
                "performance_final": float(g.attrs.get("performance_final", np.nan)),
            }
            if "trials" in g["history"]:
                out["trials"] = c.num("tom/history/trials", (None, 6))
            if "sensitivities" in g:
                out["S"] = c.num("tom/sensitivities/S", (n, m))
                out["G"] = c.num("tom/sensitivities/G", (m,))
            if "grid" in g:
                gammas = c.num("tom/grid/gammas", (None,))
                j = gammas.shape[0]
                pairs = {}
                for key in g["grid"]:
                    if key.startswith("pair_"):
                        a, b = (int(s) for s in key[5:].split("_"))
                        pairs[(a, b)] = c.num(f"tom/grid/{key}", (j, j))
                out["grid"] = {"single": c.num("tom/grid/single", (m, j)), "gammas": gammas, "pairs": pairs}
            return out
    except OSError as exc:
        raise ResultsFileError(f"{p}: cannot read as HDF5 ({one_line(exc)}), expected a TOM results file") from None
