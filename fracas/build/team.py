"""From a validated TEAM deck to a :class:`~fracas.team.study.Study` in canonical units (FRACAS DATA, sec. 5.3.2).

The application layer of TEAM (the core in :mod:`fracas.team` never sees the deck): reads
the trajectory deck named by [ertraj], sorts the study's parameters into the augmented-state
roles (solve-for s, dynamic consider u, measurement consider v, ignore w), builds the
a-priori covariances (assumed and, for generalized covariance, true), the Gauss-Markov
thrust noise levels, the stations, the observations of every [[tracking]] entry and the
event schedule, converting days, hours, degrees and deck sigmas on the way.  Every problem
is a one-line :class:`~fracas.errors.DeckError` naming the deck, the field and what was expected.
"""

from __future__ import annotations

import dataclasses
import importlib
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fracas.build.guidance import control_a_priori, guidance_specs, guidance_times
from fracas.build.onboard import count_start_times, onboard_config
from fracas.build.trajectory import Problem, build_propagation
from fracas.config.limits import check_team_sizes
from fracas.config.team import SIGMA_UNITS, APriori, TeamDeck, ThrustNoise, WhiteNoise
from fracas.config.trajectory import BACKWARD_TEAM_PROBLEM, TrajectoryDeck, load_deck, trajectory_hash
from fracas.constants import DAY_S
from fracas.errors import ConfigError, DeckError
from fracas.filters.apriori import shaped_covariance
from fracas.filters.covariance import Layout
from fracas.integrate.propagate import propagate
from fracas.integrate.variational import THRUST_NOISE_LABELS
from fracas.measurements import trakm
from fracas.measurements.stations import DSN_STATIONS, Station
from fracas.params import param_unit, parse_label
from fracas.team.schedule import build_schedule, merge_times, range_times
from fracas.team.study import Study, TrackingSpec
from fracas.team.transitions import noise_cell_step

__all__ = [
    "TeamCase",
    "build_study",
    "build_case",
    "trajectory_problem",
    "stm_file_times",
    "stm_file_labels",
    "thrust_switch_times",
]

_NOISE_FIELDS = ("proportionality", "in_plane_deg", "out_of_plane_deg")
_NOISE_SCALE = (1.0, math.pi / 180.0, math.pi / 180.0)


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


def _err(src: str, field: str, value, expected: str) -> DeckError:
    v = f' = "{value}"' if isinstance(value, str) else (f" = {value}" if value is not None else "")
    return DeckError(f"{src}: {field}{v}: {expected}")


def trajectory_problem(deck: TeamDeck, src: str) -> tuple[TrajectoryDeck, Problem]:
    """Load the [ertraj] trajectory deck and build its propagation problem."""
    path = deck.resolve(deck.ertraj.deck)
    if not path.exists():
        raise _err(src, "ertraj.deck", deck.ertraj.deck, f"no such trajectory deck ({path})")
    tdeck = load_deck(path)
    if tdeck.backward:
        raise _err(src, "ertraj.deck", deck.ertraj.deck, BACKWARD_TEAM_PROBLEM)
    check_team_sizes(deck, tdeck)  # refuse a study too big for its trajectory before building anything
    return tdeck, build_propagation(tdeck)


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


def _state_sigmas(ap: APriori, nx: int) -> np.ndarray:
    pos, vel = ap.sigmas()
    s = list(pos) + list(vel) + ([ap.mass_sigma_kg] if nx == 7 else [])
    return np.asarray(s, dtype=np.float64)


def _noise(tn: ThrustNoise) -> tuple[np.ndarray, np.ndarray]:
    sig, tau = np.zeros(3), np.full(3, DAY_S)
    for i, (f, k) in enumerate(zip(_NOISE_FIELDS, _NOISE_SCALE)):
        c = getattr(tn, f)
        if c is not None:
            sig[i], tau[i] = c.sigma * k, c.tau_days * DAY_S
    return sig, tau


def start_state(deck: TeamDeck, src: str, problem: Problem | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """(r km (3,), v km/s (3,), mu km^3/s^2): the reference state at the filter's start
    (filter.start_days) relative to its primary, and that primary's gravitational parameter
    (the shaped a-priori's pseudo measurements are evaluated there).  Integrates the
    trajectory from its epoch (loading it when ``problem`` is None)."""
    if problem is None:
        _, problem = trajectory_problem(deck, src)
    t0 = deck.filter.start_days * DAY_S
    x, prim = np.asarray(problem.x0, np.float64), int(problem.model.primary)
    if t0 > 0:
        pr = dataclasses.replace(problem, sensitivities=False)
        traj = propagate(pr.model, pr.params, pr.ephem, pr.epoch_et_s, pr.x0, np.array([0.0, t0]))
        x, prim = np.asarray(traj.x, np.float64)[-1], int(np.asarray(traj.primary)[-1])
        if not np.all(np.isfinite(x)):
            raise _err(
                src, "a_priori.shaped", None, f"the trajectory does not reach filter.start_days = {t0 / DAY_S:g}"
            )
    return x[:3], x[3:6], float(np.asarray(problem.params.mu)[prim])


def _shape(P: np.ndarray, ap: APriori | None, state) -> np.ndarray:
    """P with its 6x6 state block replaced by ``ap.shaped``'s correlated a-priori (UNF)."""
    if ap is None or ap.shaped is None or P is None:
        return P
    sh = ap.shaped
    r, v, mu = state
    P = np.array(P, dtype=np.float64)
    P[:6, :6] = np.asarray(
        shaped_covariance(
            r,
            v,
            mu,
            sh.sigma_r_km,
            sh.sigma_v_km_s,
            sh.sigma_energy_km2_s2,
            sh.sigma_h_km2_s,
            sh.lv_crosstrack_sigma_r_km,
            sh.lv_crosstrack_sigma_v_km_s,
        )
    )
    return P


def _white(pn: WhiteNoise, base: tuple[float, str]) -> tuple[float, str]:
    q = base[0] if pn.white_acceleration_km2_s3 is None else float(pn.white_acceleration_km2_s3)
    return q, base[1] if pn.direction is None else pn.direction


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


def study_numbers(deck: TeamDeck, src: str, nx: int, labels: list[str], nw: int, thrust: bool, state=None) -> dict:
    """The numbers of a study that its deck alone fixes (DATA), as build_case computes them:
    the diagonal a-priori covariances (assumed, with the ignore parameters at zero, and
    true; None without [a_priori] sigmas), the Gauss-Markov levels, the observations with
    their assumed sigmas, the true sigmas and the noise cell step.  ``labels``: the study's
    parameters in layout order, the last ``nw`` of them ignore parameters; ``state``: the
    :func:`start_state` for a shaped a-priori (None: computed here when needed).  Shared with
    :func:`fracas.build.vary.derive_study` (a sweep's studies that differ only in numbers)."""
    gen = deck.gencov if (deck.gencov is not None and deck.gencov.enabled) else None
    sigma = {p.label: p.sigma for p in deck.parameter}
    true_sigma: dict[str, float] = {}
    if gen is not None:
        for g in gen.parameter:
            if g.role == "ignore":
                sigma[g.label] = g.sigma
            else:
                true_sigma[g.label] = g.sigma
    p_sig_a = np.array([sigma[lab] for lab in labels], dtype=np.float64)
    p_sig_t = np.array([true_sigma.get(lab, sigma[lab]) for lab in labels], dtype=np.float64)
    if nw:  # the filter does not know its ignore parameters
        p_sig_a[-nw:] = 0.0
    P0a = P0t = None
    if deck.a_priori is not None and not deck.a_priori.from_punch:
        xs_a = _state_sigmas(deck.a_priori, nx)
        xs_t = _state_sigmas(gen.a_priori, nx) if (gen is not None and gen.a_priori is not None) else xs_a
        P0a = np.diag(np.concatenate([xs_a, p_sig_a]) ** 2)
        P0t = np.diag(np.concatenate([xs_t, p_sig_t]) ** 2)
        ap_t = gen.a_priori if (gen is not None and gen.a_priori is not None) else deck.a_priori
        if deck.a_priori.shaped is not None or ap_t.shaped is not None:
            state = start_state(deck, src) if state is None else state
            P0a, P0t = _shape(P0a, deck.a_priori, state), _shape(P0t, ap_t, state)
    sig_a, tau_a = _noise(deck.thrust_noise)
    sig_t, tau_t = _noise(gen.thrust_noise) if (gen is not None and gen.thrust_noise is not None) else (sig_a, tau_a)
    if (np.any(sig_a > 0) or np.any(sig_t > 0)) and not thrust:
        raise _err(src, "thrust_noise", None, "the trajectory deck has no thrust ([propulsion] and [[thrust_arc]])")
    wq_a = _white(deck.process_noise, (0.0, "full"))
    wq_t = _white(gen.process_noise, wq_a) if (gen is not None and gen.process_noise is not None) else wq_a
    if gen is not None and gen.process_noise is not None and gen.process_noise.quadrature_step_hours is not None:
        raise _err(
            src, "gencov.process_noise.quadrature_step_hours", None, "set the quadrature step in [process_noise]"
        )
    obs, tsig = [], []
    for t in deck.tracking:
        _, k = SIGMA_UNITS[t.type]
        obs.append(trakm.Observation(t.type, tuple(t.stations), t.sigma * k, *onboard_config(t)))
        tsig.append((gen.measurement_sigma.get(t.type, t.sigma) if gen is not None else t.sigma) * k)
    return {
        "P0_assumed": P0a,
        "P0_true": P0t,
        "noise_sigma_assumed": sig_a,
        "noise_tau_assumed": tau_a,
        "noise_sigma_true": sig_t,
        "noise_tau_true": tau_t,
        "observations": obs,
        "true_sigma": np.array(tsig, dtype=np.float64),
        "white_q_assumed": wq_a[0],
        "white_q_true": wq_t[0],
        "white_direction_assumed": wq_a[1],
        "white_direction_true": wq_t[1],
        "white_step_s": (deck.process_noise.quadrature_step_hours or deck.errcon.noise_step_hours) * 3600.0,
        "noise_step_s": noise_cell_step(  # on the deck's STM grid: in-line and file runs share the cells
            deck.errcon.noise_step_hours * 3600.0, (deck.stm.grid_hours or 0.0) * 3600.0, np.concatenate([tau_a, tau_t])
        ),
    }


def build_study(deck: TeamDeck, punched: dict | None = None) -> Study:
    """DATA: validate the deck against the trajectory and the catalogues; build the core's study."""
    return build_case(deck, punched).study


def build_case(deck: TeamDeck, punched: dict | None = None) -> TeamCase:
    """DATA: validate the deck against the trajectory and the catalogues; the study with its decks."""
    src = deck.source_path or "<deck>"
    tdeck, problem = trajectory_problem(deck, src)
    model = problem.model
    nx = 7 if model.thrust else 6

    stations = dict(DSN_STATIONS)
    for s in deck.station:
        stations[s.name] = Station(s.name, s.radius_km, math.radians(s.latitude_deg), math.radians(s.longitude_deg))
    names = tuple(stations)

    # ---- parameters and roles
    groups: dict[str, list[tuple[str, float, bool]]] = {"s": [], "u": [], "v": [], "w": []}
    for k, p in enumerate(deck.parameter):
        dyn = _classify(p.label, model, names, src, f"parameter[{k}].label")
        role = {"solve_for": "s", "ignore": "w"}.get(p.role, "u" if dyn else "v")
        groups[role].append((p.label, p.sigma, dyn))
    gen = deck.gencov if (deck.gencov is not None and deck.gencov.enabled) else None
    if gen is not None:
        for k, g in enumerate(gen.parameter):
            if g.role == "ignore":
                dyn = _classify(g.label, model, names, src, f"gencov.parameter[{k}].label")
                groups["w"].append((g.label, g.sigma, dyn))
    ordered = groups["s"] + groups["u"] + groups["v"] + groups["w"]
    labels = [lab for lab, _, _ in ordered]
    dynamic = np.array([d for _, _, d in ordered], dtype=bool)
    roles = (
        ["solve_for"] * len(groups["s"])
        + ["dynamic_consider"] * len(groups["u"])
        + ["measurement_consider"] * len(groups["v"])
        + ["ignore"] * len(groups["w"])
    )
    units = [_unit(lab, d, model) for lab, _, d in ordered]
    layout = Layout(nx, len(groups["s"]), len(groups["u"]), len(groups["v"]), len(groups["w"]))

    # ---- a-priori covariances, noise levels, measurement sigmas
    n = layout.n
    shaped = any(
        a is not None and a.shaped is not None
        for a in (deck.a_priori, gen.a_priori if gen is not None else None, deck.control)
    )
    state = start_state(deck, src, problem) if shaped else None
    num = study_numbers(deck, src, nx, labels, layout.nw, bool(model.thrust), state)
    if punched is not None:
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
    else:
        P0a, P0t = num["P0_assumed"], num["P0_true"]

    # ---- the tracking entries and their schedule
    track_times, specs = [], []
    for t in deck.tracking:
        star = None
        if t.type == "star_planet_angle":
            ra, de = math.radians(t.star_ra_deg), math.radians(t.star_dec_deg)
            star = np.array([math.cos(de) * math.cos(ra), math.cos(de) * math.sin(ra), math.sin(de)])
        specs.append(TrackingSpec(t.type, tuple(t.stations), t.body, star))
        track_times.append(range_times(t.start_days * DAY_S, t.stop_days * DAY_S, t.interval_hours * 3600.0))

    dur = tdeck.duration_days * DAY_S
    start = deck.filter.start_days * DAY_S
    stop = min(deck.filter.stop_days * DAY_S, dur) if deck.filter.stop_days is not None else dur
    if punched is not None:
        start = float(punched["time_s"])
    if start >= stop:
        raise _err(src, "filter.start_days", start / DAY_S, f"must be before the end of the study ({stop / DAY_S:g} d)")
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
    guid = guidance_specs(deck, tdeck, src)
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

    gain = load_user_gain(deck.filter.user_gain, src) if deck.filter.type == "user" else None
    problem = dataclasses.replace(
        problem, param_labels=tuple(lab for lab, d in zip(labels, dynamic) if d), sensitivities=True
    )
    study = Study(
        source=src,
        title=deck.title,
        problem=problem,
        layout=layout,
        labels=labels,
        roles=roles,
        units=units,
        dynamic=dynamic,
        P0_assumed=P0a,
        P0_true=P0t,
        noise_sigma_assumed=num["noise_sigma_assumed"],
        noise_tau_assumed=num["noise_tau_assumed"],
        noise_sigma_true=num["noise_sigma_true"],
        noise_tau_true=num["noise_tau_true"],
        stations=stations,
        tracking=specs,
        observations=num["observations"],
        true_sigma=num["true_sigma"],
        schedule=sched,
        start_s=start,
        stop_s=stop,
        gencov=gen is not None,
        filter_kind=deck.filter.type,
        square_root=deck.filter.square_root,
        user_gain=gain,
        min_elevation_deg=deck.filter.min_elevation_deg,
        propagation=deck.errcon.propagation,
        thrust_switches_s=thrust_switch_times(tdeck),
        trajectory_end_s=dur,
        pdot_step_s=deck.ertraj.pdot_step_hours * 3600.0,
        noise_model=deck.errcon.process_noise,
        P0_noise_states=(
            (
                np.array(punched["assumed_with_noise_states"], dtype=np.float64),
                np.array(punched.get("true_with_noise_states", punched["assumed_with_noise_states"]), np.float64),
                None
                if "control_with_noise_states" not in punched or deck.control is not None
                else np.array(punched["control_with_noise_states"], np.float64),
            )
            if punched is not None and "assumed_with_noise_states" in punched
            else None
        ),
        noise_step_s=num["noise_step_s"],
        white_q_assumed=num["white_q_assumed"],
        white_q_true=num["white_q_true"],
        white_direction_assumed=num["white_direction_assumed"],
        white_direction_true=num["white_direction_true"],
        white_step_s=num["white_step_s"],
        user_gain_spec=deck.filter.user_gain or "",
        trajectory_hash=trajectory_hash(tdeck),
        trajectory_source=tdeck.source_path or "",
        punched=punched,
        guidance=guid,
        resets=tuple(resets),
        guidance_model=deck.errcon.guidance_model,
        guidance_reset=deck.errcon.guidance_reset,
        guidance_estimates=deck.errcon.guidance_estimates,
        P0_control=(
            np.array(punched["control"], dtype=np.float64)
            if punched is not None and punched.get("control") is not None and deck.control is None
            else _shape(control_a_priori(deck.control, src, nx, P0t, _state_sigmas), deck.control, state)
        ),
        budget=bool(deck.budget.enabled and deck.errcon.propagation == "phi"),
        budget_at_s=tuple(t * DAY_S for t in deck.budget.at_days),
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
