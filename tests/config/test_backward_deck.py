"""Backward decks (final time before the epoch): what the schema accepts and the one-line
errors for what it refuses.  References: the deck text itself (times written by hand) and,
for the output times, the list an analyst would write out by hand."""

from __future__ import annotations

import numpy as np
import pytest

from fracas.build import output_times_s
from fracas.config.trajectory import parse_deck
from fracas.errors import DeckError

BASE = """
[epoch]
iso = "2030-01-01T00:00:00"
[initial_state]
centre = "earth"
[initial_state.cartesian]
r_km = [7000.0, 0.0, 0.0]
v_km_s = [0.0, 7.5, 1.0]
[spacecraft]
mass_kg = 1000.0
"""
PROP = """
[propulsion]
power_source = "nuclear"
power_kw = 10.0
efficiency = 0.65
exhaust_velocity_km_s = 30.0
"""


def _deck(stop: str, extra: str = ""):
    return parse_deck(BASE + extra + "\n[stop]\n" + stop + "\n", "d.toml")


def _error(stop: str, extra: str = "") -> str:
    with pytest.raises(DeckError) as info:
        _deck(stop, extra)
    msg = str(info.value)
    assert "\n" not in msg
    return msg


def test_negative_duration_is_backward():
    d = _deck("duration_days = -2.0")
    assert d.backward and d.duration_days == -2.0
    assert not _deck("duration_days = 2.0").backward


def test_final_epoch_before_the_epoch_is_backward():
    d = _deck('final_epoch = "2029-12-30T12:00:00"')
    assert d.backward
    assert d.duration_days == pytest.approx(-1.5, abs=1e-9)


def test_output_times_run_backward_with_step_magnitude():
    """step_days = 0.25 on a -1 d deck: 0, -0.25, ..., -1 by hand, plus a listed time."""
    d = _deck("duration_days = -1.0", "[output]\nstep_days = 0.25\ntimes_days = [-0.1]\n")
    want = np.array([0.0, -0.1, -0.25, -0.5, -0.75, -1.0]) * 86400.0
    np.testing.assert_allclose(output_times_s(d), want, rtol=0, atol=1e-9)
    assert np.all(np.diff(output_times_s(d)) < 0)
    # a negative step agreeing with the direction means the same
    d2 = _deck("duration_days = -1.0", "[output]\nstep_days = -0.25\ntimes_days = [-0.1]\n")
    np.testing.assert_array_equal(output_times_s(d2), output_times_s(d))


def test_arcs_and_impulses_inside_a_backward_span_accepted():
    extra = (
        PROP
        + "[[thrust_arc]]\nstart_days = -0.8\nstop_days = -0.5\n"
        + "[[thrust_arc]]\nstart_days = -0.3\nstop_days = 0.0\n"
        + "[[impulse]]\ntime_days = -0.9\ndv_km_s = [0.01, 0, 0]\n"
        + "[[impulse]]\ntime_days = -1.0\ndv_km_s = [0.01, 0, 0]\n".replace("-1.0", "-0.95")
    )
    with pytest.raises(DeckError):  # impulses must be listed in increasing time
        _deck("duration_days = -1.0", extra)
    extra = extra.replace("time_days = -0.9\n", "time_days = -0.99\n")
    d = _deck("duration_days = -1.0", extra)
    assert [a.start_days for a in d.thrust_arc] == [-0.8, -0.3]


BAD = {
    "zero duration": ("duration_days = 0.0", "", "d.toml: stop.duration_days = 0.0: must be nonzero"),
    "final epoch equal to the epoch": (
        'final_epoch = "2030-01-01T00:00:00"',
        "",
        'd.toml: stop.final_epoch = "2030-01-01T00:00:00": must differ from the epoch',
    ),
    "negative step on a forward deck": (
        "duration_days = 1.0",
        "[output]\nstep_days = -0.1\n",
        "d.toml: output.step_days = -0.1: must be > 0 on a forward propagation",
    ),
    "zero step": ("duration_days = -1.0", "[output]\nstep_days = 0.0\n", "d.toml: output.step_days = 0.0: must be"),
    "arc before the final time": (
        "duration_days = -1.0",
        PROP + "[[thrust_arc]]\nstart_days = -1.5\nstop_days = -0.5\n",
        "d.toml: thrust_arc[0].start_days = -1.5: must be >= the final time, -1 days",
    ),
    "arc after the epoch": (
        "duration_days = -1.0",
        PROP + "[[thrust_arc]]\nstart_days = -0.5\nstop_days = 0.5\n",
        "d.toml: thrust_arc[0].stop_days = 0.5: must be <= 0 (the epoch",
    ),
    "forward arc before the epoch": (
        "duration_days = 1.0",
        PROP + "[[thrust_arc]]\nstart_days = -0.5\nstop_days = 0.5\n",
        "d.toml: thrust_arc[0].start_days = -0.5: must be >= 0 (the epoch)",
    ),
    "impulse outside the span": (
        "duration_days = -1.0",
        "[[impulse]]\ntime_days = -2.0\ndv_km_s = [0.01, 0, 0]\n",
        "d.toml: impulse[0].time_days = -2.0: must be >= the final time, -1 days",
    ),
    "impulse at the epoch": (
        "duration_days = -1.0",
        "[[impulse]]\ntime_days = 0.0\ndv_km_s = [0.01, 0, 0]\n",
        "d.toml: impulse[0].time_days = 0.0: must be < 0 on a backward propagation",
    ),
    "output time after the epoch": (
        "duration_days = -1.0",
        "[output]\ntimes_days = [0.5]\n",
        "d.toml: output.times_days[0] = 0.5: must be <= 0 (the epoch",
    ),
    "closest approach": (
        'duration_days = -1.0\ncondition = "closest_approach"\nbody = "moon"',
        "",
        'd.toml: stop.condition = "closest_approach": not supported on a backward propagation',
    ),
    "soi entry": (
        'duration_days = -1.0\ncondition = "soi_entry"\nbody = "moon"',
        "",
        'd.toml: stop.condition = "soi_entry": not supported on a backward propagation',
    ),
    "primary change": (
        "duration_days = -1.0",
        "[forces]\nchange_primary_at_soi = true\n",
        "d.toml: forces.change_primary_at_soi = true: not supported on a backward propagation",
    ),
}


@pytest.mark.parametrize("case", BAD, ids=list(BAD))
def test_bad_backward_decks_one_line(case):
    stop, extra, start = BAD[case]
    assert _error(stop, extra).startswith(start)


def test_team_refuses_a_backward_trajectory(tmp_path):
    from fracas.build.team import trajectory_problem
    from fracas.config.team import load_team_deck
    from fracas.modes import validate_path

    (tmp_path / "traj.toml").write_text(BASE + "\n[stop]\nduration_days = -1.0\n")
    team = tmp_path / "team.toml"
    team.write_text('[ertraj]\ndeck = "traj.toml"\n[errcon]\nanalysis = false\n')
    deck = load_team_deck(team)
    with pytest.raises(DeckError) as info:
        trajectory_problem(deck, "team.toml")
    msg = str(info.value)
    want = "is a backward trajectory (final time before the epoch); TEAM needs a forward one"
    assert msg == f'team.toml: ertraj.deck = "traj.toml": {want}'
    problems = validate_path(team)  # fracas validate says the same, one line
    assert any(p.endswith(f'ertraj.deck = "traj.toml": {want}') for p in problems), problems
