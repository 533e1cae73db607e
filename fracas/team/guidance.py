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

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fracas.team.guidance_events import _HANDLERS, Z99, GuidanceOutcome, _sym
from fracas.team.guidance_span import ReferenceSpan
from fracas.team.guidance_span import _relative_body_state as _relative_body_state  # fracas.build.tsim
from fracas.team.study import Study

__all__ = ["GuidanceOutcome", "ReferenceSpan", "GuidanceRun", "run_guidance", "Z99"]


@dataclass
class GuidanceRun:
    """The filter outputs with every event's execution errors, and the control history."""

    outs: tuple
    control: np.ndarray  # (K, n, n) after each event
    control_epoch: np.ndarray  # (K,) schedule index of the last reset
    outcomes: list[GuidanceOutcome]
    Xa: np.ndarray
    Xt: np.ndarray


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
