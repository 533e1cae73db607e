"""PNG plots of the guidance events, the control covariance and the error budget of a TEAM
results file (``r``, :func:`fracas.io.team_results.read_team_results`'s dict; only its
optional keys ``guidance``, ``control`` and ``budget``): B-plane error ellipses
(:func:`bplane_figure`), the correlation matrix at the first eigenvector event
(:func:`correlation_figure`), the error budget (:func:`budget_figure`) and the ΔV
statistics per guidance event (:func:`dv_figure`); :func:`fracas.report.team.plot_all`
writes them all.  A results file without those keys gives no figure (None).

Units as in the printout (:mod:`fracas.report.guidance`): ΔV in ``dv_unit``, other
velocities in ``velocity_unit``.  Everything public here is re-exported by
:mod:`fracas.report.guidance`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from fracas.constants import DAY_S
from fracas.report._tables import _dv, _fmt, _output_unit

# ---------------------------------------------------------------------------------------------
# plots


def ellipse_points(cov2: Any, k: float = 1.0, n: int = 361) -> np.ndarray:
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


def _plt() -> Any:
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


def _semi_major(C: Any) -> float:
    lam = np.linalg.eigvalsh(0.5 * (np.asarray(C) + np.asarray(C).T))
    return float(np.sqrt(max(lam.max(), 0.0)))


def bplane_figure(r: dict, n: int = 361) -> Any:
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


def correlation_figure(r: dict) -> Any:
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


def budget_figure(r: dict, velocity_unit: str = "mm/s", dv_unit: str = "m/s") -> Any:
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


def dv_figure(r: dict, dv_unit: str = "m/s") -> Any:
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


def mark_guidance(r: dict, axes: Any) -> None:
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


def save_figure(fig: Any, path: str | Path) -> Path:
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
