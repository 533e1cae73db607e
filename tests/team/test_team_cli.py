"""The TEAM command line on the small study: ``fracas run`` (--json, --quiet, the printout,
--plot, -o), ``fracas stm build`` / ``fracas stm info``, ``fracas run --stm`` and its
refusals (exit code 2, one line on stderr, no traceback).

In-process through click's CliRunner (the jitted kernels compiled by the other TEAM tests
are reused; a fresh interpreter per call would reload them).  References: the results
file the same command wrote, the hand counts of tests/team/test_schedule.py, the in-line
run for the STM-file run.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner, Result

from fracas.cli import main
from fracas.io.team_results import read_team_results

DATA = Path(__file__).resolve().parents[1] / "data"
SMALL = DATA / "team_small.toml"
TRAJ = DATA / "team_small_traj.toml"


def fracas(*args) -> Result:
    return CliRunner().invoke(main, [str(a) for a in args])


def ok(res) -> None:
    assert res.exit_code == 0, f"exit {res.exit_code}\nstdout: {res.stdout}\nstderr: {res.stderr}\n{res.exception!r}"


def refused(res, *expected: str) -> str:
    """Exit code 2, one line 'fracas: error: ...' on stderr containing ``expected``, no traceback."""
    assert res.exit_code == 2, f"exit {res.exit_code}\n{res.output}\n{res.exception!r}"
    assert isinstance(res.exception, SystemExit)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fracas: error: "), res.stderr
    assert "Traceback" not in res.output
    for e in expected:
        assert e in lines[0], lines[0]
    return lines[0]


@pytest.fixture(scope="module")
def tmp_mod(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("team_cli")


@pytest.fixture(scope="module")
def json_run(tmp_mod):
    out, png = tmp_mod / "small.h5", tmp_mod / "small.png"
    res = fracas("run", SMALL, "-o", out, "--plot", png, "--json")
    ok(res)
    return json.loads(res.stdout), out, png


@pytest.fixture(scope="module")
def stm_file(tmp_mod):
    path = tmp_mod / "small_stm.h5"
    res = fracas("stm", "build", SMALL, "-o", path)
    ok(res)
    return path, res.stdout


def test_run_json(json_run):
    """The JSON summary against the results file the same command wrote and the hand counts
    (21 schedule times, 42 observations; final time 4 d)."""
    s, out, _ = json_run
    assert s["file"] == str(out) and s["reference"] == "integrated" and s["filter"] == "kalman_schmidt"
    assert s["events"] == 21 and s["measurements_used"] + s["measurements_skipped"] == 42
    assert s["final_time_days"] == 4.0 and s["psd_problems"] == 0
    r = read_team_results(out)
    Pa, Pt = r["assumed"]["P_plus"][-1], r["true"]["P_plus"][-1]
    # the same float64 numbers through sqrt and a sum: rounding only
    assert s["assumed"]["position_rss_km"] == pytest.approx(np.sqrt(np.trace(Pa[:3, :3])), rel=1e-12)
    assert s["true"]["velocity_rss_km_s"] == pytest.approx(np.sqrt(np.trace(Pt[3:6, 3:6])), rel=1e-12)
    assert list(s["assumed"]["sigma"]) == r["labels"]
    assert s["assumed"]["sigma"]["cr"] == 0.0 and s["true"]["sigma"]["cr"] > 0  # ignore: the filter does not know it


def test_run_writes_png(json_run):
    s, _, png = json_run
    assert s["plot"] == str(png)
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000


def test_run_quiet(tmp_mod):
    out = tmp_mod / "quiet.h5"
    res = fracas("run", SMALL, "-o", out, "--quiet")
    ok(res)
    lines = res.stdout.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("21 events, ") and lines[0].endswith(f"written: {out}")
    assert out.exists()


@pytest.fixture(scope="module")
def printout(tmp_mod) -> str:
    res = fracas("run", SMALL, "-o", tmp_mod / "print.h5", "--verbose")  # every eigenvector event
    ok(res)
    return res.stdout


def test_run_printout(printout, tmp_mod):
    assert "TEAM TEAM test study" in printout and "reference:" in printout and "integrated" in printout
    for lab, role in (("thrust_scale", "solve_for"), ("bias_in_rad", "solve_for"), ("cr", "ignore")):
        assert re.search(rf"^\s*{re.escape(lab)}\s*│\s*{role}\b", printout, re.MULTILINE), (lab, role)
    assert "event log" in printout and "assumed knowledge at t = 1.5000 d" in printout
    assert printout.rstrip().endswith(f"written: {tmp_mod / 'print.h5'}")


def test_run_printout_shows_bracketed_labels(printout):
    assert "mu[sun]" in printout


def test_stm_build_and_info(stm_file):
    """73 file times (the 2 h grid over 6 d, see test_schedule), 5 parameter columns: the
    study's dynamic ones and the thrust-noise components."""
    path, built = stm_file
    assert built.startswith(f"written: {path} (73 times, 5 parameters: ")
    for lab in ("thrust_scale", "bias_in_rad", "mu[sun]", "cr", "bias_out_rad"):
        assert lab in built
    res = fracas("stm", "info", path)
    ok(res)
    info = res.stdout
    assert "times        73" in info and "parameters   5" in info
    for lab in ("thrust_scale", "bias_in_rad", "mu[sun]", "cr", "bias_out_rad"):
        assert f"  {lab} " in info
    assert "team_small_traj.toml" in info and "span         0.000000 to 6.000000 d" in info


def test_run_with_stm(json_run, stm_file, tmp_mod):
    """Same study through the file: equal to the in-line run at the STM-file tolerance
    (1e-8 relative; measured 5e-11 in test_team_engine)."""
    res = fracas("run", SMALL, "--stm", stm_file[0], "-o", tmp_mod / "via_file.h5", "--json")
    ok(res)
    s = json.loads(res.stdout)
    assert s["reference"] == str(stm_file[0])
    a = read_team_results(tmp_mod / "via_file.h5")["assumed"]["sigma"]
    b = read_team_results(json_run[1])["assumed"]["sigma"]
    np.testing.assert_allclose(a, b, rtol=1e-8, atol=0)


def _variant(tmp: Path, name: str, old: str, new: str, traj: Path = TRAJ) -> Path:
    text = (
        SMALL.read_text(encoding="utf-8").replace(old, new, 1).replace('"team_small_traj.toml"', json.dumps(str(traj)))
    )
    p = tmp / name
    p.write_text(text, encoding="utf-8")
    return p


def test_run_with_stm_refuses_time_not_on_file(stm_file, tmp_path):
    deck = _variant(tmp_path, "three_hours.toml", "interval_hours = 4.0", "interval_hours = 3.0")
    refused(
        fracas("run", deck, "--stm", stm_file[0], "--quiet"),
        f"{stm_file[0]}: requested time 10800.000000 s",
        "is not on the STM file",
    )


def test_run_with_stm_refuses_parameter_not_on_file(stm_file, tmp_path):
    deck = _variant(tmp_path, "mu_earth.toml", 'label = "mu[sun]"', 'label = "mu[earth]"')
    refused(
        fracas("run", deck, "--stm", stm_file[0], "--quiet"),
        "parameter mu[earth] not on the STM file",
        "it has thrust_scale, bias_in_rad, mu[sun], cr, bias_out_rad",
    )


def test_run_with_stm_refuses_other_trajectory(stm_file, tmp_path):
    traj = tmp_path / "traj.toml"
    traj.write_text(TRAJ.read_text(encoding="utf-8").replace("power_kw = 10.0", "power_kw = 10.5"), encoding="utf-8")
    deck = _variant(tmp_path, "other.toml", "", "", traj=traj)
    refused(fracas("run", deck, "--stm", stm_file[0], "--quiet"), "built from another trajectory")


def test_run_with_missing_stm_file(tmp_path):
    refused(fracas("run", SMALL, "--stm", tmp_path / "none.h5", "--quiet"), "none.h5", "no such STM file")
