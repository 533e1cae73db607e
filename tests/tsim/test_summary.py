"""The consistency report's verdicts (fracas.tsim.summary) on samples drawn with numpy from a
known covariance: the reference is the drawing distribution itself.  Bounds: the tests run
at α = 1e-3 (a consistent draw is misjudged with probability ~2e-3 per row; the seeds are
fixed, so the outcome is deterministic), the departures are 50 % in σ or 0.5 σ in the mean
at N = 2000 (over 15 SE): far from either edge."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from fracas.tsim import summary

SIGMA = np.array([[4.0, 1.0, 0.0], [1.0, 9.0, -2.0], [0.0, -2.0, 16.0]])
NAMES, UNITS = ["x", "y", "z"], ["km"] * 3


def _draw(n=2000, seed=5, scale=(1.0, 1.0, 1.0), shift=(0.0, 0.0, 0.0)):
    rng = np.random.default_rng(seed)
    x = rng.multivariate_normal(np.zeros(3), SIGMA, size=n)
    return x * np.asarray(scale) + np.asarray(shift) * np.sqrt(np.diag(SIGMA))


def test_consistent_draw_is_consistent():
    row = summary.compare_covariance("target", NAMES, UNITS, _draw(), SIGMA)
    assert row["verdict"] == "consistent", row["message"]
    assert np.all(np.abs(np.asarray(row["ratio"]) - 1.0) < 5 * row["se"])


def test_inflated_axis_is_nonlinear_and_named():
    row = summary.compare_covariance("target", NAMES, UNITS, _draw(scale=(1.0, 1.5, 1.0)), SIGMA)
    assert row["verdict"] == "nonlinear"
    assert row["message"].startswith("target y dispersion 1.5") and row["message"].endswith(": nonlinear")


def test_shifted_mean_is_biased():
    row = summary.compare_covariance("target", NAMES, UNITS, _draw(shift=(0.0, 0.0, 0.5)), SIGMA)
    assert row["verdict"] == "biased"
    assert "target z mean" in row["message"]


def test_mean_dv_z_test():
    """|ΔV| of a 3-D Gaussian: its sample mean against the exact mean (an isotropic σ gives
    2σ√(2/π)), and against a mean 10 % off."""
    rng = np.random.default_rng(3)
    dv = np.linalg.norm(rng.normal(scale=0.01, size=(4000, 3)), axis=1)
    exact = 2 * 0.01 * np.sqrt(2 / np.pi)
    assert summary.compare_mean_dv("tcm", dv, exact)["verdict"] == "consistent"
    assert summary.compare_mean_dv("tcm", dv, 1.1 * exact)["verdict"] == "nonlinear"


def test_design_miss_judged_against_teams_delivery_sigma():
    """Flagged beyond 10 % of TEAM's σ after the maneuver (summary.DESIGN_FRACTION), not by
    the design tolerance."""
    m = SimpleNamespace(
        name="tcm1",
        target=SimpleNamespace(names=("x", "y", "z"), units=("km",) * 3, tolerance=np.full(3, 0.1)),
        team={"target_cov_after": SIGMA},
    )
    small = np.full((100, 3), 0.05 * np.sqrt(np.diag(SIGMA)))
    big = np.full((100, 3), 0.2 * np.sqrt(np.diag(SIGMA)))
    assert summary.design_row(m, small, small, "linear")["verdict"] == "consistent"
    row = summary.design_row(m, big, np.zeros((100, 3)), "nonlinear")
    assert row["verdict"] == "nonlinear" and "the nonlinear design by 0 km" in row["message"]
