"""The bundled TSIM examples (namelists/earth_mars_tsim*.toml) against TEAM's covariance
analysis of the same Earth-Mars study: the near-linear example agrees with TEAM (every
likelihood-ratio and mean-|ΔV| test passes at α = 1e-3, every σ ratio within 5 SE), the
one at the main job's full errors is flagged.  Slow: the TEAM run on the STM file (built on
first use, about a minute) and the missions' 150-day flights."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fracas.config.tsim import load_tsim_deck, parse_tsim_deck
from fracas.modes.tsim.run import run_tsim

NAMELISTS = Path(__file__).resolve().parents[2] / "namelists"

pytestmark = pytest.mark.slow


def _deck(name: str, missions: int):
    cfg = load_tsim_deck(NAMELISTS / name)
    text = cfg.source_text.replace(f"missions = {cfg.insim.missions}\n", f"missions = {missions}\n", 1)
    return parse_tsim_deck(text, cfg.source_path)


def test_near_linear_example_agrees_with_team(tmp_path):
    """earth_mars_tsim.toml with 1024 missions: every consistency row consistent; the target
    σ ratios within 5 SE (5/sqrt(2N) = 11 %) and the NEES coverage of TEAM's ellipsoids within
    5 binomial SE."""
    prod, _ = run_tsim(_deck("earth_mars_tsim.toml", 1024), tmp_path / "near.h5")
    assert prod.counts["ok"] == 1024
    for row in prod.consistency:
        assert row["verdict"] == "consistent", row["message"]
        if row["ratio"] and row["output"] == "target":
            assert np.all(np.abs(np.asarray(row["ratio"]) - 1.0) < 5.0 * row["se"])
            for _k, obs, exp, se in row["coverage"]:
                assert abs(obs - exp) < 5.0 * se


def test_full_errors_example_is_flagged(tmp_path):
    """earth_mars_tsim_noise.toml with 512 missions: the low-thrust correction is flagged (the
    clean-up's propellant, which TEAM books instead of flying: docs/tsim.md), while the
    impulsive clean-up's own correction agrees with TEAM.  Since issue 24 TEAM's thrust noise
    is exact, and the final target, which its DYNO noise model used to flag too, agrees
    (σ ratios 1.05-1.08 measured; printed, not asserted: at 2.5 SE it is no test)."""
    prod, _ = run_tsim(_deck("earth_mars_tsim_noise.toml", 512), tmp_path / "full.h5")
    verdict = {row["output"]: row for row in prod.consistency}
    for row in prod.consistency:
        print(row["output"], row["verdict"], np.round(np.asarray(row["ratio"], float), 3) if row["ratio"] else "")
    assert verdict["correction lt1"]["verdict"] == "nonlinear"
    assert verdict["mean |dv| [lt1]"]["verdict"] == "nonlinear"
    assert "nonlinear" in verdict["mean |dv| [lt1]"]["message"]
    assert verdict["correction tcm1"]["verdict"] == "consistent", verdict["correction tcm1"]["message"]


def test_nonlinear_example_nonlinear_guidance_does_better(tmp_path):
    """earth_mars_tsim_nonlinear.toml (the main job's full errors) with 256 missions, the
    clean-up by the linear law and by nonlinear guidance: both runs are flagged; on the
    estimated trajectory (free of the knowledge and execution errors both laws share) the
    linear law misses its 1 km targets by more than 100 km RMS, the nonlinear design meets
    them for every mission (measured: 3090 km against 0.18 km RMS)."""
    cfg = _deck("earth_mars_tsim_nonlinear.toml", 256)
    lin_text = cfg.source_text.replace('law = "nonlinear"', 'law = "linear"', 1)
    lin = parse_tsim_deck(lin_text, cfg.source_path)
    p_lin, _ = run_tsim(lin, tmp_path / "lin.h5")
    p_nl, _ = run_tsim(cfg, tmp_path / "nl.h5")
    for prod in (p_lin, p_nl):
        assert any(r["verdict"] != "consistent" for r in prod.consistency)
    j = [m.name for m in p_nl.maneuvers].index("tcm1")
    ok = p_nl.table["status"] <= 1
    assert np.all(p_nl.table["status"] == 0)
    rms_lin = np.sqrt(np.mean(p_lin.table["design_miss"][:, j, :3] ** 2, axis=0))
    assert np.max(rms_lin) > 100.0
    assert np.max(np.abs(p_nl.table["design_miss"][ok, j, :3])) <= 1.0
    row = {r["output"]: r for r in p_nl.consistency}["design miss [tcm1]"]
    assert "the nonlinear design by" in row["message"]
