"""The trajectory deck: a TOML file describing one propagation (FRACAS TOM ``$DATA``, sec. 3.1).

Validated into frozen pydantic models in the units a user writes (days, degrees, kW,
Isp in s); :mod:`fracas.build` is the one place these convert to the core's km, s, kg,
rad.  No JAX here.  Layout (every section but ``[epoch]``, ``[initial_state]``,
``[spacecraft]`` and ``[stop]`` is optional)::

    title = "LEO with J2"                      # free text
    [epoch]           iso = "2030-01-01T00:00:00"   (TDB)   | julian_date = 2462502.5 (TDB)
    [initial_state]   centre = "earth", frame = "EME2000" | "ECLIPJ2000" | "BODY_EQUATOR"
                      and exactly one of the tables
      [initial_state.cartesian]  r_km = [x, y, z], v_km_s = [vx, vy, vz]
      [initial_state.elements]   a_km, e, i_deg, raan_deg, argp_deg,
                                 mean_anomaly_deg | true_anomaly_deg
      [initial_state.spherical]  r_km, lat_deg, lon_deg, v_km_s, gamma_deg, sigma_deg
      [initial_state.oem]        path = "x.oem", at = "start" | "end" | ISO TDB epoch
                                 (a CCSDS OEM record; [epoch] and centre may then be left
                                 out: docs/exchange.md)
    [spacecraft]      mass_kg, area_m2 = 0, cr = 1
    [propulsion]      power_source = "solar" | "nuclear", power_kw, decay_days (nuclear),
                      efficiency, exhaust_velocity_km_s | isp_s, thrust_scale = 1
    [[thrust_arc]]    start_days, stop_days, frame = "velocity" | "inertial" | "velocity_yaw_switch",
                      alpha_deg = 0, beta_deg = 0, throttle = 1
    [[impulse]]       time_days, dv_km_s = [3], frame = "velocity" | "inertial", isp_s = 300
    [forces]          third_bodies = [], j2 = false, srp = false, change_primary_at_soi = false
      [forces.overrides.BODY]     mu_km3_s2, j2, radius_km   (each optional)
      [forces.conic_bodies.BODY]  a_km, e, i_deg, raan_deg, argp_deg, mean_anomaly_deg,
                                  epoch = ISO string | Julian date (TDB),
                                  frame = "EME2000" | "ECLIPJ2000" (of the angles)
    [integrator]      method = "auto" | "dprkn12" | "dprkn8" | "dop853" | "rkn4",
                      formulation = "auto" | "cowell" | "encke", step_control = "auto" |
                      "tolerance" | "c_nom", tolerance = 1e-12, c_nom = 0.3, dt_max_s,
                      rect_ratio = 0.01, eps_t_s = 1e-6, max_steps = 200000
    [stop]            duration_days | final_epoch (ISO string or Julian date, TDB),
                      condition = "time" | "soi_entry" | "closest_approach" | "radius",
                      body, radius_km
    [output]          times_days = [], step_days, include_final = true
                      (t = 0 is always the first output), sensitivities = ["mu[earth]", ...], stm = false

Backward propagation: ``duration_days < 0`` or a ``final_epoch`` before ``[epoch]``.  Every
time (thrust arcs, impulses, output times) is then in ``[duration, 0]`` days, still measured
from the epoch; lists stay in increasing time order (an arc is on for start <= t < stop);
``step_days`` is a magnitude applied in the direction of propagation (a sign, if written,
must agree with it) and outputs run from t = 0 backward.  Stop conditions "time" and
"radius" work in both directions; "soi_entry", "closest_approach", primary changes and an
impulse at t = 0 are refused on a backward deck.

The primary body of the propagation (centre of the Encke conic) is the initial-state
centre.  :func:`load_deck` turns every problem into :class:`fracas.errors.DeckError` with
one line ``path: field.path = value: what was expected``.

Modules: :mod:`~fracas.config.trajectory.problems` (field problems),
:mod:`~fracas.config.trajectory.values` (value types and the section base),
:mod:`~fracas.config.trajectory.state` (``[epoch]``, ``[initial_state]``),
:mod:`~fracas.config.trajectory.sections` (the other tables),
:mod:`~fracas.config.trajectory.deck` (the whole deck),
:mod:`~fracas.config.trajectory.checks` (its cross checks),
:mod:`~fracas.config.trajectory.messages` (one line per problem) and
:mod:`~fracas.config.trajectory.reading` (files, TOML, validation, the deck's hash).
"""

from __future__ import annotations

from fracas.config.trajectory.checks import deck_bodies, needs_ephemeris
from fracas.config.trajectory.deck import BACKWARD_TEAM_PROBLEM, SourcedDeck, TrajectoryDeck
from fracas.config.trajectory.messages import (
    ECHO_CHARS,
    cut,
    deck_error,
    first_and_count,
    format_validation_error,
    validation_problems,
)
from fracas.config.trajectory.messages import _strip as _strip
from fracas.config.trajectory.problems import FieldProblem, FieldProblems, raise_problems
from fracas.config.trajectory.reading import (
    MAX_DECK_BYTES,
    MAX_NESTING,
    load_deck,
    load_toml,
    parse_deck,
    parse_sourced,
    read_deck_text,
    trajectory_hash,
    validate_sourced,
)
from fracas.config.trajectory.reading import _strip_bom as _strip_bom
from fracas.config.trajectory.sections import (
    BodyOverride,
    ConicBody,
    Forces,
    Impulse,
    Integrator,
    Output,
    Propulsion,
    Spacecraft,
    Stop,
    ThrustArc,
    output_count,
)
from fracas.config.trajectory.state import (
    Cartesian,
    Elements,
    Epoch,
    InitialState,
    OemState,
    Spherical,
    initial_radius_km,
)
from fracas.config.trajectory.values import (
    BODY_NAMES,
    BodyName,
    EpochValue,
    IsoEpoch,
    ParamLabel,
    PositiveFloat,
    Vector3,
    canonical_name,
)
from fracas.config.trajectory.values import _Section as _Section

__all__ = [
    "TrajectoryDeck",
    "load_deck",
    "parse_deck",
    "FieldProblem",
    "FieldProblems",
    "load_toml",
    "validation_problems",
    "MAX_NESTING",
    "BACKWARD_TEAM_PROBLEM",
    "MAX_DECK_BYTES",
    "deck_bodies",
    "needs_ephemeris",
    "initial_radius_km",
    # also used by the other decks and modules
    "BODY_NAMES",
    "ECHO_CHARS",
    "BodyName",
    "EpochValue",
    "IsoEpoch",
    "ParamLabel",
    "PositiveFloat",
    "Vector3",
    "canonical_name",
    "raise_problems",
    "SourcedDeck",
    "parse_sourced",
    "validate_sourced",
    "read_deck_text",
    "trajectory_hash",
    "cut",
    "deck_error",
    "first_and_count",
    "format_validation_error",
    "output_count",
    # the tables
    "Epoch",
    "Cartesian",
    "Elements",
    "Spherical",
    "OemState",
    "InitialState",
    "Spacecraft",
    "Propulsion",
    "ThrustArc",
    "Impulse",
    "BodyOverride",
    "ConicBody",
    "Forces",
    "Integrator",
    "Stop",
    "Output",
]
