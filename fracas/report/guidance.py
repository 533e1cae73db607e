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
writes them all.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from fracas.constants import DAY_S
from fracas.report._tables import _fmt, _num_col, _table, _text_col, _unit, _vfactor

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


def _dv(x_km_s: float, dv_unit: str) -> float:
    return float(x_km_s) * _vfactor(dv_unit)


def _sigmas(C, n: int | None = None) -> np.ndarray:
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


def guidance_table(r: dict, dv_unit: str = "m/s"):
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


def target_table(g: dict, velocity_unit: str = "mm/s"):
    """Target 1σ of one guidance event: before the correction (actual dispersion), after it,
    and the knowledge mapped to the target, each in the target's unit."""
    from rich.markup import escape

    t = _table(escape(f"{g['name']}: target 1σ"), boxed=False)
    _text_col(t, "target")
    _text_col(t, "unit")
    _num_col(t, "before")
    _num_col(t, "after")
    _num_col(t, "knowledge")
    m = len(g.get("target_names", []))
    sb, sa, sk = (_sigmas(g.get(k), m) for k in ("target_cov_before", "target_cov_after", "target_cov_knowledge"))
    for i, name in enumerate(g.get("target_names", [])):
        f, u = _unit(g["target_units"][i], velocity_unit)
        t.add_row(escape(str(name)), escape(u), _fmt(sb[i] * f), _fmt(sa[i] * f), _fmt(sk[i] * f))
    return t


def control_table(g: dict, dv_unit: str = "m/s"):
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


def _output_unit(name: str, unit: str, velocity_unit: str, dv_unit: str) -> tuple[float, str]:
    """(factor, unit shown) of a budget output: a ΔV (name with "dv"/"ΔV") in km/s goes to
    ``dv_unit``, another velocity to ``velocity_unit``."""
    if unit == "km/s" and ("dv" in name.lower() or "δv" in name.lower()):
        return _vfactor(dv_unit), dv_unit
    return _unit(unit, velocity_unit)


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


def budget_summary_table(r: dict, velocity_unit: str = "mm/s", dv_unit: str = "m/s", n_top: int = 2):
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


def budget_tables(r: dict, verbosity: str = "normal", velocity_unit: str = "mm/s", dv_unit: str = "m/s"):
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


def print_guidance(r: dict, con, *, verbosity: str = "normal", velocity_unit: str = "mm/s", dv_unit: str = "m/s"):
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


def print_budget(r: dict, con, *, verbosity: str = "normal", velocity_unit: str = "mm/s", dv_unit: str = "m/s"):
    """Print the error budget (:func:`budget_tables`); nothing at ``"quiet"`` or without one."""
    if verbosity == "quiet":
        return
    tables, line = budget_tables(r, verbosity, velocity_unit, dv_unit)
    for t in tables:
        con.print(t)
    if line:
        con.print(line)


# ---------------------------------------------------------------------------------------------
# plots


def ellipse_points(cov2, k: float = 1.0, n: int = 361) -> np.ndarray:
    """``n`` points (n, 2) of the k-σ ellipse {x : xᵀ C⁻¹ x = k²} of a 2×2 covariance ``C``,
    centred on 0: ``k V diag(sqrt λ) (cos θ, sin θ)`` with θ from 0 to 2π (closed) and
    ``C = V diag(λ) Vᵀ``; semi-axes k·sqrt(λ).  Negative eigenvalues (rounding) count as 0."""
    C = np.asarray(cov2, dtype=float)
    if C.shape != (2, 2):
        raise ValueError(f"ellipse_points: expected a 2x2 covariance, got shape {C.shape}")
    lam, V = np.linalg.eigh(0.5 * (C + C.T))
    th = np.linspace(0.0, 2.0 * np.pi, n)
    circle = np.stack([np.cos(th), np.sin(th)])
    return (k * (V * np.sqrt(np.clip(lam, 0.0, None))) @ circle).T


def bplane_block(g: dict, key: str) -> np.ndarray:
    """The 2×2 (B·T, B·R) block of covariance ``g[key]`` of a guidance event."""
    names = list(g["target_names"])
    ij = [names.index("b_dot_t"), names.index("b_dot_r")]
    return np.asarray(g[key], dtype=float)[np.ix_(ij, ij)]


def _bplane_events(r: dict) -> list[dict]:
    return [g for g in r.get("guidance") or [] if {"b_dot_t", "b_dot_r"} <= set(g.get("target_names", []))]


_BPLANE = (
    ("target_cov_knowledge", "knowledge", "tab:green"),
    ("target_cov_before", "before correction", "tab:red"),
    ("target_cov_after", "after correction", "tab:blue"),
)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _wrapped(head: str, title: str, width_in: float, fontsize: float = 10.0) -> str:
    """``head: title`` broken into lines that fit ``width_in`` inches at ``fontsize`` points
    (a title never runs off the figure)."""
    import textwrap

    chars = max(20, int(width_in * 72.0 / (0.55 * fontsize)))
    return "\n".join(textwrap.wrap(f"{head}: {title}" if title else head, chars))


#: the inset zooms on the knowledge ellipses when they are this many times smaller than the axes
_ZOOM_RATIO = 6.0


def _semi_major(C) -> float:
    lam = np.linalg.eigvalsh(0.5 * (np.asarray(C) + np.asarray(C).T))
    return float(np.sqrt(max(lam.max(), 0.0)))


def bplane_figure(r: dict, n: int = 361):
    """B-plane error ellipses (1σ solid, 3σ dashed) of the knowledge and of the dispersion
    before and after the correction of every guidance event that targets B·T and B·R, on
    B·T / B·R axes centred on the reference aim point; where the knowledge and after-
    correction ellipses are much smaller than the dispersion before it, an inset zooms on
    the aim point.  A matplotlib figure, or None."""
    gs = _bplane_events(r)
    if not gs:
        return None
    plt = _plt()
    from matplotlib.ticker import MaxNLocator

    cols = min(len(gs), 3)
    rows = math.ceil(len(gs) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.4 * cols, 5.4 * rows + 0.4), squeeze=False, layout="constrained")
    for ax, g in zip(axes.flat, gs):
        names = list(g["target_names"])
        ut = g["target_units"][names.index("b_dot_t")]
        ur = g["target_units"][names.index("b_dot_r")]
        drawn = []
        for key, label, color in _BPLANE:
            if g.get(key) is None:
                continue
            C = bplane_block(g, key)
            if not np.all(np.isfinite(C)):
                continue
            drawn.append((key, C, color))
            for k, style in ((1.0, "-"), (3.0, "--")):
                p = ellipse_points(C, k, n)
                ax.plot(p[:, 0], p[:, 1], style, color=color, label=f"{label} {k:g}σ")
        ax.plot([0.0], [0.0], "k+", label="reference aim point")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel(f"B·T deviation ({ut})")
        ax.set_ylabel(f"B·R deviation ({ur})")
        ax.set_title(
            _wrapped(g["name"], f"{float(g['time_s']) / DAY_S:.3f} d ({g.get('target_body', '')})", 5.0), fontsize=10
        )
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
        outer = max((_semi_major(C) for _k, C, _c in drawn), default=0.0)
        small = [(k, C, c) for k, C, c in drawn if k != "target_cov_before"]
        inner = max((_semi_major(C) for _k, C, _c in small), default=0.0)
        if small and inner > 0 and outer / inner >= _ZOOM_RATIO:
            ins = ax.inset_axes([0.58, 0.03, 0.39, 0.39])
            for _key, C, color in small:
                for k, style in ((1.0, "-"), (3.0, "--")):
                    p = ellipse_points(C, k, n)
                    ins.plot(p[:, 0], p[:, 1], style, color=color, lw=1.0)
            ins.plot([0.0], [0.0], "k+")
            lim = 3.3 * inner
            ins.set_xlim(-lim, lim)
            ins.set_ylim(-lim, lim)
            ins.set_aspect("equal")
            ins.tick_params(labelsize=6)
            ins.xaxis.set_major_locator(MaxNLocator(3, symmetric=True))
            ins.yaxis.set_major_locator(MaxNLocator(3, symmetric=True))
            ins.grid(True, alpha=0.3)
            ins.set_title(f"zoom on the aim point (×{outer / inner:.0f})", fontsize=7)
            ax.indicate_inset_zoom(ins, edgecolor="0.3")
    for ax in list(axes.flat)[len(gs) :]:
        ax.set_visible(False)
    fig.suptitle(_wrapped("B-plane dispersion", r["attrs"]["title"], 5.4 * cols, 12), fontsize="medium")
    return fig


def first_eigenvector_event(r: dict, h: dict) -> int:
    """Row of ``h["eigenvector_events"]`` at the first schedule event of type
    ``eigenvector`` (else the first row: a thrust switch or the final event)."""
    idx = [int(k) for k in h["eigenvector_events"]["index"]]
    for i, k in enumerate(idx):
        if "eigenvector" in str(r["event_types"][k]).split("+"):
            return i
    return 0


def correlation_figure(r: dict):
    """Heatmap of the correlation matrix (with the labels) at the first eigenvector event
    (:func:`first_eigenvector_event`), assumed and (generalized covariance) true side by
    side; a figure, or None without eigenvector events."""
    hs = [(w, r[w]) for w in ("assumed", "true") if w in r]
    hs = [(w, h) for w, h in hs if len(h["eigenvector_events"]["index"])]
    if not hs:
        return None
    plt = _plt()
    labels = r["labels"]
    m = len(labels)
    side = 0.38 * m + 1.5
    fig, axes = plt.subplots(
        1, len(hs), figsize=(side * len(hs) + 2.5, side + 2.5), squeeze=False, layout="constrained"
    )
    im = None
    for j, (ax, (w, h)) in enumerate(zip(axes.flat, hs)):
        eg = h["eigenvector_events"]
        i = first_eigenvector_event(r, h)
        k = int(eg["index"][i])
        im = ax.imshow(np.asarray(eg["correlations"][i], dtype=float), cmap="RdBu_r", vmin=-1.0, vmax=1.0)
        ax.set_xticks(range(m), labels, rotation=90, fontsize=7)
        ax.set_yticks(range(m), labels if j == 0 else [""] * m, fontsize=7)
        ax.set_title(f"{w} at t = {r['times_s'][k] / DAY_S:.4f} d", fontsize=10)
    fig.colorbar(im, ax=list(axes.flat), shrink=0.8, label="correlation coefficient (1)")
    fig.suptitle(
        _wrapped("correlations at the first eigenvector event", r["attrs"]["title"], side * len(hs) + 2.5, 12),
        fontsize="medium",
    )
    return fig


def budget_figure(r: dict, velocity_unit: str = "mm/s", dv_unit: str = "m/s"):
    """One horizontal stacked bar per budget output: % of its variance by source, each
    output labelled with its 1σ in the printout's units (ΔV in ``dv_unit``, other
    velocities in ``velocity_unit``, as :func:`budget_tables`); or None."""
    b = r.get("budget")
    if not b or not len(b.get("outputs", [])):
        return None
    plt = _plt()
    var = np.asarray(b["variance"], dtype=float)
    tot = np.asarray(b["total"], dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        pct = np.clip(100.0 * var / tot[:, None], 0.0, None)
    pct = np.where(np.isfinite(pct), pct, 0.0)
    n_out, n_src = var.shape
    fig, ax = plt.subplots(figsize=(10, 1.6 + 0.5 * n_out + 0.2 * n_src), layout="constrained")
    cmap = plt.get_cmap("tab20" if n_src > 10 else "tab10")
    y = np.arange(n_out)
    left = np.zeros(n_out)
    for j, src in enumerate(b["sources"]):
        ax.barh(y, pct[:, j], left=left, color=cmap(j % cmap.N), label=str(src))
        left += pct[:, j]
    labels = []
    for i, o in enumerate(b["outputs"]):
        f, u = _output_unit(str(o), str(b["units"][i]), velocity_unit, dv_unit)
        sig = math.sqrt(tot[i]) * f if np.isfinite(tot[i]) and tot[i] >= 0 else math.nan
        labels.append(f"{o}\n1σ {_fmt(sig)} {u}")
    ax.set_yticks(y, labels, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("share of the output's variance (%)")
    ax.set_xlim(0, max(100.0, float(left.max()) if n_out else 100.0))
    ax.grid(True, axis="x", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), title="source", title_fontsize=7)
    chk = float(b.get("sum_check", math.nan))
    ax.set_title(_wrapped(f"error budget (sum check {chk:.2g})", r["attrs"]["title"], 7.0), fontsize=10)
    return fig


def dv_figure(r: dict, dv_unit: str = "m/s"):
    """Mean and 99 % |ΔV| (``dv_unit``, the printout's) of each guidance event, bars; or None
    without guidance."""
    gs = r.get("guidance") or []
    if not gs:
        return None
    plt = _plt()
    x = np.arange(len(gs))
    mean = np.array([_dv(g.get("dv_mean_km_s", math.nan), dv_unit) for g in gs])
    p99 = np.array([_dv(g.get("dv_99_km_s", math.nan), dv_unit) for g in gs])
    width = max(6.0, 1.2 * len(gs) + 2.0)
    fig, ax = plt.subplots(figsize=(width, 4.4), layout="constrained")
    w = 0.38
    ax.bar(x - w / 2, np.nan_to_num(mean), w, label="mean |ΔV|")
    ax.bar(x + w / 2, np.nan_to_num(p99), w, label="99 % |ΔV|")
    ax.set_xticks(x, [f"{g['name']}\n({g['type']})" for g in gs], fontsize=8)
    ax.set_ylabel(f"|ΔV| ({dv_unit})")
    ax.set_xlabel("guidance event")
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(_wrapped("ΔV statistics per guidance event", r["attrs"]["title"], width - 0.8), fontsize=10)
    return fig


def mark_guidance(r: dict, axes) -> None:
    """Vertical lines at the guidance events (days), named on the first axis."""
    gs = r.get("guidance") or []
    for i, ax in enumerate(axes):
        for g in gs:
            t = float(g["time_s"]) / DAY_S
            ax.axvline(t, color="0.4", lw=0.8, ls="-.", zorder=0)
            if i == 0:
                ax.text(
                    t,
                    1.0,
                    f" {g['name']}",
                    transform=ax.get_xaxis_transform(),
                    rotation=90,
                    va="top",
                    ha="right",
                    fontsize=7,
                    color="0.3",
                )


def save_figure(fig, path: str | Path) -> Path:
    """Write ``fig`` as a PNG at ``path`` atomically and close it; returns the path."""
    from fracas.io.atomic import savefig_atomic

    plt = _plt()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        savefig_atomic(fig, path, dpi=110, format="png")
    finally:
        plt.close(fig)
    return path
