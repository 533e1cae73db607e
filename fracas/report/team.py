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

The knowledge-history plot and :func:`plot_all` live in :mod:`fracas.report.team_plots`, the
short forms (:func:`summary_dict`, :func:`quiet_line`, :func:`process_noise_line`) in
:mod:`fracas.report.team_summary`; both are re-exported here.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from typing import Any

import numpy as np

from fracas.constants import DAY_S
from fracas.report._tables import VELOCITY_UNITS, _fmt, _num_col, _table, _text_col, _unit, _vfactor
from fracas.report.guidance import print_budget, print_guidance
from fracas.report.team_plots import plot_all, plot_team, team_figure, team_figures
from fracas.report.team_summary import process_noise_line, quiet_line, summary_dict
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


def load(path: Any) -> dict:
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


def _eigen_at(h: dict, k: int) -> tuple[np.ndarray, ...]:
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
) -> tuple[Any, Any]:
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


@dataclasses.dataclass(frozen=True)
class _Printout:
    """What the sections of :func:`print_team` share: the results ``r``, the console, the
    velocity unit and its factor, each schedule time's events, the covariance histories
    (assumed, then true with generalized covariance) and their per-event status."""

    r: dict
    con: Any
    vu: str
    vf: float
    events: list[list[str]]
    gencov: bool
    hist: list[tuple[str, dict]]
    status: dict[str, np.ndarray]
    bad: set[int]


def _printout(r: dict, con: Any, vu: str, vf: float) -> _Printout:
    events = [e.split("+") for e in r["event_types"]]
    A, T = r["assumed"], r.get("true")
    gencov = T is not None
    hist = [("assumed", A)] + ([("true", T)] if gencov else [])
    status = {w: _event_status(r, w) for w, _ in hist}
    bad = {int(k) for st in status.values() for k in np.nonzero(st)[0]}
    return _Printout(r, con, vu, vf, events, gencov, hist, status, bad)


def _print_study(p: _Printout) -> None:
    """The heading, the run's settings and the augmented parameters' 1σ."""
    from rich.markup import escape

    r, con, vu, gencov = p.r, p.con, p.vu, p.gencov
    at = r["attrs"]
    labels, units, roles = r["labels"], r["units"], r["roles"]
    A, T = r["assumed"], r.get("true")
    nx = int(at.get("n_state", 7))
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


def _print_event_log(p: _Printout, verbosity: str, max_log_rows: int) -> None:
    """The event log: RSS 1σ after each event shown (:func:`_log_rows`)."""
    r, con, vu, vf, events, gencov, hist, bad = p.r, p.con, p.vu, p.vf, p.events, p.gencov, p.hist, p.bad
    pr, times = r["print"], r["times_s"]
    K = len(times)
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


def _print_noise(p: _Printout) -> None:
    """The process noise applied (:func:`process_noise_line`) and, when the deck's ``[print]``
    asks for it, its range at the propagation events."""
    r, con, vu, vf, events = p.r, p.con, p.vu, p.vf, p.events
    at, pr, A = r["attrs"], r["print"], r["assumed"]
    K = len(r["times_s"])
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


def _print_eigen_tables(p: _Printout) -> None:
    """``"verbose"``: every eigenvector event's tables (:func:`covariance_table`)."""
    from rich.markup import escape

    r, con, vu, events, hist = p.r, p.con, p.vu, p.events, p.hist
    labels, units, pr, times = r["labels"], r["units"], r["print"], r["times_s"]
    K = len(times)
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


def _print_final_knowledge(p: _Printout) -> None:
    """The final knowledge 1σ (assumed, true) and the semi-axes at the end."""
    from rich.markup import escape

    r, con, vu, vf, gencov, hist = p.r, p.con, p.vu, p.vf, p.gencov, p.hist
    labels, units, roles, times = r["labels"], r["units"], r["roles"], r["times_s"]
    K = len(times)
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


def _print_predictions(p: _Printout) -> None:
    """One line per prediction: the RSS 1σ at its target time."""
    from rich.markup import escape

    r, con, vu, vf = p.r, p.con, p.vu, p.vf
    for pred in r["predictions"]:
        line = f"prediction {pred['time_from_s'] / DAY_S:.4f} d -> {pred['time_to_s'] / DAY_S:.4f} d: "
        if pred["status"]:
            con.print(escape(line + "not computed: the trajectory ends before the target time"))
            continue
        Pa, Pt = pred["assumed"], pred["true"]
        line += f"assumed RSS {_fmt(_rss(Pa, slice(0, 3)))} km, {_fmt(_rss(Pa, slice(3, 6)) * vf)} {vu}"
        if Pt is not None:
            line += f"; true RSS {_fmt(_rss(Pt, slice(0, 3)))} km, {_fmt(_rss(Pt, slice(3, 6)) * vf)} {vu}"
        con.print(escape(line))


def _print_warnings(p: _Printout) -> None:
    """Measurements skipped or unusable, covariances not positive semi-definite, events
    whose covariance failed, and the run's status."""
    from rich.markup import escape

    r, con, events, hist, status = p.r, p.con, p.events, p.hist, p.status
    at, times = r["attrs"], r["times_s"]
    K = len(times)
    m = r["measurements"]
    used = np.asarray(m["used"], dtype=bool)
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


def print_team(
    r: dict,
    console: Any = None,
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

    if verbosity not in VERBOSITY:
        raise ValueError(f"verbosity must be one of {', '.join(VERBOSITY)}, not {verbosity!r}")
    vf = _vfactor(velocity_unit)
    vu = velocity_unit
    con = console or Console(width=width or (None if sys.stdout.isatty() else 160))
    if verbosity == "quiet":
        con.print(quiet_line(r, vu), markup=False, highlight=False, soft_wrap=True)
        return
    p = _printout(r, con, vu, vf)
    _print_study(p)
    _print_event_log(p, verbosity, max_log_rows)
    _print_noise(p)
    if verbosity == "verbose":
        _print_eigen_tables(p)
    else:
        _print_final_knowledge(p)
    _print_predictions(p)
    print_guidance(r, con, verbosity=verbosity, velocity_unit=vu)
    print_budget(r, con, verbosity=verbosity, velocity_unit=vu)
    _print_warnings(p)
    con.print(f"{file_label}: {r['path']}", markup=False, highlight=False, overflow="ignore")
