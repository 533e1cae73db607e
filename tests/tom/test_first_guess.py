"""TOM's automatic first guess (fracas/tom/first_guess.py, [tom.first_guess]): the burns read
off a segment pass and their Legendre pointing fits, against hand-built segment patterns and
numpy's own Legendre fit; the default segment count against Kepler's period; the default
optimizer."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.polynomial import legendre as npleg

from fracas.build.tom import auto_segments
from fracas.config.tom import TomSettings, parse_tom_deck, tom_trajectory_deck
from fracas.tom.first_guess import burns_from_segments, legendre_fit, legendre_values

ROOT = Path(__file__).resolve().parents[2]
DAY = 86400.0


def test_legendre_values_and_fit_against_numpy():
    """P0..P3 at s against numpy.polynomial.legendre.legval (1e-15); a weighted fit through 7
    points of a cubic recovers its Legendre coefficients (numpy's legfit with the same weights
    gives the same numbers, 1e-12)."""
    s = np.linspace(-1.0, 1.0, 7)
    vals = legendre_values(s, 3)
    for n in range(4):
        np.testing.assert_allclose(vals[:, n], npleg.legval(s, np.eye(4)[n]), atol=1e-15)
    c = np.array([0.3, -1.2, 0.5, 0.25])
    w = np.linspace(1.0, 2.0, 7)
    y = npleg.legval(s, c)
    np.testing.assert_allclose(legendre_fit(s, y, w, 3), c, atol=1e-12)
    np.testing.assert_allclose(
        legendre_fit(s, y + 0.01 * s**5, w, 3), npleg.legfit(s, y + 0.01 * s**5, 3, w=np.sqrt(w)), atol=1e-12
    )
    # fewer points than coefficients: the degree drops, the missing coefficients are zero
    np.testing.assert_allclose(legendre_fit(s[:2], y[:2], w[:2], 3)[2:], 0.0)


def test_burns_from_a_hand_built_segment_pattern():
    """10 segments of 10 d: throttle 0, 0.25, 1, 1, 0.5, 0, 0, 0.6, 0, 1.  Burns: segments 1-4,
    starting 0.75 x 10 d into segment 1 (17.5 d: its impulse kept) and ending 0.5 x 10 d before
    the end of segment 4 (45 d); segment 7 alone, its impulse 6 d centred in it (72-78 d);
    segment 9 (90-100 d).  Pointing: alpha = a linear function of t sampled at the middle of each
    segment's thrusting part (17.5-20 d for segment 1, 40-45 d for segment 4), so the fit
    recovers it exactly (P1 coefficient = slope x half-length), unwrapped through 180 deg."""
    edges = np.arange(11) * 10 * DAY
    thr = np.array([0.0, 0.25, 1.0, 1.0, 0.5, 0.0, 0.0, 0.6, 0.0, 1.0])
    mids = 0.5 * (edges[:-1] + edges[1:])
    mids[1], mids[4] = 18.75 * DAY, 42.5 * DAY
    slope = math.radians(2.0) / DAY  # 2 deg/day
    alpha = math.radians(170.0) + slope * (mids - mids[2])  # passes 180 deg inside burn 1
    alpha = -np.remainder(-alpha + np.pi, 2 * np.pi) + np.pi  # wrapped as pass 1 would give it
    beta = np.zeros(10)
    burns = burns_from_segments(edges, thr, alpha, beta, degree=3)
    spans = [(b[0].start_s / DAY, b[-1].stop_s / DAY) for b in burns]
    np.testing.assert_allclose(spans, [(17.5, 45.0), (72.0, 78.0), (90.0, 100.0)], atol=1e-9)
    b = burns[0][0]
    half = 0.5 * (b.stop_s - b.start_s)
    centre = 0.5 * (b.stop_s + b.start_s)
    assert abs(b.alpha_legendre[0] - slope * half) < 1e-9
    assert max(abs(c) for c in b.alpha_legendre[1:]) < 1e-9
    mean = math.radians(170.0) + slope * (centre - mids[2])
    assert abs(math.remainder(b.alpha - mean, 2 * math.pi)) < 1e-9


def test_a_burn_that_fits_badly_is_cut_into_contiguous_arcs():
    """A pointing that swings ±60 deg twice over 24 segments, which a cubic cannot follow: with a 5 deg
    limit the burn is cut into 2, 3 ... arcs of equal segment counts until each fits; the arcs
    meet at segment edges and span the burn."""
    edges = np.linspace(0.0, 240 * DAY, 25)
    mids = 0.5 * (edges[:-1] + edges[1:])
    alpha = np.radians(60.0) * np.sin(4 * np.pi * mids / edges[-1])
    burns = burns_from_segments(
        edges, np.ones(24), alpha, np.zeros(24), 3, max_fit_error_rad=math.radians(5.0), max_arcs=4
    )
    assert len(burns) == 1 and len(burns[0]) > 1
    arcs = burns[0]
    assert arcs[0].start_s == 0.0 and arcs[-1].stop_s == edges[-1]
    for a, b in zip(arcs[:-1], arcs[1:]):
        assert a.stop_s == b.start_s and np.any(np.isclose(a.stop_s, edges))


def test_default_segments_follow_the_initial_orbit():
    """12 per revolution of the initial osculating orbit over the window, within [24, 120]:
    Earth-Mars (1 AU circular-ish, 348.795 d ~ 0.95 rev) -> 24; the same deck over 3000 d
    (8.2 rev by Kepler's third law with a from the vis-viva energy) -> round(12 x 8.2)."""
    deck = parse_tom_deck((ROOT / "namelists" / "earth_mars_rendezvous_tom.toml").read_text(), "em.toml")
    traj = tom_trajectory_deck(deck)
    assert auto_segments(traj, 348.795) == 24
    mu = 132712440018.0
    r = np.array([-140699693.0, -51614428.0, 980.0])
    v = np.array([9.774596, -28.07828, 4.337725e-4])
    a = 1.0 / (2.0 / np.linalg.norm(r) - v @ v / mu)
    revs = 3000 * DAY / (2 * math.pi * math.sqrt(a**3 / mu))
    assert auto_segments(traj, 3000.0) == round(12 * revs)
    assert auto_segments(traj, 30000.0) == 120


def test_first_guess_defaults_to_ipopt():
    """[tom.first_guess] without an optimizer runs IPOPT (the projected gradient cannot do its
    passes); an explicit optimizer is kept; without a first guess the default stays FRACAS's."""
    assert TomSettings.model_validate({"first_guess": {}}).optimizer == "ipopt"
    assert TomSettings.model_validate({"first_guess": {}, "optimizer": "slsqp"}).optimizer == "slsqp"
    assert TomSettings.model_validate({}).optimizer == "projected_gradient"
