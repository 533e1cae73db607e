"""The short forms of a TEAM results file (``r``, :func:`fracas.io.team_results.read_team_results`'s
dict): a JSON-able summary (:func:`summary_dict`, ``fracas run --json``), the one-line
summary of ``--quiet`` (:func:`quiet_line`) and the line stating the process noise a run
applied (:func:`process_noise_line`).  Re-exported by :mod:`fracas.report.team`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fracas.constants import DAY_S
from fracas.report._tables import _vfactor


def summary_dict(r: dict) -> dict:
    """A JSON-able summary of a TEAM results file (``fracas run --json``)."""
    at = r["attrs"]
    m = r["measurements"]
    used = np.asarray(m["used"], dtype=bool)

    def block(h: dict) -> dict[str, Any]:
        sig = np.asarray(h["sigma"][-1])
        return {
            "position_rss_km": float(np.sqrt(np.sum(sig[:3] ** 2))),
            "velocity_rss_km_s": float(np.sqrt(np.sum(sig[3:6] ** 2))),
            "sigma": dict(zip(r["labels"], map(float, sig))),
        }

    out = {
        "title": str(at["title"]),
        "filter": str(at["filter"]),
        "propagation": str(at["propagation"]),
        "reference": str(at["reference"]),
        "events": int(len(r["times_s"])),
        "measurements_used": int(used.sum()),
        "measurements_skipped": int((~used).sum()),
        "final_time_days": float(r["times_s"][-1] / DAY_S),
        "assumed": block(r["assumed"]),
        "psd_problems": len(r["psd_problems"]),
        "status": int(at.get("status", 0)),
        "status_text": str(at.get("status_text", "")),
        "timing_s": {k: round(float(v), 4) for k, v in r["timing"].items()},
    }
    if "true" in r:
        out["true"] = block(r["true"])
    out["file"] = r["path"]
    return out


def quiet_line(r: dict, velocity_unit: str = "mm/s", file_label: str = "written") -> str:
    """The one-line summary (``--quiet``): events, measurements used, final assumed RSS, file
    (``file_label``: "written" after a run, the file's kind when a report reads it)."""
    s = summary_dict(r)
    v = s["assumed"]["velocity_rss_km_s"] * _vfactor(velocity_unit)
    line = (
        f"{s['events']} events, {s['measurements_used']} measurements; final assumed RSS "
        f"{s['assumed']['position_rss_km']:.4g} km, {v:.4g} {velocity_unit}; {file_label}: {r['path']}"
    )
    return line


def process_noise_line(at: Any) -> str:
    """The process noise the run applied (the filter's model; issue 24), in one line: the
    Gauss-Markov thrust noise by component (1-sigma, tau), white acceleration noise, and how
    it was propagated (PHI's model, or PDOT with its RK4 steps).  Empty without any noise."""
    sig = np.ravel(np.asarray(at.get("thrust_noise_sigma", []), float))
    tau = np.ravel(np.asarray(at.get("thrust_noise_tau_s", []), float))
    q = float(at.get("white_noise_km2_s3", 0.0) or 0.0)
    parts = []
    if sig.size == 3 and np.any(sig > 0):
        # one 80-column line: proportionality ("scale"), in-plane and out-of-plane pointing
        names = ("scale", "in", "out")
        scale = (1.0, np.degrees(1.0), np.degrees(1.0))
        unit = ("", "°", "°")
        comps = [
            f"{n} {sig[i] * scale[i]:.3g}{unit[i]}/{tau[i] / DAY_S:.3g} d" for i, n in enumerate(names) if sig[i] > 0
        ]
        parts.append("thrust 1σ/τ: " + ", ".join(comps))
    if q > 0:
        parts.append(f"white {q:.3g} km²/s³ {at.get('white_noise_direction', 'full')}")
    if not parts:
        return ""
    how = str(at.get("process_noise", ""))
    if how in ("grid", "interval") and sig.size == 3 and np.any(sig > 0):
        # FRACAS's effective Q̃, approximate (docs/team_results.md); as short as the old names
        how = {"grid": "DYNO", "interval": "DYNO int"}[how]
    if how == "pdot":
        lo, hi = at.get("pdot_step_min_s"), at.get("pdot_step_max_s")
        how = "PDOT" + (f" steps {float(lo):.3g}-{float(hi):.3g} s" if lo is not None else "")
    return f"noise ({how}) " + "; ".join(parts)
