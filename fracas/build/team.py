"""From a validated TEAM deck to a :class:`~fracas.team.study.Study` in canonical units (FRACAS DATA, sec. 5.3.2).

The application layer of TEAM (the core in :mod:`fracas.team` never sees the deck): reads
the trajectory deck named by [ertraj], sorts the study's parameters into the augmented-state
roles (solve-for s, dynamic consider u, measurement consider v, ignore w), builds the
a-priori covariances (assumed and, for generalized covariance, true), the Gauss-Markov
thrust noise levels, the stations, the observations of every [[tracking]] entry and the
event schedule, converting days, hours, degrees and deck sigmas on the way.  Every problem
is a one-line :class:`~fracas.errors.DeckError` naming the deck, the field and what was expected.
The numbers the deck alone fixes (a-priori covariances, noise levels, sigmas) are
:mod:`fracas.build.team_numbers`; :func:`build_case` is a sequence of named steps.
"""

from __future__ import annotations

import dataclasses
import importlib
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from fracas.build.guidance import control_a_priori, guidance_specs, guidance_times
from fracas.build.onboard import count_start_times
from fracas.build.team_numbers import (
    _err,
    _gencov,
    _shape,
    _state_sigmas,
    start_state,
    study_numbers,
    trajectory_problem,
)
from fracas.build.trajectory import Problem
from fracas.config.team import TeamDeck
from fracas.config.trajectory import TrajectoryDeck, trajectory_hash
from fracas.constants import DAY_S
from fracas.dynamics.model import ForceModel
from fracas.errors import ConfigError
from fracas.filters.covariance import Layout
from fracas.integrate.variational import THRUST_NOISE_LABELS
from fracas.measurements import trakm
from fracas.measurements.stations import DSN_STATIONS, Station
from fracas.params import param_unit, parse_label
from fracas.team.schedule import Schedule, build_schedule, merge_times, range_times
from fracas.team.study import Study, TrackingSpec

__all__ = [
    "TeamCase",
    "build_study",
    "build_case",
    "trajectory_problem",
    "stm_file_times",
    "stm_file_labels",
    "thrust_switch_times",
]


@dataclass(frozen=True)
class TeamCase:
    """A TEAM deck with what was built from it: the application layer's handle on a study.

    ``study`` is what the core receives; ``deck`` and ``traj_deck`` stay here, for the
    file names, the print options and the provenance the edges need.
    """

    deck: TeamDeck
    traj_deck: TrajectoryDeck
    study: Study

    @property
    def source(self) -> str:
        return self.study.source


def thrust_switch_times(tdeck: TrajectoryDeck) -> tuple[float, ...]:
    """The thrust on/off times of a trajectory deck (s from its epoch, sorted, unique)."""
    return tuple(
        sorted({a.start_days * DAY_S for a in tdeck.thrust_arc} | {a.stop_days * DAY_S for a in tdeck.thrust_arc})
    )


def _classify(label: str, model, station_names, src: str, field: str) -> bool:
    """True if the dynamics depend on ``label``, False for a measurement label; DeckError otherwise."""
    try:
        parse_label(label, model)
        return True
    except KeyError as exc:
        dyn_msg = str(exc).strip("'\"")
    if trakm.is_measurement_label(label):
        try:
            trakm.check_measurement_label(label, station_names)
        except KeyError as exc:
            raise _err(src, field, label, str(exc).strip("'\"")) from None
        return False
    lead = "" if dyn_msg.startswith("unknown parameter") else "unknown parameter: "
    raise _err(
        src,
        field,
        label,
        f"{lead}{dyn_msg}; measurement parameters are e.g. "
        "station_lon_rad[goldstone], range_bias_km[madrid], qvlbi_timing_km",
    )


def _unit(label: str, dynamic: bool, model) -> str:
    return param_unit(label, model) if dynamic else trakm.measurement_label_unit(label)


def load_user_gain(spec: str, src: str) -> Callable:
    """Import ``module:function`` (FRACAS USRGAN); it must be written with jax.numpy."""
    mod, _, fn = spec.partition(":")
    try:
        obj = getattr(importlib.import_module(mod), fn)
    except (ImportError, AttributeError) as exc:
        raise _err(src, "filter.user_gain", spec, f"cannot import it ({exc})") from None
    if not callable(obj):
        raise _err(src, "filter.user_gain", spec, "is not callable")
    return obj


def build_study(deck: TeamDeck, punched: dict | None = None) -> Study:
    """DATA: validate the deck against the trajectory and the catalogues; build the core's study."""
    return build_case(deck, punched).study


@dataclass(frozen=True)
class _Parameters:
    """The study's parameters in layout order [s, u, v, w] with their roles and units."""

    labels: list[str]
    dynamic: np.ndarray
    roles: list[str]
    units: list[str]
    layout: Layout


def _stations(deck: TeamDeck) -> dict[str, Station]:
    """The DSN stations with the deck's [[station]] entries added or overriding them."""
    stations = dict(DSN_STATIONS)
    for s in deck.station:
        stations[s.name] = Station(s.name, s.radius_km, math.radians(s.latitude_deg), math.radians(s.longitude_deg))
    return stations


def _parameters(deck: TeamDeck, model: ForceModel, names: tuple[str, ...], src: str, nx: int) -> _Parameters:
    """Sort the deck's parameters into the augmented-state roles: solve-for s, dynamic consider
    u, measurement consider v, ignore w (the gencov ignore parameters last)."""
    groups: dict[str, list[tuple[str, float, bool]]] = {"s": [], "u": [], "v": [], "w": []}
    for k, p in enumerate(deck.parameter):
        dyn = _classify(p.label, model, names, src, f"parameter[{k}].label")
        role = {"solve_for": "s", "ignore": "w"}.get(p.role, "u" if dyn else "v")
        groups[role].append((p.label, p.sigma, dyn))
    gen = _gencov(deck)
    if gen is not None:
        for k, g in enumerate(gen.parameter):
            if g.role == "ignore":
                dyn = _classify(g.label, model, names, src, f"gencov.parameter[{k}].label")
                groups["w"].append((g.label, g.sigma, dyn))
    ordered = groups["s"] + groups["u"] + groups["v"] + groups["w"]
    roles = (
        ["solve_for"] * len(groups["s"])
        + ["dynamic_consider"] * len(groups["u"])
        + ["measurement_consider"] * len(groups["v"])
        + ["ignore"] * len(groups["w"])
    )
    return _Parameters(
        labels=[lab for lab, _, _ in ordered],
        dynamic=np.array([d for _, _, d in ordered], dtype=bool),
        roles=roles,
        units=[_unit(lab, d, model) for lab, _, d in ordered],
        layout=Layout(nx, len(groups["s"]), len(groups["u"]), len(groups["v"]), len(groups["w"])),
    )


def _shaped_state(deck: TeamDeck, src: str, problem: Problem) -> tuple | None:
    """The :func:`start_state` when any a-priori is shaped ([a_priori], [gencov], [control]), else None."""
    gen = _gencov(deck)
    shaped = any(
        a is not None and a.shaped is not None
        for a in (deck.a_priori, gen.a_priori if gen is not None else None, deck.control)
    )
    return start_state(deck, src, problem) if shaped else None


def _punched_a_priori(
    deck: TeamDeck, src: str, tdeck: TrajectoryDeck, punched: dict, labels: list[str], n: int
) -> tuple[np.ndarray, np.ndarray]:
    """(assumed, true) a-priori covariances from a punch file, checked against this study."""
    if punched.get("trajectory_hash") and punched["trajectory_hash"] != trajectory_hash(tdeck):
        raise _err(
            src,
            "a_priori.from_punch",
            deck.a_priori.from_punch,
            f"was punched on another trajectory (hash {str(punched['trajectory_hash'])[:12]}), this study's "
            f"trajectory deck {tdeck.source_path} has {trajectory_hash(tdeck)[:12]}",
        )
    P0a = np.array(punched["assumed"], dtype=np.float64)
    P0t = np.array(punched.get("true", punched["assumed"]), dtype=np.float64)
    if list(punched["labels"]) != labels or P0a.shape != (n, n):
        raise _err(
            src,
            "a_priori.from_punch",
            deck.a_priori.from_punch,
            f"the punched covariance has parameters {list(punched['labels'])}, this study {labels}",
        )
    return P0a, P0t


def _tracking(deck: TeamDeck) -> tuple[list[np.ndarray], list[TrackingSpec]]:
    """(observation times (s) of each [[tracking]] entry, the entries as the core's specs)."""
    track_times, specs = [], []
    for t in deck.tracking:
        star = None
        if t.type == "star_planet_angle":
            ra, de = math.radians(t.star_ra_deg), math.radians(t.star_dec_deg)
            star = np.array([math.cos(de) * math.cos(ra), math.cos(de) * math.sin(ra), math.sin(de)])
        specs.append(TrackingSpec(t.type, tuple(t.stations), t.body, star))
        track_times.append(range_times(t.start_days * DAY_S, t.stop_days * DAY_S, t.interval_hours * 3600.0))
    return track_times, specs


def _study_span(deck: TeamDeck, tdeck: TrajectoryDeck, src: str, punched: dict | None) -> tuple[float, float, float]:
    """(trajectory end, study start, study stop), s from the epoch (a punch file sets the start)."""
    dur = tdeck.duration_days * DAY_S
    start = deck.filter.start_days * DAY_S
    stop = min(deck.filter.stop_days * DAY_S, dur) if deck.filter.stop_days is not None else dur
    if punched is not None:
        start = float(punched["time_s"])
    if start >= stop:
        raise _err(src, "filter.start_days", start / DAY_S, f"must be before the end of the study ({stop / DAY_S:g} d)")
    return dur, start, stop


def _events(
    deck: TeamDeck, src: str, dur: float, start: float, stop: float
) -> tuple[list[tuple], list[tuple[float, tuple[float, ...]]]]:
    """The [[event]] entries as (type, times s, predict-to s) and the reset events inside the study."""
    events, resets = [], []
    for k, e in enumerate(deck.event):
        ts = np.array(e.times(), dtype=np.float64) * DAY_S
        if np.any(ts > dur):
            raise _err(src, f"event[{k}]", None, f"times must be within the trajectory (<= {dur / DAY_S:g} d)")
        if e.predict_to_days is not None:
            if e.predict_to_days * DAY_S > dur:
                raise _err(
                    src,
                    f"event[{k}].predict_to_days",
                    e.predict_to_days,
                    f"must be within the trajectory (<= {dur / DAY_S:g} d, its ephemeris and thrust plan)",
                )
            if np.any(ts >= e.predict_to_days * DAY_S):
                raise _err(
                    src,
                    f"event[{k}].predict_to_days",
                    e.predict_to_days,
                    "must be after every time of the prediction event",
                )
        events.append((e.type, ts, None if e.predict_to_days is None else e.predict_to_days * DAY_S))
        if e.type == "reset":
            sig = tuple(float(x) for x in (*e.position_sigma_km, *e.velocity_sigma_km_s))
            resets += [(float(t), sig) for t in ts if start - 1e-9 <= t <= stop + 1e-9]
    return events, resets


def _schedule(
    deck: TeamDeck,
    tdeck: TrajectoryDeck,
    src: str,
    span: tuple[float, float],
    track_times: list[np.ndarray],
    events: list[tuple],
    guid: tuple,
    punched: dict | None,
) -> Schedule:
    """The study's schedule: tracking, events, guidance, thrust switches and punch times."""
    start, stop = span
    if guid:
        events.append(("guidance", guidance_times(guid)[0], None))
    switches = []
    for arc in tdeck.thrust_arc:
        switches += [(arc.start_days * DAY_S, "thrust_on"), (arc.stop_days * DAY_S, "thrust_off")]
    if deck.errcon.propagation == "pdot" and (deck.filter.type == "wls" or deck.filter.square_root):
        raise ConfigError(
            f'{src}: errcon.propagation = "pdot" supports the Kalman-Schmidt and user '
            'filters in covariance form (use propagation = "phi" for WLS or the square-root mode)'
        )
    punch = np.array(deck.punch.times_days) * DAY_S if deck.punch is not None else np.zeros(0)
    sched = build_schedule(start, stop, track_times, events, switches, punch, count_start_times(deck, track_times))
    if punched is not None:  # the punched covariance already includes the events at its time
        sched.events[0] = ["initial"]
        sched.tracking[0] = []
        sched.predict_to_s.pop(0, None)
    return sched


def _punched_noise_states(deck: TeamDeck, punched: dict | None) -> tuple | None:
    """(assumed, true, control) covariances with the noise states from a punch file, or None."""
    if punched is None or "assumed_with_noise_states" not in punched:
        return None
    return (
        np.array(punched["assumed_with_noise_states"], dtype=np.float64),
        np.array(punched.get("true_with_noise_states", punched["assumed_with_noise_states"]), np.float64),
        None
        if "control_with_noise_states" not in punched or deck.control is not None
        else np.array(punched["control_with_noise_states"], np.float64),
    )


def _control(deck: TeamDeck, src: str, nx: int, P0t: np.ndarray, state: tuple | None, punched: dict | None) -> Any:
    """The initial control covariance: punched, from [control] (shaped), or None (the true a-priori)."""
    if punched is not None and punched.get("control") is not None and deck.control is None:
        return np.array(punched["control"], dtype=np.float64)
    return _shape(control_a_priori(deck.control, src, nx, P0t, _state_sigmas), deck.control, state)


#: the Study fields that :func:`study_numbers` computes, copied as they are
_NUMBER_FIELDS = (
    "noise_sigma_assumed",
    "noise_tau_assumed",
    "noise_sigma_true",
    "noise_tau_true",
    "observations",
    "true_sigma",
    "noise_step_s",
    "white_q_assumed",
    "white_q_true",
    "white_direction_assumed",
    "white_direction_true",
    "white_step_s",
)


def _deck_options(deck: TeamDeck) -> dict[str, Any]:
    """The Study fields that are the deck's options, converted (hours -> s, days -> s)."""
    return {
        "filter_kind": deck.filter.type,
        "square_root": deck.filter.square_root,
        "min_elevation_deg": deck.filter.min_elevation_deg,
        "propagation": deck.errcon.propagation,
        "pdot_step_s": deck.ertraj.pdot_step_hours * 3600.0,
        "noise_model": deck.errcon.process_noise,
        "user_gain_spec": deck.filter.user_gain or "",
        "guidance_model": deck.errcon.guidance_model,
        "guidance_reset": deck.errcon.guidance_reset,
        "guidance_estimates": deck.errcon.guidance_estimates,
        "budget": bool(deck.budget.enabled and deck.errcon.propagation == "phi"),
        "budget_at_s": tuple(t * DAY_S for t in deck.budget.at_days),
    }


def build_case(deck: TeamDeck, punched: dict | None = None) -> TeamCase:
    """DATA: validate the deck against the trajectory and the catalogues; the study with its decks.

    The steps: the trajectory, the stations, the parameters and their roles, the a-priori
    covariances and noise levels (:func:`study_numbers`, or a punch file), the tracking
    entries, the study's span, the events, the schedule, then the core's :class:`Study`."""
    src = deck.source_path or "<deck>"
    tdeck, problem = trajectory_problem(deck, src)
    model = problem.model
    nx = 7 if model.thrust else 6
    stations = _stations(deck)
    par = _parameters(deck, model, tuple(stations), src, nx)
    state = _shaped_state(deck, src, problem)
    num = study_numbers(deck, src, nx, par.labels, par.layout.nw, bool(model.thrust), state)
    if punched is not None:
        P0a, P0t = _punched_a_priori(deck, src, tdeck, punched, par.labels, par.layout.n)
    else:
        P0a, P0t = num["P0_assumed"], num["P0_true"]
    track_times, specs = _tracking(deck)
    dur, start, stop = _study_span(deck, tdeck, src, punched)
    events, resets = _events(deck, src, dur, start, stop)
    guid = guidance_specs(deck, tdeck, src)
    sched = _schedule(deck, tdeck, src, (start, stop), track_times, events, guid, punched)
    gain = load_user_gain(deck.filter.user_gain, src) if deck.filter.type == "user" else None
    problem = dataclasses.replace(
        problem, param_labels=tuple(lab for lab, d in zip(par.labels, par.dynamic) if d), sensitivities=True
    )
    study = Study(
        source=src,
        title=deck.title,
        problem=problem,
        layout=par.layout,
        labels=par.labels,
        roles=par.roles,
        units=par.units,
        dynamic=par.dynamic,
        P0_assumed=P0a,
        P0_true=P0t,
        stations=stations,
        tracking=specs,
        schedule=sched,
        start_s=start,
        stop_s=stop,
        gencov=_gencov(deck) is not None,
        user_gain=gain,
        thrust_switches_s=thrust_switch_times(tdeck),
        trajectory_end_s=dur,
        P0_noise_states=_punched_noise_states(deck, punched),
        trajectory_hash=trajectory_hash(tdeck),
        trajectory_source=tdeck.source_path or "",
        punched=punched,
        guidance=guid,
        resets=tuple(resets),
        P0_control=_control(deck, src, nx, P0t, state, punched),
        **{k: num[k] for k in _NUMBER_FIELDS},
        **_deck_options(deck),
    )
    return TeamCase(deck, tdeck, study)


def stm_file_times(case: TeamCase) -> np.ndarray:
    """STMGEN: the time points an STM file built from this deck holds (s from the epoch).

    The study's schedule, the thrust switches, the epoch and the optional uniform grid
    ([stm] grid_hours) over the whole trajectory, so other studies can use other times.
    """
    study = case.study
    dur = case.traj_deck.duration_days * DAY_S
    grid = np.zeros(0)
    if case.deck.stm.grid_hours:
        grid = range_times(0.0, dur, case.deck.stm.grid_hours * 3600.0)
    extra = guidance_times(study.guidance)[1] if study.guidance else []
    t = merge_times([0.0], study.schedule.times_s, grid, list(study.thrust_switches_s), [dur], extra)
    return t[(t >= 0) & (t <= dur + 1e-6)]


def stm_file_labels(case: TeamCase) -> list[str]:
    """The parameter columns of an STM file built from this deck: the study's dynamic
    parameters, the thrust noise components, and [stm] parameters."""
    study = case.study
    out = list(study.dynamic_labels)
    extra = list(case.deck.stm.parameters)
    if study.problem.model.thrust:
        extra += list(THRUST_NOISE_LABELS)
    for lab in extra:
        if lab not in out:
            try:
                parse_label(lab, study.problem.model)
            except KeyError as exc:
                raise _err(study.source, "stm.parameters", lab, str(exc).strip("'\"")) from None
            out.append(lab)
    return out
