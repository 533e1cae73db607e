"""Run-status checks shared by the benchmarks and scripts: no figure from a failed run.

A propagation reports how it ended as an integer code (:mod:`fracas.status`: 0 reached the
final time, 1 stop condition met, 2 maximum number of steps, 3 non-finite state) instead of
raising, and its ``x_final`` is then wherever it stopped.  A benchmark that compares or times
runs without looking at that code prints, for a failed run, the distance to the abort point
(issue 32 1b: deck_accuracy's "7.29e6 m").  So every run whose numbers a benchmark reports
goes through this module first:

* :func:`failure` -- ``None`` when every member of the run ended as asked, else the text to
  print in the run's place, ``"FAILED (status 3: non-finite state)"`` (a batch: ``"FAILED
  (2 of 64: status 3: non-finite state)"``);
* :func:`require` -- the run itself when it ended as asked, else :class:`RunFailed` with one
  line naming the run; :func:`exit_if_failed` -- the same as a one-line exit (status 1);
* :func:`heyoka_failure` / :func:`require_heyoka` -- the same for heyoka's
  ``taylor_outcome`` (a ``propagate_until`` that ended anywhere but at its time limit);
  :func:`scipy_failure` for a ``solve_ivp`` / ``solve_bvp`` result; :func:`tom_failure` for
  a TOM run (its verified ``converged`` verdict); :func:`sweep_failure` for sweep rows;
* :class:`FailedFigure` -- an ``inf`` that carries the FAILED text, for a figure (an error, a
  rate) that a tuning loop computes from a run that failed: it compares as "too large", and
  :func:`fmt` prints its text instead of a number;
* :func:`main_guard` -- run a benchmark's ``main`` so that a :class:`RunFailed` ends it with
  one line on stderr and exit status 1 (no traceback).

TSIM missions have codes of their own (0 ok, 1 near success, 2 hopeless, 3 integration
failed): pass ``texts=TSIM_TEXT``.

``run`` is anything with a ``status``: a :class:`fracas.integrate.propagate.Trajectory`, a
batch of them (``status`` of shape ``(N,)``), a ``(Trajectory, Sensitivities)`` pair, a
product with a ``status`` field, or the code(s) themselves (an int, a sequence, an array).
``ok`` is the set of codes that count as success: by default ``OK`` and ``STOPPED`` (a run
that stopped at its deck's stop condition ended as asked); pass ``ok=(0,)`` where the run must
reach its final time.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable

import numpy as np

try:
    from fracas.status import status_text
except ImportError:  # a fracas from before fracas.status (bench_heyoka_ratio.py --ref OLD); codes 0-3 unchanged
    _OLD = {
        0: "reached the final time",
        1: "stop condition met",
        2: "maximum number of steps reached",
        3: "non-finite state",
    }

    def status_text(code):
        return _OLD.get(int(code), f"unknown status {code}")


__all__ = [
    "OK_CODES",
    "RunFailed",
    "statuses",
    "failure",
    "require",
    "exit_if_failed",
    "status_cell",
    "heyoka_failure",
    "require_heyoka",
    "scipy_failure",
    "tom_failure",
    "sweep_failure",
    "FailedFigure",
    "fmt",
    "main_guard",
    "TSIM_TEXT",
]

#: Codes that count as "ended as asked" by default: 0 reached the final time, 1 stop condition met.
OK_CODES = (0, 1)

#: TSIM mission codes (fracas.tsim.plan STATUS_*): 0 and 1 are successes.
TSIM_TEXT = {0: "ok", 1: "near success", 2: "hopeless (design did not converge)", 3: "integration failed"}


class RunFailed(RuntimeError):
    """A run whose numbers were about to be reported did not end as asked (one-line message)."""


def statuses(run) -> np.ndarray:
    """The status code(s) of ``run`` as a flat int array (one entry per batch member)."""
    if isinstance(run, tuple) and run and hasattr(run[0], "status"):  # (Trajectory, Sensitivities)
        run = run[0]
    codes = getattr(run, "status", run)
    if isinstance(codes, (str, bytes)) or codes is None:
        raise TypeError(f"no run status in {type(run).__name__}")
    return np.atleast_1d(np.asarray(codes)).astype(np.int64).ravel()


def failure(run, ok: Iterable[int] = OK_CODES, texts: dict | None = None) -> str | None:
    """``None`` when every member of ``run`` ended with a code in ``ok``; else the text to show
    in place of its figures: ``"FAILED (status 3: non-finite state)"``, for a batch with some
    members failed ``"FAILED (2 of 64: status 3: non-finite state)"`` (several codes joined
    by ``"; "``).  ``texts``: code -> meaning where the codes are not :mod:`fracas.status`'s."""
    codes = statuses(run)
    text = status_text if texts is None else (lambda c: texts.get(int(c), f"unknown status {c}"))
    ok = {int(c) for c in ok}
    bad = codes[~np.isin(codes, list(ok))]
    if bad.size == 0:
        return None
    kinds = "; ".join(f"status {c}: {text(c)}" for c in np.unique(bad))
    if codes.size == 1:
        return f"FAILED ({kinds})"
    return f"FAILED ({bad.size} of {codes.size}: {kinds})"


def require(run, what: str, ok: Iterable[int] = OK_CODES, texts: dict | None = None):
    """``run`` itself when it ended as asked, else :class:`RunFailed` ``"<what>: FAILED (...)"``."""
    f = failure(run, ok, texts)
    if f is not None:
        raise RunFailed(f"{what}: {f}")
    return run


def exit_if_failed(run, what: str, ok: Iterable[int] = OK_CODES):
    """``run`` itself when it ended as asked, else exit (status 1) with one line on stderr."""
    try:
        return require(run, what, ok)
    except RunFailed as e:
        sys.exit(f"error: {e}")


def status_cell(run, ok: Iterable[int] = OK_CODES) -> str:
    """A table cell: ``"0"`` (the codes, ``"0,1"`` for a batch with both) when the run ended as
    asked, else the :func:`failure` text."""
    return failure(run, ok) or ",".join(str(c) for c in np.unique(statuses(run)))


# --- heyoka ---------------------------------------------------------------------------------


def _outcome_name(o) -> str:
    return getattr(o, "name", str(o))


def heyoka_failure(outcomes, expect=None) -> str | None:
    """``None`` when every heyoka ``taylor_outcome`` in ``outcomes`` is ``expect`` (default
    ``taylor_outcome.time_limit``: ``propagate_until``/``propagate_for`` reached its time), else
    ``"FAILED (heyoka outcome err_nf_state)"`` (a batch: ``"FAILED (3 of 8: heyoka outcome ...)"``).

    ``outcomes``: one outcome, a ``propagate_until`` result tuple (its first entry), or a
    sequence of either (a batch integrator's ``propagate_res``).
    """
    if expect is None:
        import heyoka as hy

        expect = hy.taylor_outcome.time_limit
    if isinstance(outcomes, tuple) and outcomes and not isinstance(outcomes[0], tuple):
        outcomes = [outcomes[0]]  # one propagate_until result: (outcome, min_h, max_h, n_steps, ...)
    elif not isinstance(outcomes, (list, tuple)):
        outcomes = [outcomes]
    got = [o[0] if isinstance(o, tuple) else o for o in outcomes]
    bad = [o for o in got if o != expect]
    if not bad:
        return None
    kinds = ", ".join(sorted({_outcome_name(o) for o in bad}))
    if len(got) == 1:
        return f"FAILED (heyoka outcome {kinds})"
    return f"FAILED ({len(bad)} of {len(got)}: heyoka outcome {kinds})"


def require_heyoka(outcomes, what: str, expect=None):
    """``outcomes`` when :func:`heyoka_failure` finds nothing, else :class:`RunFailed`."""
    f = heyoka_failure(outcomes, expect)
    if f is not None:
        raise RunFailed(f"{what}: {f}")
    return outcomes


# --- other solvers and modes ----------------------------------------------------------------


def scipy_failure(sol) -> str | None:
    """``None`` for a scipy ``solve_ivp`` / ``solve_bvp`` result with ``success``, else
    ``"FAILED (scipy: <message>)"``."""
    if getattr(sol, "success", False):
        return None
    return f"FAILED (scipy: {getattr(sol, 'message', 'no success flag')})"


def tom_failure(converged, stop_reason: str = "") -> str | None:
    """``None`` for a TOM run whose verified verdict is ``converged`` (the plain-core
    re-propagation of its final controls met every target), else ``"FAILED (not converged:
    <stop reason>)"``."""
    if bool(converged):
        return None
    return f"FAILED (not converged: {stop_reason})" if stop_reason else "FAILED (not converged)"


def sweep_failure(rows) -> str | None:
    """``None`` when every sweep row (``{"status": "ok" | "failed", "error": ...}``) is ok,
    else ``"FAILED (k of n studies: <first error>)"``."""
    rows = list(rows)
    bad = [r for r in rows if r.get("status") != "ok"]
    if not bad:
        return None
    return f"FAILED ({len(bad)} of {len(rows)} studies: {bad[0].get('error', '')})"


# --- figures from failed runs ---------------------------------------------------------------


class FailedFigure(float):
    """``inf`` standing for a figure of a run that failed, carrying the FAILED text.

    It compares as larger than any error target (a tuning loop rejects it like any error too
    large) and prints as its text (``str``, ``format``, :func:`fmt`), never as a number."""

    text: str

    def __new__(cls, text: str):
        obj = super().__new__(cls, float("inf"))
        obj.text = text
        return obj

    def __str__(self) -> str:
        return self.text

    __repr__ = __str__

    def __format__(self, spec: str) -> str:
        return self.text


def fmt(value, formatter=str) -> str:
    """``formatter(value)``, or the FAILED text when ``value`` is a :class:`FailedFigure`."""
    if isinstance(value, FailedFigure):
        return value.text
    return formatter(value)


def main_guard(main, *args, **kwargs):
    """Call ``main``; a :class:`RunFailed` (a run whose figures were about to be reported
    failed) ends the process with its one line on stderr and exit status 1."""
    try:
        return main(*args, **kwargs)
    except RunFailed as e:
        sys.exit(f"error: {e}")
