"""A synthetic results dict with guidance events, a control covariance and an error budget
(known covariances), built on the small TEAM study's real results file."""

from __future__ import annotations

import numpy as np

DAY = 86400.0


def spd(rng, n: int, scales) -> np.ndarray:
    """A random symmetric positive-definite n×n covariance with 1σ about ``scales``."""
    A = rng.normal(size=(n, n))
    Q, _ = np.linalg.qr(A)
    C = Q @ np.diag(rng.uniform(0.3, 1.0, n)) @ Q.T
    d = np.sqrt(np.diag(C))
    s = np.asarray(scales, dtype=float)
    return C / np.outer(d, d) * np.outer(s, s)


def _impulsive(rng, name: str, index: int, t_s: float, scale: float) -> dict:
    names = ["b_dot_t", "b_dot_r", "time_of_flight"]
    before = spd(rng, 3, [scale * 300.0, scale * 200.0, scale * 900.0])
    return {
        "name": name,
        "type": "impulsive",
        "index": index,
        "time_s": t_s,
        "cutoff_s": t_s - 0.5 * DAY,
        "target_time_s": 10.0 * DAY,
        "target_body": "mars",
        "estimate_model": "report",
        "rank": 3,
        "status": 0,
        "target_names": names,
        "target_units": ["km", "km", "s"],
        "control_labels": ["dv_x", "dv_y", "dv_z"],
        "control_units": ["km/s", "km/s", "km/s"],
        "target_cov_before": before,
        "target_cov_after": spd(rng, 3, [scale * 20.0, scale * 12.0, scale * 60.0]),
        "target_cov_knowledge": spd(rng, 3, [scale * 15.0, scale * 9.0, scale * 40.0]),
        "correction_cov": spd(rng, 3, [1.2e-3 * scale] * 3),
        "execution_cov": spd(rng, 3, [2e-5 * scale] * 3),
        "dv_mean_km_s": 1.7e-3 * scale,
        "dv_99_km_s": 4.1e-3 * scale,
        "dv_rms_km_s": 2.0e-3 * scale,
        "propellant_sigma_kg": float("nan"),
    }


def _low_thrust(rng, index: int, t_s: float) -> dict:
    return {
        "name": "arc1",
        "type": "primary",
        "index": index,
        "time_s": t_s,
        "cutoff_s": t_s - 0.25 * DAY,
        "target_time_s": 8.0 * DAY,
        "target_body": "sun",
        "estimate_model": "orthogonal",
        "rank": 3,
        "status": 0,
        "target_names": ["a", "e", "i"],
        "target_units": ["km", "1", "rad"],
        "control_labels": ["arc_thrust_scale[0]", "arc_alpha[0]", "arc_beta[0]"],
        "control_units": ["1", "rad", "rad"],
        "target_cov_before": spd(rng, 3, [5e3, 2e-4, 3e-5]),
        "target_cov_after": spd(rng, 3, [4e2, 2e-5, 4e-6]),
        "target_cov_knowledge": spd(rng, 3, [3e2, 1e-5, 3e-6]),
        "correction_cov": spd(rng, 3, [4e-3, 2e-3, 3e-3]),
        "execution_cov": spd(rng, 3, [1e-3, 5e-4, 5e-4]),
        "dv_mean_km_s": 3.3e-3,
        "dv_99_km_s": 8.6e-3,
        "dv_rms_km_s": 3.9e-3,
        "propellant_sigma_kg": 0.31,
    }


SOURCES = [
    "a-priori state",
    "mu[sun]",
    "doppler2 noise",
    "range2 noise",
    "thrust noise",
    "execution errors",
    "station locations",
    "solar pressure",
]


def synthetic(r: dict, seed: int = 7) -> dict:
    """``r`` plus ``guidance`` (tcm1 impulsive at 1 d, arc1 primary at 2.5 d, tcm2 impulsive
    at 3.5 d), ``control`` (1.3 × the true covariance) and ``budget`` (3 outputs, 8 sources,
    totals the exact sums: sum_check 0)."""
    rng = np.random.default_rng(seed)
    times = np.asarray(r["times_s"])

    def at(t):
        return int(np.argmin(np.abs(times - t)))

    out = dict(r)
    out["guidance"] = [
        _impulsive(rng, "tcm1", at(1.0 * DAY), 1.0 * DAY, 1.0),
        _low_thrust(rng, at(2.5 * DAY), 2.5 * DAY),
        _impulsive(rng, "tcm2", at(3.5 * DAY), 3.5 * DAY, 0.1),
    ]
    P = 1.3 * np.asarray(r["true"]["P_plus"])
    out["control"] = {"P_plus": P, "sigma": np.sqrt(np.clip(np.einsum("kii->ki", P), 0, None))}
    n_src = len(SOURCES)
    scale = np.array([2e-3, 15.0, 120.0])[:, None] ** 2
    var = rng.uniform(0.0, 1.0, (3, n_src)) ** 3 * scale
    var[0, 3] = -1e-22  # a tiny negative contribution (rounding)
    total = var.sum(axis=1)
    out["budget"] = {
        "outputs": ["tcm1 |dV| rms", "tcm1 b_dot_t after", "final position rss"],
        "units": ["km/s", "km", "km"],
        "sources": list(SOURCES),
        "variance": var,
        "total": total,
        "sum_check": float(np.max(np.abs(var.sum(axis=1) - total) / total)),
    }
    return out
