"""The TEAM guidance events' corrections (FRACAS GUIDM §5.3.6, XGUID §5.3.25; digest
``tom-tsim-guidance.md`` Part B; :mod:`fracas.team.guidance`): one handler per event type
(impulsive, primary/vernier low thrust, none), each giving the event's outcome, the control
covariance after it and its execution errors.

The target covariances before and after the correction are the dispersions AT THE TARGET
TIME: the control covariance at the cutoff mapped by Ψ (GUIDM's P_T = Ψ P_c Ψᵀ, digest
(G-8)) plus the true process noise from the cutoff to the target time mapped by A_T
(``target_noise_cov``, :func:`fracas.team.guidance_span._target_noise`); GUIDM's mapping
alone leaves out every unmodeled acceleration after the last correction.  The knowledge
mapped to the target (``target_cov_knowledge``) stays Ψ P_k Ψᵀ: the navigation error the
correction is designed from."""

from __future__ import annotations

import math

import numpy as np

from fracas.dynamics.parameters import get_values
from fracas.guidance import impulsive as imp
from fracas.guidance import statistics as dvstats
from fracas.guidance.target_kinds import TARGET_KINDS
from fracas.products import GuidanceEvent
from fracas.team.guidance_span import (
    ReferenceSpan,
    _embed,
    _noise_between,
    _noise_settings,
    _target_noise,
    _target_psi,
    _thrust_ends,
    _transition,
)
from fracas.team.study import GuidanceSpec, Study

GuidanceOutcome = GuidanceEvent  # the product is what the core makes
#: what an event handler returns: the outcome, P_c after the event, [(time, execution covariance)]
Outcome = tuple[GuidanceOutcome, np.ndarray, list[tuple[float, np.ndarray]]]

__all__ = ["GuidanceOutcome", "Z99"]

Z99 = 2.5758293035489004  # the 99 % point of |N(0, 1)|: a one-dimensional |δΔV| quantile
_VEL = slice(3, 6)


def _post(p_c: np.ndarray, p_k: np.ndarray, g_mat: np.ndarray, mode: str, nx: int, reset: str = "state") -> np.ndarray:
    """P_c⁺ of the correction δX⁺ = (I − G)δX + G e (numpy):
    :func:`fracas.guidance.impulsive.post_correction_covariance`."""
    return np.asarray(imp.post_correction_covariance(p_c, p_k, g_mat, mode, None, nx, reset))


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


def _sym(p: np.ndarray) -> np.ndarray:
    return 0.5 * (p + p.T)


def _correction_cov(gamma: np.ndarray, p_c: np.ndarray, p_k: np.ndarray, mode: str) -> np.ndarray:
    """The covariance Γ P̃ Γᵀ of the commanded correction (digest (G-5)), P̃ that of the
    estimated deviation (:func:`fracas.guidance.impulsive.estimate_deviation_covariance`)."""
    p_tilde = np.asarray(imp.estimate_deviation_covariance(p_c, p_k, mode))
    return _sym(gamma @ p_tilde @ gamma.T)


def _common(study: Study, g: GuidanceSpec, k: int, body: str, t_s: float, cutoff_s: float) -> dict:
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


def _impulsive(
    study: Study, span: ReferenceSpan, g: GuidanceSpec, k: int, p_c: np.ndarray, p_k: np.ndarray, summary: bool = True
) -> Outcome:
    nx, mode = study.nx, study.guidance_model
    psi, body = _target_psi(study, span, g, g.time_s)
    gm = imp.guidance_matrix(_law_columns(psi, study), g.weights, g.tolerances)
    gamma = np.asarray(gm.gamma)
    p_dv = _correction_cov(gamma, p_c, p_k, mode)
    sig_ex = np.asarray(
        imp.execution_error_covariance(
            np.zeros(3), p_dv, g.sigma_p, g.sigma_pointing_rad, g.sigma_pointing_rad, g.sigma_res_km_s
        )
    )
    b = np.asarray(imp.velocity_selector(study.layout.n))
    p_plus = _sym(_post(p_c, p_k, b @ gamma, mode, nx, _reset(study)) + b @ sig_ex @ b.T)
    q_t = _target_noise(study, span, g, g.time_s)
    x_exec = np.zeros((nx, nx))
    x_exec[_VEL, _VEL] = sig_ex
    out = GuidanceOutcome(
        **_common(study, g, k, body, g.time_s, g.time_s),
        rank=int(gm.rank),
        control_labels=["dv_x", "dv_y", "dv_z"],
        control_units=["km/s"] * 3,
        psi=psi,
        gamma=gamma,
        target_cov_before=_sym(psi @ p_c @ psi.T) + q_t,
        target_cov_after=_sym(psi @ p_plus @ psi.T) + q_t,
        target_cov_knowledge=_sym(psi @ p_k @ psi.T),
        correction_cov=p_dv,
        execution_cov=sig_ex,
        dv_mean_km_s=dvstats.mean_dv_magnitude(p_dv) if summary else float("nan"),
        dv_99_km_s=dvstats.dv_magnitude_quantile(p_dv, 0.99) if summary else float("nan"),
        dv_rms_km_s=dvstats.rms_dv_magnitude(p_dv),
        dv_variance_km2_s2=float(np.trace(p_dv)),
        target_noise_cov=q_t,
    )
    return out, p_plus, [(g.time_s, x_exec)]


def _low_thrust(
    study: Study, span: ReferenceSpan, g: GuidanceSpec, k: int, p_c: np.ndarray, p_k: np.ndarray, summary: bool = True
) -> Outcome:
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
    p_u = _correction_cov(gamma_u, p_c, p_k, mode)
    sig_u = np.asarray(execution_covariance(tuple(g.controls), p_u, g.sigma_p))
    s_aug = np.zeros((n, s7.shape[1]))
    s_aug[:nx] = s7[:nx]
    g_mat = np.linalg.solve(phi_aug, s_aug @ gamma_u)
    p_reset = _sym(_post(p_c, p_k, g_mat, mode, nx, _reset(study)))
    key = ("noise", t_i, t_c, *_noise_settings(study))
    if key not in span.memo:
        span.memo[key] = _noise_between(study, span, t_i, t_c)
    q_ic = _embed(study, span.memo[key])
    x_exec_full = s_aug @ sig_u @ s_aug.T
    pc_cutoff = _sym(phi_aug @ p_reset @ phi_aug.T + q_ic + x_exec_full)
    q_t = _target_noise(study, span, g, t_c)
    before = _sym(psi_c @ (phi_aug @ p_c @ phi_aug.T + q_ic) @ psi_c.T) + q_t
    know = _sym(psi_c @ (phi_aug @ p_k @ phi_aug.T) @ psi_c.T)
    x_i, x_c, (a_i, thr_i), (a_c, thr_c) = _thrust_ends(study, span, t_i, t_c)
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
        target_cov_after=_sym(psi_c @ pc_cutoff @ psi_c.T) + q_t,
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
        target_noise_cov=q_t,
    )
    return out, p_reset, [(t_c, x_exec_full[:nx, :nx])]


def _none(
    study: Study, span: ReferenceSpan, g: GuidanceSpec, k: int, p_c: np.ndarray, p_k: np.ndarray, summary: bool = True
) -> Outcome:
    psi, body = _target_psi(study, span, g, g.time_s)
    q_t = _target_noise(study, span, g, g.time_s)
    before = _sym(psi @ p_c @ psi.T) + q_t
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
        target_noise_cov=q_t,
    )
    return out, p_c, []


_HANDLERS = {"impulsive": _impulsive, "primary": _low_thrust, "vernier": _low_thrust, "none": _none}
