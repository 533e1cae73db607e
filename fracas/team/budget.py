"""The error budget of a TEAM study: each error source's share of chosen output variances.

Exact by linearity.  With the gains fixed (they come from the assumed covariance, which
every budget run keeps, execution errors included), the true knowledge covariance, the
control covariance, the ΔV and control-correction covariances and the target covariances
are all linear in the true error sources: the a-priori covariance, the measurement noise
R, the thrust process noise Q̃, and the constant part of the execution errors.  So one run
per source with every other source set to zero gives that source's contribution, and the
contributions sum to the full run's variance (checked, ``sum_check``).

Sources: ``a-priori state`` (the state block of the true a-priori, and of the control
a-priori when that is the default), ``injection dispersion`` (the control a-priori's state
block when the deck gives one), each parameter label (its a-priori variance, in both), the
cross-correlations between those blocks when a punched covariance has them (``a-priori
correlations``), ``<kind> noise`` per measurement kind, ``thrust noise`` and ``execution
resolution``.  The proportionality and pointing execution errors scale with the commanded
ΔV, so they are counted with the source whose ΔV they scale (they vanish with it).

Outputs (variances, in the unit² of their names): each guidance event's ΔV RMS and each of
its targets after the correction (at the target time: the process noise after the cutoff,
:mod:`fracas.team.guidance_events`, is the process-noise source's); the true knowledge's
position and velocity RSS at the study's end and at ``Study.budget_at_s``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fracas.constants import DAY_S
from fracas.products import ErrorBudget
from fracas.team.study import Study

__all__ = ["ErrorBudget", "budget_outputs", "budget_sources", "error_budget"]


def budget_outputs(study: Study, p_true_plus: np.ndarray, outcomes) -> tuple[list[str], list[str], np.ndarray]:
    """The budget's outputs (names, units, variances) of one run."""
    names, units, vals = [], [], []
    for o in outcomes:
        if o.type != "none":
            names.append(f"{o.name} dV rms")
            units.append("km/s")
            vals.append(o.dv_variance_km2_s2)  # unclipped: a source's share may be indefinite
        for j, t in enumerate(o.target_names):
            names.append(f"{o.name} {t} after")
            units.append(o.target_units[j])
            vals.append(float(o.target_cov_after[j, j]))
    times = study.schedule.times_s
    for t in list(study.budget_at_s) + [float(times[-1])]:
        k = study.schedule.index_of(t)
        what = "final" if k == len(times) - 1 else f"{times[k] / DAY_S:g} d"
        P = p_true_plus[k]
        names += [f"{what} position rss", f"{what} velocity rss"]
        units += ["km", "km/s"]
        vals += [float(np.trace(P[:3, :3])), float(np.trace(P[3:6, 3:6]))]
    return names, units, np.array(vals, dtype=np.float64)


def _block(P: np.ndarray, idx: list[int]) -> np.ndarray:
    out = np.zeros_like(P)
    ix = np.ix_(idx, idx)
    out[ix] = P[ix]
    return out


def budget_sources(study: Study, meas) -> list[dict]:
    """The error sources of a study, each as the pieces a single-source run keeps."""
    nx, n = study.nx, study.layout.n
    P0t = np.asarray(study.P0_true, dtype=np.float64)
    separate = study.P0_control is not None
    P0c = np.asarray(study.P0_control if separate else P0t, dtype=np.float64)
    zero = np.zeros((n, n))
    out = []
    state = list(range(nx))
    out.append({"name": "a-priori state", "P0t": _block(P0t, state), "P0c": zero if separate else _block(P0c, state)})
    if separate:
        out.append({"name": "injection dispersion", "P0t": zero, "P0c": _block(P0c, state)})
    eta = list(range(n - 3, n)) if study.gm_states else []  # the exact model's noise states
    for i, lab in enumerate(study.labels):
        idx = [nx + i]
        if nx + i in eta:
            continue
        if P0t[nx + i, nx + i] > 0 or P0c[nx + i, nx + i] > 0:
            out.append({"name": lab, "P0t": _block(P0t, idx), "P0c": _block(P0c, idx)})
    eta_t, eta_c = zero.copy(), zero.copy()
    if eta:  # their block and their correlations with the rest (punched) are thrust noise
        rest = [i for i in range(n) if i not in eta]
        eta_t = P0t - _block(P0t, rest)
        eta_c = P0c - _block(P0c, rest)
    rt = P0t - sum(s["P0t"] for s in out) - eta_t
    rc = P0c - sum(s["P0c"] for s in out) - eta_c
    if np.any(rt != 0) or np.any(rc != 0):
        out.append({"name": "a-priori correlations", "P0t": rt, "P0c": rc})
    for s in out:
        s.update(thrust=False, kind=None, resolution=False)
    for kind in sorted({r.kind for r in meas.records if r.used}):
        out.append(
            {"name": f"{kind} noise", "P0t": zero, "P0c": zero, "thrust": False, "kind": kind, "resolution": False}
        )
    white = study.white_q_true > 0 if study.gencov else study.white_q_assumed > 0
    if (
        study.gencov
        and np.any(study.noise_sigma_true > 0)
        or (not study.gencov and np.any(study.noise_sigma_assumed > 0))
        or white
    ):
        out.append(
            {
                "name": "process noise" if white else "thrust noise",
                "P0t": eta_t,
                "P0c": eta_c,
                "thrust": True,
                "kind": None,
                "resolution": False,
            }
        )
    if any(g.type == "impulsive" and g.sigma_res_km_s > 0 for g in study.guidance):
        out.append(
            {
                "name": "execution resolution",
                "P0t": zero,
                "P0c": zero,
                "thrust": False,
                "kind": None,
                "resolution": True,
            }
        )
    return out


def _mask_r(meas, kind: str | None) -> np.ndarray:
    R = np.asarray(meas.R_true)
    mask = np.zeros(R.shape[:2], dtype=bool)
    if kind is not None:
        for r in meas.records:
            if r.used and r.kind == kind:
                mask[r.k, r.row] = True
    m = mask[:, :, None] & mask[:, None, :]
    return np.where(m, R, 0.0)


def error_budget(
    study: Study, phi_aug, Qa, Qt, meas, full_outs, guidance_run=None, span=None, augmented=None
) -> ErrorBudget:
    """One true-side run per source (module docstring); ``full_outs``: the full run's
    filter outputs, ``guidance_run``: its :class:`~fracas.team.guidance.GuidanceRun`;
    ``augmented``: the exact Gauss-Markov model's inputs (``run_filter``'s ``augmented``),
    with ``study`` its augmented view (fracas.team.gm_exact.augmented_view): the noise
    states' a priori belongs to the thrust-noise source (:func:`budget_sources`)."""
    from fracas.team.guidance import run_guidance
    from fracas.team.scan import run_filter

    pt_full = full_outs[3] if study.gencov else full_outs[1]
    outcomes = guidance_run.outcomes if guidance_run is not None else []
    names, units, total = budget_outputs(study, pt_full, outcomes)
    sig_t = study.noise_sigma_true if study.gencov else study.noise_sigma_assumed
    tau_t = study.noise_tau_true if study.gencov else study.noise_tau_assumed
    # the white acceleration noise belongs to the process-noise source too: the guidance
    # events' noise to cutoff and to the target time read the study's true level
    wq_t = study.white_q_true if study.gencov else study.white_q_assumed
    wd_t = study.white_direction_true if study.gencov else study.white_direction_assumed
    sources = budget_sources(study, meas)
    cols = []
    for src in sources:
        guid = tuple(
            dataclasses.replace(g, sigma_res_km_s=g.sigma_res_km_s if src["resolution"] else 0.0)
            for g in study.guidance
        )
        st = dataclasses.replace(
            study,
            gencov=True,
            P0_true=src["P0t"],
            P0_control=src["P0c"],
            noise_sigma_true=sig_t if src["thrust"] else np.zeros_like(sig_t),
            noise_tau_true=tau_t,
            white_q_true=wq_t if src["thrust"] else 0.0,
            white_direction_true=wd_t,
            guidance=guid,
        )
        qt = Qt if src["thrust"] else np.zeros_like(Qt)
        ms = dataclasses.replace(meas, R_true=_mask_r(meas, src["kind"]))
        aug = None
        if augmented is not None:  # the exact model: ``study`` is its augmented view (n + 3)
            phit = augmented.get("phi_true")
            aug = dict(augmented, phi_true=phi_aug if phit is None else phit)

        def filt(xa, xt, st=st, qt=qt, ms=ms, aug=aug):
            return run_filter(st, phi_aug, Qa, qt, ms, xa, xt, host=False, augmented=aug)

        if guidance_run is not None:
            phi_c = aug["phi_true"] if aug is not None else phi_aug  # the control covariance's (true) transitions
            gr = run_guidance(
                st, phi_c, qt, filt, span, assumed_exec=guidance_run.Xa, P0_control=src["P0c"], summary=False
            )
            _, _, vals = budget_outputs(st, gr.outs[3], gr.outcomes)
        else:
            outs = filt(None, None)
            _, _, vals = budget_outputs(st, outs[3], [])
        cols.append(vals)
    var = np.stack(cols, axis=1) if cols else np.zeros((len(names), 0))
    denom = np.where(np.abs(total) > 0, np.abs(total), 1.0)
    check = float(np.max(np.abs(var.sum(axis=1) - total) / denom)) if len(total) else 0.0
    return ErrorBudget(names, units, [s["name"] for s in sources], var, total, check)
