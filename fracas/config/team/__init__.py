"""The TEAM deck: one linear covariance study (FRACAS $ERRCON, $ERTRAJ, $ERANAL, $GENCOV, sec. 3.2).

Validated into frozen pydantic models in the units an analyst writes (days, hours, m,
mm/s, deg, µrad); :mod:`fracas.team.setup` converts to km, s, rad.  No JAX here.
Layout (only ``[ertraj]`` is required)::

    title = "Mercury approach"
    [errcon]       build_stm = false | true | "if_missing", analysis = true,  ($ERRCON)
                   propagation = "phi" | "pdot",  stm_file = "stm_files/x.h5"
                   process_noise = "grid" | "interval",  noise_step_hours = 1.0,
                   guidance_model = "report" | "orthogonal" | "tsim"  (the estimated-deviation
                   covariance that sizes corrections: P_c, P_c − P_k, P_c + P_k),
                   guidance_reset = "state" | "all"  (blocks of GUIDM's reset),
                   guidance_estimates = "state" | "state_and_solve_for"
                   (PHI mode's thrust-noise model: DYNO on fixed cells, default, or
                   FRACAS's DYNO per schedule interval; fracas.team.transitions)
    [ertraj]       deck = "trajectory.toml"   (relative to this file)      ($ERTRAJ)
                   pdot_step_hours = 2.4      (PDOT integration step)
    [stm]          parameters = [...]  (extra labels the STM file should carry for later
                   studies), grid_hours (extra uniform grid of file times)
    [filter]       type = "kalman_schmidt" | "wls" | "user", user_gain = "module:function",
                   square_root = false, min_elevation_deg = 0, start_days = 0, stop_days
    [a_priori]     position_sigma_km = [3] | position_rss_km, velocity_sigma_km_s = [3] |
                   velocity_rss_km_s, mass_sigma_kg = 0, from_punch = "file.h5"
    [[parameter]]  label, sigma (in the label's unit), role = "solve_for" | "consider" | "ignore"
    [thrust_noise] proportionality = {sigma, tau_days}, in_plane_deg = {sigma, tau_days},
                   out_of_plane_deg = {sigma, tau_days}     (Gauss-Markov, App. 9.3)
    [process_noise] white_acceleration_km2_s3 = 0, direction = "full" | "crosstrack" |
                   "radial" | "along", quadrature_step_hours   (white, UNF s_q)
    [a_priori.shaped] sigma_r_km, sigma_v_km_s, sigma_energy_km2_s2, sigma_h_km2_s,
                   lv_crosstrack_sigma_r_km, lv_crosstrack_sigma_v_km_s  (UNF pseudo-measurements)
    [[station]]    name, radius_km, latitude_deg, longitude_deg  (override/add; <= 9 in all)
    [[tracking]]   type, stations = [..], start_days, stop_days, interval_hours, sigma
                   (range types: m; Doppler types: mm/s; azimuth/elevation: deg;
                    star_planet_angle, planet_diameter: µrad), body, star_ra_deg, star_dec_deg,
                   visibility = {min_elevation_deg, max_range_km} (station kinds); onboard
                   kinds (docs/onboard_measurements.md): doppler_count_1way (m) count_interval_s;
                   sensor_beta/theta (mrad) sensor_frame, sensor_axes, target, target_point_km,
                   target_station; horizon_angle (mrad) horizon_azimuth_deg,
                   boresight_depression_deg, horizon_altitude_km, horizon_sigma_m; horizon_angle
                   and altitude (m) equatorial_radius_km, polar_radius_km; altitude
                   altitude_model, reference_radius_km
    [[event]]      type = "eigenvector" | "propagation" | "prediction" | "reset",
                   times_days = [..] | start_days + stop_days + interval_days,
                   predict_to_days (prediction); position_sigma_km, velocity_sigma_km_s
                   (reset: the ASSUMED covariance's state block restarts from these sigmas
                   with its correlations zeroed, the UNF/Apollo W reinitialization; the true
                   covariance continues; needs [gencov]; PHI propagation, Kalman-Schmidt)
    [print]        every = 1 (print every n-th measurement event), correlations = true,
                   process_noise = true
    [punch]        times_days = [..], file = "out/knowledge.h5"
    [gencov]       enabled = true, a_priori = {...}, [[gencov.parameter]] (true sigma of a study
                   parameter, or a new role = "ignore" one), thrust_noise = {...}, process_noise = {...},
                   measurement_sigma = {type = sigma}                         ($GENCOV)
    [control]      the initial control covariance (actual − reference: injection dispersions),
                   as [a_priori]; default the true a-priori
    [[guidance]]   name, type = "impulsive" | "primary" | "vernier" | "none", time_days,
                   targets = ["b_dot_t", ...], target_time_days, target_body, arc,
                   controls = ["proportionality", "alpha", "beta", "t_on", "t_off"],
                   weights, tolerances, execution = {proportionality, pointing_mrad,
                   resolution_m_s}                              (GUIDM, XGUID; §3.2)
    [budget]       enabled = true, at_days = [..]   (error budget by source)
    [output]       results = "out/x_team.h5", plot = "out/x_team.png"
    [limits]       max_measurements, max_events, ... (fracas.config.limits.Limits)

Station names and parameter labels are case-insensitive and stored as the catalogues spell
them (lower case).  Sigmas are bounded where a physical range exists: a [[tracking]] or
gencov sigma by its kind's ``max_sigma`` (fracas.measurements.kinds), a parameter sigma by
its catalogue entry's (fracas.params, fracas.measurements.kinds), thrust-noise
proportionality at most 1 (100 %) and pointing at most 180 deg, a-priori velocity below
the speed of light.  The implied sizes (observations per [[tracking]] entry and in all,
event times) are checked against ``[limits]`` here; those that need the trajectory's
duration by :func:`fracas.config.limits.check_team_sizes`.

Consider parameters are split by the catalogue: labels the dynamics depend on are dynamic
consider (u), measurement labels (station locations, biases) are measurement consider (v).

Modules: :mod:`~fracas.config.team.bounds` (sigma bounds from the catalogues),
:mod:`~fracas.config.team.sections` (the tables), :mod:`~fracas.config.team.tracking`
(``[[tracking]]``, ``[[event]]``), :mod:`~fracas.config.team.guidance` (``[[guidance]]``) and
:mod:`~fracas.config.team.deck` (the whole deck, its cross checks, parsing); the units and
bounds of the fields that recur are :mod:`fracas.config.fields`.
"""

from __future__ import annotations

from fracas.config.fields import LIGHT_KM_S, MAX_POSITION_SIGMA_KM
from fracas.config.team.bounds import MAX_STATIONS, NonNeg, StationName, sigma_bound
from fracas.config.team.deck import TeamDeck, is_team_text, load_team_deck, parse_team_deck
from fracas.config.team.guidance import GUIDANCE_MODELS, GUIDANCE_TYPES, Guidance, GuidanceExecution
from fracas.config.team.sections import (
    APriori,
    BudgetSection,
    ErrCon,
    ErTraj,
    FilterSection,
    GenCov,
    GenCovParameter,
    NoiseComponent,
    OutputSection,
    Parameter,
    PrintSection,
    Punch,
    ShapedAPriori,
    StationDef,
    StmSection,
    ThrustNoise,
    Visibility,
    WhiteNoise,
)
from fracas.config.team.tracking import Event, Tracking

# MEASUREMENT_TYPES, SIGMA_UNITS (unit of ``sigma`` in a [[tracking]] entry, per type, and
# the factor to km, km/s or rad) and N_STATIONS come from fracas.measurements.kinds.
from fracas.measurements.kinds import KINDS as MEASUREMENT_TYPES  # the data types, one catalogue
from fracas.measurements.kinds import N_STATIONS, SIGMA_UNITS

__all__ = [
    "TeamDeck",
    "load_team_deck",
    "parse_team_deck",
    "is_team_text",
    "MEASUREMENT_TYPES",
    "SIGMA_UNITS",
    # also importable from here
    "N_STATIONS",
    "MAX_STATIONS",
    "NonNeg",
    "StationName",
    "LIGHT_KM_S",
    "MAX_POSITION_SIGMA_KM",
    "sigma_bound",
    "GUIDANCE_MODELS",
    "GUIDANCE_TYPES",
    "Guidance",
    "GuidanceExecution",
    "APriori",
    "BudgetSection",
    "ErrCon",
    "ErTraj",
    "FilterSection",
    "GenCov",
    "GenCovParameter",
    "NoiseComponent",
    "OutputSection",
    "Parameter",
    "PrintSection",
    "Punch",
    "ShapedAPriori",
    "StationDef",
    "StmSection",
    "ThrustNoise",
    "Visibility",
    "WhiteNoise",
    "Event",
    "Tracking",
]
