"""The pipeline and the command line as one chain (fracas/modes, fracas/cli).

References: a run of the same study from a deck file (for the in-memory config entry
point), the results file itself (for ``fracas report``), the deck's own mode line (for
dispatch).  The small TEAM study of tests/data keeps each run to a few seconds.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from fracas.cli import main
from fracas.config.team import load_team_deck
from fracas.io.team_results import read_team_results
from fracas.modes import deck_mode
from fracas.modes.team import run_team as run

DATA = Path(__file__).resolve().parent / "data"
SMALL = DATA / "team_small.toml"


def fracas(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_in_memory_config_equals_the_deck_file(tmp_path):
    """Entry points take config objects: the small study with its filter stopped at 3 d,
    varied in memory (pydantic model_copy), gives exactly the results file of the same
    change written into a deck file (bit for bit: same arithmetic)."""
    deck = load_team_deck(SMALL)
    varied = deck.model_copy(update={"filter": deck.filter.model_copy(update={"stop_days": 3.0})})
    varied._source_path, varied._source_text = deck.source_path, deck.source_text  # same folder for relative paths
    p1, out1, _ = run(varied, output=tmp_path / "memory.h5")
    text = SMALL.read_text(encoding="utf-8").replace("stop_days = 4.0", "stop_days = 3.0")
    assert text != SMALL.read_text(encoding="utf-8")
    file_deck = DATA / "_tmp_pipeline_variant.toml"
    try:
        file_deck.write_text(text, encoding="utf-8")
        p2, out2, _ = run(file_deck, output=tmp_path / "file.h5")
    finally:
        file_deck.unlink()
    a, b = read_team_results(out1), read_team_results(out2)
    assert a["times_s"][-1] == 3.0 * 86400.0
    np.testing.assert_array_equal(a["times_s"], b["times_s"])
    np.testing.assert_array_equal(a["assumed"]["P_plus"], b["assumed"]["P_plus"])
    np.testing.assert_array_equal(a["true"]["P_plus"], b["true"]["P_plus"])
    assert p1.status == 0 and p1.assumed.P_plus.shape == a["assumed"]["P_plus"].shape


def test_report_reads_the_results_file(tmp_path):
    """``fracas report FILE --json`` gives the summary ``fracas run --json`` printed (the
    report reads the file; timings aside); the tables name the study."""
    out = tmp_path / "small.h5"
    r1 = fracas("run", SMALL, "-o", out, "--json")
    assert r1.exit_code == 0, r1.output
    r2 = fracas("report", out, "--json")
    assert r2.exit_code == 0, r2.output
    s1, s2 = json.loads(r1.stdout), json.loads(r2.stdout)
    s1.pop("timing_s"), s2.pop("timing_s")
    assert s1 == s2
    r3 = fracas("report", out)
    assert r3.exit_code == 0 and "TEAM test study" in r3.stdout and "event log" in r3.stdout


def test_report_refuses_a_missing_or_foreign_file(tmp_path):
    r = fracas("report", tmp_path / "nope.h5")
    assert r.exit_code == 2 and "no such results file" in r.stderr
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5")
    r = fracas("report", junk)
    assert r.exit_code == 2 and "junk.h5" in r.stderr and "Traceback" not in r.output


def test_mode_dispatch():
    """The mode line decides; a deck without one is a trajectory deck unless it is a TEAM
    deck written before modes existed (an [ertraj] table)."""
    assert deck_mode('mode = "team"\n') == "team"
    assert deck_mode('title = "x"\n') == "propagate"
    assert deck_mode('[ertraj]\ndeck = "t.toml"\n') == "team"
    assert deck_mode(SMALL.read_text(encoding="utf-8")) == "team"


def test_unknown_mode_or_incomplete_tsim_deck_is_refused(tmp_path):
    for mode, expected in (
        ("tsim", "insim: required"),
        ("fly", "mode = 'fly': unknown mode (expected one of: propagate, team, sweep, tom, tsim, rendezvous)"),
    ):
        deck = tmp_path / f"{mode}.toml"
        deck.write_text(f'mode = "{mode}"\n', encoding="utf-8")
        r = fracas("run", deck)
        assert r.exit_code == 2, r.output
        assert r.stderr.strip() == f"fracas: error: {deck}: {expected}"


def test_report_levels_and_units(tmp_path):
    """--quiet < normal < --verbose in lines; --velocity-unit m/s puts every velocity in m/s
    (the quiet line's RSS equals the file's final sigma in m/s); --quiet with --verbose is
    refused in one line."""
    out = tmp_path / "small.h5"
    assert fracas("run", SMALL, "-o", out, "--quiet").exit_code == 0
    n = {
        lvl: len(fracas("report", out, *flags).stdout.splitlines())
        for lvl, flags in (("quiet", ["--quiet"]), ("normal", []), ("verbose", ["--verbose"]))
    }
    assert n["quiet"] == 1 < n["normal"] < n["verbose"]
    line = fracas("report", out, "--quiet", "--velocity-unit", "m/s").stdout
    sig = read_team_results(out)["assumed"]["sigma"][-1]
    assert f"{np.sqrt(np.sum(sig[3:6] ** 2)) * 1e3:.4g} m/s" in line and "mm/s" not in line
    r = fracas("report", out, "--quiet", "--verbose")
    assert r.exit_code == 2 and r.stderr.strip() == "fracas: error: --quiet and --verbose: choose one"
