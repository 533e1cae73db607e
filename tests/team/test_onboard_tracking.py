"""The Shuttle-UNF onboard kinds in TEAM: [[tracking]] validation (one-line errors naming the
field), TRAKM observation rows against the models, the one-way Doppler count's schedule
(count starts as event-free reference times) and its exact-STM H row against the short-arc
limit, and the horizon example (namelists/near_earth_spiral_horizon_team.toml): it runs,
and its horizon and altimeter data shrink the position knowledge compared with the prior
alone.  The example's numbers are also pinned in a separate *regression* test (this code's
own output, not an independent reference).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import jax
import numpy as np
import pytest

from fracas.build.team import build_study
from fracas.config.team import parse_team_deck
from fracas.errors import DeckError
from fracas.measurements import onboard, trakm
from fracas.measurements.stations import DSN_STATIONS, station_state
from fracas.team.engine import augmented_transitions, process_noise, run_study
from fracas.team.measure import MeasurementSet, assemble_measurements
from fracas.team.reference import integrate_reference
from fracas.team.scan import run_filter

REPO = Path(__file__).resolve().parents[2]
_HORIZON_PARTIALS = jax.jit(onboard.horizon_angle_partials)
EXAMPLE = REPO / "namelists" / "near_earth_spiral_horizon_team.toml"
TRAJ = REPO / "namelists" / "near_earth_spiral_tom_reference.toml"
SRC = str(REPO / "namelists" / "deck_under_test.toml")  # [ertraj] resolves in namelists/

HEAD = f"""
mode = "team"
[ertraj]
deck = "{TRAJ.name}"
[filter]
stop_days = 0.25
[a_priori]
position_sigma_km = [1.0, 1.0, 1.0]
velocity_sigma_km_s = [1e-3, 1e-3, 1e-3]
"""


def _tracking(kind: str, extra: str = "", sigma: float = 1.0, interval_hours: float = 0.25) -> str:
    return (
        f'\n[[tracking]]\ntype = "{kind}"\nstart_days = 0.0\nstop_days = 0.25\n'
        f"interval_hours = {interval_hours}\nsigma = {sigma}\n{extra}\n"
    )


def _refusal(text: str) -> str:
    with pytest.raises(DeckError) as e:
        parse_team_deck(text, SRC)
    msg = str(e.value)
    assert "\n" not in msg, msg
    return msg


# ------------------------------------------------------------------------- deck validation
@pytest.mark.parametrize(
    "kind,extra,expected",
    [
        ("doppler_count_1way", 'stations = ["goldstone"]', "count_interval_s.*required"),
        ("altitude", 'body = "earth"\nhorizon_azimuth_deg = 10.0', "horizon_azimuth_deg.*only for type horizon_angle"),
        ("sensor_beta", 'body = "moon"\nsensor_axes = [[1, 0, 0], [0, 1, 0], [0, 1, 0]]', "sensor_axes.*orthonormal"),
        ("sensor_beta", 'body = "moon"\nsensor_axes = [[1, 0, 0], [0, 1, 0], [0, 0, -1]]', "sensor_axes.*right-handed"),
        ("sensor_theta", 'body = "moon"\ntarget = "point"', "target_point_km.*required"),
        ("sensor_theta", 'body = "moon"\ntarget = "station"\ntarget_station = "goldstone"', 'body.*"earth"'),
        ("sensor_theta", 'body = "earth"\ntarget = "station"\ntarget_station = "nowhere"', "target_station.*unknown"),
        ("horizon_angle", 'body = "earth"\nequatorial_radius_km = 6000\npolar_radius_km = 6100', "polar_radius_km"),
        ("altitude", 'body = "earth"\nvisibility = {min_elevation_deg = 5}', "visibility.*only for station kinds"),
        ("horizon_angle", "", "body.*required"),
    ],
)
def test_onboard_tracking_fields_are_validated(kind, extra, expected):
    msg = _refusal(HEAD + _tracking(kind, extra))
    import re

    assert re.search(expected, msg), msg


# ------------------------------------------------------------------------- a small study
DECK = (
    HEAD
    + """
[[parameter]]
label = "horizon_altitude_bias_km"
sigma = 2.0
role = "solve_for"
[[parameter]]
label = "sensor_misalignment_y_rad"
sigma = 1e-3
role = "consider"
[[parameter]]
label = "doppler_count_bias_km[goldstone]"
sigma = 1e-3
role = "consider"
[[parameter]]
label = "altitude_bias_km"
sigma = 0.01
role = "consider"
"""
    + _tracking(
        "doppler_count_1way",
        'stations = ["goldstone"]\ncount_interval_s = 60.0\nvisibility = {min_elevation_deg = 0.0, max_range_km = 1e5}',
        sigma=0.01,
        interval_hours=0.05,
    )
    + _tracking("horizon_angle", 'body = "earth"\nhorizon_azimuth_deg = 30.0\nhorizon_sigma_m = 300.0', sigma=0.1)
    + _tracking("sensor_theta", 'body = "moon"\nsensor_frame = "lvlh"', sigma=0.5)
    + _tracking("sensor_beta", 'body = "earth"\ntarget = "station"\ntarget_station = "madrid"', sigma=0.5)
    + _tracking("altitude", 'body = "earth"\naltitude_model = "geodetic"', sigma=30.0)
)


@pytest.fixture(scope="module")
def small():
    study = build_study(parse_team_deck(DECK, SRC))
    ref = integrate_reference(study)
    return study, ref, assemble_measurements(study, ref)


@pytest.mark.slow  # its module fixture: ~22 s of a cold make test (issue 22)
def test_count_starts_are_event_free_schedule_times(small):
    study, ref, meas = small
    sched = study.schedule
    j = 0  # the doppler_count_1way entry
    for k in range(sched.n):
        if j in sched.tracking[k] and sched.times_s[k] >= 60.0:
            k0 = sched.index_of(sched.times_s[k] - 60.0)
            assert abs(sched.times_s[k0] - (sched.times_s[k] - 60.0)) < 1e-6
            assert sched.events[k0] == [] or "measurement" in sched.events[k0]
    assert any(ev == [] for ev in sched.events)  # at least one count start is only a grid time
    first = [r for r in meas.records if r.tracking == j and r.k == 0]
    assert first and not first[0].used  # the count at t = 0 started before the study: skipped


@pytest.mark.slow  # its module fixture: ~22 s of a cold make test (issue 22)
def test_doppler_count_row_is_the_exact_stm_form_near_the_short_arc_limit(small):
    """H row of a 60 s count (q = rho(t_M) - rho(t0)) against the exact STM form with Phi(t0, t_M)
    expanded in dt_c: Phi_rr = I + dt^2 G / 2, Phi_rv = -dt I - dt^3 G / 6, G = mu (3 i i^T - I)
    / r^3 taken at t_M - dt/3 for Phi_rr and at the midpoint for Phi_rv (where their dt^3 dG/dt
    terms cancel: the kernels are tau and tau (dt - tau)), so dq/dr = i(t_M)
    - i(t0) Phi_rr and dq/dv = -i(t0) Phi_rv.  Position block: the remainder (G^2 dt^4 ~ 1e-6,
    J2 ~ 1e-3 of the G term, the Moon and the Sun less) is below the tolerance 2e-5 (terms
    ~4e-3).  Velocity block: the reference thrusts along its velocity (13 N on 1000 kg), whose
    velocity gradient A_v ~ (T/m)/|v| ~ 1.5e-6 /s adds A_v dt^2/2 ~ 3e-3 s, not modelled here:
    tolerance 1e-4 dt = 6e-3 s (the dt^3 G/6 term it resolves is 0.08 s)."""
    study, ref, meas = small
    recs = [r for r in meas.records if r.tracking == 0 and r.used]
    assert len(recs) >= 3
    nx, dt, mu = study.nx, 60.0, 398600.436
    for r in recs[:3]:
        k = r.k
        k0 = study.schedule.index_of(ref.times_s[k] - dt)
        et = study.problem.epoch_et_s
        st = DSN_STATIONS["goldstone"]
        s1 = np.asarray(station_state(st.radius_km, st.latitude_rad, st.longitude_rad, et + ref.times_s[k])[0])
        s0 = np.asarray(station_state(st.radius_km, st.latitude_rad, st.longitude_rad, et + ref.times_s[k0])[0])
        u1 = _unit(ref.states[k][:3] - s1)
        u0 = _unit(ref.states[k0][:3] - s0)
        G_rr = _gravity_gradient((2.0 * ref.states[k][:3] + ref.states[k0][:3]) / 3.0, mu)  # at t_M - dt/3
        G_rv = _gravity_gradient((ref.states[k][:3] + ref.states[k0][:3]) / 2.0, mu)  # at the midpoint
        h = meas.H[k, r.row]
        np.testing.assert_allclose(h[:3], u1 - u0 @ (np.eye(3) + 0.5 * dt * dt * G_rr), rtol=0, atol=2e-5)
        np.testing.assert_allclose(h[3:6], u0 @ (dt * np.eye(3) + dt**3 * G_rv / 6.0), rtol=0, atol=1e-4 * dt)
        # the first-order (short-arc) form is off by the gravity-gradient term, ~dt^2 mu/r^3 ~ 4e-3
        assert 1e-3 < np.linalg.norm(h[:3] - (u1 - u0)) < 1e-2
        # the count bias column: unit (range-change units)
        assert h[nx + study.labels.index("doppler_count_bias_km[goldstone]")] == 1.0
        assert r.value == pytest.approx(
            np.linalg.norm(ref.states[k][:3] - s1) - np.linalg.norm(ref.states[k0][:3] - s0), rel=1e-9
        )


def _unit(x):
    return x / np.linalg.norm(x)


def _gravity_gradient(r, mu):
    i_r = _unit(r)
    return mu * (3.0 * np.outer(i_r, i_r) - np.eye(3)) / np.linalg.norm(r) ** 3


@pytest.mark.slow  # its module fixture: ~22 s of a cold make test (issue 22)
def test_onboard_rows_are_the_model_partials(small):
    study, ref, meas = small
    nx = study.nx
    col = {lab: nx + i for i, lab in enumerate(study.labels)}
    for r in meas.records:
        if not r.used:
            continue
        h = meas.H[r.k, r.row]
        x = ref.states[r.k]
        if r.kind == "horizon_angle":
            sen = study.observations[r.tracking].sensor
            axes = onboard.horizon_sensor_axes(
                x[:3], x[3:6], sen.horizon_azimuth_rad, math.acos(6378.137 / np.linalg.norm(x[:3]))
            )
            args = (x[:3], np.zeros(3), axes, sen.pole, sen.equatorial_radius_km, sen.polar_radius_km, 0.0)
            h_sc, dgam, rho_h = (np.asarray(a) for a in _HORIZON_PARTIALS(*args))
            np.testing.assert_allclose(h[:6], h_sc, rtol=1e-12, atol=1e-18)
            assert h[col["horizon_altitude_bias_km"]] == pytest.approx(float(dgam), rel=1e-12)
            assert abs(float(dgam) * float(rho_h) - 1.0) < 5e-3
            # noise: sigma^2 = sigma_angle^2 + (alpha_H d psi/d gamma)^2 (UNF alpha^2 = alpha_H^2/rho_H^2)
            var = (0.1e-3) ** 2 + (0.3 * float(dgam)) ** 2
            assert meas.R_assumed[r.k, r.row, r.row] == pytest.approx(var, rel=1e-12)
            assert meas.R_true[r.k, r.row, r.row] == pytest.approx(var, rel=1e-12)
        elif r.kind == "altitude":
            assert h[col["altitude_bias_km"]] == 1.0
            np.testing.assert_allclose(np.linalg.norm(h[:3]), 1.0, rtol=1e-14)
            assert np.all(h[3:nx] == 0.0)
        elif r.kind == "sensor_theta":
            assert np.all(h[3:nx] == 0.0) and np.linalg.norm(h[:3]) > 0.0
            assert h[col["sensor_misalignment_y_rad"]] != 0.0
        elif r.kind == "sensor_beta":
            assert np.linalg.norm(h[:3]) > 0.0


@pytest.mark.slow  # its module fixture: ~22 s of a cold make test (issue 22)
def test_onboard_data_shrink_the_knowledge(small):
    study, ref, _ = small
    res = run_study(study, ref)
    P = res.Pa_plus
    pos0 = math.sqrt(np.trace(study.P0_assumed[:3, :3]))
    assert math.sqrt(np.trace(P[-1][:3, :3])) < 0.5 * pos0


# ------------------------------------------------------------------------- the example
@pytest.fixture(scope="module")
def example():
    from fracas.config.team import load_team_deck

    study = build_study(load_team_deck(EXAMPLE))
    ref = integrate_reference(study)
    res = run_study(study, ref)
    return study, ref, res


def _prior_only(study, ref, res):
    """The same study with every H row zero (prior, dynamics and noise only)."""
    m = res.measurements if hasattr(res, "measurements") else assemble_measurements(study, ref)
    none = MeasurementSet(np.zeros_like(m.H), m.R_assumed, m.R_true, [], {})
    Qa, Qt = process_noise(study, ref)
    phi = augmented_transitions(study, ref)
    return run_filter(study, phi, Qa, Qt, none)[1]


@pytest.mark.slow  # the horizon example deck: ~25 s of a cold make test (issue 22)
def test_example_horizon_data_shrink_the_position_knowledge(example):
    study, ref, res = example
    P_prior = _prior_only(study, ref, res)
    pos = np.sqrt(np.einsum("kii->k", res.Pa_plus[:, :3, :3]))
    pos_prior = np.sqrt(np.einsum("kii->k", P_prior[:, :3, :3]))
    assert pos[-1] < 0.5 * pos_prior[-1]  # the sign of the effect, with a wide margin
    assert np.all(pos <= pos_prior * (1 + 1e-9))
    i_gam = study.nx + study.labels.index("horizon_altitude_bias_km")
    assert math.sqrt(res.Pa_plus[-1][i_gam, i_gam]) < 0.5 * 2.0  # gamma_H is observed


@pytest.mark.slow  # the horizon example deck: ~25 s of a cold make test (issue 22)
def test_example_regression_numbers(example):
    """Regression (this code's output at the time of writing, not a reference): the final
    position RSS and the horizon-altitude sigma of the example."""
    study, _, res = example
    P = res.Pa_plus[-1]
    i_gam = study.nx + study.labels.index("horizon_altitude_bias_km")
    # 0.3847 before issue 32: the example flies the TOM spiral's yaw-switch arcs, whose STMs
    # now carry the saltation jump at each flip (-0.44 %; tests/integrate/test_yaw_switch.py)
    assert math.sqrt(np.trace(P[:3, :3])) == pytest.approx(0.3830, rel=2e-3)
    assert math.sqrt(P[i_gam, i_gam]) == pytest.approx(0.3165, rel=2e-3)


@pytest.mark.slow
def test_example_runs_with_fracas_run(tmp_path):
    from click.testing import CliRunner

    from fracas.cli import main

    text = EXAMPLE.read_text(encoding="utf-8").replace("../out/", str(tmp_path) + "/")
    deck = EXAMPLE.parent / "_onboard_example_under_test.toml"
    deck.write_text(text, encoding="utf-8")
    try:
        r = CliRunner().invoke(main, ["run", str(deck)])
    finally:
        deck.unlink()
    assert r.exit_code == 0, r.output
    assert "horizon_altitude_bias_km" in r.output


def test_observation_needs_a_count_interval():
    with pytest.raises(ValueError, match="count_interval_s"):
        trakm.Observation("doppler_count_1way", ("goldstone",), 1e-5)
    ob = trakm.Observation("altitude", (), 0.01)
    assert ob.sensor == trakm.OnboardSensor()
    assert dataclasses.replace(ob, sigma=0.02).sensor == ob.sensor


def test_onboard_settings_are_structure_for_batched_sweeps():
    """A sweep batches studies that differ only in numbers (P0, sigmas) and shares the first
    study's H.  Onboard sensor settings (here the horizon scan azimuth) and beacon cones
    shape H and the schedule, so two studies differing in them must not be batched
    together: structure_mismatch names the observations."""
    import dataclasses

    from fracas.modes.stm import load_team
    from fracas.team.batch import structure_mismatch

    study = load_team("namelists/near_earth_spiral_horizon_team.toml").study
    assert structure_mismatch(study, study) is None
    k = next(i for i, o in enumerate(study.observations) if o.sensor is not None)
    o = study.observations[k]
    moved = dataclasses.replace(
        o, sensor=dataclasses.replace(o.sensor, horizon_azimuth_rad=o.sensor.horizon_azimuth_rad + 0.1)
    )
    other = dataclasses.replace(study, observations=[*study.observations[:k], moved, *study.observations[k + 1 :]])
    assert structure_mismatch(study, other) == "observations"
