"""TOM decks: bad input gets one line naming the file and the field, GRID runs as one batch
equal to single propagations, and failures end with a reason and the best iterate written.

References: the decks' own fields (the messages), single propagations of the plain core
(GRID's batch), the search's stop rules (failure paths)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fracas.build.tom import build_tom
from fracas.cli import main
from fracas.config.tom import parse_tom_deck
from fracas.errors import FracasError
from fracas.io.tom_results import read_tom_results
from fracas.modes import validate_path

ROOT = Path(__file__).resolve().parents[2]
LAMBERT = ROOT / "namelists" / "lambert_tom.toml"
HOHMANN = ROOT / "tests" / "data" / "hohmann_tom.toml"


@pytest.mark.parametrize(
    "old,new,expected",
    [
        ('name = "vx0"', 'name = "vq0"', 'control[0].name = "vq0": a control from the catalogue'),
        ('name = "x"\nvalue', 'name = "xx"\nvalue', 'target[0].name = "xx": a target from the catalogue'),
        ("tolerance = 1e-4", "tolerance = -1.0", "target[0].tolerance = -1.0: must be > 0"),
        ('submode = "target"', 'submode = "grid"', 'grid: a [grid] table (increments) for submode = "grid"'),
        ('[[control]]\nname = "vz0"', '[[control]]\nname = "vy0"', 'control[2].name = "vy0": already control 1'),
    ],
)
def test_bad_tom_deck_one_line_naming_the_field(tmp_path, old, new, expected):
    text = LAMBERT.read_text(encoding="utf-8")
    assert old in text
    bad = tmp_path / "bad_tom.toml"
    bad.write_text(text.replace(old, new, 1), encoding="utf-8")
    r = CliRunner().invoke(main, ["run", str(bad)])
    assert r.exit_code == 2, r.output
    assert "Traceback" not in r.output
    assert r.stderr.startswith(f"fracas: error: {bad}: "), r.stderr
    assert expected in r.stderr, r.stderr


def test_controls_and_bodies_checked_against_the_trajectory(tmp_path):
    """An arc that does not exist, final_time with an event stop, a target body outside the
    model: ``fracas validate`` lists each (without JAX) and the build refuses the first."""
    text = HOHMANN.read_text(encoding="utf-8")
    text = text.replace('name = "impulse_t[1]"', 'name = "arc_t_on[0]"')
    text = text.replace('name = "a"\nvalue = 42164.17', 'name = "a"\nbody = "mars"\nvalue = 42164.17')
    bad = tmp_path / "bad.toml"
    bad.write_text(text, encoding="utf-8")
    problems = validate_path(bad)
    assert any("control[4].name = 'arc_t_on[0]': control 'arc_t_on[0]': arc 0 does not exist" in p for p in problems)
    assert any("target[0].body = 'mars': not in the trajectory's model" in p for p in problems)
    with pytest.raises(FracasError, match=r"control\[4\]\.name"):
        build_tom(parse_tom_deck(text, str(bad)))


@pytest.mark.slow  # ~36 s of a cold make test (mostly XLA compilation; issue 22)
def test_grid_is_one_batch_equal_to_single_propagations(tmp_path):
    """GRID over the Hohmann deck's first two controls (single and paired increments): the
    batched trajectories' targets equal single propagations to 1e-9 of the tolerance, and E
    is Σ((T - T0)/ε)² of them."""
    text = HOHMANN.read_text(encoding="utf-8").replace('submode = "auto"', 'submode = "grid"')
    text += "\n[grid]\nincrements = [0.01, 0.01, 0.01, 0.01, 0.001]\nsteps = 2\npairs = true\n"
    cfg = parse_tom_deck(text, str(HOHMANN))
    case = build_tom(cfg)
    us = np.array([case.u0 + np.eye(5)[0] * g * 0.01 for g in (-2, -1, 0, 1, 2)])
    vals, mass, ok = case.problem.evaluate_batch(us)
    assert ok.all()
    for u, v, m in zip(us, vals, mass):
        ev = case.problem.evaluate(u)
        assert np.all(np.abs(ev.targets - v) <= 1e-9 * case.problem.targets.tolerance)
        assert abs(ev.performance - m) < 1e-9
    deck = tmp_path / "grid.toml"
    deck.write_text(text, encoding="utf-8")
    r = CliRunner().invoke(main, ["run", str(deck), "-o", str(tmp_path / "g.h5"), "--plot", str(tmp_path / "g.png")])
    assert r.exit_code == 0, r.output
    res = read_tom_results(tmp_path / "g.h5")
    grid = res["grid"]
    assert grid["single"].shape == (5, 5) and len(grid["pairs"]) == 10
    err = (vals - case.problem.targets.desired) / case.problem.targets.tolerance
    assert np.allclose(grid["single"][0], np.sum(err**2, axis=1), rtol=1e-9)
    assert (tmp_path / "g_grid.png").exists()


def test_unreachable_start_is_a_clear_nonzero_exit(tmp_path):
    """A start whose propagation fails (here: 3 steps allowed, status "max steps"): nothing
    usable, so a one-line error and a non-zero exit, and no results file."""
    text = LAMBERT.read_text(encoding="utf-8").replace(
        "[integrator]\ntolerance = 1e-13", "[integrator]\ntolerance = 1e-13\nmax_steps = 3"
    )
    deck = tmp_path / "fail.toml"
    deck.write_text(text, encoding="utf-8")
    r = CliRunner().invoke(main, ["run", str(deck), "-o", str(tmp_path / "f.h5")])
    assert r.exit_code != 0
    assert "the trajectory at the starting controls failed" in r.stderr and "Traceback" not in r.output
    assert not (tmp_path / "f.h5").exists()


def test_iteration_limit_writes_the_best_iterate_and_says_so(tmp_path, monkeypatch):
    """One iteration allowed from far away: not converged, the reason printed and stored, the
    results file and the reference deck written (exit 0: something usable was found)."""
    monkeypatch.chdir(tmp_path)
    text = LAMBERT.read_text(encoding="utf-8").replace('submode = "target"', 'submode = "target"\nmax_iterations = 1')
    deck = tmp_path / "one.toml"
    deck.write_text(text, encoding="utf-8")
    r = CliRunner().invoke(main, ["run", str(deck), "-o", str(tmp_path / "o.h5")])
    assert r.exit_code == 0, r.output
    assert "NOT CONVERGED" in r.stdout and "iteration limit (1) reached" in r.stdout
    res = read_tom_results(tmp_path / "o.h5")
    assert res["attrs"]["converged"] == 0 and "iteration limit" in res["attrs"]["stop_reason"]
    assert Path(res["attrs"]["reference_deck"]).exists()
    # every line of the terminal summary fits 80 columns (the layout, measured with the
    # temporary folder's path written short: pytest-xdist's paths alone are ~80 characters)
    assert max(len(line) for line in r.stdout.replace(str(tmp_path), "<tmp>").splitlines()) <= 80


def test_smag_given_sensitivities_are_used_at_the_first_iteration(tmp_path):
    """$SMAG: S and G given in the deck (deck units) replace the first iteration's
    sensitivities; the search then reaches the same answer (to the targets' 1e-4 km over the
    1 h flight: 1e-7 km/s) with one AD run fewer."""
    base = build_tom(parse_tom_deck(LAMBERT.read_text(encoding="utf-8"), str(LAMBERT)))
    _, s_fd, _ = base.problem.fegs(base.u0, steps=[1e-6] * 3, central=True)
    rows = ", ".join("[" + ", ".join(repr(float(x)) for x in row) + "]" for row in s_fd)
    text = LAMBERT.read_text(encoding="utf-8") + f"\n[smag]\ns = [{rows}]\ng = [0.0, 0.0, 0.0]\n"
    from fracas.modes.tom import run_tom

    plain, _, _ = run_tom(
        parse_tom_deck(LAMBERT.read_text(encoding="utf-8"), str(LAMBERT)),
        output=tmp_path / "a.h5",
        reference_deck=tmp_path / "a.toml",
    )
    given, _, _ = run_tom(
        parse_tom_deck(text, str(LAMBERT)), output=tmp_path / "b.h5", reference_deck=tmp_path / "b.toml"
    )
    assert given.converged
    assert np.abs(given.u_final - plain.u_final).max() < 1e-7
    assert given.timing["core_sensitivity_runs"] < plain.timing["core_sensitivity_runs"]
