"""TOM report: the terminal summary (80 columns), the per-iteration progress line and the
convergence and GRID plots, from a TOM results file's contents (:func:`read_tom_results`)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

__all__ = ["progress_line", "summary_text", "plot_tom", "PROGRESS_HEADER"]

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


def summary_text(res: dict, width: int = 80) -> str:
    """The run's summary: verdict and stop reason, targets, controls, mass, cost split."""
    a = res["attrs"]
    lines = []
    title = a.get("title") or Path(a.get("source", "")).name
    lines.append(f"TOM {a.get('submode', '')} -- {title}"[:width])
    verdict = "CONVERGED" if int(a.get("converged", 0)) else "NOT CONVERGED"
    claim = "yes" if int(a.get("search_converged", 0)) else "no"
    met = "yes" if int(a.get("targets_met", 0)) else "no"
    lines.append(f"{verdict} (targets met on re-propagation: {met}; the search's own test: {claim})")
    lines += textwrap.wrap(f"stop: {a.get('stop_reason', '')}", width)
    lines.append(f"optimizer {a.get('optimizer')}, sensitivities {a.get('sensitivities')}"[:width])
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
    lines.append(
        f"final mass {res['final_mass_kg']:.6f} kg (start {res['start_mass_kg']:.6f} kg, "
        f"initial {res['initial_mass_kg']:.3f} kg)"
    )
    k = len(res["iteration"])
    n_traj = int(res["n_trajectories"][-1]) if k else 0
    t = {key[7:]: float(v) for key, v in a.items() if key.startswith("timing_")}
    lines.append(f"{k} iterations, {n_traj} trajectories in the search"[:width])
    if "core_propagations" in t:
        lines.append(
            f"the core flew {int(t['core_propagations'])} trajectories and "
            f"{int(t.get('core_sensitivity_runs', 0))} AD sensitivity runs"[:width]
        )
    if "search_s" in t:
        lines.append(
            f"search {t['search_s']:.2f} s: sensitivities {t.get('sensitivities_s', 0):.2f} s, line search "
            f"{t.get('line_search_s', 0):.2f} s, bookkeeping {t.get('bookkeeping_s', 0):.2f} s"[:width]
        )
    if "grid_s" in t:
        lines.append(f"GRID {t['grid_s']:.2f} s ({t.get('grid_trajectories_per_s', 0):.0f} trajectories/s)"[:width])
    if a.get("reference_deck"):
        lines.append(f"reference deck: {a['reference_deck']}")
    return "\n".join(lines)


def plot_tom(res: dict, path: str | Path) -> list[Path]:
    """Convergence plot (final mass and E_rms per iteration) at ``path``; with a GRID, one
    contour plot of E per control pair at ``<stem>_grid.png``.  Returns the paths written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fracas.io.atomic import savefig_atomic

    out = []
    path = Path(path)
    if len(res["iteration"]):
        fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
        it = res["iteration"]
        ax1.plot(it, res["performance_kg"], "o-", ms=3)
        ax1.set_ylabel("final mass (kg)")
        ax1.grid(alpha=0.3)
        ax2.semilogy(it, np.maximum(res["error_rms"], 1e-16), "o-", ms=3, label="E_rms (targets / tolerance)")
        ang = res["angle_rad"]
        if np.any(np.isfinite(ang)):
            ax2.semilogy(
                it, np.where(np.isfinite(ang), np.maximum(ang, 1e-16), np.nan), "s--", ms=3, label="angle (rad)"
            )
        ax2.axhline(1.0, color="k", lw=0.6, ls=":")
        ax2.set_xlabel("iteration")
        ax2.legend(fontsize=8)
        ax2.grid(alpha=0.3, which="both")
        a = res["attrs"]
        fig.suptitle(f"TOM: {a.get('title', '')}  ({'converged' if int(a.get('converged', 0)) else 'not converged'})")
        fig.tight_layout()
        out.append(savefig_atomic(fig, path, dpi=110))
        plt.close(fig)
    grid = res.get("grid")
    if grid is not None and grid.get("pairs"):
        pairs = sorted(grid["pairs"])
        ncol = min(3, len(pairs))
        nrow = (len(pairs) + ncol - 1) // ncol
        fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.6 * nrow), squeeze=False)
        gam = grid["gammas"]
        names = res["control_names"]
        for ax, (a_i, b_i) in zip(axes.ravel(), pairs):
            table = np.log10(np.maximum(grid["pairs"][(a_i, b_i)], 1e-12))
            cs = ax.contourf(gam, gam, table.T, levels=20)
            fig.colorbar(cs, ax=ax, label="log10 E")
            ax.set_xlabel(f"{names[a_i]} (increments)")
            ax.set_ylabel(f"{names[b_i]} (increments)")
        for ax in axes.ravel()[len(pairs) :]:
            ax.set_visible(False)
        fig.tight_layout()
        gpath = path.with_name(path.stem + "_grid.png")
        out.append(savefig_atomic(fig, gpath, dpi=110))
        plt.close(fig)
    return out
