"""The Clohessy-Wiltshire STM (fracas.dynamics.relative_motion) against two-body motion
(digest ``unf-apollo.md`` §C.3 item 3).

References:

* the LINEARIZED two-body propagation: the exact two-body STM (forward-mode AD through the
  universal-variable Kepler solver, itself tested against scipy elsewhere) of a circular
  reference, mapped into the rotating Hill frame.  For a circular orbit the two are the same
  linear map, so they agree to rounding: 1e-9 relative (the Hill-frame transform and
  Kepler's solution each carry ~1e-13; the STM entries reach n t ~ 6, times 1e3 margin);
* the NONLINEAR difference of two Kepler propagations 1000 ft (0.3048 km) apart, over one
  lunar-orbit period: the CW error is second order, ~ (delta / r) ~ 2e-4 of the separation;
  the bound 1e-3 relative is five times that.
"""

import jax
import jax.numpy as jnp
import numpy as np

from fracas.dynamics.kepler import kepler
from fracas.dynamics.relative_motion import cw_stm, from_hill, to_hill

MU = 4902.800  # km^3/s^2, Moon (fracas.constants)
R0 = 1738.0 + 110.0  # km, a ~60 n.mi. lunar orbit


def _target():
    v = np.sqrt(MU / R0)
    return np.array([R0, 0.0, 0.0, 0.0, v * np.cos(0.3), v * np.sin(0.3)])


def _prop(x, t):
    r, v = kepler(jnp.asarray(x[:3]), jnp.asarray(x[3:]), jnp.float64(t), jnp.float64(MU))[:2]
    return jnp.concatenate([r, v])


def test_cw_stm_equals_linearized_two_body_in_hill_frame():
    xt = _target()
    n = np.sqrt(MU / R0**3)
    for t in (300.0, 1800.0, 2 * np.pi / n):
        xt1 = _prop(xt, t)
        # linear map Hill(t0) -> inertial(t0) -> Kepler STM -> Hill(t1), by AD
        f = lambda rel, xt1=xt1, t=t: to_hill(xt1, _prop(from_hill(xt, rel), t))
        J = np.asarray(jax.jacfwd(f)(jnp.zeros(6)))
        cw = np.asarray(cw_stm(n, t))
        assert np.max(np.abs(J - cw)) <= 1e-9 * np.max(np.abs(cw)), t


def test_cw_stm_against_nonlinear_two_body_for_1000_ft_separation():
    xt = _target()
    n = np.sqrt(MU / R0**3)
    period = 2 * np.pi / n
    rng = np.random.default_rng(0)
    d = rng.standard_normal(3)
    rel0 = np.r_[0.3048 * d / np.linalg.norm(d), 0.3048 * n * rng.standard_normal(3)]
    for t in np.linspace(0.1, 1.0, 5) * period:
        rel_true = np.asarray(to_hill(_prop(xt, t), _prop(from_hill(xt, rel0), t)))
        rel_cw = np.asarray(cw_stm(n, t)) @ rel0
        assert np.linalg.norm(rel_cw[:3] - rel_true[:3]) <= 1e-3 * np.linalg.norm(rel_true[:3]) + 1e-3 * 0.3048


def test_hill_transform_round_trip():
    xt = _target()
    x = xt + np.r_[1.0, -2.0, 0.5, 1e-3, 2e-3, -1e-3]
    assert np.allclose(np.asarray(from_hill(xt, to_hill(xt, x))), x, rtol=1e-14, atol=1e-12)
