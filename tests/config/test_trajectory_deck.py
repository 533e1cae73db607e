"""The trajectory deck: example decks validate, bad decks give one precise line, and
build.py converts units and frames correctly."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from fracas import constants
from fracas.config.trajectory import TrajectoryDeck, load_deck, parse_deck
from fracas.errors import ConfigError, DeckError

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = ["leo_j2.toml", "earth_mars_sep.toml", "near_earth_spiral.toml"]

MINIMAL = """
[epoch]
iso = "2030-01-01T00:00:00"

[initial_state]
centre = "earth"

[initial_state.cartesian]
r_km = [7000.0, 0.0, 0.0]
v_km_s = [0.0, 7.5, 1.0]

[spacecraft]
mass_kg = 1000.0

[stop]
duration_days = 1.0
"""

PROPULSION = """
[propulsion]
power_kw = 10.0
efficiency = 0.65
exhaust_velocity_km_s = 30.0
"""


def _write(tmp_path: Path, text: str, name: str = "deck.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _error(tmp_path: Path, text: str) -> str:
    path = _write(tmp_path, text)
    with pytest.raises(DeckError) as info:
        load_deck(path)
    msg = str(info.value)
    assert "\n" not in msg, msg
    assert msg.startswith(f"{path}: "), msg
    return msg[len(f"{path}: ") :]


# --------------------------------------------------------------------------- good decks


@pytest.mark.parametrize("name", EXAMPLES)
def test_example_decks_validate(name):
    deck = load_deck(REPO / "namelists" / name)
    assert isinstance(deck, TrajectoryDeck)
    assert deck.duration_days > 0
    assert deck.source_text == (REPO / "namelists" / name).read_text()
    assert deck.source_path.endswith(name)


def test_minimal_deck_defaults():
    deck = parse_deck(MINIMAL)
    assert deck.primary == "earth"
    assert deck.initial_state.frame == "EME2000"
    assert deck.initial_state.kind == "cartesian"
    assert deck.integrator.c_nom == 0.3
    assert deck.stop.condition == "time"
    assert deck.output.include_final
    assert deck.forces.third_bodies == []


def test_deck_is_frozen():
    deck = parse_deck(MINIMAL)
    with pytest.raises(ValidationError):
        deck.spacecraft.mass_kg = 3.0  # type: ignore[misc]


def test_final_epoch_and_julian_date():
    text = MINIMAL.replace('iso = "2030-01-01T00:00:00"', "julian_date = 2462502.5")
    text = text.replace("duration_days = 1.0", 'final_epoch = "2030-01-03T12:00:00"')
    deck = parse_deck(text)
    # 2030-01-01T00:00 TDB is JD 2462502.5; 2.5 days later.
    assert deck.duration_days == pytest.approx(2.5, abs=1e-9)  # float JD arithmetic, ~1e-10 d


def test_toml_datetime_accepted_for_iso():
    deck = parse_deck(MINIMAL.replace('iso = "2030-01-01T00:00:00"', "iso = 2030-01-01T06:00:00"))
    assert deck.epoch.iso == "2030-01-01T06:00:00"


# --------------------------------------------------------------------------- bad decks


def test_bad_mass_deck_message():
    path = REPO / "tests" / "data" / "bad_mass.toml"
    with pytest.raises(DeckError) as info:
        load_deck(path)
    assert str(info.value) == f"{path}: spacecraft.mass_kg = -5: must be > 0"


def test_bad_mass_relative_path_named_as_given(monkeypatch):
    monkeypatch.chdir(REPO)
    with pytest.raises(DeckError) as info:
        load_deck("tests/data/bad_mass.toml")
    assert str(info.value) == "tests/data/bad_mass.toml: spacecraft.mass_kg = -5: must be > 0"


def test_missing_file(tmp_path):
    path = tmp_path / "nope.toml"
    with pytest.raises(DeckError) as info:
        load_deck(path)
    assert str(info.value) == f"{path}: no such file"


def test_toml_syntax_error_names_line(tmp_path):
    msg = _error(tmp_path, MINIMAL.replace("mass_kg = 1000.0", "mass_kg = = 1000.0"))
    assert msg.startswith("TOML syntax error")
    line = MINIMAL.splitlines().index("mass_kg = 1000.0") + 1
    assert f"line {line}" in msg


# (replacement in MINIMAL, appended text, expected message after "path: ")
BAD = {
    "unknown field": (
        ("mass_kg = 1000.0", "mass_kg = 1000.0\nmas_kg = 3"),
        "",
        "spacecraft.mas_kg = 3: unknown field (expected one of: mass_kg, area_m2, cr)",
    ),
    "unknown body": (
        ('centre = "earth"', 'centre = "vulcan"'),
        "",
        'initial_state.centre = "vulcan": must be a known body, one of ' + ", ".join(constants.BODIES),
    ),
    "bad frame": (
        ('centre = "earth"', 'centre = "earth"\nframe = "J2000"'),
        "",
        "initial_state.frame = \"J2000\": must be 'EME2000', 'ECLIPJ2000' or 'BODY_EQUATOR'",
    ),
    "short vector": (
        ("r_km = [7000.0, 0.0, 0.0]", "r_km = [7000.0, 0.0]"),
        "",
        "initial_state.cartesian.r_km = [7000.0, 0.0]: must be a list of 3 numbers",
    ),
    "string for number": (
        ("mass_kg = 1000.0", 'mass_kg = "1000"'),
        "",
        'spacecraft.mass_kg = "1000": must be a number',
    ),
    "missing field": (
        ("mass_kg = 1000.0", "cr = 1.2"),
        "",
        "spacecraft.mass_kg: required",
    ),
    "non-finite": (
        ("mass_kg = 1000.0", "mass_kg = inf"),
        "",
        "spacecraft.mass_kg = Infinity: must be a finite number",
    ),
    "two state forms": (
        None,
        "\n[initial_state.elements]\na_km = 7000.0\ne = 0.0\ni_deg = 0.0\nmean_anomaly_deg = 0.0\n",
        "initial_state = {cartesian, elements}: give exactly one of the tables cartesian, elements, spherical",
    ),
    "duration and final epoch": (
        ("duration_days = 1.0", 'duration_days = 1.0\nfinal_epoch = "2030-01-02"'),
        "",
        "stop = {duration_days, final_epoch}: give exactly one of duration_days, final_epoch",
    ),
    "bad date": (
        ('iso = "2030-01-01T00:00:00"', 'iso = "2030-13-01"'),
        "",
        'epoch.iso = "2030-13-01": must be an ISO calendar date such as "2030-01-01T00:00:00" (TDB)',
    ),
    "efficiency above one": (
        None,
        PROPULSION.replace("efficiency = 0.65", "efficiency = 1.5"),
        "propulsion.efficiency = 1.5: must be <= 1",
    ),
    "both c and isp": (
        None,
        PROPULSION + "isp_s = 3000.0\n",
        "propulsion = {exhaust_velocity_km_s, isp_s}: give exactly one of exhaust_velocity_km_s, isp_s",
    ),
    "overlapping arcs": (
        None,
        PROPULSION + "[[thrust_arc]]\nstart_days = 0.0\nstop_days = 0.5\n"
        "[[thrust_arc]]\nstart_days = 0.4\nstop_days = 0.6\n",
        "thrust_arc[1].start_days = 0.4: must be >= thrust_arc[0].stop_days = 0.5 (arcs ordered, not overlapping)",
    ),
    "reversed arc": (
        None,
        PROPULSION + "[[thrust_arc]]\nstart_days = 0.5\nstop_days = 0.2\n",
        "thrust_arc[0].stop_days = 0.2: must be >= start_days = 0.5",
    ),
    "arc past the end": (
        None,
        PROPULSION + "[[thrust_arc]]\nstart_days = 0.5\nstop_days = 2.0\n",
        "thrust_arc[0].stop_days = 2.0: must be <= the final time, 1 days",
    ),
    "arcs without propulsion": (
        None,
        "[[thrust_arc]]\nstart_days = 0.0\nstop_days = 0.5\n",
        "propulsion: a [propulsion] section is required when thrust arcs are given",
    ),
    "primary as third body": (
        None,
        '[forces]\nthird_bodies = ["moon", "earth"]\n',
        'forces.third_bodies[1] = "earth": is the primary (initial_state.centre = "earth"); it cannot also be a third body',  # noqa: E501
    ),
    "override of unknown body": (
        None,
        "[forces.overrides.vulcan]\nmu_km3_s2 = 1.0\n",
        'forces.overrides.vulcan = "vulcan": must be a known body, one of ' + ", ".join(constants.BODIES),
    ),
    "negative eccentricity": (
        (
            "[initial_state.cartesian]\nr_km = [7000.0, 0.0, 0.0]\nv_km_s = [0.0, 7.5, 1.0]",
            "[initial_state.elements]\na_km = 7000.0\ne = -0.1\ni_deg = 0.0\nmean_anomaly_deg = 0.0",
        ),
        "",
        "initial_state.elements.e = -0.1: must be >= 0",
    ),
    "hyperbola with positive a": (
        (
            "[initial_state.cartesian]\nr_km = [7000.0, 0.0, 0.0]\nv_km_s = [0.0, 7.5, 1.0]",
            "[initial_state.elements]\na_km = 7000.0\ne = 1.5\ni_deg = 0.0\nmean_anomaly_deg = 0.0",
        ),
        "",
        "initial_state.elements.a_km = 7000.0: must be < 0 for a hyperbola (e > 1)",
    ),
    "radius stop without radius": (
        ("duration_days = 1.0", 'duration_days = 1.0\ncondition = "radius"'),
        "",
        'stop.radius_km: required for condition = "radius"',
    ),
    "integer field": (
        None,
        "[integrator]\nmax_steps = 1.5\n",
        "integrator.max_steps = 1.5: must be an integer",
    ),
    "boolean field": (
        None,
        "[forces]\nj2 = 1\n",
        "forces.j2 = 1: must be true or false",
    ),
    "output after the end": (
        None,
        "[output]\ntimes_days = [0.5, 2.0]\n",
        "output.times_days[1] = 2.0: must be <= the final time, 1 days",
    ),
    "malformed label": (
        None,
        '[output]\nsensitivities = ["mu sun"]\n',
        'output.sensitivities[0] = "mu sun": must be a parameter label such as "mu[sun]", "thrust_scale" or "arc_thrust_scale[0]"',  # noqa: E501
    ),
    "srp without area": (
        None,
        "[forces]\nsrp = true\n",
        "spacecraft.area_m2 = 0.0: must be > 0 when forces.srp = true",
    ),
    "repeated third body": (
        None,
        '[forces]\nthird_bodies = ["moon", "moon"]\n',
        'forces.third_bodies[1] = "moon": listed twice',
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_deck_one_line_message(tmp_path, case):
    replace, append, expected = BAD[case]
    text = MINIMAL
    if replace is not None:
        assert replace[0] in text
        text = text.replace(replace[0], replace[1])
    msg = _error(tmp_path, text + append)
    assert msg == expected


def test_several_errors_counted(tmp_path):
    text = MINIMAL.replace("mass_kg = 1000.0", "mass_kg = -1.0\ncr = 7.0")
    msg = _error(tmp_path, text)
    assert msg == "spacecraft.mass_kg = -1.0: must be > 0 (and 1 more error)"


@settings(max_examples=40, deadline=None)
@given(mass=st.floats(allow_nan=False, allow_infinity=False, min_value=-1e9, max_value=1e9))
def test_mass_validation_property(mass):
    text = MINIMAL.replace("mass_kg = 1000.0", f"mass_kg = {mass!r}")
    if mass > 0:
        assert parse_deck(text).spacecraft.mass_kg == mass
    else:
        with pytest.raises(DeckError, match=r"^d.toml: spacecraft\.mass_kg = .*: must be > 0$"):
            parse_deck(text, "d.toml")


# --------------------------------------------------------------------------- build


def test_build_leo_units_and_overrides():
    from fracas.build import build_propagation

    p = build_propagation(load_deck(REPO / "namelists" / "leo_j2.toml"))
    assert p.model.bodies == ("earth",)
    assert p.model.j2 and not p.model.thrust
    assert p.ephem is None  # Earth alone: no body positions needed
    assert float(p.params.mu[0]) == constants.MU_EARTH_EGM96_KM3_S2
    assert float(p.params.j2[0]) == constants.J2_EARTH
    assert float(p.params.radius[0]) == constants.R_EARTH_KM
    np.testing.assert_array_equal(p.x0, [7000.0, 0.0, 0.0, 0.0, 7.5, 1.0, 1000.0])
    assert p.t_out[0] == 0.0 and p.t_out[-1] == constants.DAY_S
    assert np.all(np.diff(p.t_out) > 0)
    ig = p.model.integrator  # the deck asks for accuracy: the tolerance, no step limit
    assert (ig.method, ig.formulation, ig.step_control, ig.tolerance) == ("dprkn12", "cowell", "tolerance", 1e-12)
    assert ig.dt_max_s == np.inf
    # 2030-01-01T00:00:00 TDB = JD 2462502.5 -> (JD - 2451545) * 86400 s
    assert p.epoch_et_s == (2462502.5 - constants.J2000_JD) * constants.DAY_S


def test_build_sep_cruise():
    from fracas.build import build_propagation

    p = build_propagation(load_deck(REPO / "namelists" / "earth_mars_sep.toml"))
    m = p.model
    assert m.bodies[m.primary] == "sun"
    assert {m.bodies[i] for i in m.third_bodies} == {"venus", "earth", "mars", "jupiter"}
    assert m.thrust and m.velocity_dependent and m.n_arcs == 3 and m.power == "solar"
    np.testing.assert_allclose(p.params.arc_t_on, np.array([0.0, 150.0, 260.0]) * constants.DAY_S)
    np.testing.assert_allclose(p.params.arc_alpha, np.radians([0.0, 20.0, 0.0]))
    assert float(p.params.exhaust_velocity_km_s) == 30.0
    assert p.ephem is not None
    r_au = np.linalg.norm(p.x0[:3]) / constants.AU_KM
    assert 0.98 < r_au < 1.03  # starts near the Earth's heliocentric distance


def test_build_spiral_elements_and_ephemeris():
    from fracas.build import build_propagation

    p = build_propagation(load_deck(REPO / "namelists" / "near_earth_spiral.toml"))
    m = p.model
    assert set(m.bodies) == {"earth", "moon", "sun"}
    assert m.bodies[m.primary] == "earth"
    mu = constants.BODIES["earth"].mu_km3_s2
    # circular 7000 km orbit: |r| = a, |v| = sqrt(mu / a), r.v = 0 (round-off tolerances)
    assert np.linalg.norm(p.x0[:3]) == pytest.approx(7000.0, rel=1e-14)
    assert np.linalg.norm(p.x0[3:6]) == pytest.approx(math.sqrt(mu / 7000.0), rel=1e-14)
    assert abs(np.dot(p.x0[:3], p.x0[3:6])) < 1e-9
    inc = math.degrees(math.acos(np.cross(p.x0[:3], p.x0[3:6])[2] / np.linalg.norm(np.cross(p.x0[:3], p.x0[3:6]))))
    assert inc == pytest.approx(28.5, abs=1e-10)
    assert p.ephem is not None


def test_isp_converts_with_g0():
    from fracas.build import build_propagation

    text = MINIMAL + PROPULSION.replace("exhaust_velocity_km_s = 30.0", "isp_s = 3000.0")
    p = build_propagation(parse_deck(text))
    assert float(p.params.exhaust_velocity_km_s) == pytest.approx(3000.0 * constants.G0_KM_S2, rel=1e-15)


def test_ecliptic_frame_rotates_to_icrf():
    from fracas.build import build_propagation

    text = MINIMAL.replace('centre = "earth"', 'centre = "earth"\nframe = "ECLIPJ2000"')
    text = text.replace("r_km = [7000.0, 0.0, 0.0]", "r_km = [0.0, 7000.0, 0.0]")
    p = build_propagation(parse_deck(text))
    eps = constants.OBLIQUITY_J2000_RAD
    # ecliptic y axis -> (0, cos eps, sin eps) in EME2000
    np.testing.assert_allclose(p.x0[:3], [0.0, 7000.0 * math.cos(eps), 7000.0 * math.sin(eps)], atol=1e-9)


def test_true_and_mean_anomaly_agree():
    from fracas.build import build_propagation

    els = "[initial_state.elements]\na_km = 8000.0\ne = 0.1\ni_deg = 30.0\nraan_deg = 40.0\nargp_deg = 50.0\n"
    cart = "[initial_state.cartesian]\nr_km = [7000.0, 0.0, 0.0]\nv_km_s = [0.0, 7.5, 1.0]"
    nu = 60.0
    e = 0.1
    E = 2.0 * math.atan(math.sqrt((1 - e) / (1 + e)) * math.tan(math.radians(nu) / 2))
    M = math.degrees(E - e * math.sin(E))
    a = build_propagation(parse_deck(MINIMAL.replace(cart, els + f"true_anomaly_deg = {nu}")))
    b = build_propagation(parse_deck(MINIMAL.replace(cart, els + f"mean_anomaly_deg = {M!r}")))
    np.testing.assert_allclose(a.x0, b.x0, rtol=0, atol=1e-8)  # Kepler solve to round-off


def test_spherical_state():
    from fracas.build import build_propagation

    cart = "[initial_state.cartesian]\nr_km = [7000.0, 0.0, 0.0]\nv_km_s = [0.0, 7.5, 1.0]"
    sph = "[initial_state.spherical]\nr_km = 7000.0\nlat_deg = 0.0\nlon_deg = 0.0\nv_km_s = 7.5\ngamma_deg = 0.0\nsigma_deg = 90.0"  # noqa: E501
    p = build_propagation(parse_deck(MINIMAL.replace(cart, sph)))
    np.testing.assert_allclose(p.x0[:6], [7000.0, 0, 0, 0, 7.5, 0], atol=1e-12)


def test_override_of_body_outside_model_is_refused_by_validation():
    """Refused when the deck is read (so fracas validate refuses it), no longer only by the build."""
    with pytest.raises(DeckError, match=r"^d\.toml: forces\.overrides\.mars = mars: is not in the force model"):
        parse_deck(MINIMAL + "[forces.overrides.mars]\nmu_km3_s2 = 1.0\n", "d.toml")


def test_unknown_sensitivity_label_is_config_error():
    from fracas.build import build_propagation

    deck = parse_deck(MINIMAL + '[output]\nsensitivities = ["mu[mars]"]\n', "d.toml")
    with pytest.raises(ConfigError, match=r'^d\.toml: output\.sensitivities\[0\] = "mu\[mars\]": '):
        build_propagation(deck)


def test_output_times_merge_grid_list_and_final():
    from fracas.build import output_times_s

    deck = parse_deck(MINIMAL + "[output]\ntimes_days = [0.3, 0.5]\nstep_days = 0.25\n")
    np.testing.assert_allclose(output_times_s(deck) / constants.DAY_S, [0.0, 0.25, 0.3, 0.5, 0.75, 1.0])
