"""Sweeps (fracas.modes.sweep): the deck schema, vary(), in-process and Dask runs, resume, failures."""

from __future__ import annotations

import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from fracas.config.sweep import SweepDeck, parse_sweep_deck
from fracas.config.team import load_team_deck
from fracas.errors import DeckError
from fracas.io.sweep_table import csv_path, read_sweep_table, write_sweep_table
from fracas.modes import parse_any
from fracas.modes import stm as stm_mode
from fracas.modes import team as team_mode
from fracas.modes.sweep.run import base_hash, parse_vary, run_sweep, sweep_main, vary

DATA = Path(__file__).parent / "data"
FIELD = "thrust_noise.proportionality.sigma"
VALUES = [0.005, 0.01, 0.02, 0.04]
OUTPUTS = ["position_rss_km", "velocity_rss_km_s", "sigma[thrust_scale]", "true_position_rss_km"]


def sweep_text(values, table="sweep.h5", extra="", study="team_small.toml"):
    return f"""mode = "sweep"
title = "proportionality sweep"
[sweep]
study = "{study}"
outputs = {OUTPUTS!r}
{extra}
[[sweep.vary]]
field = "{FIELD}"
values = {values!r}
[output]
table = "{table}"
"""


@pytest.fixture(scope="module")
def study_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("sweep")
    for name in ("team_small.toml", "team_small_traj.toml"):
        shutil.copy(DATA / name, d / name)
    return d


def test_the_studies_run_the_exact_model():
    """These sweeps batch the default exact Gauss-Markov model (issue 24: the noise states
    with Gamma and E shared by the group, Q = sum_i sigma_i^2 Q_i per study), so the
    batched-vs-run_team comparisons below check it; a group needs one set of tau."""
    from fracas.team.batch import structure_mismatch

    base = load_team_deck(DATA / "team_small.toml")
    a = stm_mode.load_team(base).study
    assert a.noise_model == "exact" and a.has_noise
    b = stm_mode.load_team(vary(base, "thrust_noise.in_plane_deg.tau_days", 3.0)).study
    assert structure_mismatch(a, b) == "noise correlation times"
    c = stm_mode.load_team(vary(base, FIELD, 0.03)).study
    assert structure_mismatch(a, c) is None


def make_deck(d: Path, values, table="sweep.h5", name="sweep.toml", extra="", study="team_small.toml") -> SweepDeck:
    p = d / name
    p.write_text(sweep_text(values, table, extra, study))
    return parse_sweep_deck(p.read_text(), str(p))


@pytest.fixture(scope="module")
def serial(study_dir):
    """The 4-study sweep in this process (workers=0), timed."""
    cfg = make_deck(study_dir, VALUES, table="serial.h5", name="serial.toml")
    t0 = time.perf_counter()
    res = run_sweep(cfg, workers=0)
    return cfg, res, time.perf_counter() - t0


# ----------------------------------------------------------------------------- schema
@pytest.mark.parametrize(
    "vary_table, needle",
    [
        (
            'field = "thrust_noise.proportionality.sgma"\nvalues = [1.0]',
            "unknown field thrust_noise.proportionality.sgma",
        ),
        ('field = "tracking.sigma"\nvalues = [1.0]', "give an index"),
        ('field = "no_such_section"\nvalues = [1.0]', "unknown field no_such_section"),
        ('field = "thrust_noise"\nvalues = [1.0]', "is a table"),
        ('field = "a..b"\nvalues = [1.0]', "malformed field path"),
        (f'field = "{FIELD}"\nvalues = []', "values"),
        (f'field = "{FIELD}"', "give values, or start + stop + num"),
        (f'field = "{FIELD}"\nvalues = [1.0]\nstart = 1.0', "not both"),
        (f'field = "{FIELD}"\nstart = 0.0\nstop = 1.0\nnum = 3\nspacing = "log"', "must be > 0"),
        (f'field = "{FIELD}"\nstart = 0.0\nstop = 1.0\nnum = 0', "num"),
        (f'field = "{FIELD}"\nvalues = [[1.0]]', "values"),
    ],
)
def test_schema_refusals(vary_table, needle):
    text = f'mode = "sweep"\n[sweep]\nstudy = "x.toml"\n[[sweep.vary]]\n{vary_table}\n'
    with pytest.raises(DeckError) as exc:
        parse_sweep_deck(text, "s.toml")
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith("s.toml: ") and needle in msg, msg


def test_schema_outputs_combine_and_modes():
    base = 'mode = "sweep"\n[sweep]\nstudy = "x.toml"\n'
    two = (
        '[[sweep.vary]]\nfield = "filter.stop_days"\nvalues = [3.0, 4.0]\n'
        '[[sweep.vary]]\nfield = "tracking[0].sigma"\nstart = 0.5\nstop = 2.0\nnum = 3\n'
    )
    with pytest.raises(DeckError, match="zip needs the same number of values"):
        parse_sweep_deck(base + 'combine = "zip"\n' + two, "s.toml")
    with pytest.raises(DeckError, match="unknown output 'rss'"):
        parse_sweep_deck(base + 'outputs = ["rss"]\n' + two, "s.toml")
    with pytest.raises(DeckError, match="gives 6 studies"):
        parse_sweep_deck(base + "max_studies = 5\n" + two, "s.toml")
    cfg = parse_any(base + two, "s.toml")
    assert isinstance(cfg, SweepDeck)
    assert cfg.studies() == [(a, b) for a in (3.0, 4.0) for b in (0.5, 1.25, 2.0)]
    assert parse_vary("a.b=log:1e-3:1e-1:3") == {"field": "a.b", "start": 1e-3, "stop": 0.1, "num": 3, "spacing": "log"}
    assert parse_vary("a.b=1,2.5,true") == {"field": "a.b", "values": [1, 2.5, True]}
    with pytest.raises(DeckError, match="expected FIELD=VALUES"):
        parse_vary("a.b")


def test_vary_refuses_bad_values_and_missing_entries(study_dir):
    base = load_team_deck(study_dir / "team_small.toml")
    with pytest.raises(DeckError, match=r"thrust_noise.proportionality.sigma = 2.0: must be <= 1"):
        vary(base, FIELD, 2.0)
    with pytest.raises(DeckError, match=r"index \[7\] is out of range"):
        vary(base, "tracking[7].sigma", 1.0)
    cfg = make_deck(study_dir, [1.0], name="bad_index.toml").model_dump(mode="python", exclude_unset=True)
    cfg["sweep"]["vary"][0]["field"] = "tracking[9].sigma"
    deck = SweepDeck.model_validate(cfg)
    deck._source_path = str(study_dir / "bad_index.toml")
    with pytest.raises(DeckError, match=r"sweep.vary\[0\].field = 'tracking\[9\].sigma': not in the study"):
        run_sweep(deck, workers=0)


# ----------------------------------------------------------------------------- vary
@pytest.mark.slow  # ~36 s of a cold make test (mostly XLA compilation; issue 22)
def test_vary_equals_the_deck_edited_by_hand(study_dir, tmp_path):
    base = load_team_deck(study_dir / "team_small.toml")
    v = vary(base, "tracking[1].sigma", 1.5)
    assert v.tracking[1].sigma == 1.5 and base.tracking[1].sigma == 1.0
    assert v.source_path == base.source_path and v.source_text == base.source_text
    text = (study_dir / "team_small.toml").read_text()
    marker = 'stations = ["madrid"]\nstart_days = 0.0\nstop_days = 3.0\ninterval_hours = 4.0\nsigma = 1.0'
    assert text.count(marker) == 1
    edited = tmp_path / "team_small.toml"
    edited.write_text(text.replace(marker, marker[: -len("1.0")] + "1.5"))
    shutil.copy(study_dir / "team_small_traj.toml", tmp_path / "team_small_traj.toml")
    hand = load_team_deck(edited)
    assert hand.model_dump() == v.model_dump()
    pa, _, _ = team_mode.run_team(v, output=tmp_path / "a.h5")
    pb, _, _ = team_mode.run_team(hand, output=tmp_path / "b.h5")
    for name in ("P_plus", "P_minus", "sigma"):
        assert np.array_equal(getattr(pa.assumed, name), getattr(pb.assumed, name))
        assert np.array_equal(getattr(pa.true, name), getattr(pb.true, name))


# ----------------------------------------------------------------------------- running
RTOL = 1e-12  # batched (vmapped scan) vs team_mode.run_team one by one: measured <= 2e-15 on these outputs


def _numbers(rows):
    return [(r["index"], r["key"], r[FIELD], *(r[o] for o in OUTPUTS), r["status"]) for r in rows]


@pytest.fixture(scope="module")
def one_by_one(study_dir):
    """The same 4 studies through the batched path with batch size 1 (the reference for bit-identity)."""
    cfg = make_deck(study_dir, VALUES, table="one_by_one.h5", name="one_by_one.toml")
    return run_sweep(cfg, workers=0, max_batch=1)


def _expected(base, value, tmp_path):
    product, _, _ = team_mode.run_team(vary(base, FIELD, value), output=tmp_path / "one.h5")
    s, st = product.assumed.sigma[-1], product.true.sigma[-1]
    return {
        "position_rss_km": float(np.sqrt(np.sum(s[:3] ** 2))),
        "velocity_rss_km_s": float(np.sqrt(np.sum(s[3:6] ** 2))),
        "sigma[thrust_scale]": float(s[product.labels.index("thrust_scale")]),
        "true_position_rss_km": float(np.sqrt(np.sum(st[:3] ** 2))),
    }


@pytest.mark.slow  # ~90 s of a cold make test (four single-study sweeps compiled and run; issue 22)
@pytest.mark.slow  # shares the in-process sweep fixture with the resume test (issue 24)
def test_serial_sweep_equals_the_studies_run_one_by_one(serial, one_by_one, study_dir, tmp_path):
    cfg, res, _ = serial
    assert [r["status"] for r in res.rows] == ["ok"] * 4 and res.ran == [0, 1, 2, 3]
    assert _numbers(res.rows) == _numbers(one_by_one.rows)  # one batch of 4 == 4 batches of 1, bit for bit
    base = load_team_deck(study_dir / "team_small.toml")
    worst = 0.0
    for r, value in zip(res.rows, VALUES):
        for name, want in _expected(base, value, tmp_path).items():
            worst = max(worst, abs(r[name] - want) / abs(want))
            assert r[name] == pytest.approx(want, rel=RTOL, abs=0.0), name
    print(f"\nbatched vs run_team one by one: max relative difference {worst:.1e}")
    t = read_sweep_table(res.table)
    assert _numbers(t.rows()) == _numbers(res.rows)
    assert t.units[FIELD] == "1" and t.units["position_rss_km"] == "km" and t.units["velocity_rss_km_s"] == "km/s"
    head = csv_path(res.table).read_text().splitlines()[0]
    assert head.startswith("index,key,thrust_noise.proportionality.sigma [1],position_rss_km [km]")


@pytest.mark.slow  # ~43 s of a cold make test (issue 22)
def test_unbatched_sweep_is_run_team_exactly(study_dir, tmp_path):
    cfg = make_deck(study_dir, VALUES[:2], table="unbatched.h5", name="unbatched.toml")
    res = run_sweep(cfg, workers=0, batch=False)
    base = load_team_deck(study_dir / "team_small.toml")
    for r, value in zip(res.rows, VALUES):
        assert {k: r[k] for k in OUTPUTS} == _expected(base, value, tmp_path)


def test_numeric_and_structural_fields():
    from fracas.config.sweep import is_numeric_field

    for f in (
        FIELD,
        "thrust_noise.in_plane_deg.tau_days",
        "tracking[2].sigma",
        "parameter[0].sigma",
        "a_priori.position_sigma_km[1]",
        "gencov.measurement_sigma.doppler2",
        "gencov.thrust_noise.proportionality.sigma",
        "gencov.parameter[0].sigma",
    ):
        assert is_numeric_field(f), f
    for f in (
        "tracking[0].interval_hours",
        "tracking[0].stop_days",
        "filter.stop_days",
        "filter.type",
        "parameter[0].label",
        "parameter[0].role",
        "event[0].times_days",
        "errcon.process_noise",
        "a_priori.from_punch",
        "min_elevation_deg",
    ):
        assert not is_numeric_field(f), f


@pytest.mark.slow  # ~47 s of a cold make test (issue 22)
def test_mixed_sweep_batches_each_schedule(study_dir, tmp_path, monkeypatch):
    """filter.stop_days (structural) x the noise sigma (numeric): two batched groups, each one
    batched call; the numbers equal run_team one by one."""
    from fracas.team import batch

    calls = []
    real = batch.final_covariances
    monkeypatch.setattr(
        batch, "final_covariances", lambda setup, st, **kw: calls.append(len(st)) or real(setup, st, **kw)
    )
    extra = '[[sweep.vary]]\nfield = "filter.stop_days"\nvalues = [3.5, 4.0]\n'
    p = study_dir / "mixed.toml"
    p.write_text(sweep_text(VALUES[:3], "mixed.h5").replace("[output]", extra + "[output]"))
    cfg = parse_sweep_deck(p.read_text(), str(p))
    res = run_sweep(cfg, workers=0)
    assert calls == [3, 3] and [r["status"] for r in res.rows] == ["ok"] * 6
    base = load_team_deck(study_dir / "team_small.toml")
    for r in res.rows:
        deck = vary(vary(base, FIELD, r[FIELD]), "filter.stop_days", r["filter.stop_days"])
        product, _, _ = team_mode.run_team(deck, output=tmp_path / "m.h5")
        s = product.assumed.sigma[-1]
        assert r["position_rss_km"] == pytest.approx(float(np.sqrt(np.sum(s[:3] ** 2))), rel=RTOL, abs=0.0)


PREDICTION = '[[event]]\ntype = "prediction"\ntimes_days = [3.0]\npredict_to_days = 5.0\n'
LEAN = 'stm_file = "lean_stm.h5"'


@pytest.fixture(scope="module")
def lean(study_dir):
    """The studies of the tests that start fresh processes (worker processes, a killed run):
    team_small without its prediction event, over an STM file built once, so that a fresh
    process traces little (no in-line reference, no prediction integration); and these
    studies through the batched path one at a time (batch size 1, in process)."""
    text = (study_dir / "team_small.toml").read_text()
    assert text.count(PREDICTION) == 1
    (study_dir / "team_lean.toml").write_text(text.replace(PREDICTION, ""))
    stm_mode.build_stm(load_team_deck(study_dir / "team_lean.toml"), study_dir / "lean_stm.h5")
    cfg = make_deck(study_dir, VALUES, "lean_one_by_one.h5", "lean_one_by_one.toml", LEAN, "team_lean.toml")
    return run_sweep(cfg, workers=0, max_batch=1)


@pytest.mark.slow
def test_local_cluster_gives_the_same_numbers(lean, study_dir):
    """Two worker processes (a batched chunk each) give bit-identical numbers to the same
    studies run one by one (batch size 1, in process); and run_team's over the STM file."""
    cfg2 = make_deck(study_dir, VALUES, "cluster.h5", "cluster.toml", LEAN, "team_lean.toml")
    seen = []
    t0 = time.perf_counter()
    res = run_sweep(cfg2, workers=2, progress=lambda done, total: seen.append((done, total)))
    wall = time.perf_counter() - t0
    assert seen[-1] == (4, 4) and len(seen) == 4
    assert _numbers(res.rows) == _numbers(lean.rows)
    print(f"\n2 workers: {len(res.rows)} studies in {wall:.1f} s (cluster start included)")
    deck = vary(load_team_deck(study_dir / "team_lean.toml"), FIELD, VALUES[0])
    product, _, _ = team_mode.run_team(deck, stm=str(study_dir / "lean_stm.h5"), write_results=False)
    s = product.assumed.sigma[-1]
    assert res.rows[0]["position_rss_km"] == pytest.approx(float(np.sqrt(np.sum(s[:3] ** 2))), rel=RTOL, abs=0.0)


_KILLED = """
import os, sys
from fracas.config.sweep import load_sweep_deck
from fracas.modes.sweep.run import run_sweep
def die(done, total):
    if done == 2:
        os._exit(3)   # killed mid-run, after two studies are in the table
run_sweep(load_sweep_deck(sys.argv[1]), workers=0, max_batch=1, progress=die)
"""


@pytest.mark.slow  # ~30 s of a cold make test (mostly XLA compilation; issue 22)
def test_killed_sweep_restarts_without_redoing_finished_studies(lean, study_dir, monkeypatch):
    import subprocess
    import sys

    from fracas.team import batch

    cfg = make_deck(study_dir, VALUES, "killed.h5", "killed.toml", LEAN, "team_lean.toml")
    root = Path(__file__).resolve().parents[1]
    r = subprocess.run([sys.executable, "-c", _KILLED, str(study_dir / "killed.toml")], cwd=root, timeout=300)
    assert r.returncode == 3
    table = cfg.resolve(cfg.output.table)
    assert [row["index"] for row in read_sweep_table(table).rows()] == [0, 1]
    calls = []
    real = batch.final_covariances
    monkeypatch.setattr(
        batch, "final_covariances", lambda setup, st, **kw: calls.append(len(st)) or real(setup, st, **kw)
    )
    res = run_sweep(cfg, workers=0)
    assert res.skipped == [0, 1] and res.ran == [2, 3] and calls == [2]
    assert _numbers(read_sweep_table(table).rows()) == _numbers(lean.rows)


@pytest.mark.slow  # its module fixture (the in-process sweep): ~76 s of a cold make test (issue 24)
def test_resume_runs_only_the_missing_studies(serial, study_dir, monkeypatch):
    cfg, res0, _ = serial
    half = make_deck(study_dir, VALUES, table="resume.h5", name="resume.toml")
    table = half.resolve(half.output.table)
    rows = [dict(r) for r in res0.rows if r["index"] in (1, 3)]
    units = read_sweep_table(res0.table).units
    bh = base_hash(load_team_deck(study_dir / "team_small.toml"))  # the table is this study's
    write_sweep_table(table, rows, [FIELD], OUTPUTS, units, {"title": "partial", "base_hash": bh})
    calls = []
    real = team_mode.run_team
    monkeypatch.setattr(team_mode, "run_team", lambda cfg, **kw: calls.append(1) or real(cfg, **kw))
    res = run_sweep(half, workers=0, batch=False)
    assert len(calls) == 2 and res.ran == [0, 2] and res.skipped == [1, 3]
    got = read_sweep_table(table).rows()
    assert _numbers([got[1], got[3]]) == _numbers([res0.rows[1], res0.rows[3]])
    calls.clear()
    run_sweep(half, workers=0)  # everything is in the table now
    assert calls == []


def test_a_failed_study_is_recorded_and_the_others_complete(study_dir, monkeypatch):
    """A study that fails while it runs (here a NumericalError from its TEAM run; values the
    schema refuses never get this far) is a failed row with its one-line error and NaN
    outputs; the others complete."""
    from fracas.errors import NumericalError

    real = team_mode.run_team

    def flaky(cfg, **kw):
        if cfg.thrust_noise.proportionality.sigma == 0.03:
            raise NumericalError("team: the covariance lost positive-definiteness at t = 1.5 d")
        return real(cfg, **kw)

    monkeypatch.setattr(team_mode, "run_team", flaky)
    cfg = make_deck(study_dir, [0.01, 0.03, 0.02], table="fail.h5", name="fail.toml")
    res = run_sweep(cfg, workers=0, batch=False)
    assert [r["status"] for r in res.rows] == ["ok", "failed", "ok"]
    bad = res.rows[1]
    assert "lost positive-definiteness" in bad["error"] and "\n" not in bad["error"]
    assert all(np.isnan(bad[o]) for o in OUTPUTS)
    t = read_sweep_table(res.table)
    assert t.status == ["ok", "failed", "ok"] and t.error[1] == bad["error"]


def test_sweep_main_on_a_team_deck_with_vary(study_dir, tmp_path):
    """A TEAM deck swept with --vary: a value the TEAM schema refuses (2.0 > 1) is refused
    before any study runs, naming the study (index and value) and the field; no table."""
    out = tmp_path / "cli" / "table.h5"
    t0 = time.perf_counter()
    with pytest.raises(DeckError) as exc:
        sweep_main(study_dir / "team_small.toml", [f"{FIELD}=0.01,2.0"], workers=0, scheduler=None, out=out)
    assert time.perf_counter() - t0 < 5.0
    msg = str(exc.value)
    assert "\n" not in msg and f"study 1 ({FIELD} = 2.0): {FIELD} = 2.0: must be <= 1" in msg, msg
    assert not out.exists()


def test_plot_of_two_fields(study_dir, tmp_path):
    from fracas.report.sweep import plot_sweep

    rows = [
        {"index": i, "key": f"k{i}", "a": a, "b": b, "y": a * b, "status": "ok", "error": "", "wall_s": 0.1}
        for i, (a, b) in enumerate((a, b) for a in (1.0, 2.0, 3.0) for b in (0.1, 0.2))
    ]
    table = write_sweep_table(tmp_path / "t.h5", rows, ["a", "b"], ["y"], {"a": "d", "b": "h", "y": "km"}, {})
    png = plot_sweep(table, tmp_path / "t.png")
    assert png.stat().st_size > 1000


def test_sweep_command_in_process(tmp_path):
    """``fracas sweep TEAM_DECK --vary F=V --workers 0``: exit 0, the summary line, a table
    whose rows equal the values asked for, in order."""
    from click.testing import CliRunner

    from fracas.cli import main
    from fracas.io.sweep_table import read_sweep_table

    out = tmp_path / "cli_sweep.h5"
    small = Path(__file__).resolve().parent / "data" / "team_small.toml"
    r = CliRunner().invoke(
        main,
        [
            "sweep",
            str(small),
            "--vary",
            "thrust_noise.proportionality.sigma=0.01,0.02",
            "--workers",
            "0",
            "-o",
            str(out),
        ],
    )
    assert r.exit_code == 0, r.output
    assert "2 studies" in r.stdout and f"written: {out}" in r.stdout
    t = read_sweep_table(out)
    np.testing.assert_array_equal(t.inputs["thrust_noise.proportionality.sigma"], [0.01, 0.02])
    assert t.status == ["ok", "ok"]


# ----------------------------------------------------------------------------- numbers-only studies
def _same(a, b, path="study"):
    """Recursive equality of two studies: arrays bit for bit (dtype, shape, values)."""
    import dataclasses

    if hasattr(a, "shape") and hasattr(a, "dtype"):
        a, b = np.asarray(a), np.asarray(b)
        assert a.dtype == b.dtype and a.shape == b.shape, path
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), path
    elif dataclasses.is_dataclass(a) and not isinstance(a, type):
        assert type(a) is type(b), path
        for f in dataclasses.fields(a):
            _same(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            _same(a[k], b[k], f"{path}[{k!r}]")
    elif isinstance(a, (list, tuple)):
        assert type(a) is type(b) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{path}[{i}]")
    elif not callable(a):
        assert a == b, (path, a, b)


DERIVED = {
    "a_priori.position_sigma_km[1]": (100.0, 40.0),
    "a_priori.mass_sigma_kg": (0.5, 0.2),
    "parameter[0].sigma": (0.01, 0.03),
    "parameter[3].sigma": (0.001, 0.004),
    "thrust_noise.proportionality.sigma": (0.01, 0.02),
    "thrust_noise.in_plane_deg.tau_days": (2.0, 0.7),
    "tracking[0].sigma": (1.0, 0.6),
    "tracking[2].sigma": (2.0, 5.0),
    "gencov.measurement_sigma.doppler2": (2.0, 3.0),
    "gencov.parameter[0].sigma": (0.1, 0.25),
}


def test_derived_study_equals_build_case(study_dir):
    """A study derived from its group's first (fracas.build.vary.derive_study) equals the one
    build_case builds from its own deck, every field, arrays bit for bit."""
    from fracas.build.vary import derivable, derive_study
    from fracas.modes.sweep.run import study_deck

    base = load_team_deck(study_dir / "team_small.toml")
    fields = tuple(DERIVED)
    first = stm_mode.load_team(study_deck(base, fields, tuple(a for a, _ in DERIVED.values()))).study
    for k in range(len(fields) + 1):  # one field changed at a time, then all of them
        vals = tuple(b if (j == k or k == len(fields)) else a for j, (a, b) in enumerate(DERIVED.values()))
        deck = study_deck(base, fields, vals)
        assert derivable(first, deck)
        _same(derive_study(first, deck), stm_mode.load_team(deck).study)
    with pytest.raises(DeckError, match="must be <= 1"):
        study_deck(base, (FIELD,), (2.0,))  # the deck's own validation, as in a single run


# ----------------------------------------------------------------------------- guidance
GUIDANCE = """
[[guidance]]
name = "tcm1"
type = "impulsive"
time_days = 3.2
targets = ["x", "y", "z"]
"""
GUIDANCE_OUTPUTS = ["position_rss_km", "tcm1.dv_mean_m_s", "tcm1.dv_99_m_s", "tcm1.dv_rms_m_s", "tcm1.x_sigma_after"]


@pytest.mark.slow  # ~49 s of a cold make test (mostly XLA compilation; issue 22)
def test_guidance_sweep_equals_run_team_one_by_one(study_dir, tmp_path):
    """A study with a [[guidance]] event: its guidance outputs over a sweep of the thrust
    noise (one by one, in process) equal run_team's events; unknown names are one-line
    errors naming the field."""
    (study_dir / "team_guid.toml").write_text((study_dir / "team_small.toml").read_text() + GUIDANCE)
    text = sweep_text([0.005, 0.02], "guid.h5").replace("team_small.toml", "team_guid.toml")
    text = text.replace(f"outputs = {OUTPUTS!r}", f"outputs = {GUIDANCE_OUTPUTS!r}")
    p = study_dir / "guid_sweep.toml"
    p.write_text(text)
    res = run_sweep(parse_sweep_deck(text, str(p)), workers=0)
    assert [r["status"] for r in res.rows] == ["ok", "ok"], [r["error"] for r in res.rows]
    assert res.units["tcm1.dv_99_m_s"] == "m/s" and res.units["tcm1.x_sigma_after"] == "km"
    base = load_team_deck(study_dir / "team_guid.toml")
    for r in res.rows:
        product, _, _ = team_mode.run_team(vary(base, FIELD, r[FIELD]), write_results=False)
        (e,) = product.guidance
        assert r["tcm1.dv_mean_m_s"] == e.dv_mean_km_s * 1000.0 and r["tcm1.dv_99_m_s"] == e.dv_99_km_s * 1000.0
        assert r["tcm1.dv_rms_m_s"] == e.dv_rms_km_s * 1000.0 > 0
        assert r["tcm1.x_sigma_after"] == float(np.sqrt(e.target_cov_after[0, 0]))
        assert r["position_rss_km"] == float(np.sqrt(np.sum(product.assumed.sigma[-1][:3] ** 2)))
    for name, needle in (
        ("tcm2.dv_99_m_s", r"sweep.outputs\[0\] = 'tcm2.dv_99_m_s': the study .* has no guidance event 'tcm2'"),
        ("tcm1.b_dot_t_sigma_after", "guidance event 'tcm1' has no target 'b_dot_t'"),
        ("tcm1.propellant_sigma_kg", "only for low-thrust guidance"),
    ):
        bad = text.replace(f"outputs = {GUIDANCE_OUTPUTS!r}", f"outputs = [{name!r}]")
        with pytest.raises(DeckError, match=needle) as exc:
            run_sweep(parse_sweep_deck(bad, str(p)), workers=0)
        assert "\n" not in str(exc.value)
    for name, needle in (
        ("tcm1.dv_max", "unknown guidance output 'dv_max'"),
        ("tcm1.q_sigma_after", "unknown target 'q'"),
    ):
        with pytest.raises(DeckError, match=needle):
            parse_sweep_deck(text.replace(f"outputs = {GUIDANCE_OUTPUTS!r}", f"outputs = [{name!r}]"), str(p))


# ----------------------------------------------------------------------------- every study validated first
#: (vary tables, combine, the studies the TEAM schema refuses): values of every kind of
#: field a sweep can vary that TeamDeck's schema refuses (negative sigmas and times, a
#: fraction above 1, a filter type that does not exist), alone, in grids and in zips
BAD_SWEEPS = {
    "negative_proportionality": ([(FIELD, [0.01, -0.01, 0.02])], "grid", [1]),
    "proportionality_above_1": ([(FIELD, [2.0, 0.01])], "grid", [0]),
    "negative_tau": (["thrust_noise.proportionality.tau_days", [-1.0, 2.0]], "grid", [0]),
    "negative_tracking_sigma": ([("tracking[0].sigma", [1.0, -1.0])], "grid", [1]),
    "negative_mass_sigma": ([("a_priori.mass_sigma_kg", [0.5, -0.5])], "grid", [1]),
    "negative_parameter_sigma": ([("parameter[0].sigma", [-0.01])], "grid", [0]),
    "unknown_filter_type": ([("filter.type", ["kalman_schmidt", "nonsense"])], "grid", [1]),
    "grid_of_two": ([(FIELD, [0.01, -0.01]), ("tracking[0].sigma", [1.0, 2.0])], "grid", [2, 3]),
    "zip_of_two": ([(FIELD, [0.01, 0.02]), ("tracking[0].sigma", [1.0, -2.0])], "zip", [1]),
}
BAD_SWEEPS["negative_tau"] = ([("thrust_noise.proportionality.tau_days", [-1.0, 2.0])], "grid", [0])


def _bad_sweep(d: Path, case: str) -> Path:
    varies, combine, _ = BAD_SWEEPS[case]
    text = f'mode = "sweep"\n[sweep]\nstudy = "team_small.toml"\ncombine = "{combine}"\n'
    for field, values in varies:
        text += f'[[sweep.vary]]\nfield = "{field}"\nvalues = {values!r}\n'
    text += f'[output]\ntable = "{case}.h5"\n'
    path = d / f"{case}.toml"
    path.write_text(text)
    return path


@pytest.fixture
def no_work(monkeypatch):
    """Every way a sweep starts work (an STM build, a study run, a batched group, a
    reference, a Dask cluster) fails the test if it is called."""
    import fracas.cluster as cluster_mod
    import fracas.modes.sweep.run as sweep_mod

    def forbidden(*_a, **_k):
        raise AssertionError("a study was started before every study was validated")

    monkeypatch.setattr(team_mode, "run_team", forbidden)
    for name in ("build_stm", "load_team", "reference_from_stm"):
        monkeypatch.setattr(stm_mode, name, forbidden)
    for name in ("run_one", "run_group", "_run_tasks"):
        monkeypatch.setattr(sweep_mod, name, forbidden)
    for name in ("start", "start_cluster"):
        monkeypatch.setattr(cluster_mod, name, forbidden)


@pytest.mark.parametrize("case", sorted(BAD_SWEEPS))
def test_every_study_is_validated_before_any_work(case, study_dir, no_work):
    """Against TeamDeck's schema applied to each generated study: run_sweep, sweep_main and
    fracas validate refuse the sweep before any work (nothing is run or compiled: the runners
    fail if called; under 5 s, the 3 minutes of compilation this took before), with one line
    per refused study naming the sweep deck, the study's index and swept values, and the
    field; the table is not written."""
    from fracas.config.sweep import load_sweep_deck
    from fracas.modes import validate_path

    path = _bad_sweep(study_dir, case)
    varies, _, bad = BAD_SWEEPS[case]
    cfg = load_sweep_deck(path)
    t0 = time.perf_counter()
    with pytest.raises(DeckError) as exc:
        run_sweep(cfg, workers=0)
    assert time.perf_counter() - t0 < 5.0
    with pytest.raises(DeckError) as exc2:
        sweep_main(path, workers=0)
    assert str(exc2.value) == str(exc.value)
    problems = validate_path(path)
    assert problems == exc.value.problems
    studies = cfg.studies()
    assert len(problems) == len(bad)
    for line, i in zip(problems, bad):
        vals = ", ".join(f"{f} = {v!r}" for f, v in zip(cfg.fields, studies[i]))
        assert "\n" not in line and line.startswith(f"{path}: study {i} ({vals}): "), line
        assert any(line.split("): ", 1)[1].startswith(f) for f, _ in varies), line
    assert not (study_dir / f"{case}.h5").exists()


def test_many_refused_studies_are_counted(study_dir, no_work):
    """Against MAX_LISTED_STUDIES: a sweep whose 40 studies are all refused names the first
    five, then one line counting the others."""
    from fracas.config.sweep import MAX_LISTED_STUDIES, load_sweep_deck, sweep_problems

    path = study_dir / "many_bad.toml"
    path.write_text(
        f'mode = "sweep"\n[sweep]\nstudy = "team_small.toml"\n[[sweep.vary]]\nfield = "{FIELD}"\n'
        "start = -1.0\nstop = -0.1\nnum = 40\n"
    )
    cfg = load_sweep_deck(path)
    problems = sweep_problems(cfg, load_team_deck(study_dir / "team_small.toml"))
    assert len(problems) == MAX_LISTED_STUDIES + 1
    assert problems[-1] == f"{path}: and 35 more studies that the study's schema refuses"


@pytest.mark.parametrize("command", ["sweep", "run", "validate"])
def test_refused_sweep_on_the_command_line(command, study_dir, no_work):
    """fracas sweep / run / validate on a sweep deck with a refused study: exit 2, the
    study's one-line error on stderr, no traceback, before any work."""
    from click.testing import CliRunner

    from fracas.cli import main

    path = _bad_sweep(study_dir, "negative_proportionality")
    args = [command, str(path)] + (["--workers", "0"] if command == "sweep" else [])
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 2, r.output
    err = r.stderr.strip().splitlines()
    assert err and all(line.startswith("fracas: error: ") for line in err), r.stderr
    assert f"study 1 ({FIELD} = -0.01): {FIELD} = -0.01: must be >= 0" in err[0]
    assert "Traceback" not in r.output


def test_failed_studies_exit_non_zero_in_80_columns(study_dir, monkeypatch):
    """A sweep whose studies fail while running (a stand-in runner: nothing is compiled)
    writes its table, prints a summary whose every line fits 80 columns (long errors and
    paths wrapped between words, at most MAX_LISTED_FAILURES listed, then a count), says how many failed
    and exits with SWEEP_FAILED_EXIT (3), not 0."""
    from click.testing import CliRunner

    import fracas.modes.sweep.run as sweep_mod
    from fracas.cli import SWEEP_FAILED_EXIT, main

    long_error = f"{study_dir / 'team_small.toml'}: " + "the reference stopped early at t = 1.25 d " * 8

    def fake_one(base, index, fields, values, outputs, key, stm=None, results=None):
        row = {"index": index, "key": key, **dict(zip(fields, values)), **dict.fromkeys(outputs, float("nan"))}
        ok = index % 7 == 0
        row.update(status="ok" if ok else "failed", error="" if ok else long_error, units={}, wall_s=0.0)
        return row

    def fake_group(base, items, fields, outputs, gkey, stm=None, pad_to=1, max_batch=None):
        return [fake_one(base, i, fields, v, outputs, k) for i, v, k in items]

    monkeypatch.setattr(sweep_mod, "run_one", fake_one)
    monkeypatch.setattr(sweep_mod, "run_group", fake_group)
    out = study_dir / "wrapped" / "table.h5"
    r = CliRunner().invoke(
        main,
        ["sweep", str(study_dir / "team_small.toml"), "--vary", f"{FIELD}=0.001:0.01:14", "--workers", "0"]
        + ["-o", str(out)],
    )
    assert r.exit_code == SWEEP_FAILED_EXIT == 3, r.output
    lines = r.stdout.splitlines()
    assert all(len(line) <= 80 for line in lines), max(lines, key=len)
    assert "12 failed" in lines[0] and "and 2 more failed studies" in r.stdout
    assert r.stderr.strip() == "fracas: error: sweep: 12 studies failed"
    assert read_sweep_table(out).status.count("failed") == 12


# ----------------------------------------------------------------------------- resuming from a damaged table
def _fake_one(base, index, fields, values, outputs, key, stm=None, results=None):
    """A stand-in for a study's run (nothing compiled): outputs from the swept values."""
    x = float(values[0])
    row = {"index": index, "key": key, **dict(zip(fields, values))}
    row.update({o: x * (j + 1) for j, o in enumerate(outputs)})
    row.update(status="ok", error="", units=dict.fromkeys(outputs, "km"), wall_s=0.01)
    return row


def _fake_group(base, items, fields, outputs, gkey, stm=None, pad_to=1, max_batch=None):
    return [_fake_one(base, i, fields, v, outputs, k) for i, v, k in items]


@pytest.fixture
def resumable(study_dir, monkeypatch):
    """A sweep deck and its complete table (written by a stand-in runner), and the rows."""
    import fracas.modes.sweep.run as sweep_mod

    monkeypatch.setattr(sweep_mod, "run_one", _fake_one)
    monkeypatch.setattr(sweep_mod, "run_group", _fake_group)
    cfg = make_deck(study_dir, VALUES, table="resumable.h5", name="resumable.toml")
    res = run_sweep(cfg, workers=0, resume=False)
    assert [r["status"] for r in res.rows] == ["ok"] * 4
    return cfg, Path(res.table), read_sweep_table(res.table).rows()


def _edit_h5(path: Path, how) -> None:
    import h5py

    with h5py.File(path, "r+") as f:
        how(f)


def _rewrite(name: str, value):
    """Replace dataset ``name``'s data (its attributes, checksum included, kept)."""

    def how(f):
        ds = f[name]
        saved = dict(ds.attrs)
        data = ds.asstr()[()] if ds.dtype.kind == "O" else ds[()]
        new = value(data)
        del f[name]
        kw = {"dtype": ds.dtype} if ds.dtype.kind == "O" and not isinstance(new, np.ndarray) else {}
        nd = f.create_dataset(name, data=new, **kw)
        for k, v in saved.items():
            nd.attrs[k] = v

    return how


def _set_attr(key, value):
    def how(f):
        f.attrs[key] = value

    return how


DATASETS = ["index", "key", "status", "error", "wall_s", f"inputs/{FIELD}", *(f"outputs/{o}" for o in OUTPUTS)]


def _changed(data):
    """The same dataset with one value changed (a string edited, a number moved)."""
    if isinstance(data, np.ndarray) and data.dtype.kind in "fiu":
        out = data.copy()
        out[0] = out[0] * 3 + 1
        return out
    vals = [str(x) for x in np.atleast_1d(data)]
    vals[0] = "ok" if vals[0] != "ok" else "failed"
    return np.array(vals, dtype=object)


#: damage -> how: each dataset edited (checksum kept: the data no longer matches it),
#: deleted, cut short, made another dtype; the table's attributes (kind, base_hash, columns)
DAMAGE = {f"edited:{d}": _rewrite(d, _changed) for d in DATASETS}


def _delete(name: str):
    return lambda f: f.__delitem__(name)


DAMAGE.update({f"deleted:{d}": _delete(d) for d in DATASETS})
DAMAGE.update({f"short:{d}": _rewrite(d, lambda x: x[:-1]) for d in DATASETS})
DAMAGE.update(
    {
        "float_index": _rewrite("index", lambda x: x.astype(np.float64)),
        "text_output": _rewrite(f"outputs/{OUTPUTS[0]}", lambda x: np.array([str(v) for v in x], dtype=object)),
        "kind": _set_attr("kind", "fracas tsim results"),
        "base_hash_of_another_study": _set_attr("base_hash", "0" * 64),
        "input_columns": _set_attr("input_columns", np.array(["tracking[0].sigma"], dtype=object)),
        "output_columns": _set_attr("output_columns", np.array(OUTPUTS[:2], dtype=object)),
        "version_text": _set_attr("version", "one"),
    }
)


@pytest.mark.parametrize("damage", sorted(DAMAGE))
def test_resume_refuses_a_damaged_table(damage, resumable, no_work):
    """Against the table as written (every dataset's SHA-256 and the file's integrity header,
    fracas.io.hdf5): each dataset edited, deleted, cut short or of another dtype, and a
    table of another kind, study or columns, is refused on resume in one line naming the
    table, within 5 s and before any study runs (the runners fail if called) -- never
    resumed from silently (it was), never a TypeError/IndexError."""
    from fracas.errors import ResultsFileError

    cfg, table, _ = resumable
    _edit_h5(table, DAMAGE[damage])
    t0 = time.perf_counter()
    with pytest.raises(ResultsFileError) as exc:
        run_sweep(cfg, workers=0)
    assert time.perf_counter() - t0 < 5.0
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"{table}: "), msg


def test_resume_from_blocks_zeroed_or_bits_flipped(resumable, no_work, tmp_path):
    """Against the rows as written: a table with any 4 KiB block zeroed, or a bit flipped in
    any 512-byte stretch, is either refused in one ResultsFileError line within 5 s or read
    back with exactly the rows written (damage to bytes no value lives in); never other values."""
    import shutil

    from fracas.errors import ResultsFileError
    from fracas.modes.sweep.run import resume_table

    cfg, table, rows = resumable
    bh = base_hash(load_team_deck(cfg.resolve(cfg.sweep.study)))
    good = table.read_bytes()
    variants = []
    for off in range(0, len(good), 4096):
        variants.append(good[:off] + bytes(min(4096, len(good) - off)) + good[off + 4096 :])
    for off in range(0, len(good), 512):
        b = bytearray(good)
        b[off + 7 if off + 7 < len(b) else off] ^= 0x10
        variants.append(bytes(b))
    refused = 0
    for k, data in enumerate(variants):
        copy = tmp_path / f"damaged_{k}.h5"
        copy.write_bytes(data)
        t0 = time.perf_counter()
        try:
            got, _ = resume_table(copy, bh, cfg.fields, list(cfg.sweep.outputs))
        except ResultsFileError as exc:
            refused += 1
            assert "\n" not in str(exc) and str(exc).startswith(f"{copy}: ")
        else:
            assert [{k2: r[k2] for k2 in r if k2 != "wall_s"} for r in got] == [
                {k2: r[k2] for k2 in r if k2 != "wall_s"} for r in rows
            ], f"damaged copy {k} resumed with other values"
        assert time.perf_counter() - t0 < 5.0
    assert refused > 0
    shutil.copy(table, tmp_path / "intact.h5")
    assert resume_table(tmp_path / "intact.h5", bh, cfg.fields, list(cfg.sweep.outputs))[0] == rows


def test_resume_of_a_damaged_table_on_the_command_line(resumable, no_work):
    """fracas sweep on a sweep deck whose table was edited after it was written: exit 2, one
    line naming the table, no traceback, no study run; --no-resume starts over."""
    from click.testing import CliRunner

    from fracas.cli import main

    cfg, table, _ = resumable
    _edit_h5(table, DAMAGE[f"edited:outputs/{OUTPUTS[0]}"])
    r = CliRunner().invoke(main, ["sweep", str(cfg.source_path), "--workers", "0"])
    assert r.exit_code == 2 and "Traceback" not in r.output, r.output
    err = r.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"fracas: error: {table}: "), r.stderr
