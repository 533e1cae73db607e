"""Numpy two-body helpers for the plots: a universal-variable Kepler step, the dense
interpolation of stored trajectory samples between them, and osculating a, e, i.

The trajectory file keeps states at the deck's output times only (every 14 minutes on the
LEO deck: seven points per orbit), so joining them with straight lines draws a polygon.
:func:`dense_path` fills each interval [t_k, t_k+1] (same primary on both ends) with the
conic flown forward from sample k and the conic flown backward from sample k+1, blended by
the smooth step w = s^2 (3 - 2 s), s = (t - t_k) / (t_k+1 - t_k) (velocities by s, so
that osculating elements move evenly across a thrust arc): exact at both samples,
exact between them for two-body motion, and for a perturbed or thrusting path in error by
the perturbation's effect over half an interval, second order (J2 in LEO, 14 min: under a
kilometre; a thrust arc: a.dt^2/8).  Plot-only numbers; the propagation is the record.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["kepler_step", "dense_path", "osculating_aei", "turn_rate"]


def _stumpff(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """C(z) = (1 - cos sqrt z)/z, S(z) = (sqrt z - sin sqrt z)/z^1.5 (and their hyperbolic
    continuations; a 5-term series near 0)."""
    z = np.asarray(z, dtype=float)
    small = np.abs(z) < 1e-2
    pos = z > 0
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        ze = np.where(pos & ~small, z, 1.0)
        zh = np.where(~pos & ~small, -z, 1.0)
        ye, yh = np.sqrt(ze), np.sqrt(zh)
        c = np.where(
            small,
            0.5 - z / 24 + z**2 / 720 - z**3 / 40320 + z**4 / 3628800,
            np.where(pos, 2.0 * np.sin(ye / 2) ** 2 / ze, 2.0 * np.sinh(yh / 2) ** 2 / zh),
        )
        s = np.where(
            small,
            1 / 6 - z / 120 + z**2 / 5040 - z**3 / 362880 + z**4 / 39916800,
            np.where(pos, (ye - np.sin(ye)) / ze**1.5, (np.sinh(yh) - yh) / zh**1.5),
        )
    return c, s


def kepler_step(r0: np.ndarray, v0: np.ndarray, dt: np.ndarray, mu: float) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities (n, 3) after ``dt`` (n,) s on the conics through (r0, v0)
    (n, 3) about a body of GM ``mu``: universal variables, Laguerre-Conway iteration (any
    conic, forward or backward)."""
    r0 = np.asarray(r0, dtype=float)
    v0 = np.asarray(v0, dtype=float)
    dt = np.asarray(dt, dtype=float)
    smu = math.sqrt(mu)
    rn = np.linalg.norm(r0, axis=-1)
    sigma = np.einsum("ij,ij->i", r0, v0) / smu
    alpha = 2.0 / rn - np.einsum("ij,ij->i", v0, v0) / mu
    with np.errstate(invalid="ignore", divide="ignore"):  # Vallado's starts (Algorithm 8)
        ell = smu * dt * alpha
        a_h = np.where(alpha < 0, 1.0 / np.where(alpha < 0, alpha, -1.0), -1.0)
        sg = np.where(dt >= 0, 1.0, -1.0)
        arg = -2.0 * mu * alpha * dt / (np.einsum("ij,ij->i", r0, v0) + sg * np.sqrt(-mu * a_h) * (1.0 - rn * alpha))
        hyp = sg * np.sqrt(-a_h) * np.log(np.where(arg > 0, arg, np.nan))
    x = np.where(alpha > 1e-12 / rn, ell, np.where((alpha < -1e-12 / rn) & np.isfinite(hyp), hyp, smu * dt / rn))
    for _ in range(40):
        z = alpha * x * x
        c, s = _stumpff(z)
        f = sigma * x * x * c + (1.0 - alpha * rn) * x**3 * s + rn * x - smu * dt
        df = x * x * c + sigma * x * (1.0 - z * s) + rn * (1.0 - z * c)
        ddf = sigma * (1.0 - z * c) + (1.0 - alpha * rn) * x * (1.0 - z * s)
        n = 5.0
        root = np.sqrt(np.abs((n - 1) ** 2 * df * df - n * (n - 1) * f * ddf))
        dx = n * f / (df + np.where(df >= 0, root, -root))
        x = x - dx
        if np.all(np.abs(dx) <= 1e-13 * np.maximum(np.abs(x), 1.0)):
            break
    z = alpha * x * x
    c, s = _stumpff(z)
    f = 1.0 - x * x * c / rn
    g = dt - x**3 * s / smu
    r = f[:, None] * r0 + g[:, None] * v0
    rr = np.linalg.norm(r, axis=-1)
    fd = smu / (rr * rn) * x * (z * s - 1.0)
    gd = 1.0 - x * x * c / rr
    v = fd[:, None] * r0 + gd[:, None] * v0
    return r, v


def turn_rate(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Angular rate |r x v| / |r|^2 (rad/s) of each state."""
    h = np.linalg.norm(np.cross(r, v), axis=-1)
    return h / np.einsum("ij,ij->i", r, r)


def dense_path(
    t: np.ndarray,
    r: np.ndarray,
    v: np.ndarray,
    mass: np.ndarray,
    primary: np.ndarray,
    mu_of,
    max_turn_rad: float = math.radians(2.0),
    max_points: int = 60_000,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t, r, v, mass, primary) with every interval between consecutive samples of one
    primary filled by blended conics (module docstring) so that the path turns at most about
    ``max_turn_rad`` between points (coarser if that would exceed ``max_points``); mass is
    interpolated linearly.  ``mu_of(name)`` gives a primary's GM (None: the interval is not
    filled).  The samples themselves are kept exactly."""
    t = np.asarray(t, dtype=float)
    r = np.asarray(r, dtype=float)
    v = np.asarray(v, dtype=float)
    mass = np.asarray(mass, dtype=float)
    primary = np.asarray(primary, dtype=object)
    n = t.size
    if n < 2:
        return t, r, v, mass, primary
    h = np.diff(t)
    w = turn_rate(r, v)
    turn = np.abs(h) * np.maximum(w[:-1], w[1:])
    same = (primary[:-1] == primary[1:]) & (h != 0) & np.isfinite(turn)
    mus = {p: mu_of(p) for p in dict.fromkeys(primary.tolist())}
    fill = same & np.array([mus[p] is not None for p in primary[:-1]])
    step = max_turn_rad
    sub = np.where(fill, np.ceil(np.where(fill, turn, 0.0) / step), 1).astype(np.int64)
    if sub.sum() > max_points:  # coarser, never below one point per interval
        sub = np.maximum(np.floor(sub * (max_points / sub.sum())), 1).astype(np.int64)
    out_t, out_r, out_v, out_m, out_p = [t[:1]], [r[:1]], [v[:1]], [mass[:1]], [primary[:1]]
    # intervals with sub-points, grouped per primary for one vectorized call each
    k_idx = np.repeat(np.arange(n - 1), sub)
    frac = np.concatenate([np.arange(1, m + 1) / m for m in sub])  # (0, 1], the last is the sample
    tt = t[k_idx] + frac * h[k_idx]
    rr = r[k_idx + 1].copy()
    vv = v[k_idx + 1].copy()
    inner = frac < 1.0
    for p, mu in mus.items():
        sel = inner & fill[k_idx] & (primary[k_idx] == p)
        if mu is None or not sel.any():
            continue
        k = k_idx[sel]
        tau = frac[sel] * h[k]
        ra, va = kepler_step(r[k], v[k], tau, mu)
        rb, vb = kepler_step(r[k + 1], v[k + 1], tau - h[k], mu)
        s = frac[sel][:, None]
        wb = s * s * (3.0 - 2.0 * s)
        rr[sel] = (1.0 - wb) * ra + wb * rb
        vv[sel] = (1.0 - s) * va + s * vb  # linear: osculating elements change evenly under thrust
    mm = mass[k_idx] + frac * (mass[k_idx + 1] - mass[k_idx])
    pp = np.where(inner, primary[k_idx], primary[k_idx + 1])
    out_t.append(tt)
    out_r.append(rr)
    out_v.append(vv)
    out_m.append(mm)
    out_p.append(pp)
    return (
        np.concatenate(out_t),
        np.concatenate(out_r),
        np.concatenate(out_v),
        np.concatenate(out_m),
        np.concatenate(out_p).astype(object),
    )


def osculating_aei(r: np.ndarray, v: np.ndarray, mu: float, pole=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Osculating semi-major axis (km; NaN for e >= 1), eccentricity and inclination (rad,
    to the plane normal to ``pole``, a unit vector; default the ICRF z axis) of states
    (n, 3)."""
    r = np.asarray(r, dtype=float)
    v = np.asarray(v, dtype=float)
    rn = np.linalg.norm(r, axis=-1)
    v2 = np.einsum("ij,ij->i", v, v)
    hv = np.cross(r, v)
    hn = np.linalg.norm(hv, axis=-1)
    ev = ((v2 - mu / rn)[:, None] * r - np.einsum("ij,ij->i", r, v)[:, None] * v) / mu
    e = np.linalg.norm(ev, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = 1.0 / (2.0 / rn - v2 / mu)
        a = np.where(e < 1.0, a, np.nan)
        k = np.array([0.0, 0.0, 1.0]) if pole is None else np.asarray(pole, dtype=float)
        i = np.arccos(np.clip(hv @ k / hn, -1.0, 1.0))
    return a, e, i
