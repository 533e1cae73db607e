"""Every plot the project draws, checked as a reader sees it: no title, label, tick label,
legend or annotation runs off the figure, no two titles overlap (tests/report/layout.py),
and the defects of issue 22 stay fixed (a trajectory drawn between its samples, a spiral
readable, B-plane knowledge ellipses visible, sweep studies marked, every TOM record
plotted, one unit per quantity in plots and printout).

Data are small synthetic products (tests/report/synthetic.py): nothing here compiles JAX."""

from __future__ import annotations

import dataclasses
import math
import re

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from fracas.report import guidance, rendezvous, sweep, team, tom, trajectory, tsim  # noqa: E402
from tests.report import synthetic as syn  # noqa: E402
from tests.report.layout import assert_layout, text_problems  # noqa: E402

LONG = "A mission title as long as a real one: Earth-Mars cruise, tracking, guidance and error budget (main job)"


@pytest.fixture(scope="module")
def team_r(tmp_path_factory) -> dict:
    return syn.team_results(tmp_path_factory.mktemp("layout"))


def _tsim_product(**kw):
    from tests.io.test_tsim_results import synthetic_product

    return dataclasses.replace(synthetic_product(), **kw)


def _team_plots(r, **kw):
    return [fig for _s, fig in team.team_figures(r, **kw)]


# name -> callable(team results) returning the figures of one plot function
CASES = {
    "trajectory leo": lambda r: [trajectory.trajectory_figure(syn.trajectory_data("leo"))],
    "trajectory spiral": lambda r: [trajectory.trajectory_figure(syn.trajectory_data("spiral"))],
    "trajectory escape": lambda r: [trajectory.trajectory_figure(syn.trajectory_data("escape"))],
    "team without guidance": lambda r: _team_plots(r),
    "team guidance": lambda r: _team_plots(syn.synthetic(r)),
    "team guidance m/s": lambda r: _team_plots(syn.synthetic(r), velocity_unit="m/s"),
    "guidance bplane": lambda r: [guidance.bplane_figure({**syn.synthetic(r), "attrs": {"title": LONG}})],
    "guidance budget": lambda r: [guidance.budget_figure({**syn.synthetic(r), "attrs": {"title": LONG}})],
    "guidance dv": lambda r: [guidance.dv_figure({**syn.synthetic(r), "attrs": {"title": LONG}})],
    "guidance correlation": lambda r: [guidance.correlation_figure({**r, "attrs": {**r["attrs"], "title": LONG}})],
    "tom": lambda r: [tom.convergence_figure(syn.tom_results()), tom.grid_figure(syn.tom_results())],
    "tom 125 records": lambda r: [tom.convergence_figure(syn.tom_results(125, grid=False))],
    "tsim": lambda r: tsim.tsim_figures(_tsim_product(title=LONG)),
    "tsim bplane": lambda r: tsim.tsim_figures(
        _tsim_product(title=LONG, final_target_names=["b_dot_t", "b_dot_r", "lt"])
    ),
    "sweep grid": lambda r: [sweep.sweep_figure(syn.sweep_table())],
    "sweep one field": lambda r: [sweep.sweep_figure(syn.sweep_table(two_fields=False))],
    "rendezvous": lambda r: [rendezvous.rendezvous_figure(syn.rendezvous_product())],
}


class TestPlotLayout:
    """No text outside the figure, no overlapping titles, for every plot function."""

    @pytest.mark.parametrize("case", list(CASES))
    def test_no_clipped_or_overlapping_text(self, case, team_r):
        figs = CASES[case](team_r)
        try:
            assert figs and all(f is not None for f in figs)
            for i, fig in enumerate(figs):
                assert_layout(fig, f"{case} figure {i}")
        finally:
            for fig in figs:
                plt.close(fig)

    def test_the_check_catches_a_cut_title_and_overlapping_titles(self):
        fig, (a, b) = plt.subplots(2, 1, figsize=(4, 3))
        a.set_title("x" * 200)
        b.set_title("second")
        b.set_position(a.get_position())  # b's title now sits on a's
        problems = text_problems(fig)
        plt.close(fig)
        assert any("clipped" in p and "title" in p.lower() for p in problems), problems
        assert any("overlaps" in p for p in problems), problems
        fig, ax = plt.subplots(figsize=(4, 3))
        ax.set_ylabel("a label")
        ax.set_yticks([0, 1], ["long tick label " * 4, "b"])
        problems = text_problems(fig)
        plt.close(fig)
        assert any("tick label" in p for p in problems), problems


# --- the defects of issue 22 -----------------------------------------------------------------


def test_trajectory_is_drawn_between_samples_on_the_conic():
    """Two-body samples 14.4 min apart: the drawn path has points between them (at most 2°
    apart) and lies on the conic to 1e-6 km."""
    from fracas.report._conic import dense_path

    d = syn.trajectory_data("leo")
    t, r, _v, _m, _p = dense_path(
        d.t_s, d.r_km, d.v_km_s, d.mass_kg, np.array(d.primary, object), lambda p: syn.MU_EARTH
    )
    assert len(t) > 10 * len(d.t_s)
    ref, _ = syn.conic_samples(d.r_km[0], d.v_km_s[0], t)
    assert np.max(np.linalg.norm(r - ref, axis=1)) < 1e-6
    ang = np.arccos(
        np.clip(
            np.einsum("ij,ij->i", r[1:], r[:-1]) / np.linalg.norm(r[1:], axis=1) / np.linalg.norm(r[:-1], axis=1), -1, 1
        )
    )
    assert np.degrees(ang.max()) <= 2.0 + 1e-9
    fig = trajectory.trajectory_figure(d)
    xy = fig.axes[0].get_lines()[0].get_xydata()
    plt.close(fig)
    assert len(xy) == len(t)


def test_trajectory_between_samples_of_a_thrust_arc():
    """Under a constant tangential thrust (1e-6 km/s², a spiral), the blended conics stay
    within a.h²/8 of the integrated path between samples 14.4 min apart."""
    from scipy.integrate import solve_ivp

    from fracas.report._conic import dense_path

    acc = 1e-6

    def f(_t, y):
        r, v = y[:3], y[3:]
        return np.concatenate([v, -syn.MU_EARTH * r / np.linalg.norm(r) ** 3 + acc * v / np.linalg.norm(v)])

    h = 864.0
    ts = np.arange(0.0, 0.5 * syn.DAY, h)
    sol = solve_ivp(f, (0, ts[-1]), [7000.0, 0, 0, 0, 7.546, 0], rtol=1e-12, atol=1e-9, dense_output=True, t_eval=ts)
    Y = sol.y.T
    t, r, *_ = dense_path(
        ts, Y[:, :3], Y[:, 3:], np.ones(len(ts)), np.array(["earth"] * len(ts), object), lambda p: syn.MU_EARTH
    )
    err = np.linalg.norm(r - sol.sol(t).T[:, :3], axis=1)
    assert err.max() < acc * h**2 / 8
    assert err.max() > 0  # (between samples; the samples themselves are exact)


def test_spiral_shows_a_few_revolutions_and_elements():
    fig = trajectory.trajectory_figure(syn.trajectory_data("spiral"))
    try:
        ax = fig.axes[0]
        curves = [ln for ln in ax.get_lines() if len(ln.get_xydata()) > 10]
        assert 2 <= len(curves) <= trajectory._SHOWN_REVOLUTIONS
        assert re.search(r"\(\d of 2\d\d revolutions about earth\)", ax.get_title()), ax.get_title()
        labels = [a.get_ylabel() for a in fig.axes]
        for want in ("|r|, a (km)", "e (1)", "i (deg)", "mass (kg)"):
            assert want in labels
    finally:
        plt.close(fig)


def test_bplane_inset_zooms_on_the_knowledge(team_r):
    r = syn.synthetic(team_r)
    fig = guidance.bplane_figure(r)
    try:
        insets = [c for ax in fig.axes for c in ax.child_axes]
        assert insets, "no inset"
        ins = insets[0]
        g = guidance._bplane_events(r)[0]
        k = np.sqrt(np.linalg.eigvalsh(guidance.bplane_block(g, "target_cov_knowledge")).max())
        lo, hi = ins.get_xlim()
        assert hi - lo < 0.2 * np.diff(fig.axes[0].get_xlim())[0] and hi > 3 * k
    finally:
        plt.close(fig)


def test_sweep_contour_marks_every_study():
    t = syn.sweep_table()
    fig = sweep.sweep_figure(t)
    try:
        for ax in fig.axes:
            if not ax.get_label() == "<colorbar>":
                lines = {ln.get_label(): ln.get_xydata() for ln in ax.get_lines()}
                if "computed study" in lines:
                    assert len(lines["computed study"]) == 8 and len(lines["failed study"]) == 1
        assert sum(1 for ax in fig.axes for ln in ax.get_lines() if ln.get_label() == "computed study") == 4
    finally:
        plt.close(fig)


def test_tom_plots_every_record():
    res = syn.tom_results()
    fig = tom.convergence_figure(res)
    try:
        ax1, ax2 = fig.axes[:2]
        xs = np.unique(np.concatenate([ln.get_xdata() for ln in ax2.get_lines() if len(ln.get_xdata()) > 2]))
        assert list(xs) == list(range(1, 9))
        assert [t.get_text() for t in ax2.get_xticklabels()][2:4] == ["3\nT+O", "3\nT"]
    finally:
        plt.close(fig)
    from fracas.report.tom import summary_text

    res.update(
        target_names=[],
        control_names=[],
        u_final=[],
        u_start=[],
        final_mass_kg=968.1,
        start_mass_kg=968.2,
        initial_mass_kg=1000.0,
        n_trajectories=np.arange(8),
        lower=[],
        upper=[],
    )
    assert "8 search records in 6 iterations" in summary_text(res)


def test_units_agree_between_plots_and_printout(team_r):
    """ΔV in m/s and velocities in the printout's unit, in the tables and the plots alike."""
    import io

    from rich.console import Console

    r = syn.synthetic(team_r)
    for vu in ("mm/s", "m/s"):
        con = Console(width=80, file=io.StringIO(), record=True)
        team.print_team(r, con, verbosity="normal", velocity_unit=vu)
        text = con.export_text()
        budget = guidance.budget_figure(r, velocity_unit=vu)
        dv = guidance.dv_figure(r)
        know = team.team_figure(r, velocity_unit=vu)
        try:
            ticks = [t.get_text() for t in budget.axes[0].get_yticklabels()]
            b = r["budget"]
            i = next(j for j, o in enumerate(b["outputs"]) if "dV" in o)
            sig = math.sqrt(b["total"][i]) * 1e3
            assert f"1σ {sig:.4g} m/s" in ticks[i] and f"{sig:.4g}" in text  # the ΔV output in m/s in both
            assert not any("km/s" in t for t in ticks)
            assert dv.axes[0].get_ylabel() == "|ΔV| (m/s)" and "guidance events (ΔV in m/s)" in text
            assert know.axes[1].get_ylabel() == f"velocity RSS 1σ ({vu})" and f"({vu})" in text
        finally:
            for f in (budget, dv, know):
                plt.close(f)


def test_tsim_velocity_targets_in_mm_s():
    p = _tsim_product(final_target_units=["km", "km", "km/s"])
    text = tsim.summary_text(p)
    assert "mm/s" in text and "km/s" not in text
    figs = tsim.tsim_figures(p)
    try:
        assert figs[2].axes[2].get_xlabel() == "z error (mm/s)"
    finally:
        for f in figs:
            plt.close(f)
