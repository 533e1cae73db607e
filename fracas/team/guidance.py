"""Guidance events in TEAM: the control covariance and the statistical corrections
(FRACAS GUIDM §5.3.6, XGUID §5.3.25, TARMAT §5.4.9; digest ``tom-tsim-guidance.md`` Part B).

The **control covariance** P_c = cov(actual − reference) is carried beside the knowledge:
P_c(t_k) = Φ_k P_c(t_{k-1}) Φ_kᵀ + Q̃_k (digest (G-1), the filter's own augmented Φ and
true process noise; no measurement touches it), from ``Study.P0_control`` (the injection
dispersions; default the true a-priori).  At each guidance event, in time order:

* Ψ (TARMAT, digest (G-2)): the targets' variation with respect to the augmented state at
  the event, Ψ = A_T [Φ(t_f, t) Θ(t_f, t)] with A_T = ∂T/∂X_f of the osculating-conic targets
  about the target body (:mod:`fracas.guidance.targets`); Φ and Θ from the STM file when it
  holds t and t_f, else integrated;
* the estimated-deviation covariance P̃ of ``Study.guidance_model`` (digest (G-0), P-B1:
  ``report`` P̃ = P_c, the default as GUIDM writes it; ``orthogonal`` P_c − P_k; ``tsim``
  P_c + P_k, the one to compare with TSIM), with P_k the TRUE knowledge (P-B3);
* **impulsive**: Γ, P_ΔV = Γ P̃ Γᵀ, Gates execution errors Σ_ex, P_c⁺ (G-3..G-8), mean and
  99 % |ΔV| (G-9); Σ_ex is added to the knowledge as well (the navigator does not see it);
* **primary / vernier** (low thrust, digest B.7-B.8): S = ∂x(t_c)/∂U, K = Ψ(t_c) S,
  Λ = Ψ(t_c) Φ(t_c, t_I), Γ_U = K^{+W} Λ, P_U = Γ_U P̃ Γ_Uᵀ, the ΔV and propellant σ of the
  correction (L-4), execution errors S Σ_U Sᵀ at the cutoff.  ``report``: the control
  covariance restarts at t_I from the knowledge (state and state-parameter blocks; the
  parameter block keeps P_c,pp, P-B2) and propagates open loop (no measurement updates,
  P-B4) — GUIDM's "knowledge at initiation" with verniers to follow and, propagated, its
  "knowledge at termination" without; other models: the exact δX(t_c)⁺ = [Φ − SΓ_U]δX +
  SΓ_U e + w written as a reset at t_I with G = Φ⁻¹ S Γ_U;
* **none**: the target covariance only.

Each event changes the knowledge only through its execution errors, so the filter is run
once more after each event (the same compiled scan, :func:`fracas.team.scan.run_filter`
with ``Xa``/``Xt``).  ``assumed_exec`` fixes the assumed side's execution covariances
(the error budget's single-source runs keep the full run's gains).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fracas.dynamics.parameters import get_values
from fracas.errors import ConfigError
from fracas.guidance import impulsive as imp
from fracas.guidance import statistics as dvstats
from fracas.guidance.target_kinds import TARGET_KINDS
from fracas.products import GuidanceEvent, ReferenceTrajectory, chain, time_indices
from fracas.team.study import GuidanceSpec, Study
from fracas.team.transitions import EPS_T, interval_noise

GuidanceOutcome = GuidanceEvent  # the product is what the core makes

__all__ = ["GuidanceOutcome", "ReferenceSpan", "GuidanceRun", "run_guidance", "Z99"]

Z99 = 2.5758293035489004  # the 99 % point of |N(0, 1)|: a one-dimensional |δΔV| quantile
_VEL = slice(3, 6)


@dataclass
class GuidanceRun:
    """The filter outputs with every event's execution errors, and the control history."""

    outs: tuple
    control: np.ndarray  # (K, n, n) after each event
    control_epoch: np.ndarray  # (K,) schedule index of the last reset
    outcomes: list[GuidanceOutcome]
    Xa: np.ndarray
    Xt: np.ndarray


class ReferenceSpan:
    """The reference at any times: states and transitions between two times (7-state Φ and
    Θ for the study's dynamic labels), from a reference product when it holds the times,
    else integrated in line (cached)."""

    def __init__(self, study: Study, product: ReferenceTrajectory | None = None):
        self.study = study
        self.product = product
        self._wanted: tuple[float, ...] = ()
        self.memo: dict[tuple, object] = {}  # Ψ, S and thrust levels, reused by budget runs

    def prefetch(self, times) -> None:
        """Integrate once over every time the guidance will ask for (in-line references)."""
        self._wanted = tuple(sorted(set(self._wanted) | {float(t) for t in times}))

    def _integrated(self, times: tuple[float, ...]):
        """One in-line integration (0, the prefetched times and ``times``), cached."""
        from fracas.team.reference import run_reference

        grid = getattr(self, "_grid", None)
        if grid is not None and all(np.min(np.abs(grid[0] - t)) < 1e-6 for t in times):
            return grid
        t_out = np.array(sorted(set((0.0,) + tuple(self._wanted) + tuple(float(t) for t in times))))
        traj, sens, status, failed = run_reference(self.study.problem, t_out, self.study.dynamic_labels)
        if status != 0:
            raise ConfigError(
                f"{self.study.source}: guidance: the reference ends before {failed / 86400.0:.6g} d "
                "(a guidance, cutoff or target time lies beyond the trajectory)"
            )
        self._grid = (t_out, np.asarray(traj.x), np.asarray(traj.primary), sens, self.study.problem.model.bodies)
        self._wanted = tuple(t_out)
        return self._grid

    def _from_product(self, times):
        if self.product is None:
            return None
        try:
            time_indices(self.product, list(times))
        except Exception:  # noqa: BLE001  (a time the file lacks: integrate instead)
            return None
        return True

    def state(self, t_s: float) -> tuple[np.ndarray, str]:
        """(7,) state relative to the central body and that body's name at t_s."""
        if self._from_product([t_s]):
            i = int(time_indices(self.product, [t_s])[0])
            return np.asarray(self.product.states[i], dtype=np.float64), self.product.primary[i]
        t_out, x, prim, _, bodies = self._integrated((float(t_s),))
        i = int(np.argmin(np.abs(t_out - t_s)))
        p = int(prim[i])
        return x[i].astype(np.float64), bodies[p] if 0 <= p < len(bodies) else ""

    def transition(self, t_to: float, t_from: float) -> tuple[np.ndarray, np.ndarray]:
        """Φ(t_to, t_from) (7, 7) and Θ(t_to, t_from) (7, n_dyn)."""
        n_dyn = len(self.study.dynamic_labels)
        if abs(t_to - t_from) < 1e-9:
            return np.eye(7), np.zeros((7, n_dyn))
        if self._from_product([t_from, t_to]):
            phi, theta = chain(self.product, [t_from, t_to])
            return np.asarray(phi[1]), np.asarray(theta[1])
        t_out, _, _, sens, _ = self._integrated((float(t_from), float(t_to)))
        i0 = int(np.argmin(np.abs(t_out - t_from)))
        i1 = int(np.argmin(np.abs(t_out - t_to)))
        stm = np.asarray(sens.stm)
        par = np.asarray(sens.par)
        phi = stm[i1] @ np.linalg.inv(stm[i0])
        theta = par[i1] - phi @ par[i0]
        return phi, theta


def augment(study: Study, phi7: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """The augmented transition (n, n) of PROP eq. 3 from Φ (7, 7) and Θ (7, n_dyn)."""
    n, nx = study.layout.n, study.nx
    out = np.eye(n)
    out[:nx, :nx] = phi7[:nx, :nx]
    j = 0
    for i, d in enumerate(study.dynamic):
        if d:
            out[:nx, nx + i] = theta[:nx, j]
            j += 1
    return out


def _gm_blocks(study: Study, span: ReferenceSpan, t_to: float, t_from: float):
    """The exact model's true-side (Gamma (nx, 3), E (3,), Q (nx + 3, nx + 3)) from t_from
    to t_to (fracas.team.gm_exact; ``study.gm_states``), memoized on the span."""
    from fracas.team.gm_exact import exact_noise

    key = ("gm", float(t_to), float(t_from), tuple(study.noise_sigma_true), tuple(study.noise_tau_true))
    if key not in span.memo:
        t = np.array([t_from, t_to], dtype=np.float64)
        x0, b0 = span.state(t_from)
        x1, b1 = span.state(t_to)
        ex = exact_noise(study, t, x0, np.array([x0, x1]), [b0, b1])
        g, e, q = (
            (ex.gamma_true, ex.E_true, ex.Q_true) if study.gencov else (ex.gamma_assumed, ex.E_assumed, ex.Q_assumed)
        )
        span.memo[key] = (g[1], e[1], q[1])
    return span.memo[key]


def _transition(study: Study, span: ReferenceSpan, t_to: float, t_from: float) -> np.ndarray:
    """The augmented transition (n, n) from t_from to t_to: PROP eq. 3, and with the exact
    Gauss-Markov model's noise states (``study.gm_states``) their true Gamma and E."""
    phi, theta = span.transition(t_to, t_from)
    out = augment(study, phi, theta)
    if study.gm_states and t_to > t_from:
        gam, e, _ = _gm_blocks(study, span, t_to, t_from)
        n = study.layout.n
        out[: study.nx, n - 3 :] = gam
        out[np.arange(n - 3, n), np.arange(n - 3, n)] = e
    return out


def _embed(study: Study, x: np.ndarray) -> np.ndarray:
    n = study.layout.n
    out = np.zeros((n, n))
    k = x.shape[0]
    out[:k, :k] = x
    return out


def _target_psi(study: Study, span: ReferenceSpan, g: GuidanceSpec, t_s: float):
    """Ψ (m, n) of g's targets with respect to the augmented state at t_s; the body used."""
    key = ("psi", g.name, g.target_time_s, t_s, tuple(g.targets), g.target_body)
    if key not in span.memo:
        span.memo[key] = _target_psi_uncached(study, span, g, t_s)
    return span.memo[key]


def _target_psi_uncached(study: Study, span: ReferenceSpan, g: GuidanceSpec, t_s: float):
    from fracas.guidance.targets import target_jacobian

    x_f, body_f = span.state(g.target_time_s)
    body = g.target_body or body_f
    x_rel = np.array(x_f[:6], dtype=np.float64)
    if body != body_f:  # the target body's state relative to the central body (DE421)
        x_rel = x_rel - _relative_body_state(study, body, body_f, g.target_time_s)
    mu = float(np.asarray(get_values(study.problem.params, [f"mu[{body}]"], study.problem.model))[0])
    a_t = np.asarray(target_jacobian(tuple(g.targets), x_rel, float(g.target_time_s), mu))
    nx = study.nx
    return a_t[:, :nx] @ _transition(study, span, g.target_time_s, t_s)[:nx, :], body


def _post(p_c, p_k, g_mat, mode, nx, reset="state"):
    """P_c⁺ of the correction δX⁺ = (I − G)δX + G e (numpy):
    :func:`fracas.guidance.impulsive.post_correction_covariance`."""
    return np.asarray(imp.post_correction_covariance(p_c, p_k, g_mat, mode, None, nx, reset))


def _relative_body_state(study: Study, body: str, centre: str, t_s: float) -> np.ndarray:
    """(6,) state of ``body`` relative to ``centre`` at t_s (s from the epoch), ICRF, DE421.

    The targets are functions of the spacecraft's state relative to the target body; that
    body's own motion does not depend on the spacecraft, so A_T is unchanged."""
    from fracas.constants import DAY_S
    from fracas.dynamics.ephemeris import body_states, build_ephemeris

    et = float(study.problem.epoch_et_s) + float(t_s)
    names = sorted({body, centre} - {"sun"})
    table = build_ephemeris(names, et - DAY_S, et + DAY_S, margin_s=DAY_S)
    pos, vel = (np.asarray(a) for a in body_states(table, et))
    helio = {b: np.concatenate([pos[i], vel[i]]) for i, b in enumerate(names)}
    helio["sun"] = np.zeros(6)
    return helio[body] - helio[centre]


def _law_columns(m: np.ndarray, study: Study) -> np.ndarray:
    """The columns of Ψ or Λ the guidance law acts on.  Default the estimated STATE only
    (digest (G-4): "the guidance uses the state estimate only"); with
    ``guidance_estimates = "state_and_solve_for"`` also the solve-for parameters (the
    digest's optional −Ψ_v⁺Ψ_s ŝ).  The target covariances keep every column (the other
    parameters' dispersion still reaches the target)."""
    keep = study.nx + (study.layout.ns if study.guidance_estimates == "state_and_solve_for" else 0)
    out = np.array(m, dtype=np.float64)
    out[:, keep:] = 0.0
    return out


def _reset(study: Study) -> str:
    return "exact" if study.guidance_estimates == "state_and_solve_for" else study.guidance_reset


def _sym(p):
    return 0.5 * (p + p.T)


def _thrust_at(study: Study, t_s: float, x: np.ndarray, body: str) -> tuple[float, float]:
    """(thrust acceleration km/s², thrust kg km/s²) at t_s from the mass rate: T = −c ṁ."""
    from fracas.integrate.variational import state_derivative

    pr = study.problem
    c = float(np.asarray(get_values(pr.params, ["exhaust_velocity_km_s"], pr.model))[0])
    prim = pr.model.bodies.index(body)
    xd = np.asarray(state_derivative(pr.model, pr.params, pr.ephem, pr.epoch_et_s, float(t_s), x, prim))
    thrust = -c * float(xd[6])
    return thrust / float(x[6]), thrust


def _noise_between(study: Study, span: ReferenceSpan, t_a: float, t_b: float) -> np.ndarray:
    """True DYNO Q̃ (nx, nx) accumulated from t_a to t_b, split at the thrust switches; with
    the exact model's noise states (``study.gm_states``) the exact Q (n, n) on the state and
    noise-state blocks, plus the white noise."""
    nx = study.nx
    if study.gm_states:
        n = study.layout.n
        out = np.zeros((n, n))
        if t_b > t_a:
            _, _, q = _gm_blocks(study, span, t_b, t_a)
            sel = np.r_[np.arange(nx), np.arange(n - 3, n)]
            out[np.ix_(sel, sel)] = q
            if study.has_white_noise:
                from fracas.team.transitions import white_noise

                x0, _ = span.state(t_a)
                wa, wt = white_noise(study, np.array([t_a, t_b]), x0)
                out[:nx, :nx] += (wt if study.gencov else wa)[1]
        return out
    if not study.has_process_noise or t_b <= t_a:
        return np.zeros((nx, nx))
    cuts = [t_a] + [s for s in study.thrust_switches_s if t_a + EPS_T < s < t_b - EPS_T] + [t_b]
    t = np.array(cuts)
    states, prim, phis = [], [], [np.eye(7)]
    for i, ti in enumerate(t):
        x, b = span.state(ti)
        states.append(x)
        prim.append(b)
        if i:
            phis.append(span.transition(ti, t[i - 1])[0])
    _, qt = interval_noise(study, t, np.array(states), prim, np.array(phis))
    q = np.zeros((nx, nx))
    for i in range(1, len(t)):
        ph = phis[i][:nx, :nx]
        q = ph @ q @ ph.T + qt[i]
    return q


def _common(study, g, k, body, t_s, cutoff_s) -> dict:
    """The fields every event's outcome shares."""
    return {
        "name": g.name,
        "type": g.type,
        "index": k,
        "time_s": t_s,
        "cutoff_s": cutoff_s,
        "target_time_s": g.target_time_s,
        "target_body": body,
        "estimate_model": study.guidance_model,
        "target_names": list(g.targets),
        "target_units": [TARGET_KINDS[t].unit for t in g.targets],
    }


def _impulsive(study, span, g, k, p_c, p_k, summary=True):
    nx, mode = study.nx, study.guidance_model
    psi, body = _target_psi(study, span, g, g.time_s)
    gm = imp.guidance_matrix(_law_columns(psi, study), g.weights, g.tolerances)
    gamma = np.asarray(gm.gamma)
    p_tilde = np.asarray(imp.estimate_deviation_covariance(p_c, p_k, mode))
    p_dv = _sym(gamma @ p_tilde @ gamma.T)
    sig_ex = np.asarray(
        imp.execution_error_covariance(
            np.zeros(3), p_dv, g.sigma_p, g.sigma_pointing_rad, g.sigma_pointing_rad, g.sigma_res_km_s
        )
    )
    b = np.asarray(imp.velocity_selector(study.layout.n))
    p_plus = _sym(_post(p_c, p_k, b @ gamma, mode, nx, _reset(study)) + b @ sig_ex @ b.T)
    x_exec = np.zeros((nx, nx))
    x_exec[_VEL, _VEL] = sig_ex
    out = GuidanceOutcome(
        **_common(study, g, k, body, g.time_s, g.time_s),
        rank=int(gm.rank),
        control_labels=["dv_x", "dv_y", "dv_z"],
        control_units=["km/s"] * 3,
        psi=psi,
        gamma=gamma,
        target_cov_before=_sym(psi @ p_c @ psi.T),
        target_cov_after=_sym(psi @ p_plus @ psi.T),
        target_cov_knowledge=_sym(psi @ p_k @ psi.T),
        correction_cov=p_dv,
        execution_cov=sig_ex,
        dv_mean_km_s=dvstats.mean_dv_magnitude(p_dv) if summary else float("nan"),
        dv_99_km_s=dvstats.dv_magnitude_quantile(p_dv, 0.99) if summary else float("nan"),
        dv_rms_km_s=dvstats.rms_dv_magnitude(p_dv),
        dv_variance_km2_s2=float(np.trace(p_dv)),
    )
    return out, p_plus, [(g.time_s, x_exec)]


def _low_thrust(study, span, g, k, p_c, p_k, summary=True):
    from fracas.guidance.low_thrust import (
        control_sensitivity,
        correction_cost_jacobians,
        execution_covariance,
        weighted_correction_matrix,
    )

    nx, n, mode = study.nx, study.layout.n, study.guidance_model
    t_i, t_c = g.time_s, g.cutoff_s
    key = ("S", g.name, t_i, t_c, tuple(g.control_labels))
    if key not in span.memo:
        span.memo[key] = np.asarray(control_sensitivity(study.problem, t_i, t_c, list(g.control_labels))[0])
    s7 = span.memo[key]
    phi_aug = _transition(study, span, t_c, t_i)
    psi_c, body = _target_psi(study, span, g, t_c)
    k_mat = psi_c[:, :nx] @ s7[:nx]
    lam = psi_c @ phi_aug
    gamma_u, rank = weighted_correction_matrix(k_mat, _law_columns(lam, study), g.weights, g.tolerances)
    gamma_u = np.asarray(gamma_u)
    p_tilde = np.asarray(imp.estimate_deviation_covariance(p_c, p_k, mode))
    p_u = _sym(gamma_u @ p_tilde @ gamma_u.T)
    sig_u = np.asarray(execution_covariance(tuple(g.controls), p_u, g.sigma_p))
    s_aug = np.zeros((n, s7.shape[1]))
    s_aug[:nx] = s7[:nx]
    g_mat = np.linalg.solve(phi_aug, s_aug @ gamma_u)
    p_reset = _sym(_post(p_c, p_k, g_mat, mode, nx, _reset(study)))
    key = ("noise", t_i, t_c, tuple(study.noise_sigma_true), study.gencov)
    if key not in span.memo:
        span.memo[key] = _noise_between(study, span, t_i, t_c)
    q_ic = _embed(study, span.memo[key])
    x_exec_full = s_aug @ sig_u @ s_aug.T
    pc_cutoff = _sym(phi_aug @ p_reset @ phi_aug.T + q_ic + x_exec_full)
    before = _sym(psi_c @ (phi_aug @ p_c @ phi_aug.T + q_ic) @ psi_c.T)
    know = _sym(psi_c @ (phi_aug @ p_k @ phi_aug.T) @ psi_c.T)
    key = ("thrust", t_i, t_c)
    if key not in span.memo:
        x_i, b_i = span.state(t_i)
        x_c, b_c = span.state(t_c)
        span.memo[key] = (
            x_i,
            x_c,
            _thrust_at(study, t_i + EPS_T, x_i, b_i),
            _thrust_at(study, t_c - EPS_T, x_c, b_c),
        )
    x_i, x_c, (a_i, thr_i), (a_c, thr_c) = span.memo[key]
    c = float(np.asarray(get_values(study.problem.params, ["exhaust_velocity_km_s"], study.problem.model))[0])
    j_dv, j_m = correction_cost_jacobians(tuple(g.controls), a_i, a_c, float(x_i[6]), float(x_c[6]), c, thr_i, thr_c)
    j_dv, j_m = np.asarray(j_dv), np.asarray(j_m)
    var_dv = float(j_dv @ p_u @ j_dv)
    sig_dv = math.sqrt(max(var_dv, 0.0))
    sig_m = math.sqrt(max(float(j_m @ p_u @ j_m), 0.0))
    out = GuidanceOutcome(
        **_common(study, g, k, body, t_i, t_c),
        rank=int(rank),
        control_labels=list(g.control_labels),
        control_units=list(g.control_units),
        psi=psi_c,
        gamma=gamma_u,
        target_cov_before=before,
        target_cov_after=_sym(psi_c @ pc_cutoff @ psi_c.T),
        target_cov_knowledge=know,
        correction_cov=p_u,
        execution_cov=sig_u,
        dv_mean_km_s=math.sqrt(2.0 / math.pi) * sig_dv,
        dv_99_km_s=Z99 * sig_dv,
        dv_rms_km_s=sig_dv,
        propellant_sigma_kg=sig_m,
        dv_variance_km2_s2=var_dv,
        dv_jacobian=j_dv,
        control_matrix=np.asarray(k_mat),
    )
    return out, p_reset, [(t_c, x_exec_full[:nx, :nx])]


def _none(study, span, g, k, p_c, p_k, summary=True):
    psi, body = _target_psi(study, span, g, g.time_s)
    before = _sym(psi @ p_c @ psi.T)
    out = GuidanceOutcome(
        **_common(study, g, k, body, g.time_s, g.time_s),
        rank=0,
        control_labels=[],
        control_units=[],
        psi=psi,
        gamma=np.zeros((0, study.layout.n)),
        target_cov_before=before,
        target_cov_after=before.copy(),
        target_cov_knowledge=_sym(psi @ p_k @ psi.T),
        correction_cov=np.zeros((0, 0)),
        execution_cov=np.zeros((0, 0)),
    )
    return out, p_c, []


_HANDLERS = {"impulsive": _impulsive, "primary": _low_thrust, "vernier": _low_thrust, "none": _none}


def run_guidance(
    study: Study,
    phi_aug: np.ndarray,
    Qt: np.ndarray,
    run_filter: Callable,
    span: ReferenceSpan,
    assumed_exec: np.ndarray | None = None,
    P0_control: np.ndarray | None = None,
    summary: bool = True,
) -> GuidanceRun:
    """GUIDM/XGUID over the study's guidance events (module docstring).

    phi_aug (K, n, n), Qt (K, nx, nx): the filter's transitions and TRUE process noise;
    run_filter(Xa, Xt) -> (Pa_m, Pa_p, Pt_m, Pt_p, sig): the compiled filter with execution
    errors; assumed_exec (K, nx, nx): fixed assumed-side execution covariances (None: the
    same as the true side's).  P0_control: overrides ``study.P0_control``.  summary=False
    skips the |ΔV| mean and quantile (NaN; the error budget needs only the covariances).
    """
    sched = study.schedule
    K, n, nx = sched.n, study.layout.n, study.nx
    Xa = np.zeros((K, nx, nx)) if assumed_exec is None else np.array(assumed_exec)
    Xt = np.zeros((K, nx, nx))
    Xc = np.zeros((K, nx, nx))
    pc0 = P0_control if P0_control is not None else study.P0_control
    if pc0 is None:
        pc0 = study.P0_true
    wanted = set()
    for g in study.guidance:
        wanted |= {g.time_s, g.cutoff_s, g.target_time_s}
    lo, hi = min(wanted), max(wanted)
    wanted |= {s for s in study.thrust_switches_s if lo < s < hi}
    span.prefetch(wanted)
    outs = run_filter(Xa, Xt)
    control = np.zeros((K, n, n))
    epoch = np.zeros(K, dtype=np.int64)
    control[0] = pc0
    state = {"cursor": 0, "P": np.array(pc0, dtype=np.float64), "epoch": 0}

    def advance(k: int) -> None:
        P = state["P"]
        for j in range(state["cursor"] + 1, k + 1):
            P = phi_aug[j] @ P @ phi_aug[j].T
            if Qt.shape[-1] == n:  # the exact model's Q covers the noise states too
                P = P + Qt[j]
                P[:nx, :nx] += Xc[j]
            else:
                P[:nx, :nx] += Qt[j] + Xc[j]
            P = _sym(P)
            control[j] = P
            epoch[j] = state["epoch"]
        state["P"], state["cursor"] = P, max(state["cursor"], k)

    outcomes: list[GuidanceOutcome] = []
    for g in study.guidance:
        k = sched.index_of(g.time_s)
        advance(k)
        p_c = state["P"]
        pt_plus = outs[3] if study.gencov else outs[1]
        p_k = np.asarray(pt_plus[k], dtype=np.float64)
        out, p_plus, execs = _HANDLERS[g.type](study, span, g, k, p_c, p_k, summary)
        outcomes.append(out)
        control[k] = p_plus
        state["P"], state["epoch"] = p_plus, k
        epoch[k] = k
        changed = False
        for t_x, x in execs:
            if t_x < sched.times_s[0] - 1e-6 or t_x > sched.times_s[-1] + 1e-6:
                continue  # beyond the study: only the target covariance sees it
            kx = sched.index_of(t_x)
            Xt[kx] += x
            Xc[kx] += x
            if assumed_exec is None:
                Xa[kx] += x
            changed = True
        if changed:
            outs = run_filter(Xa, Xt)
    advance(K - 1)
    return GuidanceRun(outs, control, epoch, outcomes, Xa, Xt)
