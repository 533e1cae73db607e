"""The TEAM filter as one jitted ``lax.scan`` over the event schedule (FRACAS COVP, PROP,
FILTER, KSGAIN, WLSGAN, USRGAN), in covariance or square-root (W-matrix) form."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401
from fracas.errors import ConfigError
from fracas.filters import covariance as cov
from fracas.filters import square_root as sqr
from fracas.team.noise_base import bucket
from fracas.team.study import Study

__all__ = ["run_filter", "filter_scan", "reset_state_block", "reset_arrays"]


def _gain(kind, user_gain, layout, Pa, Pnc, H, R):
    if kind == "kalman_schmidt":
        return cov.kalman_schmidt_gain(Pa, H, R, layout), Pnc
    if kind == "wls":
        K, Pnc1 = cov.wls_gain(Pnc, H, R, layout)
        return K, Pnc1
    Kest = jnp.asarray(user_gain(Pa, H, R, layout))
    K = jnp.zeros((layout.n, H.shape[0])).at[: layout.n_est].set(Kest)
    return K, Pnc


def reset_state_block(P, flag, cov6):
    """The assumed-covariance reset (UNF/Apollo W reinitialization, digest unf-apollo.md
    A.6.1, C.1): where ``flag`` > 0 the position/velocity block of P becomes ``cov6`` (6, 6)
    and every correlation of those six states is zeroed; P unchanged otherwise."""
    n = P.shape[0]
    keep = jnp.concatenate([jnp.zeros(6, dtype=P.dtype), jnp.ones(n - 6, dtype=P.dtype)])
    Pr = (P * keep[:, None] * keep[None, :]).at[:6, :6].set(cov6)
    return jnp.where(flag > 0.0, Pr, P)


def _add_exec(P: jax.Array, x: jax.Array, nx: int) -> jax.Array:
    """P with the execution-error covariance ``x`` (nx, nx) added to its state block."""
    return P.at[:nx, :nx].add(x)


def _assumed_update(
    A: jax.Array,
    Pnc: jax.Array,
    phi: jax.Array,
    qa: jax.Array,
    h: jax.Array,
    ra: jax.Array,
    xa: jax.Array,
    fl: jax.Array,
    rc: jax.Array,
    *,
    layout: cov.Layout,
    kind: str,
    square_root: bool,
    user_gain: Callable | None,
    eye_n: jax.Array,
    nx: int,
) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array, jax.Array]:
    """The assumed side of one event (traced inside :func:`_scan`'s step): time update, reset,
    gain, measurement update and execution errors; (Pa_m, Pa_p, the carried A, K, Pnc)."""
    if square_root:
        Wa = sqr.sqrt_time_update(A, phi, qa)
        # refactor only at a reset (lax.cond: the Cholesky is not paid on every step)
        Wa = jax.lax.cond(fl > 0.0, lambda W: sqr.factor(reset_state_block(W @ W.T, fl, rc)), lambda W: W, Wa)
        Pa_m = Wa @ Wa.T
        if kind == "kalman_schmidt":
            K = sqr.sqrt_kalman_schmidt_gain(Wa, h, ra, layout)
        else:
            K, Pnc = _gain(kind, user_gain, layout, Pa_m, Pnc, h, ra)
        Wa1 = sqr.sqrt_time_update(sqr.sqrt_joseph_update(Wa, h, ra, K), eye_n, xa)
        Pa_p = Wa1 @ Wa1.T
        A1 = Wa1
    else:
        Pa_m = reset_state_block(cov.time_update(A, phi, qa), fl, rc)
        K, Pnc = _gain(kind, user_gain, layout, Pa_m, Pnc, h, ra)
        Pa_p = _add_exec(cov.joseph_update(Pa_m, h, ra, K), xa, nx)
        A1 = Pa_p
    return Pa_m, Pa_p, A1, K, Pnc


def _true_update(
    T: jax.Array,
    phit: jax.Array,
    qt: jax.Array,
    h: jax.Array,
    rt: jax.Array,
    xt: jax.Array,
    K: jax.Array,
    *,
    square_root: bool,
    eye_n: jax.Array,
    nx: int,
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The true side of one event with the assumed side's gain K (generalized covariance;
    traced inside :func:`_scan`'s step): (Pt_m, Pt_p, the carried T)."""
    if square_root:
        Wt = sqr.sqrt_time_update(T, phit, qt)
        Wt1 = sqr.sqrt_time_update(sqr.sqrt_joseph_update(Wt, h, rt, K), eye_n, xt)
        return Wt @ Wt.T, Wt1 @ Wt1.T, Wt1
    Pt_m = cov.time_update(T, phit, qt)
    Pt_p = _add_exec(cov.joseph_update(Pt_m, h, rt, K), xt, nx)
    return Pt_m, Pt_p, Pt_p


@partial(jax.jit, static_argnames=("layout", "kind", "gencov", "square_root", "user_gain"))
def _scan(
    P0a,
    P0t,
    phi_aug,
    Qa,
    Qt,
    H,
    Ra,
    Rt,
    Xa=None,
    Xt=None,
    reset_flag=None,
    reset_cov=None,
    phi_t=None,
    *,
    layout,
    kind,
    gencov,
    square_root,
    user_gain=None,
):
    """One pass of the filter over K events.  Xa / Xt (K, nx, nx), optional: maneuver
    execution-error covariance added to the assumed / true knowledge after the event's
    measurement update (guidance events, GUIDM); the ``P_plus`` outputs include it.
    reset_flag (K,), reset_cov (K, 6, 6), optional: assumed-covariance resets applied after
    the time update and before the event's measurements (:func:`reset_state_block`); the
    ``Pa_minus`` outputs are after the reset (the filter's a priori for the marks).
    phi_t (K, n, n), optional: the true covariance's transitions where they differ from the
    filter's (exact Gauss-Markov noise with true correlation times, fracas.team.gm_exact)."""
    n_est = layout.n_est
    eye_n = jnp.eye(layout.n)
    if Xa is None:
        Xa = jnp.zeros_like(Qa)
    if Xt is None:
        Xt = jnp.zeros_like(Qt)
    if reset_flag is None:
        reset_flag = jnp.zeros(Qa.shape[0], dtype=Qa.dtype)
        reset_cov = jnp.zeros((Qa.shape[0], 6, 6), dtype=Qa.dtype)
    nx = Qa.shape[-1]
    same_phi = phi_t is None  # Python-level: the usual program scans one transition per event
    opts = {"square_root": square_root, "eye_n": eye_n, "nx": nx}

    def step(carry, ev):
        A, T, Pnc = carry
        phi, qa, qt, h, ra, rt, xa, xt, fl, rc = ev[:10]
        phit = phi if same_phi else ev[10]
        if kind == "wls":
            Pnc = cov.wls_time_update(Pnc, phi, layout)
        Pa_m, Pa_p, A1, K, Pnc = _assumed_update(
            A, Pnc, phi, qa, h, ra, xa, fl, rc, layout=layout, kind=kind, user_gain=user_gain, **opts
        )
        _, J = cov.innovation(Pa_m, h, ra)
        if gencov:
            Pt_m, Pt_p, T1 = _true_update(T, phit, qt, h, rt, xt, K, **opts)
        else:
            Pt_m = Pt_p = T1 = T
        return (A1, T1, Pnc), (Pa_m, Pa_p, Pt_m, Pt_p, jnp.sqrt(jnp.diagonal(J)))

    if square_root:
        A0, T0 = sqr.factor(P0a), sqr.factor(P0t)
    else:
        A0, T0 = P0a, P0t
    Pnc0 = P0a[:n_est, :n_est]
    xs = (phi_aug, Qa, Qt, H, Ra, Rt, Xa, Xt, reset_flag, reset_cov) + (() if same_phi else (phi_t,))
    _, outs = jax.lax.scan(step, (A0, T0, Pnc0), xs)
    return outs


def _pad_events(K: int, Kp: int, arrays):
    """Append neutral events (identity Φ, zero Q and H, unit R) up to Kp."""
    out = []
    for name, a in arrays:
        if Kp == K:
            out.append(a)
            continue
        extra = np.zeros((Kp - K,) + a.shape[1:])
        if name in ("phi", "R"):
            extra[:] = np.eye(a.shape[-1])
        out.append(np.concatenate([a, extra]))
    return out


def reset_arrays(study: Study, Kp: int) -> tuple[np.ndarray, np.ndarray]:
    """(flag (Kp,), cov (Kp, 6, 6)) of the study's reset events on its schedule (zeros when none)."""
    flag, rcov = np.zeros(Kp), np.zeros((Kp, 6, 6))
    times = study.schedule.times_s
    for t, sig in study.resets:
        k = int(np.argmin(np.abs(times - t)))
        if abs(times[k] - t) <= 1e-3:
            flag[k] = 1.0
            rcov[k] = np.diag(np.asarray(sig, dtype=np.float64) ** 2)
    return flag, rcov


def run_filter(study: Study, phi_aug, Qa, Qt, meas, Xa=None, Xt=None, host: bool = True, *, augmented=None):
    """Run the jitted scan over the schedule (padded to a bucket size); numpy outputs.

    ``augmented``: the exact Gauss-Markov model's noise states (fracas.team.gm_exact), a
    dict with ``layout`` (the study's, three ignore rows more), ``P0_assumed``/``P0_true``,
    ``H`` (K, m, n + 3) and ``phi_true`` (the true covariance's transitions, or None when
    the filter's serve); ``phi_aug``, Qa, Qt are then (K, n + 3, n + 3).

    Xa / Xt (K, nx, nx): execution-error covariances of guidance events (zero elsewhere;
    default none), added to the assumed / true knowledge after the event.  host=False
    returns the padded device arrays (index them at k < K) without copying the histories
    to numpy (the error budget reads a few events of each pass)."""
    K = study.schedule.n
    Kp = bucket(K)
    Xa = np.zeros_like(Qa) if Xa is None else Xa
    Xt = np.zeros_like(Qt) if Xt is None else Xt
    if Xa.shape[-1] < Qa.shape[-1]:  # x-block execution errors beside a full-size Q (noise states)
        d = Qa.shape[-1] - Xa.shape[-1]
        Xa, Xt = (np.pad(np.asarray(X), ((0, 0), (0, d), (0, d))) for X in (Xa, Xt))
    flag, rcov = reset_arrays(study, Kp)
    aug = augmented or {}
    layout = aug.get("layout", study.layout)
    P0a, P0t = aug.get("P0_assumed", study.P0_assumed), aug.get("P0_true", study.P0_true)
    phi_t = aug.get("phi_true")
    phi_aug, Qa, Qt, H, Ra, Rt, Xa, Xt = _pad_events(
        K,
        Kp,
        [
            ("phi", phi_aug),
            ("Q", Qa),
            ("Q", Qt),
            ("H", aug.get("H", meas.H)),
            ("R", meas.R_assumed),
            ("R", meas.R_true),
            ("Q", Xa),
            ("Q", Xt),
        ],
    )
    if phi_t is not None:
        (phi_t,) = _pad_events(K, Kp, [("phi", phi_t)])
    try:
        outs = _scan(
            jnp.asarray(P0a),
            jnp.asarray(P0t),
            jnp.asarray(phi_aug),
            jnp.asarray(Qa),
            jnp.asarray(Qt),
            jnp.asarray(H),
            jnp.asarray(Ra),
            jnp.asarray(Rt),
            jnp.asarray(Xa),
            jnp.asarray(Xt),
            jnp.asarray(flag),
            jnp.asarray(rcov),
            None if phi_t is None else jnp.asarray(phi_t),
            layout=layout,
            kind=study.filter_kind,
            gencov=study.gencov,
            square_root=study.square_root,
            user_gain=study.user_gain,
        )
    except (TypeError, ValueError, jax.errors.JAXTypeError) as exc:
        if study.filter_kind == "user":
            raise ConfigError(
                f'{study.source}: filter.user_gain = "{study.user_gain_spec}" failed: '
                f"{type(exc).__name__}: {str(exc).splitlines()[0]} (it is called as "
                "gain(P_assumed, H, R, layout) -> K (n_est, m) under jax tracing)"
            ) from None
        raise
    if not host:
        return tuple(outs)
    Pa_m, Pa_p, Pt_m, Pt_p, sig = (np.asarray(o)[:K] for o in outs)
    return Pa_m, Pa_p, Pt_m, Pt_p, sig


filter_scan = _scan
