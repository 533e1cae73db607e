"""The TEAM and trajectory printouts on an 80-column terminal (issue 8 A): nothing cut, every
number in full (compared with the values in the results file), one velocity unit, the
three levels, per-entry skipped counts and the no-usable-measurement warning."""

from __future__ import annotations

import numpy as np
import pytest
from rich.console import Console

from fracas.io.team_results import read_team_results
from fracas.modes.team import run_team
from fracas.report.team import print_team, quiet_line
from tests.team.test_team_engine import SMALL

DAY = 86400.0


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    _, path, _ = run_team(SMALL, None, tmp_path_factory.mktemp("width") / "small.h5")
    return read_team_results(path)


def render(r, width=80, **kw) -> str:
    con = Console(width=width, record=True, file=open("/dev/null", "w"))  # noqa: SIM115
    print_team(r, con, **kw)
    return con.export_text()


@pytest.mark.parametrize("verbosity", ["normal", "verbose"])
@pytest.mark.parametrize("unit", ["km/s", "m/s", "mm/s"])
def test_fits_80_columns_and_numbers_in_full(results, verbosity, unit):
    text = render(results, verbosity=verbosity, velocity_unit=unit)
    lines = text.splitlines()
    assert max(len(ln) for ln in lines if not ln.startswith("written:")) <= 80
    assert "…" not in text
    f = {"km/s": 1.0, "m/s": 1e3, "mm/s": 1e6}[unit]
    A = results["assumed"]
    tokens = set(text.replace("│", " ").replace(",", " ").split())
    # every RSS of the event log's last row and every final 1σ, in the compact format
    for h in (A, results["true"]):
        P = h["P_plus"][-1]
        assert f"{np.sqrt(np.trace(P[:3, :3])):.4g}" in tokens
        assert f"{np.sqrt(np.trace(P[3:6, 3:6])) * f:.4g}" in tokens
        for i, u in enumerate(results["units"]):
            if results["roles"][i] == "noise_state" and verbosity == "normal":
                continue  # the exact model's noise states: stationary, printed with --verbose
            assert f"{h['sigma'][-1][i] * (f if u == 'km/s' else 1.0):.4g}" in tokens, results["labels"][i]
    # one velocity unit across the printout
    others = [u for u in ("km/s", "m/s", "mm/s") if u != unit]
    for u in others:
        assert f"({u})" not in text and f" {u} " not in f" {text} ".replace("\n", " ")


def test_levels_and_line_counts(results):
    normal = render(results, verbosity="normal")
    verbose = render(results, verbosity="verbose")
    quiet = render(results, verbosity="quiet", width=400)
    assert quiet.strip() == quiet_line(results) and len(quiet.strip().splitlines()) == 1
    assert len(normal.splitlines()) <= 60 < len(verbose.splitlines())
    assert "assumed knowledge at t = 1.5000 d" in verbose and "assumed knowledge at t =" not in normal
    assert "final knowledge at t = 4.0000 d" in normal


def test_skipped_per_entry_and_no_usable_warning(results):
    r = dict(results)
    m = dict(r["measurements"])
    trk = np.asarray(m["tracking"])
    j = int(trk[0])
    used = np.asarray(m["used"]).copy()
    used[trk == j] = 0  # as if entry j were always below the mask
    m["used"] = used
    r["measurements"] = m
    text = " ".join(render(r, width=200, verbosity="normal").split())
    n = int(np.sum(trk == j))
    kind, sta = r["tracking"][j]
    assert f"{kind} {sta}: skipped {n} of {n}" in text
    mask = float(r["attrs"]["min_elevation_deg"])
    assert f"tracking[{j}] {kind} {sta}: no usable measurement (all {n} below {mask:g} deg elevation)" in text


def test_trajectory_summary_fits_80_columns(tmp_path):
    from fracas.io.trajectory_file import read_trajectory_file
    from fracas.modes.propagate import propagate_deck
    from fracas.report.trajectory import print_summary

    deck = SMALL.parent / "team_small_traj.toml"
    _, path = propagate_deck(deck, tmp_path / "traj.h5")
    data = read_trajectory_file(path)
    con = Console(width=80, record=True, file=open("/dev/null", "w"))  # noqa: SIM115
    print_summary(data, None, console=con)
    text = con.export_text()
    assert max(map(len, text.splitlines())) <= 80 and "…" not in text
    tokens = set(text.replace("│", " ").split())
    for i in range(3):
        assert f"{float(data.r_final_km[i]):.9g}" in tokens and f"{float(data.v_final_km_s[i]):.9g}" in tokens
    assert f"{np.linalg.norm(data.r_final_km):.6f}" in tokens


def test_trajectory_sensitivities_line_wraps_at_word_boundaries(tmp_path):
    """The summary's "sensitivities:" line with many parameter columns wraps to 80 columns at
    word boundaries: every label printed whole (issue 22: no line over 80, no word folded)."""
    import dataclasses
    from types import SimpleNamespace

    from fracas.io.trajectory_file import read_trajectory_file
    from fracas.modes.propagate import propagate_deck
    from fracas.report.trajectory import print_summary

    _, path = propagate_deck(SMALL.parent / "team_small_traj.toml", tmp_path / "traj.h5")
    labels = ["mu[sun]", "thrust_scale", "bias_in_rad", "bias_out_rad", "station_radius_km[goldstone]"] * 4
    sens = SimpleNamespace(param_labels=labels, stm=np.zeros((3, 7, 7)))
    data = dataclasses.replace(read_trajectory_file(path), sensitivities=sens)
    con = Console(width=80, record=True, file=open("/dev/null", "w"))  # noqa: SIM115
    print_summary(data, None, console=con)
    text = con.export_text()
    assert max(map(len, text.splitlines())) <= 80
    words = " ".join(text[text.index("sensitivities:") :].split())
    assert words == f"sensitivities: STM (n=3, 7x7) and parameter matrices, columns: {', '.join(labels)}"
