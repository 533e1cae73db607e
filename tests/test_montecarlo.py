"""The TSIM driver (fracas.modes.tsim.run): bit-identical statistics whatever the batch size, the
worker count or a kill and resume; a-priori merging of two half runs against one whole run;
the command line and its errors.

References: the run's own per-mission numbers under another partition of the same missions
(bitwise: mission i's draws and lane do not depend on the partition), and, for the merge,
numpy's mean and covariance of the whole run's missions (STAT-1 is exact in count, mean and
co-moment: equal to rounding, 1e-12 relative).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fracas.cli import main
from fracas.config.tsim import parse_tsim_deck
from fracas.errors import DeckError
from fracas.io.tsim_results import read_tsim_results
from fracas.modes.tsim.run import checkpoint_path, run_tsim

DATA = Path(__file__).resolve().parent / "data"
# the TEAM study of tests/tsim/test_engine.py (one TEAM run per test process serves both)
NO_NOISE = (
    'impulse_propellant = "booked"\n[insim.team_changes]\n"thrust_noise.proportionality.sigma" = 0.0\n'
    '"thrust_noise.in_plane_deg.sigma" = 0.0\n"thrust_noise.out_of_plane_deg.sigma" = 0.0\n'
)


def _deck(tmp: Path, name="run.toml", **insim) -> Path:
    """A TSIM deck in ``tmp`` standing on a copy of the small TEAM study."""
    for f in ("tsim_team.toml", "team_small_traj.toml"):
        if not (tmp / f).exists():
            shutil.copy(DATA / f, tmp / f)
    body = {"team_deck": '"tsim_team.toml"', "missions": "96", "seed": "11", "batch_missions": "32", "scale": "0.2"}
    body.update({k: (f'"{v}"' if isinstance(v, str) else str(v).lower() if isinstance(v, bool) else str(v))
                 for k, v in insim.items()})  # fmt: skip
    path = tmp / name
    path.write_text('mode = "tsim"\n[insim]\n' + "".join(f"{k} = {v}\n" for k, v in body.items()) + NO_NOISE)
    return path


def _same(a, b):
    assert a.table.keys() == b.table.keys()
    for k in a.table:
        np.testing.assert_array_equal(a.table[k], b.table[k], err_msg=k)
    assert a.statistics.keys() == b.statistics.keys()
    for k, (n, m, c) in a.statistics.items():
        n2, m2, c2 = b.statistics[k]
        assert n == n2
        np.testing.assert_array_equal(m, m2, err_msg=k)
        np.testing.assert_array_equal(c, c2, err_msg=k)


@pytest.mark.slow  # ~73 s of a cold make test (mostly XLA compilation; issue 22)
def test_batch_size_and_resume_give_the_same_bits(tmp_path):
    """Tasks of 32 and of 64 missions, and a run killed after its first task and started
    again (resuming from its checkpoint): identical tables and statistics, bit for bit."""
    deck = _deck(tmp_path)
    a, _ = run_tsim(deck, tmp_path / "a.h5")
    b, _ = run_tsim(deck, tmp_path / "b.h5", batch_missions=64)
    _same(a, b)
    out = tmp_path / "c.h5"
    none, ckpt = run_tsim(deck, out, stop_after_tasks=1)
    assert none is None and ckpt == checkpoint_path(out) and len(list(ckpt.glob("task_*.h5"))) == 1
    assert not out.exists()
    c, path = run_tsim(deck, out)
    assert path == out and not ckpt.exists()
    _same(a, c)
    _same(a, read_tsim_results(out))  # and the file holds what the run returned


def test_two_half_runs_merged_equal_one_whole_run(tmp_path):
    """STAT-1: missions 0-95 then 96-191 with the first run's statistics as a priori, against
    one run of 192 missions: the same missions (bitwise), and the merged count, mean and
    covariance equal the whole run's and numpy's to rounding (1e-12 relative)."""
    whole, _ = run_tsim(_deck(tmp_path, "whole.toml", missions=192), tmp_path / "whole.h5")
    run_tsim(_deck(tmp_path, "h1.toml", missions=96), tmp_path / "h1.h5")
    h2_deck = _deck(tmp_path, "h2.toml", missions=96, first_mission=96)
    h2_deck.write_text(h2_deck.read_text().replace("[insim]\n", '[insim]\na_priori_statistics = ["h1.h5"]\n', 1))
    h2, _ = run_tsim(h2_deck, tmp_path / "h2.h5")
    np.testing.assert_array_equal(h2.table["target_error"], whole.table["target_error"][96:])
    assert h2.counts["a_priori"] == 96
    for k, (n, mean, cov) in whole.statistics.items():
        n2, mean2, cov2 = h2.statistics[k]
        assert n2 == n, k
        scale = max(np.max(np.abs(cov)), 1e-300)
        assert np.max(np.abs(mean2 - mean)) <= 1e-12 * max(np.max(np.abs(mean)), np.sqrt(scale)), k
        assert np.max(np.abs(cov2 - cov)) <= 1e-12 * scale, k
    ok = whole.table["status"] <= 1
    x = whole.table["target_error"][ok]
    n, mean, cov = whole.statistics["target_error"]
    np.testing.assert_allclose(mean, x.mean(axis=0), rtol=1e-12, atol=1e-12 * np.abs(x).max())
    np.testing.assert_allclose(cov, np.cov(x.T), rtol=1e-11)


@pytest.mark.slow
def test_one_and_two_dask_workers_give_the_same_bits(tmp_path):
    """A Dask LocalCluster of 1 and of 2 worker processes (one XLA device each), against the
    in-process run: identical tables and statistics, bit for bit."""
    deck = _deck(tmp_path, missions=128)
    here, _ = run_tsim(deck, tmp_path / "here.h5")
    one, _ = run_tsim(deck, tmp_path / "one.h5", workers=1, scheduler=None, force_dask=True)
    two, _ = run_tsim(deck, tmp_path / "two.h5", workers=2)
    _same(here, one)
    _same(here, two)
    assert two.settings["workers"] == 2


def test_cli_runs_a_tsim_deck_and_reports_it(tmp_path):
    """``fracas run`` prints the summary (80 columns) and writes the results and plots;
    ``fracas report`` reads the file back."""
    deck = _deck(tmp_path, missions=32)
    runner = CliRunner()
    res = runner.invoke(main, ["run", str(deck), "-o", str(tmp_path / "r.h5"), "--plot", str(tmp_path / "r.png")])
    assert res.exit_code == 0, res.output
    assert "consistency with TEAM" in res.output
    assert all(len(line) <= 80 for line in res.output.splitlines() if not line.startswith(("results:", "plot:")))
    assert (tmp_path / "r.png").stat().st_size > 0
    rep = runner.invoke(main, ["report", str(tmp_path / "r.h5")])
    assert rep.exit_code == 0, rep.output
    assert "missions 32" in rep.output


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        ('[[maneuver]]\nname = "nope"\n', "maneuver[0].name = 'nope': not a guidance event of the TEAM deck"),
        ('[[maneuver]]\nname = "lt2"\nlaw = "nonlinear"\n', 'maneuver[0].law = "nonlinear": built for impulsive'),
        ('[[maneuver]]\nname = "tcm1"\ntolerance = [1.0]\n', "maneuver[0].tolerance: 1 entries; expected 3"),
    ],
)
def test_deck_errors_name_the_field(tmp_path, extra, expected):
    """A wrong [[maneuver]] is one line naming the file and the field, exit 2, nothing written."""
    deck = _deck(tmp_path)
    deck.write_text(deck.read_text() + extra)  # [[maneuver]] after [insim.team_changes]: a new table
    res = CliRunner().invoke(main, ["run", str(deck), "-o", str(tmp_path / "x.h5")])
    assert res.exit_code == 2, res.output
    assert expected in res.output and str(deck) in res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "x.h5").exists()


def test_missing_team_deck_and_bad_values():
    """The schema's one-line errors: a missing TEAM deck, a negative scale, an unknown key."""
    from fracas.config.tsim import tsim_problems

    cfg = parse_tsim_deck('mode = "tsim"\n[insim]\nteam_deck = "nowhere.toml"\n', str(DATA / "x.toml"))
    assert "insim.team_deck = 'nowhere.toml': no such TEAM deck" in tsim_problems(cfg)[0]
    with pytest.raises(DeckError, match="insim.scale"):
        parse_tsim_deck('mode = "tsim"\n[insim]\nteam_deck = "a.toml"\nscale = -1\n', "d.toml")
    with pytest.raises(DeckError, match="missionz"):
        parse_tsim_deck('mode = "tsim"\n[insim]\nteam_deck = "a.toml"\nmissionz = 3\n', "d.toml")


@pytest.mark.slow
def test_unreachable_scheduler_is_one_line(tmp_path):
    """--scheduler at an address nobody answers: one line naming it, exit 1, nothing written
    (after the client's 10 s timeout)."""
    deck = _deck(tmp_path, missions=32)
    res = CliRunner().invoke(main, ["run", str(deck), "-o", str(tmp_path / "x.h5"), "--scheduler", "tcp://127.0.0.1:9"])
    assert res.exit_code != 0, res.output
    assert "could not start the Dask scheduler at tcp://127.0.0.1:9" in res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "x.h5").exists()


def test_a_table_too_big_for_memory_is_refused_in_one_line(tmp_path, monkeypatch):
    """A run whose per-mission table would not fit in a quarter of the memory: one line naming
    insim.missions, the size and the way out (split runs), before any mission flies."""
    import os

    real = os.sysconf
    monkeypatch.setattr(os, "sysconf", lambda k: 256 if k == "SC_PHYS_PAGES" else real(k))  # ~1 MB
    deck = _deck(tmp_path, missions=100_000)
    with pytest.raises(DeckError, match=r"insim.missions = 100000: the per-mission table would take .* GiB"):
        run_tsim(deck, tmp_path / "big.h5")
    assert not (tmp_path / "big.h5").exists()


def test_a_priori_file_of_the_same_missions_is_refused(tmp_path):
    """STAT-1 merging needs disjoint missions: an a-priori file made with the same seed over
    an overlapping mission range would count missions twice, so the run is refused in one
    line naming insim.a_priori_statistics[0], before any mission flies."""
    run_tsim(_deck(tmp_path, "h1.toml", missions=32), tmp_path / "h1.h5")
    again = _deck(tmp_path, "again.toml", missions=32, first_mission=16)
    again.write_text(again.read_text().replace("[insim]\n", '[insim]\na_priori_statistics = ["h1.h5"]\n', 1))
    with pytest.raises(DeckError, match=r"insim\.a_priori_statistics\[0\] = 'h1\.h5': missions 0\.\.31 with seed"):
        run_tsim(again, tmp_path / "again.h5")
