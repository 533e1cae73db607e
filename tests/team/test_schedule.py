"""The TEAM event schedule (FRACAS SCHED): merging of tracking, user events, thrust switches
and punch times; the order of events at one time; range end points; start/stop clipping;
measurement counts of the small study against a count by hand.

References are hand-written lists from the rules in fracas/team/schedule.py's docstring
(order at one time: thrust switch, propagation, measurement, eigenvector, prediction,
punch, final; times merged on a 1 ms grid) and the small deck's tracking table.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fracas.build.team import build_case, build_study, stm_file_times
from fracas.config.team import load_team_deck, parse_team_deck
from fracas.team.schedule import build_schedule, merge_times, range_times

DATA = Path(__file__).resolve().parents[1] / "data"
SMALL = DATA / "team_small.toml"
H = 3600.0
DAY = 86400.0


# ----------------------------------------------------------------------------- range_times
@pytest.mark.parametrize(
    "start, stop, step, expected",
    [
        (0.0, DAY, 4 * H, [k * 4 * H for k in range(7)]),  # the stop point is on the grid: kept
        (0.0, 0.3, 0.1, [0.0, 0.1, 0.2, 0.3]),  # 0.3 / 0.1 = 2.9999999999999996: kept
        (0.0, 1.0, 0.3, [0.0, 0.3, 0.6, 0.9]),  # off the grid: not reached
        (2 * H, 2 * H, H, [2 * H]),  # a single point
        (0.0, 3 * DAY, DAY, [0.0, DAY, 2 * DAY, 3 * DAY]),
    ],
)
def test_range_times(start, stop, step, expected):
    # reference: the hand list; equal to rounding of start + k step (1 ulp of the largest)
    np.testing.assert_allclose(range_times(start, stop, step), expected, rtol=0, atol=1e-9 * max(1.0, stop))


def test_range_times_does_not_overshoot():
    """The guard keeps a stop point within rounding, never one a whole step away."""
    t = range_times(0.0, 10.0 * H - 1.0, H)  # 1 s short of the 10th hour
    assert t[-1] == 9 * H and len(t) == 10


# ----------------------------------------------------------------------------- merging
def test_merge_times_on_one_millisecond_grid():
    t = merge_times([0.0, 3600.0], [3600.0004, 3600.002], np.array([7200.0]), [])
    # 3600.0004 rounds onto 3600.000; 3600.002 is 2 ms away: a time of its own
    np.testing.assert_allclose(t, [0.0, 3600.0, 3600.002, 7200.0], rtol=0, atol=1e-9)


def test_build_schedule_merges_every_source():
    """Two tracking entries, an eigenvector event, a thrust switch and a punch time over 10 h."""
    sched = build_schedule(
        0.0,
        10 * H,
        [np.array([0.0, 4 * H, 8 * H]), np.array([0.0, 8 * H])],
        [("eigenvector", np.array([4 * H]), None), ("prediction", np.array([9 * H]), 20 * H)],
        [(6 * H, "thrust_off")],
        np.array([8 * H]),
    )
    np.testing.assert_array_equal(sched.times_s, [0.0, 4 * H, 6 * H, 8 * H, 9 * H, 10 * H])
    assert sched.events == [
        ["initial", "measurement"],
        ["measurement", "eigenvector"],
        ["thrust_off"],
        ["measurement", "punch"],
        ["prediction"],
        ["final"],
    ]
    assert sched.tracking == [[0, 1], [0], [], [0, 1], [], []]
    assert sched.predict_to_s == {4: [20 * H]}
    assert sched.count("measurement") == 3 and sched.primary_type(1) == "measurement"
    assert sched.primary_type(2) == "thrust_off" and sched.primary_type(5) == "final"


def test_order_of_events_at_one_time():
    """Every kind at t = 5 h (the stop too): processed in the documented order."""
    t = 5 * H
    sched = build_schedule(
        0.0,
        t,
        [np.array([t])],
        [
            ("prediction", np.array([t]), 9 * H),
            ("eigenvector", np.array([t]), None),
            ("propagation", np.array([t]), None),
        ],
        [(t, "thrust_on")],
        np.array([t]),
    )
    assert sched.events[-1] == [
        "thrust_on",
        "propagation",
        "measurement",
        "eigenvector",
        "prediction",
        "punch",
        "final",
    ]
    assert sched.events[0] == ["initial"] and sched.n == 2


def test_switch_off_and_on_at_one_time():
    sched = build_schedule(0.0, H, [], [], [(0.5 * H, "thrust_on"), (0.5 * H, "thrust_off")])
    assert sched.events[1] == ["thrust_on", "thrust_off"]


def test_start_stop_clipping():
    """Only [start, stop] counts: earlier and later tracking, events, switches, punches and
    predictions are dropped; the start is 'initial', the stop 'final' even where nothing else is."""
    sched = build_schedule(
        2 * H,
        7 * H,
        [range_times(0.0, 10 * H, H)],
        [("eigenvector", np.array([H, 3 * H, 8 * H]), None), ("prediction", np.array([H, 6 * H]), 12 * H)],
        [(0.0, "thrust_on"), (5 * H, "thrust_off"), (9 * H, "thrust_on")],
        np.array([1 * H, 8 * H]),
    )
    np.testing.assert_array_equal(sched.times_s, [k * H for k in range(2, 8)])
    assert sched.events[0] == ["initial", "measurement"]
    assert sched.events[1] == ["measurement", "eigenvector"]
    assert sched.events[3] == ["thrust_off", "measurement"]
    assert sched.events[-1] == ["measurement", "final"]
    assert sched.count("measurement") == 6 and sched.count("punch") == 0
    assert sched.predict_to_s == {4: [12 * H]}
    assert all("thrust_on" not in e for e in sched.events)


def test_empty_schedule_is_initial_and_final():
    sched = build_schedule(0.0, DAY, [], [], [])
    np.testing.assert_array_equal(sched.times_s, [0.0, DAY])
    assert sched.events == [["initial"], ["final"]]


# ----------------------------------------------------------------------------- the small study
@pytest.fixture(scope="module")
def small():
    return build_study(load_team_deck(SMALL))


def test_small_study_counts(small):
    """By hand from tests/data/team_small.toml: Doppler from 2 stations every 4 h over
    0-3 d = 2 x 19, range daily over 0-3 d = 4; 19 measurement times; plus the thrust-on at
    3.5 d and the final time at 4 d (the thrust-off at 2.5 d, the eigenvector at 1.5 d and the
    prediction at 3 d fall on Doppler times): 21 times."""
    sched = small.schedule
    assert sum(len(tr) for tr in sched.tracking) == 2 * 19 + 4
    assert [sum(j in tr for tr in sched.tracking) for j in range(3)] == [19, 19, 4]
    assert sched.count("measurement") == 19 and sched.n == 21
    np.testing.assert_allclose(
        sched.times_s, list(range_times(0.0, 3 * DAY, 4 * H)) + [3.5 * DAY, 4 * DAY], rtol=0, atol=1e-6
    )
    k = {
        e: [i for i, ev in enumerate(sched.events) if e in ev]
        for e in ("thrust_on", "thrust_off", "eigenvector", "prediction", "final")
    }
    assert [sched.times_s[i] / DAY for i in k["thrust_on"]] == [0.0, 3.5]
    assert [sched.times_s[i] / DAY for i in k["thrust_off"]] == [2.5]
    assert sched.events[k["thrust_off"][0]] == ["thrust_off", "measurement"]
    assert [sched.times_s[i] / DAY for i in k["eigenvector"]] == [1.5]
    assert sched.predict_to_s == {k["prediction"][0]: [5.0 * DAY]}
    assert k["final"] == [20] and sched.events[0] == ["initial", "thrust_on", "measurement"]
    assert sched.tracking[0] == [0, 1, 2] and sched.tracking[6] == [0, 1, 2] and sched.tracking[1] == [0, 1]


def test_small_study_clipped_by_filter_window():
    """filter.start_days = 0.5, stop_days = 2: Doppler at 12 h ... 48 h = 2 x 10, range at 1 and
    2 d; the thrust-on at 0 and the prediction at 3 d fall outside."""
    text = SMALL.read_text(encoding="utf-8").replace("stop_days = 4.0", "start_days = 0.5\nstop_days = 2.0")
    study = build_study(parse_team_deck(text, str(SMALL)))
    sched = study.schedule
    assert study.start_s == 0.5 * DAY and study.stop_s == 2.0 * DAY
    assert sum(len(tr) for tr in sched.tracking) == 2 * 10 + 2
    assert sched.n == 10 and sched.count("prediction") == 0 and sched.count("thrust_on") == 0
    assert sched.events[0] == ["initial", "measurement"] and sched.events[-1] == ["measurement", "final"]


def test_small_study_stm_file_times(small):
    """The STM file's times: the schedule, the 2 h grid ([stm] grid_hours) over the whole
    6-day trajectory, the switches: every schedule time is on the 2 h grid, so 73."""
    t = stm_file_times(build_case(load_team_deck(SMALL)))
    np.testing.assert_allclose(t, range_times(0.0, 6 * DAY, 2 * H), rtol=0, atol=1e-6)
    assert np.all(np.isin(np.round(small.schedule.times_s, 3), np.round(t, 3)))
