"""CCSDS exchange files (fracas/io/ccsds.py, ``fracas export``, ``[initial_state.oem]``).

References: the EXTERNAL libraries reading back what fracas wrote (python-oem for OEMs,
ccsds_ndm for OPMs, the csv module for the CSV); the trajectory and TEAM results files the
exports came from; a propagation of the deck the OEM was written from.  Inputs are built
once per session: a quarter day of namelists/leo_j2.toml (propagated) and a tiny TEAM study
on it (about 10 s with a warm JAX cache).
"""

from __future__ import annotations

import csv
import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fracas.cli import main
from fracas.errors import DeckError, ResultsFileError
from fracas.io import ccsds
from fracas.io.team_results import read_team_results
from fracas.io.trajectory_file import read_trajectory_file, write_trajectory_file
from fracas.timescales import calendar_to_et

ROOT = Path(__file__).resolve().parents[2]
LEO = ROOT / "namelists" / "leo_j2.toml"
J2000_TDB = "2000-01-01T12:00:00"

TEAM_DECK = """mode = "team"
title = "tiny LEO TEAM"
[ertraj]
deck = "leo.toml"
[stm]
grid_hours = 1.0
[filter]
type = "kalman_schmidt"
stop_days = 0.25
min_elevation_deg = -90.0
[a_priori]
position_sigma_km = [1.0, 1.0, 1.0]
velocity_sigma_km_s = [0.001, 0.001, 0.001]
mass_sigma_kg = 0.5
[[parameter]]
label = "mu[earth]"
sigma = 1.0
role = "solve_for"
[[tracking]]
type = "range2"
stations = ["goldstone"]
start_days = 0.0
stop_days = 0.25
interval_hours = 1.0
sigma = 0.01
[[event]]
type = "eigenvector"
times_days = [0.125]
[gencov]
measurement_sigma = { range2 = 0.02 }
"""

OEM_DECK = """title = "LEO from an OEM"
[initial_state.oem]
path = "leo.oem"
{at}
[spacecraft]
mass_kg = 1000.0
[forces]
j2 = true
[forces.overrides.earth]
mu_km3_s2 = 398600.4418
j2 = 1.08262668e-3
radius_km = 6378.137
[integrator]
tolerance = 1e-12
[stop]
duration_days = {days}
[output]
step_days = 0.05
"""


def fracas(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def one_line_error(r, *needles):
    """Exit 2, one ``fracas: error:`` line naming every needle, no traceback."""
    assert r.exit_code == 2, r.output
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fracas: error: "), r.stderr
    assert "Traceback" not in r.output
    for n in needles:
        assert str(n) in lines[0], (n, lines[0])
    return lines[0]


def rel(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def lib_et(t) -> float:
    """TDB s past J2000 of an astropy Time, by astropy (independent of fracas's conversion)."""
    from astropy.time import Time

    return float((t - Time(J2000_TDB, format="isot", scale="tdb")).sec)


# ----------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="session")
def work(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("ccsds")
    text = LEO.read_text(encoding="utf-8")
    text = text.replace("duration_days = 1.0", "duration_days = 0.25").replace("step_days = 0.01", "step_days = 0.05")
    assert "duration_days = 0.25" in text and "step_days = 0.05" in text
    (d / "leo.toml").write_text(text, encoding="utf-8")
    (d / "team.toml").write_text(TEAM_DECK, encoding="utf-8")
    return d


@pytest.fixture(scope="session")
def traj_file(work) -> Path:
    from fracas.modes.propagate import propagate_deck

    _, path = propagate_deck(work / "leo.toml", work / "leo.h5")
    return path


@pytest.fixture(scope="session")
def team_file(work) -> Path:
    from fracas.modes.team import run_team

    _, path, _ = run_team(work / "team.toml", None, work / "team.h5")
    return path


@pytest.fixture(scope="session")
def team(team_file) -> dict:
    return read_team_results(team_file)


@pytest.fixture(scope="session")
def traj_oem(work, traj_file) -> Path:
    return ccsds.write_oem(work / "leo.oem", traj_file)


# ----------------------------------------------------------------------------- OEM out
@pytest.mark.parametrize("xml", [False, True])
def test_oem_of_a_trajectory_file_read_by_python_oem_equals_the_file(work, traj_file, xml):
    """Reference: the trajectory file; the OEM is read back by python-oem itself."""
    from oem import OrbitEphemerisMessage

    out = ccsds.write_oem(work / ("leo.xml" if xml else "leo_kvn.oem"), traj_file, xml=xml)
    data = read_trajectory_file(traj_file)
    msg = OrbitEphemerisMessage.open(out)
    assert msg.version == "2.0" and msg.header["ORIGINATOR"] == "FRACAS"
    assert "CREATION_DATE" in msg.header
    (seg,) = msg.segments
    md = seg.metadata
    assert md["CENTER_NAME"] == "EARTH" and md["REF_FRAME"] == "ICRF" and md["TIME_SYSTEM"] == "TDB"
    assert md["OBJECT_NAME"] == data.title and md["OBJECT_ID"] == "UNKNOWN"
    states = list(seg.states)
    et = np.array([lib_et(s.epoch) for s in states])
    want = data.epoch_et_s + data.t_s
    assert np.max(np.abs(et - want)) < 1e-6  # epochs to 1 µs
    assert abs(lib_et(md["START_TIME"]) - want[0]) < 1e-6 and abs(lib_et(md["STOP_TIME"]) - want[-1]) < 1e-6
    assert rel([s.position for s in states], data.r_km) < 1e-9
    assert rel([s.velocity for s in states], data.v_km_s) < 1e-9
    assert not seg.has_covariance
    if not xml:
        text = out.read_text()
        assert text.startswith("CCSDS_OEM_VERS = 2.0\nCOMMENT fracas trajectory file leo.h5")


@pytest.mark.parametrize(("which", "before"), [(None, False), ("assumed", True)])
def test_oem_of_a_team_results_file_read_by_python_oem_equals_the_file(work, team_file, team, which, before):
    """Reference: the TEAM results file (reference states, the 6x6 position/velocity block
    of the true P+ by default, or of the assumed P-); read back by python-oem."""
    from oem import OrbitEphemerisMessage

    out = ccsds.write_oem(work / f"team_{which}_{before}.oem", team_file, covariance=which, before_update=before)
    msg = OrbitEphemerisMessage.open(out)
    (seg,) = msg.segments
    states = list(seg.states)
    et = np.array([lib_et(s.epoch) for s in states])
    want_et = team["attrs"]["epoch_et_s"] + team["times_s"]
    assert np.max(np.abs(et - want_et)) < 1e-6
    assert rel([s.position for s in states], team["states"][:, :3]) < 1e-9
    assert rel([s.velocity for s in states], team["states"][:, 3:6]) < 1e-9
    covs = list(seg.covariances)
    assert len(covs) == len(team["times_s"])
    P = team[which or "true"]["P_minus" if before else "P_plus"][:, :6, :6]
    assert team["labels"][:6] == ["x", "y", "z", "vx", "vy", "vz"]
    for c, p, t in zip(covs, P, want_et):
        assert abs(lib_et(c.epoch) - t) < 1e-6
        sym = 0.5 * (p + p.T)
        np.testing.assert_allclose(c.matrix, sym, rtol=1e-9, atol=0.0)
    assert "true" in team  # the fixture study has [gencov]: the default is the true covariance


def test_oem_of_a_trajectory_with_team_covariances(work, traj_file, team_file, team):
    """Reference: both files; covariances of the TEAM file go with the trajectory's states at
    the epochs inside the segment."""
    out = ccsds.write_oem(work / "merged.oem", traj_file, team=team_file)
    f = ccsds.read_oem(out)
    (s,) = f.segments
    assert s.et_s.size == len(read_trajectory_file(traj_file).t_s)
    np.testing.assert_allclose(s.cov_et_s, team["attrs"]["epoch_et_s"] + team["times_s"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(s.cov, team["true"]["P_plus"][:, :6, :6], rtol=1e-9, atol=0)


def test_oem_splits_segments_where_the_primary_changes(work, traj_file):
    """Reference: a trajectory file whose primary changes halfway (relabelled copy of the real
    one): one segment per primary, in order, nothing lost, no overlap."""
    data = read_trajectory_file(traj_file)
    n = len(data.t_s)
    prim = tuple(["earth"] * (n // 2) + ["moon"] * (n - n // 2))
    fake = write_trajectory_file(work / "two_primaries.h5", dataclasses.replace(data, primary=prim))
    f = ccsds.read_oem(ccsds.write_oem(work / "two.oem", fake))
    assert [s.centre for s in f.segments] == ["earth", "moon"]
    assert [s.et_s.size for s in f.segments] == [n // 2, n - n // 2]
    assert f.segments[0].et_s[-1] < f.segments[1].et_s[0]
    np.testing.assert_allclose(np.concatenate([s.r_km for s in f.segments]), data.r_km, rtol=1e-13)


def test_read_oem_equals_python_oem(traj_oem):
    """Reference: python-oem's own objects for the same file."""
    from oem import OrbitEphemerisMessage

    msg = OrbitEphemerisMessage.open(traj_oem)
    f = ccsds.read_oem(traj_oem)
    (s,) = f.segments
    states = list(msg.segments[0].states)
    np.testing.assert_array_equal(s.r_km, [x.position for x in states])
    np.testing.assert_array_equal(s.v_km_s, [x.velocity for x in states])
    np.testing.assert_allclose(s.et_s, [lib_et(x.epoch) for x in states], rtol=0, atol=1e-9)
    # records 72 min apart on a 97-min orbit: too coarse to interpolate, so none is advertised
    # (ccsds.DENSE_FRACTION); the dense file of the Hermite test below gets HERMITE 7
    assert (s.centre, s.frame, s.time_system, s.interpolation, s.interpolation_degree) == (
        "earth",
        "ICRF",
        "TDB",
        "",
        0,
    )


# ----------------------------------------------------------------------------- OPM and CSV
@pytest.mark.parametrize("xml", [False, True])
def test_opm_read_by_ccsds_ndm_equals_the_covariance(work, team_file, team, xml):
    """Reference: the TEAM results file at the final event; the OPM read back by ccsds_ndm."""
    from ccsds_ndm.ndm_io import NdmIo

    (k,) = ccsds.select_events(team, ["final"])
    c = ccsds.covariance_at(team, k)
    out = ccsds.write_opm(work / f"final_{xml}.opm", c, xml=xml, object_name="LEO")
    o = NdmIo().from_path(out)
    md, d = o.body.segment.metadata, o.body.segment.data
    assert (md.center_name, md.ref_frame, md.time_system, md.object_name) == ("EARTH", "ICRF", "TDB", "LEO")
    sv = d.state_vector
    assert abs(calendar_to_et(sv.epoch) - (team["attrs"]["epoch_et_s"] + team["times_s"][k])) < 1e-6
    r = [sv.x.value, sv.y.value, sv.z.value]
    v = [sv.x_dot.value, sv.y_dot.value, sv.z_dot.value]
    assert rel(r, team["states"][k, :3]) < 1e-9 and rel(v, team["states"][k, 3:6]) < 1e-9
    cm = d.covariance_matrix
    names = ("X", "Y", "Z", "X_DOT", "Y_DOT", "Z_DOT")
    P = team["true"]["P_plus"][k][:6, :6]
    for i in range(6):
        for j in range(i + 1):
            got = getattr(cm, f"c{names[i]}_{names[j]}".lower()).value
            assert got == pytest.approx(0.5 * (P[i, j] + P[j, i]), rel=1e-9, abs=0.0)
    assert d.spacecraft_parameters.mass.value == team["states"][k, 6]
    back = ccsds.read_opm(out)
    np.testing.assert_allclose(back["cov"], 0.5 * (P + P.T), rtol=1e-9, atol=0)


def test_csv_read_back_equals_the_covariances_with_labels_and_units(work, team_file, team):
    """Reference: the TEAM results file; the CLI's CSV read with the csv module."""
    out = work / "cov.csv"
    r = fracas("export", team_file, "--covariance-at", "eigenvector", "--covariance-at", "final", "--csv", out)
    assert r.exit_code == 0, r.output
    with open(out, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    header, body = rows[0], rows[1:]
    m = len(team["labels"])
    assert header[:7] == list(ccsds.CSV_FIXED_COLUMNS)
    assert header[7:] == [f"{lab} [{u}]" for lab, u in zip(team["labels"], team["units"])]
    assert "x [km]" in header and "vx [km/s]" in header and "mu[earth] [km^3/s^2]" in header
    ks = ccsds.select_events(team, ["eigenvector", "final"])
    assert len(ks) == 2 and len(body) == 2 * m
    for b, k in enumerate(ks):
        block = body[b * m : (b + 1) * m]
        assert {row[0] for row in block} == {str(k)} and {row[4] for row in block} == {"true after"}
        assert [row[5] for row in block] == team["labels"] and [row[6] for row in block] == team["units"]
        P = team["true"]["P_plus"][k]
        np.testing.assert_array_equal(np.array([[float(x) for x in row[7:]] for row in block]), 0.5 * (P + P.T))
        assert float(block[0][2]) == team["times_s"][k]


# ----------------------------------------------------------------------------- OEM in
def _oem_deck(work: Path, name: str, at: str = "", days: float = 0.2) -> Path:
    p = work / name
    p.write_text(OEM_DECK.format(at=at, days=days), encoding="utf-8")
    return p


def test_deck_initial_state_from_oem_equals_the_record_and_reproduces_the_states(work, traj_oem, traj_file):
    """Reference: the OEM record (initial state, 1e-12) and the OEM fracas wrote from the
    same trajectory (the propagation of the deck started from it: 1e-9 relative over 0.2 d;
    in fact equal to the 15 digits the OEM keeps, the same integrator taking the same steps)."""
    from fracas.build.trajectory import build_propagation
    from fracas.config.trajectory import load_deck, trajectory_hash
    from fracas.modes.propagate import propagate_deck

    deck = load_deck(_oem_deck(work, "from_oem.toml", 'at = "start"'))
    f = ccsds.read_oem(traj_oem)
    s = f.segments[0]
    assert deck.epoch.et == s.et_s[0] and deck.initial_state.centre == "earth"
    prob = build_propagation(deck)
    x0 = np.asarray(prob.x0)
    assert rel(x0[:3], s.r_km[0]) <= 1e-12 and rel(x0[3:6], s.v_km_s[0]) <= 1e-12
    assert prob.epoch_et_s == s.et_s[0]
    _, out = propagate_deck(deck, work / "from_oem.h5")
    got = read_trajectory_file(out)
    n = len(got.t_s)
    np.testing.assert_allclose(got.epoch_et_s + got.t_s, s.et_s[:n], rtol=0, atol=1e-6)
    assert rel(got.r_km, s.r_km[:n]) < 1e-9 and rel(got.v_km_s, s.v_km_s[:n]) < 1e-9
    # the hash covers the state read, not only the file name
    other = load_deck(_oem_deck(work, "from_oem_2.toml", 'at = "2030-01-01T01:12:00"', 0.1))
    assert other.initial_state.oem.record == "record 2 of segment 1"
    assert trajectory_hash(other) != trajectory_hash(deck)


def test_deck_initial_state_interpolated_from_the_oem(work):
    """Reference: a propagation of the same deck with outputs between the records of an OEM
    sampled every 0.002 d (173 s); the deck's state at a midpoint comes from the OEM's own
    HERMITE 7 interpolation (python-oem, 4 records): an interpolation error, so a looser
    tolerance (1e-9 relative is not an interpolation's; measured ~1e-11)."""
    from fracas.config.trajectory import load_deck
    from fracas.modes.propagate import propagate_deck

    base = LEO.read_text(encoding="utf-8").replace("duration_days = 1.0", "duration_days = 0.05")
    (work / "dense.toml").write_text(base.replace("step_days = 0.01", "step_days = 0.002"), encoding="utf-8")
    (work / "half.toml").write_text(base.replace("step_days = 0.01", "step_days = 0.001"), encoding="utf-8")
    _, dense = propagate_deck(work / "dense.toml", work / "dense.h5")
    _, half = propagate_deck(work / "half.toml", work / "half.h5")
    ccsds.write_oem(work / "dense.oem", dense)
    truth = read_trajectory_file(half)
    k = 11  # t = 0.011 d, halfway between records 6 and 7 of the OEM
    at = f"2030-01-01T00:{int(truth.t_s[k] // 60):02d}:{truth.t_s[k] % 60:09.6f}"
    text = OEM_DECK.format(at=f'at = "{at}"', days=0.01).replace("leo.oem", "dense.oem")
    (work / "interp.toml").write_text(text, encoding="utf-8")
    deck = load_deck(work / "interp.toml")
    assert deck.initial_state.oem.record.startswith("interpolated (HERMITE 7)")
    assert deck.epoch.et == truth.epoch_et_s + truth.t_s[k]
    assert rel(deck.initial_state.oem.r_km, truth.r_km[k]) < 1e-8
    assert rel(deck.initial_state.oem.v_km_s, truth.v_km_s[k]) < 1e-8


# ----------------------------------------------------------------------------- errors
def _edit(src: Path, dest: Path, old: str, new: str) -> Path:
    text = src.read_text(encoding="utf-8")
    assert old in text
    dest.write_text(text.replace(old, new), encoding="utf-8")
    return dest


def test_bad_oem_files_are_one_line_errors(work, traj_oem):
    """Reference: each damaged copy of a good OEM; read_oem and a deck naming it (``fracas
    propagate``: exit 2, one line naming the deck field and the file)."""
    cases = {
        "missing.oem": None,
        "corrupt.oem": ("2030-01-01T00:00:00.000000 7.0", "2030-01-01T00:00:00.000000 seven"),
        "centre.oem": ("CENTER_NAME = EARTH", "CENTER_NAME = ALPHA CENTAURI"),
        "frame.oem": ("REF_FRAME = ICRF", "REF_FRAME = ITRF"),
        "tsys.oem": ("TIME_SYSTEM = TDB", "TIME_SYSTEM = UTC"),
    }
    needles = {
        "missing.oem": "no such OEM file",
        "corrupt.oem": "not a readable CCSDS OEM",
        "centre.oem": "CENTER_NAME = 'ALPHA CENTAURI'",
        "frame.oem": "REF_FRAME = 'ITRF'",
        "tsys.oem": "TIME_SYSTEM = 'UTC'",
    }
    for name, edit in cases.items():
        path = work / name
        if edit is not None:
            _edit(traj_oem, path, *edit)
        with pytest.raises(ResultsFileError, match=needles[name].replace("(", r"\(")) as info:
            ccsds.read_oem(path)
        assert str(path) in str(info.value) and "\n" not in str(info.value)
        deck = work / f"deck_{name}.toml"
        deck.write_text(OEM_DECK.format(at="", days=0.1).replace("leo.oem", name), encoding="utf-8")
        r = fracas("propagate", deck, "-o", work / "never.h5")
        one_line_error(r, deck, "initial_state.oem.path", name, needles[name])
    assert not (work / "never.h5").exists()


def test_deck_and_oem_that_disagree_are_refused(work, traj_oem):
    """Reference: the OEM's first record (epoch 2030-01-01T00:00:00 TDB, centre EARTH)."""
    from fracas.config.trajectory import load_deck

    text = OEM_DECK.format(at='at = "start"', days=0.1)
    p = work / "mismatch_epoch.toml"
    p.write_text(text.replace("[initial_state.oem]", '[epoch]\niso = "2030-01-01T00:00:01"\n[initial_state.oem]'))
    with pytest.raises(DeckError, match=r"initial_state\.oem\.at .*must agree"):
        load_deck(p)
    q = work / "mismatch_centre.toml"
    q.write_text(text.replace("[initial_state.oem]", '[initial_state]\ncentre = "mars"\n[initial_state.oem]'))
    with pytest.raises(DeckError, match=r"initial_state\.centre = \"mars\": .*CENTER_NAME = EARTH"):
        load_deck(q)
    w = work / "outside.toml"
    w.write_text(OEM_DECK.format(at='at = "2031-01-01T00:00:00"', days=0.1), encoding="utf-8")
    r = fracas("propagate", w, "-o", work / "never.h5")
    one_line_error(r, "initial_state.oem.at", "outside the OEM")


def test_export_errors_are_one_line(work, team_file, traj_file):
    """Reference: the TEAM file's own events (initial, measurement, eigenvector, final)."""
    r = fracas("export", team_file, "--covariance-at", "flyby", "--csv", work / "x.csv")
    line = one_line_error(r, team_file, "--covariance-at = 'flyby'", "no such event", "eigenvector")
    assert "final" in line
    one_line_error(fracas("export", team_file, "--covariance-at", "9.5", "--opm", work / "x.opm"), "no schedule time")
    one_line_error(fracas("export", work / "nope.h5", "--oem", work / "x.oem"), "nope.h5", "no such file")
    one_line_error(fracas("export", traj_file, "--oem", work / "x.oem", "--covariance", "true"), "holds no covariance")
    one_line_error(fracas("export", traj_file, "--covariance-at", "final", "--csv", work / "x.csv"), "TEAM results")
    one_line_error(fracas("export", team_file), "nothing to export")
    assert fracas("export", team_file, "--oem", work).exit_code == 2  # click's usage error
    assert not (work / "x.csv").exists() and not (work / "x.oem").exists()


def test_export_cli_writes_oem_and_opms(work, team_file, team):
    """Reference: the library functions the command wraps (same OEM content; one OPM per event)."""
    r = fracas(
        "export", team_file, "--oem", work / "cli.oem", "--covariance-at", "all", "--opm", work / "ev.opm", "--xml"
    )
    assert r.exit_code == 0, r.output
    n = len(team["times_s"])
    assert len(list(work.glob("ev_*.opm"))) == n
    f = ccsds.read_oem(work / "cli.oem")
    assert f.segments[0].cov.shape == (n, 6, 6)
    assert (work / "cli.oem").read_text().startswith("<?xml")
    shutil.rmtree(work / "unused", ignore_errors=True)


def test_compare_oem_of_a_trajectory_with_its_own_oem(work, traj_file, traj_oem):
    """Reference: the OEM written from the same trajectory file (differences at the 15 digits
    the OEM keeps, every epoch in common); another trajectory shares no epoch: one line."""
    import json

    r = fracas("compare-oem", traj_file, traj_oem, "--json")
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    n = len(read_trajectory_file(traj_file).t_s)
    assert s["common_epochs"] == s["trajectory_epochs"] == s["oem_epochs"] == n
    assert s["max_dr_km"] < 1e-9 * 7000.0 and s["max_dv_km_s"] < 1e-9 * 7.5
    table = fracas("compare-oem", traj_file, traj_oem)
    assert table.exit_code == 0 and f"{n} common epochs" in table.stdout
    one_line_error(fracas("compare-oem", traj_file, work / "nope.oem"), "nope.oem", "no such OEM file")


def test_oem_table_with_another_state_table_is_refused(work, traj_oem):
    """Reference: the deck rule "exactly one of the initial-state tables"."""
    from fracas.config.trajectory import load_deck

    text = (
        OEM_DECK.format(at="", days=0.1)
        + "[initial_state.cartesian]\nr_km = [7000.0, 0.0, 0.0]\nv_km_s = [0.0, 7.5, 1.0]\n"
    )
    p = work / "two_tables.toml"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(DeckError, match=r"initial_state = \{cartesian, oem\}: give exactly one of the tables"):
        load_deck(p)


def test_export_writes_nothing_when_a_later_part_is_refused(work, team_file):
    """All of an export is checked before any file is written: a bad --covariance-at (an
    unknown event, or NaN days, which used to pick event #0) leaves no OEM behind."""
    oem_out = work / "partial.oem"
    one_line_error(
        fracas("export", team_file, "--oem", oem_out, "--covariance-at", "nosuchevent", "--opm", work / "p.opm"),
        "no such event",
    )
    one_line_error(fracas("export", team_file, "--covariance-at", "nan", "--csv", work / "n.csv"), "finite time")
    assert not oem_out.exists() and not (work / "n.csv").exists()


def test_team_file_of_another_trajectory_is_refused(work, team_file):
    """--team must hold covariances of this trajectory: a trajectory a year later (no TEAM
    epoch in its span) is refused instead of giving an OEM without covariances."""
    from fracas.modes.propagate import propagate_deck

    text = (work / "leo.toml").read_text(encoding="utf-8")
    assert 'iso = "2030-01-01T00:00:00"' in text
    (work / "later.toml").write_text(text.replace('iso = "2030-01-01T00:00:00"', 'iso = "2031-01-01T00:00:00"'))
    _, later = propagate_deck(work / "later.toml", work / "later.h5")
    one_line_error(
        fracas("export", later, "--team", team_file, "--oem", work / "later.oem"), "none of its", "covariance epochs"
    )
    assert not (work / "later.oem").exists()
