"""The two-vehicle (rendezvous) navigation deck: Draper R-649's Apollo rendezvous filter
study as a TEAM-style covariance analysis with TSIM-style single runs (no JAX here).

Two vehicles, each with its own trajectory deck (its reference trajectory and STMs), an
augmented state [chaser (6); target (6); radar biases], relative range, range rate and two
line-of-sight angles, and the target's errors carried as solve-for (the optimum filter,
R-649 Eq. 20), consider (Schmidt) or ignore (the Apollo filter, Eq. 26, evaluated with
generalized covariance).  One run computes every role the deck lists, so they can be
compared on one page::

    mode = "rendezvous"
    title = "..."
    units = "km" | "m" | "ft"     every length in this deck (velocities: that unit per s)
    [chaser]    name, trajectory (a trajectory deck, relative to this deck), stm_file
                (optional: the vehicle's STM file, read when it exists, else built from the
                trajectory deck over the study's times and written), and its true
                a-priori: position_sigma (3) + velocity_sigma (3), or covariance (6 x 6, in
                units^2, units^2/s, units^2/s^2); filter_position_sigma / filter_velocity_sigma
                (3 each, optional): the diagonal W load the "ignore" role's filter starts
                from (the Apollo filter's 10,000 ft / 10 fps), default the true a priori
    [target]    name, trajectory, position_sigma + velocity_sigma or covariance,
                relative_a_priori = false (true: those are the errors of target - chaser,
                independent of the chaser's, so the target's a priori is E_A + E_rel with
                G_0 = E_A: a satellite ejected from the chaser, R-649 §II.E), and
                roles = ["solve_for", "consider", "ignore"] (one case per role)
    [[bias]]    name, measurement (the kind it adds to, coefficient 1), sigma (the
                measurement's deck unit: length, length/s or mrad), role = "consider" |
                "solve_for" | "ignore", tau_s (first-order Gauss-Markov; omitted: constant)
    [[tracking]]  start_min, stop_min, step_s, measurements (any of "range", "range_rate",
                "los_beta", "los_theta"): marks every step_s from start to stop (min from
                the chaser's epoch)
    [noise.<kind>]  the filter's (assumed) white noise: sigma (constant) or fraction (of
                the measured value) with floor; the real world's: true_sigma, or
                true_fraction + true_floor (default: the filter's).  Units: length,
                length/s, mrad.
    [sensor]    axes (3 x 3, rows i_xm, i_ym, i_zm in inertial axes; identity default):
                the frame of the two LOS angles (the Apollo radar: the IMU stable platform)
    [[reset]]   time_min, position_sigma (3), velocity_sigma (3), roles (default
                ["ignore"]): the assumed-covariance reset (UNF/Apollo W reinitialization;
                the true covariance continues)
    [[maneuver]]  name, time_min, arrival_min: an intercept maneuver solved on the
                estimated states (chaser arrives at the target's position at arrival_min);
                its uncertainty from knowledge errors (R-649 Fig. II-18)
    [single_runs] runs (0: none), seed, keep (runs stored in full in the results file),
                dynamics = "auto" | "linear" | "two_body" (true and estimated states flown on
                their conics with the nonlinear measurement models: the TSIM check of the
                linear analysis; point-mass ballistic references only)
    [output]    results = "out/<deck>.h5", plot = "out/<deck>.png"
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, PositiveFloat, model_validator

from fracas.config.trajectory import (
    FieldProblem,
    SourcedDeck,
    _Section,
    parse_sourced,
    read_deck_text,
)
from fracas.config.trajectory.plausible import state_warnings, warn
from fracas.errors import DeckError

#: a covariance's correlation form may dip this far below zero (rounding); fracas.filters.covariance.PSD_TOLERANCE
PSD_TOLERANCE = 1.0e-6

__all__ = [
    "RendezvousDeck",
    "parse_rendezvous_deck",
    "load_rendezvous_deck",
    "rendezvous_problems",
    "LENGTH_UNITS_KM",
    "RELATIVE_KIND_NAMES",
    "ROLES",
]

#: km per deck length unit
LENGTH_UNITS_KM = {"km": 1.0, "m": 1e-3, "ft": 0.3048e-3}
RELATIVE_KIND_NAMES = ("range", "range_rate", "los_beta", "los_theta")
ROLES = ("solve_for", "consider", "ignore")
RelKind = Literal["range", "range_rate", "los_beta", "los_theta"]
Role = Literal["solve_for", "consider", "ignore"]
Sigma3 = Annotated[list[Annotated[float, Field(ge=0)]], Field(min_length=3, max_length=3)]
Row6 = Annotated[list[float], Field(min_length=6, max_length=6)]
Row3 = Annotated[list[float], Field(min_length=3, max_length=3)]
MAX_MARKS = 200_000


class Vehicle(_Section):
    """One vehicle: its trajectory deck and true a-priori covariance (deck units)."""

    name: str
    trajectory: str
    stm_file: str | None = None
    position_sigma: Sigma3 | None = None
    velocity_sigma: Sigma3 | None = None
    covariance: Annotated[list[Row6], Field(min_length=6, max_length=6)] | None = None
    filter_position_sigma: Sigma3 | None = None
    filter_velocity_sigma: Sigma3 | None = None
    roles: list[Role] | None = None
    relative_a_priori: bool = False

    @model_validator(mode="after")
    def _a_priori(self) -> Vehicle:
        sig = self.position_sigma is not None or self.velocity_sigma is not None
        if self.covariance is not None and sig:
            raise FieldProblem("covariance", "...", "either covariance or position_sigma + velocity_sigma, not both")
        if self.covariance is None and (self.position_sigma is None or self.velocity_sigma is None):
            raise FieldProblem(
                "position_sigma", self.position_sigma, "position_sigma and velocity_sigma (or a covariance)"
            )
        if self.covariance is not None:
            c = self.covariance
            for i in range(6):
                for j in range(i):
                    if abs(c[i][j] - c[j][i]) > 1e-9 * max(abs(c[i][j]), abs(c[j][i]), 1e-300):
                        raise FieldProblem(("covariance", i, j), c[i][j], f"a symmetric matrix (covariance[{j}][{i}])")
        if (self.filter_position_sigma is None) != (self.filter_velocity_sigma is None):
            raise FieldProblem("filter_position_sigma", self.filter_position_sigma, "both filter sigmas or neither")
        return self


class Bias(_Section):
    """A measurement bias (R-649's beta): the kind it adds to, sigma, role, optional GM tau."""

    name: str
    measurement: RelKind
    sigma: Annotated[float, Field(ge=0)]
    role: Role = "consider"
    tau_s: PositiveFloat | None = None


class Tracking(_Section):
    """Marks every step_s from start_min to stop_min (min from the chaser's epoch)."""

    start_min: Annotated[float, Field(ge=0)]
    stop_min: Annotated[float, Field(ge=0)]
    step_s: PositiveFloat
    measurements: Annotated[list[RelKind], Field(min_length=1)]

    @model_validator(mode="after")
    def _span(self) -> Tracking:
        if self.stop_min < self.start_min:
            raise FieldProblem("stop_min", self.stop_min, f">= start_min ({self.start_min})")
        if (self.stop_min - self.start_min) * 60.0 / self.step_s > MAX_MARKS:
            raise FieldProblem("step_s", self.step_s, f"at most {MAX_MARKS} marks per entry")
        if len(set(self.measurements)) != len(self.measurements):
            raise FieldProblem("measurements", self.measurements, "each kind once")
        return self


class Noise(_Section):
    """White noise of one kind: constant sigma, or fraction of |q| with a floor (assumed; true_*)."""

    sigma: Annotated[float, Field(ge=0)] = 0.0
    fraction: Annotated[float, Field(ge=0, lt=1)] = 0.0
    floor: Annotated[float, Field(ge=0)] = 0.0
    true_sigma: Annotated[float, Field(ge=0)] | None = None
    true_fraction: Annotated[float, Field(ge=0, lt=1)] | None = None
    true_floor: Annotated[float, Field(ge=0)] | None = None

    @model_validator(mode="after")
    def _some(self) -> Noise:
        if self.sigma <= 0.0 and (self.fraction <= 0.0 or self.floor <= 0.0):
            raise FieldProblem("sigma", self.sigma, "> 0, or fraction > 0 with floor > 0 (a zero variance)")
        if self.sigma > 0.0 and self.fraction > 0.0:
            raise FieldProblem("fraction", self.fraction, "either sigma or fraction + floor, not both")
        if self.true_sigma is not None and (self.true_fraction is not None or self.true_floor is not None):
            raise FieldProblem("true_fraction", self.true_fraction, "either true_sigma or true_fraction + true_floor")
        if (self.true_fraction is None) != (self.true_floor is None):
            raise FieldProblem("true_fraction", self.true_fraction, "true_fraction and true_floor together")
        return self

    def true_model(self) -> tuple[float, float, float]:
        """(sigma, fraction, floor) of the real world: the true_* model when one is given
        (it replaces the filter's whole: a true_sigma means constant noise, whatever the
        filter assumes), else the filter's own."""
        if self.true_sigma is not None:
            return (self.true_sigma, 0.0, 0.0)
        if self.true_fraction is not None:
            return (0.0, self.true_fraction, float(self.true_floor))
        return (self.sigma, self.fraction, self.floor)


class NoiseTable(_Section):
    range: Noise | None = None
    range_rate: Noise | None = None
    los_beta: Noise | None = None
    los_theta: Noise | None = None


class Sensor(_Section):
    axes: Annotated[list[Row3], Field(min_length=3, max_length=3)] = [
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ]

    @model_validator(mode="after")
    def _orthonormal(self) -> Sensor:
        a = self.axes
        for i in range(3):
            for j in range(3):
                d = sum(a[i][k] * a[j][k] for k in range(3))
                if abs(d - (1.0 if i == j else 0.0)) > 1e-9:
                    raise FieldProblem("axes", a, "three orthonormal rows (i_xm, i_ym, i_zm)")
        return self


class Reset(_Section):
    """Assumed-covariance reset (W reinitialization): the filter restarts from these sigmas."""

    time_min: Annotated[float, Field(ge=0)]
    position_sigma: Sigma3
    velocity_sigma: Sigma3
    roles: list[Role] = ["ignore"]


class Maneuver(_Section):
    """An intercept maneuver at time_min arriving at the target's position at arrival_min."""

    name: str
    time_min: Annotated[float, Field(ge=0)]
    arrival_min: PositiveFloat

    @model_validator(mode="after")
    def _order(self) -> Maneuver:
        if self.arrival_min <= self.time_min:
            raise FieldProblem("arrival_min", self.arrival_min, f"> time_min ({self.time_min})")
        return self


class SingleRuns(_Section):
    """Single runs: how many, the seed, how many to keep in full, and how they fly: "linear"
    (errors carried by the reference STMs), "two_body" (true and estimated states on their
    conics, nonlinear measurements; point-mass ballistic references only) or "auto" (two_body
    when the references allow it)."""

    runs: Annotated[int, Field(ge=0, le=100_000)] = 0
    dynamics: Literal["auto", "linear", "two_body"] = "auto"
    seed: Annotated[int, Field(ge=0, lt=2**31)] = 1
    keep: Annotated[int, Field(ge=0, le=1000)] = 10


class Output(_Section):
    results: str | None = None
    plot: str | None = None


class RendezvousDeck(SourcedDeck):
    """A whole two-vehicle navigation deck (frozen); see the module docstring."""

    mode: Literal["rendezvous"] = "rendezvous"
    title: str = ""
    units: Literal["km", "m", "ft"] = "km"
    chaser: Vehicle
    target: Vehicle
    bias: list[Bias] = []
    tracking: Annotated[list[Tracking], Field(min_length=1)]
    noise: NoiseTable
    sensor: Sensor = Sensor()
    reset: list[Reset] = []
    maneuver: list[Maneuver] = []
    single_runs: SingleRuns = SingleRuns()
    output: Output = Output()

    @model_validator(mode="after")
    def _cross(self) -> RendezvousDeck:
        if self.chaser.roles is not None:
            raise FieldProblem(
                ("chaser", "roles"), self.chaser.roles, "roles only in [target] (the chaser is estimated)"
            )
        roles = self.target.roles or ["solve_for"]
        if len(set(roles)) != len(roles) or not roles:
            raise FieldProblem(("target", "roles"), roles, "one or more distinct roles")
        used = {k for t in self.tracking for k in t.measurements}
        for k in sorted(used):
            if getattr(self.noise, k) is None:
                raise FieldProblem(("noise", k), None, f"a [noise.{k}] table (tracking uses {k})")
        for name, items in (("bias", self.bias), ("maneuver", self.maneuver)):
            seen: dict[str, int] = {}
            for i, b in enumerate(items):
                if b.name in seen:
                    raise FieldProblem((name, i, "name"), b.name, f"repeats {name}[{seen[b.name]}]")
                seen[b.name] = i
        for i, b in enumerate(self.bias):
            if b.measurement not in used:
                raise FieldProblem(
                    ("bias", i, "measurement"), b.measurement, f"a tracked kind ({', '.join(sorted(used))})"
                )
        for i, r in enumerate(self.reset):
            for role in r.roles:
                if role not in roles:
                    raise FieldProblem(("reset", i, "roles"), r.roles, f"roles of [target] ({', '.join(roles)})")
        return self

    @property
    def roles(self) -> list[str]:
        return list(self.target.roles or ["solve_for"])

    @property
    def km_per_unit(self) -> float:
        return LENGTH_UNITS_KM[self.units]


def parse_rendezvous_deck(text: str, source: str = "<deck>") -> RendezvousDeck:
    """Validate rendezvous-deck TOML text; any problem -> one-line DeckError naming the field."""
    return parse_sourced(text, source, RendezvousDeck)


def load_rendezvous_deck(path: str | Path) -> RendezvousDeck:
    """Read and validate a rendezvous deck; every failure is a one-line DeckError."""
    return parse_rendezvous_deck(read_deck_text(path), str(path))


def vehicle_deck(deck: RendezvousDeck, which: str):
    """The trajectory deck of ``which`` ("chaser" | "target"); DeckError naming the field."""
    from fracas.config.trajectory import load_deck

    v = getattr(deck, which)
    path = deck.resolve(v.trajectory)
    if not path.exists():
        raise DeckError(f"{deck.source_path}: {which}.trajectory = {v.trajectory!r}: no such trajectory deck ({path})")
    return load_deck(path)


def rendezvous_problems(deck: RendezvousDeck) -> list[str]:
    """Every problem the schema alone cannot see, one line each, without JAX: both
    trajectory decks exist and validate, share one centre and are ballistic over the study."""
    src = deck.source_path or "<deck>"
    out, decks = [], {}
    for which in ("chaser", "target"):
        try:
            decks[which] = vehicle_deck(deck, which)
            warn(state_warnings(decks[which]))  # a unit slip in the initial state, most likely (not refused)
        except DeckError as exc:
            out.extend(exc.problems or [str(exc)])
    if len(decks) == 2:
        ca, ct = decks["chaser"].initial_state.centre, decks["target"].initial_state.centre
        if ca != ct:
            out.append(
                f"{src}: target.trajectory: centre {ct!r} differs from the chaser's {ca!r} (expected one centre)"
            )
        end = max(
            [t.stop_min for t in deck.tracking]
            + [r.time_min for r in deck.reset]
            + [m.arrival_min for m in deck.maneuver]
        )
        shift_min = (decks["chaser"].epoch.et - decks["target"].epoch.et) / 60.0
        if shift_min < -1e-8:
            out.append(
                f"{src}: target.trajectory: its epoch is {-shift_min:.3f} min after the chaser's; "
                "expected the target's epoch at or before the chaser's"
            )
        for which, d in decks.items():
            dur_min = d.duration_days * 1440.0
            need = end + (max(shift_min, 0.0) if which == "target" else 0.0)
            if dur_min + 1e-9 < need:
                out.append(
                    f"{src}: {which}.trajectory: {getattr(deck, which).trajectory} lasts {dur_min:.1f} min; "
                    f"expected >= {need:.1f} min (the last mark, reset or arrival"
                    + (", from its own earlier epoch)" if which == "target" and shift_min > 0 else ")")
                )
    for which in ("chaser", "target"):
        cov = getattr(deck, which).covariance
        if cov is not None:
            w = np.linalg.eigvalsh(np.asarray(cov, dtype=np.float64))
            scale = np.sqrt(np.abs(np.diag(cov))).max() if np.any(np.diag(cov)) else 1.0
            # scale-free: the smallest eigenvalue of the correlation form, as TEAM's psd_check
            d = np.sqrt(np.maximum(np.diag(cov), 1e-300 * scale**2))
            wc = np.linalg.eigvalsh(np.asarray(cov, dtype=np.float64) / np.outer(d, d))
            if wc.min() < -PSD_TOLERANCE:
                out.append(
                    f"{src}: {which}.covariance: not positive semidefinite (smallest eigenvalue {w.min():.4g} "
                    f"{deck.units}^2 units; of the correlation matrix {wc.min():.3g}); expected a covariance matrix"
                )
    return out
