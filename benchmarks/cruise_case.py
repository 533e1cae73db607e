"""The 300-day heliocentric solar-electric cruise shared by the core benchmarks
(bench_core.py, bench_highorder.py): Sun primary; Venus, Earth, Mars, Jupiter perturbing
(DE421); two thrust arcs (tangential for 100 days, then 10 deg in-plane / 5 deg out-of-plane
from day 150), 10 kW at 1 AU, efficiency 0.65, exhaust velocity 30 km/s; and its scipy DOP853
reference on the plain equations (tests/reference.py right-hand side with a two-part Julian
date).  Import after the process has set its XLA flags (this imports jax through fracas).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import tests.reference as ref  # noqa: E402
from fracas import constants as C  # noqa: E402
from fracas.dynamics.ephemeris import build_ephemeris, calendar_to_et  # noqa: E402
from fracas.dynamics.model import ForceModel, IntegratorSettings, default_params  # noqa: E402

DAY = 86400.0


def helio_position_2part(body: str, et_s: float) -> np.ndarray:
    """tests/reference.helio_position with a two-part Julian date (2451545, et/86400).

    The one-part JD of tests/reference.py rounds time to ~40 us (float64 spacing at JD 2.46e6):
    ~1 m of jitter in the Earth's position, enough to leave ~12 m of error in the 300-day
    cruise reference at rtol 1e-13.  Same jplephem/DE421 data otherwise.
    """
    e = ref._eph()
    jd2 = et_s / DAY
    if body == "sun":
        return np.zeros(3)
    sun = e.position("sun", 2451545.0, jd2)
    if body in ("earth", "moon"):
        emb = e.position("earthmoon", 2451545.0, jd2)
        moon = e.position("moon", 2451545.0, jd2)
        k = 1.0 / (1.0 + e.EMRAT) if body == "earth" else -e.EMRAT / (1.0 + e.EMRAT)
        pos = emb - moon * k
    else:
        pos = e.position(body, 2451545.0, jd2)
    return np.ravel(pos - sun)


ref.helio_position = helio_position_2part  # used by ref.cowell_rhs_factory at call time

CR_BODIES = ("sun", "venus", "earth", "mars", "jupiter")
CR_ET0 = calendar_to_et("2030-06-01T00:00:00")
CR_T = np.array([0.0, 300 * DAY])
CR_BREAKS = [0.0, 100 * DAY, 150 * DAY, 300 * DAY]
_e = helio_position_2part("earth", CR_ET0)
_ve = (helio_position_2part("earth", CR_ET0 + 60) - helio_position_2part("earth", CR_ET0 - 60)) / 120
_vh = _ve / np.linalg.norm(_ve)
CR_X0 = np.concatenate([_e + 1.5e6 * _vh, _ve + 1.0 * _vh, [1000.0]])
CR_EPH = build_ephemeris(CR_BODIES, CR_ET0, CR_ET0 + 300 * DAY)


def cruise_model(dt_max_days: float, c_nom: float = 0.05) -> ForceModel:
    return ForceModel(
        bodies=CR_BODIES,
        primary=0,
        third_bodies=(1, 2, 3, 4),
        thrust=True,
        velocity_dependent=True,
        n_arcs=2,
        integrator=IntegratorSettings(c_nom=c_nom, dt_max_s=dt_max_days * DAY),
    )


CR_P = default_params(
    cruise_model(0.5),
    power_kw=10.0,
    efficiency=0.65,
    exhaust_velocity_km_s=30.0,
    arc_t_on=[0, 150 * DAY],
    arc_t_off=[100 * DAY, 300 * DAY],
    arc_alpha=[0, np.radians(10)],
    arc_beta=[0, np.radians(5)],
)


def cruise_states(n: int, seed: int = 1) -> np.ndarray:
    """Row 0 the nominal departure (1.5e6 km ahead of the Earth, +1 km/s); then +-1000 km, +-5 m/s."""
    rng = np.random.default_rng(seed)
    x = np.tile(CR_X0, (n, 1))
    x[1:, :3] += rng.normal(0.0, 1000.0, (n - 1, 3))
    x[1:, 3:6] += rng.normal(0.0, 0.005, (n - 1, 3))
    return x


def _cruise_rhs():
    mus = {b: C.BODIES[b].mu_km3_s2 for b in CR_BODIES}
    fac = lambda t: 1.0 if (t < 100 * DAY or t >= 150 * DAY) else 0.0  # noqa: E731
    al = lambda t: 0.0 if t < 100 * DAY else np.radians(10)  # noqa: E731
    be = lambda t: 0.0 if t < 100 * DAY else np.radians(5)  # noqa: E731
    return ref.cowell_rhs_factory(
        mus["sun"],
        "sun",
        CR_BODIES[1:],
        mus,
        epoch_et=CR_ET0,
        thrust={"p0_kw": 10.0, "eta": 0.65, "c": 30.0, "alpha": al, "beta": be, "factor": fac},
    )


def dop853(rhs, y0, breaks, rtol, atol):
    """DOP853 through the breaks: (final state, accepted steps)."""
    y = np.asarray(y0, float)
    steps = 0
    for ta, tb in zip(breaks[:-1], breaks[1:]):
        sol = solve_ivp(rhs, (ta, tb), y, method="DOP853", rtol=rtol, atol=atol)
        assert sol.success, sol.message
        y = sol.y[:, -1]
        steps += len(sol.t) - 1
    return y, steps
