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


def test_true_sigma_replaces_a_proportional_filter_model():
    """A true_sigma means constant real-world noise even when the filter's is proportional
    (it used to keep the filter's fraction); true_sigma with true_fraction is refused."""
    from fracas.build.rendezvous import build_rendezvous

    text = _text().replace("[noise.range]\nfraction", "[noise.range]\ntrue_sigma = 50.0\nfraction", 1)
    study = build_rendezvous(_parse(text))
    assert list(study.noise_true[0]) == [50.0 * 0.3048e-3, 0.0, 0.0]
    assert study.noise_assumed[0][1] == pytest.approx(1 / 300, rel=1e-15)
    with pytest.raises(DeckError, match=r"noise\.range\.true_fraction"):
        _parse(text.replace("true_sigma = 50.0", "true_sigma = 50.0\ntrue_fraction = 0.01\ntrue_floor = 1.0"))


def test_non_psd_covariance_and_late_target_epoch_are_found_by_validate(tmp_path):
    """fracas validate (rendezvous_problems) sees a covariance that is not positive
    semidefinite (reported in the deck's units) and a target epoch after the chaser's."""
    cov = (
        "covariance = [\n"
        + ",\n".join(
            "  [" + ", ".join(("1.0e6" if i == j else ("2.0e6" if {i, j} == {0, 1} else "0.0")) for j in range(6)) + "]"
            for i in range(6)
        )
        + "\n]"
    )
    text = _text().replace("position_sigma = [3000.0, 4000.0, 3400.0]\nvelocity_sigma = [4.0, 4.2, 4.5]", cov, 1)
    probs = rendezvous_problems(_parse(text))
    assert len(probs) == 1 and "chaser.covariance: not positive semidefinite" in probs[0]
    assert "-1e+06 ft^2" in probs[0]
    traj = Path("namelists/apollo12_csm_traj.toml").read_text(encoding="utf-8")
    late = tmp_path / "late_csm.toml"
    late.write_text(traj.replace('iso = "1969-11-20T14:00:00"', 'iso = "1969-11-20T14:10:00"'), encoding="utf-8")
    probs = rendezvous_problems(_parse(_text().replace("../../namelists/apollo12_csm_traj.toml", str(late))))
    assert any("10.000 min after the chaser's" in p for p in probs)


def test_degenerate_mark_and_unreachable_intercept_are_one_line_errors(tmp_path):
    """A mark with both vehicles at one place, and an intercept the conic targeting cannot
    find, are refused naming tracking[i] and maneuver[j].arrival_min (they gave NaN
    covariances and a silently reported non-converged maneuver)."""
    from fracas.build.rendezvous import build_rendezvous

    same = _text().replace("../../namelists/apollo12_csm_traj.toml", "../../namelists/apollo12_lm_traj.toml")
    with pytest.raises(DeckError, match=r"tracking\[0\]: a mark at 18\.000 min has range 0 m"):
        build_rendezvous(_parse(same))
    far = _text().replace("time_min = 45.0\narrival_min = 85.0", "time_min = 40.0\narrival_min = 95.0")
    with pytest.raises(DeckError, match=r"maneuver\[0\]\.arrival_min = 95: no intercept"):
        build_rendezvous(_parse(far))
