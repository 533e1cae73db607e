"""Terminal summary and plot of one trajectory (reads only :class:`~fracas.io.TrajectoryData`).

The summary is a rich table: initial and final state (position, velocity, their
magnitudes, mass) relative to the primary, mass used, duration, integration steps,
Encke rectifications and the termination status.  The plot is a PNG drawn with
matplotlib's Agg canvas (no pyplot, no global backend change): the x-y projection of the
path about each primary, and radius and mass against time.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from fracas.constants import AU_KM, DAY_S
from fracas.io.trajectory_file import TrajectoryData
from fracas.status import RunStatus, status_text

__all__ = ["print_summary", "summary_table", "plot_trajectory"]

_STATUS_STYLE = {
    RunStatus.OK: "green",
    RunStatus.STOPPED: "cyan",
    RunStatus.MAX_STEPS: "yellow",
    RunStatus.NONFINITE: "red",
}  # any other code: red


def _valid(data: TrajectoryData) -> np.ndarray:
    return np.isfinite(np.asarray(data.t_s, dtype=np.float64))


def summary_table(data: TrajectoryData):
    """A :class:`rich.table.Table` summarising ``data`` (states, mass used, steps, status).

    Fits an 80-column terminal: one row per vector component, numbers in columns that never
    wrap or cut; the status is the last row."""
    from rich.markup import escape
    from rich.table import Table

    ok = _valid(data)
    first = int(np.argmax(ok)) if ok.any() else 0
    r0, v0, m0 = data.r_km[first], data.v_km_s[first], float(data.mass_kg[first])
    p0 = data.primary[first] if data.primary else data.centre
    rf, vf, mf = data.r_final_km, data.v_final_km_s, float(data.mass_final_kg)
    title = data.title or "trajectory"
    t = Table(title=escape(title), show_header=True, header_style="bold", title_justify="left")
    t.add_column("", style="bold", overflow="fold")
    t.add_column("initial", justify="right", no_wrap=True)
    t.add_column("final", justify="right", no_wrap=True)
    t.add_row("time (days)", f"{float(data.t_s[first]) / DAY_S:.6g}", f"{data.t_final_s / DAY_S:.6g}")
    t.add_row("primary", escape(p0), escape(data.primary_final))
    for i, c in enumerate("xyz"):
        t.add_row(f"r{c} (km)", f"{float(r0[i]):.9g}", f"{float(rf[i]):.9g}")
    t.add_row("|r| (km)", f"{np.linalg.norm(r0):.6f}", f"{np.linalg.norm(rf):.6f}")
    for i, c in enumerate("xyz"):
        t.add_row(f"v{c} (km/s)", f"{float(v0[i]):.9g}", f"{float(vf[i]):.9g}")
    t.add_row("|v| (km/s)", f"{np.linalg.norm(v0):.9f}", f"{np.linalg.norm(vf):.9f}")
    t.add_row("mass (kg)", f"{m0:.6f}", f"{mf:.6f}")
    t.add_section()
    used = m0 - mf
    t.add_row("mass used (kg)", "", f"{used:.6f} ({100.0 * used / m0:.3g} %)" if m0 > 0 else f"{used:.6f}")
    t.add_row("epoch (TDB)", escape(data.epoch_tdb or f"ET {data.epoch_et_s:.3f} s"), "")
    if data.integrator:
        t.add_row("integrator", "", escape(data.integrator))
    rejected = f" ({int(data.n_reject)} rejected)" if data.n_reject else ""
    t.add_row("steps", "", f"{int(data.n_steps)}{rejected}")
    if data.integrator.split(", ")[1:2] != ["cowell"]:
        t.add_row("rectifications", "", f"{int(data.n_rect)}")
    code = int(data.status)
    style = _STATUS_STYLE.get(code, "red")
    t.add_row("status", "", f"[{style}]{code}: {escape(status_text(code))}[/{style}]")
    return t


def print_summary(data: TrajectoryData, path: str | Path | None = None, console=None, width: int | None = None) -> None:
    """Print :func:`summary_table` to ``console`` (a :class:`rich.console.Console`; stdout by
    default, ``width`` columns or the terminal's)."""
    from rich.console import Console

    console = console or Console(width=width)
    console.print(summary_table(data))
    if data.sensitivities is not None:
        sd = data.sensitivities
        cols = ", ".join(sd.param_labels) if sd.param_labels else "none"
        n = sd.stm.shape[0]
        console.print(
            f"sensitivities: STM (n={n}, 7x7) and parameter matrices, columns: {cols}",
            markup=False,
            highlight=False,
            soft_wrap=True,
        )
    if path is not None:
        console.print(f"written: {path}", markup=False, highlight=False, soft_wrap=True)


def plot_trajectory(data: TrajectoryData, png: str | Path, dpi: int = 120) -> Path:
    """Write a PNG: x-y projection (per primary) and |r|, mass against time. Returns the path."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ok = _valid(data)
    t_day = np.asarray(data.t_s, dtype=np.float64)[ok] / DAY_S
    r = np.asarray(data.r_km, dtype=np.float64)[ok]
    m = np.asarray(data.mass_kg, dtype=np.float64)[ok]
    prim = (
        np.asarray(data.primary, dtype=object)[ok]
        if len(data.primary) == len(ok)
        else np.array([data.centre] * ok.sum(), dtype=object)
    )
    rmag = np.linalg.norm(r, axis=-1) if r.size else np.zeros(0)
    big = rmag.size and float(np.nanmax(rmag)) > 0.05 * AU_KM
    scale, unit = (AU_KM, "AU") if big else (1.0, "km")

    fig = Figure(figsize=(11, 5.5), layout="constrained")
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(2, 2, width_ratios=(1.1, 1.0))
    ax = fig.add_subplot(grid[:, 0])
    style = ".-" if r.shape[0] <= 200 else "-"
    for name in dict.fromkeys(prim.tolist()):
        sel = prim == name
        ax.plot(r[sel, 0] / scale, r[sel, 1] / scale, style, ms=3, lw=0.8, label=f"about {name or '?'}")
        ax.plot([0.0], [0.0], "o", ms=6, color="k")
    if r.size:
        ax.plot(r[0, 0] / scale, r[0, 1] / scale, "g^", ms=8, label="start")
        ax.plot(data.r_final_km[0] / scale, data.r_final_km[1] / scale, "rs", ms=7, label="end")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"x ({unit}, ICRF)")
    ax.set_ylabel(f"y ({unit}, ICRF)")
    ax.set_title("x-y projection about the primary")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)

    ax1 = fig.add_subplot(grid[0, 1])
    ax1.plot(t_day, rmag / scale, "-", lw=1)
    ax1.set_ylabel(f"|r| ({unit})")
    ax1.grid(True, alpha=0.3)
    ax2 = fig.add_subplot(grid[1, 1], sharex=ax1)
    ax2.plot(t_day, m, "-", lw=1, color="tab:orange")
    ax2.set_ylabel("mass (kg)")
    ax2.set_xlabel("time from epoch (days)")
    ax2.grid(True, alpha=0.3)
    if m.size and math.isclose(float(m.min()), float(m.max())):
        ax2.set_ylim(float(m[0]) - 1.0, float(m[0]) + 1.0)
    fig.suptitle(data.title or "trajectory")

    from fracas.io.atomic import savefig_atomic

    out = Path(png)
    out.parent.mkdir(parents=True, exist_ok=True)
    savefig_atomic(fig, out, dpi=dpi)  # a kill mid-write never leaves a partial PNG or damages the old one
    return out
