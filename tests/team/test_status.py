"""Run status instead of exceptions in the TEAM core (fracas.status.RunStatus).

Reference: the integrator's own status and the schedule: a reference integration that
stops before the study's last time returns OUTSIDE_TRAJECTORY and the schedule time where
it stopped, without raising; the pipeline turns that into the one-line error users see.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from fracas.build.team import build_study
from fracas.config.team import load_team_deck
from fracas.status import RunStatus
from fracas.team.reference import integrate_reference

SMALL = Path(__file__).resolve().parents[1] / "data" / "team_small.toml"


def _stopped_study(max_steps: int):
    study = build_study(load_team_deck(SMALL))
    m = study.problem.model
    model = dataclasses.replace(m, integrator=dataclasses.replace(m.integrator, max_steps=max_steps))
    return dataclasses.replace(study, problem=dataclasses.replace(study.problem, model=model))


def test_reference_off_the_trajectory_returns_a_status():
    """max_steps = 40 stops the 4-day reference early: status OUTSIDE_TRAJECTORY, the first
    schedule time not reached, the integrator's MAX_STEPS; the matrices before it finite."""
    study = _stopped_study(40)
    ref = integrate_reference(study)
    assert ref.status == RunStatus.OUTSIDE_TRAJECTORY
    assert ref.integrator_status == RunStatus.MAX_STEPS
    k = int(np.searchsorted(study.schedule.times_s, ref.failed_at_s))
    assert 0 < k < study.schedule.n and study.schedule.times_s[k] == ref.failed_at_s
    assert np.all(np.isfinite(ref.phi[:k])) and not np.all(np.isfinite(ref.phi[k:]))


def test_healthy_reference_is_ok():
    ref = integrate_reference(build_study(load_team_deck(SMALL)))
    assert ref.status == RunStatus.OK and np.isnan(ref.failed_at_s)


def test_pipeline_turns_the_status_into_one_line(monkeypatch):
    """The edge raises NumericalError naming the trajectory deck and the time."""
    import fracas.modes.team as team_mode
    from fracas.errors import NumericalError

    real = team_mode.load_team

    def stopped(deck):
        case = real(deck)
        st = _stopped_study(40)
        return dataclasses.replace(case, study=st)

    monkeypatch.setattr(team_mode, "load_team", stopped)
    with pytest.raises(NumericalError, match=r"team_small_traj\.toml: the reference trajectory stopped before t = "):
        team_mode.run_team(SMALL, output=None)


def test_failed_prediction_still_writes_the_results_file(monkeypatch, tmp_path):
    """A prediction that reports OUTSIDE_TRAJECTORY (patched in: the deck validators refuse
    a target beyond the trajectory) does not cost the run: the results file is written,
    records the prediction's status and the run's, and the edge's one-line error says so."""
    import fracas.team.result as result
    from fracas.errors import NumericalError
    from fracas.io.team_results import read_team_results
    from fracas.modes.team import run_team

    real = result.predictions

    def failing(res):
        out, status = real(res)
        return out, {k: [int(RunStatus.OUTSIDE_TRAJECTORY)] * len(v) for k, v in status.items()}

    monkeypatch.setattr(result, "predictions", failing)
    out = tmp_path / "pred.h5"
    with pytest.raises(NumericalError, match=rf"prediction from .* results written to {out}"):
        run_team(SMALL, output=out)
    r = read_team_results(out)
    assert [p["status"] for p in r["predictions"]] == [int(RunStatus.OUTSIDE_TRAJECTORY)]
    assert int(r["attrs"]["status"]) == RunStatus.OUTSIDE_TRAJECTORY
