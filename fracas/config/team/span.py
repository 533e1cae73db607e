"""A TEAM study's times against its reference trajectory's span (no JAX, nothing built).

A study cannot run past the end of the trajectory it stands on: there is no reference
state, transition matrix or ephemeris there.  Without this check a filter ``stop_days``,
a ``[[tracking]]`` schedule, a punch time or an error-budget epoch beyond the trajectory's
final time was cut to it without a word (a 10-day study on a 5-day trajectory stopped at
5 d and reported success).  :func:`team_span_problems` names every such time, one line
each, with both spans (the study's and the trajectory's); ``fracas validate``
(:func:`fracas.validate.team_problems`) and every run (:func:`fracas.build.team_numbers.
trajectory_problem`, before anything is built) refuse the same lines.  Event, prediction
and guidance times are checked where they always were (:mod:`fracas.validate`,
:mod:`fracas.build.team`, :mod:`fracas.build.guidance`).
"""

from __future__ import annotations

from typing import Any

from fracas.errors import DeckError

__all__ = ["team_span_problems", "check_team_span"]

#: a time this far (relative) past the final time is still "at" it (the decks' days are rounded)
_SLACK = 1e-12


def _after(t: float, end: float) -> bool:
    return t > end * (1.0 + _SLACK) + 1e-12


def team_span_problems(deck: Any, traj: Any) -> list[str]:
    """Every time of a TEAM deck past the end of its trajectory deck, one line each:
    ``filter.start_days``/``stop_days``, each ``[[tracking]]`` entry's start and stop,
    ``[punch] times_days`` and ``[budget] at_days``.  ``traj`` is a forward trajectory deck
    (a backward one is refused before)."""
    src = deck.source_path or "<deck>"
    end = traj.duration_days
    where = f"{traj.source_path or deck.ertraj.deck} spans 0-{end:g} d"
    fix = f"expected <= {end:g} d, or a longer trajectory (its [stop])"
    out: list[str] = []
    f = deck.filter
    if f.stop_days is not None and _after(f.stop_days, end):
        out.append(
            f"{src}: filter.stop_days = {f.stop_days:g}: the study runs {f.start_days:g}-{f.stop_days:g} d, "
            f"past the end of its reference trajectory ({where}); {fix}"
        )
    if f.start_days >= end * (1.0 - _SLACK):
        out.append(
            f"{src}: filter.start_days = {f.start_days:g}: the study starts at or after the end of its reference "
            f"trajectory ({where}); expected < {end:g} d"
        )
    for k, t in enumerate(deck.tracking):
        for name in ("stop_days", "start_days"):
            value = getattr(t, name)
            if _after(value, end):
                out.append(
                    f"{src}: tracking[{k}].{name} = {value:g}: the tracking runs {t.start_days:g}-{t.stop_days:g} d, "
                    f"past the end of its reference trajectory ({where}); {fix}"
                )
                break
    if deck.punch is not None:
        late = [t for t in deck.punch.times_days if _after(t, end)]
        if late:
            out.append(
                f"{src}: punch.times_days: {len(late)} time{'s' if len(late) > 1 else ''} past the end of the "
                f"reference trajectory (the latest {max(late):g} d; {where}); {fix}"
            )
    late = [t for t in deck.budget.at_days if _after(t, end)]
    if late:
        out.append(
            f"{src}: budget.at_days: {len(late)} epoch{'s' if len(late) > 1 else ''} past the end of the "
            f"reference trajectory (the latest {max(late):g} d; {where}); {fix}"
        )
    return out


def check_team_span(deck: Any, traj: Any) -> None:
    """Refuse a TEAM study whose times run past its trajectory (DeckError with every line of
    :func:`team_span_problems`), before anything is built."""
    problems = team_span_problems(deck, traj)
    if problems:
        n = len(problems) - 1
        line = problems[0] + (f" (and {n} more error{'s' if n > 1 else ''})" if n else "")
        raise DeckError(line, problems=problems)
