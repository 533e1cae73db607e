"""Hardening of the deck readers (issue 8): every refusal is one line naming the file and
the field, with the cause; sizes are bounded before work starts; sigmas have physical ranges."""

from __future__ import annotations

from pathlib import Path

import pytest

from fracas.config.limits import DEFAULT_LIMITS, HARD_LIMITS, check_team_sizes
from fracas.config.modes import load_any
from fracas.config.team import parse_team_deck
from fracas.config.trajectory import parse_deck, trajectory_hash
from fracas.errors import DeckError

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
