"""The TEAM deck: the example decks validate, bad decks are refused with ONE line that
names the file, the field and what was expected; through the command line, exit code 2,
the message on stderr and no traceback.

References are the deck documentation (fracas/config/team/__init__.py docstring) and the
catalogues: DSN stations (goldstone, madrid, canberra), the bodies of the trajectory's
force model, N_STATIONS per measurement type.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from fracas.build.team import build_study
from fracas.cli import main
from fracas.config.team import load_team_deck, parse_team_deck
from fracas.errors import DeckError

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "tests" / "data"
SMALL = DATA / "team_small.toml"
EXAMPLES = sorted((REPO / "namelists").glob("*_team.toml"))
SRC = str(DATA / "bad_deck.toml")  # as if read from tests/data (the trajectory deck resolves there)


def small_text() -> str:
    return SMALL.read_text(encoding="utf-8")


def refusal(text: str, build: bool = False) -> str:
    """The DeckError message of a deck text (validation, and the study set-up if ``build``)."""
    with pytest.raises(DeckError) as e:
        deck = parse_team_deck(text, SRC)
        if build:
            build_study(deck)
    msg = str(e.value)
    assert "\n" not in msg, msg
    assert msg.startswith(SRC + ": "), msg
    return msg


# ----------------------------------------------------------------------------- the examples
def test_there_are_examples():
    assert len(EXAMPLES) >= 2 and SMALL.exists()


@pytest.mark.parametrize("path", EXAMPLES + [SMALL], ids=lambda p: p.name)
def test_example_decks_validate_and_build(path):
    """Validation and the study set-up (labels against the force model and catalogues)."""
    deck = load_team_deck(path)
    study = build_study(deck)
    assert study.labels and study.observations and study.schedule.count("measurement") > 0
    # roles come out in layout order s, u, v, w
    order = {"solve_for": 0, "dynamic_consider": 1, "measurement_consider": 2, "ignore": 3}
    assert [order[r] for r in study.roles] == sorted(order[r] for r in study.roles)


def test_small_deck_roles_and_units():
    """The small test deck as documented in its header: solve-for thrust bias, dynamic
    consider mu[sun], measurement consider Goldstone's radius, C_R ignored (gencov)."""
    study = build_study(load_team_deck(SMALL))
    assert study.labels == ["thrust_scale", "bias_in_rad", "mu[sun]", "station_radius_km[goldstone]", "cr"]
    assert study.roles == ["solve_for", "solve_for", "dynamic_consider", "measurement_consider", "ignore"]
    assert list(study.dynamic) == [True, True, True, False, True]
    assert study.units[2] == "km^3/s^2" and study.units[3] == "km"
    # Doppler 1 mm/s assumed, 2 mm/s true (gencov.measurement_sigma); range 2 m both (km, km/s)
    assert [o.sigma for o in study.observations] == pytest.approx([1e-6, 1e-6, 2e-3], rel=1e-15)
    assert list(study.true_sigma) == pytest.approx([2e-6, 2e-6, 2e-3], rel=1e-15)
    # the filter does not know its ignore parameter; the true a priori does (0.1)
    assert study.P0_assumed[-1, -1] == 0.0 and study.P0_true[-1, -1] == pytest.approx(0.01, rel=1e-15)


# ----------------------------------------------------------------------------- refusals
def test_unknown_field():
    msg = refusal(small_text().replace("[filter]\n", "[filter]\ntypo = 1\n"))
    assert "filter.typo = 1: unknown field (expected one of: type, user_gain, square_root" in msg


def test_missing_a_priori():
    text = re.sub(r"\[a_priori\]\n(.+\n)+", "", small_text())
    assert "[a_priori]" not in text
    msg = refusal(text)
    assert "a_priori: required when errcon.analysis = true" in msg


def test_a_priori_not_needed_without_analysis():
    """The rule behind the refusal above: a deck that only builds an STM file needs no a priori."""
    without = re.sub(r"\[a_priori\]\n(.+\n)+", "", small_text())
    text = without.replace("[ertraj]", "[errcon]\nanalysis = false\n\n[ertraj]")
    assert text != without and "[a_priori]" not in text
    deck = parse_team_deck(text, SRC)
    assert deck.errcon.analysis is False and deck.a_priori is None
    # the same deck with analysis on is refused for the missing a priori (the rule's other side)
    on = text.replace("analysis = false", "analysis = true")
    assert "a_priori: required when errcon.analysis = true" in refusal(on)


def test_a_priori_exactly_one_of_sigma_and_rss():
    msg = refusal(small_text().replace("mass_sigma_kg = 0.5", "mass_sigma_kg = 0.5\nposition_rss_km = 10.0"))
    assert "give exactly one of position_sigma_km, position_rss_km" in msg


@pytest.mark.parametrize(
    "label, expected",
    [
        # an unknown body: the message lists the bodies of this trajectory's force model
        ("mu[pluto]", "body 'pluto' is not in the force model ('sun', 'earth')"),
        # an unknown name: the message lists the catalogue
        ("frobnicate", "unknown parameter 'frobnicate'; known: ['area_m2', 'bias_in_rad'"),
        # an unknown station in a measurement label: the stations that exist
        ("station_radius_km[parkes]", "station 'parkes' is not one of canberra, goldstone, madrid"),
    ],
)
def test_unknown_parameter_label(label, expected):
    msg = refusal(small_text().replace('label = "mu[sun]"', f'label = "{label}"'), build=True)
    assert f'parameter[2].label = "{label}"' in msg and expected in msg


def test_unknown_gencov_ignore_label():
    msg = refusal(small_text().replace('label = "cr"', 'label = "crr"'), build=True)
    assert 'gencov.parameter[0].label = "crr": unknown parameter' in msg


def test_repeated_label():
    msg = refusal(small_text().replace('label = "bias_in_rad"', 'label = "thrust_scale"'))
    assert 'parameter[1].label = "thrust_scale": repeats parameter[0]' in msg


@pytest.mark.parametrize(
    "kind, stations, expected",
    [
        ("range3", '["goldstone"]', 'tracking[0].stations = ["goldstone"]: type "range3" needs 2 stations'),
        ("doppler2", '["goldstone", "madrid"]', 'type "doppler2" needs 1 station'),
        ("doppler3", '["madrid", "madrid"]', "the two stations must differ"),
    ],
)
def test_station_count_for_tracking_type(kind, stations, expected):
    text = small_text().replace(
        'type = "doppler2"\nstations = ["goldstone"]', f'type = "{kind}"\nstations = {stations}', 1
    )
    assert kind in text
    assert expected in refusal(text)


def test_unknown_station():
    msg = refusal(small_text().replace('stations = ["madrid"]', 'stations = ["parkes"]'))
    assert 'tracking[1].stations[0] = "parkes": unknown station (expected one of: canberra, goldstone, madrid)' in msg


def test_added_station_is_known():
    """A [[station]] table makes a name known (the reference of the refusal above)."""
    text = small_text().replace('stations = ["madrid"]', 'stations = ["parkes"]') + (
        '\n[[station]]\nname = "parkes"\nradius_km = 6372.0\nlatitude_deg = -33.0\nlongitude_deg = 148.3\n'
    )
    study = build_study(parse_team_deck(text, SRC))
    assert "parkes" in study.stations and study.observations[1].stations == ("parkes",)


def test_gencov_parameter_not_in_study():
    msg = refusal(small_text().replace('role = "ignore"', ""))
    assert (
        'gencov.parameter[0].label = "cr": is not a study parameter; add role = "ignore" to make it an ignore parameter'
    ) in msg


def test_gencov_ignore_of_a_study_parameter():
    msg = refusal(small_text().replace('label = "cr"', 'label = "mu[sun]"'))
    assert 'gencov.parameter[0].role = "ignore": mu[sun] is already a study parameter (parameter[2])' in msg


def test_user_filter_without_gain():
    msg = refusal(small_text().replace('type = "kalman_schmidt"', 'type = "user"'))
    assert 'filter.user_gain: required for type = "user" (a "module:function" name)' in msg


def test_user_gain_that_cannot_be_imported():
    text = small_text().replace('type = "kalman_schmidt"', 'type = "user"\nuser_gain = "tests.team.nope:gain"')
    msg = refusal(text, build=True)
    assert 'filter.user_gain = "tests.team.nope:gain": cannot import it' in msg


def test_missing_trajectory_deck():
    msg = refusal(small_text().replace("team_small_traj.toml", "nope.toml"), build=True)
    assert 'ertraj.deck = "nope.toml": no such trajectory deck' in msg


def test_missing_file():
    with pytest.raises(DeckError, match=r"^nowhere/x\.toml: no such file$"):
        load_team_deck("nowhere/x.toml")


# ----------------------------------------------------------------------------- through the CLI
@pytest.mark.parametrize(
    "name, expected",
    [
        (
            "team_bad_station.toml",
            ('tracking[0].stations[0] = "parkes": unknown station (expected one of: canberra, goldstone, madrid)'),
        ),
        (
            "team_bad_label.toml",
            (
                "parameter[1].label = \"mu[pluto]\": unknown parameter: parameter 'mu[pluto]': "
                "body 'pluto' is not in the force model ('sun', 'earth')"
            ),
        ),
    ],
    ids=["station", "label"],
)
def test_cli_refuses_bad_deck(name, expected):
    path = DATA / name
    res = CliRunner().invoke(main, ["run", str(path), "--quiet"])
    assert res.exit_code == 2, res.output
    assert res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"fracas: error: {path}: ") and expected in lines[0], res.stderr
    assert "Traceback" not in res.output
    assert isinstance(res.exception, SystemExit)  # the CLI's own exit, not an escaped exception


@pytest.mark.parametrize(
    "predict_to, expected",
    [
        (99.0, "event[1].predict_to_days = 99.0: must be within the trajectory (<= 6 d"),
        (2.0, "event[1].predict_to_days = 2.0: must be after every time of the prediction event"),
    ],
)
def test_prediction_target_checked(predict_to, expected):
    """A prediction beyond the trajectory (no ephemeris or thrust plan there) or before its
    own event time is refused in one line naming the field."""
    text = small_text().replace("predict_to_days = 5.0", f"predict_to_days = {predict_to}")
    assert expected in refusal(text, build=True)
