"""TOM's problem object: controls U -> propagation -> targets T(U) and final mass F(U), with
S = ∂T/∂U and G = ∂F/∂U from the core's exact sensitivities (FRACAS FEGS, FUNCT).

Arrays only (no deck objects): :func:`fracas.build.tom.build_tom` makes a
:class:`TomProblem` from a deck.  Controls are in canonical units (km, km/s, s, rad, 1).

How U sets a propagation (:class:`ControlMap`):
  * parameters p (labels of :mod:`fracas.params`) are affine in U: p = p_base + A U;
  * the initial state is affine in U (x0 = x0_base + B U) except the launch excess velocity
    (``vinf``, ``vinf_ra``, ``vinf_dec``): v0 = v_dep + v∞ [cos δ cos α, cos δ sin α, sin δ]
    with v_dep the departure body's velocity relative to the centre at the epoch;
  * ``final_time`` sets the final time (stop = time).

Targets (:data:`fracas.guidance.target_kinds.TARGET_KINDS`) are functions of the state
relative to their body at the stop: the final time, or the stop condition's event.

Sensitivities.  X_u = dx_f/dU at fixed final time is Φ x0_u + Θ A (Φ, Θ: the core's STM and
parameter matrix), computed by forward-mode AD through the integrator with the M control
directions as its only tangents (``integrate.propagate.final_state_jacobian``), plus f(x_f) in a
``final_time`` column.  When a stop condition (SOI entry, closest approach, radius) ends the
run at t_e, the event moves with U (digest P-A3): dt_e/dU = −(∂g/∂x X_u)/ġ with
ġ = ∂g/∂x f + ∂g/∂t, and dx_f/dU = X_u + f dt_e/dU.  The sensitivity run then stops a
δ = 1e-3 s short of t_e (so the event cannot end it first) and X_u is carried over δ by
(I + A δ), an O(δ²) error (relative 1e-12 for any orbit with a period above a minute).
Then S = ∂T/∂x dx_f/dU + ∂T/∂t dt_f/dU, G = dm_f/dU.  ``fegs`` is the report's forward
difference (FEGS-3) with steps δU_j, for cross-checks and the benchmark.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401
from fracas.dynamics.model import STOP_TIME, ForceModel, Params
from fracas.dynamics.parameters import set_values
from fracas.guidance.targets import target_values
from fracas.integrate import encke
from fracas.integrate.batch import propagate_batch
from fracas.integrate.propagate import final_state_jacobian, propagate
from fracas.integrate.variational import state_derivative, state_jacobians
from fracas.params import parse_label
from fracas.status import RunStatus
from fracas.tom.search_types import Evaluation

__all__ = ["ControlMap", "TargetSet", "TomProblem", "Outcome"]

_EVENT_BACKOFF_S = 1e-3


@dataclasses.dataclass(frozen=True)
class ControlMap:
    """How the decision vector U (M,) (canonical units) sets one propagation.

    names: the controls' names; param_labels (L,): the core parameters U moves;
    param_base (L,), param_matrix (L, M): p = param_base + param_matrix U;
    x0_base (7,), x0_matrix (7, M): x0 = x0_base + x0_matrix U before the v∞ controls;
    vinf_index: (j_vinf, j_ra, j_dec) indices of the launch controls (-1: not a control;
    its fixed value is vinf_fixed), v_departure (3,) km/s; final_time_index (-1: none) and
    final_time_s (the fixed final time otherwise).
    """

    names: tuple[str, ...]
    param_labels: tuple[str, ...]
    param_base: np.ndarray
    param_matrix: np.ndarray
    x0_base: np.ndarray
    x0_matrix: np.ndarray
    final_time_s: float
    final_time_index: int = -1
    vinf_index: tuple[int, int, int] = (-1, -1, -1)
    vinf_fixed: tuple[float, float, float] = (0.0, 0.0, 0.0)
    v_departure: np.ndarray | None = None

    @property
    def n_controls(self) -> int:
        return len(self.names)

    def params_of(self, u) -> np.ndarray:
        """Parameter values (L,) at U."""
        return self.param_base + self.param_matrix @ np.asarray(u, float)

    def final_time(self, u) -> float:
        return float(u[self.final_time_index]) if self.final_time_index >= 0 else self.final_time_s

    def _vinf_values(self, u):
        return [float(u[j]) if j >= 0 else f for j, f in zip(self.vinf_index, self.vinf_fixed)]

    def x0_of(self, u) -> np.ndarray:
        """Initial state (7,) at U."""
        u = np.asarray(u, float)
        x0 = self.x0_base + self.x0_matrix @ u
        if max(self.vinf_index) >= 0:
            vinf, ra, dec = self._vinf_values(u)
            x0 = x0.copy()
            x0[3:6] = self.v_departure + vinf * np.array(
                [np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)]
            )
        return x0

    def x0_jacobian(self, u) -> np.ndarray:
        """dx0/dU (7, M)."""
        jac = self.x0_matrix.copy()
        if max(self.vinf_index) >= 0:
            vinf, ra, dec = self._vinf_values(u)
            cd, sd, ca, sa = np.cos(dec), np.sin(dec), np.cos(ra), np.sin(ra)
            cols = (
                np.array([cd * ca, cd * sa, sd]),
                vinf * np.array([-cd * sa, cd * ca, 0.0]),
                vinf * np.array([-sd * ca, -sd * sa, cd]),
            )
            for j, col in zip(self.vinf_index, cols):
                if j >= 0:
                    jac[3:6, j] = col
        return jac


@dataclasses.dataclass(frozen=True)
class TargetSet:
    """The targets T (N,): names, each one's body (index into the model's bodies), the
    desired values and tolerances (canonical units), and which are angles (wrapped)."""

    names: tuple[str, ...]
    bodies: tuple[int, ...]
    desired: np.ndarray
    tolerance: np.ndarray
    angle: tuple[bool, ...]

    @property
    def n_targets(self) -> int:
        return len(self.names)

    def error(self, values) -> np.ndarray:
        """ΔT = T − T0, angles wrapped to (−π, π] (digest P-A4); ``values`` (N,) or (K, N)."""
        d = np.asarray(values, float) - self.desired
        ang = np.asarray(self.angle, bool)
        if ang.any():
            d[..., ang] = -np.remainder(-d[..., ang] + np.pi, 2.0 * np.pi) + np.pi
        return d


class Outcome:
    """One evaluated trajectory: the search's :class:`Evaluation` plus the stop details."""

    def __init__(
        self, evaluation: Evaluation, t_final: float, x_final: np.ndarray, primary: int, status: int, n_steps: int
    ):
        self.evaluation = evaluation
        self.t_final = t_final
        self.x_final = x_final
        self.primary = primary
        self.status = status
        self.n_steps = n_steps


def _target_fn(model: ForceModel, names: tuple[str, ...], bodies: tuple[int, ...]):
    """T(params, ephem, epoch, t, x, primary) as a jnp function (for jit and jacfwd)."""
    groups: dict[int, list[int]] = {}
    for i, b in enumerate(bodies):
        groups.setdefault(b, []).append(i)

    def fn(params, ephem, epoch_et, t, x, primary):
        pos, vel = encke.body_states(model, params, ephem, epoch_et + t)
        out = [None] * len(names)
        for b, idx in groups.items():
            rel = jnp.concatenate([x[:3] + pos[primary] - pos[b], x[3:6] + vel[primary] - vel[b]])
            vals = target_values(tuple(names[i] for i in idx), rel, t, params.mu[b])
            for k, i in enumerate(idx):
                out[i] = vals[k]
        return jnp.stack(out) if out else jnp.zeros(0)

    return fn


@partial(jax.jit, static_argnums=(0, 1, 2))
def _targets(model, names, bodies, params, ephem, epoch_et, t, x, primary):
    return _target_fn(model, names, bodies)(params, ephem, epoch_et, t, x, primary)


@partial(jax.jit, static_argnums=(0, 1, 2))
def _targets_batch(model, names, bodies, params, ephem, epoch_et, t, x, primary):
    fn = _target_fn(model, names, bodies)
    return jax.vmap(lambda tt, xx, pp: fn(params, ephem, epoch_et, tt, xx, pp))(t, x, primary)


@partial(jax.jit, static_argnums=(0, 1, 2))
def _target_partials(model, names, bodies, params, ephem, epoch_et, t, x, primary):
    """(T, ∂T/∂t (N,), ∂T/∂x (N, 7))."""
    fn = _target_fn(model, names, bodies)
    val = fn(params, ephem, epoch_et, t, x, primary)
    dt, dx = jax.jacfwd(lambda tt, xx: fn(params, ephem, epoch_et, tt, xx, primary), argnums=(0, 1))(t, x)
    return val, dt, dx


@partial(jax.jit, static_argnums=(0,))
def _event_partials(model, params, ephem, epoch_et, t, x, primary):
    """Stop-condition function g and its partials ∂g/∂t, ∂g/∂x (7,), with f(x) and A = ∂f/∂x."""

    def g(tt, xx):
        pos, vel = encke.body_states(model, params, ephem, epoch_et + tt)
        return encke.event_functions(model, params, xx[:3], xx[3:6], primary, pos, vel, 1.0)[0]

    gt, gx = jax.grad(g, argnums=(0, 1))(t, x)
    f = state_derivative(model, params, ephem, epoch_et, t, x, primary)
    a_mat, _ = state_jacobians(model, params, ephem, epoch_et, t, x, primary, ())
    return gt, gx, f, a_mat


@partial(jax.jit, static_argnums=(0,))
def _state_derivative(model, params, ephem, epoch_et, t, x, primary):
    return state_derivative(model, params, ephem, epoch_et, t, x, primary)


class TomProblem:
    """The TOM problem in canonical units: evaluate T and F at U, and S, G (FEGS / AD).

    model, params, ephem, epoch_et_s: the core's propagation objects (the deck's trajectory);
    controls: :class:`ControlMap`; targets: :class:`TargetSet`; sensitivity_method: "ad"
    (the core's exact sensitivities) or "fegs" (forward differences with steps fd_steps).
    Counters ``n_trajectories`` / ``n_sensitivity_runs`` and the time spent in each are kept.
    """

    def __init__(
        self,
        model: ForceModel,
        params: Params,
        ephem,
        epoch_et_s: float,
        controls: ControlMap,
        targets: TargetSet,
        fd_steps: Sequence[float] | None = None,
        sensitivity_method: str = "ad",
        performance: tuple[str, int, float] | None = None,
    ):
        self.model = model
        # F: the final mass (None), or sign x a target kind's value about a body, (name, body, sign)
        self.performance = performance
        perf = () if performance is None else (performance[0],)
        perf_body = () if performance is None else (performance[1],)
        self._names = tuple(targets.names) + perf
        self._bodies = tuple(targets.bodies) + perf_body
        self.params = params
        self.ephem = ephem
        self.epoch_et_s = float(epoch_et_s)
        self.controls = controls
        self.targets = targets
        m = controls.n_controls
        self.fd_steps = np.asarray(fd_steps if fd_steps is not None else np.full(m, 1e-6), float)
        self.sensitivity_method = sensitivity_method
        self.event_stop = model.stop.kind != STOP_TIME
        self.n_trajectories = 0
        self.n_sensitivity_runs = 0
        self._cache: dict[bytes, Outcome] = {}
        self.last_outcome: Outcome | None = None
        self.time_propagation_s = 0.0

    # ------------------------------------------------------------------ one trajectory
    def params_at(self, u) -> Params:
        """The core's Params at U (the labelled entries replaced, ``dynamics.parameters.set_values``)."""
        labels = self.controls.param_labels
        if not labels:
            return self.params
        return set_values(self.params, labels, jnp.asarray(self.controls.params_of(u)), self.model)

    def _t_out(self, u):
        return np.array([0.0, self.controls.final_time(u)])

    def _ok(self, status: int) -> bool:
        return status == (RunStatus.STOPPED if self.event_stop else RunStatus.OK)

    def outcome(self, u) -> Outcome:
        """Propagate at U with the plain core: targets, final mass, status (cached per U)."""
        u = np.asarray(u, float)
        key = u.tobytes()
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        t0 = time.perf_counter()
        prm = self.params_at(u)
        x0 = self.controls.x0_of(u)
        tr = propagate(self.model, prm, self.ephem, self.epoch_et_s, x0, self._t_out(u))
        status = int(tr.status)
        t_f, x_f, p_f = float(tr.t_final), np.asarray(tr.x_final), int(tr.primary_final)
        ok = self._ok(status) and bool(np.all(np.isfinite(x_f)))
        n = self.targets.n_targets
        if ok:
            vals = np.asarray(
                _targets(self.model, self._names, self._bodies, prm, self.ephem, self.epoch_et_s, t_f, x_f, p_f)
            )
            ok = bool(np.all(np.isfinite(vals)))
        else:
            vals = np.full(len(self._names), np.nan)
        perf = float(x_f[6]) if self.performance is None else self.performance[2] * float(vals[n])
        out = Outcome(Evaluation(vals[:n], perf if ok else float("nan"), ok), t_f, x_f, p_f, status, int(tr.n_steps))
        self.n_trajectories += 1
        self.time_propagation_s += time.perf_counter() - t0
        if len(self._cache) > 256:
            self._cache.clear()
        self._cache[key] = out
        self.last_outcome = out
        return out

    def fresh_outcome(self, u) -> Outcome:
        """:meth:`outcome` propagated afresh (its cached value dropped): TOM's verification."""
        self._cache.pop(np.asarray(u, float).tobytes(), None)
        return self.outcome(u)

    def evaluate(self, u) -> Evaluation:
        """FUNCT's trajectory: (T, F, ok) at U."""
        return self.outcome(u).evaluation

    # ------------------------------------------------------------------ sensitivities
    def sensitivities(self, u):
        """(Evaluation, S (N, M), G (M,)) at U by the configured method."""
        if self.sensitivity_method == "fegs":
            return self.fegs(u)
        return self.exact_sensitivities(u)

    def exact_sensitivities(self, u):
        """S and G from the core's exact STM and parameter matrix (module docstring)."""
        u = np.asarray(u, float)
        cm = self.controls
        m = cm.n_controls
        base = self.outcome(u)
        ev = base.evaluation
        if not ev.ok:
            nan = np.full((self.targets.n_targets, m), np.nan)
            return ev, nan, np.full(m, np.nan)
        t0 = time.perf_counter()
        prm = self.params_at(u)
        x0 = cm.x0_of(u)
        t_f, x_f, p_f = base.t_final, base.x_final, base.primary
        t_end = t_f - _EVENT_BACKOFF_S if self.event_stop else t_f
        dp_du = cm.param_matrix if cm.param_labels else np.zeros((0, m))
        _, x_u = final_state_jacobian(
            self.model, prm, self.ephem, self.epoch_et_s, x0, t_end, cm.param_labels, cm.x0_jacobian(u), dp_du
        )
        self.n_sensitivity_runs += 1
        x_u = np.array(x_u)
        t_u = np.zeros(m)
        if self.event_stop:
            gt, gx, f, a_mat = (
                np.asarray(a) for a in _event_partials(self.model, prm, self.ephem, self.epoch_et_s, t_f, x_f, p_f)
            )
            x_u = (np.eye(7) + a_mat * _EVENT_BACKOFF_S) @ x_u
            g_dot = float(gx @ f + gt)
            t_u = -(gx @ x_u) / g_dot if g_dot != 0.0 else np.full(m, np.nan)
            x_u = x_u + np.outer(f, t_u)
        elif cm.final_time_index >= 0:
            f = np.asarray(_state_derivative(self.model, prm, self.ephem, self.epoch_et_s, t_f, x_f, p_f))
            x_u[:, cm.final_time_index] += f
            t_u[cm.final_time_index] = 1.0
        _, dt, dx = (
            np.asarray(a)
            for a in _target_partials(
                self.model, self._names, self._bodies, prm, self.ephem, self.epoch_et_s, t_f, x_f, p_f
            )
        )
        s_all = dx @ x_u + np.outer(dt, t_u)
        n = self.targets.n_targets
        s_mat = s_all[:n]
        g_vec = x_u[6].copy() if self.performance is None else self.performance[2] * s_all[n]
        self.time_propagation_s += time.perf_counter() - t0
        return ev, s_mat, g_vec

    def fegs(self, u, steps: Sequence[float] | None = None, central: bool = False):
        """FEGS-3: forward (or central) differences of T and F with steps δU_j (canonical units)."""
        u = np.asarray(u, float)
        h = np.asarray(steps if steps is not None else self.fd_steps, float)
        base = self.evaluate(u)
        m = len(u)
        s_mat = np.zeros((self.targets.n_targets, m))
        g_vec = np.zeros(m)
        for j in range(m):
            e = np.zeros(m)
            e[j] = h[j]
            plus = self.evaluate(u + e)
            if central:
                minus = self.evaluate(u - e)
                s_mat[:, j] = self.targets.error(plus.targets) - self.targets.error(minus.targets)
                s_mat[:, j] /= 2 * h[j]
                g_vec[j] = (plus.performance - minus.performance) / (2 * h[j])
            else:
                s_mat[:, j] = (self.targets.error(plus.targets) - self.targets.error(base.targets)) / h[j]
                g_vec[j] = (plus.performance - base.performance) / h[j]
        return base, s_mat, g_vec

    # ------------------------------------------------------------------ many trajectories
    def evaluate_batch(self, us, progress=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """T (K, N), F (K,), ok (K,) for K control vectors in one batched core call (GRID).

        Parameters are batched on their Params fields, initial states per lane; every lane
        shares the final time (a ``final_time`` control is not batched: ValueError)."""
        us = np.atleast_2d(np.asarray(us, float))
        k = us.shape[0]
        cm = self.controls
        if cm.final_time_index >= 0 and np.ptp(us[:, cm.final_time_index]) > 0:
            raise ValueError("evaluate_batch: the final_time control must be the same in every lane")
        fields: dict[str, np.ndarray] = {}
        for label in cm.param_labels:
            field, _ = parse_label(label, self.model)
            if field not in fields:
                base = np.asarray(getattr(self.params, field), np.float64)
                fields[field] = np.broadcast_to(base, (k, *base.shape)).copy()
        vals = np.array([cm.params_of(u) for u in us])  # (K, L)
        for j, label in enumerate(cm.param_labels):
            field, idx = parse_label(label, self.model)
            fields[field][(slice(None), *idx)] = vals[:, j]
        prm = self.params._replace(**fields)
        axes = dict.fromkeys(fields, 0)
        x0s = np.array([cm.x0_of(u) for u in us])
        tr = propagate_batch(
            self.model, prm, self.ephem, self.epoch_et_s, x0s, self._t_out(us[0]), params_axes=axes, progress=progress
        )
        self.n_trajectories += k
        status = np.asarray(tr.status)
        ok = status == (RunStatus.STOPPED if self.event_stop else RunStatus.OK)
        t_f, x_f, p_f = (np.asarray(a) for a in (tr.t_final, tr.x_final, tr.primary_final))
        # targets: shared parameters suffice unless a batched field enters them (mu is never a control)
        vals = np.asarray(
            _targets_batch(
                self.model,
                self._names,
                self._bodies,
                self.params,
                self.ephem,
                self.epoch_et_s,
                t_f,
                x_f,
                p_f,
            )
        )
        ok &= np.all(np.isfinite(vals), axis=1) & np.all(np.isfinite(x_f), axis=1)
        n = self.targets.n_targets
        f = x_f[:, 6] if self.performance is None else self.performance[2] * vals[:, n]
        perf = np.where(ok, f, np.nan)
        return vals[:, :n], perf, ok
