"""Stages as data (fracas.integrate.stages, issue 23) against a plain step written here from
the published tableaux (fracas.integrate.tableaux, unfolded, every stage evaluated).

The reference is a numpy loop over the original coefficients; the kernels fold repeated
RKN stages, append DOP853's error stage as a coupling row and run the stages under
``lax.fori_loop`` or unrolled.  The same arithmetic in a different order: equal to 1e-13
relative (rounding of sums of ~17 terms of size |r| ~ 7000 km, eps 2.2e-16, with margin).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fracas.integrate import stages as S
from fracas.integrate import tableaux as T

MU = 398600.4418
R0 = np.array([7000.0, 300.0, -200.0])
V0 = np.array([0.1, 7.4, 1.0])
H = 120.0  # s: a typical DPRKN12 LEO step at tol 1e-8 is ~1200 s; any h tests the algebra


def accel_np(r):
    return -MU * r / np.linalg.norm(r) ** 3


def accel_v_np(r, v):
    # a velocity-dependent term (drag-like) so that a first-order method's stages use v
    return accel_np(r) - 1e-7 * v


def reference_nystrom(tab, r, v, h):
    ks = []
    for i in range(tab.stages):
        ri = r + tab.c[i] * h * v + h * h * sum((tab.a_bar[i, j] * ks[j] for j in range(i)), np.zeros(3))
        ks.append(accel_np(ri))
    ks = np.array(ks)
    r1 = r + h * v + h * h * tab.bbar @ ks
    v1 = v + h * tab.b @ ks
    err = None if tab.bbar_low is None else (h * h * tab.ebar @ ks, h * tab.e @ ks)
    return r1, v1, err


def reference_rk(tab, r, v, h):
    y = np.concatenate([r, v])

    def f(yy):
        return np.concatenate([yy[3:], accel_v_np(yy[:3], yy[3:])])

    ks = []
    for i in range(tab.stages):
        yi = y + h * sum((tab.a[i, j] * ks[j] for j in range(i)), np.zeros(6))
        ks.append(f(yi))
    y1 = y + h * np.asarray(tab.b) @ np.array(ks)
    ks.append(f(y1))
    return y1, h * np.asarray(tab.e) @ np.array(ks), h * np.asarray(tab.e_aux) @ np.array(ks)


def _rel(a, b):
    return np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(np.asarray(b)).max()


@pytest.mark.parametrize("tab", [T.RKN4, T.DPRKN8, T.DPRKN12], ids=lambda t: t.name)
@pytest.mark.parametrize("unroll", [False, True])
def test_nystrom_stages_equal_the_plain_tableau_step(tab, unroll):
    plan = S.plan_of_tableau(tab)
    calls = []

    def stage(i, ri):
        calls.append(i)
        return -MU * ri / jnp.linalg.norm(ri) ** 3

    q, p = jnp.asarray(R0), jnp.asarray(V0)
    ks = S.nystrom_stages(stage, q, p, H, plan, unroll=unroll)
    r1 = q + H * p + H * H * ks.weighted(plan.bbar)
    v1 = p + H * ks.weighted(plan.b)
    r_ref, v_ref, err = reference_nystrom(tab, R0, V0, H)
    assert _rel(r1, r_ref) < 1e-13 and _rel(v1, v_ref) < 1e-13
    if err is not None:
        # error estimates are differences of nearly equal sums: compare to the state's size
        assert np.abs(H * H * np.asarray(ks.weighted(plan.ebar)) - err[0]).max() < 1e-13 * np.abs(R0).max()
        assert np.abs(H * np.asarray(ks.weighted(plan.e)) - err[1]).max() < 1e-13 * np.abs(V0).max()
    # traced once under the loop; once per distinct stage unrolled
    assert len(calls) == (plan.stages if unroll else 1)


def test_repeated_rkn_stages_are_folded():
    """RKN4's stages 2 and 3 (same node, same coupling) are one evaluation; DPRKN12 has none
    to fold (17 distinct stages: Dormand, El-Mikkawy & Prince 1987)."""
    assert S.plan_of_tableau(T.RKN4).stages == 3
    assert S.plan_of_tableau(T.DPRKN12).stages == 17
    for tab in (T.RKN4, T.DPRKN8, T.DPRKN12):
        plan = S.plan_of_tableau(tab)
        assert np.all(np.triu(plan.a) == 0)  # still explicit after folding
        assert plan.nodes[-1] == 1.0 and np.all(plan.nodes[plan.node] == plan.c)


@pytest.mark.parametrize("unroll", [False, True])
def test_dop853_stages_equal_the_plain_tableau_step(unroll):
    tab = T.DOP853
    plan = S.plan_of_tableau(tab)
    assert plan.stages == tab.stages + 1 and plan.first_order

    def stage(i, y):
        r, v = y
        return v, -MU * r / jnp.linalg.norm(r) ** 3 - 1e-7 * v

    ks = S.rk_stages(stage, (jnp.asarray(R0), jnp.asarray(V0)), H, plan, unroll=unroll)
    kr, kv = ks.part(0), ks.part(1)
    y1 = np.concatenate([R0 + H * np.asarray(kr.weighted(plan.b)), V0 + H * np.asarray(kv.weighted(plan.b))])
    y_ref, e5, e3 = reference_rk(tab, R0, V0, H)
    assert _rel(y1, y_ref) < 1e-13
    e5_k = np.concatenate([H * np.asarray(kr.weighted(plan.e)), H * np.asarray(kv.weighted(plan.e))])
    e3_k = np.concatenate([H * np.asarray(kr.weighted(plan.e_aux)), H * np.asarray(kv.weighted(plan.e_aux))])
    assert np.abs(e5_k - e5).max() < 1e-13 * np.abs(y_ref).max()
    assert np.abs(e3_k - e3).max() < 1e-13 * np.abs(y_ref).max()
    # the last stage is f(t + h, y1): its velocity part is v1
    np.testing.assert_allclose(np.asarray(ks.last()[0]), y_ref[3:], rtol=1e-13)


def test_loop_and_unrolled_steps_are_the_same_under_vmap():
    """The two forms of the propagator's step on a batch of states (what propagate_batch and a
    single propagation compile): the same numbers to rounding."""
    plan = S.plan_of_tableau(T.DPRKN12)
    rng = np.random.default_rng(3)
    rs = R0 + rng.normal(0, 50, (16, 3))
    vs = V0 + rng.normal(0, 0.01, (16, 3))

    def one(r, v, unroll):
        ks = S.nystrom_stages(lambda i, ri: -MU * ri / jnp.linalg.norm(ri) ** 3, r, v, H, plan, unroll=unroll)
        return r + H * v + H * H * ks.weighted(plan.bbar)

    a = jax.vmap(lambda r, v: one(r, v, False))(rs, vs)
    b = jax.vmap(lambda r, v: one(r, v, True))(rs, vs)
    assert _rel(a, b) < 1e-13
