"""The TOM deck: targeting and final-mass optimization (FRACAS $DATA, $SMAG; report §3.1).

A TOM deck is a trajectory deck (inline, as in any ``fracas propagate`` deck, or named by
``[trajectory] deck``) plus the tables below.  Values are in the units an analyst writes:
times in days, angles in degrees, km, km/s, kg (:data:`fracas.params.CONTROL_KINDS` gives
each control's unit, :data:`fracas.guidance.target_kinds.TARGET_KINDS` each target's; a
target in rad is written in deg, one in s in days).  No JAX here::

    mode = "tom"
    [trajectory]   deck = "trajectory.toml"  (relative to this file; else the trajectory
                   tables are inline)
    [tom]          submode = "auto" (TEST decides) | "grid" | "target" | "target_optimize" | "optimize" | "nominal"
                   optimizer = "projected_gradient" | "slsqp" | "trust_constr"
                   sensitivities = "ad" | "fegs"  (FEGS: forward finite differences)
                   max_iterations = 100, max_performance_change_kg (ΔF_max; default 0.5 %
                   of the initial mass), correction_fraction = 1 (p), linearity_radius (R, in
                   scaled units: tolerances of the most sensitive target; default none),
                   max_scale_factor = 4 (γ_max), curve_fit_tolerance = 0.1 (η),
                   dependent_angle_deg = 1 (STEST θ_min), convergence_angle_rad = 1e-3
                   (TEST θ_conv), targeting_threshold = 10 (T_up), optimization_threshold = 1
                   (T_low; both on the RMS of ΔT_i/ε_i), weighting = "sensitivity" | "control",
                   departure_body (for the vinf controls; default the deck's centre),
                   results = "out/<deck>_tom.h5", reference_deck = "out/<deck>_reference.toml",
                   plot = "out/<deck>_tom.png", stm_file (optional: an STM file of the optimum)
    [[control]]    name ("arc_t_off[0]", "vx0", "impulse_dv[0,1]", ...; or any name with
                   ``links``), nominal (default the trajectory's value), scale = 1 (WEIGHT's
                   k_j), lower, upper, fd_step (FEGS δU; default 1e-6 max(|U|, 1) in deck
                   units), links = {"arc_beta[0]" = 1.0, "arc_beta[1]" = -1.0} (a linked
                   control: each named control moves by coefficient × this one)
    [[target]]     name, value, tolerance (> 0), body (default the stop body, else the
                   centre); evaluated at the stop (the stop condition or the final time)
    [smag]         s = [[..], ..] (targets × controls), g = [..]  (given S and G for the
                   first iteration, in deck units per deck unit)
    [grid]         increments = [..] (one per control, deck units), steps = 4 (±1..±steps
                   increments), pairs = true
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, PositiveFloat, PositiveInt, PrivateAttr, ValidationError, model_validator

from fracas.config.limits import MAX_GRID_TRAJECTORIES, count_text, grid_count
from fracas.config.trajectory import (
    BodyName,
    FieldProblem,
    SourcedDeck,
    TrajectoryDeck,
    _Section,
    _strip_bom,
    deck_error,
    load_toml,
    read_deck_text,
    validation_problems,
)
from fracas.config.trajectory.plausible import state_warnings, warn
from fracas.errors import DeckError
from fracas.guidance.target_kinds import TARGET_KINDS
from fracas.params import CONTROL_KINDS

__all__ = [
    "FirstGuess",
    "TomDeck",
    "TomSettings",
    "ControlSpec",
    "TargetSpec",
    "parse_tom_deck",
    "load_tom_deck",
    "SUBMODES",
]

SUBMODES = ("auto", "grid", "target", "target_optimize", "optimize", "nominal")
OPTIMIZERS = ("projected_gradient", "slsqp", "trust_constr", "ipopt")
_TOM_KEYS = ("mode", "title", "trajectory", "tom", "control", "target", "smag", "grid")


class TrajectoryRef(_Section):
    """$DATA's trajectory part named by file: a trajectory deck (relative to this deck)."""

    deck: str


class FirstGuess(_Section):
    """[tom.first_guess]: TOM's automatic first guess for low-thrust problems
    (:mod:`fracas.tom.first_guess`).  Pass 1 cuts the thrust window into ``segments`` contiguous
    arcs, each with its own throttle (when ``throttle``) and constant pointing as controls, from
    half throttle and thrust along the velocity; pass 2 merges the thrusting segments into burns
    with full throttle, each split into at most ``max_arcs_per_burn`` contiguous arcs until a
    Legendre law of ``degree`` fits the pass-1 pointing within ``max_fit_error_deg``, and
    optimizes their switch times and pointing laws.  The deck's own thrust arcs are replaced.
    ``segments`` defaults to 12 per revolution of the initial osculating orbit over the window,
    at least 24 and at most 120 (a burn pattern repeats about twice per revolution)."""

    # None: 12 per revolution of the initial osculating orbit over the window, within [24, 120]
    segments: Annotated[int, Field(ge=2, le=120)] | None = None
    start_days: float | None = None  # the thrust window (default: the whole flight)
    stop_days: float | None = None
    throttle: bool | None = None  # a throttle per segment; default: true when maximizing the final mass
    out_of_plane: bool = True  # beta (and its law) as controls; false keeps the thrust in the orbit plane
    degree: Annotated[int, Field(ge=0, le=3)] = 3
    max_fit_error_deg: PositiveFloat = 5.0
    max_arcs_per_burn: Annotated[int, Field(ge=1, le=8)] = 4
    frame: Literal["velocity", "inertial"] = "velocity"

    @model_validator(mode="after")
    def _window(self) -> FirstGuess:
        if self.start_days is not None and self.stop_days is not None and self.stop_days <= self.start_days:
            raise FieldProblem("stop_days", self.stop_days, f"must be > start_days = {self.start_days:g}")
        return self


class TomSettings(_Section):
    """$DATA's iteration inputs (names and recommended defaults: digest §A.2)."""

    submode: Literal["auto", "grid", "target", "target_optimize", "optimize", "nominal"] = "auto"
    optimizer: Literal["projected_gradient", "slsqp", "trust_constr", "ipopt"] = "projected_gradient"
    sensitivities: Literal["ad", "fegs"] = "ad"
    max_iterations: PositiveInt = 100
    max_performance_change_kg: PositiveFloat | None = None
    correction_fraction: Annotated[float, Field(gt=0, le=1)] = 1.0
    linearity_radius: PositiveFloat | None = None  # None: no radius (ΔF_max, p and the line search bound the step)
    max_scale_factor: Annotated[float, Field(ge=1)] = 4.0
    curve_fit_tolerance: PositiveFloat = 0.1
    dependent_angle_deg: Annotated[float, Field(ge=0, lt=90)] = 1.0
    convergence_angle_rad: PositiveFloat = 1e-3
    targeting_threshold: PositiveFloat = 10.0
    optimization_threshold: PositiveFloat = 1.0
    weighting: Literal["sensitivity", "control"] = "control"
    # what the search maximizes: the final mass, or a target kind's value about a body at the stop
    # (e.g. "radius": Bryson & Ho's maximum-radius transfer); maximize = false minimizes it
    performance: str = "final_mass"
    performance_body: BodyName | None = None
    maximize: bool = True
    departure_body: BodyName | None = None
    first_guess: FirstGuess | None = None
    results: str | None = None
    reference_deck: str | None = None
    plot: str | None = None
    stm_file: str | None = None

    @model_validator(mode="before")
    @classmethod
    def _first_guess_optimizer(cls, data):
        # a low-thrust first guess defaults to IPOPT: the projected gradient cannot do its passes
        # (Earth-Mars: pass 1 stopped at E_rms 1e6, pass 2 0.7 % short after 200 iterations)
        if isinstance(data, dict) and data.get("first_guess") is not None and "optimizer" not in data:
            data = {**data, "optimizer": "ipopt"}
        return data

    @model_validator(mode="after")
    def _thresholds(self) -> TomSettings:
        if self.performance != "final_mass" and self.performance not in TARGET_KINDS:
            raise FieldProblem(
                "performance", self.performance, f'"final_mass" or a target kind: {", ".join(TARGET_KINDS)}'
            )
        if self.performance == "final_mass" and not self.maximize:
            raise FieldProblem("maximize", self.maximize, 'true for performance = "final_mass"')
        if self.optimization_threshold >= self.targeting_threshold:
            raise FieldProblem(
                "optimization_threshold",
                self.optimization_threshold,
                f"must be < targeting_threshold = {self.targeting_threshold:g}",
            )
        return self


class ControlSpec(_Section):
    """One control U_j ($DATA control codes): a catalogue name, or a linked combination."""

    name: str
    nominal: float | None = None
    scale: PositiveFloat = 1.0
    lower: float | None = None
    upper: float | None = None
    fd_step: PositiveFloat | None = None
    links: dict[str, float] = {}

    @model_validator(mode="after")
    def _checks(self) -> ControlSpec:
        names = list(self.links) if self.links else [self.name]
        for n in names:
            base = n.split("[")[0].strip()
            if base not in CONTROL_KINDS:
                where = ("links", n) if self.links else "name"
                raise FieldProblem(where, n, f"a control from the catalogue: {', '.join(CONTROL_KINDS)}")
        for n, c in self.links.items():
            if c == 0.0 or not math.isfinite(c):
                raise FieldProblem(("links", n), c, "a nonzero, finite coefficient")
        if self.lower is not None and self.upper is not None and self.lower >= self.upper:
            raise FieldProblem("upper", self.upper, f"must be > lower = {self.lower:g}")
        if self.nominal is not None:
            if self.lower is not None and self.nominal < self.lower:
                raise FieldProblem("nominal", self.nominal, f"must be >= lower = {self.lower:g}")
            if self.upper is not None and self.nominal > self.upper:
                raise FieldProblem("nominal", self.nominal, f"must be <= upper = {self.upper:g}")
        return self


class TargetSpec(_Section):
    """One target T_i with its tolerance ε_i (deck units: km, km/s, deg, days, 1)."""

    name: str
    value: float
    tolerance: PositiveFloat
    body: BodyName | None = None

    @model_validator(mode="after")
    def _known(self) -> TargetSpec:
        if self.name not in TARGET_KINDS:
            raise FieldProblem("name", self.name, f"a target from the catalogue: {', '.join(TARGET_KINDS)}")
        return self


class Smag(_Section):
    """$SMAG: S (targets × controls) and G (controls) for the first iteration."""

    s: list[list[float]]
    g: list[float]


class GridSpec(_Section):
    """GRID: each control alone over ±1..±steps increments, and (pairs) every pair."""

    increments: list[PositiveFloat]
    steps: PositiveInt = 4
    pairs: bool = True


class TomDeck(SourcedDeck):
    """A whole TOM deck (frozen).  ``trajectory_deck`` is the inline trajectory, if any."""

    mode: Literal["tom"] = "tom"
    title: str = ""
    trajectory: TrajectoryRef | None = None
    tom: TomSettings = TomSettings()
    control: list[ControlSpec] = []
    target: list[TargetSpec] = []
    smag: Smag | None = None
    grid: GridSpec | None = None
    _inline: TrajectoryDeck | None = PrivateAttr(None)

    # C901 on purpose: a flat list of independent deck checks, each raising the one problem it finds
    @model_validator(mode="after")
    def _cross_checks(self) -> TomDeck:  # noqa: C901
        if not self.control and self.tom.first_guess is None:
            raise FieldProblem("control", [], "at least one [[control]] (or a [tom.first_guess] table)")
        if self.tom.first_guess is not None:
            for k, c in enumerate(self.control):
                for n in list(c.links) or [c.name]:
                    if n.strip().startswith("arc_"):
                        raise FieldProblem(
                            ("control", k, "links" if c.links else "name"),
                            n,
                            "no thrust-arc control with [tom.first_guess] (it makes the arcs and their controls)",
                        )
            if self.tom.submode in ("grid", "nominal", "target"):
                raise FieldProblem(
                    ("tom", "submode"),
                    self.tom.submode,
                    'an optimizing submode ("auto", "target_optimize", "optimize") with [tom.first_guess]',
                )
        seen: dict[str, int] = {}
        for k, c in enumerate(self.control):
            if c.name in seen:
                raise FieldProblem(("control", k, "name"), c.name, f"already control {seen[c.name]}")
            seen[c.name] = k
        m, n = len(self.control), len(self.target)
        if self.smag is not None:
            if len(self.smag.s) != n or any(len(row) != m for row in self.smag.s):
                raise FieldProblem(("smag", "s"), f"{len(self.smag.s)} rows", f"{n} rows (targets) of {m} (controls)")
            if len(self.smag.g) != m:
                raise FieldProblem(("smag", "g"), f"{len(self.smag.g)} entries", f"{m} entries (one per control)")
        if self.tom.submode == "grid":
            if self.grid is None:
                raise FieldProblem("grid", None, 'a [grid] table (increments) for submode = "grid"')
        if self.grid is not None and len(self.grid.increments) != m:
            raise FieldProblem(
                ("grid", "increments"), f"{len(self.grid.increments)} entries", f"{m} entries (one per control)"
            )
        if self.grid is not None:
            n_grid = grid_count(m, self.grid.steps, self.grid.pairs)
            if n_grid > MAX_GRID_TRAJECTORIES:
                raise FieldProblem(
                    ("grid", "steps"),
                    self.grid.steps,
                    f"gives {count_text(n_grid)} trajectories for {m} controls"
                    f"{' and their pairs' if self.grid.pairs else ''} (limit {MAX_GRID_TRAJECTORIES}, one batch); "
                    "use fewer steps",
                )
        if self.tom.submode in ("target", "target_optimize", "auto") and not self.target:
            raise FieldProblem("target", [], f'at least one [[target]] for submode = "{self.tom.submode}"')
        return self

    @property
    def trajectory_deck(self) -> TrajectoryDeck | None:
        """The inline trajectory deck (None when [trajectory] names a file)."""
        return self._inline


def parse_tom_deck(text: str, source: str = "<deck>") -> TomDeck:
    """Validate TOM-deck TOML text; any problem -> one-line DeckError naming the field.

    The TOM tables are validated as :class:`TomDeck`; every other table is the inline
    trajectory deck, validated as :class:`TrajectoryDeck` (``mode`` dropped), unless
    ``[trajectory] deck`` names one (then no trajectory table may be inline)."""
    text = _strip_bom(text)
    data = load_toml(text, source)
    tom_data = {k: v for k, v in data.items() if k in _TOM_KEYS}
    traj_data = {k: v for k, v in data.items() if k not in _TOM_KEYS}
    problems: list[str] = []
    deck = None
    try:
        deck = TomDeck.model_validate(tom_data)
    except ValidationError as exc:
        problems += validation_problems(exc, source, TomDeck, tom_data)
    inline = None
    if "trajectory" in tom_data and traj_data:
        problems.append(
            f"{source}: {', '.join(sorted(traj_data))}: not expected with [trajectory] deck "
            "(give the trajectory inline or by file, not both)"
        )
    elif "trajectory" not in tom_data:
        if "title" in data:
            traj_data["title"] = data["title"]
        try:
            inline = TrajectoryDeck.model_validate(traj_data, context={"source": source})
        except ValidationError as exc:
            problems += validation_problems(exc, source, TrajectoryDeck, traj_data)
    if problems:
        raise deck_error(problems)
    deck._source_path = source
    deck._source_text = text
    if inline is not None:
        inline._source_path = source
        inline._source_text = text
        deck._inline = inline
    return deck


def load_tom_deck(path: str | Path) -> TomDeck:
    """Read and validate a TOM deck; every failure is a one-line DeckError."""
    return parse_tom_deck(read_deck_text(path), str(path))


def tom_trajectory_deck(deck: TomDeck) -> TrajectoryDeck:
    """The trajectory deck a TOM deck stands on: inline, or the file [trajectory] names."""
    if deck.trajectory_deck is not None:
        return deck.trajectory_deck
    from fracas.config.trajectory import load_deck

    path = deck.resolve(deck.trajectory.deck)
    if not path.exists():
        raise DeckError(
            f"{deck.source_path}: trajectory.deck = {deck.trajectory.deck!r}: no such trajectory deck ({path})"
        )
    return load_deck(path)


# C901 on purpose: a flat list of independent checks against the trajectory deck, one problem line each
def tom_problems(deck: TomDeck) -> list[str]:  # noqa: C901
    """Every problem of a parsed TOM deck the schema alone cannot see, one line each, without
    JAX: the trajectory deck exists and validates; every control names an arc or impulse the
    trajectory has and a final_time control comes with stop.condition = "time"; every
    target body is one whose state the trajectory's model carries."""
    from fracas.params import parse_control

    src = deck.source_path or "<deck>"
    try:
        traj = tom_trajectory_deck(deck)
    except DeckError as exc:
        return list(exc.problems) or [str(exc)]
    warn(state_warnings(traj))  # a unit slip in the initial state, most likely (not refused)
    out = []
    n_arcs, n_imp = len(traj.thrust_arc), len(traj.impulse)
    for j, c in enumerate(deck.control):
        names = list(c.links) if c.links else [c.name]
        for name in names:
            field = f"control[{j}]." + (f"links.{name}" if c.links else "name")
            try:
                kind, _ = parse_control(name, n_arcs, n_imp)
            except KeyError as exc:
                out.append(f"{src}: {field} = {name!r}: {str(exc).strip(chr(34) + chr(39))}")
                continue
            if kind.name == "final_time" and traj.stop.condition != "time":
                out.append(f'{src}: {field} = "final_time": only with stop.condition = "time"')
            if kind.name in ("vinf", "vinf_ra", "vinf_dec", "final_time") and c.links:
                out.append(f"{src}: {field} = {name!r}: cannot be linked")
    out += _nominal_problems(deck, traj, src)
    bodies = {traj.initial_state.centre, *traj.forces.third_bodies, *traj.forces.conic_bodies}
    if traj.stop.body:
        bodies.add(traj.stop.body)
    if traj.forces.srp or (traj.propulsion is not None and traj.propulsion.power_source == "solar" and traj.thrust_arc):
        bodies.add("sun")
    default = traj.stop.body or traj.initial_state.centre
    for i, t in enumerate(deck.target):
        body = t.body or default
        if body not in bodies and not traj.forces.change_primary_at_soi:
            out.append(
                f"{src}: target[{i}].body = {body!r}: not in the trajectory's model ({', '.join(sorted(bodies))}); "
                "add it to forces.third_bodies or make it the stop body"
            )
    fg = deck.tom.first_guess
    if fg is not None:
        if traj.propulsion is None:
            out.append(f"{src}: tom.first_guess: the trajectory has no [propulsion] section to thrust with")
        for name in ("start_days", "stop_days"):
            value = getattr(fg, name)
            if value is not None and not 0.0 <= value <= traj.duration_days:
                out.append(
                    f"{src}: tom.first_guess.{name} = {value:g}: within the flight, [0, {traj.duration_days:g}] days"
                )
    if deck.tom.departure_body is not None and deck.tom.departure_body not in bodies:
        out.append(f"{src}: tom.departure_body = {deck.tom.departure_body!r}: not in the trajectory's model")
    return out


def _trajectory_value(traj, kind: str, idx: tuple[int, ...]) -> float | None:
    """The trajectory deck's own value of a control (deck units), for the kinds a deck states
    directly; None for the others (the state, v∞, propulsion: checked when the case is built)."""
    if kind.startswith("arc_"):
        arc = traj.thrust_arc[idx[0]]
        direct = {
            "arc_t_on": arc.start_days,
            "arc_t_off": arc.stop_days,
            "arc_duration": arc.stop_days - arc.start_days,
            "arc_alpha": arc.alpha_deg,
            "arc_beta": arc.beta_deg,
            "arc_throttle": arc.throttle,
        }
        if kind in direct:
            return direct[kind]
        for angle in ("alpha", "beta"):
            for n in (1, 2, 3):
                if kind == f"arc_{angle}_p{n}":
                    coeffs = getattr(arc, f"{angle}_legendre_deg")
                    return coeffs[n - 1] if n <= len(coeffs) else 0.0
        return None
    if kind == "impulse_t":
        return traj.impulse[idx[0]].time_days
    if kind == "impulse_dv":
        return traj.impulse[idx[0]].dv_km_s[idx[1]]
    if kind == "final_time":
        return traj.duration_days
    return None


def _nominal_problems(deck: TomDeck, traj, src: str) -> list[str]:
    """Each control's starting value (its nominal, else the trajectory's) within its bounds (the
    deck's, else the catalogue's; times within the flight), and the thrust arcs at the starting
    values in order: each arc's start <= its end <= the next arc's start (arcs cannot overlap:
    where they did, thrust doubled and pointing angles added)."""
    from fracas.params import parse_control

    out: list[str] = []
    n_arcs, n_imp = len(traj.thrust_arc), len(traj.impulse)
    starts = [a.start_days for a in traj.thrust_arc]
    stops = [a.stop_days for a in traj.thrust_arc]
    moved: dict[int, int] = {}  # arc -> the control that moves it (for the message)
    span = sorted((0.0, traj.duration_days))
    for j, c in enumerate(deck.control):
        if c.links:
            continue
        try:
            kind, idx = parse_control(c.name, n_arcs, n_imp)
        except KeyError:
            continue  # reported above
        value = c.nominal if c.nominal is not None else _trajectory_value(traj, kind.name, idx)
        if value is None:
            continue
        lo = c.lower if c.lower is not None else kind.bounds[0]
        hi = c.upper if c.upper is not None else kind.bounds[1]
        if kind.name in ("arc_t_on", "arc_t_off", "impulse_t"):
            lo = span[0] if lo is None else lo
            hi = span[1] if hi is None else hi
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            which = "nominal" if c.nominal is not None else "name"
            origin = "" if c.nominal is not None else " (the trajectory's value)"
            bounds = f"[{'-inf' if lo is None else f'{lo:g}'}, {'inf' if hi is None else f'{hi:g}'}]"
            out.append(f"{src}: control[{j}].{which} = {value:g}{origin}: within its bounds {bounds} {kind.unit}")
        if kind.name == "arc_t_on":
            starts[idx[0]] = value
            moved[idx[0]] = j
        elif kind.name == "arc_t_off":
            stops[idx[0]] = value
            moved[idx[0]] = j
        elif kind.name == "arc_duration":
            stops[idx[0]] = starts[idx[0]] + value
            moved[idx[0]] = j
    for k in range(n_arcs):
        nxt = starts[k + 1] if k + 1 < n_arcs else math.inf
        if not starts[k] <= stops[k] <= nxt:
            j = moved.get(k, moved.get(k + 1))
            where = f"control[{j}].nominal" if j is not None else f"thrust_arc[{k}]"
            out.append(
                f"{src}: {where}: thrust_arc[{k}] would run {starts[k]:g}-{stops[k]:g} d"
                + (f" and thrust_arc[{k + 1}] start at {nxt:g} d" if k + 1 < n_arcs else "")
                + ": arcs in order, each start <= its end <= the next start (arcs cannot invert or overlap)"
            )
    return out
