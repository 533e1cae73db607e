"""Hardening of the deck readers (issue 8): every refusal is one line naming the file and
the field, with the cause; sizes are bounded before work starts; sigmas have physical ranges."""

from __future__ import annotations

from pathlib import Path

import pytest

from fracas.config.limits import DEFAULT_LIMITS, HARD_LIMITS, check_team_sizes
from fracas.config.team import parse_team_deck
from fracas.config.trajectory import parse_deck, trajectory_hash
from fracas.errors import DeckError
from fracas.modes import load_any

ROOT = Path(__file__).resolve().parents[2]
TRAJ = (ROOT / "namelists" / "leo_j2.toml").read_text(encoding="utf-8")
TEAM = (ROOT / "namelists" / "mercury_approach_team.toml").read_text(encoding="utf-8")
TEAM_TRAJ = ROOT / "namelists" / "mercury_approach_traj.toml"
SRC = "deck.toml"


def refusal(text: str, team: bool = False) -> DeckError:
    with pytest.raises(DeckError) as info:
        (parse_team_deck if team else parse_deck)(text, SRC)
    exc = info.value
    for line in [str(exc), *exc.problems]:
        assert "\n" not in line and line.startswith(f"{SRC}: ")
    return exc


def sub(text: str, old: str, new: str, count: int = 1) -> str:
    assert old in text
    return text.replace(old, new, count)


# ----------------------------------------------------------------------------- reading
def test_bom_is_stripped():
    assert parse_deck("\ufeff" + TRAJ, SRC).spacecraft.mass_kg == 1000.0


def test_bom_file(tmp_path):
    p = tmp_path / "d.toml"
    p.write_bytes(b"\xef\xbb\xbf" + TRAJ.encode())
    assert load_any(p).spacecraft.mass_kg == 1000.0


def test_deep_nesting_beyond_the_parser_names_the_key():
    exc = refusal(sub(TRAJ, "mass_kg = 1000.0", "mass_kg = " + "[" * 3000 + "]" * 3000))
    assert str(exc).startswith(f"{SRC}: spacecraft.mass_kg = [[[[")
    assert str(exc).endswith("arrays / inline tables nested more than 16 deep (line 17)")


def test_deep_nesting_within_the_parser_names_the_key():
    exc = refusal(sub(TRAJ, "mass_kg = 1000.0", "mass_kg = " + "[" * 40 + "]" * 40))
    assert str(exc) == f"{SRC}: spacecraft.mass_kg[0] = […]: nested more than 16 deep"


def test_huge_integer_is_refused_and_cut():
    exc = refusal(sub(TRAJ, "mass_kg = 1000.0", "mass_kg = 1" + "0" * 400))
    assert str(exc) == (
        f"{SRC}: spacecraft.mass_kg = 1{'0' * 38}…: an integer of 401 digits (TOML integers are 64-bit)"
    )


def test_huge_integer_in_a_vector():
    team = sub(TEAM, "position_rss_km = 25000.0", "position_sigma_km = [1, 2, " + "9" * 400 + "]")
    exc = refusal(team, team=True)
    assert str(exc).startswith(f"{SRC}: a_priori.position_sigma_km[2] = 999")


def test_long_values_are_cut_to_40_characters():
    exc = refusal(sub(TRAJ, 'centre = "earth"', 'centre = "' + "x" * 300 + '"'))
    value = str(exc).split(" = ", 1)[1].split(": ", 1)[0]
    assert len(value) == 40 and value.endswith("…")


# ----------------------------------------------------------------------------- causes
def test_typo_names_the_unknown_key_with_did_you_mean():
    exc = refusal(sub(TRAJ, "mass_kg = 1000.0", "mass_kgs = 1000.0"))
    assert str(exc) == f"{SRC}: spacecraft.mass_kgs: unknown key; did you mean mass_kg? (and 1 more error)"
    assert exc.problems == [
        f"{SRC}: spacecraft.mass_kgs: unknown key; did you mean mass_kg?",
        f"{SRC}: spacecraft.mass_kg: required",
    ]


def test_typo_in_a_team_deck():
    exc = refusal(sub(TEAM, "mass_sigma_kg", "mass_sigma"), team=True)
    assert str(exc) == f"{SRC}: a_priori.mass_sigma: unknown key; did you mean mass_sigma_kg?"


def test_team_deck_given_as_trajectory_deck():
    assert str(refusal(TEAM)) == (
        f'{SRC}: this is a TEAM deck (mode = "team"), not a trajectory deck: run it with fracas run'
    )


def test_trajectory_deck_given_as_team_deck():
    assert str(refusal(TRAJ, team=True)) == (
        f"{SRC}: this is a trajectory deck (it has no [ertraj] table), not a TEAM deck: run it with fracas propagate"
    )
    assert str(refusal('mode = "propagate"\n' + TRAJ, team=True)).startswith(
        f'{SRC}: this is a trajectory deck (mode = "propagate"), not a TEAM deck'
    )


def test_every_problem_is_listed():
    text = sub(sub(TRAJ, "mass_kg = 1000.0", "mass_kg = -1.0\ncr = 7.0"), "title =", "titel =")
    exc = refusal(text)
    assert len(exc.problems) == 3
    assert exc.problems[0] == f"{SRC}: titel: unknown key; did you mean title?"
    assert str(exc) == exc.problems[0] + " (and 2 more errors)"


def test_case_insensitive_stations_and_labels_stored_canonical():
    text = sub(TEAM, 'stations = ["goldstone"]', 'stations = ["GoldStone"]')
    text = sub(text, 'label = "mu[mercury]"', 'label = "Mu[Mercury]"')
    text = sub(text, 'label = "station_lon_rad[madrid]"', 'label = "Station_Lon_Rad[MADRID]"')
    text = sub(text, 'parameters = ["mu[sun]", "mu[venus]"]', 'parameters = ["MU[Sun]", "mu[venus]"]')
    text = sub(text, 'label = "cr"', 'label = "CR"')
    text += '\n[[station]]\nname = "Perth"\nradius_km = 6371.0\nlatitude_deg = -31.8\nlongitude_deg = 115.9\n'
    deck = parse_team_deck(text, SRC)
    assert deck.tracking[0].stations == ["goldstone"]
    assert deck.parameter[3].label == "mu[mercury]"
    assert deck.parameter[9].label == "station_lon_rad[madrid]"
    assert deck.stm.parameters == ["mu[sun]", "mu[venus]"]
    assert deck.gencov.parameter[0].label == "cr"
    assert deck.station[0].name == "perth"


def test_case_insensitive_sensitivities():
    text = TRAJ.replace("[output]", '[output]\nsensitivities = ["MU[Earth]"]', 1)
    assert parse_deck(text, SRC).output.sensitivities == ["mu[earth]"]


def test_repeat_after_canonicalisation():
    text = sub(TEAM, 'label = "bias_out_rad"', 'label = "BIAS_IN_RAD"')
    assert str(refusal(text, team=True)) == f'{SRC}: parameter[2].label = "bias_in_rad": repeats parameter[1]'


# ----------------------------------------------------------------------------- bounds
BOUNDS = {
    "thrust-noise proportionality": (
        "proportionality = { sigma = 0.02,",
        "proportionality = { sigma = 1e20,",
        "thrust_noise.proportionality.sigma = 1e+20: must be <= 1 (100 %)",
    ),
    "thrust-noise pointing": (
        "in_plane_deg = { sigma = 0.5,",
        "in_plane_deg = { sigma = 200.0,",
        "thrust_noise.in_plane_deg.sigma = 200.0: must be <= 180 deg",
    ),
    "tau": ("tau_days = 1.0 }", "tau_days = 0.0 }", "thrust_noise.proportionality.tau_days = 0.0: must be > 0"),
    "tau infinite": (
        "tau_days = 1.0 }",
        "tau_days = inf }",
        "thrust_noise.proportionality.tau_days = Infinity: must be a finite number",
    ),
    "tracking sigma": (
        "sigma = 1.0                          # mm/s",
        "sigma = 1e308",
        'tracking[0].sigma = 1e+308: must be <= 1e+06 mm/s for type "doppler2"',
    ),
    "range sigma": (
        "sigma = 1.0                          # m\n",
        "sigma = 2e7\n",
        'tracking[3].sigma = 20000000.0: must be <= 1e+07 m for type "range2"',
    ),
    "gencov measurement sigma": (
        "measurement_sigma = { doppler2 = 1.5 }",
        "measurement_sigma = { doppler2 = 1e9 }",
        'gencov.measurement_sigma.doppler2 = 1000000000.0: must be <= 1e+06 mm/s for type "doppler2"',
    ),
    "mu sigma relative": (
        "sigma = 88.13",
        "sigma = 1e300",
        "parameter[3].sigma = 1e+300: must be <= 22032.1 km^3/s^2 (1 x mercury's 22032.1) for mu[mercury]",
    ),
    "proportionality parameter": (
        "sigma = 0.005\n",
        "sigma = 2.0\n",
        "parameter[0].sigma = 2.0: must be <= 1 (100 %) for thrust_scale",
    ),
    "angle parameter": (
        "sigma = 0.0087266\n",
        "sigma = 4.0\n",
        "parameter[1].sigma = 4.0: must be <= 3.14159 rad for bias_in_rad",
    ),
    "measurement parameter": (
        "sigma = 9.6e-8\n",
        "sigma = 7.0\n",
        "parameter[5].sigma = 7.0: must be <= 3.14159 rad for station_lon_rad[goldstone]",
    ),
    "gencov parameter": (
        'label = "cr"\nsigma = 0.1',
        'label = "cr"\nsigma = 3.0',
        "gencov.parameter[0].sigma = 3.0: must be <= 2 (200 %) for cr",
    ),
    "a-priori velocity": (
        "velocity_rss_km_s = 0.025",
        "velocity_rss_km_s = 3e5",
        "a_priori.velocity_rss_km_s = 300000.0: must be < 299792",
    ),
}


@pytest.mark.parametrize("case", sorted(BOUNDS))
def test_bound(case):
    old, new, expected = BOUNDS[case]
    assert str(refusal(sub(TEAM, old, new), team=True)) == f"{SRC}: {expected}"


# ----------------------------------------------------------------------------- sizes
def test_output_step_limit():
    exc = refusal(sub(TRAJ, "step_days = 0.01", "step_days = 1e-9"))
    assert str(exc) == (
        f"{SRC}: output.step_days = 1e-09: gives 1e+09 output times over 0-1 d "
        "(limit 100000, [limits] max_output_times); use a longer step"
    )


def test_output_limit_override_admits_more():
    text = sub(TRAJ, "step_days = 0.01", "step_days = 1e-5")
    refusal(text)
    deck = parse_deck(text + "\n[limits]\nmax_output_times = 200000\n", SRC)
    assert deck.limits.max_output_times == 200000
    other = parse_deck(text + "\n[limits]\nmax_output_times = 300000\n", SRC)
    assert trajectory_hash(deck) == trajectory_hash(other)  # [limits] is not part of the trajectory


def test_tracking_interval_limit():
    exc = refusal(sub(TEAM, "interval_hours = 2.0", "interval_hours = 1e-9"), team=True)
    assert str(exc) == (
        f"{SRC}: tracking[0].interval_hours = 1e-09: gives 9.6e+11 observation times over 0-40 d "
        "(limit 200000, [limits] max_measurements); use a longer interval"
    )


def test_tracking_each_entry_reported():
    exc = refusal(TEAM.replace("interval_hours = 2.0", "interval_hours = 1e-3"), team=True)
    assert len(exc.problems) == 3
    assert exc.problems[2].startswith(f"{SRC}: tracking[2].interval_hours = 0.001: gives 960001 observation times")


def test_tracking_total_limit_and_override():
    text = TEAM.replace("interval_hours = 2.0", "interval_hours = 0.01")  # 96,001 each, 3 entries
    exc = refusal(text, team=True)
    assert str(exc).startswith(f"{SRC}: tracking: the 6 entries give 2")
    assert "observation times in all (limit 200000, [limits] max_measurements)" in str(exc)
    deck = parse_team_deck(text + "\n[limits]\nmax_measurements = 400000\nmax_schedule_times = 400000\n", SRC)
    assert deck.limits.max_measurements == 400000


def test_event_limit():
    exc = refusal(sub(TEAM, "interval_days = 1.0", "interval_days = 1e-6"), team=True)
    assert str(exc) == (
        f"{SRC}: event[1].interval_days = 1e-06: gives 4e+07 event times "
        "(limit 20000, [limits] max_events); use a longer interval"
    )


def test_limits_table_is_bounded():
    exc = refusal(TEAM + "\n[limits]\nmax_measurements = 1e12\n", team=True)
    assert str(exc) == f"{SRC}: limits.max_measurements = 1000000000000.0: must be an integer"
    exc = refusal(TEAM + "\n[limits]\nmax_measurements = 1000000000000\n", team=True)
    assert str(exc) == f"{SRC}: limits.max_measurements = 1000000000000: must be <= {HARD_LIMITS['max_measurements']:g}"
    exc = refusal(TEAM + "\n[limits]\nmax_measurement = 10\n", team=True)
    assert str(exc) == f"{SRC}: limits.max_measurement: unknown key; did you mean max_measurements?"


def test_defaults_pass_the_bundled_decks_widely():
    assert DEFAULT_LIMITS["max_measurements"] == 200_000


def _team_sizes(text: str):
    deck = parse_team_deck(text, str(ROOT / "namelists" / "x_team.toml"))
    traj = parse_deck(TEAM_TRAJ.read_text(encoding="utf-8"), str(TEAM_TRAJ))
    with pytest.raises(DeckError) as info:
        check_team_sizes(deck, traj)
    return deck.source_path, info.value


def test_stm_grid_limit():
    src, exc = _team_sizes(sub(TEAM, "grid_hours = 1.0", "grid_hours = 1e-9"))
    assert str(exc) == (
        f"{src}: stm.grid_hours = 1e-09: gives 9.6e+11 STM times over 0-40 d "
        "(limit 100000, [limits] max_stm_times); use a longer grid"
    )


def test_stm_grid_override_admits_more():
    text = sub(TEAM, "grid_hours = 1.0", "grid_hours = 0.005")  # 192,001 grid times
    _team_sizes(text)
    deck = parse_team_deck(text + "\n[limits]\nmax_stm_times = 300000\n", SRC)
    check_team_sizes(deck, parse_deck(TEAM_TRAJ.read_text(encoding="utf-8"), str(TEAM_TRAJ)))


def test_schedule_limit():
    text = TEAM.replace("interval_hours = 2.0", "interval_hours = 0.02")
    text += "\n[limits]\nmax_schedule_times = 100000\n"
    src, exc = _team_sizes(text)
    assert str(exc).startswith(f"{src}: tracking: gives 145376 schedule times over 0-40 d (limit 100000")


def test_pdot_step_limit():
    text = sub(TEAM, 'propagation = "phi"', 'propagation = "pdot"')
    text = sub(text, "pdot_step_hours = 2.4", "pdot_step_hours = 1e-7")
    src, exc = _team_sizes(text)
    assert str(exc).startswith(f"{src}: ertraj.pdot_step_hours = 1e-07: gives 9.6e+09 PDOT steps over 0-40 d")


def test_build_case_checks_sizes_first(tmp_path):
    """fracas.build.team.trajectory_problem refuses the size before building the ephemeris."""
    from fracas.build.team import trajectory_problem

    (tmp_path / "mercury_approach_traj.toml").write_text(TEAM_TRAJ.read_text(encoding="utf-8"), encoding="utf-8")
    p = tmp_path / "t.toml"
    p.write_text(sub(TEAM, "grid_hours = 1.0", "grid_hours = 1e-9"), encoding="utf-8")
    deck = load_any(p)
    with pytest.raises(DeckError, match=r"stm\.grid_hours = 1e-09: gives 9\.6e\+11 STM times"):
        trajectory_problem(deck, str(p))


# ----------------------------------------------------------------------------- what a run would refuse
def deck_text(
    centre: str,
    state: str,
    *,
    epoch: str = 'iso = "2030-01-01T00:00:00"',
    stop: str = "duration_days = 1.0",
    forces: str = "",
) -> str:
    return (
        f'[epoch]\n{epoch}\n[initial_state]\ncentre = "{centre}"\n{state}\n'
        f"[spacecraft]\nmass_kg = 1000.0\n[forces]\n{forces}\n[stop]\n{stop}\n"
    )


#: (centre, initial-state table, |r| of the start in km, the radius it is checked against):
#: every form an initial state can take, about several central bodies, elliptic and
#: hyperbolic, mean and true anomaly, and a radius set by forces.overrides
STARTS = {
    "cartesian_earth": (
        "earth",
        "[initial_state.cartesian]\nr_km = [3000.0, 0.0, 0.0]\nv_km_s = [0.0, 7.5, 0.0]",
        3000.0,
        6378.137,
    ),
    "cartesian_3d_mars": (
        "mars",
        "[initial_state.cartesian]\nr_km = [1000.0, 2000.0, -2000.0]\nv_km_s = [0, 3, 0]",
        3000.0,
        3396.19,
    ),
    "spherical_moon": (
        "moon",
        "[initial_state.spherical]\nr_km = 1500.0\nlat_deg = 10.0\nlon_deg = 0.0\n"
        "v_km_s = 1.0\ngamma_deg = 0.0\nsigma_deg = 90.0",
        1500.0,
        1737.4,
    ),
    "elements_true_anomaly": (
        "earth",
        "[initial_state.elements]\na_km = 7000.0\ne = 0.2\ni_deg = 30.0\ntrue_anomaly_deg = 0.0",
        5600.0,
        6378.137,
    ),
    "elements_mean_anomaly": (
        "earth",
        "[initial_state.elements]\na_km = 7000.0\ne = 0.2\ni_deg = 30.0\nmean_anomaly_deg = 10.0",
        None,
        6378.137,
    ),
    "elements_high_e_mean_anomaly": (
        "sun",
        "[initial_state.elements]\na_km = 1.0e7\ne = 0.95\ni_deg = 0.0\nmean_anomaly_deg = 0.1",
        None,
        695700.0,
    ),
    "hyperbola_mean_anomaly": (
        "moon",
        "[initial_state.elements]\na_km = -2000.0\ne = 1.5\ni_deg = 10.0\nmean_anomaly_deg = 5.0",
        None,
        1737.4,
    ),
    "hyperbola_true_anomaly": (
        "jupiter",
        "[initial_state.elements]\na_km = -50000.0\ne = 2.0\ni_deg = 0.0\ntrue_anomaly_deg = 20.0",
        None,
        71492.0,
    ),
    "override_radius": (
        "earth",
        "[initial_state.cartesian]\nr_km = [7000.0, 0.0, 0.0]\nv_km_s = [0.0, 7.5, 0.0]",
        7000.0,
        7100.0,
    ),
}


def _start(case: str, radius_km: float | None = None) -> str:
    """The deck of ``case``; ``radius_km``: the centre's radius set by forces.overrides."""
    centre, state, _, radius = STARTS[case]
    if case == "override_radius" and radius_km is None:
        radius_km = radius
    forces = f"[forces.overrides.{centre}]\nradius_km = {radius_km}" if radius_km is not None else ""
    return deck_text(centre, state, forces=forces)


def _core_radius(deck) -> float:
    """|r| of the start as the propagation converts it (fracas.build.trajectory, JAX)."""
    import numpy as np

    from fracas.build.trajectory import _initial_state
    from fracas.constants import BODIES

    r, _ = _initial_state(deck, BODIES[deck.initial_state.centre].mu_km3_s2)
    return float(np.linalg.norm(r))


@pytest.mark.parametrize("case", sorted(STARTS))
def test_a_start_inside_the_centre_is_refused(case):
    """Against the propagation's own conversion of the initial state (cartesian, spherical,
    elements by true or mean anomaly, ellipse or hyperbola, any centre) and the body radius of
    fracas.constants (or forces.overrides): a start inside the centre is one line naming
    initial_state and the radius; with the radius overridden below the start, the deck is
    accepted and validation's |r| equals the core's to 1e-12."""
    from fracas.config.trajectory import initial_radius_km

    centre, _, r_given, radius = STARTS[case]
    msg = str(refusal(_start(case)))
    assert msg.startswith(f"{SRC}: initial_state.") and f"inside its radius {radius:.10g} km" in msg, msg
    assert f"from the centre of {centre}" in msg
    deck = parse_deck(_start(case, radius_km=1.0), SRC)
    r = initial_radius_km(deck.initial_state)
    assert r == pytest.approx(_core_radius(deck), rel=1e-12) and r < radius
    if r_given is not None:
        assert r == pytest.approx(r_given, rel=1e-12)


def test_a_start_on_or_just_outside_the_surface_is_accepted():
    """Against constants.BODIES["earth"].radius_km: |r| equal to the radius, or 1 m above, is
    a valid start (only a start strictly inside is refused)."""
    for r in (6378.137, 6378.138):
        state = f"[initial_state.cartesian]\nr_km = [0.0, {r}, 0.0]\nv_km_s = [7.9, 0.0, 0.0]"
        assert parse_deck(deck_text("earth", state), SRC).initial_state.cartesian.r_km[1] == r


def test_an_override_of_a_body_outside_the_model_is_refused():
    """Against fracas.build.trajectory (which refused it only when building): an override of a
    body the force model does not have is one line naming forces.overrides.<body>."""
    state = "[initial_state.cartesian]\nr_km = [7000.0, 0.0, 0.0]\nv_km_s = [0.0, 7.5, 0.0]"
    msg = str(refusal(deck_text("earth", state, forces="[forces.overrides.mars]\nmu_km3_s2 = 1.0")))
    assert msg.startswith(f"{SRC}: forces.overrides.mars = mars: is not in the force model (earth)"), msg


LEO = "[initial_state.cartesian]\nr_km = [7000.0, 0.0, 0.0]\nv_km_s = [0.0, 7.5, 0.0]"
#: (epoch, stop, forces, the field refused): decks whose span leaves DE421's, by the epoch
#: (ISO or Julian date, before or after the span) or by the end (duration forward or
#: backward, final_epoch), for every way the force model comes to need body positions
SPANS = {
    "epoch_after": ('iso = "2060-01-01T00:00:00"', "duration_days = 1.0", 'third_bodies = ["moon"]', "epoch.iso"),
    "epoch_before_jd": (
        "julian_date = 2400000.5",
        "duration_days = 1.0",
        'third_bodies = ["sun"]',
        "epoch.julian_date",
    ),
    "end_by_duration": (
        'iso = "2053-10-01T00:00:00"',
        "duration_days = 30.0",
        'third_bodies = ["moon"]',
        "stop.duration_days",
    ),
    "end_backward": (
        'iso = "1899-12-10T00:00:00"',
        "duration_days = -30.0",
        'third_bodies = ["moon"]',
        "stop.duration_days",
    ),
    "end_by_final_epoch": (
        'iso = "2050-01-01T00:00:00"',
        'final_epoch = "2054-01-01T00:00:00"',
        "srp = true",
        "stop.final_epoch",
    ),
    "soi_parents": ('iso = "2070-01-01T00:00:00"', "duration_days = 1.0", "change_primary_at_soi = true", "epoch.iso"),
}


@pytest.mark.parametrize("case", sorted(SPANS))
def test_a_span_outside_the_ephemeris_is_refused(case):
    """Against the ephemeris' own coverage (fracas.dynamics.ephemeris.coverage_et, which
    build_ephemeris enforces when a propagation needs positions): the epoch or the end of
    the trajectory outside it is one line naming the field and the span."""
    epoch, stop, forces, field = SPANS[case]
    text = deck_text("earth", LEO, epoch=epoch, stop=stop, forces=forces)
    if "srp" in forces:
        text = text.replace("mass_kg = 1000.0", "mass_kg = 1000.0\narea_m2 = 10.0")
    msg = str(refusal(text))
    assert msg.startswith(f"{SRC}: {field} = ") and "the DE421 ephemeris spans 1899-12-04 to 2053-10-09 TDB" in msg
    # the same dates without a body position to read (two-body) are not the ephemeris' business
    two_body = deck_text("earth", LEO, epoch=epoch, stop=stop)
    assert parse_deck(two_body, SRC).epoch is not None


def test_the_span_checked_is_the_ephemeris_coverage():
    """constants.DE421_START_JD / DE421_END_JD (validation, no JAX) equal the coverage the
    ephemeris module serves (fracas.dynamics.ephemeris.coverage_et, from the de421 data)."""
    from fracas.constants import DAY_S, DE421_END_JD, DE421_START_JD, J2000_JD
    from fracas.dynamics.ephemeris import coverage_et

    assert coverage_et() == ((DE421_START_JD - J2000_JD) * DAY_S, (DE421_END_JD - J2000_JD) * DAY_S)


def test_validate_and_propagate_refuse_the_same_line(tmp_path):
    """fracas validate and fracas propagate on a deck starting 3000 km from Earth's centre:
    both exit 2 with the same one line naming initial_state and the radius, no traceback."""
    from click.testing import CliRunner

    from fracas.cli import main

    path = tmp_path / "inside.toml"
    path.write_text(deck_text("earth", LEO.replace("7000.0", "3000.0", 1)))
    lines = []
    for args in (["validate", str(path)], ["propagate", str(path)]):
        r = CliRunner().invoke(main, args)
        assert r.exit_code == 2 and "Traceback" not in r.output, r.output
        err = r.stderr.strip().splitlines()
        assert len(err) == 1
        lines.append(err[0])
    assert lines[0] == lines[1]
    assert "initial_state.cartesian.r_km" in lines[0] and "inside its radius 6378.137 km" in lines[0]
