"""The sweep deck: one TEAM study run many times with some of its fields varied (no JAX here).

Layout (``mode = "sweep"``; see docs/sweep.md)::

    mode = "sweep"
    title = "thrust noise sweep"
    [sweep]        study = "team_deck.toml"   (a TEAM deck, relative to this file)
                   combine = "grid" | "zip"   (every combination, or the i-th value of each)
                   outputs = ["position_rss_km", "velocity_rss_km_s", "sigma[thrust_scale]", ...]
                   stm_file = "stm_files/x.h5"  (optional: one STM file every study reuses;
                                                 built once first if missing)
                   keep_results = false, results_folder = "out/sweep_results"
                   max_studies = 10000
    [[sweep.vary]] field = "thrust_noise.proportionality.sigma"   (a TeamDeck field path,
                   list entries by index: "tracking[0].sigma")
                   values = [...]  |  start, stop, num, spacing = "linear" | "log"
    [output]       table = "out/sweep.h5"  (and out/sweep.csv), plot = "out/sweep.png"

Outputs (final values of each study, after its last event):
``position_rss_km`` / ``velocity_rss_km_s`` (assumed 1σ RSS of position / velocity),
``true_position_rss_km`` / ``true_velocity_rss_km_s`` (generalized covariance; the study
must have [gencov]), ``sigma[LABEL]`` (the assumed final 1σ of any covariance label, e.g.
``sigma[thrust_scale]``, ``sigma[x]``) and ``true_sigma[LABEL]``; per [[guidance]] event NAME
of the study: ``NAME.dv_mean_m_s`` / ``NAME.dv_99_m_s`` / ``NAME.dv_rms_m_s`` (the correction's
mean, 99 % and RMS |ΔV|, m/s), ``NAME.<target>_sigma_after`` (the target's 1σ after the
correction, the target's unit) and ``NAME.propellant_sigma_kg`` (low thrust).
"""

from __future__ import annotations

import math
import re
import typing
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, Field, model_validator

from fracas.config.fields import A_PRIORI_SECTIONS, THRUST_NOISE_SECTIONS, a_priori_paths, thrust_noise_paths
from fracas.config.team import TeamDeck
from fracas.config.trajectory import (
    FieldProblem,
    SourcedDeck,
    _Section,
    _strip,
    cut,
    deck_error,
    parse_sourced,
    read_deck_text,
    validation_problems,
)
from fracas.errors import DeckError

__all__ = [
    "SweepDeck",
    "Vary",
    "parse_sweep_deck",
    "load_sweep_deck",
    "parse_field_path",
    "check_field_path",
    "check_output_name",
    "FIXED_OUTPUTS",
    "GUIDANCE_OUTPUTS",
    "guidance_output",
    "output_unit",
    "DEFAULT_OUTPUTS",
    "NUMERIC_FIELDS",
    "is_numeric_field",
    "varied_deck",
    "output_problems",
    "sweep_problems",
    "study_label",
]

#: output name -> unit
FIXED_OUTPUTS = {
    "position_rss_km": "km",
    "velocity_rss_km_s": "km/s",
    "true_position_rss_km": "km",
    "true_velocity_rss_km_s": "km/s",
}
DEFAULT_OUTPUTS = ("position_rss_km", "velocity_rss_km_s")
_SIGMA_OUTPUT = re.compile(r"^(true_)?sigma\[([^\]]+)\]$")
#: per [[guidance]] event NAME: NAME.<quantity> -> unit (dV statistics in m/s; low thrust:
#: the propellant 1σ), and NAME.<target>_sigma_after (the target's 1σ after the correction,
#: in the target's unit)
GUIDANCE_OUTPUTS = {"dv_mean_m_s": "m/s", "dv_99_m_s": "m/s", "dv_rms_m_s": "m/s", "propellant_sigma_kg": "kg"}
_GUIDANCE_OUTPUT = re.compile(r"^([A-Za-z][A-Za-z0-9_\-]*)\.([A-Za-z_0-9]+)$")
_PART = re.compile(r"^([A-Za-z_][A-Za-z_0-9]*)((?:\[[0-9]+\])*)$")
MAX_STUDIES = 1_000_000
Scalar = float | int | bool | str


#: Fields whose value changes only numbers of a study (a-priori and parameter sigmas, noise
#: levels and correlation times, measurement sigmas), never its schedule, layout, labels,
#: roles, filter or reference: studies that differ only in these are batched into one
#: compiled computation (fracas.team.batch).  Paths with list indices dropped ("*" any
#: dict key).  Anything not listed is structural (its studies run one by one).
NUMERIC_FIELDS = frozenset(
    {
        *(path for table in A_PRIORI_SECTIONS for path in a_priori_paths(table)),  # fracas.config.fields
        "parameter.sigma",
        "tracking.sigma",
        *(path for table in THRUST_NOISE_SECTIONS for path in thrust_noise_paths(table)),
        "gencov.parameter.sigma",
        "gencov.measurement_sigma.*",
    }
)


def is_numeric_field(path: str) -> bool:
    """Whether varying ``path`` changes only numbers of a study (:data:`NUMERIC_FIELDS`)."""
    try:
        parts = parse_field_path(path)
    except ValueError:
        return False
    names = [p for p in parts if isinstance(p, str)]
    plain = ".".join(names)
    if plain in NUMERIC_FIELDS:
        return True
    return (
        len(names) == 3
        and names[:2] == ["gencov", "measurement_sigma"]
        and "gencov.measurement_sigma.*" in NUMERIC_FIELDS
    )


def parse_field_path(path: str) -> tuple[str | int, ...]:
    """``"tracking[0].sigma"`` -> ``("tracking", 0, "sigma")``; ValueError if malformed."""
    if not isinstance(path, str) or not path.strip():
        raise ValueError("a field path must be a non-empty string like thrust_noise.proportionality.sigma")
    out: list[str | int] = []
    for part in path.strip().split("."):
        m = _PART.match(part)
        if m is None:
            raise ValueError(f'malformed field path (at "{part}"), expected e.g. tracking[0].sigma')
        out.append(m.group(1))
        out.extend(int(i) for i in re.findall(r"\[([0-9]+)\]", m.group(2)))
    return tuple(out)


def check_field_path(path: str) -> tuple[str | int, ...]:
    """The parts of ``path`` if it names a field of :class:`TeamDeck`'s schema, else ValueError
    (saying where it goes wrong).  List entries need an index; dict entries take any key."""
    parts = parse_field_path(path)
    cur: Any = TeamDeck
    done = ""
    for part in parts:
        cur = _strip(cur)
        origin = typing.get_origin(cur)
        here = f"{done}[{part}]" if isinstance(part, int) else (f"{done}.{part}" if done else part)
        if origin is list:
            if not isinstance(part, int):
                raise ValueError(f"{done} is a list: give an index, e.g. {done}[0]")
            cur = typing.get_args(cur)[0]
        elif origin is dict:
            cur = typing.get_args(cur)[1]
        elif isinstance(part, str) and isinstance(cur, type) and issubclass(cur, BaseModel):
            if part not in cur.model_fields or part in ("mode",):
                known = ", ".join(k for k in cur.model_fields if k != "mode")
                raise ValueError(f"unknown field {here} (expected one of: {known})")
            cur = cur.model_fields[part].annotation
        else:
            raise ValueError(f"{done or '<deck>'} has no part {part!r}")
        done = here
    cur = _strip(cur)
    if isinstance(cur, type) and issubclass(cur, BaseModel):
        raise ValueError(f"{path} is a table; vary one of its fields, e.g. {path}.{next(iter(cur.model_fields))}")
    return parts


def guidance_output(name: str) -> tuple[str, str, str | None] | None:
    """``"tcm1.dv_99_m_s"`` -> ``("tcm1", "dv_99_m_s", None)``, ``"tcm1.b_dot_t_sigma_after"``
    -> ``("tcm1", "sigma_after", "b_dot_t")``; None if ``name`` is no guidance output; ValueError
    for an event output whose quantity or target is unknown."""
    from fracas.guidance.target_kinds import TARGET_KINDS

    m = _GUIDANCE_OUTPUT.match(name)
    if m is None:
        return None
    event, what = m.group(1), m.group(2)
    if what in GUIDANCE_OUTPUTS:
        return event, what, None
    if what.endswith("_sigma_after"):
        target = what[: -len("_sigma_after")]
        if target in TARGET_KINDS:
            return event, "sigma_after", target
        raise ValueError(f"output {name!r}: unknown target {target!r} (expected one of: {', '.join(TARGET_KINDS)})")
    raise ValueError(
        f"output {name!r}: unknown guidance output {what!r} (expected one of: {', '.join(GUIDANCE_OUTPUTS)}, "
        "<target>_sigma_after)"
    )


def output_unit(name: str) -> str | None:
    """The unit of an output known from its name alone (None: the covariance label's unit)."""
    from fracas.guidance.target_kinds import TARGET_KINDS

    if name in FIXED_OUTPUTS:
        return FIXED_OUTPUTS[name]
    g = guidance_output(name)
    if g is None:
        return None
    return GUIDANCE_OUTPUTS[g[1]] if g[2] is None else TARGET_KINDS[g[2]].unit


def check_output_name(name: str) -> str:
    if name in FIXED_OUTPUTS or _SIGMA_OUTPUT.match(name) or guidance_output(name) is not None:
        return name
    raise ValueError(
        f"unknown output {name!r} (expected one of: {', '.join(FIXED_OUTPUTS)}, sigma[LABEL], true_sigma[LABEL], "
        f"GUIDANCE_EVENT.{{{', '.join(GUIDANCE_OUTPUTS)}, TARGET_sigma_after}})"
    )


class Vary(_Section):
    """One varied field: its values, or ``num`` values from ``start`` to ``stop``."""

    field: str
    values: Annotated[list[Scalar], Field(min_length=1)] | None = None
    start: float | None = None
    stop: float | None = None
    num: Annotated[int, Field(ge=1, le=MAX_STUDIES)] | None = None
    spacing: Literal["linear", "log"] = "linear"

    @model_validator(mode="after")
    def _consistent(self) -> Vary:
        try:
            check_field_path(self.field)
        except ValueError as exc:
            raise FieldProblem("field", self.field, str(exc)) from None
        rng = (self.start, self.stop, self.num)
        if self.values is not None and any(v is not None for v in rng):
            raise FieldProblem((), None, "give values, or start + stop + num, not both")
        if self.values is None:
            if any(v is None for v in rng):
                raise FieldProblem((), None, "give values, or start + stop + num")
            if self.spacing == "log" and (self.start <= 0 or self.stop <= 0):
                raise FieldProblem("start", self.start, 'start and stop must be > 0 for spacing = "log"')
        elif self.spacing != "linear":
            raise FieldProblem("spacing", self.spacing, "only with start + stop + num")
        return self

    def points(self) -> list[Scalar]:
        """The values, in order (``numpy.linspace`` / ``logspace`` semantics, plain floats)."""
        if self.values is not None:
            return list(self.values)
        import numpy as np

        if self.spacing == "log":
            pts = np.logspace(math.log10(self.start), math.log10(self.stop), self.num)
        else:
            pts = np.linspace(self.start, self.stop, self.num)
        return [float(p) for p in pts]


class SweepSection(_Section):
    study: str
    vary: Annotated[list[Vary], Field(min_length=1)]
    combine: Literal["grid", "zip"] = "grid"
    outputs: Annotated[list[str], Field(min_length=1)] = list(DEFAULT_OUTPUTS)
    stm_file: str | None = None
    keep_results: bool = False
    results_folder: str | None = None
    max_studies: Annotated[int, Field(ge=1, le=MAX_STUDIES)] = 10_000

    @model_validator(mode="after")
    def _consistent(self) -> SweepSection:
        for k, name in enumerate(self.outputs):
            try:
                check_output_name(name)
            except ValueError as exc:
                raise FieldProblem(("outputs", k), name, str(exc)) from None
        if len(set(self.outputs)) != len(self.outputs):
            raise FieldProblem("outputs", self.outputs, "outputs must be unique")
        fields = [v.field for v in self.vary]
        for k, f in enumerate(fields):
            if f in fields[:k]:
                raise FieldProblem(("vary", k, "field"), f, f"repeats vary[{fields.index(f)}]")
        lengths = [len(v.points()) if v.values is not None else v.num for v in self.vary]
        if self.combine == "zip" and len(set(lengths)) != 1:
            raise FieldProblem(
                "combine", "zip", f"zip needs the same number of values in each vary entry, got {lengths}"
            )
        n = lengths[0] if self.combine == "zip" else math.prod(lengths)
        if n > self.max_studies:
            raise FieldProblem("vary", None, f"gives {n} studies (limit {self.max_studies}, sweep.max_studies)")
        return self


class SweepOutput(_Section):
    table: str | None = None
    plot: str | None = None


class SweepDeck(SourcedDeck):
    """A whole sweep deck (frozen)."""

    mode: Literal["sweep"] = "sweep"
    title: str = ""
    sweep: SweepSection
    output: SweepOutput = SweepOutput()

    def studies(self) -> list[tuple[Scalar, ...]]:
        """The varied values of every study, in order (grid: the last field varies fastest)."""
        import itertools

        pts = [v.points() for v in self.sweep.vary]
        if self.sweep.combine == "zip":
            return [tuple(p) for p in zip(*pts)]
        return [tuple(p) for p in itertools.product(*pts)]

    @property
    def fields(self) -> tuple[str, ...]:
        return tuple(v.field for v in self.sweep.vary)


def parse_sweep_deck(text: str, source: str = "<deck>") -> SweepDeck:
    """Validate sweep-deck TOML text; any problem -> one-line DeckError."""
    return parse_sourced(text, source, SweepDeck)


def load_sweep_deck(path: str | Path) -> SweepDeck:
    """Read and validate a sweep deck; every failure is a one-line DeckError."""
    return parse_sweep_deck(read_deck_text(path), str(path))


# ----------------------------------------------------------------------------- the studies of a sweep
#: at most this many failing studies are named one by one (then a count)
MAX_LISTED_STUDIES = 5


def _set(data: Any, parts: tuple, value: Any, field: str) -> Any:
    """``data`` (a dump) with the element at ``parts`` set to ``value`` (copies along the path)."""
    if not parts:
        return value
    head, rest = parts[0], parts[1:]
    if isinstance(head, int):
        if not isinstance(data, list) or not -len(data) <= head < len(data):
            n = len(data) if isinstance(data, list) else 0
            raise DeckError(f"{field}: index [{head}] is out of range (the study has {n} entries)")
        out = list(data)
        out[head] = _set(data[head], rest, value, field)
        return out
    out = dict(data) if isinstance(data, dict) else {}
    out[head] = (
        _set(out.get(head) if isinstance(out.get(head), (dict, list)) else {}, rest, value, field) if rest else value
    )
    return out


def varied_deck(deck: TeamDeck, values: dict[str, Any], source: str | None = None) -> TeamDeck:
    """``deck`` with each field of ``values`` (a dotted path, list entries by index) set to
    its value, validated again by TeamDeck's schema (every validator runs); the base deck's
    ``source_path``/``source_text`` are kept so relative paths resolve as before.  A refused
    value is a DeckError carrying every problem, one line each, prefixed with ``source``
    (default: the deck's path and the varied values)."""
    from pydantic import ValidationError

    data = deck.model_dump(mode="python", exclude_unset=True)
    for field, value in values.items():
        try:
            parts = check_field_path(field)
        except ValueError as exc:
            raise DeckError(f"{deck.source_path or '<deck>'}: vary {field}: {exc}") from None
        if hasattr(value, "item") and not isinstance(value, (list, dict, str)):
            value = value.item()  # a numpy scalar
        data = _set(data, parts, value, f"{deck.source_path or '<deck>'}: vary {field}")
    if source is None:
        source = f"{deck.source_path or '<deck>'} (varied {', '.join(f'{k} = {v!r}' for k, v in values.items())})"
    try:
        new = TeamDeck.model_validate(data)
    except ValidationError as exc:
        raise deck_error(validation_problems(exc, source, TeamDeck, data)) from None
    new._source_path = deck._source_path
    new._source_text = deck._source_text
    return new


def study_label(index: int, fields: tuple[str, ...], values: tuple) -> str:
    """``study 3 (thrust_noise.proportionality.sigma = -0.01)``: a study by index and swept values."""
    shown = ", ".join(f"{f} = {cut(repr(v), 40)}" for f, v in zip(fields, values))
    return f"study {index} ({shown})"


def output_problems(cfg: SweepDeck, base: TeamDeck) -> list[str]:
    """A guidance output the study cannot give (one line each, naming ``sweep.outputs[k]``):
    an event it does not have, a target not among the event's, the propellant of an
    impulsive event."""
    events = {g.name: g for g in (base.guidance or [])}
    out: list[str] = []
    for k, name in enumerate(cfg.sweep.outputs):
        g = guidance_output(name)
        if g is None:
            continue
        event, what, target = g
        where = f"{cfg.source_path or '<deck>'}: sweep.outputs[{k}] = {name!r}"
        e = events.get(event)
        if e is None:
            have = ", ".join(events) or "none"
            out.append(f"{where}: the study {base.source_path} has no guidance event {event!r} (it has: {have})")
        elif target is not None and target not in e.targets:
            out.append(
                f"{where}: guidance event {event!r} has no target {target!r} (its targets: {', '.join(e.targets)})"
            )
        elif what == "propellant_sigma_kg" and e.type not in ("primary", "vernier"):
            out.append(f"{where}: only for low-thrust guidance (primary, vernier); {event!r} is {e.type}")
    return out


def _field_in(base: TeamDeck, parts: tuple) -> bool:
    cur: Any = base.model_dump(mode="python")
    try:
        for p in parts:
            cur = cur[p]
    except (KeyError, IndexError, TypeError):
        return False
    return True


def sweep_problems(cfg: SweepDeck, base: TeamDeck) -> list[str]:
    """Everything a sweep would refuse, before any work (one line each; [] if none): a study
    without analysis, a varied field the base study does not have (a list index beyond its
    entries), a guidance output it cannot give, and every generated study validated by
    TeamDeck's schema, as the run will build it.  A failing study is named by the sweep
    deck, its index and swept values, then the field and what was expected; at most
    :data:`MAX_LISTED_STUDIES` failing studies are named, then a count of the others."""
    src = cfg.source_path or "<deck>"
    out: list[str] = []
    if not base.errcon.analysis:
        out.append(f"{base.source_path}: errcon.analysis = false: a sweep needs the analysis of each study")
    fields = cfg.fields
    missing = False
    for k, f in enumerate(fields):
        if not _field_in(base, parse_field_path(f)):
            missing = True
            out.append(
                f"{src}: sweep.vary[{k}].field = {f!r}: not in the study {base.source_path} "
                "(a list index beyond its entries, or a table the study does not have)"
            )
    out += output_problems(cfg, base)
    if missing:
        return out
    failing = 0
    for i, values in enumerate(cfg.studies()):
        try:
            varied_deck(base, dict(zip(fields, values)), source="")
        except DeckError as exc:
            failing += 1
            if failing <= MAX_LISTED_STUDIES:
                head = f"{src}: {study_label(i, fields, values)}"
                out += [head + (p if p.startswith(": ") else f": {p}") for p in exc.problems]
    if failing > MAX_LISTED_STUDIES:
        n = failing - MAX_LISTED_STUDIES
        out.append(f"{src}: and {n} more stud{'ies' if n > 1 else 'y'} that the study's schema refuses")
    return out
