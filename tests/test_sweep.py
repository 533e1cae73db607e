"""Sweeps (fracas.sweep): the deck schema, vary(), in-process and Dask runs, resume, failures."""

from __future__ import annotations

import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from fracas import pipeline
from fracas.config.modes import parse_any
from fracas.config.sweep import SweepDeck, parse_sweep_deck
from fracas.config.team import load_team_deck
from fracas.errors import DeckError
from fracas.io.sweep_table import csv_path, read_sweep_table, write_sweep_table
from fracas.sweep import parse_vary, run_sweep, sweep_main, vary

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
    pa, _, _ = pipeline.run_team(v, output=tmp_path / "a.h5")
    pb, _, _ = pipeline.run_team(hand, output=tmp_path / "b.h5")
    for name in ("P_plus", "P_minus", "sigma"):
        assert np.array_equal(getattr(pa.assumed, name), getattr(pb.assumed, name))
        assert np.array_equal(getattr(pa.true, name), getattr(pb.true, name))


# ----------------------------------------------------------------------------- running
RTOL = 1e-12  # batched (vmapped scan) vs pipeline.run_team one by one: measured <= 2e-15 on these outputs


def _numbers(rows):
    return [(r["index"], r["key"], r[FIELD], *(r[o] for o in OUTPUTS), r["status"]) for r in rows]


@pytest.fixture(scope="module")
def one_by_one(study_dir):
    """The same 4 studies through the batched path with batch size 1 (the reference for bit-identity)."""
    cfg = make_deck(study_dir, VALUES, table="one_by_one.h5", name="one_by_one.toml")
    return run_sweep(cfg, workers=0, max_batch=1)


def _expected(base, value, tmp_path):
    product, _, _ = pipeline.run_team(vary(base, FIELD, value), output=tmp_path / "one.h5")
    s, st = product.assumed.sigma[-1], product.true.sigma[-1]
    return {
        "position_rss_km": float(np.sqrt(np.sum(s[:3] ** 2))),
        "velocity_rss_km_s": float(np.sqrt(np.sum(s[3:6] ** 2))),
        "sigma[thrust_scale]": float(s[product.labels.index("thrust_scale")]),
        "true_position_rss_km": float(np.sqrt(np.sum(st[:3] ** 2))),
    }


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
        product, _, _ = pipeline.run_team(deck, output=tmp_path / "m.h5")
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
    pipeline.build_stm(load_team_deck(study_dir / "team_lean.toml"), study_dir / "lean_stm.h5")
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
    product, _, _ = pipeline.run_team(deck, stm=str(study_dir / "lean_stm.h5"), write_results=False)
    s = product.assumed.sigma[-1]
    assert res.rows[0]["position_rss_km"] == pytest.approx(float(np.sqrt(np.sum(s[:3] ** 2))), rel=RTOL, abs=0.0)


_KILLED = """
import os, sys
from fracas.config.sweep import load_sweep_deck
from fracas.sweep import run_sweep
def die(done, total):
    if done == 2:
        os._exit(3)   # killed mid-run, after two studies are in the table
run_sweep(load_sweep_deck(sys.argv[1]), workers=0, max_batch=1, progress=die)
"""


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


def test_resume_runs_only_the_missing_studies(serial, study_dir, monkeypatch):
    cfg, res0, _ = serial
    half = make_deck(study_dir, VALUES, table="resume.h5", name="resume.toml")
    table = half.resolve(half.output.table)
    rows = [dict(r) for r in res0.rows if r["index"] in (1, 3)]
    units = read_sweep_table(res0.table).units
    write_sweep_table(table, rows, [FIELD], OUTPUTS, units, {"title": "partial"})
    calls = []
    real = pipeline.run_team
    monkeypatch.setattr(pipeline, "run_team", lambda cfg, **kw: calls.append(1) or real(cfg, **kw))
    res = run_sweep(half, workers=0, batch=False)
    assert len(calls) == 2 and res.ran == [0, 2] and res.skipped == [1, 3]
    got = read_sweep_table(table).rows()
    assert _numbers([got[1], got[3]]) == _numbers([res0.rows[1], res0.rows[3]])
    calls.clear()
    run_sweep(half, workers=0)  # everything is in the table now
    assert calls == []


def test_a_failed_study_is_recorded_and_the_others_complete(study_dir):
    cfg = make_deck(study_dir, [0.01, 2.0, 0.02], table="fail.h5", name="fail.toml")
    res = run_sweep(cfg, workers=0)
    assert [r["status"] for r in res.rows] == ["ok", "failed", "ok"]
    bad = res.rows[1]
    assert "thrust_noise.proportionality.sigma = 2.0: must be <= 1" in bad["error"] and "\n" not in bad["error"]
    assert all(np.isnan(bad[o]) for o in OUTPUTS)
    t = read_sweep_table(res.table)
    assert t.status == ["ok", "failed", "ok"] and t.error[1] == bad["error"]


def test_sweep_main_on_a_team_deck_with_vary(study_dir, tmp_path):
    out = tmp_path / "cli" / "table.h5"
    path, text = sweep_main(
        study_dir / "team_small.toml", [f"{FIELD}=0.01,2.0"], workers=0, scheduler=None, resume=True, out=out
    )
    assert path == out and out.exists() and csv_path(out).exists()
    assert "2 studies" in text and "1 ok, 1 failed" in text and "must be <= 1" in text


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
    from fracas.sweep import study_deck

    base = load_team_deck(study_dir / "team_small.toml")
    fields = tuple(DERIVED)
    first = pipeline.load_team(study_deck(base, fields, tuple(a for a, _ in DERIVED.values()))).study
    for k in range(len(fields) + 1):  # one field changed at a time, then all of them
        vals = tuple(b if (j == k or k == len(fields)) else a for j, (a, b) in enumerate(DERIVED.values()))
        deck = study_deck(base, fields, vals)
        assert derivable(first, deck)
        _same(derive_study(first, deck), pipeline.load_team(deck).study)
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
        product, _, _ = pipeline.run_team(vary(base, FIELD, r[FIELD]), write_results=False)
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
