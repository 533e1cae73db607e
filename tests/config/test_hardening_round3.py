"""Hardening round 3 (issue 32, items 1d and 1e and the schema/wording items): each class of
bad input is refused (or warned about) in one line naming the file and the field, by
``fracas validate`` and by the run alike, before any work.

* 1d: a TEAM study's times past the end of its reference trajectory (the run used to stop
  at the trajectory's end without a word);
* 1e: an initial state hyperbolic by orders of magnitude, or far beyond its centre's
  sphere of influence (m/s or m typed for km): a warning, the run goes on;
* physical bounds on every magnitude (positions, velocities, impulses, masses, angles,
  pointing-law coefficients, times, the integrator tolerance's floor);
* sizes refused before any work (TSIM's per-mission table, TOM's GRID, noise grids);
* wording: a later integrity-header version, a forged header kind; validate runs the
  output-path checks the run does.
"""

from __future__ import annotations

import copy
import re
from pathlib import Path
from typing import Any

import pytest
import tomllib
from click.testing import CliRunner

from fracas.cli import main
from fracas.config.trajectory import TrajectoryDeck, plausible, validate_sourced
from fracas.errors import DeckError

ROOT = Path(__file__).resolve().parents[2]
NAMELISTS = ROOT / "namelists"
DATA = ROOT / "tests" / "data"
SRC = "deck.toml"


@pytest.fixture(autouse=True)
def _fresh_warnings():
    plausible.reset()
    yield
    plausible.reset()


def _data(name: str, folder: Path = NAMELISTS) -> dict[str, Any]:
    return tomllib.loads((folder / name).read_text(encoding="utf-8"))


def _set(data: dict, path: str, value: Any) -> dict:
    """``data`` with the dotted ``path`` (list entries as ``name[k]``) set to ``value``."""
    out = copy.deepcopy(data)
    cur: Any = out
    parts = path.split(".")
    for i, part in enumerate(parts):
        m = re.fullmatch(r"([a-z_0-9]+)(?:\[(\d+)\])?", part)
        key, idx = m.group(1), m.group(2)
        last = i == len(parts) - 1
        if idx is None:
            if last:
                cur[key] = value
            else:
                cur = cur.setdefault(key, {})
        else:
            if last:
                cur[key][int(idx)] = value
            else:
                cur = cur[key][int(idx)]
    return out


def _refused(cls: type, data: dict) -> DeckError:
    with pytest.raises(DeckError) as info:
        validate_sourced(data, SRC, cls)
    for line in [str(info.value), *info.value.problems]:
        assert "\n" not in line and line.startswith(f"{SRC}: "), line
    return info.value


# ----------------------------------------------------------------------------- magnitudes
SPIRAL = _data("near_earth_spiral.toml")  # thrust arcs, elements
LEO = _data("leo_j2.toml")  # cartesian state
LEO_IMPULSE = _set(LEO, "impulse", [{"time_days": 0.5, "dv_km_s": [0.1, 0.0, 0.0]}])

#: (base deck, field, huge value, the field named in the line, a word of what is expected)
TRAJECTORY_BOUNDS = [
    (LEO, "initial_state.cartesian.r_km", [0.0, 7000.0, 8.3e18], "initial_state.cartesian.r_km", "km"),
    (LEO, "initial_state.cartesian.v_km_s", [0.0, 1e6, 0.0], "initial_state.cartesian.v_km_s", "speed of light"),
    (LEO_IMPULSE, "impulse[0].dv_km_s", [1e6, 0.0, 0.0], "impulse[0].dv_km_s", "impulsive engine"),
    (LEO_IMPULSE, "impulse[0].isp_s", 1e300, "impulse[0].isp_s", "speed of light"),
    (LEO, "spacecraft.mass_kg", 1e300, "spacecraft.mass_kg", "tonnes"),
    (LEO, "spacecraft.area_m2", 1e300, "spacecraft.area_m2", "km^2"),
    (LEO, "stop.duration_days", 1e300, "stop.duration_days", "years"),
    (LEO, "integrator.tolerance", 1e-16, "integrator.tolerance", "float64"),
    (LEO, "integrator.tolerance", 1e-17, "integrator.tolerance", "float64"),
    (SPIRAL, "thrust_arc[0].alpha_deg", 1e300, "thrust_arc[0].alpha_deg", "two turns"),
    (SPIRAL, "thrust_arc[0].alpha_legendre_deg", [1e308], "thrust_arc[0].alpha_legendre_deg[0]", "two turns"),
    (SPIRAL, "thrust_arc[0].beta_legendre_deg", [0.0, 1e300], "thrust_arc[0].beta_legendre_deg[1]", "two turns"),
    (SPIRAL, "thrust_arc[0].stop_days", 1e300, "thrust_arc[0].stop_days", "years"),
    (SPIRAL, "propulsion.power_kw", 1e300, "propulsion.power_kw", "GW"),
    (SPIRAL, "propulsion.exhaust_velocity_km_s", 1e300, "propulsion.exhaust_velocity_km_s", "speed of light"),
    (SPIRAL, "propulsion.thrust_scale", 1e300, "propulsion.thrust_scale", "<="),
    (SPIRAL, "initial_state.elements.a_km", 1e300, "initial_state.elements.a_km", "AU"),
    (SPIRAL, "initial_state.elements.raan_deg", 1e300, "initial_state.elements.raan_deg", "two turns"),
    (SPIRAL, "forces.overrides", {"earth": {"mu_km3_s2": 1e300}}, "forces.overrides.earth.mu_km3_s2", "Sun"),
]


@pytest.mark.parametrize(
    "base,field,value,named,word", TRAJECTORY_BOUNDS, ids=[f"{c[1]}={c[2]!r:.12}" for c in TRAJECTORY_BOUNDS]
)
def test_every_bounded_trajectory_field_is_refused_in_one_line(base, field, value, named, word):
    exc = _refused(TrajectoryDeck, _set(base, field, value))
    assert str(exc).startswith(f"{SRC}: {named} = "), str(exc)
    assert word in str(exc)


def test_the_tolerance_floor_says_why_and_1e_14_stays_allowed():
    exc = _refused(TrajectoryDeck, _set(LEO, "integrator.tolerance", 1e-16))
    assert "must be >= 1e-15" in str(exc) and "epsilon" in str(exc)
    for ok in (1e-14, 1e-13, 1e-15):
        validate_sourced(_set(LEO, "integrator.tolerance", ok), SRC, TrajectoryDeck)


def test_bounds_leave_every_bundled_value_alone():
    """The largest magnitudes of the bundled decks validate (the bounds are far beyond them)."""
    validate_sourced(_set(SPIRAL, "thrust_arc[0].alpha_legendre_deg", [720.0, -720.0, 0.0]), SRC, TrajectoryDeck)
    validate_sourced(_set(LEO, "initial_state.cartesian.r_km", [1e12, 0.0, 0.0]), SRC, TrajectoryDeck)


TEAM = _data("team_small.toml", DATA)
TEAM_BOUNDS = [
    ("a_priori.mass_sigma_kg", 1e300, "a_priori.mass_sigma_kg"),
    (
        "event",
        [{"type": "reset", "times_days": [1.0], "position_sigma_km": [1e300, 1, 1], "velocity_sigma_km_s": [1, 1, 1]}],
        "event[0].position_sigma_km[0]",
    ),
    (
        "event",
        [{"type": "reset", "times_days": [1.0], "position_sigma_km": [1, 1, 1], "velocity_sigma_km_s": [1, 1e6, 1]}],
        "event[0].velocity_sigma_km_s[1]",
    ),
]


@pytest.mark.parametrize("field,value,named", TEAM_BOUNDS, ids=[c[2] for c in TEAM_BOUNDS])
def test_every_bounded_team_field_is_refused_in_one_line(field, value, named):
    from fracas.config.team import TeamDeck

    exc = _refused(TeamDeck, _set(TEAM, field, value))
    assert any(p.startswith(f"{SRC}: {named} = ") for p in exc.problems), exc.problems


TSIM = _data("earth_mars_tsim.toml")
TSIM_BOUNDS = [
    ("insim.scale", 1e300, "insim.scale"),
    (
        "insim.injection",
        {"position_sigma_km": [1e300, 0.0, 0.0], "velocity_sigma_km_s": [0.0, 0.0, 0.0]},
        "insim.injection.position_sigma_km[0]",
    ),
    (
        "insim.injection",
        {"position_sigma_km": [1.0, 1.0, 1.0], "velocity_sigma_km_s": [0.0, 1e6, 0.0], "mass_sigma_kg": 1.0},
        "insim.injection.velocity_sigma_km_s[1]",
    ),
]


@pytest.mark.parametrize("field,value,named", TSIM_BOUNDS, ids=[c[2] for c in TSIM_BOUNDS])
def test_every_bounded_tsim_field_is_refused_in_one_line(field, value, named):
    from fracas.config.tsim import TsimDeck

    exc = _refused(TsimDeck, _set(TSIM, field, value))
    assert str(exc).startswith(f"{SRC}: {named} = "), str(exc)


def test_validate_refuses_a_huge_pointing_angle_in_one_line(tmp_path):
    deck = tmp_path / "spiral.toml"
    text = (NAMELISTS / "near_earth_spiral.toml").read_text(encoding="utf-8")
    deck.write_text(text.replace("alpha_deg = 0.0", "alpha_deg = 1e300", 1), encoding="utf-8")
    res = CliRunner().invoke(main, ["validate", str(deck)])
    assert res.exit_code == 2
    lines = res.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"fracas: error: {deck}: thrust_arc[0].alpha_deg = 1e+300: ")


# ----------------------------------------------------------------------------- sizes
def _tsim_deck(tmp_path: Path, missions: int, extra: str = "") -> Path:
    text = (NAMELISTS / "earth_mars_tsim.toml").read_text(encoding="utf-8")
    text = text.replace(
        'team_deck = "earth_mars_guidance.toml"', f'team_deck = "{NAMELISTS / "earth_mars_guidance.toml"}"'
    )
    text = re.sub(r"(?m)^missions = \d+", f"missions = {missions}{extra}", text)
    deck = tmp_path / "tsim.toml"
    deck.write_text(re.sub(r"(?m)^(results|plot) = .*$", "", text), encoding="utf-8")
    return deck


def test_ten_million_tsim_missions_are_refused_before_any_work(tmp_path, monkeypatch):
    from fracas.config import limits
    from fracas.modes import check_path

    monkeypatch.setattr(limits, "machine_memory_bytes", lambda: 16 * 2**30)
    _, problems = check_path(_tsim_deck(tmp_path, 10_000_000))
    assert len(problems) == 1 and "insim.missions = 10000000: the per-mission table would take at least" in problems[0]
    assert check_path(_tsim_deck(tmp_path, 2000))[1] == []


def test_a_tiny_tsim_noise_step_is_refused(tmp_path):
    from fracas.modes import check_path

    _, problems = check_path(_tsim_deck(tmp_path, 2000, "\nnoise_step_days = 1e-9"))
    assert len(problems) == 1 and "insim.noise_step_days = 1e-09: gives 3e+11 noise-grid points" in problems[0]


def test_tom_grid_size_is_refused_in_the_schema():
    from fracas.config.tom import TomDeck

    data = {
        "mode": "tom",
        "trajectory": {"deck": "x.toml"},
        "tom": {"submode": "grid"},
        "control": [{"name": "vx0"}, {"name": "vy0"}, {"name": "vz0"}],
        "grid": {"increments": [1e-3, 1e-3, 1e-3], "steps": 1_000_000},
    }
    exc = _refused(TomDeck, data)
    assert str(exc).startswith(f"{SRC}: grid.steps = 1000000: gives ") and "limit 100000" in str(exc)


# ----------------------------------------------------------------------------- 1d: past the trajectory's end
def _truncated(tmp_path: Path) -> Path:
    """A TEAM deck whose filter and tracking run to 10 d on a 5-day trajectory (issue 32 1d)."""
    traj = (DATA / "team_small_traj.toml").read_text(encoding="utf-8")
    traj = traj.replace("duration_days = 6.0", "duration_days = 5.0").replace("stop_days = 6.0", "stop_days = 5.0")
    (tmp_path / "traj.toml").write_text(traj, encoding="utf-8")
    team = tmp_path / "team.toml"
    team.write_text(
        'mode = "team"\n[ertraj]\ndeck = "traj.toml"\n[filter]\nstop_days = 10.0\n'
        "[a_priori]\nposition_rss_km = 100.0\nvelocity_rss_km_s = 0.001\n"
        '[[tracking]]\ntype = "doppler2"\nstations = ["goldstone"]\nstart_days = 0.0\nstop_days = 10.0\n'
        "interval_hours = 4.0\nsigma = 1.0\n",
        encoding="utf-8",
    )
    return team


@pytest.mark.parametrize("command", ["validate", "run"])
def test_a_study_past_its_trajectory_is_refused_by_validate_and_run(tmp_path, command):
    team = _truncated(tmp_path)
    args = [command, str(team)] + (["-o", str(tmp_path / "out.h5")] if command == "run" else [])
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert lines and all(ln.startswith(f"fracas: error: {team}: ") for ln in lines), lines
    assert len(lines) == (2 if command == "validate" else 1)  # validate: every problem; run: the first, counted
    first = lines[0]
    assert "filter.stop_days = 10" in first and "0-10 d" in first and "0-5 d" in first, first
    if command == "validate":
        assert "tracking[0].stop_days = 10" in lines[1] and "0-5 d" in lines[1]
    assert not (tmp_path / "out.h5").exists()


def test_every_study_time_past_the_trajectory_is_named(tmp_path):
    from fracas.config.team import load_team_deck
    from fracas.config.team.span import team_span_problems
    from fracas.config.trajectory import load_deck

    team = _truncated(tmp_path)
    text = team.read_text(encoding="utf-8").replace("stop_days = 10.0\n[a_priori]", "stop_days = 4.0\n[a_priori]")
    text = text.replace("start_days = 0.0\nstop_days = 10.0", "start_days = 6.0\nstop_days = 7.0")
    text += '[punch]\ntimes_days = [1.0, 8.0]\nfile = "p.h5"\n[budget]\nat_days = [2.0, 9.0, 12.0]\n'
    team.write_text(text, encoding="utf-8")
    deck = load_team_deck(team)
    problems = team_span_problems(deck, load_deck(tmp_path / "traj.toml"))
    assert [p.split(": ")[1].split(" = ")[0] for p in problems] == [
        "tracking[0].stop_days",
        "punch.times_days",
        "budget.at_days",
    ]
    assert all("spans 0-5 d" in p for p in problems)
    assert "the latest 12 d" in problems[2]


def test_a_sweep_on_a_truncated_study_is_refused_by_validate(tmp_path):
    from fracas.modes import check_path

    team = _truncated(tmp_path)
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(
        f'mode = "sweep"\n[sweep]\nstudy = "{team.name}"\n[[sweep.vary]]\nfield = "tracking[0].sigma"\n'
        "values = [1.0, 2.0]\n",
        encoding="utf-8",
    )
    _, problems = check_path(sweep)
    assert any("filter.stop_days = 10" in p and "0-5 d" in p for p in problems), problems


@pytest.mark.parametrize("command", ["validate", "sweep"])
def test_a_sweep_that_varies_a_study_past_its_trajectory_is_refused_before_work(tmp_path, command):
    """A sweep whose varied ``filter.stop_days`` takes one study past the trajectory's end is
    refused by validate and by the run alike (exit 2, no table), naming the study."""
    team = _truncated(tmp_path)
    text = team.read_text(encoding="utf-8").replace("stop_days = 10.0\n[a_priori]", "stop_days = 4.0\n[a_priori]")
    team.write_text(text.replace("start_days = 0.0\nstop_days = 10.0", "start_days = 0.0\nstop_days = 4.0"))
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(
        f'mode = "sweep"\n[sweep]\nstudy = "{team.name}"\n[[sweep.vary]]\nfield = "filter.stop_days"\n'
        "values = [4.0, 10.0]\n",
        encoding="utf-8",
    )
    args = [command, str(sweep)] + (["--workers", "0"] if command == "sweep" else [])
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 2, res.output
    err = res.stderr
    assert "filter.stop_days = 10" in err and "0-5 d" in err, err
    assert "filter.stop_days = 4" not in err.replace("filter.stop_days = 4.0\n", "")
    assert not list(tmp_path.glob("*.h5"))


# ----------------------------------------------------------------------------- 1e: implausible states
def _leo(tmp_path: Path, r: str, v: str, name: str = "leo.toml") -> Path:
    deck = tmp_path / name
    deck.write_text(
        '[epoch]\niso = "2030-01-01T00:00:00"\n[initial_state]\ncentre = "earth"\n'
        f"[initial_state.cartesian]\nr_km = {r}\nv_km_s = {v}\n[spacecraft]\nmass_kg = 1000.0\n"
        "[stop]\nduration_days = 0.01\n",
        encoding="utf-8",
    )
    return deck


def test_m_per_s_in_a_km_s_field_is_warned_about_by_validate_and_run(tmp_path):
    deck = _leo(tmp_path, "[7000.0, 0.0, 0.0]", "[0.0, 7500.0, 1000.0]")
    res = CliRunner().invoke(main, ["validate", str(deck)])
    assert res.exit_code == 0 and res.stdout.startswith("ok: ")
    (line,) = res.stderr.splitlines()
    assert line.startswith(f"fracas: warning: {deck}: initial_state.cartesian.v_km_s = [0.0, 7500.0, 1000.0]: ")
    assert "escape speed" in line and "likely m/s" in line
    plausible.reset()
    res = CliRunner().invoke(main, ["run", str(deck), "-o", str(tmp_path / "t.h5"), "--quiet"])
    assert res.exit_code == 0, res.output
    assert [ln for ln in res.stderr.splitlines() if "warning" in ln] == [line]


def test_metres_in_a_km_field_are_warned_about(tmp_path):
    deck = _leo(tmp_path, "[7000000.0, 0.0, 0.0]", "[0.0, 7.5, 1.0]")
    res = CliRunner().invoke(main, ["validate", str(deck)])
    assert res.exit_code == 0
    (line,) = res.stderr.splitlines()
    assert line.startswith(f"fracas: warning: {deck}: initial_state.cartesian.r_km = ")
    assert "sphere of influence" in line and "likely m " in line


@pytest.mark.parametrize(
    "centre,table,field",
    [
        ("moon", {"cartesian": {"r_km": [1.838e6, 0.0, 0.0], "v_km_s": [0.0, 1.6, 0.0]}}, "r_km"),  # LLO in m
        ("sun", {"cartesian": {"r_km": [1.496e11, 0.0, 0.0], "v_km_s": [0.0, 29.8, 0.0]}}, "r_km"),  # 1 AU in m
        ("mars", {"elements": {"a_km": 3.8e6, "e": 0.0, "i_deg": 0.0, "true_anomaly_deg": 0.0}}, "a_km"),
        (
            "earth",
            {
                "spherical": {
                    "r_km": 7000.0,
                    "lat_deg": 0.0,
                    "lon_deg": 0.0,
                    "v_km_s": 7500.0,
                    "gamma_deg": 0.0,
                    "sigma_deg": 90.0,
                }
            },
            "v_km_s",
        ),
    ],
)
def test_each_form_of_state_is_checked(centre, table, field):
    data = _set(LEO, "initial_state", {"centre": centre, **table})
    data.pop("forces", None)
    deck = validate_sourced(data, SRC, TrajectoryDeck)
    (line,) = plausible.state_warnings(deck)
    assert f".{field} = " in line and "likely" in line, line


def test_physical_states_are_not_warned_about():
    """Hyperbolic flybys and states out to a few spheres of influence are physical."""
    flyby = {"centre": "earth", "cartesian": {"r_km": [5e5, 0.0, 0.0], "v_km_s": [-30.0, 5.0, 0.0]}}
    l2 = {"centre": "earth", "cartesian": {"r_km": [1.5e6, 0.0, 0.0], "v_km_s": [0.0, 0.3, 0.0]}}
    voyager = {"centre": "sun", "cartesian": {"r_km": [165 * 1.496e8, 0.0, 0.0], "v_km_s": [17.0, 0.0, 0.0]}}
    escape = {"centre": "moon", "cartesian": {"r_km": [2000.0, 0.0, 0.0], "v_km_s": [0.0, 10.0, 0.0]}}
    for st in (flyby, l2, voyager, escape):
        data = _set(LEO, "initial_state", st)
        data.pop("forces", None)
        assert plausible.state_warnings(validate_sourced(data, SRC, TrajectoryDeck)) == [], st


def test_warnings_are_silent_in_worker_processes(capsys, monkeypatch):
    import multiprocessing

    monkeypatch.setattr(multiprocessing, "parent_process", lambda: object())
    plausible.warn(["x.toml: a line"])
    assert capsys.readouterr().err == ""
    monkeypatch.undo()
    plausible.warn(["x.toml: a line", "x.toml: a line"])
    assert capsys.readouterr().err == "fracas: warning: x.toml: a line\n"


def test_every_bundled_deck_validates_clean_without_warnings(capsys):
    from fracas.modes import check_path

    for deck in sorted(NAMELISTS.glob("*.toml")):
        kind, problems = check_path(deck)
        assert kind is not None and problems == [], (deck, problems)
    assert "warning" not in capsys.readouterr().err


# ----------------------------------------------------------------------------- output paths, wording
def test_validate_refuses_a_sweep_plot_that_the_run_refuses(tmp_path):
    from fracas.modes import check_path

    text = (NAMELISTS / "earth_mars_sweep.toml").read_text(encoding="utf-8")
    text = text.replace('study = "earth_mars_team.toml"', f'study = "{NAMELISTS / "earth_mars_team.toml"}"')
    text = re.sub(r"(?m)^table = .*$", 'table = "sweep.h5"', text)
    deck = tmp_path / "sweep.toml"
    deck.write_text(re.sub(r"(?m)^plot = .*$", 'plot = "."', text), encoding="utf-8")
    _, problems = check_path(deck)
    assert len(problems) == 1 and problems[0].startswith(f'{deck}: output.plot = ".": is a directory'), problems


def test_tsim_deck_outputs_are_checked_by_validate(tmp_path):
    from fracas.modes import check_path

    deck = _tsim_deck(tmp_path, 2000)
    (tmp_path / "folder").mkdir()
    text = deck.read_text(encoding="utf-8").replace("[output]", '[output]\nresults = "folder"')
    deck.write_text(text, encoding="utf-8")
    _, problems = check_path(deck)
    assert len(problems) == 1 and problems[0].startswith(f'{deck}: output.results = "folder": is a directory')


def _sealed(tmp_path: Path, kind: str = "fracas-trajectory") -> Path:
    from fracas.io.hdf5 import atomic_h5

    path = tmp_path / "f.h5"
    with atomic_h5(path) as f:
        f.attrs["file_kind"] = kind
        f.create_dataset("x", data=[1.0, 2.0])
    return path


def test_a_later_integrity_header_is_written_by_a_newer_fracas(tmp_path):
    from fracas.errors import ResultsFileError
    from fracas.io.hdf5 import verify_file

    path = _sealed(tmp_path)
    raw = bytearray(path.read_bytes())
    raw[: len(b"fracas-hdf5-integrity 1")] = b"fracas-hdf5-integrity 2"
    path.write_bytes(bytes(raw))
    with pytest.raises(ResultsFileError) as info:
        verify_file(path)
    msg = str(info.value)
    assert "written by a newer fracas" in msg and "garbled" not in msg and "damaged" not in msg


def test_a_forged_header_kind_is_not_believed(tmp_path):
    from fracas.errors import ResultsFileError
    from fracas.io.hdf5 import read_kind
    from fracas.io.hdf5_integrity import seal

    path = _sealed(tmp_path)
    assert read_kind(path) == "fracas-trajectory"
    seal(path, "fracas-punch")  # a header rewritten to claim another kind, its checksums made consistent
    with pytest.raises(ResultsFileError) as info:
        read_kind(path)
    assert "integrity header says kind 'fracas-punch' but the file itself says 'fracas-trajectory'" in str(info.value)
    res = CliRunner().invoke(main, ["report", str(path)])
    assert res.exit_code == 2 and "punch file" not in res.stderr.replace("'fracas-punch'", "")
