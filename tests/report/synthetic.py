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


# --- small synthetic products for the plot tests (no JAX, no propagation) ---------------------

MU_EARTH = 398600.4418
MU_SUN = 132_712_440_040.944


def conic_samples(r0, v0, t_s, mu: float = MU_EARTH) -> tuple[np.ndarray, np.ndarray]:
    """States (n, 3) at times ``t_s`` on the conic through (r0, v0)."""
    from fracas.report._conic import kepler_step

    n = len(t_s)
    return kepler_step(np.tile(r0, (n, 1)), np.tile(v0, (n, 1)), np.asarray(t_s, float), mu)


def trajectory_data(kind: str):
    """A :class:`~fracas.products.TrajectoryData`: ``"leo"`` (two-body, a day sampled every
    14.4 min), ``"spiral"`` (20 days of circular orbits growing from 7000 to 8600 km, mass
    falling: 290 revolutions) or ``"escape"`` (about Earth, then about the Sun)."""
    from fracas.products import TrajectoryData

    if kind == "leo":
        t = np.arange(0.0, DAY + 1.0, 0.01 * DAY)
        r, v = conic_samples(np.array([7000.0, 0, 0]), np.array([0.0, 7.5, 1.0]), t)
        prim = ("earth",) * len(t)
        m = np.full(len(t), 1000.0)
    elif kind == "spiral":
        t = np.arange(0.0, 20 * DAY + 1.0, 0.01 * DAY)
        a = 7000.0 + 1600.0 * t / t[-1]
        n = np.sqrt(MU_EARTH / a**3)
        th = np.cumsum(np.concatenate([[0.0], np.diff(t) * n[1:]]))
        inc = np.radians(28.5)
        u = np.stack([np.cos(th), np.sin(th) * np.cos(inc), np.sin(th) * np.sin(inc)], axis=-1)
        w = np.stack([-np.sin(th), np.cos(th) * np.cos(inc), np.cos(th) * np.sin(inc)], axis=-1)
        r = a[:, None] * u
        v = (a * n)[:, None] * w
        prim = ("earth",) * len(t)
        m = 1000.0 - 25.0 * t / t[-1]
    elif kind == "escape":
        t1 = np.linspace(0.0, 3 * DAY, 40)
        r1, v1 = conic_samples(np.array([7000.0, 0, 0]), np.array([0.0, 11.6, 0.0]), t1)
        t2 = np.linspace(3 * DAY, 300 * DAY, 31)[1:]
        r2, v2 = conic_samples(np.array([1.5e8, 0, 0]), np.array([0.0, 32.0, 0.5]), t2 - t2[0], MU_SUN)
        t = np.concatenate([t1, t2])
        r, v = np.concatenate([r1, r2]), np.concatenate([v1, v2])
        prim = ("earth",) * len(t1) + ("sun",) * len(t2)
        m = np.linspace(1000.0, 900.0, len(t))
    else:
        raise ValueError(kind)
    return TrajectoryData(
        epoch_et_s=0.0,
        t_s=t,
        r_km=r,
        v_km_s=v,
        mass_kg=m,
        primary=prim,
        bodies=("sun", "earth"),
        t_final_s=float(t[-1]),
        r_final_km=r[-1],
        v_final_km_s=v[-1],
        mass_final_kg=float(m[-1]),
        primary_final=prim[-1],
        status=0,
        n_steps=len(t),
        n_rect=0,
        centre="earth",
        title=f"synthetic {kind} trajectory with a title as long as the bundled decks' titles",
        integrator="dop853, cowell, tolerance 1e-12",
    )


def team_results(tmp_path) -> dict:
    """A small TEAM results dict (tests/io's synthetic product written and read back)."""
    from fracas.io.team_results import read_team_results, write_team_results
    from tests.io.test_corrupt_files import _team_product

    prod = _team_product(K=40)
    prod = type(prod)(**{**prod.__dict__, "title": "Earth-Mars cruise: tracking, guidance and error budget (main job)"})
    write_team_results(tmp_path / "team.h5", prod)
    return read_team_results(tmp_path / "team.h5")


def tom_results(k: int = 8, grid: bool = True) -> dict:
    """A TOM results dict as :func:`fracas.io.tom_results.read_tom_results` gives it: ``k``
    records, two of them a retried iteration (8 records, 6 iterations by default)."""
    if k == 8:
        it = [1, 2, 3, 3, 4, 5, 5, 6]
        modes = ["T", "T", "T+O", "T", "O", "T+O", "T", "O"]
    else:
        it = list(range(1, k + 1))
        modes = ["T+O"] * k
    rng = np.random.default_rng(1)
    res = {
        "attrs": {"title": "Near-Earth spiral, 7000 -> 9000 km, 2 deg plane change", "converged": 1},
        "iteration": np.array(it),
        "submode": modes,
        "performance_kg": 968.1 + 0.3 * rng.random(k),
        "error_rms": np.logspace(4, -3, k),
        "angle_rad": np.where(np.arange(k) % 3 == 0, np.nan, 1e-3),
        "control_names": ["arc_t_off[1]", "arc_beta[0]", "arc_beta[1]"],
    }
    if grid:
        g = np.linspace(-1.0, 1.0, 7)
        res["grid"] = {
            "gammas": g,
            "pairs": {
                (0, 1): 1.0 + np.add.outer(g**2, g**2),
                (0, 2): 2.0 + np.add.outer(g**2, g),
                (1, 2): 1.5 + np.abs(np.add.outer(g, g)),
            },
        }
    return res


def sweep_table(two_fields: bool = True):
    """A :class:`~fracas.io.sweep_table.SweepTable` of the demo's 3 x 3 grid (one failed
    study), or of one field."""
    from fracas.io.sweep_table import SweepTable

    s = np.repeat([0.005, 0.01, 0.02], 3)
    tau = np.tile(np.geomspace(0.5, 4.0, 3), 3)
    inputs = {"thrust_noise.proportionality.sigma": s, "thrust_noise.proportionality.tau_days": tau}
    if not two_fields:
        inputs = {"thrust_noise.proportionality.sigma": s}
    outs = {
        "position_rss_km": 10 * s * tau**0.5,
        "velocity_rss_km_s": 1e-5 * s / tau,
        "true_position_rss_km": 12 * s * tau**0.4,
        "sigma[thrust_scale]": 0.1 * s,
    }
    status = ["ok"] * 9
    status[4] = "failed"
    return SweepTable(
        index=np.arange(9),
        key=[f"k{i}" for i in range(9)],
        inputs=inputs,
        outputs=outs,
        status=status,
        error=[""] * 9,
        wall_s=np.ones(9),
        units={
            "thrust_noise.proportionality.sigma": "1",
            "thrust_noise.proportionality.tau_days": "d",
            "position_rss_km": "km",
            "velocity_rss_km_s": "km/s",
            "true_position_rss_km": "km",
            "sigma[thrust_scale]": "1",
        },
        attrs={"title": "Earth-Mars cruise: thrust-noise level x correlation time"},
    )


def rendezvous_product():
    """A :class:`~fracas.products.RendezvousProduct` with three roles, marks, a reset, two
    maneuvers and single runs (ft units, as the Apollo example)."""
    from fracas.products import RendezvousProduct

    rng = np.random.default_rng(2)
    K, R, n = 60, 3, 12
    t = np.linspace(0.0, 3600.0, K)
    rms = np.exp(-t / 2000.0)[None, :, None] * np.array([1.0, 1e-3, 0.8, 8e-4, 0.5, 5e-4])[None, None, :]
    rms = rms * np.array([1.0, 1.3, 2.0])[:, None, None]
    z = np.zeros
    return RendezvousProduct(
        title="Apollo 12 LM-active rendezvous: optimum, Schmidt and Apollo filters (R-649)",
        source="apollo12_rendezvous.toml",
        epoch_et_s=0.0,
        centre="moon",
        chaser_name="LM",
        target_name="CSM",
        roles=["solve_for", "consider", "ignore"],
        labels=[f"x{i}" for i in range(n)],
        units=["km"] * n,
        times_s=t,
        marks=rng.random((K, 4)) > 0.5,
        x_chaser=z((K, 6)),
        x_target=z((K, 6)),
        P_true=z((R, K, n, n)),
        P_assumed=z((R, K, n, n)),
        P_true_minus=z((R, K, n, n)),
        P_assumed_minus=z((R, K, n, n)),
        maneuver_names=["TPI", "MCC1"],
        maneuver_time_s=np.array([1500.0, 2400.0]),
        maneuver_arrival_s=np.array([3600.0, 3600.0]),
        maneuver_dv_km_s=np.full((2, 3), 1e-3),
        maneuver_status=np.zeros(2, np.int64),
        maneuver_cov_true=np.tile(np.eye(3) * 1e-8, (R, 2, 1, 1)),
        maneuver_cov_assumed=np.tile(np.eye(3) * 1e-8, (R, 2, 1, 1)),
        reset_times_s=np.array([900.0]),
        n_runs=20,
        team_rms=rms,
        assumed_rms=0.8 * rms,
        run_rms=rms * (1.0 + 0.1 * rng.normal(size=rms.shape)),
        length_unit="ft",
        km_per_unit=0.0003048,
    )
