"""How big a run a deck may ask for: :class:`Limits` and the size checks (no JAX, no arrays built).

A deck's numbers imply sizes: ``[output] step_days`` the number of output times,
``[[tracking]] interval_hours`` the number of observations, ``[stm] grid_hours`` the number
of STM-file times, an ``[[event]]`` range its event times.  A typo (``1e-9`` for ``1``)
would otherwise allocate terabytes or run for days before anything is said, so the sizes
are computed *arithmetically* (never by building the lists) and refused at parse time, with
how many and why.  Sizes that need the trajectory's duration (the STM grid, the whole
schedule of a TEAM study) are checked by :func:`check_team_sizes` before anything is built.

Defaults (:class:`Limits`) are about ten or more times what the bundled decks use
(namelists/: at most ~5,000 output times, ~2,200 measurements, ~2,000 schedule times,
~2,200 STM times, ~40 events) and sized so a 2-core / 24 GiB machine runs a study at the
limit: an STM-file time holds a 7 x (7 + p) step matrix (p ~ 20: ~1.5 kB), a schedule
time a covariance of ~25 x 25 (~5 kB) in the results, an output time a state and perhaps
its STM (~1.5 kB), so 100,000 STM or output times are ~150 MB and 300,000 schedule times
~1.5 GB, with room for the engine's working copies.  A deck may raise (or lower) them
with an optional ``[limits]`` table, itself bounded (:data:`HARD_LIMITS`, a further
factor 100) so a typo there cannot lift the guard::

    [limits]
    max_measurements = 1_000_000
"""

from __future__ import annotations

import json
import math
from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field

from fracas.constants import DAY_S
from fracas.errors import DeckError

__all__ = [
    "Limits",
    "DEFAULT_LIMITS",
    "HARD_LIMITS",
    "count_text",
    "MEMORY_FRACTION",
    "MAX_GRID_TRAJECTORIES",
    "grid_count",
    "machine_memory_bytes",
    "range_count",
    "tracking_count",
    "event_count",
    "team_size_problems",
    "check_team_sizes",
]

#: the default limits (see the module docstring for why these sizes)
DEFAULT_LIMITS = {
    "max_output_times": 100_000,
    "max_schedule_times": 300_000,
    "max_measurements": 200_000,
    "max_stm_times": 100_000,
    "max_events": 20_000,
}
#: the most a ``[limits]`` table may ask for (100 x the defaults)
HARD_LIMITS = {k: 100 * v for k, v in DEFAULT_LIMITS.items()}


class Limits(BaseModel):
    """The largest sizes a deck may imply (frozen); the optional ``[limits]`` table of a deck.

    ``max_output_times``: trajectory output times ([output] times_days + step_days);
    ``max_measurements``: observation times, per [[tracking]] entry and in total;
    ``max_schedule_times``: time points of a TEAM study's schedule (tracking, events,
    thrust switches, punches) and PDOT integration steps; ``max_stm_times``: times on an
    STM file (the schedule plus the [stm] grid); ``max_events``: [[event]] times, per
    entry and in total.  Each is an integer from 1 to :data:`HARD_LIMITS`.
    """

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)

    max_output_times: Annotated[int, Field(ge=1, le=HARD_LIMITS["max_output_times"])] = DEFAULT_LIMITS[
        "max_output_times"
    ]
    max_schedule_times: Annotated[int, Field(ge=1, le=HARD_LIMITS["max_schedule_times"])] = DEFAULT_LIMITS[
        "max_schedule_times"
    ]
    max_measurements: Annotated[int, Field(ge=1, le=HARD_LIMITS["max_measurements"])] = DEFAULT_LIMITS[
        "max_measurements"
    ]
    max_stm_times: Annotated[int, Field(ge=1, le=HARD_LIMITS["max_stm_times"])] = DEFAULT_LIMITS["max_stm_times"]
    max_events: Annotated[int, Field(ge=1, le=HARD_LIMITS["max_events"])] = DEFAULT_LIMITS["max_events"]


#: the most trajectories TOM's GRID may fly (one batch: every lane's state and outputs in
#: memory; the bundled GRID cases fly a few hundred)
MAX_GRID_TRAJECTORIES = 100_000

#: the most of the machine's memory a run's result table may take (TSIM's per-mission table)
MEMORY_FRACTION = 0.25


def grid_count(controls: int, steps: int, pairs: bool) -> int:
    """Trajectories of TOM's GRID: each control alone over -steps..steps increments, and
    (``pairs``) every pair over the square of them (fracas.modes.tom_search.grid_tables)."""
    g = 2 * steps + 1
    return controls * g + (controls * (controls - 1) // 2 * g * g if pairs else 0)


def machine_memory_bytes() -> int | None:
    """The machine's physical memory (bytes), or None where the platform does not say."""
    import os

    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return None


def count_text(n: float) -> str:
    """A count for an error line: exact below a million, else two figures (3.5e+14)."""
    return f"{int(n)}" if n < 1e6 else f"{n:.2g}"


def range_count(start: float, stop: float, step: float) -> float:
    """How many points start, start + step, ... <= stop there are (as team.schedule.range_times
    makes them), as a float so that absurd steps give a large number instead of a list."""
    if stop < start:
        return 0.0
    q = (stop - start) / step * (1 + 1e-12) + 1e-9
    return math.floor(q) + 1.0 if q < 1e18 else q  # inf for a subnormal step


def tracking_count(t: Any, start_days: float | None = None, stop_days: float | None = None) -> float:
    """Observation times of one [[tracking]] entry (optionally only those in a window, days)."""
    lo = t.start_days * DAY_S
    step = t.interval_hours * 3600.0
    n = range_count(lo, t.stop_days * DAY_S, step)
    if start_days is None and stop_days is None:
        return n
    a = lo if start_days is None else max(lo, start_days * DAY_S)
    b = t.stop_days * DAY_S if stop_days is None else min(t.stop_days * DAY_S, stop_days * DAY_S)
    if b < a:
        return 0.0
    return min(n, range_count(a, b, step) + 1.0)


def event_count(e: Any) -> float:
    """Times of one [[event]] entry (times_days plus its start/stop/interval range)."""
    n = float(len(e.times_days))
    if e.start_days is not None and e.stop_days is not None and e.interval_days:
        n += range_count(e.start_days, e.stop_days, e.interval_days)
    return n


def _echo(v: Any) -> str:
    s = json.dumps(v) if isinstance(v, (int, float, str)) else str(v)
    return s if len(s) <= 40 else s[:39] + "…"


def team_size_problems(deck: Any, traj: Any) -> list[str]:
    """Every size problem of a TEAM deck that needs its trajectory's duration (one line each):
    the [stm] grid, the STM-file times, the whole schedule and PDOT's steps."""
    src = deck.source_path or "<deck>"
    lim = deck.limits
    dur = traj.duration_days
    out: list[str] = []
    grid = 0.0
    if deck.stm.grid_hours:
        grid = range_count(0.0, dur * DAY_S, deck.stm.grid_hours * 3600.0)
        if grid > lim.max_stm_times:
            out.append(
                f"{src}: stm.grid_hours = {_echo(deck.stm.grid_hours)}: gives {count_text(grid)} STM times over "
                f"0-{dur:g} d (limit {lim.max_stm_times}, [limits] max_stm_times); use a longer grid"
            )
    start = deck.filter.start_days
    stop = min(deck.filter.stop_days, dur) if deck.filter.stop_days is not None else dur
    sched = 2.0 + 2.0 * len(traj.thrust_arc) + (len(deck.punch.times_days) if deck.punch is not None else 0)
    sched += sum(tracking_count(t, start, stop) for t in deck.tracking)
    sched += sum(event_count(e) for e in deck.event)
    if sched > lim.max_schedule_times:
        out.append(
            f"{src}: tracking: gives {count_text(sched)} schedule times over {start:g}-{stop:g} d "
            f"(limit {lim.max_schedule_times}, [limits] max_schedule_times); use longer intervals"
        )
    elif grid <= lim.max_stm_times and sched + grid > lim.max_stm_times:
        out.append(
            f"{src}: stm.grid_hours = {_echo(deck.stm.grid_hours)}: gives {count_text(sched + grid)} STM times "
            f"with the schedule (limit {lim.max_stm_times}, [limits] max_stm_times); use a longer grid"
        )
    # fixed-step grids over the whole study: the grid model's noise cells, PDOT's RK4 steps
    for field, used, hours, what in (
        ("errcon.noise_step_hours", deck.errcon.process_noise == "grid", deck.errcon.noise_step_hours, "noise cells"),
        ("ertraj.pdot_step_hours", deck.errcon.propagation == "pdot", deck.ertraj.pdot_step_hours, "PDOT steps"),
    ):
        n = range_count(0.0, dur * DAY_S, hours * 3600.0) if used else 0
        if n > lim.max_schedule_times:
            out.append(
                f"{src}: {field} = {_echo(hours)}: gives {count_text(n)} {what} over 0-{dur:g} d "
                f"(limit {lim.max_schedule_times}, [limits] max_schedule_times); use a longer step"
            )
    return out


def check_team_sizes(deck: Any, traj: Any) -> None:
    """Refuse a TEAM study whose trajectory makes it too big (DeckError with every problem),
    before its ephemeris, STMs or schedule are built (see :func:`team_size_problems`)."""
    problems = team_size_problems(deck, traj)
    if problems:
        n = len(problems) - 1
        line = problems[0] + (f" (and {n} more error{'s' if n > 1 else ''})" if n else "")
        raise DeckError(line, problems=problems)
