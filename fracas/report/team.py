"""TEAM printout (FRACAS PRINT, GPRINT) as terminal tables, and a PNG of the knowledge history.

Everything here reads a results file (:func:`fracas.io.team_results.read_team_results`'s
dict, ``r`` below), never the engine's state, so ``fracas report FILE`` can print any run.

The printout has three levels (``verbosity``): ``"quiet"`` one line (:func:`quiet_line`),
``"normal"`` the study, the parameters, an event log thinned to the interesting events, the
final knowledge, predictions and warnings, and ``"verbose"`` everything (every event the
deck's ``[print]`` asks for and each eigenvector event's table with correlations).  Every
table fits an 80-column terminal: text columns (labels, roles, units, events) wrap, numbers
are printed in a fixed compact format in columns that never wrap or cut.  One unit per
quantity across a printout: positions in km, velocities in ``velocity_unit``.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from fracas.constants import DAY_S
from fracas.report._tables import VELOCITY_UNITS, _fmt, _num_col, _table, _text_col, _unit, _vfactor
from fracas.report.guidance import (
    bplane_figure,
    budget_figure,
    correlation_figure,
    dv_figure,
    mark_guidance,
    print_budget,
    print_guidance,
    save_figure,
)
from fracas.status import RunStatus, status_text

__all__ = [
    "print_team",
    "plot_team",
    "plot_all",
    "team_figure",
    "team_figures",
    "covariance_table",
    "summary_dict",
    "quiet_line",
    "load",
    "VERBOSITY",
    "VELOCITY_UNITS",
]

_EIGEN_EVENTS = ("eigenvector", "thrust_on", "thrust_off", "final")
#: the printout levels, least to most
VERBOSITY = ("quiet", "normal", "verbose")
_SHORT_EVENT = {
    "initial": "init",
    "thrust_on": "on",
    "thrust_off": "off",
    "propagation": "prop",
    "measurement": "meas",
    "eigenvector": "eigen",
    "prediction": "pred",
    "punch": "punch",
    "final": "final",
}
_EVENT_LEGEND = (
    "events: init initial, on/off thrust on/off, prop propagation, meas measurement, eigen eigenvector, pred prediction"
)
_SHORT_ROLE = {"dynamic_consider": "dyn_consider", "measurement_consider": "meas_consider"}
_NORMAL_EVENTS = ("initial", "thrust_on", "thrust_off", "eigenvector", "prediction", "punch", "final")


def _breakable_where_too_wide(rows: list[list[str]], width: int) -> list[list[str]]:
    """The parameter table's rows, with break points where the table is wider than ``width``.

    Rows are (label, role, unit, three numbers).  When the widest cells need more than
    ``width`` columns, a label may wrap before its bracket (``station_radius_km`` /
    ``[goldstone]``) and a role at its underscore (``meas`` / ``consider``), so that rich never
    folds a word in the middle (``station_radius_km[go`` / ``ldstone]``).  A table that fits is
    printed as before.
    """
    if not rows:
        return rows
    natural = sum(max(len(r[j]) for r in rows) for j in range(6)) + 3 * 5 + 9 * 3  # separators; headers
    if natural <= width:
        return rows
    return [[r[0].replace("[", " ["), r[1].replace("_", " "), *r[2:]] for r in rows]


def load(path) -> dict:
    """The results file's contents (a one-line error if it is missing or not a results file)."""
    from fracas.io.team_results import read_team_results

    return read_team_results(path)


def _rss(P: np.ndarray, blk: slice) -> float:
    with np.errstate(invalid="ignore"):
        s = np.sqrt(np.clip(np.diag(P)[blk], 0.0, None))
        return float(np.sqrt(np.sum(s**2)))


def _trace_rss(P: np.ndarray, blk: slice) -> float:
    with np.errstate(invalid="ignore"):
        return float(np.sqrt(max(np.trace(P[blk, blk]), 0.0))) if np.isfinite(np.trace(P[blk, blk])) else math.nan


def _eigen_at(h: dict, k: int):
    """(sigma, corr, pos axes, pos eigvec, vel axes, vel eigvec) of history ``h`` at event k."""
    eg = h["eigenvector_events"]
    i = int(np.nonzero(eg["index"] == k)[0][0])
    with np.errstate(invalid="ignore"):
        return (
            h["sigma"][k],
            eg["correlations"][i],
            np.sqrt(np.clip(eg["position_eigenvalues"][i], 0.0, None)),
            eg["position_eigenvectors"][i],
            np.sqrt(np.clip(eg["velocity_eigenvalues"][i], 0.0, None)),
            eg["velocity_eigenvectors"][i],
        )


_EVENT_SHOW = ("thrust_on", "thrust_off", "propagation", "eigenvector", "prediction", "punch", "final", "initial")


def covariance_table(
    h: dict,
    k: int,
    labels: list[str],
    units: list[str],
    title: str,
    correlations: bool = True,
    velocity_unit: str = "mm/s",
):
    """Standard deviations and the state correlation matrix (like App. 9.3 Table 2) of
    history ``h`` at eigenvector event ``k``, and the position/velocity semi-axes (km and
    ``velocity_unit``); two :class:`rich.table.Table`."""
    from rich.markup import escape

    sigma, corr, pos_axes, pos_vec, vel_axes, vel_vec = _eigen_at(h, k)
    state = labels[:6]
    t = _table(title, boxed=False)
    _text_col(t, "")
    _num_col(t, "1σ")
    _text_col(t, "unit")
    if correlations:
        for s in state:
            _num_col(t, s)
    for i, lab in enumerate(labels):
        f, u = _unit(units[i], velocity_unit)
        row = [escape(lab), _fmt(sigma[i] * f), escape(u)]
        if correlations:
            row += [f"{corr[i, j]:+.3f}" if (j <= i or i >= 6) else "" for j in range(6)]
        t.add_row(*row)
    eig = _table("position / velocity 1σ semi-axes (eigenvalues^½) and eigenvectors", boxed=False)
    for c in ("block", "axis"):
        _text_col(eig, c, "right")
    _num_col(eig, "1σ")
    _text_col(eig, "unit", "right")
    for c in ("x", "y", "z"):
        _num_col(eig, c)
    vf = _vfactor(velocity_unit)
    for name, ax, V, unit in (
        ("position", pos_axes, pos_vec, "km"),
        ("velocity", vel_axes * vf, vel_vec, velocity_unit),
    ):
        for a in range(3)[::-1]:
            eig.add_row(name, str(3 - a), _fmt(ax[a]), unit, *(f"{v:+.3f}" for v in V[:, a]))
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


def quiet_line(r: dict, velocity_unit: str = "mm/s", file_label: str = "written") -> str:
    """The one-line summary (``--quiet``): events, measurements used, final assumed RSS, file
    (``file_label``: "written" after a run, the file's kind when a report reads it)."""
    s = summary_dict(r)
    v = s["assumed"]["velocity_rss_km_s"] * _vfactor(velocity_unit)
    line = (
        f"{s['events']} events, {s['measurements_used']} measurements; final assumed RSS "
        f"{s['assumed']['position_rss_km']:.4g} km, {v:.4g} {velocity_unit}; {file_label}: {r['path']}"
    )
    return line


def _event_status(r: dict, which: str) -> np.ndarray:
    """Per-event status of history ``which`` (the file's event_status; older files: from
    psd_problems and the stored matrices)."""
    h = r[which]
    if "event_status" in h:
        return np.asarray(h["event_status"], dtype=np.int64)
    P = h["P_plus"]
    st = np.zeros(len(P), dtype=np.int64)
    for k, _e, w, _v in r["psd_problems"]:
        if w == which:
            st[k] = int(RunStatus.NOT_POSITIVE_DEFINITE)
    st[~np.all(np.isfinite(P.reshape(len(P), -1)), axis=1)] = int(RunStatus.NONFINITE_COVARIANCE)
    return st


def _log_rows(events: list[list[str]], every: int, verbosity: str, bad: set[int], max_rows: int) -> list[int]:
    """Schedule indices shown in the event log."""
    meas = [k for k, e in enumerate(events) if "measurement" in e]
    if verbosity == "verbose":
        keep = {k for k, e in enumerate(events) if any(x in _EVENT_SHOW for x in e)}
        keep |= {k for i, k in enumerate(meas, 1) if i % every == 0}
        return sorted(keep | bad)
    keep = {k for k, e in enumerate(events) if any(x in _NORMAL_EVENTS for x in e)}
    keep |= set(sorted(bad)[:1])
    if meas:
        keep |= {meas[0], meas[-1]}
        room = max(max_rows - len(keep), 1)
        step = max(every, math.ceil(len(meas) / room))
        keep |= {k for i, k in enumerate(meas, 1) if i % step == 0}
    return sorted(keep)


def process_noise_line(at) -> str:
    """The process noise the run applied (the filter's model; issue 24), in one line: the
    Gauss-Markov thrust noise by component (1-sigma, tau), white acceleration noise, and how
    it was propagated (PHI's model, or PDOT with its RK4 steps).  Empty without any noise."""
    sig = np.ravel(np.asarray(at.get("thrust_noise_sigma", []), float))
    tau = np.ravel(np.asarray(at.get("thrust_noise_tau_s", []), float))
    q = float(at.get("white_noise_km2_s3", 0.0) or 0.0)
    parts = []
    if sig.size == 3 and np.any(sig > 0):
        # one 80-column line: proportionality ("scale"), in-plane and out-of-plane pointing
        names = ("scale", "in", "out")
        scale = (1.0, np.degrees(1.0), np.degrees(1.0))
        unit = ("", "°", "°")
        comps = [
            f"{n} {sig[i] * scale[i]:.3g}{unit[i]}/{tau[i] / DAY_S:.3g} d" for i, n in enumerate(names) if sig[i] > 0
        ]
        parts.append("thrust 1σ/τ: " + ", ".join(comps))
    if q > 0:
        parts.append(f"white {q:.3g} km²/s³ {at.get('white_noise_direction', 'full')}")
    if not parts:
        return ""
    how = str(at.get("process_noise", ""))
    if how in ("grid", "interval") and sig.size == 3 and np.any(sig > 0):
        # FRACAS's effective Q̃, approximate (docs/team_results.md); as short as the old names
        how = {"grid": "DYNO", "interval": "DYNO int"}[how]
    if how == "pdot":
        lo, hi = at.get("pdot_step_min_s"), at.get("pdot_step_max_s")
        how = "PDOT" + (f" steps {float(lo):.3g}-{float(hi):.3g} s" if lo is not None else "")
    return f"noise ({how}) " + "; ".join(parts)


def print_team(
    r: dict,
    console=None,
    *,
    verbosity: str = "normal",
    velocity_unit: str = "mm/s",
    width: int | None = None,
    max_log_rows: int = 16,
    file_label: str = "written",
) -> None:
    """The FRACAS-style printout of a results file ``r`` (:func:`load`).

    ``verbosity``: ``"quiet"`` (:func:`quiet_line`), ``"normal"`` (study, parameters, an
    event log of at most about ``max_log_rows`` rows -- thrust switches, eigenvector,
    prediction and punch events, the first and last measurement and every N-th --, the
    final assumed/true 1σ table, predictions, warnings) or ``"verbose"`` (every event the
    deck's ``[print] every`` asks for and every eigenvector event's tables, the printout
    before the levels existed; the default of this function, the command line's default is
    ``"normal"``).  ``velocity_unit``: one of :data:`VELOCITY_UNITS`, used for every velocity
    in the printout.  ``console``: a :class:`rich.console.Console` (default: stdout, ``width``
    columns, else the terminal's width, 160 when not a terminal).
    """
    from rich.console import Console
    from rich.markup import escape

    if verbosity not in VERBOSITY:
        raise ValueError(f"verbosity must be one of {', '.join(VERBOSITY)}, not {verbosity!r}")
    vf = _vfactor(velocity_unit)
    vu = velocity_unit
    con = console or Console(width=width or (None if sys.stdout.isatty() else 160))
    if verbosity == "quiet":
        con.print(quiet_line(r, vu), markup=False, highlight=False, soft_wrap=True)
        return
    at, pr = r["attrs"], r["print"]
    labels, units, roles = r["labels"], r["units"], r["roles"]
    events = [e.split("+") for e in r["event_types"]]
    times = r["times_s"]
    K = len(times)
    A, T = r["assumed"], r.get("true")
    gencov = T is not None
    nx = int(at.get("n_state", 7))
    hist = [("assumed", A)] + ([("true", T)] if gencov else [])
    status = {w: _event_status(r, w) for w, _ in hist}
    bad = {int(k) for st in status.values() for k in np.nonzero(st)[0]}

    con.rule(f"[bold]TEAM[/bold] {escape(str(at['title']))}")
    con.print(
        escape(
            f"filter {at['filter']}{' (square root)' if int(at['square_root']) else ''}, propagation "
            f"{at['propagation']}, generalized covariance {'on' if gencov else 'off'}; "
            f"reference: {at['reference']}"
        )
    )
    pt = _table("augmented parameters (1σ)")
    for c in ("label", "role", "unit"):
        _text_col(pt, c)
    for c in ("a priori\nassumed", "a priori\ntrue", "final\nassumed"):
        _num_col(pt, c)
    rows = []
    for i in range(nx, len(labels)):
        if roles[i] == "noise_state":
            continue
        f, u = _unit(units[i], vu)
        true0 = T["a_priori_sigma"][i] if gencov else A["a_priori_sigma"][i]
        rows.append(
            [
                labels[i],
                _SHORT_ROLE.get(roles[i], roles[i]),
                u,
                _fmt(A["a_priori_sigma"][i] * f),
                _fmt(true0 * f),
                _fmt(A["sigma"][-1][i] * f),
            ]
        )
    for row in _breakable_where_too_wide(rows, con.width):
        pt.add_row(*(escape(c) for c in row))
    con.print(pt)

    m = r["measurements"]
    used = np.asarray(m["used"], dtype=bool)
    used_at: dict[int, int] = {}
    for k in np.asarray(m["index"])[used]:
        used_at[int(k)] = used_at.get(int(k), 0) + 1
    rows = _log_rows(events, max(int(pr.get("every", 1)), 1), verbosity, bad, max_log_rows)
    title = "event log (RSS 1σ after each event)"
    if len(rows) < K:
        title += f", {len(rows)} of {K} events"
    ev = _table(title)
    _num_col(ev, "t (d)")
    _text_col(ev, "event")
    _num_col(ev, "obs")
    _num_col(ev, "pos\n(km)")
    _num_col(ev, f"vel\n({vu})")
    if gencov:
        _num_col(ev, "true pos\n(km)")
        _num_col(ev, f"true vel\n({vu})")
    for k in rows:
        row = [f"{times[k] / DAY_S:.4f}", " ".join(_SHORT_EVENT.get(e, e) for e in events[k]), str(used_at.get(k, ""))]
        for _w, h in hist:
            P = h["P_plus"][k]
            row += [_fmt(_trace_rss(P, slice(0, 3))), _fmt(_trace_rss(P, slice(3, 6)) * vf)]
        ev.add_row(*row)
    ev.caption = _EVENT_LEGEND
    ev.caption_justify = "left"
    con.print(ev)
    noise_line = process_noise_line(at)
    if noise_line:
        con.print(noise_line)
    if int(pr.get("process_noise", 0)) and at.get("process_noise") != "pdot":
        kq = [k for k in range(K) if "propagation" in events[k]]
        if kq:
            q = np.array([_trace_rss(A["process_noise"][k], slice(3, 6)) * vf for k in kq])
            con.print(
                f"process noise at propagation events: RSS velocity 1σ {_fmt(np.nanmin(q))}..{_fmt(np.nanmax(q))} "
                f"{vu} per interval"
            )

    if verbosity == "verbose":
        for k in range(K):
            if not (set(_EIGEN_EVENTS) & set(events[k])):
                continue
            for which, h in hist:
                t, eig = covariance_table(
                    h,
                    k,
                    labels,
                    units,
                    escape(f"{which} knowledge at t = {times[k] / DAY_S:.4f} d ({'+'.join(events[k])})"),
                    bool(int(pr.get("correlations", 1))),
                    velocity_unit=vu,
                )
                con.print(t)
                con.print(eig)
    else:
        ft = _table(f"final knowledge at t = {times[-1] / DAY_S:.4f} d (1σ)", boxed=False)
        for c in ("label", "unit"):
            _text_col(ft, c)
        _num_col(ft, "assumed")
        if gencov:
            _num_col(ft, "true")
        for i, lab in enumerate(labels):
            if roles[i] == "noise_state":  # stationary, never estimated: in --verbose's tables
                continue
            f, u = _unit(units[i], vu)
            ft.add_row(escape(lab), escape(u), *(_fmt(h["sigma"][-1][i] * f) for _w, h in hist))
        con.print(ft)
        for which, h in hist:
            eg = h["eigenvector_events"]
            if K - 1 in np.asarray(eg["index"]).tolist():
                _s, _c, pa, _pv, va, _vv = _eigen_at(h, K - 1)
                con.print(
                    f"{which} 1σ semi-axes at the end: position {', '.join(_fmt(x) for x in pa[::-1])} km; "
                    f"velocity {', '.join(_fmt(x * vf) for x in va[::-1])} {vu}"
                )

    for p in r["predictions"]:
        line = f"prediction {p['time_from_s'] / DAY_S:.4f} d -> {p['time_to_s'] / DAY_S:.4f} d: "
        if p["status"]:
            con.print(escape(line + "not computed: the trajectory ends before the target time"))
            continue
        Pa, Pt = p["assumed"], p["true"]
        line += f"assumed RSS {_fmt(_rss(Pa, slice(0, 3)))} km, {_fmt(_rss(Pa, slice(3, 6)) * vf)} {vu}"
        if Pt is not None:
            line += f"; true RSS {_fmt(_rss(Pt, slice(0, 3)))} km, {_fmt(_rss(Pt, slice(3, 6)) * vf)} {vu}"
        con.print(escape(line))

    print_guidance(r, con, verbosity=verbosity, velocity_unit=vu)
    print_budget(r, con, verbosity=verbosity, velocity_unit=vu)

    mask = float(at.get("min_elevation_deg", 0.0))
    trk = np.asarray(m["tracking"])
    parts, none_used = [], []
    for j, (kind, sta) in enumerate(r["tracking"]):
        n = int(np.sum(trk == j))
        nu = int(np.sum(used[trk == j]))
        if n - nu:
            parts.append(f"{kind} {sta}: skipped {n - nu} of {n}")
        if nu == 0:
            why = f"all {n} below {mask:g} deg elevation" if n else "none scheduled in the run"
            none_used.append(f"tracking[{j}] {kind} {sta}: no usable measurement ({why})")
    if parts:
        con.print(f"[yellow]below {mask:g} deg elevation:[/yellow] " + escape("; ".join(parts)))
    for line in none_used:
        con.print("[yellow]warning:[/yellow] " + escape(line))
    for k, e, which, val in r["psd_problems"][:5]:
        if np.isfinite(val):
            con.print(
                f"[red]warning:[/red] {which} covariance not positive semi-definite at t = "
                f"{times[k] / DAY_S:.4f} d ({e} event), smallest eigenvalue {_fmt(val)} (mixed units)"
            )
    for which, _h in hist:
        st = status[which]
        nz = np.nonzero(st)[0]
        if len(nz):
            k = int(nz[0])
            con.print(
                f"[red]warning:[/red] {which} covariance first at t = {times[k] / DAY_S:.4f} d "
                f"({escape('+'.join(events[k]))} event): {escape(status_text(st[k]))}; "
                f"{len(nz)} of {K} events affected"
            )
    code = int(at.get("status", 0))
    if code:
        con.print(f"[red]status {code}:[/red] {escape(str(at.get('status_text', status_text(code))))}")
    con.print(f"{file_label}: {r['path']}", markup=False, highlight=False, overflow="ignore")


def team_figure(r: dict, velocity_unit: str = "mm/s"):
    """Position and velocity RSS 1σ and parameter 1σ (relative to a priori) against time, a
    matplotlib figure; velocities in ``velocity_unit`` (the printout's).

    With guidance events in the file (``r["guidance"]``), vertical lines mark them; with a
    control covariance (``r["control"]``), its RSS 1σ (the actual dispersion about the
    reference) is a third curve.  Without either the figure is what it always was."""
    import matplotlib

    matplotlib.use("Agg")

    import matplotlib.pyplot as plt

    vf = _vfactor(velocity_unit)
    nx = int(r["attrs"].get("n_state", 7))
    t = r["times_s"] / DAY_S
    fig, ax = plt.subplots(3, 1, figsize=(8, 9), sharex=True)
    for which, style in (("assumed", "-"), ("true", "--")):
        if which not in r:
            continue
        P = r[which]["P_plus"]
        pos = np.sqrt(np.clip(np.einsum("kii->k", P[:, :3, :3]), 0, None))
        vel = np.sqrt(np.clip(np.einsum("kii->k", P[:, 3:6, 3:6]), 0, None)) * vf
        ax[0].semilogy(t, pos, style, label=which)
        ax[1].semilogy(t, vel, style, label=which)
    if r.get("control") is not None:
        P = np.asarray(r["control"]["P_plus"])
        pos = np.sqrt(np.clip(np.einsum("kii->k", P[:, :3, :3]), 0, None))
        vel = np.sqrt(np.clip(np.einsum("kii->k", P[:, 3:6, 3:6]), 0, None)) * vf
        ax[0].semilogy(t, pos, ":", label="control (actual dispersion)")
        ax[1].semilogy(t, vel, ":", label="control (actual dispersion)")
    ax[0].set_ylabel("position RSS 1σ (km)")
    ax[1].set_ylabel(f"velocity RSS 1σ ({velocity_unit})")
    A = r["assumed"]
    for i, lab in enumerate(r["labels"]):
        prior = A["a_priori_sigma"][i]
        if i >= nx and prior > 0 and r["roles"][i] == "solve_for":
            ax[2].plot(t, A["sigma"][:, i] / prior, label=lab)
    ax[2].set_ylabel("solve-for 1σ / a priori")
    ax[2].set_xlabel("days from the trajectory epoch")
    if r.get("guidance"):
        mark_guidance(r, ax)
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(f"TEAM knowledge: {r['attrs']['title']}")
    fig.tight_layout()
    return fig


def plot_team(r: dict, png: str | Path, velocity_unit: str = "mm/s") -> Path:
    """Write :func:`team_figure` as a PNG at ``png`` (atomically); returns the path."""
    return save_figure(team_figure(r, velocity_unit), png)


def plot_all(r: dict, png: str | Path, velocity_unit: str = "mm/s", dv_unit: str = "m/s") -> list[Path]:
    """Every plot of a results file: the knowledge history at ``png`` (:func:`plot_team`)
    and, where they apply, ``<stem>_bplane.png`` (guidance events targeting B·T and B·R),
    ``<stem>_correlation.png`` (an eigenvector event), ``<stem>_budget.png`` (an error
    budget) and ``<stem>_dv.png`` (guidance events) beside it; the paths written, in that
    order, each atomically.  Velocities in ``velocity_unit`` and ΔV in ``dv_unit``, the
    printout's (:func:`print_team`)."""
    png = Path(png)
    out = [plot_team(r, png, velocity_unit)]
    for suffix, fig in team_figures(r, velocity_unit, dv_unit, knowledge=False)[1:]:
        out.append(save_figure(fig, png.with_name(f"{png.stem}_{suffix}.png")))
    return out


def team_figures(r: dict, velocity_unit: str = "mm/s", dv_unit: str = "m/s", knowledge: bool = True) -> list:
    """(suffix, figure) of every plot :func:`plot_all` writes ("" for the knowledge
    history, first), built and not saved; the knowledge history is built only if
    ``knowledge`` (else its entry is ("", None))."""
    figs = [("", team_figure(r, velocity_unit) if knowledge else None)]
    for suffix, fig in (
        ("bplane", bplane_figure(r)),
        ("correlation", correlation_figure(r)),
        ("budget", budget_figure(r, velocity_unit, dv_unit)),
        ("dv", dv_figure(r, dv_unit)),
    ):
        if fig is not None:
            figs.append((suffix, fig))
    return figs
