"""Propagation to a list of output times, with exact sensitivities (FRACAS TRAJ, STMGEN, PTRAN).

``propagate`` integrates x = (r km, v km/s, m kg) from ``t_out[0]`` through the output
times in order (forward or backward).  ``propagate_with_sensitivities`` also returns, by
forward-mode automatic differentiation through the integrator, the state transition
matrix and the parameter matrix between consecutive output times and from the start:

    stm_step[k] = dx(t_k)/dx(t_{k-1}),   par_step[k] = dx(t_k)/dp  (x(t_{k-1}) held fixed)
    stm[k] = stm_step[k] stm[k-1],      par[k] = stm_step[k] par[k-1] + par_step[k]

Each segment restarts from the state through ``encke.restart_from_state`` while keeping the
conic of the continued run, so the primal trajectory is the same as one uninterrupted
propagation and every derivative (including d/dmu through the conic) is exact.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401
from fracas.dynamics.model import ForceModel, Params
from fracas.dynamics.parameters import get_values, set_values
from fracas.integrate import encke


class Trajectory(NamedTuple):
    """Outputs of one propagation (see module docstring); NaN rows after an early stop."""

    t: jax.Array  # (n,) s from the epoch
    x: jax.Array  # (n, 7) r km, v km/s, m kg relative to primary[k]
    primary: jax.Array  # (n,) body index
    t_final: jax.Array
    x_final: jax.Array  # (7,)
    primary_final: jax.Array
    status: jax.Array  # 0 final time, 1 stop condition, 2 max steps, 3 non-finite
    n_steps: jax.Array
    n_rect: jax.Array
    n_reject: jax.Array = 0  # steps rejected by the error control (tolerance step control)
    # yaw switch (``ForceModel.yaw_switch``; :func:`propagate` only): flips located up to each
    # output time (n,), and the time (s) of the last of them (n,) (NaN before the first)
    n_flips: jax.Array = 0
    t_flip: jax.Array = float("nan")


class Sensitivities(NamedTuple):
    """State transition and parameter matrices at the output times (rows/cols: r, v, m)."""

    stm_step: jax.Array  # (n, 7, 7)
    stm: jax.Array  # (n, 7, 7)
    par_step: jax.Array  # (n, 7, np)
    par: jax.Array  # (n, 7, np)


def _segment(model, params, ephem, epoch_et, carry, x, t_end, radius_sign):
    """Advance from state x (on carry's conic) to t_end; returns (x_end, carry_end)."""
    c = encke.restart_from_state(model, params, carry, x)
    c = encke.advance(model, params, ephem, epoch_et, c, t_end, radius_sign)
    return encke.state_of(c), c


def _finish(model, outs, c_final, t_out, flips=(0, float("nan"))):
    xs, ts, prim, valid = outs
    nan = jnp.nan
    xs = jnp.where(valid[:, None], xs, nan)
    ts = jnp.where(valid, ts, nan)
    return Trajectory(
        t=ts,
        x=xs,
        primary=prim,
        t_final=c_final.t,
        x_final=encke.state_of(c_final),
        primary_final=c_final.primary,
        status=c_final.status,
        n_steps=c_final.n_steps,
        n_rect=c_final.n_rect,
        n_reject=c_final.n_reject,
        n_flips=flips[0],
        t_flip=flips[1],
    )


#: the traced integrator settings (:func:`split_model`'s ``dyn``, in this order) and their dtypes
_TRACED_SETTINGS = (
    ("c_nom", np.float64),
    ("dt_max_s", np.float64),
    ("rect_ratio", np.float64),
    ("eps_t_s", np.float64),
    ("max_steps", np.int32),
    ("tolerance", np.float64),
)


def split_model(model: ForceModel) -> tuple[ForceModel, tuple[Any, ...]]:
    """(static model, dynamic integrator settings): c_nom, dt_max, the rectification ratio,
    eps_t, max_steps and the tolerance are traced values, so changing them does not
    recompile; method, formulation and step control stay static."""
    st = model.integrator

    # numpy scalars (creating jax scalars here costs ~0.2 ms each per call); traced values
    # (settings batched by propagate_batch) pass through as they are
    def scalar(v: Any, dtype: type) -> Any:
        return v if isinstance(v, jax.core.Tracer) else dtype(v)

    dyn = tuple(scalar(getattr(st, name), dtype) for name, dtype in _TRACED_SETTINGS)
    return dataclasses.replace(model, integrator=st.static_part()), dyn


def join_model(static: ForceModel, dyn: Sequence[Any]) -> ForceModel:
    """Inverse of :func:`split_model` inside a trace."""
    traced = {name: value for (name, _), value in zip(_TRACED_SETTINGS, dyn, strict=True)}
    return dataclasses.replace(static, integrator=dataclasses.replace(static.integrator, **traced))


#: Output-time counts are padded (the last time repeated: zero-length segments, a few
#: microseconds each) to the first of these sizes that holds them, then to powers of two, so a
#: run compiles each propagation program at most twice whatever its numbers of output times
#: (issue 33: the main job compiled ``_propagate_var`` for 2, 3, 512, 1024 and 2048 outputs).
OUTPUT_BUCKETS = (64, 4096)


def output_bucket(n: int) -> int:
    """The padded output count for ``n`` output times (:data:`OUTPUT_BUCKETS`)."""
    for b in OUTPUT_BUCKETS:
        if n <= b:
            return b
    return 1 << (int(n) - 1).bit_length()


def _padded_times(t_out) -> tuple[np.ndarray | jax.Array, int]:
    """(t_out padded to :func:`output_bucket` with its last time, its own length)."""
    n = int(np.shape(t_out)[0])
    nb = output_bucket(n)
    if nb == n:
        return t_out, n
    if isinstance(t_out, jax.core.Tracer):
        return jnp.concatenate([t_out, jnp.repeat(t_out[-1:], nb - n)]), n
    t = np.asarray(t_out, np.float64)
    return np.concatenate([t, np.repeat(t[-1:], nb - n)]), n


#: the per-output fields (first axis: the output times) of the scans' results
_PER_OUTPUT = {"t", "x", "primary", "n_flips", "t_flip", "stm_step", "stm", "par_step", "par"}


def _cut(tree, n: int):
    """A Trajectory / Sensitivities with its per-output arrays cut back to ``n`` outputs."""
    return tree._replace(
        **{k: v[:n] for k, v in tree._asdict().items() if k in _PER_OUTPUT and getattr(v, "ndim", 0) >= 1}
    )


def propagate(model: ForceModel, params: Params, ephem, epoch_et_s, x0, t_out) -> Trajectory:
    """Propagate x0 (at t_out[0], s from the epoch ``epoch_et_s`` TDB s past J2000) through t_out.

    Jitted once per static model structure and output bucket (:data:`OUTPUT_BUCKETS`;
    integrator constants are traced).
    """
    static, dyn = split_model(model)
    t_pad, n = _padded_times(t_out)
    return _cut(_propagate(static, dyn, params, ephem, epoch_et_s, x0, t_pad), n)


@partial(jax.jit, static_argnums=(0,))
def _propagate(static: ForceModel, dyn, params: Params, ephem, epoch_et_s, x0, t_out) -> Trajectory:
    model = join_model(static, dyn)
    t_out = jnp.asarray(t_out, jnp.float64)
    x0 = jnp.asarray(x0, jnp.float64)
    c0, rs = encke.init_carry(model, params, ephem, epoch_et_s, t_out[0], x0)

    def step(carry, t_end):
        c = carry
        x = encke.state_of(c)
        x1, c1 = _segment(model, params, ephem, epoch_et_s, jax.lax.stop_gradient(c), x, t_end, rs)
        valid = ~c1.done | (c1.status == encke.STATUS_OK)
        valid = valid & (jnp.abs(c1.t - t_end) < model.integrator.eps_t_s)
        return c1, (x1, c1.t, c1.primary, valid, c1.n_flips, c1.t_flip)

    c_final, outs = jax.lax.scan(step, c0, t_out)
    return _finish(model, outs[:4], c_final, t_out, outs[4:])


def propagate_with_sensitivities(
    model: ForceModel,
    params: Params,
    ephem,
    epoch_et_s,
    x0,
    t_out,
    param_labels: Sequence[str] = (),
    method: str = "auto",
) -> tuple[Trajectory, Sensitivities]:
    """As :func:`propagate`, plus STMs and parameter matrices (FRACAS STMGEN).

    ``param_labels``: labels from :mod:`fracas.params` (e.g. ``"mu[sun]"``, ``"thrust_scale"``,
    ``"arc_bias_in_rad[0]"``); the parameter matrices have one column per label.

    ``method``: ``"ad"`` -- forward-mode automatic differentiation through the integrator
    (every model); ``"variational"`` -- the explicit variational equations integrated with the
    same steps (``highorder.variational_supported`` models: Cowell, any method -- DOP853 with
    thrust, mass and arcs included --, no impulses, no located events, no switch- or
    impulse-time labels); ``"auto"`` -- variational where supported, else AD.
    Both give the derivative of the same discrete map at fixed step sizes (equal to rounding;
    tests/integrate/test_variational_stm.py).
    """
    from fracas.integrate import highorder

    static, dyn = split_model(model)
    if method not in ("auto", "ad", "variational"):
        raise ValueError(f"method = {method!r}: expected 'auto', 'ad' or 'variational'")
    supported = highorder.variational_supported(model, param_labels)
    if method == "variational" and not supported:
        raise ValueError(
            "explicit variational equations need Cowell, no impulses, no located events and no"
            " switch- or impulse-time parameters"
        )
    t_pad, n = _padded_times(t_out)
    run = _propagate_var if method == "variational" or (method == "auto" and supported) else _propagate_sens
    traj, sens = run(static, dyn, params, ephem, epoch_et_s, x0, t_pad, tuple(param_labels))
    return _cut(traj, n), _cut(sens, n)


def _compose(model, c1, x1, jx, jp, stm, par, t_end):
    """One output of the sensitivity scans: stm[k] = stm_step[k] stm[k-1], par[k] = stm_step[k]
    par[k-1] + par_step[k], and whether the segment reached its end time."""
    stm1 = jx @ stm
    par1 = jx @ par + jp
    valid = (~c1.done | (c1.status == encke.STATUS_OK)) & (jnp.abs(c1.t - t_end) < model.integrator.eps_t_s)
    return (c1, stm1, par1), (x1, c1.t, c1.primary, valid, jx, stm1, jp, par1)


def _scan_segments(model, step, c0, n_p, t_out):
    """Run ``step`` over the output times; NaN sensitivities after an early stop."""
    init = (c0, jnp.eye(7), jnp.zeros((7, n_p)))
    (c_final, _, _), outs = jax.lax.scan(step, init, t_out)
    x1, t1, prim, valid, jx, stm, jp, par = outs
    traj = _finish(model, (x1, t1, prim, valid), c_final, t_out)
    nanm = lambda a: jnp.where(valid[:, None, None], a, jnp.nan)  # noqa: E731
    return traj, Sensitivities(nanm(jx), nanm(stm), nanm(jp), nanm(par))


@partial(jax.jit, static_argnums=(0, 7))
def _propagate_var(static, dyn, params, ephem, epoch_et_s, x0, t_out, param_labels):
    model = join_model(static, dyn)
    t_out = jnp.asarray(t_out, jnp.float64)
    x0 = jnp.asarray(x0, jnp.float64)
    labels = tuple(param_labels)
    n_p = len(labels)
    c0, rs = encke.init_carry(model, params, ephem, epoch_et_s, t_out[0], x0)
    phi0 = jnp.eye(7, 7 + n_p)
    c0 = c0._replace(phi=phi0)

    def step(state, t_end):
        c, stm, par = state
        c1 = encke.advance(model, params, ephem, epoch_et_s, c._replace(phi=phi0), t_end, rs, var_labels=labels)
        x1 = encke.state_of(c1)
        jx, jp = c1.phi[:, :7], c1.phi[:, 7:]
        return _compose(model, c1, x1, jx, jp, stm, par, t_end)

    return _scan_segments(model, step, c0, n_p, t_out)


@partial(jax.jit, static_argnums=(0, 7))
def _propagate_sens(static, dyn, params, ephem, epoch_et_s, x0, t_out, param_labels):
    model = join_model(static, dyn)
    t_out = jnp.asarray(t_out, jnp.float64)
    x0 = jnp.asarray(x0, jnp.float64)
    labels = tuple(param_labels)
    p_sel = get_values(params, labels, model)
    c0, rs = encke.init_carry(model, params, ephem, epoch_et_s, t_out[0], x0)
    n_p = len(labels)

    def seg(x, p, carry, t_end):
        prm = set_values(params, labels, p, model)
        x1, c1 = _segment(model, prm, ephem, epoch_et_s, carry, x, t_end, rs)
        return x1, c1

    def step(state, t_end):
        c, stm, par = state
        x = encke.state_of(c)
        cs = jax.lax.stop_gradient(c)
        (jx, jp), c1 = jax.jacfwd(lambda xx, pp: seg(xx, pp, cs, t_end), argnums=(0, 1), has_aux=True)(x, p_sel)
        x1 = encke.state_of(c1)
        return _compose(model, c1, x1, jx, jp, stm, par, t_end)

    return _scan_segments(model, step, c0, n_p, t_out)


def finite_difference_sensitivities(
    model: ForceModel,
    params: Params,
    ephem,
    epoch_et_s,
    x0,
    t_out,
    param_labels: Sequence[str] = (),
    state_steps=(1e-3, 1e-3, 1e-3, 1e-6, 1e-6, 1e-6, 1e-3),
    param_steps: Sequence[float] | None = None,
):
    """Central finite differences of the final output state (FRACAS PTRAN), for cross-checks.

    Perturbs x0 by ``state_steps`` (km, km/s, kg) and each parameter by ``param_steps``
    (default 1e-6 relative, or 1e-6 absolute for zero-valued parameters).  Returns
    (stm (7,7), par (7,np)) from t_out[0] to t_out[-1].  One propagation per +/- perturbation
    (the jitted ``propagate`` is traced once).
    """
    labels = tuple(param_labels)
    x0 = np.asarray(x0, float)
    base = np.asarray(get_values(params, labels, model), float)
    if param_steps is None:
        param_steps = [1e-6 * abs(b) if b != 0 else 1e-6 for b in base]
    stm = np.zeros((7, 7))
    for j, h in enumerate(state_steps):
        e = np.zeros(7)
        e[j] = h
        xp = np.asarray(propagate(model, params, ephem, epoch_et_s, x0 + e, t_out).x[-1])
        xm = np.asarray(propagate(model, params, ephem, epoch_et_s, x0 - e, t_out).x[-1])
        stm[:, j] = (xp - xm) / (2 * h)
    par = np.zeros((7, len(labels)))
    for j, h in enumerate(param_steps):
        vp = base.copy()
        vp[j] += h
        vm = base.copy()
        vm[j] -= h
        pp = set_values(params, labels, jnp.asarray(vp), model)
        pm = set_values(params, labels, jnp.asarray(vm), model)
        xp = np.asarray(propagate(model, pp, ephem, epoch_et_s, x0, t_out).x[-1])
        xm = np.asarray(propagate(model, pm, ephem, epoch_et_s, x0, t_out).x[-1])
        par[:, j] = (xp - xm) / (2 * h)
    return stm, par


def final_state_jacobian(
    model: ForceModel,
    params: Params,
    ephem,
    epoch_et_s,
    x0,
    t_end,
    param_labels: Sequence[str],
    dx0_du,
    dp_du,
) -> tuple[jax.Array, jax.Array]:
    """(x(t_end) (7,), dx(t_end)/du (7, M)) for controls u that move the initial state by
    dx0_du (7, M) and the labelled parameters by dp_du (L, M) (TOM's FEGS by AD).

    Forward-mode AD through the integrator, like :func:`propagate_with_sensitivities`, but
    with only the M control directions as tangents instead of the 7 + L columns of the full
    STM and parameter matrix (the same derivative of the same discrete map: equal to
    rounding to Phi dx0_du + Theta dp_du, tests/integrate/test_final_jacobian.py).
    """
    static, dyn = split_model(model)
    return _final_jac(
        static,
        dyn,
        params,
        ephem,
        epoch_et_s,
        jnp.asarray(x0, jnp.float64),
        jnp.asarray(t_end, jnp.float64),
        tuple(param_labels),
        jnp.asarray(dx0_du, jnp.float64),
        jnp.asarray(dp_du, jnp.float64),
    )


@partial(jax.jit, static_argnums=(0, 7))
def _final_jac(static, dyn, params, ephem, epoch_et_s, x0, t_end, param_labels, dx0_du, dp_du):
    model = join_model(static, dyn)
    labels = tuple(param_labels)
    p0 = get_values(params, labels, model)
    t0 = jnp.zeros(())

    def run(delta):
        # the initial carry inside the differentiated map: an impulse at t = 0 (applied by
        # init_carry) then depends on its controls like any other
        x = x0 + dx0_du @ delta
        prm = set_values(params, labels, p0 + dp_du @ delta, model) if labels else params
        c0, rs = encke.init_carry(model, prm, ephem, epoch_et_s, t0, x)
        c1 = encke.advance(model, prm, ephem, epoch_et_s, c0, t_end, rs)
        return encke.state_of(c1)

    delta0 = jnp.zeros(dx0_du.shape[1])
    return run(delta0), jax.jacfwd(run)(delta0)
