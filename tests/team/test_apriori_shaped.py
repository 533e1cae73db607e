"""The UNF correlated a priori ([a_priori.shaped]; digest unf-apollo.md A.6.1-A.6.3, A.3.10;
fracas.filters.apriori) against its references:

- the energy and |h| partials against central differences;
- the W-only (Potter square-root) pseudo update against the plain Kalman formula
  E - E b b^T E / (b^T E b + sigma^2);
- information: the shaped covariance's energy variance b^T P b is below both the diagonal
  prior's and sigma_E^2 (likewise for |h|);
- the LV -> reference transform is orthogonal and preserves the covariance (T E T^T round
  trip), and puts the crosstrack sigmas on the orbit normal;
- the deck wiring: P0 (assumed and true) of a TEAM study, at filter.start_days.
"""

from __future__ import annotations

import numpy as np
import pytest

from fracas.build.team import build_study, start_state
from fracas.config.team import load_team_deck, parse_team_deck
from fracas.errors import DeckError
from fracas.filters.apriori import (
    energy,
    energy_partials,
    lv_axes,
    lv_covariance,
    lv_to_reference,
    momentum,
    momentum_partials,
    pseudo_update,
    shaped_covariance,
)
from tests.team.test_white_noise_team import LEO_TRAJ

MU = 398600.4418
R = np.array([6800.0, 1200.0, -300.0])
V = np.array([-1.1, 6.9, 3.2])


def _central(f, x, h):
    out = np.zeros(6)
    for i in range(6):
        e = np.zeros(6)
        e[i] = h[i]
        out[i] = (float(f(x + e)) - float(f(x - e))) / (2 * h[i])
    return out


@pytest.mark.parametrize("which", ["energy", "momentum"])
def test_partials_match_central_differences(which):
    x = np.concatenate([R, V])
    h = np.sqrt(np.finfo(float).eps) * np.array([7000.0] * 3 + [7.0] * 3)
    if which == "energy":
        fd = _central(lambda y: energy(y[:3], y[3:], MU), x, h)
        an = np.asarray(energy_partials(R, V, MU))
    else:
        fd = _central(lambda y: momentum(y[:3], y[3:]), x, h)
        an = np.asarray(momentum_partials(R, V))
    np.testing.assert_allclose(an, fd, rtol=1e-6, atol=1e-9 * np.max(np.abs(an)))


def test_pseudo_update_is_the_kalman_update():
    rng = np.random.default_rng(7)
    B = rng.normal(size=(6, 6)) * np.array([1.0] * 3 + [1e-3] * 3)
    E = B @ B.T
    for b, var in ((np.asarray(energy_partials(R, V, MU)), 1e-6), (np.asarray(momentum_partials(R, V)), 4.0)):
        ref = E - np.outer(E @ b, b @ E) / (b @ E @ b + var)
        got = np.asarray(pseudo_update(E, b, var))
        d = np.sqrt(np.diag(ref))
        assert np.max(np.abs(got - ref) / np.outer(d, d)) < 1e-12


def test_shaped_covariance_information():
    sr, sv, sE, sH = 1.0, 1e-3, 1e-4, 1e-2
    P0 = np.diag([sr**2] * 3 + [sv**2] * 3)
    P = np.asarray(shaped_covariance(R, V, MU, sr, sv, sE, sH))
    bE, bH = np.asarray(energy_partials(R, V, MU)), np.asarray(momentum_partials(R, V))
    assert bE @ P @ bE < min(bE @ P0 @ bE, sE**2)
    assert bH @ P @ bH < min(bH @ P0 @ bH, sH**2)
    assert np.min(np.linalg.eigvalsh(P)) > 0
    # energy only, then energy and |h|: the second update shrinks |h|'s variance further
    PE = np.asarray(shaped_covariance(R, V, MU, sr, sv, sE, None))
    assert bH @ P @ bH < bH @ PE @ bH
    # no pseudo measurement: the diagonal itself
    np.testing.assert_allclose(np.asarray(shaped_covariance(R, V, MU, sr, sv)), P0, rtol=1e-14, atol=1e-20)


def test_lv_transform_preserves_the_covariance():
    T = np.asarray(lv_to_reference(R, V))
    np.testing.assert_allclose(T @ T.T, np.eye(6), atol=1e-15)
    E_lv = np.asarray(lv_covariance(1.0, 1e-3, 0.1, 1e-5))
    E_ref = T @ E_lv @ T.T
    d = np.sqrt(np.diag(E_lv))
    assert np.max(np.abs(T.T @ E_ref @ T - E_lv) / np.outer(d, d)) < 1e-11  # eps x sigma ratio^2 (1e4)
    M = np.asarray(lv_axes(R, V))
    zeta = np.cross(R, V) / np.linalg.norm(np.cross(R, V))
    np.testing.assert_allclose(M[1], -zeta, atol=1e-15)  # LV y = -orbit normal
    np.testing.assert_allclose(M[2], -R / np.linalg.norm(R), atol=1e-15)  # LV z = down
    assert abs(zeta @ E_ref[:3, :3] @ zeta - 0.1**2) < 1e-14
    assert abs(zeta @ E_ref[3:, 3:] @ zeta - 1e-5**2) < 1e-20
    # the shaped covariance with LV crosstrack values keeps the crosstrack channel (the
    # energy and |h| partials have no crosstrack component ... for |h| only the velocity part)
    P = np.asarray(shaped_covariance(R, V, MU, 1.0, 1e-3, 1e-4, None, 0.1, 1e-5))
    bE = np.asarray(energy_partials(R, V, MU))
    assert abs(bE[:3] @ zeta) < 1e-12 * np.linalg.norm(bE[:3]) and abs(bE[3:] @ zeta) < 1e-12 * np.linalg.norm(V)
    assert abs(zeta @ P[:3, :3] @ zeta - 0.1**2) < 1e-12


SHAPED_TEAM = """
mode = "team"
title = "shaped a priori"
[ertraj]
deck = "leo_traj.toml"
[filter]
start_days = START
[a_priori.shaped]
sigma_r_km = 1.0
sigma_v_km_s = 1e-3
sigma_energy_km2_s2 = 1e-4
sigma_h_km2_s = 1e-2
lv_crosstrack_sigma_r_km = 0.1
lv_crosstrack_sigma_v_km_s = 1e-5
[[event]]
type = "propagation"
times_days = [0.02]
[gencov]
a_priori = { shaped = { sigma_r_km = 2.0, sigma_v_km_s = 2e-3, sigma_energy_km2_s2 = 1e-3 } }
"""


@pytest.mark.parametrize("start", [0.0, 0.01])
def test_deck_builds_the_shaped_a_priori(tmp_path, start):
    (tmp_path / "leo_traj.toml").write_text(LEO_TRAJ)
    p = tmp_path / "shaped.toml"
    p.write_text(SHAPED_TEAM.replace("START", repr(start)))
    deck = load_team_deck(p)
    st = build_study(deck)
    r, v, mu = start_state(deck, str(p))
    assert mu == MU
    if start == 0.0:
        np.testing.assert_array_equal(r, [7000.0, 0.0, 0.0])
    else:  # the reference state at the filter start
        from fracas.team.reference import integrate_reference

        ref = integrate_reference(st)
        np.testing.assert_allclose(np.concatenate([r, v]), ref.states[0, :6], rtol=1e-12, atol=1e-9)
    want_a = np.asarray(shaped_covariance(r, v, mu, 1.0, 1e-3, 1e-4, 1e-2, 0.1, 1e-5))
    want_t = np.asarray(shaped_covariance(r, v, mu, 2.0, 2e-3, 1e-3))
    np.testing.assert_allclose(st.P0_assumed[:6, :6], want_a, rtol=1e-14, atol=1e-22)
    np.testing.assert_allclose(st.P0_true[:6, :6], want_t, rtol=1e-14, atol=1e-22)


def test_deck_errors():
    base = SHAPED_TEAM.replace("START", "0.0").split("[gencov]")[0]
    with pytest.raises(DeckError, match="position_sigma_km"):
        parse_team_deck(
            base.replace("[a_priori.shaped]", "[a_priori]\nposition_sigma_km = [1.0, 1.0, 1.0]\n[a_priori.shaped]")
        )
    with pytest.raises(DeckError, match="sigma_energy_km2_s2"):
        parse_team_deck(base.replace("sigma_energy_km2_s2 = 1e-4", "sigma_energy_km2_s2 = -1e-4"))
    with pytest.raises(DeckError, match="sigma_r_km"):
        parse_team_deck(base.replace("sigma_r_km = 1.0\n", ""))
