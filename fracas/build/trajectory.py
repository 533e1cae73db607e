"""Deck -> core objects: the one place where units convert.

:func:`build_propagation` turns a validated :class:`~fracas.config.trajectory.TrajectoryDeck`
(days, degrees, Isp in s, frames as written) into a :class:`Problem`: a static
:class:`~fracas.dynamics.model.ForceModel`, a :class:`~fracas.dynamics.model.Params` pytree
and the initial state, all in km, s, kg, kW, rad and ICRF axes, plus the ephemeris table
over the propagation window when any body's position is needed.

Conversions made here (and nowhere else):
  * days -> s (``constants.DAY_S``); degrees -> rad;
  * Isp -> exhaust velocity c = Isp g0 (``constants.G0_KM_S2``);
  * decay_days -> e-folding time tau in s (nuclear power);
  * initial state: elements / spherical -> Cartesian (``fracas.dynamics.elements``), then
    ECLIPJ2000 -> ICRF by R1(-eps), BODY_EQUATOR -> ICRF by A^T with A the planet
    equatorial matrix of the centre's IAU pole;
  * conic-body elements given in ECLIPJ2000 are rotated to ICRF-referenced elements;
  * epochs (ISO TDB or Julian date) -> TDB s past J2000.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from fracas import constants
from fracas.config.trajectory import (
    Impulse,
    Integrator,
    Propulsion,
    ThrustArc,
    TrajectoryDeck,
    deck_bodies,
    needs_ephemeris,
)
from fracas.dynamics.model import (
    FRAME_INERTIAL,
    FRAME_VELOCITY,
    FRAME_VELOCITY_YAW_SWITCH,
    POWER_NUCLEAR,
    POWER_SOLAR,
    ForceModel,
    IntegratorSettings,
    Params,
    StopCondition,
    default_params,
)
from fracas.errors import ConfigError
from fracas.integrate.problem import Problem
from fracas.timescales import epoch_to_et

__all__ = ["Problem", "build_propagation", "output_times_s", "model_bodies"]


_ARC_FRAMES = {"velocity": FRAME_VELOCITY, "inertial": FRAME_INERTIAL, "velocity_yaw_switch": FRAME_VELOCITY_YAW_SWITCH}


def _src(deck: TrajectoryDeck) -> str:
    return deck.source_path or "<deck>"


def model_bodies(deck: TrajectoryDeck) -> tuple[str, ...]:
    """Bodies whose GM/position the propagation needs, in catalogue order
    (:func:`fracas.config.trajectory.deck_bodies`, which validation uses too)."""
    return deck_bodies(deck)


def output_times_s(deck: TrajectoryDeck) -> np.ndarray:
    """De-duplicated output times (s from the epoch) from ``[output]`` in the order the
    propagation meets them: t = 0 first, increasing, or decreasing on a backward deck
    (``step_days`` is a magnitude applied in the direction of propagation)."""
    out = deck.output
    dur = deck.duration_days
    sign = -1.0 if dur < 0.0 else 1.0
    days = [0.0, *out.times_days]  # the propagation starts at the first output time
    if out.include_final:
        days.append(dur)
    if out.step_days is not None:
        step = abs(out.step_days)
        n = int(math.floor(abs(dur) / step * (1.0 + 1e-12)))
        days.extend(sign * k * step for k in range(n + 1))
    # work on |t| (increasing along the propagation), then restore the sign
    t = np.unique(np.clip(sign * np.asarray(days, dtype=np.float64), 0.0, abs(dur)) * constants.DAY_S)
    keep = np.concatenate([[True], np.diff(t) > 1e-6])  # merge times within a microsecond
    return sign * t[keep] + 0.0


def _rotation_to_icrf(frame: str, centre: str) -> np.ndarray:
    from fracas.dynamics import elements as el

    if frame == "EME2000":
        return np.eye(3)
    if frame == "ECLIPJ2000":
        return np.asarray(el.ecliptic_to_equatorial_matrix())
    if frame == "BODY_EQUATOR":
        return np.asarray(el.planet_equatorial_matrix(np.array(constants.pole_unit_vector(centre)))).T
    raise AssertionError(frame)


def _initial_state(deck: TrajectoryDeck, mu_centre: float) -> tuple[np.ndarray, np.ndarray]:
    """Initial r (km), v (km/s) relative to the centre, ICRF axes."""
    from fracas.dynamics import elements as el

    st = deck.initial_state
    rad = math.radians
    if st.cartesian is not None:
        r = np.asarray(st.cartesian.r_km, dtype=np.float64)
        v = np.asarray(st.cartesian.v_km_s, dtype=np.float64)
    elif st.oem is not None:  # read from the OEM at validation (fracas.io.ccsds), ICRF axes
        r = np.asarray(st.oem.r_km, dtype=np.float64)
        v = np.asarray(st.oem.v_km_s, dtype=np.float64)
    elif st.elements is not None:
        e = st.elements
        if e.mean_anomaly_deg is not None:
            m = rad(e.mean_anomaly_deg)
        else:
            m = float(el.true_to_mean_anomaly(rad(e.true_anomaly_deg), e.e))
        vec = np.array([e.a_km, e.e, rad(e.i_deg), rad(e.raan_deg), rad(e.argp_deg), m])
        r, v = (np.asarray(x, dtype=np.float64) for x in el.elements_to_cartesian(vec, mu_centre))
    else:
        s = st.spherical
        r, v = (
            np.asarray(x, dtype=np.float64)
            for x in el.spherical_to_cartesian(
                s.r_km, rad(s.lat_deg), rad(s.lon_deg), s.v_km_s, rad(s.gamma_deg), rad(s.sigma_deg)
            )
        )
    rot = _rotation_to_icrf(st.frame, st.centre)
    return rot @ r, rot @ v


def _conic_elements(deck: TrajectoryDeck, bodies: tuple[str, ...], mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(nb, 6) ICRF-referenced heliocentric elements (rad) and (nb,) their epochs (TDB s)."""
    from fracas.dynamics import elements as el

    nb = len(bodies)
    elems = np.zeros((nb, 6))
    et = np.zeros(nb)
    mu_sun = float(mu[bodies.index("sun")]) if "sun" in bodies else constants.BODIES["sun"].mu_km3_s2
    for name, c in deck.forces.conic_bodies.items():
        k = bodies.index(name)
        rad = math.radians
        vec = np.array([c.a_km, c.e, rad(c.i_deg), rad(c.raan_deg), rad(c.argp_deg), rad(c.mean_anomaly_deg)])
        if c.frame == "ECLIPJ2000":
            rot = np.asarray(el.ecliptic_to_equatorial_matrix())
            r, v = (np.asarray(x) for x in el.elements_to_cartesian(vec, mu_sun))
            vec = np.asarray(el.cartesian_to_elements(rot @ r, rot @ v, mu_sun), dtype=np.float64)
        elems[k] = vec
        et[k] = epoch_to_et(c.epoch)
    return elems, et


def integrator_settings(ig: Integrator, thrust: bool) -> IntegratorSettings:
    """The core's step settings from a deck's ``[integrator]`` (every "auto" resolved).

    dt_max_s unset: 4000 s under FRACAS's c_nom rule (Doc. 4), no limit under tolerance
    control (the error estimate sizes the steps).
    """
    method, formulation, control = ig.resolved(thrust)
    dt_max = ig.dt_max_s
    if dt_max is None:
        dt_max = 4000.0 if control == "c_nom" else math.inf
    return IntegratorSettings(
        c_nom=ig.c_nom,
        dt_max_s=float(dt_max),
        rect_ratio=ig.rect_ratio,
        eps_t_s=ig.eps_t_s,
        max_steps=ig.max_steps,
        tolerance=ig.tolerance,
        method=method,
        formulation=formulation,
        step_control=control,
    )


def _force_model(deck: TrajectoryDeck, bodies: tuple[str, ...]) -> ForceModel:
    """The static force model: bodies, primary, perturbations, thrust layout, steps and stop."""
    f, prop = deck.forces, deck.propulsion
    idx = bodies.index
    centre = deck.initial_state.centre
    ig = deck.integrator
    stop_body = deck.stop.body or centre
    return ForceModel(
        bodies=bodies,
        primary=idx(centre),
        third_bodies=tuple(idx(b) for b in bodies if b in f.third_bodies),
        j2=f.j2,
        srp=f.srp,
        thrust=bool(deck.thrust_arc),
        velocity_dependent=any(a.frame != "inertial" for a in deck.thrust_arc),
        power=(prop.power_source if prop is not None else POWER_SOLAR),
        change_primary_at_soi=f.change_primary_at_soi,
        conic_bodies=tuple(idx(b) for b in bodies if b in f.conic_bodies),
        n_arcs=len(deck.thrust_arc),
        steering=any(a.steered for a in deck.thrust_arc),
        n_impulses=len(deck.impulse),
        yaw_switch=any(a.frame == "velocity_yaw_switch" for a in deck.thrust_arc),
        integrator=integrator_settings(ig, bool(deck.thrust_arc)),
        stop=StopCondition(
            kind=deck.stop.condition,
            body=idx(stop_body),
            radius_km=float(deck.stop.radius_km or 0.0),
        ),
    )


def _body_constants(
    deck: TrajectoryDeck, bodies: tuple[str, ...], model: ForceModel
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mu, j2, radius) of the model's bodies: the catalogue's, with ``[forces.overrides]``."""
    base = default_params(model)
    mu, j2, radius = (np.array(a, dtype=np.float64) for a in (base.mu, base.j2, base.radius))
    for name, ov in deck.forces.overrides.items():
        if name not in bodies:
            raise ConfigError(
                f'{_src(deck)}: forces.overrides.{name}: body "{name}" is not in the force model '
                f"({', '.join(bodies)}); add it to forces.third_bodies or remove the override"
            )
        k = bodies.index(name)
        if ov.mu_km3_s2 is not None:
            mu[k] = ov.mu_km3_s2
        if ov.j2 is not None:
            j2[k] = ov.j2
        if ov.radius_km is not None:
            radius[k] = ov.radius_km
    return mu, j2, radius


def _propulsion_params(prop: Propulsion) -> dict[str, Any]:
    """The engine's parameters: power, its decay (nuclear), efficiency, c = Isp g0, thrust scale."""
    c = prop.exhaust_velocity_km_s if prop.exhaust_velocity_km_s is not None else prop.isp_s * constants.G0_KM_S2
    decay = prop.decay_days * constants.DAY_S if (prop.power_source == POWER_NUCLEAR and prop.decay_days) else math.inf
    return {
        "power_kw": prop.power_kw,
        "power_decay_s": decay,
        "efficiency": prop.efficiency,
        "exhaust_velocity_km_s": c,
        "thrust_scale": prop.thrust_scale,
    }


def _arc_params(arcs: list[ThrustArc]) -> dict[str, Any]:
    """The thrust arcs' switch times (s), angles (rad), throttles, frames and pointing laws."""
    over: dict[str, Any] = {
        "arc_t_on": [a.start_days * constants.DAY_S for a in arcs],
        "arc_t_off": [a.stop_days * constants.DAY_S for a in arcs],
        "arc_alpha": [math.radians(a.alpha_deg) for a in arcs],
        "arc_beta": [math.radians(a.beta_deg) for a in arcs],
        "arc_throttle": [a.throttle for a in arcs],
        "arc_frame": [_ARC_FRAMES[a.frame] for a in arcs],
    }
    for angle in ("alpha", "beta"):
        for k in range(3):
            over[f"arc_{angle}_p{k + 1}"] = [
                math.radians(c[k]) if k < len(c) else 0.0 for c in (getattr(a, f"{angle}_legendre_deg") for a in arcs)
            ]
    return over


def _impulse_params(imps: list[Impulse]) -> dict[str, Any]:
    """The impulses' times (s), ΔV (km/s), frames and the one engine's Isp."""
    return {
        "impulse_t": [i.time_days * constants.DAY_S for i in imps],
        "impulse_dv": np.array([i.dv_km_s for i in imps], dtype=np.float64).reshape(len(imps), 3),
        "impulse_frame": [FRAME_VELOCITY if i.frame == "velocity" else FRAME_INERTIAL for i in imps],
        "impulse_isp_s": imps[0].isp_s,
    }


def _params(deck: TrajectoryDeck, bodies: tuple[str, ...], model: ForceModel) -> tuple[Params, np.ndarray]:
    """The dynamic parameters (canonical units) and the bodies' mu (km^3/s^2)."""
    sc, prop = deck.spacecraft, deck.propulsion
    mu, j2, radius = _body_constants(deck, bodies, model)
    over: dict = {"mu": mu, "j2": j2, "radius": radius, "area_m2": sc.area_m2, "cr": sc.cr}
    if prop is not None:
        over.update(_propulsion_params(prop))
    if deck.thrust_arc:
        over.update(_arc_params(deck.thrust_arc))
    if deck.impulse:
        over.update(_impulse_params(deck.impulse))
    if deck.forces.conic_bodies:
        over["body_elements"], over["body_elements_et"] = _conic_elements(deck, bodies, mu)
    return default_params(model, **over), mu


def _initial_vector(deck: TrajectoryDeck, mu_centre: float) -> np.ndarray:
    """x0 = (r km, v km/s relative to the centre, ICRF; mass kg), checked finite."""
    r0, v0 = _initial_state(deck, mu_centre)
    x0 = np.concatenate([r0, v0, [deck.spacecraft.mass_kg]]).astype(np.float64)
    if not np.all(np.isfinite(x0)):
        raise ConfigError(f"{_src(deck)}: initial_state: the state converts to non-finite numbers {x0.tolist()}")
    return x0


def _ephemeris(deck: TrajectoryDeck, bodies: tuple[str, ...], epoch_et: float, t_final: float) -> Any:
    """The DE421 table over the propagation window, or None when no body other than the Sun
    and the conic bodies needs a position (:func:`fracas.config.trajectory.needs_ephemeris`)."""
    if not needs_ephemeris(deck):
        return None
    from fracas.dynamics.ephemeris import build_ephemeris

    try:
        return build_ephemeris(bodies, epoch_et + min(0.0, t_final), epoch_et + max(0.0, t_final))
    except ConfigError as exc:
        raise ConfigError(f"{_src(deck)}: {exc}") from None


def _sensitivity_labels(deck: TrajectoryDeck, model: ForceModel) -> tuple[str, ...]:
    """``[output] sensitivities``, each checked against the force model."""
    labels = tuple(deck.output.sensitivities)
    if labels:
        from fracas.params import parse_label

        for k, label in enumerate(labels):
            try:
                parse_label(label, model)
            except Exception as exc:  # noqa: BLE001 - any parse failure is a deck problem
                raise ConfigError(f'{_src(deck)}: output.sensitivities[{k}] = "{label}": {exc}') from None
    return labels


def build_propagation(deck: TrajectoryDeck) -> Problem:
    """Validated deck -> :class:`Problem` in canonical units (see the module docstring).

    The steps: the static force model, the dynamic parameters, the initial state, the
    ephemeris table and the sensitivity labels."""
    st = deck.initial_state
    bodies = model_bodies(deck)
    centre = st.centre
    epoch_et = deck.epoch.et
    t_final = deck.duration_days * constants.DAY_S
    model = _force_model(deck, bodies)
    params, mu = _params(deck, bodies, model)
    x0 = _initial_vector(deck, float(mu[bodies.index(centre)]))
    ephem = _ephemeris(deck, bodies, epoch_et, t_final)
    labels = _sensitivity_labels(deck, model)
    return Problem(
        model=model,
        params=params,
        ephem=ephem,
        epoch_et_s=epoch_et,
        x0=x0,
        t_out=output_times_s(deck),
        param_labels=labels,
        sensitivities=bool(labels) or deck.output.stm,
        title=deck.title,
        source_path=deck.source_path,
        source_text=deck.source_text,
        centre=centre,
        final_time_s=t_final,
        info={
            "epoch": deck.epoch.iso if deck.epoch.iso is not None else f"JD {deck.epoch.julian_date} TDB",
            "input_frame": st.frame,
            "input_state": st.kind,
            "ephemeris": "DE421" if ephem is not None else "none",
        },
    )
