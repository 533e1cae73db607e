"""The analyst's chain: ``fracas run tom.toml`` writes the optimized reference deck, and a TEAM
deck whose [ertraj] names it runs end to end (reference: the TOM targets themselves, reached
again by an independent propagation of the written deck)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fracas.build.trajectory import build_propagation
from fracas.cli import main
from fracas.config.trajectory import load_deck
from fracas.integrate.propagate import propagate
from fracas.io.tom_results import read_tom_results

ROOT = Path(__file__).resolve().parents[2]

TEAM = """mode = "team"
title = "TEAM on the TOM optimum"
[ertraj]
deck = "{ref}"
[filter]
type = "kalman_schmidt"
min_elevation_deg = -90.0
[a_priori]
position_sigma_km = [1.0, 1.0, 1.0]
velocity_sigma_km_s = [1e-4, 1e-4, 1e-4]
[[parameter]]
label = "mu[earth]"
sigma = 1e-3
role = "consider"
[[tracking]]
type = "range2"
stations = ["goldstone"]
start_days = 0.0
stop_days = 0.04
interval_hours = 0.1
sigma = 5.0
[[tracking]]
type = "doppler2"
stations = ["canberra"]
start_days = 0.0
stop_days = 0.04
interval_hours = 0.1
sigma = 1.0
"""


@pytest.mark.slow  # ~40 s of a cold make test (mostly XLA compilation; issue 22)
def test_tom_reference_deck_feeds_team(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the reference deck goes to out/ of the working directory
    ref = tmp_path / "lambert_reference.toml"
    res = tmp_path / "lambert_tom.h5"
    deck = tmp_path / "lambert_tom.toml"
    text = (ROOT / "namelists" / "lambert_tom.toml").read_text(encoding="utf-8")
    deck.write_text(text.replace("[tom]\n", '[tom]\nstm_file = "lambert_stm.h5"\n'), encoding="utf-8")
    r = CliRunner().invoke(main, ["run", str(deck), "-o", str(res), "--quiet"])
    assert r.exit_code == 0, r.output
    assert "TOM converged" in r.stdout
    # the STM file of the optimum, on request, reads back like any other
    r = CliRunner().invoke(main, ["stm", "info", str(tmp_path / "lambert_stm.h5")])
    assert r.exit_code == 0, r.output
    tom = read_tom_results(res)
    written = Path(tom["attrs"]["reference_deck"])
    ref.write_text(written.read_text(encoding="utf-8"), encoding="utf-8")
    # the written deck alone reaches the targets (an independent propagation of the deck)
    pr = build_propagation(load_deck(ref))
    tr = propagate(pr.model, pr.params, pr.ephem, pr.epoch_et_s, pr.x0, pr.t_out)
    assert np.all(np.abs(np.asarray(tr.x_final[:3]) - tom["desired"]) <= tom["tolerance"])
    team = tmp_path / "team.toml"
    team.write_text(TEAM.format(ref=ref.name), encoding="utf-8")
    out = tmp_path / "team.h5"
    r = CliRunner().invoke(main, ["run", str(team), "-o", str(out), "--quiet"])
    assert r.exit_code == 0, r.output
    assert out.exists()


def test_reference_deck_of_an_oem_started_trajectory_is_self_contained(tmp_path):
    """A TOM deck whose initial state comes from an OEM ([initial_state.oem], epoch and
    centre taken from the file) writes a reference deck that stands alone: the OEM record's
    state as cartesian, with the epoch and centre explicit, so it validates in another
    folder and starts from exactly the OEM's state."""
    from fracas.build.tom import build_tom, reference_deck_text
    from fracas.config.tom import parse_tom_deck
    from fracas.config.trajectory import parse_deck

    oem = tmp_path / "start.oem"
    oem.write_text(
        "CCSDS_OEM_VERS = 2.0\nCREATION_DATE = 2026-12-01T00:00:00\nORIGINATOR = TEST\n\nMETA_START\n"
        "OBJECT_NAME = X\nOBJECT_ID = X\nCENTER_NAME = EARTH\nREF_FRAME = ICRF\nTIME_SYSTEM = TDB\n"
        "START_TIME = 2030-01-01T00:00:00.000000\nSTOP_TIME = 2030-01-01T00:01:00.000000\nMETA_STOP\n\n"
        "2030-01-01T00:00:00.000000 6678.137 0.0 0.0 0.0 7.725760634075587 0.0\n"
        "2030-01-01T00:01:00.000000 6676.0 463.0 0.0 -0.5 7.7 0.0\n",
        encoding="utf-8",
    )
    text = (ROOT / "tests" / "data" / "hohmann_tom.toml").read_text(encoding="utf-8")
    head = '[epoch]\niso = "2030-01-01T00:00:00"\n\n[initial_state]\ncentre = "earth"\nframe = "EME2000"\n\n'
    cart = "[initial_state.cartesian]\nr_km = [6678.137, 0.0, 0.0]\nv_km_s = [0.0, 7.725760634075587, 0.0]"
    assert head in text and cart in text
    text = text.replace(head, "").replace(cart, f'[initial_state.oem]\npath = "{oem}"\nat = "start"')
    deck = parse_tom_deck(text, str(tmp_path / "tom.toml"))
    case = build_tom(deck)
    out = reference_deck_text(case, np.asarray(case.u0))
    other = tmp_path / "elsewhere" / "ref.toml"
    other.parent.mkdir()
    ref = parse_deck(out, str(other))
    assert ref.initial_state.oem is None and ref.initial_state.centre == "earth"
    assert ref.epoch.et == case.trajectory.epoch.et
    assert ref.initial_state.cartesian.r_km == [6678.137, 0.0, 0.0]
