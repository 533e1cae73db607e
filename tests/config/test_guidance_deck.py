"""[[guidance]], [control] and [budget] in a TEAM deck: each mistake is one line naming the
deck, the field and what was expected (the deck schema, fracas validate and the build)."""

from __future__ import annotations

from pathlib import Path

import pytest

from fracas.config.team import parse_team_deck
from fracas.errors import DeckError
from fracas.modes import validate_path

DATA = Path(__file__).resolve().parents[1] / "data"

BASE = f"""
mode = "team"
[ertraj]
deck = "{(DATA / "team_small_traj.toml").as_posix()}"
[filter]
stop_days = 4.0
[a_priori]
position_sigma_km = [100.0, 100.0, 100.0]
velocity_sigma_km_s = [0.001, 0.001, 0.001]
"""


def _deck(extra: str):
    return parse_team_deck(BASE + extra, "g.toml")


def test_a_valid_guidance_deck():
    d = _deck(
        """
[[guidance]]
name = "tcm1"
type = "impulsive"
time_days = 1.0
targets = ["b_dot_t", "b_dot_r"]
[[guidance]]
name = "lt"
type = "primary"
time_days = 3.5
arc = 1
targets = ["x", "y", "z"]
[[guidance]]
name = "ltv"
type = "vernier"
time_days = 3.8
arc = 1
targets = ["x", "y", "z"]
"""
    )
    assert [g.name for g in d.guidance] == ["tcm1", "lt", "ltv"]
    assert d.errcon.guidance_model == "report" and d.budget.enabled


@pytest.mark.parametrize(
    "extra, field, words",
    [
        (
            'name = "a"\ntype = "impulsive"\ntime_days = 1.0\ntargets = ["b_dot_q"]',
            "guidance[0].targets[0]",
            "unknown target",
        ),
        ('name = "a"\ntype = "impulsive"\ntime_days = 1.0\ntargets = []', "guidance[0].targets", "at least one"),
        ('name = "a"\ntype = "primary"\ntime_days = 1.0\ntargets = ["x"]', "guidance[0].arc", "required"),
        (
            'name = "a"\ntype = "primary"\narc = 0\ntime_days = 1.0\ntargets = ["x"]\ncontrols = ["throttle"]',
            "guidance[0].controls[0]",
            "unknown control",
        ),
        (
            'name = "a"\ntype = "vernier"\narc = 0\ntime_days = 1.0\ntargets = ["x"]',
            "guidance[0].type",
            "earlier primary",
        ),
        (
            'name = "a"\ntype = "impulsive"\ntime_days = 1.0\ntargets = ["x", "y"]\ntolerances = [1.0]',
            "guidance[0].tolerances",
            "expected 2",
        ),
        (
            'name = "a"\ntype = "impulsive"\ntime_days = 1.0\ntargets = ["x"]\nweights = [1.0, 2.0]',
            "guidance[0].weights",
            "expected 3",
        ),
        (
            'name = "a"\ntype = "impulsive"\ntime_days = 9.0\ntargets = ["x"]',
            "guidance[0].time_days",
            "outside the study",
        ),
    ],
)
def test_guidance_mistakes_name_the_field(extra, field, words):
    with pytest.raises(DeckError) as e:
        _deck("[[guidance]]\n" + extra + "\n")
    msg = str(e.value)
    assert "g.toml" in msg and field in msg and words in msg and "\n" not in msg


GOOD_TAIL = 'time_days = 1.0\ntargets = ["x"]\n'


def test_pdot_with_guidance_refused():
    with pytest.raises(DeckError, match=r"errcon.propagation.*phi"):
        _deck('[errcon]\npropagation = "pdot"\n[[guidance]]\nname = "a"\ntype = "impulsive"\n' + GOOD_TAIL)


def test_validate_checks_guidance_against_the_trajectory(tmp_path):
    """fracas validate (no JAX, no build): the arc must exist and hold the event; t_on only
    at the arc's start; the target time within the trajectory."""
    p = tmp_path / "g.toml"
    p.write_text(
        BASE
        + """
[[guidance]]
name = "a"
type = "primary"
time_days = 1.0
arc = 5
targets = ["x"]
[[guidance]]
name = "b"
type = "primary"
time_days = 3.6
arc = 1
controls = ["t_on"]
targets = ["x"]
target_time_days = 60.0
"""
    )
    problems = validate_path(p)
    text = "\n".join(problems)
    assert "guidance[0].arc = 5" in text
    assert "guidance[1].controls" in text and "t_on" in text
    assert "guidance[1].target_time_days = 60" in text
