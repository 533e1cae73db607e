"""``fracas validate``'s checks of trajectory and TEAM decks, without running (or importing)
anything heavy.  :func:`fracas.modes.check_path` reads a deck of any mode and asks its mode
(the registry) for these; each returns every problem found, one line each (``source: field
= value: expected``; an empty list means the deck is valid):

* the schema (all problems, not only the first: :attr:`fracas.errors.FracasError.problems`);
* a TEAM deck's trajectory deck ([ertraj] deck: exists, parses, its sizes) and the sizes
  that need its duration (:func:`fracas.config.limits.team_size_problems`);
* parameter labels against the catalogues (:func:`fracas.params.parse_label` with the
  trajectory's bodies, arcs and impulses; measurement labels against the stations);
* files a run reads: an STM file ([errcon] stm_file when the run does not build it: an
  HDF5 file of file_kind "fracas-stm" built from this trajectory, by its hash) and a
  punch file ([a_priori] from_punch: file_kind "fracas-punch"); only attributes are read;
* a user gain ``module:function``: importable and callable (this imports the module);
* files a run writes ([output] results/plot, [punch] file, [errcon] stm_file when built):
  not a directory, the folder exists or can be created, and is writable (nothing is created).

No JAX is imported (the deck, the catalogues and h5py only), so this takes milliseconds per
deck: about 5-20 ms per bundled deck in a warm process on the 2-core development machine.
"""

from __future__ import annotations

import importlib
import types
from collections.abc import Iterable
from pathlib import Path

from fracas.build.trajectory import model_bodies
from fracas.config.limits import team_size_problems
from fracas.config.team import TeamDeck
from fracas.config.team.span import team_span_problems
from fracas.config.trajectory import (
    BACKWARD_TEAM_PROBLEM,
    TrajectoryDeck,
    cut,
    load_deck,
    trajectory_hash,
)
from fracas.config.trajectory.plausible import state_warnings, warn
from fracas.errors import FracasError, OutputPathError
from fracas.io.atomic import check_output_path
from fracas.measurements.kinds import check_measurement_label, is_measurement_label
from fracas.params import parse_label

__all__ = ["trajectory_problems", "team_problems", "output_problems"]

_BUILTIN_STATIONS = ("goldstone", "madrid", "canberra")


def _line(src: str, field: str, value, expected: str) -> str:
    if value is None:
        return f"{src}: {field}: {expected}"
    v = f'"{cut(value)}"' if isinstance(value, str) else cut(str(value))
    return f"{src}: {field} = {v}: {expected}"


def _guidance_problems(deck, tdeck: TrajectoryDeck, src: str) -> list[str]:
    """[[guidance]] against the trajectory: target times within it, a low-thrust event on an
    existing thrust arc (the same checks as fracas.build.guidance, without building)."""
    out: list[str] = []
    dur = tdeck.duration_days
    arcs = list(tdeck.thrust_arc)
    for k, g in enumerate(deck.guidance):
        f = f"guidance[{k}]"
        t_f = g.target_time_days if g.target_time_days is not None else dur
        if t_f > dur * (1 + 1e-12):
            out.append(_line(src, f"{f}.target_time_days", t_f, f"must be within the trajectory (<= {dur:g} d)"))
        if g.time_days > dur * (1 + 1e-12):
            out.append(_line(src, f"{f}.time_days", g.time_days, f"must be within the trajectory (<= {dur:g} d)"))
        if g.type not in ("primary", "vernier"):
            continue
        if g.arc is None or g.arc >= len(arcs):
            have = f"0..{len(arcs) - 1}" if arcs else "none: the trajectory deck has no [[thrust_arc]]"
            out.append(_line(src, f"{f}.arc", g.arc, f"expected a thrust arc ({have})"))
            continue
        arc = arcs[g.arc]
        if not (arc.start_days - 1e-9 <= g.time_days < arc.stop_days):
            out.append(
                _line(
                    src,
                    f"{f}.time_days",
                    g.time_days,
                    f"must lie on thrust_arc[{g.arc}] ({arc.start_days:g} to {arc.stop_days:g} d)",
                )
            )
        if "t_on" in g.controls and abs(g.time_days - arc.start_days) > 1e-9:
            out.append(
                _line(
                    src,
                    f"{f}.controls",
                    g.controls,
                    f"t_on is a control only when the guidance starts the arc (time_days = {arc.start_days:g})",
                )
            )
        if t_f < arc.stop_days:
            out.append(_line(src, f"{f}.target_time_days", t_f, f"must not precede the cutoff ({arc.stop_days:g} d)"))
    return out


def _model(tdeck: TrajectoryDeck) -> types.SimpleNamespace:
    """What :func:`fracas.params.parse_label` reads of a force model, from the deck alone."""
    return types.SimpleNamespace(
        bodies=model_bodies(tdeck), n_arcs=len(tdeck.thrust_arc), n_impulses=len(tdeck.impulse)
    )


def _label_problem(label: str, model, stations, src: str, field: str, dynamic_only: bool = False) -> str | None:
    try:
        parse_label(label, model)
        return None
    except KeyError as exc:
        dyn_msg = str(exc).strip("'\"")
    if not dynamic_only and is_measurement_label(label):
        try:
            check_measurement_label(label, stations)
            return None
        except KeyError as exc:
            return _line(src, field, label, str(exc).strip("'\""))
    return _line(src, field, label, dyn_msg)


def _output_problem(path: Path, src: str, field: str, rel: str) -> str | None:
    """A file a run will write, checked as the run will check it (:func:`fracas.io.atomic.check_output_path`)."""
    try:
        check_output_path(path, field)
    except OutputPathError as exc:
        return _line(src, field, rel, exc.reason)
    return None


def output_problems(deck, fields: Iterable[tuple[str, str | None]]) -> list[str]:
    """The files a run writes that the deck names (``(field, path as written)``; None: not
    named), each checked as the run checks it (:func:`fracas.io.atomic.check_output_path`),
    so that ``fracas validate`` refuses what the run would (a plot named ``"."``, a folder,
    an unwritable place), one line each naming the field."""
    src = deck.source_path or "<deck>"
    out = []
    for field, rel in fields:
        if rel:
            problem = _output_problem(deck.resolve(rel), src, field, rel)
            if problem:
                out.append(problem)
    return out


def _h5_attrs(path: Path, group: str | None = None) -> dict | str:
    """The attributes of an HDF5 file (or one of its groups), or why they cannot be read (the
    file's integrity is checked first, :func:`fracas.io.hdf5.file_problem`: a damaged file
    never reaches the HDF5 library, whose decoder can loop on some damage)."""
    from fracas.io.hdf5 import file_problem, one_line  # noqa: PLC0415 (only when a deck names a file to read)

    why = file_problem(path)
    if why is not None:
        return why
    import h5py  # noqa: PLC0415

    try:
        with h5py.File(path, "r") as f:
            node = f if group is None else f.get(group)
            if node is None:
                return {}
            return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in node.attrs.items()}
    except (OSError, KeyError, ValueError, RuntimeError) as exc:
        return f"unreadable HDF5 file ({one_line(exc)})"


def _input_problems(path: Path, src: str, field: str, rel: str, kind: str, thash: str | None) -> list[str]:
    if not path.exists():
        return [_line(src, field, rel, f"no such file ({path})")]
    if path.is_dir():
        return [_line(src, field, rel, f"is a directory ({path}); expected a {kind} file")]
    attrs = _h5_attrs(path)
    if isinstance(attrs, str):
        return [_line(src, field, rel, f"{attrs} ({path}); expected a {kind} file")]
    if attrs.get("file_kind") != kind:
        return [_line(src, field, rel, f"file_kind = {attrs.get('file_kind')!r}, expected {kind!r}")]
    if thash is not None:
        got = attrs.get("trajectory_hash")
        if got is None and kind == "fracas-stm":
            sub = _h5_attrs(path, "trajectory_deck")
            got = sub.get("trajectory_hash") if isinstance(sub, dict) else None
        if got and str(got) != thash:
            return [
                _line(
                    src, field, rel, f"was built from another trajectory (hash {str(got)[:12]}, this one {thash[:12]})"
                )
            ]
    why = _content_problem(path, kind)
    return [_line(src, field, rel, why)] if why else []


def _content_problem(path: Path, kind: str) -> str | None:
    """What a run would refuse inside the file: its reader's checks (every dataset there,
    dtypes, shapes, finite values, checksums, schema version), or None."""
    from fracas.errors import FracasError  # noqa: PLC0415

    try:
        if kind == "fracas-stm":
            from fracas.io.stm_file import read_stm_file  # noqa: PLC0415

            read_stm_file(path)
        elif kind == "fracas-punch":
            from fracas.io.team_results import read_punch  # noqa: PLC0415

            read_punch(path, "")
    except FracasError as exc:
        msg = str(exc)
        return msg.split(f"{path}", 1)[-1].lstrip('": ') or msg  # the reason, without the path
    return None


def trajectory_problems(tdeck: TrajectoryDeck) -> list[str]:
    """A trajectory deck's labels against its force model; an implausible initial state is
    warned about on stderr (:mod:`fracas.config.trajectory.plausible`), not refused."""
    warn(state_warnings(tdeck))
    src = tdeck.source_path or "<deck>"
    model = _model(tdeck)
    out = []
    for k, lab in enumerate(tdeck.output.sensitivities):
        p = _label_problem(lab, model, (), src, f"output.sensitivities[{k}]", dynamic_only=True)
        if p:
            out.append(p)
    return out


def team_problems(deck: TeamDeck) -> list[str]:
    try:
        return _team_checks(deck)
    except OSError as exc:  # a path no file system accepts (too long, NUL, ...)
        src = deck.source_path or "<deck>"
        return [f"{src}: a file named in the deck is not a usable path ({exc.strerror or type(exc).__name__})"]


def _reference_deck(deck: TeamDeck, src: str) -> tuple[TrajectoryDeck | None, list[str]]:
    """The study's trajectory deck ([ertraj] deck), or None with why not."""
    path = deck.resolve(deck.ertraj.deck)
    if not path.exists():
        return None, [_line(src, "ertraj.deck", deck.ertraj.deck, f"no such trajectory deck ({path})")]
    try:
        tdeck = load_deck(path)
    except FracasError as exc:
        return None, list(exc.problems)
    if tdeck.backward:
        return None, [_line(src, "ertraj.deck", deck.ertraj.deck, BACKWARD_TEAM_PROBLEM)]
    return tdeck, []


def _against_trajectory(deck: TeamDeck, tdeck: TrajectoryDeck, src: str) -> list[str | None]:
    """Labels, sizes, guidance and event times checked against the trajectory deck."""
    out: list[str | None] = [
        *trajectory_problems(tdeck),
        *team_span_problems(deck, tdeck),
        *team_size_problems(deck, tdeck),
    ]
    model = _model(tdeck)
    stations = set(_BUILTIN_STATIONS) | {s.name for s in deck.station}
    for k, p in enumerate(deck.parameter):
        out.append(_label_problem(p.label, model, stations, src, f"parameter[{k}].label"))
    if deck.gencov is not None:
        for k, g in enumerate(deck.gencov.parameter):
            if g.role == "ignore":
                out.append(_label_problem(g.label, model, stations, src, f"gencov.parameter[{k}].label"))
    for k, lab in enumerate(deck.stm.parameters):
        out.append(_label_problem(lab, model, stations, src, f"stm.parameters[{k}]", dynamic_only=True))
    dur = tdeck.duration_days
    out += _guidance_problems(deck, tdeck, src)
    for k, e in enumerate(deck.event):
        late = [t for t in e.times() if t > dur * (1 + 1e-12)]
        if late:
            out.append(_line(src, f"event[{k}]", None, f"times must be within the trajectory (<= {dur:g} d)"))
        if e.predict_to_days is not None and e.predict_to_days > dur * (1 + 1e-12):
            out.append(
                _line(src, f"event[{k}].predict_to_days", e.predict_to_days, f"must be <= {dur:g} d (the trajectory)")
            )
    return out


def _files_read(deck: TeamDeck, src: str, thash: str | None) -> list[str | None]:
    """The STM file (read, or built: then written), the punch file and the user gain."""
    out: list[str | None] = []
    ec = deck.errcon
    if ec.stm_file:
        spath = deck.resolve(ec.stm_file)
        if ec.build_stm is True or (ec.build_stm == "if_missing" and not spath.exists()):
            out.append(_output_problem(spath, src, "errcon.stm_file", ec.stm_file))
        else:
            out += _input_problems(spath, src, "errcon.stm_file", ec.stm_file, "fracas-stm", thash)
    if deck.a_priori is not None and deck.a_priori.from_punch:
        rel = deck.a_priori.from_punch
        out += _input_problems(deck.resolve(rel), src, "a_priori.from_punch", rel, "fracas-punch", None)
    if deck.filter.user_gain and deck.filter.type == "user":
        spec = deck.filter.user_gain
        mod, _, fn = spec.partition(":")
        try:
            obj = getattr(importlib.import_module(mod), fn)
        except Exception as exc:  # noqa: BLE001 (any failure of the user's module is a deck problem)
            out.append(_line(src, "filter.user_gain", spec, f"cannot import it ({cut(str(exc), 80)})"))
        else:
            if not callable(obj):
                out.append(_line(src, "filter.user_gain", spec, "is not callable"))
    return out


def _team_checks(deck: TeamDeck) -> list[str]:
    src = deck.source_path or "<deck>"
    tdeck, out = _reference_deck(deck, src)
    found: list[str | None] = list(out)
    if tdeck is not None:
        found += _against_trajectory(deck, tdeck, src)
    thash = trajectory_hash(tdeck) if tdeck is not None else None
    found += _files_read(deck, src, thash)
    for field, rel in (
        ("output.results", deck.output.results),
        ("output.plot", deck.output.plot),
        ("punch.file", deck.punch.file if deck.punch is not None else None),
    ):
        if rel:
            found.append(_output_problem(deck.resolve(rel), src, field, rel))
    return [p for p in found if p]
