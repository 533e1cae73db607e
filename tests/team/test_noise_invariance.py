"""Diagnostic events must not change the answer (issue 9 item 8; fracas.team.transitions).

PHI mode's fixed-cell thrust-noise model (``errcon.process_noise = "grid"``) computes DYNO's
Q̃ on fixed noise cells and maps it to the event times, so adding eigenvector and
prediction events leaves every covariance at the common schedule times unchanged up to
integration round-off.  FRACAS's per-interval DYNO (``"interval"``, still the default) does
not: it is the negative control.  Also PDOT's step accuracy and 4th-order convergence.

Measured on tests/data/team_small.toml with eigenvector events at 0.37 and 1.91 d and a
prediction event at 2.23 d: grid 3.5e-12 (scaled, Pa+, Pa-, Pt+), interval 3.0e-3.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from fracas.team.engine import run_study
from fracas.team.reference import integrate_reference
from tests.team.test_team_engine import pos_rss, scaled_diff, small_dict, study_of

EXTRA_EVENTS = [
    {"type": "eigenvector", "times_days": [0.37, 1.91]},
    {"type": "prediction", "times_days": [2.23], "predict_to_days": 4.5},
]


def _run(d: dict):
    study = study_of(d)
    return run_study(study, integrate_reference(study))


def _pair(mode: str):
    d = small_dict()
    d["errcon"] = {"process_noise": mode}
    e = copy.deepcopy(d)
    e["event"] = e["event"] + copy.deepcopy(EXTRA_EVENTS)
    return _run(d), _run(e)


def _common(a, b):
    ia = [i for i, t in enumerate(a.times_s) if np.min(np.abs(b.times_s - t)) < 1e-6]
    ib = [int(np.argmin(np.abs(b.times_s - a.times_s[i]))) for i in ia]
    return ia, ib


def _max_diff(a, b) -> float:
    ia, ib = _common(a, b)
    assert len(ia) == len(a.times_s) and len(b.times_s) == len(a.times_s) + 3
    pred = [0.0]
    for k, got in a.predictions.items():  # the deck's own prediction (3 d to 5 d) is in both
        other = {t: (Pa, Pt) for t, Pa, Pt in b.predictions[ib[ia.index(k)]]}
        for t, Pa, Pt in got:
            pred += [scaled_diff(other[t][0][None], Pa[None]), scaled_diff(other[t][1][None], Pt[None])]
    assert len(pred) > 1
    return max(
        max(pred),
        scaled_diff(b.Pa_plus[ib], a.Pa_plus[ia]),
        scaled_diff(b.Pa_minus[ib], a.Pa_minus[ia]),
        scaled_diff(b.Pt_plus[ib], a.Pt_plus[ia]),
        scaled_diff(b.Pt_minus[ib], a.Pt_minus[ia]),
    )


@pytest.fixture(scope="module")
def grid_pair():
    return _pair("grid")


def test_grid_noise_is_invariant_to_events(grid_pair):
    """Every covariance (assumed and true, before and after each update) at the common
    schedule times is unchanged by the extra events: measured 3.5e-12 scaled (integration
    round-off at the extra output times); tolerance 1e-10."""
    a, b = grid_pair
    assert a.study.noise_model == "grid" and study_of(small_dict()).noise_model == "interval"  # FRACAS default
    assert a.study.has_noise and np.any(a.Q_assumed[1:] != 0)
    e = _max_diff(a, b)
    print(f"grid: max scaled difference with/without extra events {e:.2e}")
    assert e < 1e-10


def test_interval_noise_changes_with_events():
    """Negative control: FRACAS's per-interval DYNO changes the covariances when events are
    added (measured 3.0e-3 scaled; the issue's ~1.5e-3 in sigma)."""
    a, b = _pair("interval")
    e = _max_diff(a, b)
    print(f"interval: max scaled difference with/without extra events {e:.2e}")
    assert e > 1e-6


def test_grid_close_to_interval_and_pdot(grid_pair):
    """The grid model is the same DYNO on other cells: its position RSS stays within 10 % of
    the per-interval one, and PDOT/grid is of the same order as PDOT/interval
    (tests/team/test_team_engine.py::test_pdot_and_phi_position_sigmas bands)."""
    a, _ = grid_pair
    d = small_dict()
    d["errcon"] = {"process_noise": "interval"}
    iv = run_study(study_of(d), a.ref)
    r = pos_rss(a.Pa_plus) / pos_rss(iv.Pa_plus)
    print(f"grid/interval position RSS: {r.min():.4f}-{r.max():.4f}")
    assert np.all(np.abs(r - 1) < 0.1)
    d = small_dict()
    d["errcon"] = {"propagation": "pdot"}
    pd = run_study(study_of(d), a.ref)
    n = a.study.layout.n
    q = pos_rss(pd.Pa_plus[:, :n, :n]) / pos_rss(a.Pa_plus)
    print(f"PDOT/grid position RSS: final {q[-1]:.4f}, range {q.min():.3f}-{q.max():.3f}")
    assert 0.8 < q[-1] < 1.25 and 0.5 < q.min() and q.max() < 2.0


def test_pdot_step_accuracy_and_order():
    """PDOT's default step (2.4 h) against a 0.15 h reference: measured max relative sigma
    error 1.0e-6 (4.8 h: 1.7e-5, 1.2 h: 6.1e-8), i.e. 4th order (ratio 16.8 from 4.8 to
    2.4 h).  Asserted: default < 1e-5 (the stated accuracy, fracas.config.team.ErTraj) and
    an observed order above 3.5 between 4.8 and 2.4 h."""
    d0 = small_dict()
    del d0["event"][1]
    study = study_of(d0)
    ref = integrate_reference(study)
    n = study.layout.n
    assert study.pdot_step_s == 2.4 * 3600.0

    def sig(h):
        d = copy.deepcopy(d0)
        d["errcon"] = {"propagation": "pdot"}
        d["ertraj"]["pdot_step_hours"] = h
        r = run_study(study_of(d), ref)
        return np.sqrt(np.einsum("kii->ki", r.Pa_plus[:, :n, :n]))

    s_ref = sig(0.15)
    m = s_ref > 0
    err = {h: float(np.max(np.abs(sig(h)[m] / s_ref[m] - 1))) for h in (4.8, 2.4)}
    print("PDOT max relative sigma error:", {h: f"{e:.2e}" for h, e in err.items()})
    assert err[2.4] < 1e-5
    assert np.log2(err[4.8] / err[2.4]) > 3.5
