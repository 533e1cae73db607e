"""The maneuvers of a TSIM block (FRACAS GUIDS, digest ``tom-tsim-guidance.md`` C.4-C.5):
the impulsive design (linear, or nonlinear by iterating on the estimated trajectory) and its
execution with Gates errors, and the low-thrust control update with its fractional errors.

Part of the block engine (:mod:`fracas.tsim.engine`, whose module docstring describes the
steps); every function here works on a whole block of lanes at once, numpy arrays updated in
place.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401  (float64 before any array exists)
from fracas.constants import G0_KM_S2
from fracas.tsim.plan import STATUS_HOPELESS, STATUS_NEAR, STATUS_OK, ManeuverPlan, TsimPlan

BlockResult = dict  # name -> (block, ...) array (fracas.tsim.engine.block_fields)


def _fail(out: BlockResult, status: np.ndarray, alive: np.ndarray, mask: np.ndarray, code: int, j: int) -> None:
    """Mark the live lanes of ``mask`` failed with ``code`` at maneuver ``j`` (in place)."""
    new = mask & alive
    status[new] = code
    out["failed_maneuver"][new] = j


def _impulsive_maneuver(
    plan: TsimPlan,
    prog: dict,
    dyn: tuple,
    m: ManeuverPlan,
    j: int,
    x: np.ndarray,
    know: np.ndarray,
    est: np.ndarray,
    ctrl_now: np.ndarray,
    nominal_dyn: np.ndarray,
    lanes: tuple[np.ndarray, np.ndarray, np.ndarray],
    ek: jax.Array,
    out: BlockResult,
) -> None:
    """Design (GUIDS) and execute (Gates errors) impulsive maneuver ``j`` on the block's lanes:
    updates x, ``lanes`` = (alive, status, booked propellant) and ``out`` in place."""
    alive, status, booked = lanes
    dv = -est @ m.gamma.T
    nonlin = m.law == "nonlinear"
    dv, code, iters, miss_lin, miss = _impulsive_design(
        plan, prog, dyn, m, x, know, est, dv, nominal_dyn, ctrl_now, alive, nonlin
    )
    mt = len(m.target.names)
    out["linear_design_miss"][:, j, :mt] = miss_lin
    out["design_miss"][:, j, :mt] = miss
    out["maneuver_status"][:, j] = np.where(alive, code, STATUS_OK)
    if nonlin:
        _fail(out, status, alive, code == STATUS_HOPELESS, STATUS_HOPELESS, j)
        near = (code == STATUS_NEAR) & alive & (status == STATUS_OK)
        status[near] = STATUS_NEAR
        alive &= code != STATUS_HOPELESS
    dv[~alive] = 0.0
    err = np.array(prog["gates"](ek, jnp.asarray(dv), m.sigma_p, m.sigma_pointing_rad, m.sigma_res_km_s))
    err[~alive] = 0.0
    applied = dv + err
    x[:, 3:6] += applied
    spent = x[:, 6] * (1.0 - np.exp(-np.linalg.norm(applied, axis=1) / (G0_KM_S2 * plan.isp_s)))
    if plan.impulse_propellant == "spent":
        x[:, 6] -= spent
    else:
        booked += spent
    out["correction"][:, j, :3] = dv
    out["execution_error"][:, j, :3] = err
    out["dv_km_s"][:, j] = np.linalg.norm(dv, axis=1)
    out["iterations"][:, j] = iters


def _low_thrust_maneuver(
    prog: dict,
    m: ManeuverPlan,
    j: int,
    est: np.ndarray,
    ctrl_labels: tuple,
    ctrls: tuple[np.ndarray, np.ndarray],
    alive: np.ndarray,
    ek: jax.Array,
    out: BlockResult,
) -> None:
    """Low-thrust maneuver ``j``: the control update dU and its fractional execution errors;
    ``ctrls`` = (commanded, actual) arc-control offsets and ``out`` updated in place."""
    ctrl_cmd, ctrl_actual = ctrls
    M = m.n_controls
    idx = [ctrl_labels.index(c) for c in m.control_labels]
    du = -est @ m.gamma.T - ctrl_cmd[:, idx] @ m.kk.T
    du[~alive] = 0.0
    err = np.array(prog["proportional"](ek, jnp.asarray(du), m.sigma_p))
    err[~alive] = 0.0
    ctrl_cmd[:, idx] += du
    ctrl_actual[:, idx] += du + err
    out["correction"][:, j, :M] = du
    out["execution_error"][:, j, :M] = err
    out["dv_km_s"][:, j] = np.abs(du @ m.dv_jacobian)


def _fd_jacobian(miss: Callable, dv: np.ndarray) -> np.ndarray:
    """K about the current design ``dv``, central differences (SCOMP by FD): (B, m, 3)."""
    h = 1e-4  # km/s: the flights' step-size noise (up to ~10 km over 150 d) / h stays below 1 % of K
    cols = []
    for i in range(3):
        e = np.zeros(3)
        e[i] = h
        cols.append((miss(dv + e)[0] - miss(dv - e)[0]) / (2 * h))
    return np.stack(cols, axis=-1)  # (B, m, 3)


def _backtrack(miss: Callable, measure: Callable, todo: np.ndarray, step: np.ndarray, design: tuple) -> None:
    """Backtracking on the lanes of ``todo``: halve the step while the weighted miss grows (at
    most 4 trials); a lane takes the first trial that lowers it.  ``design`` = (dv, dT, norm,
    good), updated in place."""
    dv, dT, norm, good = design
    lam = 1.0
    for _ in range(4):  # backtracking: halve the step while the weighted miss grows
        trial = np.where(todo[:, None], dv - lam * step, dv)
        dT_t, good_t = miss(trial)
        norm_t = measure(dT_t, good_t)
        take = todo & (norm_t < norm)
        dv[take], dT[take], norm[take], good[take] = trial[take], dT_t[take], norm_t[take], good_t[take]
        todo &= ~take
        if not todo.any():
            break
        lam *= 0.5


def _impulsive_design(
    plan: TsimPlan,
    prog: dict,
    dyn: tuple,
    m: ManeuverPlan,
    x: np.ndarray,
    know: np.ndarray,
    est: np.ndarray,
    dv0: np.ndarray,
    nominal_dyn: np.ndarray,
    ctrl_now: np.ndarray,
    alive: np.ndarray,
    iterate: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """GUIDS for the impulsive lanes of a block (engine module docstring, item 4): the design's miss
    on the estimated trajectory (the estimated state with the correction flown to the target
    time by the nominal model at the estimated parameters), and with ``iterate`` the
    nonlinear design.  Returns (ΔV, status code, iterations, the linear design's miss, the
    final design's miss), misses (B, m) in target units."""
    B = x.shape[0]
    nx = plan.nx
    tgt = m.target
    x_est = x.copy()
    x_est[:, :nx] += know[:, :nx]
    dyn_est = nominal_dyn + np.where(plan.est_dyn, est[:, plan.dyn_index], 0.0) if plan.dyn_labels else np.zeros((B, 0))
    params_est = prog["lane_params"](plan.params, jnp.asarray(dyn_est), jnp.asarray(ctrl_now))
    fn_t = prog["targets"][tgt.names]
    ephem, epoch = plan.ephem, jnp.asarray(plan.epoch_et_s)

    def miss(dv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        xs = x_est.copy()
        xs[:, 3:6] += dv
        xf, good = prog["fly_to"](dyn, params_est, ephem, epoch, jnp.asarray(xs), m.time_s, tgt.t_s)
        val = np.asarray(fn_t(xf, tgt.t_s, jnp.asarray(tgt.offset), tgt.mu))
        return val - tgt.reference, np.array(good)

    def measure(dT: np.ndarray, good: np.ndarray) -> np.ndarray:
        return np.where(good, np.max(np.abs(dT) / tgt.tolerance, axis=1), np.inf)

    dv = dv0.copy()
    done = ~alive.copy()
    code = np.full(B, STATUS_HOPELESS, dtype=np.int32)
    code[~alive] = STATUS_OK
    iters = np.zeros(B, dtype=np.int32)
    dT, good = miss(dv)
    miss_linear = np.where(alive[:, None], dT, 0.0)
    if not iterate:
        return dv, np.full(B, STATUS_OK, dtype=np.int32), iters, miss_linear, miss_linear
    norm = measure(dT, good)
    kp = np.tile(m.k_pinv, (B, 1, 1))  # first step: K about the reference
    for it in range(m.max_iterations):
        conv = (norm <= 1.0) & ~done
        code[conv] = STATUS_OK
        done |= conv
        if done.all():
            break
        iters[~done] = it + 1
        if it > 0:
            kp = np.linalg.pinv(_fd_jacobian(miss, dv))
        step = np.einsum("bij,bj->bi", kp, np.where(good[:, None], dT, 0.0))
        todo = ~done & good
        _backtrack(miss, measure, todo, step, (dv, dT, norm, good))
    conv = (norm <= 1.0) & ~done
    code[conv] = STATUS_OK
    done |= conv
    near = ~done & (norm <= plan.near_success_factor)
    code[near] = STATUS_NEAR
    return dv, code, iters, miss_linear, np.where(alive[:, None], dT, 0.0)
