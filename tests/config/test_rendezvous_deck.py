"""The rendezvous deck (fracas.config.rendezvous): what it accepts and the one-line errors
(file, field, what was expected) for what it refuses.  References: the deck documentation
(the module docstring) and the house rule of one message per problem, exit 2, no traceback."""

from pathlib import Path

import pytest
from click.testing import CliRunner

from fracas.cli import main
from fracas.config.rendezvous import parse_rendezvous_deck, rendezvous_problems
from fracas.errors import DeckError

SMALL = Path("tests/data/rendezvous_small.toml")


def _text():
    return SMALL.read_text(encoding="utf-8")


def _parse(text):
    return parse_rendezvous_deck(text, str(SMALL))


def test_small_deck_validates_and_converts_units():
    d = _parse(_text())
    assert d.roles == ["solve_for", "ignore"]
    assert d.km_per_unit == pytest.approx(0.3048e-3, rel=1e-15)
    assert rendezvous_problems(d) == []


@pytest.mark.parametrize(
    "old,new,field",
    [
        ('roles = ["solve_for", "ignore"]', 'roles = ["solve_for", "estimate"]', "target.roles"),
        ("[noise.los_theta]\nsigma = 1.0", "", "noise.los_theta"),
        ('measurement = "range"', 'measurement = "doppler"', "bias[0].measurement"),
        ("stop_min = 40.0", "stop_min = 10.0", "tracking[0].stop_min"),
        ("arrival_min = 85.0", "arrival_min = 40.0", "maneuver[0].arrival_min"),
        ("position_sigma = [3000.0, 4000.0, 3400.0]", "position_sigma = [3000.0, 4000.0]", "chaser.position_sigma"),
        ('units = "ft"', 'units = "furlong"', "units"),
        ("[[reset]]\ntime_min = 30.0", '[[reset]]\nroles = ["consider"]\ntime_min = 30.0', "reset[0].roles"),
    ],
)
def test_bad_fields_give_one_line_naming_the_field(old, new, field):
    text = _text()
    assert old in text
    with pytest.raises(DeckError) as exc:
        _parse(text.replace(old, new))
    msg = str(exc.value)
    assert "\n" not in msg and str(SMALL) in msg and field in msg, msg


def test_missing_trajectory_deck_and_short_trajectory_are_reported(tmp_path):
    text = _text().replace("../../namelists/apollo12_csm_traj.toml", "nowhere.toml")
    d = _parse(text)
    probs = rendezvous_problems(d)
    assert len(probs) == 1 and "target.trajectory" in probs[0] and "nowhere.toml" in probs[0]
    d = _parse(_text().replace("arrival_min = 85.0", "arrival_min = 500.0"))
    probs = rendezvous_problems(d)
    assert probs and all("lasts 180.0 min" in p for p in probs)


def test_cli_run_bad_deck_exits_2_without_traceback(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(_text().replace('units = "ft"', 'units = "furlong"'), encoding="utf-8")
    r = CliRunner().invoke(main, ["run", str(bad)])
    assert r.exit_code == 2
    assert "Traceback" not in r.output and "units" in r.output
    r = CliRunner().invoke(main, ["validate", str(SMALL)])
    assert r.exit_code == 0 and "(rendezvous)" in r.output
