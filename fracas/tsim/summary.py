"""TSIM statistics (STAT, SCØMP) and the TEAM ↔ TSIM consistency report (digest C.4-C.7).

Host numpy.  Every statistic is over the successful missions (status 0 ok or 1 near
success, P-C6; the others are counted, never averaged).  Running statistics are
(count, mean, co-moment) triples (:mod:`fracas.tsim.statistics`), computed block by block
in mission-index order (blocks of :attr:`TsimPlan.block` missions) and merged in that order
(STAT-1), so they are the same bits whatever the batch size, the worker count or a resume;
a-priori statistics of earlier runs merge in last (exact in count, mean and co-moment; the
order of a merge changes only rounding).

Consistency (one row per compared output): TSIM's sample covariance against TEAM's
prediction.  The final target errors are judged against the last maneuver's
``target_cov_after``: the dispersion at the target time, with the execution errors and the
process noise from the maneuver's cutoff to the target time (the thrust noise TSIM flies
after the last maneuver), not the control covariance mapped from the cutoff alone.

* ``ratio``: σ_TSIM/σ_TEAM per axis, with its standard error ≈ 1/√(2(N−1)) (P-C7);
* ``chi2``/``p_value``: the likelihood-ratio test of the whole matrix (Box-corrected);
* ``mean_chi2``/``mean_p_value``: N x̄ᵀΣ⁻¹x̄ (TEAM predicts zero mean);
* ``coverage``: the fraction of missions inside TEAM's 1σ/2σ/3σ ellipsoids against χ²_p's;
* ``verdict``: "consistent" when neither test rejects at α = 1e-3; "nonlinear" when the
  covariance test rejects and some axis is off by more than both 3 SE and 10 %; "biased"
  when only the mean test rejects; "differs" when the covariance test rejects with every
  axis within 10 % (a correlation or a small but significant scale difference).  The
  message names the worst axis in words ("target z dispersion 1.8× TEAM's: nonlinear").

Mean |ΔV| rows compare TSIM's mean |ΔV| with TEAM's exact mean (the Hoffman-Young stand-in,
digest (G-9)) by a z-score on the sample's standard error.
"""

from __future__ import annotations

import numpy as np

from fracas.tsim import statistics as st
from fracas.tsim.plan import STATUS_NEAR, STATUS_OK, TsimPlan

__all__ = ["ALPHA", "good_rows", "statistics_of", "merge_a_priori", "consistency", "counts_of", "percentiles_of"]

ALPHA = 1e-3  # false-alarm probability of each consistency test
DESIGN_FRACTION = 0.1  # a linear design miss beyond 10 % of TEAM's delivery sigma is flagged


def good_rows(table: dict) -> np.ndarray:
    s = table["status"]
    return (s == STATUS_OK) | (s == STATUS_NEAR)


def _groups(plan: TsimPlan, table: dict) -> dict[str, np.ndarray]:
    """name -> (N, p) values of every statistic (all missions; filter with good_rows)."""
    out = {"target_error": table["target_error"]}
    for j, m in enumerate(plan.maneuvers):
        out[f"dv_km_s[{m.name}]"] = table["dv_km_s"][:, j : j + 1]
        out[f"correction[{m.name}]"] = table["correction"][:, j, : m.n_controls]
        out[f"state_deviation[{m.name}]"] = table["state_deviation"][:, j, : plan.nx]
    out["dv_total_km_s"] = table["dv_total_km_s"][:, None]
    out["final_mass_kg"] = table["final_mass_kg"][:, None]
    return out


def statistics_of(plan: TsimPlan, table: dict) -> dict[str, st.Moments]:
    """Block-ordered running statistics (module docstring) of this run's missions."""
    good = good_rows(table)
    n = table["mission"].shape[0]
    out = {}
    for name, vals in _groups(plan, table).items():
        blocks = []
        for s in range(0, n, plan.block):
            sel = good[s : s + plan.block]
            blocks.append(st.moments_of(vals[s : s + plan.block][sel]))
        out[name] = st.merge_all(blocks) if blocks else st.moments_of(vals[:0])
    return out


def merge_a_priori(stats: dict[str, st.Moments], earlier: list[dict[str, tuple]]) -> dict[str, st.Moments]:
    """``stats`` merged with earlier runs' (count, mean, covariance) statistics (STAT-1;
    M2 = C(n−1) rebuilt from what was punched)."""
    out = dict(stats)
    for prev in earlier:
        for name, (count, mean, cov) in prev.items():
            if name in out and count > 0:
                out[name] = st.merge(out[name], st.from_covariance(int(count), np.asarray(mean), np.asarray(cov)))
    return out


def percentiles_of(plan: TsimPlan, table: dict, q=(50.0, 90.0, 99.0)) -> dict[str, dict[float, float]]:
    """Percentiles of |ΔV| per maneuver, total ΔV and final mass (this run's missions)."""
    good = good_rows(table)
    out = {}
    for j, m in enumerate(plan.maneuvers):
        out[f"dv_km_s[{m.name}]"] = st.percentiles(table["dv_km_s"][good, j], q)
    out["dv_total_km_s"] = st.percentiles(table["dv_total_km_s"][good], q)
    out["final_mass_kg"] = st.percentiles(table["final_mass_kg"][good], (1.0, 10.0, 50.0))
    return out


def counts_of(plan: TsimPlan, table: dict) -> dict[str, int]:
    s = table["status"]
    return {
        "missions": int(s.shape[0]),
        "ok": int(np.sum(s == STATUS_OK)),
        "near": int(np.sum(s == STATUS_NEAR)),
        "hopeless": int(np.sum(s == 2)),
        "failed": int(np.sum(s == 3)),
    }


def _words(output: str, name: str, ratio: float) -> str:
    return f"{output} {name} dispersion {ratio:.2f}x TEAM's"


def compare_covariance(output: str, names, units, x: np.ndarray, predicted: np.ndarray) -> dict:
    """One consistency row (module docstring) of samples x (N, p) against TEAM's ``predicted``."""
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0]
    row = {"output": output, "names": list(names), "units": list(units), "count": int(n)}
    if n < 3 or not np.all(np.isfinite(predicted)):
        row.update(ratio=[], se=float("nan"), chi2=float("nan"), dof=0, p_value=float("nan"),
                   mean_chi2=float("nan"), mean_p_value=float("nan"), coverage=[], verdict="not compared",
                   message=f"{output}: not compared ({n} successful missions)")  # fmt: skip
        return row
    mom = st.moments_of(x)
    cov = st.covariance(mom)
    ratio, se = st.axis_ratios(cov, predicted, n)
    chi2, dof, p = st.covariance_test(cov, n, predicted)
    mchi2, mdof, mp = st.mean_test(mom.mean, n, predicted)
    cover = [list(map(float, c)) for c in st.ellipse_coverage(x, predicted)]
    se_v = float(np.atleast_1d(se)[0])
    off = np.abs(np.asarray(ratio) - 1.0)
    worst = int(np.nanargmax(off)) if off.size else 0
    big = bool(np.any((off > 3.0 * se_v) & (off > 0.10)))
    if p >= ALPHA and mp >= ALPHA:
        verdict = "consistent"
        msg = f"{output}: consistent with TEAM (worst axis {names[worst]} {ratio[worst]:.2f}x, SE {se_v:.2f})"
    elif p < ALPHA and big:
        verdict = "nonlinear"
        msg = _words(output, names[worst], ratio[worst]) + ": nonlinear"
    elif p >= ALPHA:
        verdict = "biased"
        k = int(np.argmax(np.abs(mom.mean) / np.sqrt(np.maximum(np.diag(predicted), 1e-300))))
        msg = f"{output} {names[k]} mean {mom.mean[k]:.3g} {units[k]} off TEAM's zero: nonlinear (biased)"
    else:
        verdict = "differs"
        msg = f"{output}: differs from TEAM (covariance test p = {p:.1e}; every axis within 10 %)"
    row.update(
        ratio=[float(r) for r in ratio], se=se_v, chi2=float(chi2), dof=int(dof), p_value=float(p),
        mean_chi2=float(mchi2), mean_p_value=float(mp), coverage=cover, verdict=verdict, message=msg,
    )  # fmt: skip
    return row


def compare_mean_dv(name: str, dv: np.ndarray, team_mean: float) -> dict:
    """TSIM's mean |ΔV| against TEAM's exact mean (z-score on the sample's standard error)."""
    n = dv.shape[0]
    mean = float(np.mean(dv)) if n else float("nan")
    sem = float(np.std(dv, ddof=1) / np.sqrt(n)) if n > 1 else float("nan")
    z = (mean - team_mean) / sem if sem > 0 else float("nan")
    ok = np.isfinite(z) and abs(z) < 3.29  # two-sided α = 1e-3
    rel = mean / team_mean - 1.0 if team_mean > 0 else float("nan")
    verdict = "consistent" if ok else "nonlinear"
    msg = (
        f"mean |dv| {name}: {mean * 1e3:.4g} m/s vs TEAM {team_mean * 1e3:.4g} m/s ({100 * rel:+.1f} %, "
        f"z = {z:.1f}){'' if ok else ': nonlinear'}"
    )
    return {"output": f"mean |dv| [{name}]", "names": ["|dv|"], "units": ["km/s"], "count": int(n),
            "ratio": [mean / team_mean if team_mean > 0 else float("nan")], "se": sem / team_mean if team_mean > 0
            else float("nan"), "chi2": float(z * z) if np.isfinite(z) else float("nan"), "dof": 1,
            "p_value": float("nan"), "mean_chi2": float("nan"), "mean_p_value": float("nan"), "coverage": [],
            "verdict": verdict, "message": msg}  # fmt: skip


def consistency(plan: TsimPlan, table: dict) -> list[dict]:
    """Every consistency row of this run: the final target errors, each maneuver's commanded
    correction and its mean |ΔV| (module docstring)."""
    good = good_rows(table)
    rows = [
        compare_covariance(
            "target", plan.final.names, plan.final.units, table["target_error"][good], plan.final_team["target_cov"]
        )
    ]
    for j, m in enumerate(plan.maneuvers):
        rows.append(
            compare_covariance(
                f"correction {m.name}",
                m.control_labels,
                m.control_units,
                table["correction"][good, j, : m.n_controls],
                m.team["correction_cov"],
            )
        )
        team_mean = m.team["dv_mean_km_s"]
        if np.isfinite(team_mean):
            rows.append(compare_mean_dv(m.name, table["dv_km_s"][good, j], team_mean))
        if m.impulsive and "design_miss" in table:
            rows.append(design_row(m, table["linear_design_miss"][good, j], table["design_miss"][good, j], m.law))
    return rows


def design_row(m, linear_miss: np.ndarray, miss: np.ndarray, law: str) -> dict:
    """How far the linear design misses its targets on the estimated trajectory (RMS over
    missions, per target), against TEAM's predicted dispersion at those targets after the
    maneuver: "nonlinear" when the miss exceeds :data:`DESIGN_FRACTION` of that σ for some
    target (the law's linearization, not the knowledge, then shapes the delivery; below it
    the miss adds under 1 % to the variance); with a nonlinear law, what the iteration left
    (against its tolerances)."""
    k = len(m.target.names)
    tol = np.asarray(m.target.tolerance, float)
    sig = np.sqrt(np.maximum(np.diag(np.asarray(m.team["target_cov_after"], float))[:k], 0.0))
    n = linear_miss.shape[0]
    rms_lin = np.sqrt(np.mean(np.square(linear_miss[:, :k]), axis=0)) if n else np.full(k, np.nan)
    rms = np.sqrt(np.mean(np.square(miss[:, :k]), axis=0)) if n else np.full(k, np.nan)
    rel = rms_lin / np.where(sig > 0, sig, np.inf)
    worst = int(np.nanargmax(rel)) if n else 0
    linear_ok = bool(n) and bool(np.all(rel <= DESIGN_FRACTION))
    unit = m.target.units[worst]
    msg = (
        f"design {m.name}: the linear law misses {m.target.names[worst]} by {rms_lin[worst]:.3g} {unit} RMS "
        f"on the estimated trajectory ({100 * rel[worst]:.2g} % of TEAM's sigma after it)"
    )
    if law == "nonlinear":
        msg += f"; the nonlinear design by {rms[worst]:.3g} {unit} (tolerance {tol[worst]:.3g})"
    if not linear_ok:
        msg += ": nonlinear"
    return {"output": f"design miss [{m.name}]", "names": list(m.target.names), "units": list(m.target.units),
            "count": int(n), "ratio": [float(r) for r in rel], "se": float("nan"),
            "chi2": float("nan"), "dof": 0, "p_value": float("nan"), "mean_chi2": float("nan"),
            "mean_p_value": float("nan"), "coverage": [],
            "verdict": "consistent" if linear_ok else "nonlinear", "message": msg}  # fmt: skip
