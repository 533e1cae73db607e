"""TEAM printout (FRACAS PRINT, GPRINT) as terminal tables, and a PNG of the knowledge history.

Everything here reads a results file (:func:`fracas.io.team_results.read_team_results`'s
dict, ``r`` below), never the engine's state, so ``fracas report FILE`` can print any run.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fracas.constants import DAY_S

__all__ = ["print_team", "plot_team", "covariance_table", "summary_dict", "load"]

_EIGEN_EVENTS = ("eigenvector", "thrust_on", "thrust_off", "final")


def load(path) -> dict:
    """The results file's contents (a one-line error if it is missing or not a results file)."""
    from fracas.io.team_results import read_team_results

    return read_team_results(path)


def _rss(P: np.ndarray, blk: slice) -> float:
    s = np.sqrt(np.clip(np.diag(P)[blk], 0.0, None))
    return float(np.sqrt(np.sum(s**2)))


def _eigen_at(h: dict, k: int):
    """(sigma, corr, pos axes, pos eigvec, vel axes, vel eigvec) of history ``h`` at event k."""
    eg = h["eigenvector_events"]
    i = int(np.nonzero(eg["index"] == k)[0][0])
    return (
        h["sigma"][k],
        eg["correlations"][i],
        np.sqrt(np.clip(eg["position_eigenvalues"][i], 0.0, None)),
        eg["position_eigenvectors"][i],
        np.sqrt(np.clip(eg["velocity_eigenvalues"][i], 0.0, None)),
        eg["velocity_eigenvectors"][i],
    )


_EVENT_SHOW = ("thrust_on", "thrust_off", "propagation", "eigenvector", "prediction", "punch", "final", "initial")


def _fmt(x: float) -> str:
    return f"{x:.4g}" if np.isfinite(x) else "-"


def covariance_table(h: dict, k: int, labels: list[str], units: list[str], title: str, correlations: bool = True):
    """Standard deviations and the state correlation matrix (like App. 9.3 Table 2) of
    history ``h`` at eigenvector event ``k``, and the position/velocity semi-axes."""
    from rich.markup import escape
    from rich.table import Table

    sigma, corr, pos_axes, pos_vec, vel_axes, vel_vec = _eigen_at(h, k)
    state = labels[:6]
    t = Table(title=title, title_justify="left", show_edge=False, pad_edge=False)
    t.add_column("", justify="left")
    t.add_column("1σ", justify="right")
    t.add_column("unit")
    if correlations:
        for s in state:
            t.add_column(s, justify="right")
    for i, lab in enumerate(labels):
        row = [escape(lab), f"{sigma[i]:.6g}", escape(units[i])]
        if correlations:
            row += [f"{corr[i, j]:+.4f}" if (j <= i or i >= 6) else "" for j in range(6)]
        t.add_row(*row)
    eig = Table(
        title="position / velocity 1σ semi-axes (eigenvalues^½) and eigenvectors",
        title_justify="left",
        show_edge=False,
        pad_edge=False,
    )
    for c in ("block", "axis", "1σ", "unit", "x", "y", "z"):
        eig.add_column(c, justify="right")
    for name, ax, V, unit in (("position", pos_axes, pos_vec, "km"), ("velocity", vel_axes * 1e6, vel_vec, "mm/s")):
        for a in range(3)[::-1]:
            eig.add_row(name, str(3 - a), f"{ax[a]:.5g}", unit, *(f"{v:+.4f}" for v in V[:, a]))
    return t, eig


def summary_dict(r: dict) -> dict:
    """A JSON-able summary of a TEAM results file (``fracas run --json``)."""
    at = r["attrs"]
    m = r["measurements"]
    used = np.asarray(m["used"], dtype=bool)

    def block(h):
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


def print_team(r: dict, console=None) -> None:
    """The FRACAS-style printout of a results file: study, event log, eigenvector events,
    predictions, warnings."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    con = console or Console(width=None if __import__("sys").stdout.isatty() else 160)
    at, pr = r["attrs"], r["print"]
    labels, units, roles = r["labels"], r["units"], r["roles"]
    events = [e.split("+") for e in r["event_types"]]
    times = r["times_s"]
    A, T = r["assumed"], r.get("true")
    gencov = T is not None
    nx = int(at.get("n_state", 7))
    con.rule(f"[bold]TEAM[/bold] {escape(str(at['title']))}")
    con.print(
        escape(
            f"filter {at['filter']}{' (square root)' if int(at['square_root']) else ''}, propagation "
            f"{at['propagation']}, generalized covariance {'on' if gencov else 'off'}; "
            f"reference: {at['reference']}"
        )
    )
    pt = Table(title="augmented parameters", title_justify="left", show_edge=False, pad_edge=False)
    for c in ("label", "role", "unit", "a-priori 1σ (assumed)", "a-priori 1σ (true)", "final 1σ (assumed)"):
        pt.add_column(c, justify="right" if "σ" in c else "left")
    for i in range(nx, len(labels)):
        if roles[i] == "noise_state":
            continue
        true0 = T["a_priori_sigma"][i] if gencov else A["a_priori_sigma"][i]
        pt.add_row(
            escape(labels[i]),
            roles[i],
            escape(units[i]),
            _fmt(A["a_priori_sigma"][i]),
            _fmt(true0),
            _fmt(np.sqrt(max(A["P_plus"][-1][i, i], 0.0))),
        )
    con.print(pt)

    ev = Table(title="event log (RSS 1σ after each event)", title_justify="left", show_edge=False, pad_edge=False)
    for c in ("t (d)", "event", "obs", "pos (km)", "vel (mm/s)"):
        ev.add_column(c, justify="right")
    if gencov:
        ev.add_column("true pos (km)", justify="right")
        ev.add_column("true vel (mm/s)", justify="right")
    m = r["measurements"]
    used = np.asarray(m["used"], dtype=bool)
    used_at: dict[int, int] = {}
    for k in np.asarray(m["index"])[used]:
        used_at[int(k)] = used_at.get(int(k), 0) + 1
    n_meas = 0
    every = int(pr.get("every", 1))
    for k in range(len(times)):
        evs = events[k]
        show = any(e in _EVENT_SHOW for e in evs)
        if "measurement" in evs:
            n_meas += 1
            show = show or (n_meas % every == 0)
        if not show:
            continue
        P = A["P_plus"][k]
        row = [
            f"{times[k] / DAY_S:.4f}",
            "+".join(evs),
            str(used_at.get(k, "")),
            f"{np.sqrt(max(np.trace(P[:3, :3]), 0)):.5g}",
            f"{np.sqrt(max(np.trace(P[3:6, 3:6]), 0)) * 1e6:.5g}",
        ]
        if gencov:
            Pt = T["P_plus"][k]
            row += [
                f"{np.sqrt(max(np.trace(Pt[:3, :3]), 0)):.5g}",
                f"{np.sqrt(max(np.trace(Pt[3:6, 3:6]), 0)) * 1e6:.5g}",
            ]
        ev.add_row(*row)
    con.print(ev)
    if int(pr.get("process_noise", 0)):
        kq = [k for k in range(len(times)) if "propagation" in events[k]]
        if kq:
            q = np.array([np.sqrt(max(np.trace(A["process_noise"][k][3:6, 3:6]), 0)) * 1e6 for k in kq])
            con.print(
                f"process noise at propagation events: RSS velocity 1σ {q.min():.3g}..{q.max():.3g} mm/s per interval"
            )

    for k in range(len(times)):
        if not (set(_EIGEN_EVENTS) & set(events[k])):
            continue
        for which, h in (("assumed", A), ("true", T)):
            if h is None:
                continue
            t, eig = covariance_table(
                h,
                k,
                labels,
                units,
                escape(f"{which} knowledge at t = {times[k] / DAY_S:.4f} d ({'+'.join(events[k])})"),
                bool(int(pr.get("correlations", 1))),
            )
            con.print(t)
            con.print(eig)
    for p in r["predictions"]:
        line = f"prediction {p['time_from_s'] / DAY_S:.4f} d -> {p['time_to_s'] / DAY_S:.4f} d: "
        if p["status"]:
            con.print(escape(line + "not computed: the trajectory ends before the target time"))
            continue
        Pa, Pt = p["assumed"], p["true"]
        line += f"assumed RSS {_rss(Pa, slice(0, 3)):.5g} km, {_rss(Pa, slice(3, 6)) * 1e6:.5g} mm/s"
        if Pt is not None:
            line += f"; true RSS {_rss(Pt, slice(0, 3)):.5g} km, {_rss(Pt, slice(3, 6)) * 1e6:.5g} mm/s"
        con.print(escape(line))
    skipped: dict[int, int] = {}
    for j in np.asarray(m["tracking"])[~used]:
        skipped[int(j)] = skipped.get(int(j), 0) + 1
    if skipped:
        parts = [f"{r['tracking'][j][0]} {r['tracking'][j][1]}: {c}" for j, c in sorted(skipped.items())]
        con.print(
            f"[yellow]below {float(at.get('min_elevation_deg', 0.0)):g} deg elevation, skipped:[/yellow] "
            + escape("; ".join(parts))
        )
    for k, e, which, val in r["psd_problems"][:5]:
        con.print(
            f"[red]warning:[/red] {which} covariance not positive semi-definite at t = "
            f"{times[k] / DAY_S:.6g} d ({e} event), smallest eigenvalue {val:.3g} (mixed units)"
        )
    con.print(escape(f"written: {r['path']}"))


def plot_team(r: dict, png: str | Path) -> Path:
    """Position and velocity RSS 1σ and parameter 1σ (relative to a priori) against time."""
    import matplotlib

    matplotlib.use("Agg")
    import os
    import tempfile

    import matplotlib.pyplot as plt

    nx = int(r["attrs"].get("n_state", 7))
    t = r["times_s"] / DAY_S
    fig, ax = plt.subplots(3, 1, figsize=(8, 9), sharex=True)
    for which, style in (("assumed", "-"), ("true", "--")):
        if which not in r:
            continue
        P = r[which]["P_plus"]
        pos = np.sqrt(np.clip(np.einsum("kii->k", P[:, :3, :3]), 0, None))
        vel = np.sqrt(np.clip(np.einsum("kii->k", P[:, 3:6, 3:6]), 0, None)) * 1e6
        ax[0].semilogy(t, pos, style, label=which)
        ax[1].semilogy(t, vel, style, label=which)
    ax[0].set_ylabel("position RSS 1σ (km)")
    ax[1].set_ylabel("velocity RSS 1σ (mm/s)")
    A = r["assumed"]
    for i, lab in enumerate(r["labels"]):
        prior = A["a_priori_sigma"][i]
        if i >= nx and prior > 0 and r["roles"][i] == "solve_for":
            ax[2].plot(t, A["sigma"][:, i] / prior, label=lab)
    ax[2].set_ylabel("solve-for 1σ / a priori")
    ax[2].set_xlabel("days from the trajectory epoch")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(f"TEAM knowledge: {r['attrs']['title']}")
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
