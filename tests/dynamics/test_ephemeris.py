"""FRACAS EPHEM: heliocentric DE421 Chebyshev table (fracas.dynamics.ephemeris).

References: jplephem's own legacy ``Ephemeris.position_and_velocity`` over the same de421
package arrays (independent evaluation of the raw, barycentric series, combined here in
numpy), central finite differences, ``jax.jacfwd``, and Python's ``datetime`` for the
calendar (proleptic Gregorian, no leap seconds - the TDB convention).
"""

from __future__ import annotations

import datetime as dt

import de421
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from jplephem.ephem import Ephemeris

from fracas.dynamics import ephemeris as E
from fracas.errors import ConfigError

NAMES = E.BODY_NAMES
T0 = E.calendar_to_et("2025-01-01T00:00:00")
T1 = E.calendar_to_et("2027-01-01T00:00:00")
EPS = np.finfo(np.float64).eps


@pytest.fixture(scope="module")
def table():
    return E.build_ephemeris(NAMES, T0, T1)


@pytest.fixture(scope="module")
def jpl():
    return Ephemeris(de421)


def _reference(jpl, ets):
    """Heliocentric states from jplephem (km, km/s), bodies in NAMES order: (N, nb, 3) each.

    The time is passed as tdb = 2451545.0 plus tdb2 = et/86400 days, both exact for the
    test grid below, so jplephem and fracas evaluate the polynomials at the same instant.
    """
    tdb = np.full(ets.shape, 2451545.0)
    tdb2 = ets / 86400.0

    def pv(name):
        p, v = jpl.position_and_velocity(name, tdb, tdb2)
        return p.T, v.T / 86400.0  # legacy API: km and km/day

    sun_p, sun_v = pv("sun")
    emb_p, emb_v = pv("earthmoon")
    moon_p, moon_v = pv("moon")  # geocentric in the legacy layout
    out = {
        "sun": (np.zeros_like(sun_p), np.zeros_like(sun_v)),
        "earth": (emb_p - moon_p * jpl.earth_share - sun_p, emb_v - moon_v * jpl.earth_share - sun_v),
        "moon": (emb_p + moon_p * jpl.moon_share - sun_p, emb_v + moon_v * jpl.moon_share - sun_v),
    }
    for name in NAMES:
        if name not in out:
            p, v = pv(name)
            out[name] = (p - sun_p, v - sun_v)
    pos = np.stack([out[n][0] for n in NAMES], axis=1)
    vel = np.stack([out[n][1] for n in NAMES], axis=1)
    return pos, vel


def test_matches_jplephem_at_random_times(table, jpl):
    # 200 random instants in the 2-year window (and the window ends), on a grid of
    # 84.375 s = 86400/1024 s so that et/86400 is exact and both codes see the same time.
    rng = np.random.default_rng(421)
    step = 86400.0 / 1024
    ets = T0 + rng.integers(0, int((T1 - T0) / step) + 1, 200) * step
    ets = np.concatenate([ets, [T0, T1]])
    pos, vel = jax.vmap(lambda t: E.body_states(table, t))(jnp.asarray(ets))
    ref_pos, ref_vel = _reference(jpl, ets)
    pos, vel = np.asarray(pos), np.asarray(vel)
    # Both sides are float64 evaluations of the same polynomials (fracas: re-expanded
    # combination; jplephem: each raw series, then combined), so they differ by a few
    # roundings of the largest term.  Measured (2025-2027): max |dr| 2.2e-8 km (Mercury),
    # 8.9e-8 km (Earth), 6.0e-8 km (Moon), 2.4e-7 km (Jupiter), 1.9e-6 km (Neptune) =
    # 4.3e-16 |r|; max |dv| 2.1e-14 km/s.  (Against an 80-bit re-evaluation of the raw
    # series fracas is off by <= 1.2e-6 km for Neptune, jplephem-style float64 by 1.6e-6.)
    # 1e-6 km is below one ulp of Neptune's/Pluto's coordinates
    # (ulp(4.5e9 km) = 9.5e-7 km), so the bound is 1e-6 km plus 8 ulp of |r|.
    r = np.linalg.norm(ref_pos, axis=-1, keepdims=True)
    assert np.all(np.abs(pos - ref_pos) <= 1e-6 + 8 * EPS * r)
    assert np.max(np.abs(vel - ref_vel)) < 1e-12
    # The Sun is the origin: exactly zero.
    assert np.all(pos[:, 0] == 0.0) and np.all(vel[:, 0] == 0.0)
    # Sanity: Earth ~1 AU from the Sun, Moon ~384 000 km from the Earth.
    d_earth = np.linalg.norm(pos[:, 3], axis=-1) / 149_597_870.7
    d_moon = np.linalg.norm(pos[:, 4] - pos[:, 3], axis=-1)
    assert np.all((0.98 < d_earth) & (d_earth < 1.02))
    assert np.all((356_000 < d_moon) & (d_moon < 407_000))


def test_array_time_argument_and_body_subset(jpl):
    # An array et gives the vmapped result; a subset/reordering of bodies gives the
    # same rows as the full table (same polynomials, so bit-identical).
    sub = E.build_ephemeris(["moon", "mars", "sun"], T0, T0 + 86400.0 * 10, margin_s=0.0)
    full = E.build_ephemeris(NAMES, T0, T0 + 86400.0 * 10, margin_s=0.0)
    ets = jnp.linspace(T0, T0 + 86400.0 * 10, 7).reshape(7, 1)
    p_sub, v_sub = E.body_states(sub, ets)
    p_full, v_full = E.body_states(full, ets)
    assert p_sub.shape == (7, 1, 3, 3)
    assert E.table_bodies(sub) == ("moon", "mars", "sun")
    idx = [NAMES.index(n) for n in E.table_bodies(sub)]
    np.testing.assert_array_equal(np.asarray(p_sub), np.asarray(p_full)[..., idx, :])
    np.testing.assert_array_equal(np.asarray(v_sub), np.asarray(v_full)[..., idx, :])
    assert float(sub.et_start) <= T0 and float(sub.et_end) >= T0 + 86400.0 * 10


def test_velocity_is_derivative_of_position(table):
    rng = np.random.default_rng(7)
    ets = T0 + np.round(rng.uniform(0, T1 - T0, 50))  # whole seconds: et +- h exact
    h = 64.0
    states = jax.jit(jax.vmap(lambda t: E.body_states(table, t)))
    _, vel = states(jnp.asarray(ets))
    p_plus, _ = states(jnp.asarray(ets + h))
    p_minus, _ = states(jnp.asarray(ets - h))
    fd = (np.asarray(p_plus) - np.asarray(p_minus)) / (2 * h)
    # Central difference error: truncation h^2/6 |r'''| (largest for Mercury,
    # |r| n^3 ~ 3e-11 km/s^3 -> h^2/6 |r'''| ~ 2e-8 km/s; measured 5.2e-8 km/s) plus
    # rounding ~ulp(|r|)/h (Neptune: 9.5e-7/64 = 1.5e-8 km/s; measured 1.3e-8 km/s).
    assert np.max(np.abs(fd - np.asarray(vel))) < 1e-7

    # Forward-mode AD of the position w.r.t. time is the same Chebyshev derivative as
    # the analytic velocity (only the association of the floating-point sums differs).
    jac = jax.jit(jax.vmap(jax.jacfwd(lambda t: E.body_states(table, t)[0])))
    dpos_dt = np.asarray(jac(jnp.asarray(ets)))
    err = np.abs(dpos_dt - np.asarray(vel))
    assert np.max(err) < 1e-12  # measured 7.1e-15 km/s
    # Reverse mode agrees too (gradient of one coordinate).
    g = jax.grad(lambda t: E.body_states(table, t)[0][4, 1])(jnp.float64(ets[0]))
    assert abs(float(g) - float(vel[0, 4, 1])) < 1e-12


def test_usable_inside_while_loop(table):
    # The evaluation is a pure function of (table, et): it traces inside lax loops.
    def body(carry):
        i, t, acc = carry
        p, _ = E.body_states(table, t)
        return i + 1, t + 86400.0, acc + jnp.linalg.norm(p[3])

    n, _, acc = jax.jit(lambda t: jax.lax.while_loop(lambda c: c[0] < 10, body, (0, t, 0.0)))(jnp.float64(T0))
    assert int(n) == 10 and 0.98 < float(acc) / 10 / 149_597_870.7 < 1.02


def test_segment_boundaries_are_continuous(table):
    # Evaluate each body at the right end (x = +1) of segment k and the left end (x = -1)
    # of segment k + 1, for every interior boundary of the table.  Boundaries inside a
    # longer DE record (created by the re-expansion) must agree to rounding; DE421
    # records are fitted with position/velocity continuity at their ends.  Measured max
    # jumps: 1.9e-6 km for Neptune (= 2 ulp of 4.5e9 km), < 1.1e-7 km for Mercury..Mars,
    # and 3.6e-14 km/s - rounding level, so the bound is 1e-6 km + 8 ulp(|r|).
    nseg = np.asarray(table.nseg)
    k = np.minimum(np.arange(nseg.max() - 1)[:, None], np.maximum(nseg - 2, 0)[None, :])
    k = k.astype(np.int32)
    ones = np.ones(k.shape)
    at = jax.jit(jax.vmap(lambda kv, xv: E._states_at(table, kv, xv)))
    p_l, v_l = (np.asarray(a) for a in at(k, ones))
    p_r, v_r = (np.asarray(a) for a in at(k + (nseg >= 2), -ones))
    r = np.linalg.norm(p_l, axis=-1, keepdims=True)
    assert np.all(np.abs(p_l - p_r) <= 1e-6 + 8 * EPS * r)
    assert np.max(np.abs(v_l - v_r)) < 1e-12
    # And through the public function, across a Moon/Earth segment boundary: the
    # position change over 2 ms is v * 2 ms (the quadratic term, |a| (1e-3 s)^2, is
    # ~1e-11 km; the times carry ulp(8e8 s) = 1.2e-7 s, i.e. < 1e-5 km at 48 km/s).
    b = NAMES.index("moon")
    t_b = float(table.et_start) + 10 * float(table.seg_len[b])
    t_a, t_c = t_b - 1e-3, t_b + 1e-3
    p_a, v_a = E.body_states(table, t_a)
    p_c, _ = E.body_states(table, t_c)
    jump = np.asarray(p_c) - np.asarray(p_a) - np.asarray(v_a) * (t_c - t_a)
    assert np.max(np.abs(jump)) < 1e-5


def test_table_keeps_only_the_window():
    tab = E.build_ephemeris(["earth"], T0, T0, margin_s=0.0)
    # one 32-day record grid cell, cut into 4-day Earth segments
    assert int(tab.nseg[0]) == 8 and tab.coef.shape == (8, 3, 13)
    assert float(tab.et_start) <= T0 <= float(tab.et_end)
    assert float(tab.et_end) - float(tab.et_start) == 32 * 86400.0
    long = E.build_ephemeris(["earth"], T0, T1)
    assert long.coef.shape[0] < 250  # ~2.2 years / 4 days, not the whole 150 years


def test_errors_name_body_and_coverage():
    with pytest.raises(ConfigError, match=r"unknown body 'vulcan'.*mercury"):
        E.build_ephemeris(["earth", "vulcan"], T0, T1)
    late = E.calendar_to_et("2060-01-01T00:00:00")
    with pytest.raises(ConfigError) as info:
        E.build_ephemeris(["mars"], T0, late)
    msg = str(info.value)
    assert "mars" in msg and "2060-01-01" in msg and "1899-07-29..2053-10-09" in msg
    # Inside the published DE421 span but before the de421 package's first record.
    with pytest.raises(ConfigError, match="1899-12-04"):
        E.build_ephemeris(["earth"], E.calendar_to_et("1899-09-01T00:00:00"), T0)
    with pytest.raises(ConfigError, match="start <= end"):
        E.build_ephemeris(["earth"], T1, T0)
    # The coverage ends are usable; the margin is clipped there, not an error.
    c0, c1 = E.coverage_et()
    assert E.et_to_calendar(c0) == "1899-12-04T00:00:00.000"
    assert E.et_to_calendar(c1) == "2053-10-09T00:00:00.000"
    tab = E.build_ephemeris(["pluto"], c1 - 86400.0, c1)
    assert float(tab.et_end) == c1


def test_calendar_j2000_and_round_trip():
    assert E.calendar_to_et("2000-01-01T12:00:00") == 0.0
    assert E.calendar_to_et("2000-01-01T12:00:00.000 TDB") == 0.0
    assert E.et_to_calendar(0.0) == "2000-01-01T12:00:00.000"
    assert E.calendar_to_et("2000-01-01") == -43200.0
    assert E.calendar_to_et("2000-03-01T00:00:00") - E.calendar_to_et("2000-02-28T00:00:00") == 2 * 86400.0
    assert E.calendar_to_et("1900-03-01") - E.calendar_to_et("1900-02-28") == 86400.0
    with pytest.raises(ConfigError, match="expected ISO"):
        E.calendar_to_et("01/02/2025")
    with pytest.raises(ConfigError, match="day 30"):
        E.calendar_to_et("2025-02-30T00:00:00")


@settings(max_examples=200, deadline=None)
@given(st.datetimes(min_value=dt.datetime(1900, 1, 1), max_value=dt.datetime(2199, 12, 31)))
def test_calendar_against_datetime(when):
    # Reference: datetime arithmetic on the proleptic Gregorian calendar with 86400-s
    # days (the TDB convention); whole milliseconds are exact in both directions.
    when = when.replace(microsecond=(when.microsecond // 1000) * 1000)
    iso = when.strftime("%Y-%m-%dT%H:%M:%S.") + f"{when.microsecond // 1000:03d}"
    expect = (when - dt.datetime(2000, 1, 1, 12)).total_seconds()
    et = E.calendar_to_et(iso)
    assert abs(et - expect) <= 1e-6
    assert E.et_to_calendar(et) == iso
    assert abs(E.calendar_to_et(E.et_to_calendar(et + 0.25e-3, digits=6)) - (et + 0.25e-3)) < 1e-6
