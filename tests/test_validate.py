"""fracas.modes.validate_path: every bundled deck is valid; broken copies list every
problem, one line each naming the file and the field; no JAX is imported.

Timings (warm process, 2-core development machine): 1-8 ms per bundled deck
(leo_j2 ~1 ms, mercury_approach_team ~7 ms), measured by ``test_bundled_decks_are_valid``.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fracas.modes import check_path, validate_path

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = sorted((ROOT / "namelists").glob("*.toml")) + [ROOT / "tests" / "data" / "team_small.toml"]


@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: p.name)
def test_bundled_decks_are_valid(path):
    validate_path(path)  # warm
    t0 = time.perf_counter()
    assert validate_path(path) == []
    elapsed = time.perf_counter() - t0
    print(f"{path.name}: {elapsed * 1e3:.1f} ms")  # reported, not asserted


def test_kind_is_reported():
    assert check_path(ROOT / "namelists" / "leo_j2.toml") == ("propagate", [])
    assert check_path(ROOT / "namelists" / "mercury_approach_team.toml") == ("team", [])


@pytest.fixture
def study(tmp_path):
    """A copy of the Mercury study (TEAM deck + its trajectory deck) in tmp_path."""
    for name in ("mercury_approach_team.toml", "mercury_approach_traj.toml"):
        shutil.copy(ROOT / "namelists" / name, tmp_path / name)
    team = tmp_path / "mercury_approach_team.toml"
    text = team.read_text(encoding="utf-8").replace("../out/", "out/")
    team.write_text(text, encoding="utf-8")
    return team


def _edit(path: Path, *pairs: tuple[str, str]) -> None:
    text = path.read_text(encoding="utf-8")
    for old, new in pairs:
        assert old in text
        text = text.replace(old, new, 1)
    path.write_text(text, encoding="utf-8")


def _one_line_each(problems, src):
    assert problems
    for line in problems:
        assert "\n" not in line and line.startswith(f"{src}: ")


def test_several_problems_all_listed(study):
    _edit(
        study,
        ("mass_sigma_kg", "mass_sigmakg"),
        ("sigma = 88.13", "sigma = 1e300"),
        ("min_elevation_deg = 10.0", "min_elevation_deg = 100.0"),
    )
    problems = validate_path(study)
    _one_line_each(problems, study)
    text = "\n".join(problems)
    assert len(problems) == 3
    assert f"{study}: a_priori.mass_sigmakg: unknown key; did you mean mass_sigma_kg?" == problems[0]
    assert "parameter[3].sigma = 1e+300: must be <=" in text
    assert "filter.min_elevation_deg = 100.0: must be <= 90" in text


def test_trajectory_deck_problems_are_listed(study):
    traj = study.parent / "mercury_approach_traj.toml"
    _edit(traj, ("[spacecraft]\n", "[spacecraft]\nmass_kgs = 3\n"))
    problems = validate_path(study)
    _one_line_each(problems, traj)
    assert problems[0].startswith(f"{traj}: spacecraft.mass_kgs")


def test_missing_trajectory_deck(study):
    (study.parent / "mercury_approach_traj.toml").unlink()
    assert validate_path(study) == [
        f'{study}: ertraj.deck = "mercury_approach_traj.toml": no such trajectory deck '
        f"({study.parent / 'mercury_approach_traj.toml'})"
    ]


def test_unknown_parameter_label(study):
    _edit(study, ('label = "mu[mercury]"', 'label = "mu[jupiter]"'))
    (problem,) = validate_path(study)
    assert problem.startswith(f'{study}: parameter[3].label = "mu[jupiter]": parameter')
    assert "is not in the force model" in problem


def test_missing_stm_file(study):
    _edit(study, ('propagation = "phi"', 'propagation = "phi"\nstm_file = "stm/none.h5"'))
    (problem,) = validate_path(study)
    assert problem == f'{study}: errcon.stm_file = "stm/none.h5": no such file ({study.parent / "stm" / "none.h5"})'


def test_stm_file_of_another_kind(study):
    h5py = pytest.importorskip("h5py")
    with h5py.File(study.parent / "other.h5", "w") as f:
        f.attrs["file_kind"] = "fracas-punch"
    (study.parent / "text.h5").write_text("not hdf5", encoding="utf-8")
    _edit(study, ('propagation = "phi"', 'propagation = "phi"\nstm_file = "other.h5"'))
    (problem,) = validate_path(study)
    assert problem == f"{study}: errcon.stm_file = \"other.h5\": file_kind = 'fracas-punch', expected 'fracas-stm'"
    _edit(study, ('stm_file = "other.h5"', 'stm_file = "text.h5"'))
    (problem,) = validate_path(study)
    assert problem.startswith(f'{study}: errcon.stm_file = "text.h5": not an HDF5 file')


def test_stm_file_of_another_trajectory(study):
    h5py = pytest.importorskip("h5py")
    with h5py.File(study.parent / "stm.h5", "w") as f:
        f.attrs["file_kind"] = "fracas-stm"
        f.create_group("trajectory_deck").attrs["trajectory_hash"] = "0" * 64
    _edit(study, ('propagation = "phi"', 'propagation = "phi"\nstm_file = "stm.h5"'))
    (problem,) = validate_path(study)
    assert problem.startswith(
        f'{study}: errcon.stm_file = "stm.h5": was built from another trajectory (hash 000000000000'
    )


def test_missing_punch_file(study):
    _edit(study, ("mass_sigma_kg = 1.0", 'mass_sigma_kg = 1.0\nfrom_punch = "k.h5"'))
    (problem,) = validate_path(study)
    assert problem == f'{study}: a_priori.from_punch = "k.h5": no such file ({study.parent / "k.h5"})'


def test_bad_user_gain(study):
    _edit(study, ('type = "kalman_schmidt"', 'type = "user"\nuser_gain = "no_such_module_xyz:gain"'))
    (problem,) = validate_path(study)
    assert problem.startswith(f'{study}: filter.user_gain = "no_such_module_xyz:gain": cannot import it')
    _edit(study, ('user_gain = "no_such_module_xyz:gain"', 'user_gain = "math:pi"'))
    assert validate_path(study) == [f'{study}: filter.user_gain = "math:pi": is not callable']
    _edit(study, ('user_gain = "math:pi"', 'user_gain = "math:hypot"'))
    assert validate_path(study) == []


def test_output_path_is_a_directory(study):
    (study.parent / "out" / "mercury_approach_team.h5").mkdir(parents=True)
    (problem,) = validate_path(study)
    assert problem.startswith(f'{study}: output.results = "out/mercury_approach_team.h5": is a directory')


def test_output_folder_under_a_file(study):
    (study.parent / "out").write_text("a file", encoding="utf-8")
    problems = validate_path(study)
    assert len(problems) == 3  # results, plot, punch file
    assert problems[0] == (
        f'{study}: output.results = "out/mercury_approach_team.h5": cannot create its folder: {study.parent / "out"} '
        "is a file"
    )
    assert not (study.parent / "out").is_dir()  # nothing was created


def test_sizes_need_the_trajectory(study):
    _edit(study, ("grid_hours = 1.0", "grid_hours = 1e-9"))
    (problem,) = validate_path(study)
    assert problem.startswith(f"{study}: stm.grid_hours = 1e-09: gives 9.6e+11 STM times over 0-40 d")


def test_unreadable_decks(tmp_path):
    assert validate_path(tmp_path / "none.toml") == [f"{tmp_path / 'none.toml'}: no such file"]
    bad = tmp_path / "bad.toml"
    bad.write_text('mode = "fly"\n', encoding="utf-8")
    assert validate_path(bad) == [
        f"{bad}: mode = 'fly': unknown mode (expected one of: propagate, team, sweep, tom, tsim, rendezvous)"
    ]


def test_no_jax_imported():
    code = (
        "import sys\nfrom fracas.modes import validate_path\n"
        f"paths = {[str(p) for p in BUNDLED]!r}\n"
        "for p in paths:\n    assert validate_path(p) == [], p\n"
        "print(sorted(m for m in sys.modules if m == 'jax' or m.startswith('jax.')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == "[]"


def test_validate_command_lists_every_problem(tmp_path):
    """``fracas validate``: "ok: DECK (mode)" and exit 0 for the bundled decks; a broken copy
    gets one line per problem on stderr and exit 2, no traceback."""
    from click.testing import CliRunner

    from fracas.cli import main

    decks = sorted(str(p) for p in (ROOT / "namelists").glob("*.toml"))
    r = CliRunner().invoke(main, ["validate", *decks])
    assert r.exit_code == 0, r.output
    kind = {"_team.toml": "team", "_guidance.toml": "team", "_sweep.toml": "sweep", "_tom.toml": "tom"}

    def mode(d: str) -> str:
        if "_tsim" in Path(d).name:
            return "tsim"
        if d.endswith("_rendezvous.toml"):
            return "rendezvous"
        return next((v for k, v in kind.items() if d.endswith(k)), "propagate")

    expected = [f"ok: {d} ({mode(d)})" for d in decks]
    assert r.stdout.splitlines() == expected
    bad = tmp_path / "bad.toml"
    text = (ROOT / "tests/data/team_small.toml").read_text(encoding="utf-8")
    bad.write_text(
        text.replace('title = "TEAM test study"', 'title = "x"\nbogus_key = 1').replace(
            "sigma = 0.01", "sigma = 1e300", 1
        ),
        encoding="utf-8",
    )
    r = CliRunner().invoke(main, ["validate", str(bad)])
    lines = r.stderr.strip().splitlines()
    assert r.exit_code == 2 and len(lines) >= 2 and "Traceback" not in r.output
    assert all(line.startswith(f"fracas: error: {bad}: ") for line in lines)
    assert any("bogus_key" in line for line in lines) and any("parameter[0].sigma" in line for line in lines)
