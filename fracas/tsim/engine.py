"""One block of TSIM missions flown through every maneuver (FRACAS TSIM, CSAMP, NOISE, GUIDS,
SETUP; digest ``tom-tsim-guidance.md`` C.3-C.6).

For each mission (one lane of a vmapped block of :attr:`TsimPlan.block` missions):

1. **Sample the real world** (CSAMP, RNUM): δX₀ = L₀ z over the augmented state (injection
   state, mass and every parameter, :attr:`TsimPlan.init_factor`); the trajectory's
   parameters (:attr:`TsimPlan.dyn_labels`) take their sampled values in the real world's
   ``Params``; the Gauss-Markov thrust errors are drawn on the hold grid as their exact means over
   each cell (NOISE-1, jointly with the node values, started stationary;
   :func:`fracas.tsim.sampling.gauss_markov_cell_means`, issue 24) and held constant over
   the cell (P-C3), the integrator restarting at every node so a realization does not
   depend on the step size.
2. **Fly to each maneuver** with the real world (SETUP(real)): phase by phase, in chunks of
   :data:`CHUNK` grid cells (one compiled program for every phase and chunk).
3. **Estimate by sampling** (P-C1, independent): δX̂ = (X_actual − X_ref) + n, n = L_k z
   with P_k TEAM's true knowledge covariance at the maneuver (or the deck's).
4. **Design** (GUIDS; SETUP(nominal): the nominal model, no noise, at the estimated
   parameters the law estimates):
   * linear: ΔV = −Γ δX̂ (impulsive) or δU = −Γ_U δX̂ − K^{+W}K δU_c (low thrust; δU_c is
     what earlier events already commanded on the same arc, so a vernier replaces the
     command it updates rather than stacking on it, as TEAM's exact reset does);
   * nonlinear (impulsive): start from the linear ΔV; fly the estimated state with the
     correction to the target time (its propellant is not in the design: see docs/tsim.md);
     ΔV ← ΔV − λ K⁺ ΔT, K about the reference for the first step and by central differences
     about the current design after it, λ halved (up to 3 times) while the weighted miss max|ΔT_i/ε_i| grows; converged
     when every |ΔT_i| ≤ ε_i; after ``max_iterations`` a design within ``near_success_factor``
     × ε is accepted (status 1, near success), otherwise the mission is **hopeless**
     (status 2): it ends there and is counted, never dropped.
5. **Execute with errors** on the actual trajectory: Gates (proportionality σ_p along ΔV, two
   pointing angles across it, resolution) for impulses, with the propellant at the impulsive
   engine's Isp spent (or only booked against the final mass, ``impulse_propellant``: TEAM's
   model, where a correction changes the velocity only); a fractional error per control for
   low thrust.
6. After the last maneuver fly to the final target time; record the target errors
   T(X_actual) − T_ref, ΔV per maneuver, the final mass, and for each impulsive maneuver its
   design's miss on the estimated trajectory (``design_miss``; ``linear_design_miss`` the
   linear law's, which a nonlinear design starts from): what the linear law leaves undone
   where the problem is nonlinear, free of the knowledge and execution errors.

Nothing raises in the jitted parts: a lane whose integration fails (status 3) is frozen on
the reference (NaN-free, P-C5) with its status set, so one failed mission never stops its
block.  States are relative to the model's primary; a mission that changes primary on the
way is a failure (status 3).

Bit-identity: mission i always flies in lane i mod block of block i // block with the same
compiled shapes, so its numbers do not depend on the batch size, the worker count or where a
run was resumed.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401  (float64 before any array exists)
from fracas.dynamics.model import Params
from fracas.dynamics.parameters import get_values, set_values
from fracas.guidance.targets import target_values
from fracas.integrate.propagate import join_model, propagate, split_model
from fracas.tsim import sampling as smp
from fracas.tsim.maneuvers import _fail, _impulsive_maneuver, _low_thrust_maneuver
from fracas.tsim.plan import STATUS_INTEGRATION, TsimPlan

__all__ = ["CHUNK", "BlockResult", "simulate_block", "block_fields"]

CHUNK = 32  # noise-grid cells per compiled flight call


def _lane_params(static, params: Params, dyn_labels, dyn_values, ctrl_labels, ctrl_values) -> Params:
    p = set_values(params, dyn_labels, dyn_values, static) if dyn_labels else params
    return set_values(p, ctrl_labels, ctrl_values, static) if ctrl_labels else p


@functools.lru_cache(maxsize=16)
def _programs(static, dyn_labels: tuple, ctrl_labels: tuple, final_names: tuple, man_names: tuple):
    """The compiled (jitted, vmapped) pieces for one model structure and label set."""

    def fly_chunk_one(dyn, params, ephem, epoch, x, t0s, t1s, eta, alive):
        model = join_model(static, dyn)

        def seg(carry, s):
            x_c, ok = carry
            t0, t1, e = s
            p = params._replace(
                thrust_scale=params.thrust_scale + e[0],
                bias_in_rad=params.bias_in_rad + e[1],
                bias_out_rad=params.bias_out_rad + e[2],
            )
            tr = propagate(model, p, ephem, epoch, x_c, jnp.stack([t0, t1]))
            empty = t1 <= t0
            good = empty | ((tr.status == 0) & (tr.primary_final == model.primary) & jnp.all(jnp.isfinite(tr.x_final)))
            x_n = jnp.where(empty | ~good | ~ok, x_c, tr.x_final)
            return (x_n, ok & good), None

        (x_f, ok), _ = jax.lax.scan(seg, (x, alive), (t0s, t1s, eta))
        return x_f, ok

    def fly_to_one(dyn, params, ephem, epoch, x, t0, t1):
        model = join_model(static, dyn)
        tr = propagate(model, params, ephem, epoch, x, jnp.stack([t0, t1]))
        good = (tr.status == 0) & (tr.primary_final == model.primary) & jnp.all(jnp.isfinite(tr.x_final))
        return jnp.where(good, tr.x_final, x), good

    # params are batched: every leaf has the lane axis
    fly_chunk = jax.jit(jax.vmap(fly_chunk_one, in_axes=(None, 0, None, None, 0, None, None, 0, 0)))
    fly_to = jax.jit(jax.vmap(fly_to_one, in_axes=(None, 0, None, None, 0, None, None)))

    def lane_params(params, dyn_values, ctrl_values):
        return _lane_params(static, params, dyn_labels, dyn_values, ctrl_labels, ctrl_values)

    lane_params_b = jax.jit(jax.vmap(lane_params, in_axes=(None, 0, 0)))

    def targets_of(names):
        def one(x, t, offset, mu):
            return target_values(names, x[:6] - offset, t, mu)

        return jax.jit(jax.vmap(one, in_axes=(0, None, None, None)))

    tgt = {names: targets_of(names) for names in set((final_names,) + man_names)}

    def draws(seed, missions, init_factor, sigma, tau, dt, kfacs):
        def one(i):
            key = smp.mission_key(seed, i)
            dx0 = smp.sample_normal(smp.stream_key(key, smp.STREAM_INITIAL), init_factor)
            eta = smp.gauss_markov_cell_means(smp.stream_key(key, smp.STREAM_NOISE), sigma, tau, dt)
            kn = [smp.sample_normal(smp.stream_key(key, smp.STREAM_KNOWLEDGE, j), f) for j, f in enumerate(kfacs)]
            ek = [smp.stream_key(key, smp.STREAM_EXECUTION, j) for j in range(len(kfacs))]
            return dx0, eta, kn, ek

        return jax.vmap(one)(missions)

    draws_b = jax.jit(draws)

    def gates(keys, dv, sp, sb, sr):
        return jax.vmap(lambda k, d: smp.gates_error(k, d, sp, sb, sb, sr))(keys, dv)

    def proportional(keys, du, frac):
        return jax.vmap(lambda k, d: smp.proportional_error(k, d, frac))(keys, du)

    return {
        "fly_chunk": fly_chunk,
        "fly_to": fly_to,
        "lane_params": lane_params_b,
        "targets": tgt,
        "draws": draws_b,
        "gates": jax.jit(gates),
        "proportional": jax.jit(proportional),
    }


def _setup(plan: TsimPlan):
    """(traced integrator constants, the compiled programs, nominal values of the trajectory's
    parameters and of the arc controls) of a plan."""
    static, dyn = split_model(plan.model)
    prog = _programs(
        static, plan.dyn_labels, plan.control_labels, plan.final.names, tuple(m.target.names for m in plan.maneuvers)
    )

    def values(labels):
        return np.asarray(get_values(plan.params, labels, plan.model)) if labels else np.zeros(0)

    return dyn, prog, values(plan.dyn_labels), values(plan.control_labels)


def block_fields(plan: TsimPlan) -> dict[str, tuple]:
    """Name -> (shape after the mission axis, dtype) of every per-mission output."""
    J = len(plan.maneuvers)
    m_max = max([m.n_controls for m in plan.maneuvers] + [3])
    m_tgt = max([len(m.target.names) for m in plan.maneuvers] + [1])
    return {
        "mission": ((), np.int64),
        "status": ((), np.int32),
        "failed_maneuver": ((), np.int32),
        "iterations": ((J,), np.int32),
        "initial_deviation": ((plan.n,), np.float64),
        "state_deviation": ((J, 7), np.float64),
        "knowledge_error": ((J, plan.n), np.float64),
        "correction": ((J, m_max), np.float64),
        "execution_error": ((J, m_max), np.float64),
        "dv_km_s": ((J,), np.float64),
        "dv_total_km_s": ((), np.float64),
        "target_error": ((len(plan.final.names),), np.float64),
        "maneuver_status": ((J,), np.int32),
        "linear_design_miss": ((J, m_tgt), np.float64),
        "design_miss": ((J, m_tgt), np.float64),
        "final_mass_kg": ((), np.float64),
    }


BlockResult = dict  # name -> (block, ...) array, :func:`block_fields`


def _grid_chunks(grid: np.ndarray, t_a: float, t_b: float):
    """Chunks (t0 (C,), t1 (C,), cell index (C,)) of the grid cells from t_a to t_b."""
    i0 = int(np.searchsorted(grid, t_a - 1e-6))
    i1 = int(np.searchsorted(grid, t_b - 1e-6))
    cells = np.arange(i0, i1)
    out = []
    for s in range(0, max(len(cells), 1), CHUNK):
        c = cells[s : s + CHUNK]
        t0 = np.full(CHUNK, t_b)
        t1 = np.full(CHUNK, t_b)
        idx = np.zeros(CHUNK, dtype=np.int64)
        t0[: len(c)] = grid[c]
        t1[: len(c)] = grid[c + 1]
        idx[: len(c)] = c
        out.append((t0, t1, idx))
    return out


def _new_outputs(plan: TsimPlan, missions: np.ndarray, dx0: np.ndarray) -> BlockResult:
    """The block's zeroed outputs (:func:`block_fields`) with the mission numbers, no failed
    maneuver yet and the sampled initial deviations."""
    B = plan.block
    fields = block_fields(plan)
    out = {k: np.zeros((B,) + shp, dtype=dt_) for k, (shp, dt_) in fields.items()}
    out["mission"][:] = missions
    out["failed_maneuver"][:] = -1
    out["initial_deviation"][:] = dx0
    return out


def _final_outputs(
    plan: TsimPlan,
    prog: dict,
    out: BlockResult,
    x: np.ndarray,
    alive: np.ndarray,
    status: np.ndarray,
    booked: np.ndarray,
) -> None:
    """Fill the target errors, final mass, total ΔV and status of the block (NaN for lanes
    that did not fly to the end)."""
    tf = plan.final
    t_val = np.asarray(prog["targets"][tf.names](jnp.asarray(x), tf.t_s, jnp.asarray(tf.offset), tf.mu))
    out["target_error"][:] = t_val - tf.reference
    out["final_mass_kg"][:] = x[:, 6] - booked
    out["dv_total_km_s"][:] = out["dv_km_s"].sum(axis=1)
    out["status"][:] = status
    dead = ~alive
    for k in ("target_error", "final_mass_kg"):
        out[k][dead] = np.nan


def simulate_block(plan: TsimPlan, block_index: int) -> BlockResult:
    """Fly the missions ``first_mission + block_index·block + (0..block-1)`` (module docstring).

    Returns every per-mission output (:func:`block_fields`) for the whole block, lanes past
    the run's last mission included (the caller drops them)."""
    B = plan.block
    man = plan.maneuvers
    ctrl_labels = plan.control_labels
    dyn, prog, nominal_dyn, nominal_ctrl = _setup(plan)
    missions = plan.first_mission + block_index * B + np.arange(B, dtype=np.int64)
    dt = np.diff(plan.grid_s)
    kfacs = tuple(jnp.asarray(m.knowledge_factor) for m in man)
    dx0, eta, kn, ek = prog["draws"](
        plan.seed,
        jnp.asarray(missions),
        jnp.asarray(plan.init_factor),
        jnp.asarray(plan.noise_sigma),
        jnp.asarray(plan.noise_tau_s),
        jnp.asarray(dt),
        kfacs,
    )
    dx0 = np.array(dx0)
    eta = np.array(eta)
    nx = plan.nx
    J = len(man)
    out = _new_outputs(plan, missions, dx0)

    dyn_dev = dx0[:, plan.dyn_index] if plan.dyn_labels else np.zeros((B, 0))
    ctrl_actual = np.zeros((B, len(ctrl_labels)))
    ctrl_cmd = np.zeros((B, len(ctrl_labels)))

    x = np.tile(plan.x0, (B, 1))
    x[:, :nx] += dx0[:, :nx]
    alive = np.ones(B, dtype=bool)
    status = np.zeros(B, dtype=np.int32)
    ephem, epoch = plan.ephem, jnp.asarray(plan.epoch_et_s)
    p_nom = plan.params

    def fly(x: np.ndarray, t_a: float, t_b: float, alive: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        params_b = prog["lane_params"](
            p_nom, jnp.asarray(nominal_dyn + dyn_dev), jnp.asarray(nominal_ctrl + ctrl_actual)
        )
        xj = jnp.asarray(x)
        ok = jnp.asarray(alive)
        for t0, t1, idx in _grid_chunks(plan.grid_s, t_a, t_b):
            xj, ok = prog["fly_chunk"](
                dyn, params_b, ephem, epoch, xj, jnp.asarray(t0), jnp.asarray(t1), jnp.asarray(eta[:, idx, :]), ok
            )
        return np.array(xj), np.asarray(ok)

    booked = np.zeros(B)  # impulsive propellant not flown (impulse_propellant = "booked")
    t_prev = 0.0
    for j, m in enumerate(man):
        x, ok = fly(x, t_prev, m.time_s, alive)
        _fail(out, status, alive, ~ok, STATUS_INTEGRATION, j)
        alive &= ok
        x[~alive] = plan.x_ref[j]  # frozen on the reference: NaN-free dummies
        dev = x - plan.x_ref[j]
        out["state_deviation"][:, j] = dev
        aug = np.concatenate([dev[:, :nx], dx0[:, nx:]], axis=1)
        know = np.array(kn[j])
        out["knowledge_error"][:, j] = know
        est = aug + know
        if m.impulsive:
            ctrl_now = nominal_ctrl + ctrl_cmd  # what the navigator believes the arcs will fly
            lanes = (alive, status, booked)
            _impulsive_maneuver(plan, prog, dyn, m, j, x, know, est, ctrl_now, nominal_dyn, lanes, ek[j], out)
        else:
            _low_thrust_maneuver(prog, m, j, est, ctrl_labels, (ctrl_cmd, ctrl_actual), alive, ek[j], out)
        t_prev = m.time_s
    x, ok = fly(x, t_prev, plan.final.t_s, alive)
    _fail(out, status, alive, ~ok, STATUS_INTEGRATION, J)
    alive &= ok
    x[~alive] = plan.x_ref[J]
    _final_outputs(plan, prog, out, x, alive, status, booked)
    return out


def reference_states(plan: TsimPlan, times_s) -> tuple[np.ndarray, float]:
    """(states, failed_at_s): the reference (7,) at each of ``times_s`` (sorted, s), flown by
    the engine with every deviation and the noise zero through the plan's hold grid (the
    states the missions' deviations are measured from: the null run deviates by exactly
    zero), and the first of those times it could not be flown to (NaN when it flew; the
    states from there on are not finite).  Nothing raises here: the build reports it."""
    B = plan.block  # a block of identical lanes: the missions' compiled programs serve
    dyn, prog, nominal_dyn, nominal_ctrl = _setup(plan)
    params_b = prog["lane_params"](
        plan.params, jnp.asarray(np.tile(nominal_dyn, (B, 1))), jnp.asarray(np.tile(nominal_ctrl, (B, 1)))
    )
    x = jnp.asarray(np.tile(plan.x0, (B, 1)))
    ok = jnp.ones(B, dtype=bool)
    zero = jnp.zeros((B, CHUNK, 3))
    out, t_prev = [], 0.0
    for t in times_s:
        for t0, t1, _ in _grid_chunks(plan.grid_s, t_prev, t):
            x, ok = prog["fly_chunk"](
                dyn, params_b, plan.ephem, jnp.asarray(plan.epoch_et_s), x, jnp.asarray(t0), jnp.asarray(t1), zero, ok
            )
        if not bool(np.asarray(ok)[0]):
            out += [np.full(7, np.nan)] * (len(times_s) - len(out))
            return np.stack(out), float(t)
        out.append(np.asarray(x)[0].copy())
        t_prev = t
    return np.stack(out), float("nan")
