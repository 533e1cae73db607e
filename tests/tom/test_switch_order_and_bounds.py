"""Thrust arcs stay ordered, controls stay in their bounds, angles stay wrapped, and the odd
deck (no targets) runs: the six defects of issue 25, each against its own reference.

1. an arc inverted by the search (start after end) -> a reference deck fracas rejected:
   trial points are projected onto the switch order (reference: the Euclidean projection onto
   t_a <= t_b, in closed form: a violated pair meets at its mean), and a closed arc (start = end)
   is a valid deck;
2. overlapping arcs accepted by ``validate`` (reference: the deck's own numbers);
3. ``submode = "optimize"`` without targets ended in an internal ValueError (reference: the run
   writes its results file and exits 0);
4. a nominal outside the control's own bound accepted by ``validate`` (reference: the bound);
5. "203 iterations" printed after a limit of 200 (reference: the limit);
6. unbounded angles drifting to 1.68e6 degrees (reference: the wrapped angle is the same
   trajectory, within (-180, 180]).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from fracas.build.tom import _wrap_deg, build_tom, reference_deck_text
from fracas.cli import main
from fracas.config.tom import parse_tom_deck
from fracas.config.trajectory import parse_deck
from fracas.io.tom_results import read_tom_results
from fracas.modes import validate_path
from fracas.tom.search import Evaluation, Problem, SearchSettings, feasible_point, projected_gradient, wrap_periodic

ROOT = Path(__file__).resolve().parents[2]
SPIRAL = ROOT / "namelists" / "near_earth_spiral_tom.toml"
HOHMANN = ROOT / "tests" / "data" / "hohmann_tom.toml"
LAMBERT = ROOT / "namelists" / "lambert_tom.toml"


# ---------------------------------------------------------------- 1. the switch order
def test_trial_point_projected_onto_the_switch_order():
    """Two arcs, U = (t_on0, t_off0, t_on1, t_off1) with rows t_on0 - t_off0 <= 0,
    t_off0 - t_on1 <= 0, t_on1 - t_off1 <= 0.  An arc inverted and overlapping the next:
    x = (0, 10, 8, 20) -> the nearest ordered point pools t_off0 and t_on1 at their mean 9
    (pool-adjacent-violators); x = (5, 3, 8, 20) -> arc 0 closes at 4.  Bounds are kept."""
    A = np.array([[1.0, -1.0, 0.0, 0.0], [0.0, 1.0, -1.0, 0.0], [0.0, 0.0, 1.0, -1.0]])
    b = np.zeros(3)
    lo, hi = np.full(4, 0.0), np.full(4, 30.0)
    y = feasible_point(np.array([0.0, 10.0, 8.0, 20.0]), lo, hi, A, b)
    np.testing.assert_allclose(y, [0.0, 9.0, 9.0, 20.0], atol=1e-9)
    y = feasible_point(np.array([5.0, 3.0, 8.0, 20.0]), lo, hi, A, b)
    np.testing.assert_allclose(y, [4.0, 4.0, 8.0, 20.0], atol=1e-9)
    assert np.all(A @ y <= 1e-12)
    # already ordered: only clipped to the bounds
    np.testing.assert_array_equal(feasible_point(np.array([-1.0, 2.0, 3.0, 40.0]), lo, hi, A, b), [0, 2, 3, 30])


def test_switch_order_rows_from_the_deck_and_a_closed_arc_is_a_valid_deck():
    """The spiral deck's arc times as controls give the rows t_on0 <= t_off0 <= t_on1 <=
    t_off1 (reference: the deck's order); the reference deck of a closed arc (start = end)
    validates as a trajectory deck (before: stop_days must be > start_days)."""
    text = SPIRAL.read_text(encoding="utf-8")
    text = text.split("[[control]]")[0] + "".join(
        f'[[control]]\nname = "{n}"\n' for n in ("arc_t_on[0]", "arc_t_off[0]", "arc_t_on[1]", "arc_t_off[1]")
    )
    text += '[[target]]\nname = "a"\nvalue = 9000.0\ntolerance = 1.0\n'
    case = build_tom(parse_tom_deck(text, str(SPIRAL)))
    A, b = case.ineq_matrix, case.ineq_bound
    assert A.shape == (3, 4)
    day = 86400.0
    np.testing.assert_allclose(A @ case.u0 - b, [-0.45 * day, 0.0, -0.4 * day], atol=1e-6)
    u = case.u0.copy()
    u[1] = u[0]  # arc 0 closed
    ref = parse_deck(reference_deck_text(case, u), "closed_arc.toml")
    assert ref.thrust_arc[0].start_days == ref.thrust_arc[0].stop_days == 0.0


# ---------------------------------------------------------------- 2 and 4. validate
def _spiral_with(tmp_path, controls: str) -> Path:
    text = SPIRAL.read_text(encoding="utf-8")
    deck = tmp_path / "bad_spiral.toml"
    deck.write_text(
        text.split("[[control]]")[0] + controls + '[[target]]\nname = "a"\nvalue = 9000.0\ntolerance = 1.0\n'
    )
    return deck


def test_validate_refuses_overlapping_arcs(tmp_path):
    """A nominal end of arc 0 at 0.6 d while arc 1 starts at 0.45 d: the arcs would overlap;
    ``fracas validate`` names the control, and the build refuses it too."""
    deck = _spiral_with(tmp_path, '[[control]]\nname = "arc_t_off[0]"\nnominal = 0.6\n')
    problems = validate_path(deck)
    assert any("control[0].nominal" in p and "cannot invert or overlap" in p for p in problems), problems
    r = CliRunner().invoke(main, ["validate", str(deck)])
    assert r.exit_code != 0 and "Traceback" not in r.output


def test_validate_refuses_a_nominal_outside_its_bound(tmp_path):
    """arc_beta's catalogue bound is [-90, 90] deg; the spiral's beta is -15 deg, outside a
    deck bound lower = -10 (the upper bound stays the catalogue's): both are reported with the
    bound they break."""
    deck = _spiral_with(
        tmp_path,
        '[[control]]\nname = "arc_beta[0]"\nnominal = 120.0\n[[control]]\nname = "arc_beta[1]"\nlower = -10.0\n',
    )
    problems = validate_path(deck)
    assert any("control[0].nominal = 120: within its bounds [-90, 90] deg" in p for p in problems), problems
    assert any("control[1].name = -15 (the trajectory's value): within its bounds [-10, 90] deg" in p for p in problems)


# ---------------------------------------------------------------- 3. no targets
def test_optimize_without_targets_runs_to_its_results_file(tmp_path):
    """Hohmann's impulses with no target and submode "optimize" (maximize the final mass: the
    answer is no impulse at all, m_f = m0 = 1000 kg): exit 0 and a results file."""
    text = HOHMANN.read_text(encoding="utf-8")
    text = text[: text.index("[[target]]")].replace('submode = "auto"', 'submode = "optimize"')
    text = text.replace("max_iterations = 100", "max_iterations = 5")
    deck = tmp_path / "no_targets.toml"
    deck.write_text(text, encoding="utf-8")
    r = CliRunner().invoke(main, ["run", str(deck), "-o", str(tmp_path / "nt.h5")])
    assert r.exit_code == 0, r.output
    res = read_tom_results(tmp_path / "nt.h5")
    assert res["final_mass_kg"] > res["start_mass_kg"]
    assert res["targets"].shape == (len(res["iteration"]), 0)


# ---------------------------------------------------------------- 5. the iteration count
def test_iteration_count_never_exceeds_the_limit(tmp_path):
    """Lambert from far away with max_iterations = 2: the history's last iteration is 2 and
    the summary says 2 iterations (before: the limit's final test counted as iteration 3)."""
    text = LAMBERT.read_text(encoding="utf-8").replace('submode = "target"', 'submode = "target"\nmax_iterations = 2')
    deck = tmp_path / "two.toml"
    deck.write_text(text, encoding="utf-8")
    r = CliRunner().invoke(main, ["run", str(deck), "-o", str(tmp_path / "two.h5")])
    assert r.exit_code == 0, r.output
    res = read_tom_results(tmp_path / "two.h5")
    assert int(np.max(res["iteration"])) == 2
    assert "2 iterations" in r.stdout or "records in 2 iterations" in r.stdout


# ---------------------------------------------------------------- 6. wrapped angles
def test_periodic_angle_stays_wrapped_through_the_search():
    """Maximize F = cos(u - 3.5) (no targets) from u = 3.0 with u periodic: the optimum 3.5 rad
    lies past +pi, so the search crosses it; the answer is 3.5 - 2 pi = -2.783 rad (the same
    direction), within (-pi, pi], to 1e-4 rad (the search's convergence angle 1e-3 on a unit
    gradient scale)."""

    def evaluate(u):
        return Evaluation(np.zeros(0), float(np.cos(u[0] - 3.5)), True)

    def sensitivities(u):
        return evaluate(u), np.zeros((0, 1)), np.array([-np.sin(u[0] - 3.5)])

    prob = Problem(
        u0=np.array([3.0]),
        desired=np.zeros(0),
        tolerance=np.zeros(0),
        scale=np.ones(1),
        lower=np.full(1, -np.inf),
        upper=np.full(1, np.inf),
        floor=np.ones(1),
        evaluate=evaluate,
        sensitivities=sensitivities,
        periodic=np.array([True]),
    )
    res = projected_gradient(
        prob, SearchSettings(submode="optimize", max_performance_change=0.1, weighting="control", max_iterations=60)
    )
    assert -math.pi < res.u[0] <= math.pi
    assert abs(res.u[0] - (3.5 - 2 * math.pi)) < 1e-3, res.stop_reason
    np.testing.assert_allclose(wrap_periodic(np.array([3.5, 1.0]), np.array([True, False])), [3.5 - 2 * math.pi, 1.0])
    # the reference deck writes in-plane angles wrapped (1.68e6 deg was seen)
    assert _wrap_deg(1.68e6) == 1.68e6 - 4667 * 360.0
    assert _wrap_deg(-180.0) == 180.0
