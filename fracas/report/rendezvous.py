"""Two-vehicle (rendezvous) report: the terminal summary (80 columns) and the error-history
plot, from a :class:`fracas.products.RendezvousProduct`
(:func:`fracas.io.rendezvous_results.read_rendezvous_results`).

Everything is shown in the deck's length unit (ft and fps for the Apollo example, as in
R-649).  "RMS" is the root of the trace of a 3 x 3 block (R-649's "statistical" curves):
of the TRUE covariance unless marked "belief" (what the filter believes: its assumed
covariance); the run computed them (``team_rms``, ``assumed_rms``; the relative covariance
is E_R = E_A + E_T - G - G', R-649 Eq. 17).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fracas.products import RendezvousProduct
from fracas.report._tables import fit_line

__all__ = ["rms_table", "summary_text", "plot_rendezvous", "rendezvous_figure", "report_times", "run_consistency"]

_GROUPS = ("chaser_r", "chaser_v", "target_r", "target_v", "relative_r", "relative_v")

_ROLE = {"solve_for": "optimum", "consider": "Schmidt", "ignore": "Apollo"}


def rms_table(product: RendezvousProduct, which: str = "true") -> dict[str, np.ndarray]:
    """RMS magnitudes (R, K) in km and km/s after each event, as the run computed them:
    chaser_r, chaser_v, target_r, target_v, relative_r, relative_v."""
    rms = product.team_rms if which == "true" else product.assumed_rms
    return {g: rms[..., i] for i, g in enumerate(_GROUPS)}


def report_times(product: RendezvousProduct) -> list[int]:
    """Event indices the summary lists: the a priori, the first and last marks, every reset
    and maneuver, and about six evenly spaced marks."""
    t = np.asarray(product.times_s)
    marked = np.nonzero(np.any(product.marks, axis=1))[0]
    idx = {0, len(t) - 1}
    if marked.size:
        idx |= {int(marked[0]), int(marked[-1])}
        idx |= {int(marked[i]) for i in np.linspace(0, marked.size - 1, 6).round().astype(int)}
    for ts in list(product.reset_times_s) + list(product.maneuver_time_s):
        idx.add(int(np.argmin(np.abs(t - ts))))
    return sorted(idx)


def _n(x: float, width: int) -> str:
    """A number right-justified in ``width`` columns with at least one leading space:
    integers from 100 up, else 3 (then fewer) significant figures."""
    if not np.isfinite(x):
        return f"{'-':>{width}}"
    tries = ([f"{x:.0f}"] if abs(x) >= 100.0 else []) + [f"{x:.3g}", f"{x:.2g}", f"{x:.1e}", f"{x:.0e}"]
    txt = next((t for t in tries if len(t) <= width - 1), tries[-1])
    return f"{txt:>{width}}"


def run_consistency(product: RendezvousProduct) -> list[tuple[str, float, float, str]]:
    """Per role: (role, worst ratio of the runs' sample RMS to the TEAM RMS, its 5-sigma
    bound, verdict "consistent" | "linear analysis does not hold"), over the six RMS groups
    at every mark time.  The bound 5 sqrt(1/(2N)) is five standard errors of a sample RMS
    ratio when one component dominates the magnitude (the largest such error)."""
    if product.run_rms is None or product.n_runs < 2:
        return []
    tt = rms_table(product)
    marked = np.any(product.marks, axis=1)
    bound = 5.0 * np.sqrt(1.0 / (2.0 * product.n_runs))
    out = []
    for r, role in enumerate(product.roles):
        team = np.stack([tt[g][r] for g in _GROUPS], axis=-1)[marked]
        runs = product.run_rms[r][marked]
        ok = team > 0.0
        ratio = np.where(ok, runs / np.where(ok, team, 1.0), 1.0)
        worst = float(ratio.flat[np.argmax(np.abs(ratio - 1.0))])
        verdict = "consistent" if abs(worst - 1.0) <= bound else "linear analysis does not hold"
        out.append((role, worst, bound, verdict))
    return out


def summary_text(product: RendezvousProduct, width: int = 80) -> str:
    """The terminal summary (fits ``width`` >= 80 columns)."""
    u = product.length_unit
    f = 1.0 / product.km_per_unit
    vu = f"{u}/s" if u != "ft" else "fps"
    tt = rms_table(product)
    ta = rms_table(product, "assumed")
    lines = [
        (product.title or Path(product.source).name),
        f"{product.chaser_name} (chaser) and {product.target_name} (target) about the {product.centre}; "
        f"{int(np.any(product.marks, axis=1).sum())} mark times, {int(product.marks.sum())} marks, "
        f"{len(product.reset_times_s)} resets",
        *(
            [
                f"references: {product.chaser_name} {product.reference_sources[0]}; "
                f"{product.target_name} {product.reference_sources[1]}"
            ]
            if len(product.reference_sources) == 2
            else []
        ),
        "",
        f"RMS errors after each event ({u}, {vu}): true; 'belief' = the filter's own",
        f"{'t min':>6} {'filter':<8}{'chaser r':>9}{'v':>6}{'target r':>9}{'v':>6}"
        f"{'rel r':>8}{'v':>6}{'belief r':>9}{'v':>6}",
    ]
    for k in report_times(product):
        tag = ""
        if np.any(np.abs(product.reset_times_s - product.times_s[k]) < 1e-6):
            tag = " R"
        for j, name in enumerate(product.maneuver_names):
            if abs(product.maneuver_time_s[j] - product.times_s[k]) < 1e-6:
                tag = f" {name}"
        for r, role in enumerate(product.roles):
            head = f"{product.times_s[k] / 60.0:6.1f}" if r == 0 else " " * 6
            lines.append(
                f"{head} {_ROLE.get(role, role):<8}{_n(tt['chaser_r'][r, k] * f, 9)}{_n(tt['chaser_v'][r, k] * f, 6)}"
                f"{_n(tt['target_r'][r, k] * f, 9)}{_n(tt['target_v'][r, k] * f, 6)}"
                f"{_n(tt['relative_r'][r, k] * f, 8)}{_n(tt['relative_v'][r, k] * f, 6)}"
                f"{_n(ta['relative_r'][r, k] * f, 9)}{_n(ta['relative_v'][r, k] * f, 6)}" + (tag if r == 0 else "")
            )
    lines.append("optimum: target solve-for (R-649 Eq. 20); Schmidt: consider; Apollo: ignore (Eq. 26)")
    lines.append("R: assumed-covariance reset")
    if product.maneuver_names:
        lines += [
            "",
            f"Maneuver error |dV_hat - dV_true| from knowledge errors, 1-sigma RMS ({vu}; R-649 Fig. II-18)",
            f"{'maneuver':<9}{'t min':>6}{'|dV|':>8}"
            + "".join(f"{_ROLE.get(r, r):>10}{'belief':>8}" for r in product.roles),
        ]
        for j, name in enumerate(product.maneuver_names):
            row = f"{name:<8} {product.maneuver_time_s[j] / 60.0:6.1f}"
            row += _n(np.linalg.norm(product.maneuver_dv_km_s[j]) * f, 8)
            for r in range(len(product.roles)):
                row += _n(np.sqrt(max(np.trace(product.maneuver_cov_true[r, j]), 0.0)) * f, 10)
                row += _n(np.sqrt(max(np.trace(product.maneuver_cov_assumed[r, j]), 0.0)) * f, 8)
            lines.append(row)
    if product.n_runs > 0 and product.envelope_1sigma is not None:
        how = {"two_body": "flown on the conics", "linear": "linear"}.get(product.run_dynamics, "")
        lines += ["", f"Single runs: {product.n_runs} per role, {how} (seed {product.seed}); share of errors"]
        lines.append("inside TEAM's true sigma envelopes (Gaussian: 68.27 % and 99.73 %):")
        for r, role in enumerate(product.roles):
            se1 = product.envelope_1sigma_se[r] if product.envelope_1sigma_se is not None else np.nan
            se3 = product.envelope_3sigma_se[r] if product.envelope_3sigma_se is not None else np.nan
            lines.append(
                f"  {_ROLE.get(role, role):<8} 1 sigma {100 * product.envelope_1sigma[r]:6.2f} % (SE {100 * se1:.2f})"
                f"   3 sigma {100 * product.envelope_3sigma[r]:6.2f} % (SE {100 * se3:.2f})"
            )
        rows = run_consistency(product)
        if rows:
            lines.append("runs' sample RMS / TEAM RMS, worst over the marks (6 groups; bound 5 SE):")
            for role, worst, bound, verdict in rows:
                lines.append(f"  {_ROLE.get(role, role):<8} {worst:8.3g}  (1 +- {bound:.2f})  {verdict}")
    return "\n".join(fit_line(line, width) for line in lines)


def rendezvous_figure(product: RendezvousProduct):
    """One PNG: RMS chaser, target and relative position errors and the relative velocity
    error against time for each role (TEAM's true RMS solid, the filter's belief dashed), the
    single runs' sample RMS as dots, resets and maneuvers marked; the figure (not saved)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    u = product.length_unit
    f = 1.0 / product.km_per_unit
    vu = f"{u}/s" if u != "ft" else "fps"
    t = product.times_s / 60.0
    tt, ta = rms_table(product), rms_table(product, "assumed")
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), sharex=True)
    panels = (
        ("chaser_r", f"{product.chaser_name} inertial position ({u})", slice(0, 3)),
        ("target_r", f"{product.target_name} inertial position ({u})", slice(6, 9)),
        ("relative_r", f"relative position ({u})", None),
        ("relative_v", f"relative velocity ({vu})", None),
    )
    for ax, (key, title, _sl) in zip(axes.ravel(), panels):
        for r, role in enumerate(product.roles):
            c = f"C{r}"
            ax.semilogy(t, tt[key][r] * f, "-", color=c, lw=1.4, label=f"{_ROLE.get(role, role)} (true RMS)")
            belief = ta[key][r] * f
            ax.semilogy(t, np.where(belief > 0.0, belief, np.nan), "--", color=c, lw=0.9, alpha=0.8)
            if product.run_rms is not None:
                mag = product.run_rms[r][:, _GROUPS.index(key)]
                ax.semilogy(t, np.where(mag > 0.0, mag * f, np.nan), ".", color=c, ms=2.5, alpha=0.6)
        for ts in product.reset_times_s:
            ax.axvline(ts / 60.0, color="0.6", lw=0.8, ls=":")
        for j, name in enumerate(product.maneuver_names):
            ax.axvline(product.maneuver_time_s[j] / 60.0, color="k", lw=0.8, ls="-.")
            ax.text(product.maneuver_time_s[j] / 60.0, ax.get_ylim()[1], name, fontsize=7, va="top", ha="right")
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3, which="both")
    for ax in axes[1]:
        ax.set_xlabel("time (min)")
    axes[0, 0].legend(fontsize=7, loc="best")
    fig.suptitle(
        f"{(product.title or Path(product.source).name)[:90]}\n"
        f"solid: TEAM true RMS; dashed: the filter's own belief; dots: sample RMS of {product.n_runs} single runs; "
        "dotted lines: resets",
        fontsize=9,
    )
    fig.tight_layout()
    return fig


def plot_rendezvous(product: RendezvousProduct, path: str | Path) -> list[Path]:
    """One PNG of :func:`rendezvous_figure` at ``path``; returns [path]."""
    import matplotlib.pyplot as plt

    from fracas.io.atomic import savefig_atomic

    fig = rendezvous_figure(product)
    try:
        return [savefig_atomic(fig, Path(path), dpi=110)]
    finally:
        plt.close(fig)
