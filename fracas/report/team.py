"""TEAM printout (FRACAS PRINT, GPRINT) as terminal tables, and a PNG of the knowledge history."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fracas.constants import DAY_S
from fracas.team.eigen import eigen_summary

__all__ = ["print_team", "plot_team", "covariance_table", "summary_dict"]

_EVENT_SHOW = ("thrust_on", "thrust_off", "propagation", "eigenvector", "prediction", "punch", "final", "initial")


def _fmt(x: float) -> str:
    return f"{x:.4g}" if np.isfinite(x) else "-"


def covariance_table(P: np.ndarray, labels: list[str], units: list[str], title: str, correlations: bool = True):
    """Standard deviations and the state correlation matrix (like App. 9.3 Table 2)."""
    from rich.markup import escape
    from rich.table import Table

    e = eigen_summary(P)
    state = labels[:6]
    t = Table(title=title, title_justify="left", show_edge=False, pad_edge=False)
    t.add_column("", justify="left")
    t.add_column("1σ", justify="right")
    t.add_column("unit")
    if correlations:
        for s in state:
            t.add_column(s, justify="right")
    for i, lab in enumerate(labels):
        row = [escape(lab), f"{e.sigma[i]:.6g}", escape(units[i])]
        if correlations:
            row += [f"{e.corr[i, j]:+.4f}" if (j <= i or i >= 6) else "" for j in range(6)]
        t.add_row(*row)
    eig = Table(title="position / velocity 1σ semi-axes (eigenvalues^½) and eigenvectors", title_justify="left",
                show_edge=False, pad_edge=False)
    for c in ("block", "axis", "1σ", "unit", "x", "y", "z"):
        eig.add_column(c, justify="right")
    for name, ax, V, unit in (("position", e.pos_axes, e.pos_eigvec, "km"), ("velocity", e.vel_axes * 1e6, e.vel_eigvec, "mm/s")):
        for a in range(3)[::-1]:
            eig.add_row(name, str(3 - a), f"{ax[a]:.5g}", unit, *(f"{v:+.4f}" for v in V[:, a]))
    return t, eig


def summary_dict(res, path: Path | None, source: str) -> dict:
    """A JSON-able summary of a TEAM run (``fracas run --json``)."""
    st = res.study
    k = -1
    ea = eigen_summary(res.Pa_plus[k])
    out = {
        "title": st.deck.title, "filter": st.filter_kind, "propagation": st.propagation, "reference": source,
        "events": int(st.schedule.n), "measurements_used": int(sum(r.used for r in res.meas.records)),
        "measurements_skipped": int(sum(res.meas.skipped.values())), "final_time_days": float(res.times_s[k] / DAY_S),
        "assumed": {"position_rss_km": ea.pos_rss, "velocity_rss_km_s": ea.vel_rss,
                    "sigma": dict(zip(res.labels, map(float, ea.sigma)))},
        "psd_problems": len(res.psd_problems), "timing_s": {k: round(v, 4) for k, v in res.timing.items()},
    }
    if res.Pt_plus is not None:
        et = eigen_summary(res.Pt_plus[k])
        out["true"] = {"position_rss_km": et.pos_rss, "velocity_rss_km_s": et.vel_rss,
                       "sigma": dict(zip(res.labels, map(float, et.sigma)))}
    if path is not None:
        out["file"] = str(path)
    return out


def print_team(res, path: Path | None, source: str, console=None) -> None:
    """The FRACAS-style printout: study, event log, eigenvector events, predictions, warnings."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    con = console or Console(width=None if __import__("sys").stdout.isatty() else 160)
    st = res.study
    sched = st.schedule
    units = res.units
    con.rule(f"[bold]TEAM[/bold] {escape(st.deck.title)}")
    con.print(escape(f"filter {st.filter_kind}{' (square root)' if st.square_root else ''}, propagation {st.propagation}, "
                     f"generalized covariance {'on' if st.gencov else 'off'}; reference: {source}"))
    pt = Table(title="augmented parameters", title_justify="left", show_edge=False, pad_edge=False)
    for c in ("label", "role", "unit", "a-priori 1σ (assumed)", "a-priori 1σ (true)", "final 1σ (assumed)"):
        pt.add_column(c, justify="right" if "σ" in c else "left")
    n0 = st.nx
    for j, lab in enumerate(st.labels):
        i = n0 + j
        pt.add_row(escape(lab), st.roles[j], escape(st.units[j]), _fmt(np.sqrt(st.P0_assumed[i, i])), _fmt(np.sqrt(st.P0_true[i, i])),
                   _fmt(np.sqrt(max(res.Pa_plus[-1][i, i], 0.0))))
    con.print(pt)

    ev = Table(title="event log (RSS 1σ after each event)", title_justify="left", show_edge=False, pad_edge=False)
    for c in ("t (d)", "event", "obs", "pos (km)", "vel (mm/s)"):
        ev.add_column(c, justify="right")
    if st.gencov:
        ev.add_column("true pos (km)", justify="right")
        ev.add_column("true vel (mm/s)", justify="right")
    used_at = {}
    for r in res.meas.records:
        if r.used:
            used_at[r.k] = used_at.get(r.k, 0) + 1
    n_meas = 0
    every = st.deck.print.every
    for k in range(sched.n):
        evs = sched.events[k]
        show = any(e in _EVENT_SHOW for e in evs)
        if "measurement" in evs:
            n_meas += 1
            show = show or (n_meas % every == 0)
        if not show:
            continue
        P = res.Pa_plus[k]
        row = [f"{res.times_s[k] / DAY_S:.4f}", "+".join(evs), str(used_at.get(k, "")),
               f"{np.sqrt(max(np.trace(P[:3, :3]), 0)):.5g}", f"{np.sqrt(max(np.trace(P[3:6, 3:6]), 0)) * 1e6:.5g}"]
        if st.gencov:
            T = res.Pt_plus[k]
            row += [f"{np.sqrt(max(np.trace(T[:3, :3]), 0)):.5g}", f"{np.sqrt(max(np.trace(T[3:6, 3:6]), 0)) * 1e6:.5g}"]
        ev.add_row(*row)
    con.print(ev)
    if st.deck.print.process_noise:
        kq = [k for k in range(sched.n) if "propagation" in sched.events[k]]
        if kq:
            q = np.array([np.sqrt(max(np.trace(res.Q_assumed[k][3:6, 3:6]), 0)) * 1e6 for k in kq])
            con.print(f"process noise at propagation events: RSS velocity 1σ {q.min():.3g}..{q.max():.3g} mm/s per interval")

    for k in range(sched.n):
        if not ({"eigenvector", "thrust_on", "thrust_off", "final"} & set(sched.events[k])):
            continue
        for which, P in (("assumed", res.Pa_plus[k]), ("true", res.Pt_plus[k] if res.Pt_plus is not None else None)):
            if P is None:
                continue
            t, eig = covariance_table(P, res.labels, units,
                                      escape(f"{which} knowledge at t = {res.times_s[k] / DAY_S:.4f} d ({'+'.join(sched.events[k])})"),
                                      st.deck.print.correlations)
            con.print(t)
            con.print(eig)
    for k, lst in sorted(res.predictions.items()):
        for t_to, Pa, Pt in lst:
            ea = eigen_summary(Pa)
            line = (f"prediction {res.times_s[k] / DAY_S:.4f} d -> {t_to / DAY_S:.4f} d: assumed RSS {ea.pos_rss:.5g} km, "
                    f"{ea.vel_rss * 1e6:.5g} mm/s")
            if Pt is not None:
                et = eigen_summary(Pt)
                line += f"; true RSS {et.pos_rss:.5g} km, {et.vel_rss * 1e6:.5g} mm/s"
            con.print(escape(line))
    if res.meas.skipped:
        parts = [f"{st.deck.tracking[j].type} {'+'.join(st.deck.tracking[j].stations)}: {c}"
                 for j, c in sorted(res.meas.skipped.items())]
        con.print(f"[yellow]below {st.min_elevation_deg:g} deg elevation, skipped:[/yellow] " + escape("; ".join(parts)))
    for k, e, which, val in res.psd_problems[:5]:
        con.print(f"[red]warning:[/red] {which} covariance not positive semi-definite at t = "
                  f"{res.times_s[k] / DAY_S:.6g} d ({e} event), smallest eigenvalue {val:.3g} (mixed units)")
    if path is not None:
        con.print(escape(f"written: {path}"))


def plot_team(res, png: str | Path) -> Path:
    """Position and velocity RSS 1σ and parameter 1σ (relative to a priori) against time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import os
    import tempfile

    st = res.study
    t = res.times_s / DAY_S
    fig, ax = plt.subplots(3, 1, figsize=(8, 9), sharex=True)
    for which, P, style in (("assumed", res.Pa_plus, "-"), ("true", res.Pt_plus, "--")):
        if P is None:
            continue
        pos = np.sqrt(np.clip(np.einsum("kii->k", P[:, :3, :3]), 0, None))
        vel = np.sqrt(np.clip(np.einsum("kii->k", P[:, 3:6, 3:6]), 0, None)) * 1e6
        ax[0].semilogy(t, pos, style, label=which)
        ax[1].semilogy(t, vel, style, label=which)
    ax[0].set_ylabel("position RSS 1σ (km)")
    ax[1].set_ylabel("velocity RSS 1σ (mm/s)")
    prior = np.sqrt(np.diag(st.P0_assumed))[st.nx:]
    sig = np.sqrt(np.clip(np.einsum("kii->ki", res.Pa_plus[:, st.nx:st.layout.n, st.nx:st.layout.n]), 0, None))
    for j, lab in enumerate(st.labels):
        if prior[j] > 0 and st.roles[j] == "solve_for":
            ax[2].plot(t, sig[:, j] / prior[j], label=lab)
    ax[2].set_ylabel("solve-for 1σ / a priori")
    ax[2].set_xlabel("days from the trajectory epoch")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(f"TEAM knowledge: {st.deck.title}")
    fig.tight_layout()
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{png.name}.", suffix=".tmp", dir=png.parent)
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=110, format="png")
        os.replace(tmp, png)
    finally:
        plt.close(fig)
        if os.path.exists(tmp):
            os.unlink(tmp)
    return png
