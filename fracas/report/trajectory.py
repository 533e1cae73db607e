"""Terminal summary and plot of one trajectory (reads only :class:`~fracas.io.TrajectoryData`).

The summary is a rich table: initial and final state (position, velocity, their
magnitudes, mass) relative to the primary, mass used, duration, integration steps,
Encke rectifications and the termination status.  The plot is a PNG drawn with
matplotlib's Agg canvas (no pyplot, no global backend change): the x-y projection of the
path about each primary (the conics between the stored samples, a few revolutions of a
spiral), and radius, osculating a, e, i and mass against time (:func:`trajectory_figure`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from fracas.constants import AU_KM, BODIES, DAY_S, OBLIQUITY_J2000_RAD
from fracas.io.trajectory_file import TrajectoryData
from fracas.report._conic import dense_path, osculating_aei
from fracas.report._tables import fit_line
from fracas.status import RunStatus, status_text

__all__ = ["print_summary", "summary_table", "plot_trajectory", "trajectory_figure"]

_STATUS_STYLE = {
    RunStatus.OK: "green",
    RunStatus.STOPPED: "cyan",
    RunStatus.MAX_STEPS: "yellow",
    RunStatus.NONFINITE: "red",
}  # any other code: red


def _valid(data: TrajectoryData) -> np.ndarray:
    return np.isfinite(np.asarray(data.t_s, dtype=np.float64))


def summary_table(data: TrajectoryData) -> Any:
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


def print_summary(
    data: TrajectoryData, path: str | Path | None = None, console: Any = None, width: int | None = None
) -> None:
    """Print :func:`summary_table` to ``console`` (a :class:`rich.console.Console`; stdout by
    default, ``width`` columns or the terminal's)."""
    from rich.console import Console

    console = console or Console(width=width)
    console.print(summary_table(data))
    if data.sensitivities is not None:
        sd = data.sensitivities
        cols = ", ".join(sd.param_labels) if sd.param_labels else "none"
        n = sd.stm.shape[0]
        line = f"sensitivities: STM (n={n}, 7x7) and parameter matrices, columns: {cols}"
        # wrapped at word boundaries to the console's width (a label is never folded mid-way)
        console.print(fit_line(line, console.width), markup=False, highlight=False, soft_wrap=True)
    if path is not None:
        console.print(f"written: {path}", markup=False, highlight=False, soft_wrap=True)


def _mu_of(name: str) -> float | None:
    body = BODIES.get(str(name))
    return body.mu_km3_s2 if body is not None else None


def _pole(name: str) -> tuple[np.ndarray | None, str]:
    """The pole the inclination is measured from, and its name: the ecliptic's about the
    Sun (heliocentric inclinations are ecliptic ones), the ICRF/EME2000 z axis otherwise."""
    if str(name) == "sun":
        eps = OBLIQUITY_J2000_RAD
        return np.array([0.0, -math.sin(eps), math.cos(eps)]), "ecliptic"
    return None, "ICRF equator"


def _revolutions(r: np.ndarray) -> np.ndarray:
    """Cumulative revolutions (angle swept / 2 pi) along a dense path (n, 3)."""
    if len(r) < 2:
        return np.zeros(len(r))
    a, b = r[:-1], r[1:]
    ang = np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.einsum("ij,ij->i", a, b))
    return np.concatenate([[0.0], np.cumsum(ang)]) / (2.0 * np.pi)


def _per_revolution(revs: np.ndarray, t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean time and mean of ``y`` over each whole revolution (the orbit average an analyst
    reads through the short-period oscillation)."""
    k = np.floor(revs).astype(np.int64)
    whole = k < int(revs[-1]) if revs.size else np.zeros(0, bool)
    k, t, y = k[whole], t[whole], y[whole]
    n = np.bincount(k)
    keep = n > 0
    with np.errstate(invalid="ignore"):
        return (np.bincount(k, t)[keep] / n[keep]), (np.bincount(k, np.nan_to_num(y))[keep] / n[keep])


#: above this many revolutions about one primary the x-y view shows a few, coloured by time
MAX_REVOLUTIONS_DRAWN = 20
_SHOWN_REVOLUTIONS = 7


def _draw_xy(
    fig: Any, ax: Any, data: TrajectoryData, r: np.ndarray, t_day: np.ndarray, prim: np.ndarray, scale: float, unit: str
) -> None:
    """The x-y projection about each primary (a few revolutions of a spiral, coloured by time)."""
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    names = list(dict.fromkeys(prim.tolist()))
    notes = []
    for c, name in enumerate(names):
        sel = prim == name
        rs, ts = r[sel], t_day[sel]
        lab = f"about {name or '?'}"
        revs = _revolutions(rs)
        n_rev = int(revs[-1]) if revs.size else 0
        if n_rev > MAX_REVOLUTIONS_DRAWN:
            picks = np.unique(np.linspace(0, n_rev, _SHOWN_REVOLUTIONS).round().astype(int))
            norm = Normalize(float(t_day[0]), float(t_day[-1]) if t_day[-1] != t_day[0] else float(t_day[0]) + 1.0)
            cmap = colormaps["viridis"]
            for j in picks:
                w = (revs >= j) & (revs <= j + 1)
                if w.sum() < 2:
                    continue
                ax.plot(rs[w, 0] / scale, rs[w, 1] / scale, "-", lw=1.0, color=cmap(norm(float(ts[w].mean()))))
            fig.colorbar(ScalarMappable(norm, cmap), ax=ax, label="time from epoch (days)", shrink=0.8)
            notes.append(f"{len(picks)} of {n_rev} revolutions about {name}")
        else:
            ax.plot(rs[:, 0] / scale, rs[:, 1] / scale, "-", lw=1.0, color=f"C{c}", label=lab)
        ax.plot([0.0], [0.0], "o", ms=6, color="k")
    if r.size:
        ax.plot(r[0, 0] / scale, r[0, 1] / scale, "g^", ms=8, label="start")
        ax.plot(data.r_final_km[0] / scale, data.r_final_km[1] / scale, "rs", ms=7, label="end")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"x ({unit}, ICRF)")
    ax.set_ylabel(f"y ({unit}, ICRF)")
    ax.set_title("x-y projection about the primary" + (f"\n({'; '.join(notes)})" if notes else ""), fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)


def _draw_elements(
    right: list[Any],
    r: np.ndarray,
    v: np.ndarray,
    m: np.ndarray,
    t_day: np.ndarray,
    rmag: np.ndarray,
    prim: np.ndarray,
    scale: float,
    unit: str,
) -> None:
    """Against time: radius and osculating a, e, i (averaged per revolution on a spiral), mass."""
    ax_r, ax_e, ax_i, ax_m = right
    names = list(dict.fromkeys(prim.tolist()))
    ref = "ICRF equator"
    for c, name in enumerate(names):
        sel = prim == name
        ts = t_day[sel]
        mu = _mu_of(name)
        suffix = f" ({name})" if len(names) > 1 else ""
        ax_r.plot(ts, rmag[sel] / scale, "-", lw=0.6, color=f"C{c}", label=f"|r|{suffix}")
        if mu is None:
            continue
        pole, ref = _pole(name)
        a, e, inc = osculating_aei(r[sel], v[sel], mu, pole)
        a = np.where(a < 5.0 * float(np.nanmax(rmag[sel])), a, np.nan)
        revs = _revolutions(r[sel])
        averaged = revs.size and revs[-1] > 3.0
        lw, alpha = (0.5, 0.35) if averaged else (1.0, 1.0)
        ax_r.plot(ts, a / scale, "-", lw=1.6, color=f"C{c + 1}" if len(names) == 1 else f"C{c}", label=f"a{suffix}")
        ax_e.plot(ts, e, "-", lw=lw, alpha=alpha, color=f"C{c}", label="osculating" if averaged else None)
        ax_i.plot(ts, np.degrees(inc), "-", lw=lw, alpha=alpha, color=f"C{c}")
        if averaged:
            tm, em = _per_revolution(revs, ts, e)
            _, im = _per_revolution(revs, ts, np.degrees(inc))
            ax_e.plot(
                tm, em, "-", lw=1.6, color=f"C{c + 1}" if len(names) == 1 else f"C{c}", label="mean per revolution"
            )
            ax_i.plot(tm, im, "-", lw=1.6, color=f"C{c + 1}" if len(names) == 1 else f"C{c}")
            ax_e.legend(fontsize=7, loc="best")
    ax_r.set_ylabel(f"|r|, a ({unit})")
    ax_r.set_title(f"radius and osculating elements (i to the {ref})", fontsize=10)
    ax_r.legend(fontsize=7, loc="best")
    ax_e.set_ylabel("e (1)")
    ax_i.set_ylabel("i (deg)")
    ax_m.plot(t_day, m, "-", lw=1, color="tab:orange")
    ax_m.set_ylabel("mass (kg)")
    ax_m.set_xlabel("time from epoch (days)")
    if m.size and math.isclose(float(m.min()), float(m.max())):
        ax_m.set_ylim(float(m[0]) - 1.0, float(m[0]) + 1.0)
    for a_ in right:
        a_.grid(True, alpha=0.3)
        a_.ticklabel_format(axis="y", useOffset=False)
    for a_ in right[:-1]:
        a_.tick_params(labelbottom=False)


def trajectory_figure(data: TrajectoryData) -> Any:
    """The trajectory plot as a matplotlib :class:`~matplotlib.figure.Figure` (Agg canvas).

    Left: the x-y projection (ICRF) drawn through the samples with the conics between them
    (:func:`fracas.report._conic.dense_path`); a path of more than
    :data:`MAX_REVOLUTIONS_DRAWN` revolutions (a spiral) shows a few evenly spaced
    revolutions, first and last included, coloured by time.  Right, against time: radius
    with the osculating semi-major axis, eccentricity, inclination (to the ecliptic about
    the Sun, to the ICRF equator otherwise) and mass."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ok = _valid(data)
    t_s = np.asarray(data.t_s, dtype=np.float64)[ok]
    r = np.asarray(data.r_km, dtype=np.float64)[ok]
    v = np.asarray(data.v_km_s, dtype=np.float64)[ok]
    m = np.asarray(data.mass_kg, dtype=np.float64)[ok]
    prim = (
        np.asarray(data.primary, dtype=object)[ok]
        if len(data.primary) == len(ok)
        else np.array([data.centre] * ok.sum(), dtype=object)
    )
    t_s, r, v, m, prim = dense_path(t_s, r, v, m, prim, _mu_of)
    t_day = t_s / DAY_S
    rmag = np.linalg.norm(r, axis=-1) if r.size else np.zeros(0)
    big = rmag.size and float(np.nanmax(rmag)) > 0.05 * AU_KM
    scale, unit = (AU_KM, "AU") if big else (1.0, "km")

    fig = Figure(figsize=(12, 7.5), layout="constrained")
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(4, 2, width_ratios=(1.15, 1.0))
    ax = fig.add_subplot(grid[:, 0])
    right = [fig.add_subplot(grid[0, 1])]
    right += [fig.add_subplot(grid[j, 1], sharex=right[0]) for j in (1, 2, 3)]
    _draw_xy(fig, ax, data, r, t_day, prim, scale, unit)
    _draw_elements(right, r, v, m, t_day, rmag, prim, scale, unit)
    fig.suptitle(data.title or "trajectory")
    return fig


def plot_trajectory(data: TrajectoryData, png: str | Path, dpi: int = 120) -> Path:
    """Write :func:`trajectory_figure` as a PNG at ``png``; returns the path."""
    from fracas.io.atomic import savefig_atomic

    fig = trajectory_figure(data)
    out = Path(png)
    out.parent.mkdir(parents=True, exist_ok=True)
    savefig_atomic(fig, out, dpi=dpi)  # a kill mid-write never leaves a partial PNG or damages the old one
    return out
