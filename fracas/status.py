"""Run status codes, one enumeration for every mode (propagation, batches, covariance analysis).

A run reports an integer code instead of raising (the core is jit/vmap-able and has no
exceptions); this module names the codes and says what each means.  It imports nothing but
the standard library, so a reader, a report or a scheduler can use it without jax.

    ====  =========================  ===========================================================
    code  name                       meaning
    ====  =========================  ===========================================================
    0     ``OK``                     reached the final time
    1     ``STOPPED``                the stop condition was met (located to eps_t)
    2     ``MAX_STEPS``              ``integrator.max_steps`` reached before the final time
    3     ``NONFINITE``              the state became NaN/inf (or started so), or the step
                                     controller asked for a step below eps_t (a collision, a
                                     singularity: the tolerance cannot be met)
    5     ``OUTSIDE_TRAJECTORY``     a requested time lies beyond the end of the reference
    6     ``NOT_POSITIVE_DEFINITE``  a covariance lost positive-definiteness
    7     ``NONFINITE_COVARIANCE``   a covariance became NaN/inf
    ====  =========================  ===========================================================

Codes 0-3 are written by the integrator (``fracas.integrate.encke``) and stored in trajectory
files; 5-7 are for the callers built on a propagation (prediction to a target time,
covariance analysis).  Code 4 is left unassigned on purpose: the integrator has no separate
"event location did not converge" failure -- the Newton steps that locate an event count
towards ``max_steps``, so a location that never converges ends as ``MAX_STEPS``.

``RunStatus(c).ok`` is true for a run that ended as asked (``OK`` or ``STOPPED``);
:func:`status_text` accepts any integer (unknown codes get ``"unknown status N"``) and
:func:`batch_status_summary` counts the codes of a batch.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable
from typing import SupportsInt

__all__ = [
    "RunStatus",
    "STATUS_TEXT",
    "PROPAGATION_STATUSES",
    "status_text",
    "batch_status_summary",
    "format_status_summary",
]


class RunStatus(enum.IntEnum):
    """How a run ended (an ``int``: compares and serialises as its code)."""

    OK = 0
    STOPPED = 1
    MAX_STEPS = 2
    NONFINITE = 3
    OUTSIDE_TRAJECTORY = 5
    NOT_POSITIVE_DEFINITE = 6
    NONFINITE_COVARIANCE = 7

    @property
    def text(self) -> str:
        """One line saying what the code means (the text stored in trajectory files)."""
        return _TEXT[self]

    @property
    def ok(self) -> bool:
        """True when the run ended as asked: at the final time or at its stop condition."""
        return self in (RunStatus.OK, RunStatus.STOPPED)


_TEXT = {
    RunStatus.OK: "reached the final time",
    RunStatus.STOPPED: "stop condition met",
    RunStatus.MAX_STEPS: "maximum number of steps reached",
    RunStatus.NONFINITE: "non-finite state or step below eps_t",
    RunStatus.OUTSIDE_TRAJECTORY: "a requested time lies beyond where the reference trajectory ended",
    RunStatus.NOT_POSITIVE_DEFINITE: "a covariance lost positive-definiteness",
    RunStatus.NONFINITE_COVARIANCE: "non-finite covariance",
}

#: code (plain ``int``) -> text, for every :class:`RunStatus`.
STATUS_TEXT: dict[int, str] = {int(s): s.text for s in RunStatus}

#: The codes a propagation (``fracas.integrate``) can end with, as stored in trajectory files.
PROPAGATION_STATUSES = (RunStatus.OK, RunStatus.STOPPED, RunStatus.MAX_STEPS, RunStatus.NONFINITE)


def status_text(code: SupportsInt) -> str:
    """Text of ``code`` (a :class:`RunStatus`, an int, a numpy integer); ``"unknown status N"``
    for an integer that is no :class:`RunStatus`."""
    try:
        return RunStatus(int(code)).text
    except (ValueError, TypeError):
        return f"unknown status {code}"


def batch_status_summary(codes: Iterable[SupportsInt]) -> dict:
    """Count the codes of a batch: ``{RunStatus.OK: 98, RunStatus.NONFINITE: 2}``.

    ``codes``: any iterable of integers (a list, the ``(N,)`` ``status`` array of
    :func:`fracas.integrate.batch.propagate_batch`).  Keys are :class:`RunStatus` members, or
    plain ints for unknown codes; only codes that occur appear, in increasing order.
    """
    counts: dict[int, int] = {}
    for c in codes:
        c = int(c)
        counts[c] = counts.get(c, 0) + 1
    out: dict = {}
    for c in sorted(counts):
        key: RunStatus | int
        try:
            key = RunStatus(c)
        except ValueError:
            key = c
        out[key] = counts[c]
    return out


def format_status_summary(summary: dict) -> str:
    """One line from :func:`batch_status_summary`: ``"98 reached the final time, 2 non-finite state"``."""
    return ", ".join(f"{n} {status_text(c)}" for c, n in summary.items())
