"""TOM report: the terminal summary (80 columns), the per-iteration progress line and the
convergence and GRID plots, from a TOM results file's contents (:func:`read_tom_results`)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from fracas.report._tables import fit_line

__all__ = ["progress_line", "summary_text", "plot_tom", "convergence_figure", "grid_figure", "PROGRESS_HEADER"]

PROGRESS_HEADER = (
    f"{'iter':>4} {'mode':<4} {'final mass kg':>14} {'E_rms':>10} {'angle rad':>10} {'step':>7} {'traj':>5}"
)


def progress_line(rec) -> str:
    """One line per iteration (an :class:`fracas.tom.search.IterationRecord`)."""
    ang = "" if not np.isfinite(rec.angle_rad) else f"{rec.angle_rad:10.3e}"
    return (
        f"{rec.iteration:4d} {rec.submode:<4} {rec.performance:14.6f} {rec.error_rms:10.3e} "
        f"{ang:>10} {rec.gamma:7.3f} {rec.n_evaluations:5d}"
    )


def _g(x: float, width: int = 14) -> str:
    if not np.isfinite(x):
        return f"{'-':>{width}}"
    return f"{x:{width}.8g}"


def _shown(path: str) -> str:
    """A path as the reader would type it: relative to the working directory when it is
    inside it, else as stored."""
    import os

    try:
        rel = os.path.relpath(path)
    except ValueError:  # another drive
        return path
    return rel if not rel.startswith("..") else path


def summary_text(res: dict, width: int = 80) -> str:
    """The run's summary: verdict and stop reason, targets, controls, mass, cost split."""
    a = res["attrs"]
    lines = []
    title = a.get("title") or Path(a.get("source", "")).name
    lines.append(f"TOM {a.get('submode', '')} -- {title}")
    verdict = "CONVERGED" if int(a.get("converged", 0)) else "NOT CONVERGED"
    claim = "yes" if int(a.get("search_converged", 0)) else "no"
    met = "yes" if int(a.get("targets_met", 0)) else "no"
    lines.append(f"{verdict} (targets met on re-propagation: {met}; the search's own test: {claim})")
    lines += textwrap.wrap(f"stop: {a.get('stop_reason', '')}", width)
    lines.append(f"optimizer {a.get('optimizer')}, sensitivities {a.get('sensitivities')}")
    lines.append("")
    lines.append(f"{'target':<20} {'desired':>14} {'achieved':>14} {'error':>11} {'tol':>9} {'unit':<5}")
    for i, name in enumerate(res["target_names"]):
        d = res["achieved"][i] - res["desired"][i]
        if res["target_units"][i] == "deg":
            d = -np.remainder(-d + 180.0, 360.0) + 180.0
        flag = "" if abs(d) <= res["tolerance"][i] else " *"
        label = f"{name}@{res['target_bodies'][i]}"[:20]
        lines.append(
            f"{label:<20} {_g(res['desired'][i])} {_g(res['achieved'][i])} {d:11.3e} "
            f"{res['tolerance'][i]:9.2e} {res['target_units'][i]:<5}{flag}"
        )
    lines.append("")
    lines.append(f"{'control':<20} {'start':>14} {'final':>14} {'change':>11} {'unit':<5}")
    for j, name in enumerate(res["control_names"]):
        du = res["u_final"][j] - res["u_start"][j]
        bound = ""
        if np.isclose(res["u_final"][j], res["lower"][j]) or np.isclose(res["u_final"][j], res["upper"][j]):
            bound = " [bound]"
        lines.append(
            f"{name[:20]:<20} {_g(res['u_start'][j])} {_g(res['u_final'][j])} {du:11.3e} "
            f"{res['control_units'][j]:<5}{bound}"
        )
    lines.append("")
    perf = res.get("performance_name", "final_mass")
    if perf != "final_mass":
        unit = res.get("performance_unit", "")
        lines.append(
            f"performance {perf} {res['performance_final']:.10g} {unit} (start {res['performance_start']:.10g} {unit})"
        )
    lines.append(
        f"final mass {res['final_mass_kg']:.6f} kg (start {res['start_mass_kg']:.6f} kg, "
        f"initial {res['initial_mass_kg']:.3f} kg)"
    )
    k = len(res["iteration"])
    n_traj = int(res["n_trajectories"][-1]) if k else 0
    t = {key[7:]: float(v) for key, v in a.items() if key.startswith("timing_")}
    n_it = len(set(np.asarray(res["iteration"]).tolist()))
    steps = f"{k} iterations" if n_it == k else f"{k} search records in {n_it} iterations"
    lines.append(f"{steps}, {n_traj} trajectories in the search")
    if "core_propagations" in t:
        lines.append(
            f"the core flew {int(t['core_propagations'])} trajectories and "
            f"{int(t.get('core_sensitivity_runs', 0))} AD sensitivity runs"
        )
    if "search_s" in t:
        lines.append(
            f"search {t['search_s']:.2f} s: sensitivities {t.get('sensitivities_s', 0):.2f} s, line search "
            f"{t.get('line_search_s', 0):.2f} s, bookkeeping {t.get('bookkeeping_s', 0):.2f} s"
        )
    if "grid_s" in t:
        lines.append(f"GRID {t['grid_s']:.2f} s ({t.get('grid_trajectories_per_s', 0):.0f} trajectories/s)")
    if a.get("reference_deck"):
        lines.append(f"reference deck: {_shown(a['reference_deck'])}")
    return "\n".join(fit_line(line, width) for line in lines)


_MODE_MARKER = {"T": "o", "O": "s", "T+O": "^"}


def convergence_figure(res: dict):
    """Final mass, E_rms and the gradient angle per search record, or None without records.

    Every record is its own point: an iteration whose first step is refused is retried in
    the same iteration (two records with one iteration number, e.g. ``3 T+O`` then ``3 T``),
    so the x axis counts records and the tick labels give the iteration and its mode."""
    k = len(res["iteration"])
    if not k:
        return None
    plt = _plt()
    x = np.arange(1, k + 1)
    it = np.asarray(res["iteration"], dtype=int)
    modes = [str(m) for m in res.get("submode", [""] * k)]
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7.5, 6.2))
    ax1.plot(x, res["performance_kg"], "-", color="C0", lw=1)
    ax2.semilogy(x, np.maximum(res["error_rms"], 1e-16), "-", color="C0", lw=1, label="E_rms (targets / tolerance)")
    ang = np.asarray(res["angle_rad"], dtype=float)
    if np.any(np.isfinite(ang)):
        ax2.semilogy(
            x, np.where(np.isfinite(ang), np.maximum(ang, 1e-16), np.nan), "--", color="C1", lw=1, label="angle (rad)"
        )
    for mode in dict.fromkeys(modes):
        sel = np.array([m == mode for m in modes])
        mk = _MODE_MARKER.get(mode, "D")
        ax1.plot(x[sel], np.asarray(res["performance_kg"])[sel], mk, color="C0", ms=4, label=f"{mode or '?'} step")
        ax2.semilogy(x[sel], np.maximum(np.asarray(res["error_rms"])[sel], 1e-16), mk, color="C0", ms=4)
        if np.any(np.isfinite(ang)):
            ax2.semilogy(
                x[sel], np.where(np.isfinite(ang[sel]), np.maximum(ang[sel], 1e-16), np.nan), mk, color="C1", ms=4
            )
    perf = res.get("performance_name", "final_mass")
    # the history holds F in canonical units: kg for the mass, the target kind's own unit otherwise
    if perf == "final_mass":
        ax1.set_ylabel("final mass (kg)")
    else:
        from fracas.guidance.target_kinds import TARGET_KINDS

        ax1.set_ylabel(f"performance: {perf} ({TARGET_KINDS[perf].unit})")
    ax1.grid(alpha=0.3)
    ax1.legend(fontsize=8, title="mode", title_fontsize=8)
    ax1.ticklabel_format(axis="y", useOffset=False)
    ax2.axhline(1.0, color="k", lw=0.6, ls=":")
    n_it = len(set(it.tolist()))
    if k <= 24:
        ax2.set_xticks(x, [f"{i}\n{m}" for i, m in zip(it, modes)], fontsize=8)
        ax2.set_xlabel(f"search record (iteration and mode): {k} records in {n_it} iterations")
    else:
        ax2.set_xlabel(f"search record ({k} records in {n_it} iterations)")
    ax2.legend(fontsize=8)
    ax2.grid(alpha=0.3, which="both")
    a = res["attrs"]
    verdict = "converged" if int(a.get("converged", 0)) else "not converged"
    fig.suptitle(f"TOM: {a.get('title', '')} ({verdict})", fontsize="medium", wrap=True)
    fig.tight_layout()
    return fig


def grid_figure(res: dict):
    """One contour plot of log10 E per control pair of the GRID, or None without a GRID."""
    grid = res.get("grid")
    if grid is None or not grid.get("pairs"):
        return None
    plt = _plt()
    pairs = sorted(grid["pairs"])
    ncol = min(3, len(pairs))
    nrow = (len(pairs) + ncol - 1) // ncol
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.4 * ncol, 3.8 * nrow), squeeze=False)
    gam = grid["gammas"]
    names = res["control_names"]
    for ax, (a_i, b_i) in zip(axes.ravel(), pairs):
        table = np.log10(np.maximum(grid["pairs"][(a_i, b_i)], 1e-12))
        cs = ax.contourf(gam, gam, table.T, levels=20)
        fig.colorbar(cs, ax=ax, label="log10 E (1)")
        ax.set_xlabel(f"{names[a_i]} (increments)")
        ax.set_ylabel(f"{names[b_i]} (increments)")
    for ax in axes.ravel()[len(pairs) :]:
        ax.set_visible(False)
    fig.tight_layout()
    return fig


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_tom(res: dict, path: str | Path) -> list[Path]:
    """Convergence plot (:func:`convergence_figure`) at ``path``; with a GRID, one contour
    plot of E per control pair (:func:`grid_figure`) at ``<stem>_grid.png``.  Returns the
    paths written."""
    from fracas.io.atomic import savefig_atomic

    plt = _plt()
    out = []
    path = Path(path)
    for fig, p in ((convergence_figure(res), path), (grid_figure(res), path.with_name(path.stem + "_grid.png"))):
        if fig is None:
            continue
        try:
            out.append(savefig_atomic(fig, p, dpi=110))
        finally:
            plt.close(fig)
    return out
