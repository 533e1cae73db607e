"""TSIM report: the terminal summary (80 columns) and the target-plane, ΔV and target-error
plots, from a :class:`fracas.products.TsimProduct` (:func:`fracas.io.tsim_results.read_tsim_results`).

Only the successful missions (status 0 ok or 1 near success) enter the tables computed from
the per-mission table and the plots; the final target errors use the run's merged
``statistics["target_error"]`` when present (a-priori missions included).

Units: |ΔV| in m/s; target errors in the file's units except velocities, in mm/s (the
TEAM printout's), in the summary and the plots alike."""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

import numpy as np

from fracas.products import TsimProduct
from fracas.report.guidance import ellipse_points

__all__ = ["summary_text", "plot_tsim", "tsim_figures", "successful"]

_MS = 1e3  # m/s per km/s (ΔV in m/s, as in the TEAM printout)
#: target-error units shown: a velocity in mm/s (the TEAM printout's default), the rest as stored
_SHOWN = {"km/s": (1e6, "mm/s")}


def _shown(unit: str) -> tuple[float, str]:
    """(factor, unit shown) of a target error stored in ``unit``."""
    return _SHOWN.get(str(unit), (1.0, str(unit)))


def _scales(product: TsimProduct) -> tuple[np.ndarray, list[str]]:
    pairs = [_shown(u) for u in product.final_target_units]
    return np.array([f for f, _u in pairs], dtype=float), [u for _f, u in pairs]


_BPLANE = {"b_dot_t": "B·T", "b_dot_r": "B·R"}


def successful(product: TsimProduct) -> np.ndarray:
    """Boolean mask (N,) of the successful missions (status 0 or 1)."""
    status = np.asarray(product.table.get("status", np.zeros(0, np.int32)))
    return (status == 0) | (status == 1)


def _g(x: float, width: int = 10) -> str:
    if x is None or not np.isfinite(x):
        return f"{'-':>{width}}"
    return f"{x:{width}.4g}"


def _pct(x: np.ndarray, q: float) -> float:
    return float(np.percentile(x, q)) if x.size else float("nan")


def _mean(x: np.ndarray) -> float:
    return float(np.mean(x)) if x.size else float("nan")


def _dv(product: TsimProduct, ok: np.ndarray, j: int) -> np.ndarray:
    dv = product.table.get("dv_km_s")
    if dv is None or np.asarray(dv).ndim != 2 or j >= np.asarray(dv).shape[1]:
        return np.zeros(0)
    x = np.asarray(dv)[ok, j] * _MS
    return x[np.isfinite(x)]


def _target_errors(product: TsimProduct, ok: np.ndarray) -> np.ndarray:
    m = len(product.final_target_names)
    te = product.table.get("target_error")
    if te is None:
        return np.zeros((0, m))
    te = np.asarray(te, float).reshape(-1, m)[ok]
    return te[np.all(np.isfinite(te), axis=1)]


def summary_text(product: TsimProduct, width: int = 80) -> str:
    """The run's summary: missions, per-maneuver ΔV (TSIM vs TEAM), final target errors
    (TSIM vs TEAM) and the consistency verdicts; every line at most ``width`` characters."""
    lines: list[str] = []
    title = product.title or Path(product.source).name
    lines.append(f"TSIM -- {title}"[:width])
    c = product.counts
    n = int(c.get("missions", len(product.table.get("status", ()))))
    line = (
        f"missions {n}: ok {c.get('ok', 0)}, near {c.get('near', 0)}, hopeless {c.get('hopeless', 0)}, "
        f"failed {c.get('failed', 0)}"
    )
    if c.get("a_priori"):
        line += f" (+{c['a_priori']} a priori)"
    lines += textwrap.wrap(line, width)
    ok = successful(product)

    lines.append("")
    lines.append("maneuver |dV| (m/s), successful missions:")
    lines.append(
        f"{'maneuver':<16} {'type':<9} {'law':<9} {'TSIM mean':>10} {'TSIM 99%':>10} {'TEAM mean':>10} {'TEAM 99%':>10}"
    )
    for j, m in enumerate(product.maneuvers):
        x = _dv(product, ok, j)
        lines.append(
            f"{m.name[:16]:<16} {m.type[:9]:<9} {m.law[:9]:<9} {_g(_mean(x))} {_g(_pct(x, 99))} "
            f"{_g(m.team_dv_mean_km_s * _MS)} {_g(m.team_dv_99_km_s * _MS)}"
        )
        if m.failures or m.near:
            lines.append(f"{'':<16} {m.failures} hopeless, {m.near} near success"[:width])

    names = product.final_target_names
    if names:
        stat = product.statistics.get("target_error")
        te = _target_errors(product, ok)
        if stat is not None and int(stat[0]) > 0 and np.asarray(stat[1]).size == len(names):
            count, mean, cov = int(stat[0]), np.asarray(stat[1], float), np.asarray(stat[2], float)
        else:
            count = te.shape[0]
            mean = te.mean(axis=0) if count else np.full(len(names), np.nan)
            cov = np.atleast_2d(np.cov(te, rowvar=False)) if count > 1 else np.full((len(names),) * 2, np.nan)
        f, shown = _scales(product)
        sig = np.sqrt(np.maximum(np.diag(cov), 0.0)) * f
        mean = mean * f
        team = np.sqrt(np.maximum(np.diag(np.asarray(product.team_target_cov, float)), 0.0)) * f
        lines.append("")
        lines.append(f"final target errors ({count} missions):"[:width])
        lines.append(f"{'target':<20} {'unit':<8} {'TSIM mean':>10} {'TSIM sigma':>10} {'TEAM sigma':>10} {'ratio':>8}")
        for i, name in enumerate(names):
            ratio = sig[i] / team[i] if team[i] > 0 else float("nan")
            lines.append(f"{name[:20]:<20} {shown[i][:8]:<8} {_g(mean[i])} {_g(sig[i])} {_g(team[i])} {_g(ratio, 8)}")

    if product.consistency:
        lines.append("")
        lines.append("consistency with TEAM:")
        for row in product.consistency:
            text = f"[{row.get('verdict', '')}] {row.get('message') or row.get('output', '')}"
            lines += textwrap.wrap(text, width, subsequent_indent="    ") or [""]
    return "\n".join(line[:width] for line in lines)


# --------------------------------------------------------------------------- plots


def _ellipse(cov: np.ndarray, k: float, center: Any = (0.0, 0.0), npts: int = 181) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) of the k-sigma ellipse of a 2x2 covariance about ``center`` (report.guidance.ellipse_points)."""
    pts = ellipse_points(cov, k, npts) + np.asarray(center, dtype=float)
    return pts[:, 0], pts[:, 1]


def _label(name: str, unit: str) -> str:
    return f"{_BPLANE.get(name, name)} error ({unit})"


def _empty(ax: Any, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes)


def _wrapped(text: str, width_in: float, fontsize: float = 10.0) -> str:
    chars = max(20, int(width_in * 72.0 / (0.55 * fontsize)))
    return "\n".join(textwrap.wrap(text, chars))


def _target_plane_figure(
    plt: Any, te: np.ndarray, team_cov: np.ndarray, names: list[str], units: list[str], title: str
) -> Any:
    """(a) the target plane: the missions' first two final target errors, TEAM's ellipses."""
    fig, ax = plt.subplots(figsize=(6.5, 6.3), layout="constrained")
    if len(names) >= 2 and te.shape[0]:
        ax.plot(te[:, 0], te[:, 1], ".", ms=3, alpha=0.5, label=f"TSIM ({te.shape[0]} missions)")
        c2 = team_cov[:2, :2]
        for k, ls in ((1, "-"), (3, "-")):
            ax.plot(*_ellipse(c2, k), ls, color="C3" if k == 1 else "C1", lw=1.2, label=f"TEAM {k}σ")
        if te.shape[0] > 2:
            ax.plot(
                *_ellipse(np.cov(te[:, :2], rowvar=False), 1, te[:, :2].mean(axis=0)),
                "--",
                color="k",
                lw=1.0,
                label="TSIM sample 1σ",
            )
        ax.set_xlabel(_label(names[0], units[0]))
        ax.set_ylabel(_label(names[1], units[1]))
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    else:
        _empty(ax, "no successful missions" if len(names) >= 2 else "fewer than two final targets")
    plane = "B-plane" if list(names[:2]) == ["b_dot_t", "b_dot_r"] else "target plane"
    ax.set_title(_wrapped(f"TSIM {plane}: {title}", 6.0), fontsize=10)
    return fig


def _dv_figure(plt: Any, product: TsimProduct, ok: np.ndarray, title: str) -> Any:
    """(b) the ΔV histograms, one per maneuver (m/s), TEAM's and TSIM's mean and 99 %."""
    nj = max(len(product.maneuvers), 1)
    ncol = min(3, nj)
    nrow = (nj + ncol - 1) // ncol
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.8 * ncol, 3.6 * nrow + 1.0), squeeze=False, layout="constrained")
    handles = None
    for j, (ax, m) in enumerate(zip(axes.ravel(), product.maneuvers)):
        x = _dv(product, ok, j)
        if x.size:
            ax.hist(x, bins=min(50, max(10, x.size // 10)), color="C0", alpha=0.6, label="TSIM missions")
            ax.axvline(m.team_dv_mean_km_s * _MS, color="C3", lw=1.5, label="TEAM mean (exact Hoffman-Young stand-in)")
            ax.axvline(m.team_dv_99_km_s * _MS, color="C3", lw=1.5, ls="--", label="TEAM 99 %")
            ax.axvline(_mean(x), color="k", lw=1.2, label="TSIM mean")
            ax.axvline(_pct(x, 99), color="k", lw=1.2, ls="--", label="TSIM 99th percentile")
            handles = handles or ax.get_legend_handles_labels()
        else:
            _empty(ax, "no successful missions")
        ax.set_title(f"{m.name} ({m.type}, {m.law})", fontsize=9)
        ax.set_xlabel("|ΔV| (m/s)")
        ax.set_ylabel("missions (count)")
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(product.maneuvers) :]:
        ax.set_visible(len(product.maneuvers) == 0)
        if not product.maneuvers:
            _empty(ax, "no maneuvers")
    if handles:
        fig.legend(*handles, loc="outside lower center", ncol=3, fontsize=7)
    fig.suptitle(_wrapped(f"TSIM ΔV per maneuver: {title}", 4.8 * ncol, 11), fontsize="medium")
    return fig


def _errors_figure(
    plt: Any, te: np.ndarray, team_cov: np.ndarray, names: list[str], units: list[str], title: str
) -> Any:
    """(c) the final target-error histograms, TEAM's normal density over each."""
    nm = max(len(names), 1)
    ncol = min(3, nm)
    nrow = (nm + ncol - 1) // ncol
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.8 * ncol, 3.6 * nrow + 0.5), squeeze=False, layout="constrained")
    sig = np.sqrt(np.maximum(np.diag(team_cov), 0.0)) if team_cov.size else np.zeros(0)
    for i, (ax, name) in enumerate(zip(axes.ravel(), names)):
        x = te[:, i] if te.shape[0] else np.zeros(0)
        if x.size:
            ax.hist(x, bins=min(50, max(10, x.size // 10)), density=True, color="C0", alpha=0.6, label="TSIM")
            if sig[i] > 0:
                lim = max(4.0 * sig[i], float(np.max(np.abs(x))))
                g = np.linspace(-lim, lim, 301)
                pdf = np.exp(-0.5 * (g / sig[i]) ** 2) / (sig[i] * np.sqrt(2.0 * np.pi))
                ax.plot(g, pdf, color="C3", lw=1.5, label=f"TEAM N(0, {sig[i]:.3g}²)")
            ax.legend(fontsize=7)
        else:
            _empty(ax, "no successful missions")
        ax.set_xlabel(_label(name, units[i]))
        ax.set_ylabel(f"density (1/{units[i]})")
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(names) :]:
        ax.set_visible(len(names) == 0)
        if not names:
            _empty(ax, "no final targets")
    fig.suptitle(_wrapped(f"TSIM final target errors: {title}", 4.8 * ncol, 11), fontsize="medium")
    return fig


def tsim_figures(product: TsimProduct) -> list:
    """The three TSIM figures (matplotlib, not saved): the target-plane scatter (first two
    final target components, TEAM's 1σ and 3σ ellipses, the sample 1σ ellipse dashed), the
    ΔV histograms (m/s) and the target-error histograms (velocities in mm/s)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = successful(product)
    names = product.final_target_names
    f, units = _scales(product)
    te = _target_errors(product, ok) * f[None, :] if len(names) else _target_errors(product, ok)
    team_cov = np.asarray(product.team_target_cov, float)
    if team_cov.size and len(names):
        team_cov = team_cov * np.outer(f, f)
    title = product.title or Path(product.source).name
    return [
        _target_plane_figure(plt, te, team_cov, names, units, title),
        _dv_figure(plt, product, ok, title),
        _errors_figure(plt, te, team_cov, names, units, title),
    ]


def plot_tsim(product: TsimProduct, path: str | Path) -> list[Path]:
    """Three PNG files (:func:`tsim_figures`): the target-plane scatter at ``path``, the ΔV
    histograms at ``<stem>_dv.png`` and the target-error histograms at
    ``<stem>_errors.png``.  Returns the paths written."""
    import matplotlib.pyplot as plt

    from fracas.io.atomic import savefig_atomic

    path = Path(path)
    out: list[Path] = []
    names = (path, path.with_name(path.stem + "_dv.png"), path.with_name(path.stem + "_errors.png"))
    for fig, p in zip(tsim_figures(product), names):
        try:
            out.append(savefig_atomic(fig, p, dpi=110))
        finally:
            plt.close(fig)
    return out
