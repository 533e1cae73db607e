"""Heliocentric DE421 body states as one jit-able Chebyshev table (FRACAS EPHEM).

Source data: the ``de421`` PyPI package, i.e. the DE421 Chebyshev records as numpy
arrays for jplephem's legacy :class:`jplephem.ephem.Ephemeris` API (no ``.bsp``).  In
that layout each series ``jpl-<name>.npy`` has shape ``(n_records, 3, n_coef)`` on a
uniform grid of ``(jomega - jalpha) / n_records`` days starting at ``jalpha`` (JD TDB);
positions are km relative to the solar-system barycentre, except ``moon`` which is
geocentric (Moon minus Earth) and ``earthmoon`` which is the Earth-Moon barycentre.

:func:`build_ephemeris` (numpy, at the edge) re-expresses, for each requested body, the
linear combination that gives its **heliocentric** ICRF position

    planet  = planet - sun
    earth   = earthmoon - moon / (1 + EMRAT) - sun
    moon    = earthmoon + moon * EMRAT / (1 + EMRAT) - sun
    sun     = 0 (exactly)

as a single Chebyshev series per segment.  The series in a combination have different
record lengths (Moon 4 d, Mercury 8 d, Sun/EMB/Venus 16 d, outer planets 32 d); every
record length is a power of two in days and the grids share the origin ``jalpha``, so a
longer record restricted to one of its halves/quarters is still a polynomial of the same
degree.  Each body therefore gets the finest record length of its components and the
longer records are re-expanded exactly on the sub-intervals (the transformation matrices
are built with rational arithmetic, applied in extended precision, rounded once to
float64).  Only the records covering the requested window plus a margin are kept,
aligned to the 32-day grid so all bodies cover the same interval ``[et_start, et_end]``.

:func:`body_states` (pure JAX; jit/vmap/while_loop friendly) evaluates every body at
once: per body ``k = clip(floor((et - et_start) / seg_len), 0, nseg - 1)`` picks the
segment in a flat coefficient array, ``x = 2 (et - t_k) / seg_len - 1`` and Clenshaw's
recurrence gives position and, analytically, velocity (derivative of the
same polynomial, so velocity is exactly d(position)/dt and forward/reverse AD through
the evaluation gives the same numbers).  Outside ``[et_start, et_end]`` the end segments'
polynomials are extrapolated (no error is raised inside traced code); build the table
for the window you need (the default 30-day margin absorbs integrator overshoot).

Times are TDB seconds past J2000 (2000-01-01T12:00:00 TDB = JD 2451545.0 TDB), float64.
Units: km, km/s.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Sequence
from fractions import Fraction
from typing import TYPE_CHECKING, Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.typing import ArrayLike

from fracas import (
    _jax,  # noqa: F401  (float64, compilation cache)
    constants,
)
from fracas.errors import ConfigError
from fracas.timescales import calendar_to_et, et_to_calendar  # noqa: F401  (re-exported)

if TYPE_CHECKING:
    from jplephem.ephem import Ephemeris

# --- coverage ------------------------------------------------------------------------
# Published DE421 span (de421.bsp / JPL header): JD 2414864.5 .. 2471184.5 TDB
# (1899-07-29 .. 2053-10-09).  The arrays of the ``de421`` PyPI package start later, at
# jalpha = JD 2414992.5 (1899-12-04), and run on to jomega = JD 2524624.5 (2200-02-01).
# We serve the intersection: what the package holds, within the published DE421 span.
DE421_PUBLISHED_START_JD = 2_414_864.5  # 1899-07-29T00:00:00 TDB
DE421_PUBLISHED_END_JD = 2_471_184.5  # 2053-10-09T00:00:00 TDB

BODY_NAMES: tuple[str, ...] = (
    "sun",
    "mercury",
    "venus",
    "earth",
    "moon",
    "mars",
    "jupiter",
    "saturn",
    "uranus",
    "neptune",
    "pluto",
)
_PLANET_SERIES = {
    "mercury": "mercury",
    "venus": "venus",
    "mars": "mars",
    "jupiter": "jupiter",
    "saturn": "saturn",
    "uranus": "uranus",
    "neptune": "neptune",
    "pluto": "pluto",
}
_COARSEST_DAYS = 32  # longest record length in DE421; table bounds are aligned to it


class EphemerisTable(NamedTuple):
    """Heliocentric Chebyshev table of ``nb`` bodies over ``[et_start, et_end]`` (a pytree).

    coef:     (n_seg_total, 3, n_coef) float64, km; the segments of every body, body ``b``
              owning rows ``offset[b] .. offset[b] + nseg[b] - 1``; series of fewer
              coefficients are zero-padded (exact).
    offset:   (nb,) int32 first row of each body in ``coef``.
    nseg:     (nb,) int32 number of segments of each body.
    seg_len:  (nb,) float64 segment length (s); segment ``k`` of every body starts at
              ``et_start + k * seg_len[b]``.
    et_start: () float64 TDB s past J2000, start of coverage (all bodies).
    et_end:   () float64 TDB s past J2000, end of coverage (all bodies).
    body_id:  (nb,) int32 index of each body in :data:`BODY_NAMES` (see :func:`table_bodies`).
    """

    coef: jax.Array
    offset: jax.Array
    nseg: jax.Array
    seg_len: jax.Array
    et_start: jax.Array
    et_end: jax.Array
    body_id: jax.Array


# --- source data (lazy, cached) ------------------------------------------------------
@functools.lru_cache(maxsize=1)
def _de421() -> Ephemeris:
    """The jplephem legacy ``Ephemeris`` over the de421 package (constants only are read here)."""
    import de421
    from jplephem.ephem import Ephemeris

    return Ephemeris(de421)


@functools.cache
def _series(name: str) -> np.ndarray:
    """One raw DE421 series, memory-mapped (records, 3, n_coef); km, SSB (moon: geocentric)."""
    eph = _de421()
    return np.load(os.path.join(eph.dirpath, f"jpl-{name}.npy"), mmap_mode="r")


def _record_days(name: str) -> int:
    eph = _de421()
    days = (float(eph.jomega) - float(eph.jalpha)) / _series(name).shape[0]
    if days != int(days) or int(days) & (int(days) - 1):
        raise ConfigError(f"de421 series {name!r}: record length {days} d is not a power of two")
    return int(days)


def coverage_et() -> tuple[float, float]:
    """(start, end) TDB s past J2000 of the DE421 data this module serves."""
    eph = _de421()
    start_jd = max(float(eph.jalpha), DE421_PUBLISHED_START_JD)
    end_jd = min(float(eph.jomega), DE421_PUBLISHED_END_JD)
    return _jd_to_et(start_jd), _jd_to_et(end_jd)


def _jd_to_et(jd: float) -> float:
    return (jd - constants.J2000_JD) * constants.DAY_S


def _components(body: str) -> list[tuple[str, Fraction | float | np.floating[Any]]]:
    """(series, weight) pairs whose weighted sum is the heliocentric position of ``body``."""
    if body == "sun":
        return []
    if body in _PLANET_SERIES:
        return [(_PLANET_SERIES[body], 1), ("sun", -1)]
    emrat = np.longdouble(float(_de421().EMRAT))
    if body == "earth":
        return [("earthmoon", 1), ("moon", -1 / (1 + emrat)), ("sun", -1)]
    if body == "moon":
        return [("earthmoon", 1), ("moon", emrat / (1 + emrat)), ("sun", -1)]
    raise AssertionError(body)


# --- exact Chebyshev re-expansion on a sub-interval ---------------------------------
@functools.cache
def _cheb_power(n: int) -> tuple[tuple[int, ...], ...]:
    """Power-basis coefficients of T_0 .. T_{n-1} (integers)."""
    t = [[1], [0, 1]]
    for k in range(2, n):
        nxt = [0] * (k + 1)
        for i, c in enumerate(t[k - 1]):
            nxt[i + 1] += 2 * c
        for i, c in enumerate(t[k - 2]):
            nxt[i] -= c
        t.append(nxt)
    return tuple(tuple(p) for p in t[:n])


@functools.cache
def _subinterval_matrix(n: int, ratio: int, sub: int) -> np.ndarray:
    """M (n, n) with T_k(a x + b) = sum_j M[j, k] T_j(x) for sub-interval ``sub`` of ``ratio``.

    The parent interval [-1, 1] is cut into ``ratio`` equal parts; on part ``sub`` the
    parent variable is ``a x + b`` with ``a = 1/ratio``, ``b = (2 sub + 1)/ratio - 1``.
    Built exactly with rationals; returned in extended precision (each entry is a dyadic
    rational, converted as a rounded double-double).
    """
    a = Fraction(1, ratio)
    b = Fraction(2 * sub + 1, ratio) - 1
    tpow = _cheb_power(n)
    out = np.zeros((n, n), dtype=np.longdouble)
    for k in range(n):
        # power coefficients of T_k(a x + b)
        poly = [Fraction(0)] * n
        for m, pm in enumerate(tpow[k]):
            if pm == 0:
                continue
            for i in range(m + 1):  # (a x + b)^m = sum_i C(m,i) a^i x^i b^(m-i)
                poly[i] += pm * math.comb(m, i) * a**i * b ** (m - i)
        # power -> Chebyshev, highest degree first
        cheb = [Fraction(0)] * n
        for d in range(n - 1, -1, -1):
            if poly[d] == 0:
                continue
            lead = tpow[d][d]  # 2^(d-1) (1 for d = 0)
            c = poly[d] / lead
            cheb[d] = c
            for i, pi in enumerate(tpow[d]):
                poly[i] -= c * pi
        for j, c in enumerate(cheb):
            hi = float(c)
            lo = float(c - Fraction(hi))
            out[j, k] = np.longdouble(hi) + np.longdouble(lo)
    return out


def _body_coefficients(body: str, jd0: float, jd1: float, n_coef: int) -> tuple[np.ndarray, int]:
    """Heliocentric coefficients of ``body`` on [jd0, jd1] (aligned to the 32-day grid).

    Returns (coef (nseg, 3, n_coef) float64, segment length in days).
    """
    comps = _components(body)
    if not comps:  # the Sun: one all-zero segment over the whole table, exactly zero
        return np.zeros((1, 3, n_coef)), round(jd1 - jd0)
    jalpha = float(_de421().jalpha)
    seg_days = min(_record_days(s) for s, _ in comps)
    j0 = round((jd0 - jalpha) / seg_days)
    j1 = round((jd1 - jalpha) / seg_days)
    js = np.arange(j0, j1)
    acc = np.zeros((js.size, 3, n_coef), dtype=np.longdouble)
    for name, weight in comps:
        raw = _series(name)
        n_i = raw.shape[2]
        ratio = _record_days(name) // seg_days
        w = np.longdouble(weight)
        for sub in range(ratio):
            sel = np.nonzero(js % ratio == sub)[0]
            block = np.asarray(raw[js[sel] // ratio], dtype=np.longdouble)  # (m, 3, n_i)
            if ratio > 1:
                block = block @ _subinterval_matrix(n_i, ratio, sub).T
            acc[sel, :, :n_i] += w * block
    return acc.astype(np.float64), seg_days


# --- public construction -------------------------------------------------------------
def build_ephemeris(
    bodies: Sequence[str],
    et_start_s: float,
    et_end_s: float,
    margin_s: float = 30 * constants.DAY_S,
) -> EphemerisTable:
    """Table of heliocentric DE421 states of ``bodies`` (in that order) over a time window.

    ``et_start_s``/``et_end_s``: TDB s past J2000; the window must lie inside the DE421
    coverage (1899-12-04 .. 2053-10-09 TDB for the data of the de421 package, see
    :func:`coverage_et`).  ``margin_s`` is added on both sides (and silently clipped at the
    coverage ends); the kept interval is then widened to DE421's 32-day record grid.
    Raises :class:`~fracas.errors.ConfigError` for an unknown body or a time outside the
    coverage.
    """
    names = [str(b).strip().lower() for b in bodies]
    for given, name in zip(bodies, names):
        if name not in BODY_NAMES:
            raise ConfigError(f"ephemeris: unknown body {given!r}; DE421 provides {', '.join(BODY_NAMES)}")
    if not names:
        raise ConfigError("ephemeris: no bodies requested")
    t0, t1, margin = float(et_start_s), float(et_end_s), float(margin_s)
    if not (math.isfinite(t0) and math.isfinite(t1)) or t1 < t0:
        raise ConfigError(
            f"ephemeris: invalid time window et_start={et_start_s!r} s, et_end={et_end_s!r} s "
            "(TDB s past J2000; need finite values with start <= end)"
        )
    if not (math.isfinite(margin) and margin >= 0):
        raise ConfigError(f"ephemeris: margin_s={margin_s!r} must be finite and >= 0")
    cov0, cov1 = coverage_et()
    for t, what in ((t0, "start"), (t1, "end")):
        if not cov0 <= t <= cov1:
            raise ConfigError(
                f"ephemeris: window {what} {et_to_calendar(t)} TDB (et = {t:.3f} s) requested for "
                f"{', '.join(names)} is outside DE421 coverage {et_to_calendar(cov0)[:10]} .. "
                f"{et_to_calendar(cov1)[:10]} TDB (published DE421 span 1899-07-29..2053-10-09; "
                "the de421 package data begin 1899-12-04)"
            )
    jalpha = float(_de421().jalpha)
    lo = max(t0 - margin, cov0)
    hi = min(t1 + margin, cov1)
    grid_s = _COARSEST_DAYS * constants.DAY_S
    base = _jd_to_et(jalpha)
    k0 = math.floor((lo - base) / grid_s)
    k1 = max(math.ceil((hi - base) / grid_s), k0 + 1)
    k_cov1 = round((cov1 - base) / grid_s)
    k1 = min(k1, k_cov1)
    k0 = min(k0, k1 - 1)
    jd0 = jalpha + k0 * _COARSEST_DAYS
    jd1 = jalpha + k1 * _COARSEST_DAYS

    comps_all = {s for b in names for s, _ in _components(b)}
    n_coef = max([_series(s).shape[2] for s in comps_all], default=1)
    blocks, offset, nseg, seg_len = [], [], [], []
    row = 0
    cache: dict[str, tuple[np.ndarray, int]] = {}
    for name in names:
        if name not in cache:
            cache[name] = _body_coefficients(name, jd0, jd1, n_coef)
        coef, days = cache[name]
        blocks.append(coef)
        offset.append(row)
        nseg.append(coef.shape[0])
        seg_len.append(days * constants.DAY_S)
        row += coef.shape[0]
    return EphemerisTable(
        coef=jnp.asarray(np.concatenate(blocks, axis=0)),
        offset=jnp.asarray(np.array(offset, dtype=np.int32)),
        nseg=jnp.asarray(np.array(nseg, dtype=np.int32)),
        seg_len=jnp.asarray(np.array(seg_len, dtype=np.float64)),
        et_start=jnp.asarray(np.float64(_jd_to_et(jd0))),
        et_end=jnp.asarray(np.float64(_jd_to_et(jd1))),
        body_id=jnp.asarray(np.array([BODY_NAMES.index(n) for n in names], dtype=np.int32)),
    )


def table_bodies(table: EphemerisTable) -> tuple[str, ...]:
    """Names of the bodies of ``table`` in row order (numpy, at the edge)."""
    return tuple(BODY_NAMES[int(i)] for i in np.asarray(table.body_id))


# --- evaluation (pure JAX) -------------------------------------------------------------
def _chebyshev(coef: Array, x: Array, n_coef: int) -> tuple[Array, Array]:
    """Clenshaw sums  f = sum_k c_k T_k(x)  and  f' = sum_k c_k T_k'(x);  coef (..., 3, n), x (...).

    b_k = c_k + 2x b_{k+1} - b_{k+2},  f = c_0 + x b_1 - b_2, and its x-derivative
    d_k = 2 b_{k+1} + 2x d_{k+1} - d_{k+2},  f' = b_1 + x d_1 - d_2  (n_coef is static;
    the loop unrolls).  About 4x cheaper than forward T_k/T_k' recurrences in a scalar
    ``while_loop`` on CPU.
    """
    x = x[..., None]
    two_x = x + x
    b1 = jnp.zeros_like(coef[..., 0])
    b2, d1, d2 = b1, b1, b1
    for k in range(n_coef - 1, 0, -1):
        b0 = coef[..., k] + two_x * b1 - b2
        d0 = 2.0 * b1 + two_x * d1 - d2
        b2, b1 = b1, b0
        d2, d1 = d1, d0
    return coef[..., 0] + x * b1 - b2, b1 + x * d1 - d2


def _segment_and_x(table: EphemerisTable, et: Array) -> tuple[Array, Array]:
    """Per body (segment index k, normalised time x in [-1, 1] inside coverage)."""
    dt = et - table.et_start
    k = jnp.clip(jnp.floor(dt / table.seg_len), 0.0, (table.nseg - 1).astype(dt.dtype))
    tau = dt - k * table.seg_len
    x = 2.0 * tau / table.seg_len - 1.0
    return k.astype(jnp.int32), x


def _states_at(table: EphemerisTable, k: Array, x: Array) -> tuple[Array, Array]:
    """Position (nb, 3) and velocity (nb, 3) of each body ``b`` in its segment ``k[b]`` at ``x[b]``."""
    coef = table.coef[table.offset + k]  # (nb, 3, n)
    pos, dpos = _chebyshev(coef, x, table.coef.shape[-1])
    return pos, dpos * (2.0 / table.seg_len)[:, None]


def _body_states_scalar(table: EphemerisTable, et: Array) -> tuple[Array, Array]:
    k, x = _segment_and_x(table, et)
    return _states_at(table, k, x)


@jax.jit
def body_states(table: EphemerisTable, et_s: ArrayLike) -> tuple[Array, Array]:
    """Heliocentric ICRF position (km) and velocity (km/s) of every body of ``table``.

    ``et_s``: TDB s past J2000 (float64), a scalar -> ``(pos (nb, 3), vel (nb, 3))``; an
    array of shape ``S`` gives ``(S + (nb, 3), S + (nb, 3))`` (same as ``jax.vmap``).
    Jit/vmap/AD friendly; outside ``[table.et_start, table.et_end]`` the end polynomials are
    extrapolated.
    """
    et = jnp.asarray(et_s, dtype=jnp.float64)
    fn = lambda t: _body_states_scalar(table, t)  # noqa: E731
    for _ in range(et.ndim):
        fn = jax.vmap(fn)
    return fn(et)


# --- calendar <-> TDB seconds past J2000: fracas.timescales (re-exported here) --------


__all__ = [
    "BODY_NAMES",
    "EphemerisTable",
    "body_states",
    "build_ephemeris",
    "calendar_to_et",
    "coverage_et",
    "et_to_calendar",
    "table_bodies",
]
