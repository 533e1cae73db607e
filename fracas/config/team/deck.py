"""The whole TEAM deck (:class:`TeamDeck`) and its cross checks (parameters, resets, stations,
guidance events, sizes against ``[limits]``); parsing and loading it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import model_validator

from fracas.config.limits import Limits, count_text, event_count, tracking_count
from fracas.config.team.bounds import MAX_STATIONS
from fracas.config.team.guidance import Guidance
from fracas.config.team.sections import (
    APriori,
    BudgetSection,
    ErrCon,
    ErTraj,
    FilterSection,
    GenCov,
    OutputSection,
    Parameter,
    PrintSection,
    Punch,
    StationDef,
    StmSection,
    ThrustNoise,
    WhiteNoise,
)
from fracas.config.team.tracking import Event, Tracking
from fracas.config.trajectory import (
    FieldProblem,
    SourcedDeck,
    load_toml,
    parse_sourced,
    raise_problems,
    read_deck_text,
)
from fracas.errors import DeckError


class TeamDeck(SourcedDeck):
    """A whole TEAM deck (frozen)."""

    mode: Literal["team"] = "team"
    title: str = ""
    errcon: ErrCon = ErrCon()
    ertraj: ErTraj
    stm: StmSection = StmSection()
    filter: FilterSection = FilterSection()
    a_priori: APriori | None = None
    parameter: list[Parameter] = []
    thrust_noise: ThrustNoise = ThrustNoise()
    process_noise: WhiteNoise = WhiteNoise()
    station: list[StationDef] = []
    tracking: list[Tracking] = []
    event: list[Event] = []
    print: PrintSection = PrintSection()
    punch: Punch | None = None
    gencov: GenCov | None = None
    control: APriori | None = None
    guidance: list[Guidance] = []
    budget: BudgetSection = BudgetSection()
    output: OutputSection = OutputSection()
    limits: Limits = Limits()

    # C901 on purpose: a flat list of independent deck checks, each raising the one problem it finds
    @model_validator(mode="after")
    def _cross_checks(self) -> TeamDeck:  # noqa: C901
        if self.errcon.analysis and self.a_priori is None:
            raise FieldProblem("a_priori", None, "required when errcon.analysis = true")
        seen: dict[str, int] = {}
        for k, p in enumerate(self.parameter):
            if p.label in seen:
                raise FieldProblem(("parameter", k, "label"), p.label, f"repeats parameter[{seen[p.label]}]")
            seen[p.label] = k
        if self.gencov is not None:
            for k, g in enumerate(self.gencov.parameter):
                if g.label not in seen and g.role != "ignore":
                    raise FieldProblem(
                        ("gencov", "parameter", k, "label"),
                        g.label,
                        'is not a study parameter; add role = "ignore" to make it an ignore parameter',
                    )
                if g.label in seen and g.role == "ignore":
                    raise FieldProblem(
                        ("gencov", "parameter", k, "role"),
                        "ignore",
                        f"{g.label} is already a study parameter (parameter[{seen[g.label]}])",
                    )
        for k, e in enumerate(self.event):
            if e.type != "reset":
                continue
            if self.gencov is None or not self.gencov.enabled:
                raise FieldProblem(
                    ("event", k, "type"),
                    "reset",
                    "a [gencov] section (a reset changes only the filter's assumed covariance; "
                    "without generalized covariance nothing would report the true errors)",
                )
            if self.errcon.propagation != "phi" or self.filter.type != "kalman_schmidt":
                raise FieldProblem(
                    ("event", k, "type"),
                    "reset",
                    'errcon.propagation = "phi" and filter.type = "kalman_schmidt" (reset events)',
                )
        names = [s.name for s in self.station]
        if len(set(names)) != len(names):
            raise FieldProblem("station", names, "station names must be unique")
        builtin = {"goldstone", "madrid", "canberra"}
        if len(builtin | set(names)) > MAX_STATIONS:
            raise FieldProblem(
                "station", names, f"at most {MAX_STATIONS} stations in all (including the 3 DSN defaults)"
            )
        known = builtin | set(names)
        for k, t in enumerate(self.tracking):
            for j, s in enumerate(t.stations):
                if s not in known:
                    raise FieldProblem(
                        ("tracking", k, "stations", j),
                        s,
                        f"unknown station (expected one of: {', '.join(sorted(known))})",
                    )
            if t.target_station is not None and t.target_station not in known:
                raise FieldProblem(
                    ("tracking", k, "target_station"),
                    t.target_station,
                    f"unknown station (expected one of: {', '.join(sorted(known))})",
                )
        self._check_guidance()
        self._check_sizes()
        return self

    def _check_guidance(self) -> None:
        """Guidance events: unique names, times inside the study, one-per-time, PHI only,
        verniers after a primary on the same arc, a control a-priori only with guidance."""
        problems = []
        seen: dict[str, int] = {}
        times: dict[float, int] = {}
        primaries: dict[int, float] = {}
        if self.guidance and self.errcon.propagation == "pdot":
            problems.append(
                FieldProblem(
                    ("errcon", "propagation"),
                    "pdot",
                    'guidance events need propagation = "phi" in this release',
                )
            )
        stop = self.filter.stop_days
        for k, g in enumerate(self.guidance):
            if g.name in seen:
                problems.append(FieldProblem(("guidance", k, "name"), g.name, f"repeats guidance[{seen[g.name]}]"))
            seen[g.name] = k
            if g.time_days < self.filter.start_days or (stop is not None and g.time_days > stop):
                problems.append(
                    FieldProblem(
                        ("guidance", k, "time_days"),
                        g.time_days,
                        f"outside the study ({self.filter.start_days:g} to "
                        f"{'the trajectory end' if stop is None else f'{stop:g}'} d)",
                    )
                )
            if g.time_days in times:
                problems.append(
                    FieldProblem(
                        ("guidance", k, "time_days"), g.time_days, f"guidance[{times[g.time_days]}] is at the same time"
                    )
                )
            times[g.time_days] = k
            if g.type == "primary":
                primaries[int(g.arc)] = g.time_days
            if g.type == "vernier" and (g.arc not in primaries or primaries[g.arc] >= g.time_days):
                problems.append(
                    FieldProblem(
                        ("guidance", k, "type"),
                        "vernier",
                        f"needs an earlier primary on arc {g.arc} (list guidance events in time order)",
                    )
                )
            if g.target_time_days is not None and g.target_time_days < g.time_days:
                problems.append(
                    FieldProblem(("guidance", k, "target_time_days"), g.target_time_days, "before the guidance time")
                )
        order = [g.time_days for g in self.guidance]
        if order != sorted(order):
            problems.append(FieldProblem("guidance", order, "list guidance events in time order"))
        if self.control is not None and self.control.from_punch is None and not self.guidance:
            problems.append(FieldProblem("control", None, "a control a-priori needs [[guidance]] events"))
        raise_problems(problems)

    def _check_sizes(self) -> None:
        """The sizes the deck alone implies (observations, event times) against ``[limits]``."""
        lim = self.limits
        problems = []
        total = 0.0
        for k, t in enumerate(self.tracking):
            n = tracking_count(t)
            total += n
            if n > lim.max_measurements:
                problems.append(
                    FieldProblem(
                        ("tracking", k, "interval_hours"),
                        t.interval_hours,
                        f"gives {count_text(n)} observation times over {t.start_days:g}-{t.stop_days:g} d "
                        f"(limit {lim.max_measurements}, [limits] max_measurements); use a longer interval",
                    )
                )
        if not problems and total > lim.max_measurements:
            problems.append(
                FieldProblem(
                    ("tracking",),
                    None,
                    f"the {len(self.tracking)} entries give {count_text(total)} observation times in all "
                    f"(limit {lim.max_measurements}, [limits] max_measurements); use longer intervals",
                )
            )
        total = 0.0
        for k, e in enumerate(self.event):
            n = event_count(e)
            total += n
            if n > lim.max_events:
                problems.append(
                    FieldProblem(
                        ("event", k, "interval_days" if e.interval_days else "times_days"),
                        e.interval_days if e.interval_days else None,
                        f"gives {count_text(n)} event times (limit {lim.max_events}, [limits] max_events); "
                        "use a longer interval",
                    )
                )
        if not any(p.field[0] == "event" for p in problems) and total > lim.max_events:
            problems.append(
                FieldProblem(
                    ("event",),
                    None,
                    f"the {len(self.event)} entries give {count_text(total)} event times in all "
                    f"(limit {lim.max_events}, [limits] max_events)",
                )
            )
        raise_problems(problems)


def parse_team_deck(text: str, source: str = "<deck>") -> TeamDeck:
    """Validate TEAM-deck TOML text; any problem -> one-line DeckError."""
    return parse_sourced(text, source, TeamDeck)


def is_team_text(text: str) -> bool:
    """Whether TOML text is a TEAM deck (it has an [ertraj] table) rather than a trajectory deck."""
    try:
        return "ertraj" in load_toml(text, "<deck>")
    except DeckError:
        return False


def load_team_deck(path: str | Path) -> TeamDeck:
    """Read and validate a TEAM deck; every failure is a one-line DeckError."""
    return parse_team_deck(read_deck_text(path), str(path))
