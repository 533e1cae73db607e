"""The TEAM assumed-covariance reset event ([[event]] type = "reset": the UNF / Apollo W
reinitialization, digest unf-apollo.md A.6.1, C.1) on tests/data/team_small.toml.

References (independent of the scan): the definition (at the reset the filter's state block
is diag(sigma^2) with its correlations zeroed, and the true covariance is untouched); the
runs with and without the reset are identical before it (the same gains); after it, the
true covariance at the next marks is the Joseph update of the true covariance with the
Kalman-Schmidt gain recomputed in numpy from the reset filter's own covariance (1e-9
relative: a few hundred flops on matrices of condition ~1e8)."""

from pathlib import Path

import numpy as np
import pytest

from fracas.build.team import build_study
from fracas.config.team import parse_team_deck
from fracas.errors import DeckError
from fracas.team.engine import run_study
from fracas.team.reference import integrate_reference

DECK = Path("tests/data/team_small.toml")
RESET = (
    '[[event]]\ntype = "reset"\ntimes_days = [1.9]\nposition_sigma_km = [50.0, 50.0, 50.0]\n'
    "velocity_sigma_km_s = [0.0005, 0.0005, 0.0005]\n"
)
T_RESET = 1.9 * 86400.0


def _study(extra=""):
    text = DECK.read_text(encoding="utf-8")
    text = text.replace('[[event]]\ntype = "eigenvector"', extra + '[[event]]\ntype = "eigenvector"', 1)
    return build_study(parse_team_deck(text, str(DECK)))


@pytest.fixture(scope="module")
def runs():
    base, reset = _study(), _study(RESET)
    ref_b, ref_r = integrate_reference(base), integrate_reference(reset)
    return (base, run_study(base, ref_b)), (reset, ref_r, run_study(reset, ref_r))


@pytest.mark.slow  # its module fixture: ~22 s of a cold make test (issue 22)
def test_reset_sets_the_filter_state_block_and_leaves_the_truth(runs):
    (base, rb), (study, ref, rr) = runs
    times = study.schedule.times_s
    k = int(np.argmin(np.abs(times - T_RESET)))
    assert abs(times[k] - T_RESET) < 1e-3 and "reset" in study.schedule.events[k]
    Pa = rr.Pa_minus[k]
    assert np.array_equal(Pa[:6, :6], np.diag([50.0**2] * 3 + [0.0005**2] * 3))
    assert np.all(Pa[:6, 6:] == 0.0) and np.all(Pa[6:, :6] == 0.0)
    # the reset is a pure covariance event here (no marks at 1.9 d): the truth is untouched
    assert np.array_equal(rr.Pt_plus[k], rr.Pt_minus[k])
    # before the reset both runs carry the same covariances (same gains, same schedule up to it)
    tb = base.schedule.times_s
    for kb in range(len(tb)):
        if tb[kb] >= T_RESET:
            break
        assert np.allclose(rr.Pt_plus[kb], rb.Pt_plus[kb], rtol=1e-12, atol=0.0)
    # and after it they differ (the gains changed)
    assert not np.allclose(rr.Pt_plus[-1], rb.Pt_plus[-1], rtol=1e-6)


@pytest.mark.slow  # its module fixture: ~22 s of a cold make test (issue 22)
def test_true_covariance_after_reset_uses_the_reset_filters_gain(runs):
    _, (study, ref, rr) = runs
    meas = rr.meas
    times = study.schedule.times_s
    k0 = int(np.argmin(np.abs(times - T_RESET)))
    lay = study.layout
    checked = 0
    for k in range(k0 + 1, len(times)):
        used = np.any(meas.H[k] != 0.0, axis=1)
        if not np.any(used):
            continue
        H = meas.H[k][used]
        n_all = rr.Pa_minus.shape[-1]  # the exact model's noise states follow (issue 24)
        H = np.concatenate([H, np.zeros((H.shape[0], n_all - H.shape[1]))], axis=1)
        Ra = meas.R_assumed[k][np.ix_(used, used)]
        Rt = meas.R_true[k][np.ix_(used, used)]
        Pa, Pt = rr.Pa_minus[k], rr.Pt_minus[k]
        A = Pa @ H.T
        K = np.zeros((n_all, H.shape[0]))
        K[: lay.n_est] = np.linalg.solve(H @ A + Ra, A[: lay.n_est].T).T
        IKH = np.eye(n_all) - K @ H
        Pt_ref = IKH @ Pt @ IKH.T + K @ Rt @ K.T
        scale = np.max(np.abs(np.diag(Pt_ref)))
        assert np.max(np.abs(rr.Pt_plus[k] - Pt_ref)) <= 1e-9 * scale, k
        checked += 1
        if checked == 3:
            break
    assert checked == 3


def test_reset_needs_generalized_covariance():
    text = DECK.read_text(encoding="utf-8")
    text = text.replace('[[event]]\ntype = "eigenvector"', RESET + '[[event]]\ntype = "eigenvector"', 1)
    i = text.index("[gencov]")
    text = text[:i]  # drop [gencov] and what follows it (its parameters)
    with pytest.raises(DeckError, match=r"event\[0\]\.type"):
        parse_team_deck(text, str(DECK))


@pytest.mark.slow  # its module fixture: ~22 s of a cold make test (issue 22)
def test_square_root_mode_resets_the_same_way(runs):
    """The W-matrix mode refactors the reset covariance; its history equals the covariance
    form's (1e-8 relative: the QR time and measurement updates round differently)."""
    _, (study, _, rr) = runs
    text = DECK.read_text(encoding="utf-8")
    text = text.replace('[[event]]\ntype = "eigenvector"', RESET + '[[event]]\ntype = "eigenvector"', 1)
    text = text.replace("[filter]\n", "[filter]\nsquare_root = true\n", 1)
    sq = build_study(parse_team_deck(text, str(DECK)))
    rs = run_study(sq, integrate_reference(sq))
    for P, Q in ((rs.Pa_plus, rr.Pa_plus), (rs.Pt_plus, rr.Pt_plus)):
        scale = np.max(np.abs(np.diagonal(Q, axis1=1, axis2=2)), axis=1)
        assert np.all(np.max(np.abs(P - Q), axis=(1, 2)) <= 1e-8 * scale)
