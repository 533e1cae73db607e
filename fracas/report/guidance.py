"""Guidance events, the control covariance and the error budget of a TEAM results file:
terminal tables and PNG plots.

Reads the dict of :func:`fracas.io.team_results.read_team_results` (``r``) and only its
optional keys ``r["guidance"]`` (one dict per guidance event), ``r["control"]`` (the
control covariance, actual minus reference) and ``r["budget"]`` (the error budget); a
results file without them (older files, runs without guidance) prints and plots nothing
here.  Tables fit ``width`` columns (80 by default, like :mod:`fracas.report.team`).

Units: ΔV in ``dv_unit`` (m/s unless told), other velocities in ``velocity_unit`` (the
printout's), every other quantity in the unit the file gives it.

Plots: the knowledge history (:func:`fracas.report.team.plot_team`,
with the guidance events marked and the control 1σ), B-plane error ellipses
(:func:`bplane_figure`), the correlation matrix at the first eigenvector event
(:func:`correlation_figure`), the error budget (:func:`budget_figure`) and the ΔV
statistics per guidance event (:func:`dv_figure`); :func:`fracas.report.team.plot_all`
writes them all.  The plots live in :mod:`fracas.report.guidance_plots` and are
re-exported here; this module holds the tables.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from fracas.constants import DAY_S
from fracas.report._tables import _dv, _fmt, _num_col, _output_unit, _table, _text_col, _unit
from fracas.report.guidance_plots import (
    _bplane_events,  # noqa: F401  (re-exported: tests read it here)
    bplane_block,
    bplane_figure,
    budget_figure,
    correlation_figure,
    dv_figure,
    ellipse_points,
    first_eigenvector_event,
    mark_guidance,
    save_figure,
)

__all__ = [
    "print_guidance",
    "print_budget",
    "guidance_table",
    "target_table",
    "control_table",
    "budget_rows",
    "budget_tables",
    "ellipse_points",
    "bplane_block",
    "bplane_figure",
    "correlation_figure",
    "first_eigenvector_event",
    "budget_figure",
    "dv_figure",
    "mark_guidance",
    "save_figure",
    "running_mean_dv",
    "BUDGET_TOP",
]

#: sources listed per output at the normal level (the rest summed as "others")
BUDGET_TOP = 5
_SHORT_TYPE = {"impulsive": "impulsive", "primary": "primary", "vernier": "vernier", "none": "none"}
_LOW_THRUST = ("primary", "vernier")
_DV_FOOTNOTE = (
    "Σ mean: running sum of the mean |ΔV|; means add, RMS and 99 % values do not (the RMS of a "
    "sum is not the sum of the RMS). Low thrust: |ΔV| of the change of the arc's ΔV."
)


# ---------------------------------------------------------------------------------------------
# tables


def _sigmas(C: Any, n: int | None = None) -> np.ndarray:
    """1σ from the diagonal of a covariance (NaN where non-finite, negative diagonals as 0;
    ``n`` NaN where the covariance is missing)."""
    if C is None or np.ndim(C) != 2 or (n is not None and np.shape(C)[0] < n):
        return np.full(n or 0, math.nan)
    d = np.diag(np.asarray(C, dtype=float))
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(d), np.sqrt(np.clip(d, 0.0, None)), np.nan)


def running_mean_dv(guidance: list[dict]) -> np.ndarray:
    """Running sum of the events' mean |ΔV| (km/s; an event without a finite mean adds 0)."""
    m = np.array([float(g.get("dv_mean_km_s", math.nan)) for g in guidance], dtype=float)
    return np.cumsum(np.where(np.isfinite(m), m, 0.0))


def guidance_table(r: dict, dv_unit: str = "m/s") -> Any:
    """The guidance events: name, type, time, targets, rank, mean and 99 % |ΔV| and the
    running sum of the mean |ΔV| (a :class:`rich.table.Table`), or None without guidance."""
    from rich.markup import escape

    gs = r.get("guidance") or []
    if not gs:
        return None
    t = _table(f"guidance events (ΔV in {dv_unit})")
    _text_col(t, "event")
    _text_col(t, "type")
    _num_col(t, "t (d)")
    _text_col(t, "targets")
    _num_col(t, "rank")
    _num_col(t, "mean\n|ΔV|")
    _num_col(t, "99 %\n|ΔV|")
    _num_col(t, "Σ mean\n|ΔV|")
    total = running_mean_dv(gs)
    for g, s in zip(gs, total):
        t.add_row(
            escape(str(g["name"])),
            _SHORT_TYPE.get(str(g["type"]), escape(str(g["type"]))),
            f"{float(g['time_s']) / DAY_S:.4f}",
            escape(" ".join(map(str, g.get("target_names", [])))),
            str(int(g.get("rank", 0))),
            _fmt(_dv(g.get("dv_mean_km_s", math.nan), dv_unit)),
            _fmt(_dv(g.get("dv_99_km_s", math.nan), dv_unit)),
            _fmt(_dv(s, dv_unit)),
        )
    t.caption = _DV_FOOTNOTE
    t.caption_justify = "left"
    return t


def target_table(g: dict, velocity_unit: str = "mm/s") -> Any:
    """Target 1σ of one guidance event at the target time: the actual dispersion without
    the correction and after it (both with the process noise from the cutoff to the target
    time), the knowledge at the event mapped to the target, and that noise alone ("noise";
    blank for a file written before it existed, whose before/after lack it), each in the
    target's unit."""
    from rich.markup import escape

    t = _table(escape(f"{g['name']}: target 1σ at the target time"), boxed=False)
    _text_col(t, "target")
    _text_col(t, "unit")
    _num_col(t, "before")
    _num_col(t, "after")
    _num_col(t, "knowledge")
    _num_col(t, "noise")
    m = len(g.get("target_names", []))
    keys = ("target_cov_before", "target_cov_after", "target_cov_knowledge", "target_noise_cov")
    sb, sa, sk, sn = (_sigmas(g.get(k), m) for k in keys)
    for i, name in enumerate(g.get("target_names", [])):
        f, u = _unit(g["target_units"][i], velocity_unit)
        noise = _fmt(sn[i] * f) if np.isfinite(sn[i]) else ""
        t.add_row(escape(str(name)), escape(u), _fmt(sb[i] * f), _fmt(sa[i] * f), _fmt(sk[i] * f), noise)
    return t


def control_table(g: dict, dv_unit: str = "m/s") -> Any:
    """Correction and execution 1σ of one guidance event's controls (ΔV components in
    ``dv_unit``, low-thrust controls in their units)."""
    from rich.markup import escape

    t = _table(escape(f"{g['name']}: correction 1σ per control"), boxed=False)
    _text_col(t, "control")
    _text_col(t, "unit")
    _num_col(t, "correction")
    _num_col(t, "execution")
    m = len(g.get("control_labels", []))
    sc, se = _sigmas(g.get("correction_cov"), m), _sigmas(g.get("execution_cov"), m)
    for i, lab in enumerate(g.get("control_labels", [])):
        f, u = _unit(g["control_units"][i], dv_unit)
        t.add_row(escape(str(lab)), escape(u), _fmt(sc[i] * f), _fmt(se[i] * f))
    return t


def budget_rows(r: dict, i: int, top: int | None = None) -> list[tuple[str, float, float, float]]:
    """Sources of output ``i`` ranked by their contribution to its variance (largest first):
    (source, variance, σ-equivalent, % of the run's total variance), in the file's units.

    σ-equivalent: sqrt(variance), signed (a negative contribution, from rounding, keeps its
    sign).  ``top``: keep that many and sum the rest into one row ``"others (N)"``."""
    b = r["budget"]
    var = np.asarray(b["variance"], dtype=float)[i]
    total = float(np.asarray(b["total"], dtype=float)[i])
    order = np.argsort(-var, kind="stable")

    def row(name: str, v: float) -> tuple[str, float, float, float]:
        pct = 100.0 * v / total if total != 0 and np.isfinite(total) else math.nan
        return (name, float(v), float(math.copysign(math.sqrt(abs(v)), v)) if np.isfinite(v) else math.nan, pct)

    rows = [row(str(b["sources"][j]), var[j]) for j in order]
    if top is not None and len(rows) > top + 1:
        rest = var[order[top:]]
        rows = rows[:top] + [row(f"others ({len(rest)})", float(np.sum(rest)))]
    return rows


def budget_summary_table(r: dict, velocity_unit: str = "mm/s", dv_unit: str = "m/s", n_top: int = 2) -> Any:
    """The budget in one table (the normal printout): per output its 1σ and its ``n_top``
    largest sources with their % of the variance."""
    from rich.markup import escape

    b = r["budget"]
    t = _table("error budget (largest sources, % of variance; --verbose: every source)", boxed=False)
    _text_col(t, "output")
    _num_col(t, "1σ")
    _text_col(t, "unit")
    for j in range(n_top):
        _text_col(t, f"source {j + 1}")
    totals = np.asarray(b["total"], dtype=float)
    for i, name in enumerate(b["outputs"]):
        f, u = _output_unit(str(name), str(b["units"][i]), velocity_unit, dv_unit)
        tot = totals[i]
        sig = math.sqrt(tot) * f if np.isfinite(tot) and tot >= 0 else math.nan
        rows = budget_rows(r, i)[:n_top]
        cells = [escape(f"{src} {pct:.0f}%") if np.isfinite(pct) else escape(src) for src, _v, _s, pct in rows]
        cells += [""] * (n_top - len(cells))
        t.add_row(escape(str(name)), _fmt(sig), u, *cells)
    return t


def budget_tables(
    r: dict, verbosity: str = "normal", velocity_unit: str = "mm/s", dv_unit: str = "m/s"
) -> tuple[list, str | None]:
    """The budget's tables and the sum-check line; ([], None) without a budget.  Normal: one
    summary table (:func:`budget_summary_table`); verbose: one table per output, its sources
    ranked (σ-equivalent in the output's unit and % of the total variance)."""
    from rich.markup import escape

    b = r.get("budget")
    if not b or not len(b.get("outputs", [])):
        return [], None
    top = None if verbosity == "verbose" else BUDGET_TOP
    tables = []
    totals = np.asarray(b["total"], dtype=float)
    if verbosity == "normal":
        tables.append(budget_summary_table(r, velocity_unit, dv_unit))
    for i, name in enumerate(b["outputs"] if verbosity == "verbose" else []):
        f, u = _output_unit(str(name), str(b["units"][i]), velocity_unit, dv_unit)
        tot = totals[i]
        sig = math.sqrt(tot) * f if np.isfinite(tot) and tot >= 0 else math.nan
        t = _table(escape(f"error budget: {name}"), boxed=False)
        _text_col(t, "source")
        _num_col(t, f"1σ-equiv. ({u})")
        _num_col(t, "% of variance")
        for src, _v, s, pct in budget_rows(r, i, top):
            t.add_row(escape(src), _fmt(s * f), f"{pct:.2f}" if np.isfinite(pct) else "nan")
        t.add_row("total (run)", _fmt(sig), "100.00", end_section=False)
        tables.append(t)
    chk = float(b.get("sum_check", math.nan))
    line = f"error budget sum check: max |Σ contributions - total| / total = {chk:.3g}"
    if not (np.isfinite(chk) and chk <= 1e-6):
        line = "[yellow]warning:[/yellow] " + escape(line) + " (the sources do not add up to the run)"
    return tables, line


def _heading(g: dict) -> str:
    return (
        f"{g['name']} ({g['type']}) at {float(g['time_s']) / DAY_S:.4f} d, cutoff "
        f"{float(g.get('cutoff_s', math.nan)) / DAY_S:.4f} d: target {g.get('target_body', '')} at "
        f"{float(g.get('target_time_s', math.nan)) / DAY_S:.4f} d, estimate {g.get('estimate_model', '')}"
    )


def print_guidance(
    r: dict, con: Any, *, verbosity: str = "normal", velocity_unit: str = "mm/s", dv_unit: str = "m/s"
) -> None:
    """Print the guidance events (:func:`guidance_table`), each event's target 1σ and, for
    low thrust (every event at ``"verbose"``), its controls; nothing at ``"quiet"`` or
    without guidance."""
    from rich.markup import escape

    gs = r.get("guidance") or []
    if verbosity == "quiet" or not gs:
        return
    con.print(guidance_table(r, dv_unit))
    for g in gs:
        con.print(escape(_heading(g)))
        if len(g.get("target_names", [])):
            con.print(target_table(g, velocity_unit))
        low = str(g["type"]) in _LOW_THRUST
        if len(g.get("control_labels", [])) and (low or verbosity == "verbose"):
            con.print(control_table(g, dv_unit))
        if low:
            con.print(
                escape(
                    f"{g['name']}: ΔV σ (rms of the change of the arc's ΔV) "
                    f"{_fmt(_dv(g.get('dv_rms_km_s', math.nan), dv_unit))} {dv_unit}; propellant σ "
                    f"{_fmt(float(g.get('propellant_sigma_kg', math.nan)))} kg"
                )
            )
        elif verbosity == "verbose" and str(g["type"]) == "impulsive":
            con.print(escape(f"{g['name']}: |ΔV| rms {_fmt(_dv(g.get('dv_rms_km_s', math.nan), dv_unit))} {dv_unit}"))
        st = int(g.get("status", 0))
        if st:
            con.print(f"[red]warning:[/red] guidance event {escape(str(g['name']))}: status {st}")


def print_budget(
    r: dict, con: Any, *, verbosity: str = "normal", velocity_unit: str = "mm/s", dv_unit: str = "m/s"
) -> None:
    """Print the error budget (:func:`budget_tables`); nothing at ``"quiet"`` or without one."""
    if verbosity == "quiet":
        return
    tables, line = budget_tables(r, verbosity, velocity_unit, dv_unit)
    for t in tables:
        con.print(t)
    if line:
        con.print(line)
