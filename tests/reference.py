"""Independent reference: plain Cowell equations integrated by scipy DOP853 at rtol 1e-13.

Nothing here uses fracas numerics: accelerations are written out again in numpy, planet
positions come straight from jplephem's legacy API over the de421 package, Kepler's
problem is not used.  Tests compare the Encke/Nystrom core against these integrations.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.integrate import solve_ivp

AU = 149_597_870.7


@functools.lru_cache(maxsize=1)
def _eph():
    import de421
    from jplephem import Ephemeris

    return Ephemeris(de421)


def helio_position(body: str, et_s: float) -> np.ndarray:
    """Heliocentric ICRF position (km) of a body from jplephem directly (DE421)."""
    e = _eph()
    # two-part Julian date: a single JD float resolves only ~5e-5 s
    jd = (2451545.0, et_s / 86400.0)
    sun = e.position("sun", *jd)
    if body == "sun":
        return np.zeros(3)
    if body in ("earth", "moon"):
        emb = e.position("earthmoon", *jd)
        moon = e.position("moon", *jd)
        emrat = e.EMRAT
        pos = emb - moon / (1.0 + emrat) if body == "earth" else emb + moon * emrat / (1.0 + emrat)
    else:
        pos = e.position(body, *jd)
    return np.ravel(pos - sun)


def helio_velocity(body: str, et_s: float) -> np.ndarray:
    """Heliocentric ICRF velocity (km/s) from jplephem's own Chebyshev derivative (DE421).

    (A finite difference of jplephem positions is no good here: its positions jitter by
    ~5e-6 km with the time argument, which a 2 s difference turns into 2e-6 km/s.)"""
    e = _eph()
    jd = (2451545.0, et_s / 86400.0)
    vel = lambda name: np.ravel(e.position_and_velocity(name, *jd)[1]) / 86400.0  # noqa: E731
    if body == "sun":
        return np.zeros(3)
    if body in ("earth", "moon"):
        emrat = e.EMRAT
        emb, moon = vel("earthmoon"), vel("moon")
        v = emb - moon / (1.0 + emrat) if body == "earth" else emb + moon * emrat / (1.0 + emrat)
    else:
        v = vel(body)
    return v - vel("sun")


def cowell_rhs_factory(mu_primary, primary="sun", third=(), mus=None, j2=None, thrust=None, epoch_et=0.0):
    """RHS of the plain equations for y = (r, v, m).

    j2: (J2, R, pole) of the primary; third: body names with GM in ``mus``; thrust: dict with
    p0_kw, eta, c, alpha, beta, factor (velocity frame, solar power 1/r^2) or None.
    """

    def rhs(t, y):
        r, v, m = y[:3], y[3:6], y[6]
        rn = np.linalg.norm(r)
        a = -mu_primary * r / rn**3
        et = epoch_et + t
        if j2 is not None:
            J2, R, pole = j2
            s = r @ pole / rn
            a = a - 1.5 * J2 * mu_primary * R**2 / rn**4 * ((1 - 5 * s * s) * r / rn + 2 * s * pole)
        rp = helio_position(primary, et) if third or thrust else np.zeros(3)
        for b in third:
            rho = helio_position(b, et) - rp
            d = rho - r
            a = a + mus[b] * (d / np.linalg.norm(d) ** 3 - rho / np.linalg.norm(rho) ** 3)
        mdot = 0.0
        if thrust is not None and thrust["factor"](t) > 0:
            rs = r + rp
            p_kw = thrust["p0_kw"] * AU**2 / (rs @ rs)
            tm = thrust["factor"](t) * 2e-3 * thrust["eta"] * p_kw / thrust["c"]
            h = np.cross(r, v)
            x = v / np.linalg.norm(v)
            z = h / np.linalg.norm(h)
            yv = np.cross(z, x)
            al, be = thrust["alpha"](t), thrust["beta"](t)
            u = np.cos(be) * np.cos(al) * x + np.cos(be) * np.sin(al) * yv + np.sin(be) * z
            a = a + tm / m * u
            mdot = -tm / thrust["c"]
        return np.concatenate([v, a, [mdot]])

    return rhs


def integrate_piecewise(rhs, y0, t_breaks, rtol=1e-13, atol=1e-12):
    """DOP853 from t_breaks[0] to t_breaks[-1], restarting at every break (thrust switches)."""
    y = np.asarray(y0, float)
    for ta, tb in zip(t_breaks[:-1], t_breaks[1:]):
        if tb == ta:
            continue
        sol = solve_ivp(rhs, (ta, tb), y, method="DOP853", rtol=rtol, atol=atol)
        assert sol.success, sol.message
        y = sol.y[:, -1]
    return y
