"""The first run, as a class (issue 22 section 2), on the small decks of tests/data:

* ``-o`` decides where every output of a run goes: each mode (trajectory, TEAM, TOM,
  TSIM, sweep, rendezvous) run with ``-o DIR/x.h5`` from another working directory writes
  nothing outside DIR (directory listings compared);
* ``fracas report`` names each file's kind and says "written:" only for files it wrote;
* every line a command prints on a terminal fits 80 columns and no word is broken (the
  tokens of each 80-column printout are tokens of the same printout 400 columns wide).

One module fixture runs each mode once, on first use (in process: they share the compiled
programs); the TSIM cases are in the slow subset.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from fracas.cli import console as cli_console
from fracas.cli import main

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "tests" / "data"

NARROW = ("--width", "80")  # fracas run's printout as on an 80-column terminal
# mode -> (command line before -o, the results file's kind in `fracas report`)
RUNS = {
    "trajectory": (["run", str(DATA / "team_small_traj.toml"), *NARROW], "trajectory file"),
    "team": (["run", str(DATA / "team_small.toml"), *NARROW], "TEAM results file"),
    "tom": (["run", str(DATA / "hohmann_tom.toml"), *NARROW], "TOM results file"),
    "tsim": (["run", str(DATA / "tsim_small.toml"), *NARROW], "TSIM results file"),
    "sweep": (
        ["sweep", str(DATA / "team_small.toml"), "--vary", "thrust_noise.proportionality.sigma=0.01,0.02"]
        + ["--workers", "0"],
        "sweep table",
    ),
    "rendezvous": (["run", str(DATA / "rendezvous_small.toml"), *NARROW], "rendezvous results file"),
    # a sweep deck naming its table, plot and results folder (under out/): -o moves them all
    "sweep_deck": (["run", str(DATA / "sweep_small.toml"), "--workers", "0"], "sweep table"),
}
WATCHED = [DATA, REPO / "namelists", REPO / "out", REPO / "stm_files"]
SHARED = (REPO / "out", REPO / "stm_files")  # the default folders: compared by the names this test's runs would use
STEMS = ("team_small", "sweep_small", "hohmann", "tsim_small", "tsim_team", "rendezvous_small", "apollo12", "x.", "x_")


def _listing(folder: Path) -> dict[str, int]:
    """Every file under ``folder``: relative path -> modification time (ns)."""
    if not folder.exists():
        return {}
    return {
        str(p.relative_to(folder)): p.stat().st_mtime_ns
        for p in folder.rglob("*")
        if p.is_file() and "__pycache__" not in p.parts
    }


@pytest.fixture(scope="module")
def terminal():
    """The command line as on an 80-column terminal (one-line summaries and errors wrap)."""
    mp = pytest.MonkeyPatch()
    mp.setattr(cli_console, "_stdout_is_terminal", lambda: True)
    mp.setattr(cli_console, "_stderr_is_terminal", lambda: True)
    mp.setenv("COLUMNS", "80")
    yield mp
    mp.undo()


class _Runs(dict):
    """mode -> (result, output folder, working directory, listings of the watched folders
    before): each mode run once, on first use, with -o <mode>/x.h5 from an empty working
    directory (so a deselected mode costs nothing)."""

    def __init__(self, root: Path):
        super().__init__()
        self.root = root

    def __missing__(self, mode: str):
        args, _ = RUNS[mode]
        cwd, dest = self.root / f"{mode}_cwd", self.root / mode
        cwd.mkdir()
        dest.mkdir()
        before = {str(w): _listing(w) for w in WATCHED}
        old = os.getcwd()
        os.chdir(cwd)
        try:
            res = CliRunner().invoke(main, [*args, "-o", str(dest / "x.h5")])
        finally:
            os.chdir(old)
        self[mode] = (res, dest, cwd, before)
        return self[mode]


@pytest.fixture(scope="module")
def runs(tmp_path_factory, terminal):
    return _Runs(tmp_path_factory.mktemp("runs"))


# TSIM's first run compiles its mission programs (~60 s of a cold make test): its cases run in
# the slow subset (tests/test_montecarlo.py runs a TSIM deck through the CLI in the fast one).
MODES = [pytest.param(m, marks=pytest.mark.slow) if m == "tsim" else m for m in RUNS]


@pytest.mark.parametrize("mode", MODES)
def test_every_output_goes_where_o_says(runs, mode):
    res, dest, cwd, before = runs[mode]
    assert res.exit_code == 0, res.output
    assert (dest / "x.h5").is_file()
    assert _listing(cwd) == {}, f"{mode}: written in the working directory: {sorted(_listing(cwd))}"
    for w in WATCHED:
        now, then = _listing(w), before[str(w)]
        changed = {n for n in set(now) | set(then) if now.get(n) != then.get(n)}
        if w in SHARED:  # other work may write there meanwhile: only this run's names count
            changed = {n for n in changed if Path(n).name.startswith(STEMS)}
        assert not changed, f"{mode}: {w} changed: {sorted(changed)}"
    written = set(_listing(dest))
    if mode == "tom":  # the optimized reference deck goes beside -o too
        assert "hohmann_tom_reference.toml" in written, written
    if mode == "sweep_deck":  # the deck's plot and kept results go beside -o too
        assert "sweep_small.png" in written and any(n.startswith("sweep_small_results") for n in written), written


def test_tom_reference_deck_option_and_team_trajectory_deck(runs, tmp_path):
    """--reference-deck puts TOM's deck where it says; --trajectory-deck runs a TEAM deck
    on another trajectory deck than [ertraj] names (make demo's TOM -> TEAM chain)."""
    ref = runs["tom"][1] / "hohmann_tom_reference.toml"
    team = tmp_path / "team.toml"
    team.write_text(
        (DATA / "team_small.toml").read_text(encoding="utf-8").replace("team_small_traj.toml", "missing.toml"),
        encoding="utf-8",
    )
    r = CliRunner().invoke(main, ["run", str(team), "--trajectory-deck", str(DATA / "team_small_traj.toml")]
                           + ["-o", str(tmp_path / "t.h5"), "--quiet"])  # fmt: skip
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(main, ["run", str(DATA / "team_small.toml"), "--reference-deck", str(ref)])
    assert r.exit_code == 2 and "--reference-deck is for TOM decks" in " ".join(r.stderr.split())
    assert ref.is_file()


@pytest.mark.parametrize("mode", MODES)
def test_report_names_the_kind_and_writes_nothing(runs, mode):
    dest = runs[mode][1]
    before = _listing(dest)
    r = CliRunner().invoke(main, ["report", str(dest / "x.h5")])
    assert r.exit_code == 0, r.output
    assert "written:" not in r.output
    kind = RUNS[mode][1]
    assert f"{kind}: {dest / 'x.h5'}" in " ".join(r.stdout.split()), r.stdout
    assert _listing(dest) == before


# ----------------------------------------------------------------------------- 80 columns
_DECOR = re.compile(r"^[\W_]+$")


def _tokens(text: str) -> set[str]:
    """Words of a printout, without box drawing and the numbers that differ run to run.  A label
    may break before its bracket and a role at its underscore (the TEAM parameter table on a
    narrow terminal): those are word boundaries here, so only a fold inside a word shows."""
    text = text.replace("[", " [").replace("_", " ")
    return {t for t in text.split() if not _DECOR.match(t) and not re.search(r"\d", t)}


def _fits(text: str, what: str) -> None:
    """Every line within 80 columns, except a line that is one unbreakable word (a path longer
    than a line stands whole on a line of its own: pytest-xdist's temporary paths are ~80)."""
    long = [line for line in text.splitlines() if len(line) > 80 and len(line.split()) > 1]
    assert not long, f"{what}: {len(long)} line(s) over 80 columns, e.g. {long[0]!r}"
    assert "…" not in text, f"{what}: something was cut"


@pytest.mark.parametrize("mode", MODES)
def test_run_output_fits_80_columns(runs, mode):
    _fits(runs[mode][0].output, f"fracas {RUNS[mode][0][0]} ({mode})")


def _same_words(args: list[str], terminal, wide_args: list[str] = ()) -> None:
    """``args`` at 80 columns fits them, and its words are the words at 400 columns."""
    narrow = CliRunner().invoke(main, args)
    _fits(narrow.output, " ".join(args[:2]))
    terminal.setenv("COLUMNS", "400")
    try:
        wide = CliRunner().invoke(main, [*args, *wide_args])
    finally:
        terminal.setenv("COLUMNS", "80")
    broken = _tokens(narrow.output) - _tokens(wide.output)
    assert not broken, f"{' '.join(args[:2])}: words broken at 80 columns: {sorted(broken)[:10]}"


@pytest.mark.parametrize("mode", MODES)
def test_report_fits_80_columns_without_breaking_words(runs, mode, terminal):
    _same_words(["report", str(runs[mode][1] / "x.h5"), "--width", "80"], terminal, ["--width", "400"])


def test_stm_build_info_and_validate_fit_80_columns(tmp_path, terminal):
    stm = tmp_path / "s.h5"
    r = CliRunner().invoke(main, ["stm", "build", str(DATA / "team_small.toml"), "-o", str(stm)])
    assert r.exit_code == 0, r.output
    _fits(r.output, "stm build")
    _same_words(["stm", "info", str(stm)], terminal)
    r = CliRunner().invoke(main, ["report", str(stm)])  # an STM file is described, not misnamed
    assert r.exit_code == 0 and " ".join(r.stdout.split()).startswith(f"STM file {stm}"), r.output
    decks = sorted(str(p) for p in DATA.glob("*.toml")) + [str(REPO / "namelists" / "earth_mars_guidance.toml")]
    r = CliRunner().invoke(main, ["validate", *decks])
    assert r.exit_code == 2  # tests/data holds bad decks: their problems wrap too
    _same_words(["validate", *decks], terminal)
