"""benchmarks/runs.py refuses a figure from a failed run (issue 32 1b): no jax, no compile."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks import runs


def fake(status):
    """A stand-in for a Trajectory: only what the helper reads, plus an abort-point state."""
    return SimpleNamespace(status=np.asarray(status), x_final=np.full(7, 1e4))


def test_ok_runs_pass():
    assert runs.failure(fake(0)) is None
    assert runs.failure(fake(1)) is None  # a stop condition met is a run that ended as asked
    assert runs.failure(fake([0, 0, 1])) is None
    tr = fake(0)
    assert runs.require(tr, "deck") is tr
    assert runs.status_cell(fake([0, 1])) == "0,1"


def test_nonfinite_run_refused():
    assert runs.failure(fake(3)) == "FAILED (status 3: non-finite state or step below eps_t)"
    with pytest.raises(
        runs.RunFailed, match=r"^spiral tol 1e-14: FAILED \(status 3: non-finite state or step below eps_t\)$"
    ):
        runs.require(fake(3), "spiral tol 1e-14")
    assert runs.status_cell(fake(3)) == "FAILED (status 3: non-finite state or step below eps_t)"


def test_max_steps_and_stop_when_final_time_required():
    assert runs.failure(fake(2)) == "FAILED (status 2: maximum number of steps reached)"
    assert runs.failure(fake(1), ok=(0,)) == "FAILED (status 1: stop condition met)"


def test_batch_counts_failed_members():
    f = runs.failure(fake([0, 3, 0, 2, 3]))
    assert (
        f
        == "FAILED (3 of 5: status 2: maximum number of steps reached; status 3: non-finite state or step below eps_t)"
    )
    # a (Trajectory, Sensitivities) pair is read through its trajectory
    assert runs.failure((fake([0, 3]), object())) == "FAILED (1 of 2: status 3: non-finite state or step below eps_t)"


def test_exit_and_main_guard_are_one_line(capsys):
    with pytest.raises(SystemExit) as e:
        runs.exit_if_failed(fake(3), "reference")
    assert e.value.code == "error: reference: FAILED (status 3: non-finite state or step below eps_t)"

    def main():
        runs.require(fake(2), "deck")
        return "figure"  # never reached

    with pytest.raises(SystemExit) as e:
        runs.main_guard(main)
    assert str(e.value.code).count("\n") == 0 and "FAILED (status 2" in str(e.value.code)


def test_failed_figure_prints_as_text_and_loses_comparisons():
    v = runs.FailedFigure("FAILED (status 3: non-finite state or step below eps_t)")
    assert math.isinf(v) and not v <= 1e-3
    assert f"{v:.3g}" == "FAILED (status 3: non-finite state or step below eps_t)"
    assert runs.fmt(v, lambda x: f"{x:.3g} m") == "FAILED (status 3: non-finite state or step below eps_t)"
    assert runs.fmt(0.5, lambda x: f"{x:.3g} m") == "0.5 m"


def test_other_outcomes():
    assert runs.failure(fake(2), texts=runs.TSIM_TEXT) == "FAILED (status 2: hopeless (design did not converge))"
    assert runs.scipy_failure(SimpleNamespace(success=True)) is None
    assert runs.scipy_failure(SimpleNamespace(success=False, message="step too small")) == (
        "FAILED (scipy: step too small)"
    )
    assert runs.tom_failure(True) is None
    assert runs.tom_failure(False, "iteration limit") == "FAILED (not converged: iteration limit)"
    assert runs.sweep_failure([{"status": "ok"}, {"status": "failed", "error": "boom"}]) == (
        "FAILED (1 of 2 studies: boom)"
    )
    assert runs.heyoka_failure("time_limit", expect="time_limit") is None
    assert runs.heyoka_failure(("err_nf_state", 0.1, 1.0, 5), expect="time_limit") == (
        "FAILED (heyoka outcome err_nf_state)"
    )
    assert runs.heyoka_failure([("time_limit", 0, 0, 1), ("step_limit", 0, 0, 9)], expect="time_limit") == (
        "FAILED (1 of 2: heyoka outcome step_limit)"
    )
