"""Rendezvous results file (fracas.io.rendezvous_results) and report (fracas.report.rendezvous).

References: the written product itself (the file must give back every array bit for bit);
the 80-column rule for the terminal summary; the documented layout (file_kind, units)."""

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from fracas.cli import main
from fracas.errors import ResultsFileError
from fracas.io.rendezvous_results import read_rendezvous_results
from fracas.modes.rendezvous import run_rendezvous
from fracas.report.rendezvous import plot_rendezvous, summary_text
from tests.io.damage import edited

SMALL = "tests/data/rendezvous_small.toml"


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    out = tmp_path_factory.mktemp("rdv") / "small.h5"
    product, path = run_rendezvous(SMALL, out)
    return product, path


def test_file_gives_back_the_product(written):
    product, path = written
    back = read_rendezvous_results(path)
    for name in ("times_s", "P_true", "P_assumed", "P_true_minus", "maneuver_cov_true", "run_errors", "run_rms"):
        assert np.array_equal(getattr(back, name), getattr(product, name)), name
    assert back.roles == product.roles and back.labels == product.labels
    assert back.run_dynamics == "linear" and back.n_runs == 20
    with h5py.File(path, "r") as f:
        assert f.attrs["file_kind"] == "fracas-rendezvous-results"
        assert f["rendezvous/P_true"].attrs["units"] == "labels' units^2"


def test_summary_fits_80_columns_and_names_the_roles(written):
    product, _ = written
    text = summary_text(product)
    assert max(len(line) for line in text.splitlines()) <= 80
    for word in ("optimum", "Apollo", "TPI", "Single runs"):
        assert word in text


def test_plot_and_report_command(written, tmp_path):
    product, path = written
    assert plot_rendezvous(product, tmp_path / "p.png")[0].stat().st_size > 10_000
    r = CliRunner().invoke(main, ["report", str(path), "--plot", str(tmp_path / "q.png")])
    assert r.exit_code == 0, r.output
    assert "Maneuver error" in r.output and (tmp_path / "q.png").exists()


def test_not_a_rendezvous_file(tmp_path):
    p = tmp_path / "x.h5"
    with h5py.File(p, "w") as f:
        f.attrs["file_kind"] = "fracas-team-results"
    with pytest.raises(ResultsFileError, match="expected 'fracas-rendezvous-results'"):
        read_rendezvous_results(p)
    with pytest.raises(ResultsFileError, match="no such results file"):
        read_rendezvous_results(tmp_path / "none.h5")


def test_vehicle_stm_files_are_written_then_reused(tmp_path):
    """Each vehicle's STM file (the two-vehicle study's 'own STM file'): a first run writes
    both, a second reads them, and the covariances agree to 1e-12 relative (the file's step
    matrices are the integration's own; chaining identity steps changes nothing)."""
    from pathlib import Path

    from fracas.config.rendezvous import parse_rendezvous_deck

    text = Path(SMALL).read_text(encoding="utf-8")
    text = text.replace(
        'trajectory = "../../namelists/apollo12_lm_traj.toml"',
        f'trajectory = "../../namelists/apollo12_lm_traj.toml"\nstm_file = "{tmp_path}/lm.h5"',
    ).replace(
        'trajectory = "../../namelists/apollo12_csm_traj.toml"',
        f'trajectory = "../../namelists/apollo12_csm_traj.toml"\nstm_file = "{tmp_path}/csm.h5"',
    )
    deck = parse_rendezvous_deck(text, SMALL)
    first, _ = run_rendezvous(deck, write_results=False)
    assert (tmp_path / "lm.h5").exists() and (tmp_path / "csm.h5").exists()
    assert first.reference_sources[0].startswith("integrated, written to")
    second, _ = run_rendezvous(deck, write_results=False)
    assert second.reference_sources == [f"{tmp_path}/lm.h5", f"{tmp_path}/csm.h5"]
    scale = np.max(np.abs(first.P_true))
    assert np.max(np.abs(second.P_true - first.P_true)) <= 1e-12 * scale


def test_run_command_writes_results_and_plot(tmp_path):
    """``fracas run`` on a rendezvous deck: exit 0, the results file and the plot written,
    the JSON line naming them."""
    import json

    out, png = tmp_path / "r.h5", tmp_path / "r.png"
    r = CliRunner().invoke(main, ["run", SMALL, "-o", str(out), "--plot", str(png), "--json"])
    assert r.exit_code == 0, r.output
    info = json.loads(r.stdout.strip().splitlines()[-1])
    assert info["results"] == str(out) and info["roles"] == ["solve_for", "ignore"]
    assert out.exists() and png.exists()
    r = CliRunner().invoke(main, ["run", SMALL, "--stm", "x.h5"])
    assert r.exit_code == 2 and "not for rendezvous decks" in r.output


def test_too_many_single_runs_is_refused_in_one_line(monkeypatch):
    """A run whose single-run histories would not fit in a quarter of the memory is refused
    before the analysis and the runs, naming single_runs.runs (the memory is faked small here)."""
    import os

    from fracas.errors import DeckError

    real = os.sysconf
    monkeypatch.setattr(os, "sysconf", lambda k: 1 if k == "SC_PHYS_PAGES" else real(k))
    with pytest.raises(DeckError, match=r"single_runs\.runs = 20: .* GiB"):
        run_rendezvous(SMALL, write_results=False)


def test_damaged_or_incomplete_file_is_refused_naming_the_dataset(written, tmp_path):
    """Every dataset is checked (dtype, shape, SHA-256) on reading: an edited covariance or a
    missing dataset is one ResultsFileError naming the file and the dataset."""
    import shutil

    _, path = written
    bad = tmp_path / "edited.h5"
    shutil.copy(path, bad)
    with edited(bad) as f:
        f["rendezvous/P_true"][0, 0, 0, 0] += 1.0
    with pytest.raises(ResultsFileError, match=r"edited\.h5: rendezvous/P_true: SHA-256 checksum mismatch"):
        read_rendezvous_results(bad)
    gone = tmp_path / "gone.h5"
    shutil.copy(path, gone)
    with edited(gone) as f:
        del f["rendezvous/maneuvers/cov_true"]
    with pytest.raises(ResultsFileError, match=r"rendezvous/maneuvers/cov_true: missing"):
        read_rendezvous_results(gone)
