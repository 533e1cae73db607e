"""Non-finite covariances inside a TEAM run (issue 8 B): the run reports them per event
instead of raising, and the results file is still written with what is valid.

The small study (tests/data/team_small.toml) with one a-priori parameter variance set to
1e300^2 = inf in memory (the deck validators may refuse such a sigma, so it is injected into
the built Study): the covariances that the infinite variance reaches become non-finite.
The reference for the flags is ``np.isfinite`` of the stored P_plus; the healthy eigenvector
events must equal :func:`eigen_summary` of the stored matrix.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fracas.io.team_results import read_team_results, write_team_results
from fracas.status import RunStatus
from fracas.team.eigen import eigen_summary
from fracas.team.engine import run_study
from fracas.team.reference import integrate_reference
from fracas.team.result import event_status, team_product
from tests.team.test_team_engine import small_dict, study_of


@pytest.fixture(scope="module")
def broken(tmp_path_factory):
    study = study_of(small_dict())
    i = study.nx  # the first parameter (thrust_scale, solve-for)
    P0 = study.P0_assumed.copy()
    P0[i, i] = np.inf  # what a sigma of 1e300 squares to
    study = dataclasses.replace(study, P0_assumed=P0)
    ref = integrate_reference(study)
    res = run_study(study, ref)
    prod = team_product(res, reference_source="integrated")
    path = tmp_path_factory.mktemp("nonfinite") / "broken.h5"
    write_team_results(path, prod)  # must not raise (it used to: LinAlgError in eigen_summary)
    return res, prod, path


def test_file_written_and_status_says_so(broken):
    res, prod, path = broken
    assert path.exists()
    r = read_team_results(path)
    assert int(r["attrs"]["status"]) == RunStatus.NONFINITE_COVARIANCE == res.status
    assert r["attrs"]["status_text"] == RunStatus.NONFINITE_COVARIANCE.text


def test_event_status_flags_exactly_the_nonfinite_events(broken):
    _, prod, path = broken
    r = read_team_results(path)
    for which in ("assumed", "true"):
        if which not in r:
            continue
        P = r[which]["P_plus"]
        bad = ~np.all(np.isfinite(P.reshape(len(P), -1)), axis=1)
        st = r[which]["event_status"]
        assert st.shape == (len(r["times_s"]),)
        np.testing.assert_array_equal(st == RunStatus.NONFINITE_COVARIANCE, bad)
        assert set(np.unique(st)) <= {0, int(RunStatus.NOT_POSITIVE_DEFINITE), int(RunStatus.NONFINITE_COVARIANCE)}
        np.testing.assert_array_equal(st, getattr(prod, which).event_status)
    assert np.any(r["assumed"]["event_status"] == RunStatus.NONFINITE_COVARIANCE)  # the premise


def test_eigen_events_nan_where_bad_and_exact_where_healthy(broken):
    _, _, path = broken
    r = read_team_results(path)
    A = r["assumed"]
    eg = A["eigenvector_events"]
    n_bad = n_good = 0
    for i, k in enumerate(eg["index"]):
        P = A["P_plus"][k]
        if A["event_status"][k] == RunStatus.NONFINITE_COVARIANCE:
            for blk, key in ((slice(0, 3), "position"), (slice(3, 6), "velocity")):
                if not np.all(np.isfinite(P[blk, blk])):
                    assert np.all(np.isnan(eg[f"{key}_eigenvalues"][i]))
                    assert np.all(np.isnan(eg[f"{key}_eigenvectors"][i]))
            n_bad += 1
        else:
            e = eigen_summary(P)
            np.testing.assert_array_equal(eg["position_eigenvalues"][i], e.pos_eigval)
            np.testing.assert_array_equal(eg["velocity_eigenvectors"][i], e.vel_eigvec)
            np.testing.assert_array_equal(eg["correlations"][i], e.corr)
            n_good += 1
    assert n_bad >= 1


def test_eigen_summary_of_nonfinite_matrix_does_not_raise():
    P = np.eye(7)
    P[0, 0] = np.inf
    P[4, 5] = P[5, 4] = np.nan
    e = eigen_summary(P)
    assert np.all(np.isnan(e.pos_eigval)) and np.all(np.isnan(e.vel_eigvec))
    P = np.diag([1.0, 2, 3, 4, 5, 6, 7])
    P[0, 0] = np.nan
    e = eigen_summary(P)
    assert np.all(np.isnan(e.pos_eigval)) and np.allclose(e.vel_eigval, [4, 5, 6])


def test_event_status_kernel():
    P = np.stack([np.eye(2), np.eye(2), np.full((2, 2), np.nan), -np.eye(2)])
    st = event_status(P, [(3, "measurement", "assumed", -1.0), (1, "measurement", "true", -1.0)], "assumed")
    np.testing.assert_array_equal(st, [0, 0, 7, 6])


def test_report_names_first_bad_event(broken):
    from rich.console import Console

    from fracas.report.team import print_team

    _, _, path = broken
    r = read_team_results(path)
    con = Console(width=80, record=True)
    print_team(r, con, verbosity="normal")
    text = con.export_text()
    st = r["assumed"]["event_status"]
    k = int(np.nonzero(st)[0][0])
    ev = r["event_types"][k]
    line = next(ln for ln in text.splitlines() if "assumed covariance" in ln and "first at t =" in ln)
    assert f"{r['times_s'][k] / 86400.0:.4f} d" in line and ev.split("+")[0] in line
