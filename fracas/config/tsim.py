"""The TSIM deck: Monte Carlo mission simulation with guidance in the loop (FRACAS $INSIM,
$INMAN; report §3.3, §4.1.3).

A TSIM deck stands on a TEAM deck with guidance events (``[insim] team_deck``): that deck
gives the reference trajectory, the injection dispersions (its ``[control]``, else its
a-priori), the spacecraft and model parameters with their true sigmas, the Gauss-Markov
thrust noise, the tracking (hence the knowledge covariance at every maneuver) and one
guidance event per maneuver (epoch, law, cutoff, targets, execution errors).  This is
$INSIM and $INMAN read from the deck the covariance analysis used, so TSIM and TEAM fly
the same mission.  The tables below override or add what the Monte Carlo needs.  Units
as written by an analyst: km, km/s, kg, days.  No JAX here::

    mode = "tsim"
    [insim]        team_deck (required, relative to this deck); missions = 1000;
                   first_mission = 0 (global index of the first mission: a second half run
                   starts where the first ended); seed = 1 (master seed: mission i draws
                   from fold_in(PRNGKey(seed), i)); batch_missions = 256 (missions per task,
                   whole blocks of 32); scale = 1 (every dispersion × scale, digest S3);
                   sampling = "eigen" (CSAMP) | "cholesky"; noise_step_days (the
                   Gauss-Markov hold step, default min τ / 10, P-C3);
                   a_priori_statistics (earlier TSIM results files whose statistics this
                   run's are merged with, STAT-1); near_success_factor = 10 (GUIDS c_close);
                   impulse_propellant = "spent" (an impulsive correction's propellant,
                   at the impulsive engine's Isp, leaves the spacecraft: the later thrust
                   arcs accelerate a lighter vehicle) | "booked" (TEAM's model, where a
                   correction changes the velocity only: the propellant is subtracted from
                   the final mass but not flown); team_changes = {"field" = value, ...}
                   (TEAM-deck fields changed for this run, as a sweep varies them, e.g.
                   {"thrust_noise.proportionality.sigma" = 0.0})
    [insim.injection]   optional: the injection dispersions instead of the TEAM deck's
                   [control]: frame = "inertial" | "rtn" (radial, along-track, normal at
                   injection), position_sigma_km (3), velocity_sigma_km_s (3), mass_sigma_kg
    [[maneuver]]   name (a TEAM [[guidance]] name; maneuvers not named fly linear
                   guidance), law = "linear" | "nonlinear", max_iterations = 8,
                   tolerance (one per target, target units; default 0.1 km / 1e-6 km/s /
                   1e-7 rad / 1 s: fracas.build.tsim.default_tolerance), knowledge = "team" |
                   "deck" (knowledge covariance from
                   the TEAM run, or knowledge_position_sigma_km / knowledge_velocity_sigma_km_s
                   given here), enabled = true (false: the event is not flown)
    [output]       results = "out/<deck>_tsim.h5", plot = "out/<deck>_tsim.png"
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, PositiveFloat, PositiveInt, model_validator

from fracas.config.fields import LIGHT_KM_S, MAX_MASS_KG, MAX_POSITION_SIGMA_KM
from fracas.config.trajectory import (
    FieldProblem,
    SourcedDeck,
    _Section,
    parse_sourced,
    read_deck_text,
)
from fracas.config.trajectory.values import at_most
from fracas.errors import DeckError

__all__ = ["TsimDeck", "InSim", "Injection", "Maneuver", "parse_tsim_deck", "load_tsim_deck", "tsim_problems"]

MAX_MISSIONS = 10_000_000

#: the largest dispersion scale: a deviation scaled further is no longer small, and the
#: linear guidance TSIM flies (and compares with TEAM) is meaningless there
MAX_SCALE = 100.0
_Sigma = Annotated[float, Field(ge=0)]
_PositionSigma = Annotated[_Sigma, at_most(MAX_POSITION_SIGMA_KM, "km", "no knowledge at all")]
_VelocitySigma = Annotated[_Sigma, at_most(LIGHT_KM_S, "km/s", "the speed of light", strict=True)]
PositionSigmas = Annotated[list[_PositionSigma], Field(min_length=3, max_length=3)]
VelocitySigmas = Annotated[list[_VelocitySigma], Field(min_length=3, max_length=3)]


class Injection(_Section):
    """Injection dispersions (1σ) in a stated frame (the TEAM deck's [control] otherwise)."""

    frame: Literal["inertial", "rtn"] = "inertial"
    position_sigma_km: PositionSigmas
    velocity_sigma_km_s: VelocitySigmas
    mass_sigma_kg: Annotated[float, Field(ge=0), at_most(MAX_MASS_KG, "kg", "a million tonnes")] = 0.0


class InSim(_Section):
    """$INSIM: the run's size, seed and sampling (module docstring)."""

    team_deck: str
    missions: Annotated[int, Field(ge=1, le=MAX_MISSIONS)] = 1000
    first_mission: Annotated[int, Field(ge=0)] = 0
    seed: Annotated[int, Field(ge=0, lt=2**31)] = 1
    batch_missions: PositiveInt = 256
    scale: Annotated[float, Field(ge=0), at_most(MAX_SCALE, "", "a larger dispersion is no longer small")] = 1.0
    sampling: Literal["eigen", "cholesky"] = "eigen"
    noise_step_days: PositiveFloat | None = None
    near_success_factor: Annotated[float, Field(ge=1)] = 10.0
    impulse_propellant: Literal["spent", "booked"] = "spent"
    team_changes: dict[str, Any] = {}
    a_priori_statistics: list[str] = []
    injection: Injection | None = None


class Maneuver(_Section):
    """$INMAN: one maneuver's Monte Carlo settings (the TEAM guidance event gives the rest)."""

    name: str
    law: Literal["linear", "nonlinear"] = "linear"
    max_iterations: Annotated[int, Field(ge=1, le=50)] = 8
    tolerance: list[PositiveFloat] | None = None
    knowledge: Literal["team", "deck"] = "team"
    knowledge_position_sigma_km: PositionSigmas | None = None
    knowledge_velocity_sigma_km_s: VelocitySigmas | None = None
    enabled: bool = True

    @model_validator(mode="after")
    def _knowledge(self) -> Maneuver:
        given = self.knowledge_position_sigma_km is not None and self.knowledge_velocity_sigma_km_s is not None
        if self.knowledge == "deck" and not given:
            raise FieldProblem(
                "knowledge", "deck", "knowledge_position_sigma_km and knowledge_velocity_sigma_km_s with it"
            )
        if self.knowledge == "team" and (
            self.knowledge_position_sigma_km is not None or self.knowledge_velocity_sigma_km_s is not None
        ):
            raise FieldProblem("knowledge", "team", '"deck" when knowledge sigmas are given')
        return self


class TsimOutput(_Section):
    results: str | None = None
    plot: str | None = None


class TsimDeck(SourcedDeck):
    """A whole TSIM deck (frozen)."""

    mode: Literal["tsim"] = "tsim"
    title: str = ""
    insim: InSim
    maneuver: list[Maneuver] = []
    output: TsimOutput = TsimOutput()

    @model_validator(mode="after")
    def _cross_checks(self) -> TsimDeck:
        seen: dict[str, int] = {}
        for k, m in enumerate(self.maneuver):
            if m.name in seen:
                raise FieldProblem(("maneuver", k, "name"), m.name, f"repeats maneuver[{seen[m.name]}]")
            seen[m.name] = k
        return self


def parse_tsim_deck(text: str, source: str = "<deck>") -> TsimDeck:
    """Validate TSIM-deck TOML text; any problem -> one-line DeckError naming the field."""
    return parse_sourced(text, source, TsimDeck)


def load_tsim_deck(path: str | Path) -> TsimDeck:
    """Read and validate a TSIM deck; every failure is a one-line DeckError."""
    return parse_tsim_deck(read_deck_text(path), str(path))


def tsim_team_deck(deck: TsimDeck):
    """The TEAM deck a TSIM deck stands on (DeckError naming insim.team_deck when missing)."""
    from fracas.config.team import load_team_deck

    path = deck.resolve(deck.insim.team_deck)
    if not path.exists():
        raise DeckError(f"{deck.source_path}: insim.team_deck = {deck.insim.team_deck!r}: no such TEAM deck ({path})")
    return load_team_deck(path)


def tsim_problems(deck: TsimDeck) -> list[str]:
    """Every problem the schema alone cannot see, one line each, without JAX: the TEAM deck
    exists, validates and has guidance events; every [[maneuver]] names one of them; the
    tolerance lists match the event's targets; a nonlinear law is asked only of an
    impulsive event; the a-priori statistics files exist."""
    src = deck.source_path or "<deck>"
    try:
        team = tsim_team_deck(deck)
    except DeckError as exc:
        return list(exc.problems) or [str(exc)]
    out = []
    events = {g.name: g for g in team.guidance}
    if not events:
        out.append(f"{src}: insim.team_deck: {deck.insim.team_deck} has no [[guidance]] events (TSIM flies them)")
    for k, m in enumerate(deck.maneuver):
        g = events.get(m.name)
        if g is None:
            out.append(
                f"{src}: maneuver[{k}].name = {m.name!r}: not a guidance event of the TEAM deck "
                f"(expected one of: {', '.join(events) or 'none'})"
            )
            continue
        if m.tolerance is not None and len(m.tolerance) != len(g.targets):
            out.append(
                f"{src}: maneuver[{k}].tolerance: {len(m.tolerance)} entries; expected {len(g.targets)} "
                f"(one per target of {m.name}: {', '.join(g.targets)})"
            )
        if m.law == "nonlinear" and g.type != "impulsive":
            out.append(
                f'{src}: maneuver[{k}].law = "nonlinear": built for impulsive events only '
                f'({m.name} is {g.type}; expected "linear")'
            )
    for j, f in enumerate(deck.insim.a_priori_statistics):
        if not deck.resolve(f).exists():
            out.append(f"{src}: insim.a_priori_statistics[{j}] = {f!r}: no such TSIM results file")
    size = _table_size_problem(deck, team)
    if size:
        out.append(size)
    grid = _noise_grid_problem(deck, team)
    if grid:
        out.append(grid)
    return out


def _noise_grid_problem(deck: TsimDeck, team: Any) -> str | None:
    """The line naming insim.noise_step_days when the Gauss-Markov hold grid over the TEAM
    deck's trajectory would exceed its ``[limits] max_schedule_times`` (a typo such as 1e-9
    would build a grid of billions of points before any mission flies)."""
    from fracas.config.limits import count_text, range_count
    from fracas.config.trajectory import load_deck

    step = deck.insim.noise_step_days
    if step is None:
        return None
    try:
        dur = load_deck(team.resolve(team.ertraj.deck)).duration_days
    except DeckError:
        return None  # the TEAM deck's own checks name it
    n = range_count(0.0, abs(dur), step)
    if n <= team.limits.max_schedule_times:
        return None
    return (
        f"{deck.source_path or '<deck>'}: insim.noise_step_days = {step:g}: gives {count_text(n)} noise-grid "
        f"points over 0-{dur:g} d (limit {team.limits.max_schedule_times}, the TEAM deck's [limits] "
        "max_schedule_times); use a longer step"
    )


#: TSIM flies missions in blocks of this many (fracas.tsim.plan)
_BLOCK = 32


def table_bytes_floor(deck: TsimDeck, team: Any) -> int:
    """A lower bound of the bytes of the per-mission table a run holds and writes (the fields
    of :func:`fracas.tsim.engine.block_fields`, with the state at its smallest: the
    spacecraft state and the TEAM deck's parameters), from the decks alone."""
    n_events = len(team.guidance)
    thrust = 7  # a state row of state_deviation is always 7 wide
    n = 6 + len(team.parameter)
    controls = max([len(g.controls) if g.type in ("primary", "vernier") else 3 for g in team.guidance] + [3])
    targets = max([len(g.targets) for g in team.guidance] + [1])
    per = 8 + 4 + 4 + 8 + 8  # mission, status, failed maneuver, total dv, final mass
    per += n_events * (4 + 4 + 8)  # iterations, maneuver status, dv
    per += 8 * (n + n_events * (thrust + n + 2 * controls + 2 * targets) + targets)
    missions = -(-deck.insim.missions // _BLOCK) * _BLOCK
    return per * missions


def _table_size_problem(deck: TsimDeck, team: Any) -> str | None:
    """The line naming insim.missions when the table would take more than
    :data:`fracas.config.limits.MEMORY_FRACTION` of this machine's memory (checked before any
    work; the run checks the exact size again once its plan is built)."""
    from fracas.config.limits import MEMORY_FRACTION, machine_memory_bytes

    mem = machine_memory_bytes()
    need = table_bytes_floor(deck, team)
    if mem is None or need <= mem * MEMORY_FRACTION:
        return None
    return (
        f"{deck.source_path or '<deck>'}: insim.missions = {deck.insim.missions}: the per-mission table would take "
        f"at least {need / 2**30:.1f} GiB of this machine's {mem / 2**30:.1f} GiB (expected at most "
        f"{MEMORY_FRACTION:.0%}); split the run (first_mission, a_priori_statistics)"
    )
