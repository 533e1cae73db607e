"""White acceleration process noise in TEAM ([process_noise], Shuttle UNF s_q; digest
unf-apollo.md A.5.4) against its references:

- a TEAM run (PHI, fixed cells) on a short two-body LEO arc against a scipy integration
  (rtol 1e-12) of dP/dt = F P + P F^T + B q D B^T from the same a priori;
- the batched sweep path (fracas.team.batch.batch_noise) against the single-study Q;
- generalized covariance: the true direction and level differ from the filter's;
- extra event times leave the covariances unchanged (the integral composes);
- PDOT against PHI with white noise on tests/data/team_small.toml (slow);
- deck errors.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fracas.build.team import build_study
from fracas.config.team import load_team_deck, parse_team_deck
from fracas.errors import DeckError
from fracas.team.engine import process_noise, run_study
from fracas.team.reference import integrate_reference
from tests.filters.test_white_noise import _block_err, _cov_ode

DATA = Path(__file__).resolve().parents[1] / "data"
DAY = 86400.0

LEO_TRAJ = """
title = "LEO two-body arc"
[epoch]
iso = "2030-01-01T00:00:00"
[initial_state]
centre = "earth"
frame = "EME2000"
[initial_state.cartesian]
r_km = [7000.0, 0.0, 0.0]
v_km_s = [0.0, 6.5, 3.752]
[spacecraft]
mass_kg = 1000.0
[forces.overrides.earth]
mu_km3_s2 = 398600.4418
[integrator]
tolerance = 1e-13
[stop]
duration_days = 0.03
"""

LEO_TEAM = """
mode = "team"
title = "white noise on a LEO arc"
[ertraj]
deck = "leo_traj.toml"
[a_priori]
position_sigma_km = [0.1, 0.2, 0.3]
velocity_sigma_km_s = [1e-4, 2e-4, 3e-4]
[process_noise]
white_acceleration_km2_s3 = 1e-10
direction = "crosstrack"
quadrature_step_hours = 0.02
[[event]]
type = "propagation"
times_days = [0.01, 0.02]
"""


def _deck(tmp: Path, team: str = LEO_TEAM, name: str = "leo_team.toml"):
    (tmp / "leo_traj.toml").write_text(LEO_TRAJ)
    (tmp / name).write_text(team)
    return load_team_deck(tmp / name)


@pytest.fixture(scope="module")
def leo(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("leo")
    study = build_study(_deck(tmp))
    ref = integrate_reference(study)
    return tmp, study, ref, run_study(study, ref)


def test_team_matches_scipy_covariance_ode(leo):
    """PHI time updates with the quadrature Q reproduce the covariance ODE at every event."""
    _, study, ref, res = leo
    P0 = study.P0_assumed[:6, :6]
    x0 = ref.states[0, :6]
    errs = []
    for k, t in enumerate(ref.times_s):
        if k == 0:
            continue
        P_ode = _cov_ode(x0, float(t), 1e-10, "crosstrack", P0)
        errs.append(_block_err(res.Pa_minus[k][:6, :6], P_ode))
    assert max(errs) < 1e-8, errs
    # and the noise mattered: without it the crosstrack velocity sigma is smaller
    P_no = _cov_ode(x0, float(ref.times_s[-1]), 0.0, "crosstrack", P0)
    assert _block_err(P_no, res.Pa_minus[-1][:6, :6]) > 1e-3


def test_batch_noise_matches_single_study(leo):
    from fracas.team.batch import batch_noise, prepare

    _, study, ref, res = leo
    setup = prepare(study, ref)
    Qa, Qt = batch_noise(setup, [study, study])
    np.testing.assert_allclose(Qa[0], res.Q_assumed, rtol=1e-12, atol=1e-30)
    np.testing.assert_allclose(Qa[1], res.Q_assumed, rtol=1e-12, atol=1e-30)


def test_gencov_true_noise_differs(leo):
    """[gencov] process_noise: the truth has full white noise at twice q; the filter assumes
    crosstrack only."""
    tmp, study, ref, _ = leo
    deck = _deck(
        tmp,
        LEO_TEAM + '\n[gencov]\nprocess_noise = { white_acceleration_km2_s3 = 2e-10, direction = "full" }\n',
        "leo_gencov.toml",
    )
    st = build_study(deck)
    assert (st.white_q_true, st.white_direction_true) == (2e-10, "full")
    assert (st.white_q_assumed, st.white_direction_assumed) == (1e-10, "crosstrack")
    Qa, Qt = process_noise(st, ref)
    np.testing.assert_allclose(Qa, process_noise(study, ref)[0], rtol=1e-12, atol=1e-30)
    from fracas.team.transitions import white_unit_noise

    full = white_unit_noise(st, ref.times_s, ref.states[0], ["full"])["full"]
    np.testing.assert_allclose(Qt, 2e-10 * full, rtol=1e-12, atol=1e-30)
    # crosstrack + radial + along = full (linearity of the integral in D)
    parts = white_unit_noise(st, ref.times_s, ref.states[0], ["crosstrack", "radial", "along"])
    np.testing.assert_allclose(sum(parts.values()), full, rtol=1e-9, atol=1e-12 * np.max(np.abs(full)))


@pytest.mark.slow  # ~22 s of a cold make test (mostly XLA compilation; issue 22)
def test_event_times_do_not_change_the_covariance(leo):
    """The exact integral composes: more events give the same covariance at the shared times."""
    tmp, study, ref, res = leo
    deck = _deck(tmp, LEO_TEAM.replace("[0.01, 0.02]", "[0.005, 0.01, 0.0137, 0.02]"), "leo_more.toml")
    st = build_study(deck)
    r2 = run_study(st, integrate_reference(st))
    for t, P in zip(ref.times_s, res.Pa_plus):
        k = int(np.argmin(np.abs(r2.ref.times_s - t)))
        assert _block_err(r2.Pa_plus[k][:6, :6], P[:6, :6]) < 1e-10


def test_deck_fields_and_errors(tmp_path):
    deck = _deck(tmp_path)
    assert deck.process_noise.direction == "crosstrack"
    with pytest.raises(DeckError, match="direction"):
        parse_team_deck(LEO_TEAM.replace('"crosstrack"', '"sideways"'))
    with pytest.raises(DeckError, match="white_acceleration_km2_s3"):
        parse_team_deck(LEO_TEAM.replace("1e-10", "-1.0"))
    bad = LEO_TEAM + "\n[gencov]\nprocess_noise = { quadrature_step_hours = 0.1 }\n"
    (tmp_path / "bad.toml").write_text(bad)
    with pytest.raises(DeckError, match="quadrature_step_hours"):
        build_study(load_team_deck(tmp_path / "bad.toml"))


@pytest.mark.slow
def test_pdot_matches_phi_with_white_noise(tmp_path):
    """PDOT (Qc = B q D B^T at the RK4 nodes) against PHI (quadrature Q) on team_small
    without tracking and Gauss-Markov noise (so the covariance is linear in Q): the white
    part P(q) - P(0) of the two propagation modes agrees to PDOT's RK4 error."""
    import tomllib

    from tests.team.test_team_engine import dumps

    d = tomllib.loads((DATA / "team_small.toml").read_text())
    for k in ("thrust_noise", "tracking", "gencov", "event", "print"):
        d.pop(k, None)
    d["ertraj"]["deck"] = str(DATA / "team_small_traj.toml")
    out = {}
    for prop in ("phi", "pdot"):
        for q in (0.0, 1e-14):
            d["errcon"] = {"propagation": prop}
            d["process_noise"] = {"white_acceleration_km2_s3": q, "direction": "crosstrack"}
            p = tmp_path / f"{prop}{q}.toml"
            p.write_text(dumps(d))
            st = build_study(load_team_deck(p))
            out[prop, q] = run_study(st, integrate_reference(st)).Pa_plus[-1][:6, :6]
    d_phi = out["phi", 1e-14] - out["phi", 0.0]
    d_pdot = out["pdot", 1e-14] - out["pdot", 0.0]
    assert np.max(np.abs(d_phi)) > 0
    assert _block_err(d_pdot, d_phi) < 1e-5
