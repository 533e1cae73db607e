"""A namelist deck -> the TOML deck(s) of its mode (``fracas import-namelist``).

:func:`import_namelist` reads the deck (:mod:`~fracas.config.namelist.scan`), decides the mode
(:func:`_detect`), fills each mapped variable into the deck it belongs to (:func:`_part_of`,
:mod:`~fracas.config.namelist.values`), fixes the fields that are not one-to-one
(:mod:`~fracas.config.namelist.post`), then names the sub-decks, writes the TOML texts and
validates each by its schema (:func:`_assemble`), an error naming the namelist field it came
from (:func:`_renamed`)."""

from __future__ import annotations

import re
from pathlib import Path

import tomli_w

from fracas.config.namelist.fields import (
    _MODE_GROUPS,
    _MODE_LABELS,
    KNOWN_GROUPS,
    NAMELIST_MODES,
    TOM_FIELDS,
    TRAJECTORY_FIELDS,
)
from fracas.config.namelist.post import _post
from fracas.config.namelist.results import ImportResult, Unmapped, _loc_text
from fracas.config.namelist.scan import _parse, _read_text, _scan_outside
from fracas.config.namelist.team_fields import ERTRAJ_FIELDS, KNOWN_UNMAPPED, _table
from fracas.config.namelist.values import _fill, _fix_lists, _Target, _trim
from fracas.errors import DeckError


def _detect(groups: list[str], label: str | None, forced: str | None, src: str) -> tuple[str, str]:
    """(mode, how it was decided)."""
    present = set(groups)
    if forced is not None:
        if forced == "sweep":
            raise DeckError(
                f"{src}: --mode sweep: FRACAS has no sweep mode, so no namelist maps to a sweep deck "
                "(import the TEAM study, then write the [sweep] deck around it)"
            )
        if forced not in NAMELIST_MODES:
            raise DeckError(f"{src}: mode {forced!r}: expected one of: {', '.join(NAMELIST_MODES)}")
        need = {"propagate": ("DATA", "ERTRAJ"), "tom": ("DATA",), "team": ("ERTRAJ",), "tsim": ("INSIM",)}[forced]
        if not present & set(need):
            raise DeckError(
                f"{src}: mode {forced}: the deck has no ${' or $'.join(need)} namelist (it has ${', $'.join(groups)})"
            )
        return forced, "forced"
    if label is not None:
        mode = _MODE_LABELS[label]
        return mode, f"the deck's mode label {label!r}"
    if "INSIM" in present:
        return "tsim", "$INSIM present"
    if present & {"ERRCON", "ERTRAJ", "ERANAL", "GENCOV"}:
        return "team", "TEAM namelists present"
    if "SMAG" in present:
        return "tom", "$SMAG present"
    return "propagate", "$DATA only"


#: the reason given for text outside any group
_OUTSIDE = "text outside a namelist group: not read (event schedule cards are [[tracking]]/[[event]] arrays in $ERANAL)"


def import_namelist(
    text_or_path: str | Path, source: str | None = None, mode: str | None = None, name: str | None = None
) -> ImportResult:
    """A FRACAS namelist deck -> the TOML deck(s) of its mode, every unmapped field listed.

    ``text_or_path``: a Path, or a str: the deck's text when it has a newline or one of
    ``& $ =``, else a path; ``source``: the name in messages (default
    the path); ``mode``: force a mode (propagate, tom, team, tsim); ``name``: the stem of the
    companion decks (default the source's stem).  Mode (unless forced): the deck's mode label,
    else tsim with $INSIM, team with $ERRCON/$ERTRAJ/$ERANAL/$GENCOV, tom with $SMAG or TOM
    fields in $DATA, else propagate.  Groups the mode does not read, unknown groups, unknown
    fields and FRACAS fields without an equivalent are all reported in ``unmapped``.  A deck
    f90nml cannot read, a value of the wrong type or a missing required field: one DeckError
    naming the file, ``$GROUP.NAME`` and what was expected.  Each deck is validated by its
    schema (sub-decks named by file are checked by ``fracas validate`` once written)."""
    text, src = _read_text(text_or_path, source)
    label, outside = _scan_outside(text)
    parsed = _parse(text, src)
    groups = list(dict.fromkeys(g for g, _, _ in parsed))
    if mode is None and label is None and _tom_fields_in_data(groups, parsed):
        mode = "tom"
    the_mode, how = _detect(groups, label, mode, src)
    stem = name or (Path(src).stem if src and not src.startswith("<") else "imported")
    notes = [f"mode {the_mode} ({how})"]
    unmapped = [Unmapped("-", f"line {number}", line, _OUTSIDE) for number, line in outside]
    tgt = _Target()
    used = _MODE_GROUPS[the_mode]
    if the_mode == "propagate" and "DATA" not in groups:
        used = ("ERTRAJ",)
    ertraj_inline = False
    for group, occ, body in parsed:
        if _is_read(group, occ, body, used, the_mode, src, unmapped):
            ertraj_inline |= _read_group(tgt, group, occ, body, the_mode, src, notes, unmapped)
    for part, data in tgt.parts.items():
        grp = "DATA" if part in ("traj", "tom") and "DATA" in used else "ERTRAJ"
        _post(data, part, src, grp, notes)
        tgt.parts[part] = _fix_lists(data, src)
    return _assemble(tgt, the_mode, src, stem, notes, unmapped, ertraj_inline)


def _tom_fields_in_data(groups: list[str], parsed: list[tuple[str, int, dict]]) -> bool:
    """A deck of $DATA (no $INSIM, $ERRCON, $ERTRAJ or $SMAG) giving a TOM-only field: a TOM deck."""
    if "DATA" in groups and not set(groups) & {"INSIM", "ERRCON", "ERTRAJ", "SMAG"}:
        tom_names = {f.name for f in TOM_FIELDS} - {f.name for f in TRAJECTORY_FIELDS}
        if any(k in tom_names for g, _, body in parsed if g == "DATA" for k in body):
            return True
    return False


def _is_read(
    group: str, occ: int, body: dict, used: tuple[str, ...], mode: str, src: str, unmapped: list[Unmapped]
) -> bool:
    """Whether the mode reads this group; its fields listed in ``unmapped`` when not (a repeated
    group other than $INMAN: DeckError)."""
    if group not in KNOWN_GROUPS:
        for k, v in body.items():
            unmapped.append(Unmapped(group, k, v, f"unknown namelist group ${group}: not read"))
        if not body:
            unmapped.append(Unmapped(group, "-", "", f"unknown namelist group ${group}: not read"))
        return False
    if group not in used:
        for k, v in body.items():
            unmapped.append(Unmapped(group, k, v, f"${group} is not read in {mode} mode"))
        return False
    if occ > 0 and group != "INMAN":
        raise DeckError(f"{src}: ${group}: given {occ + 1} times; expected once (only $INMAN repeats)")
    return True


def _read_group(
    tgt: _Target,
    group: str,
    occ: int,
    body: dict,
    mode: str,
    src: str,
    notes: list[str],
    unmapped: list[Unmapped],
) -> bool:
    """Fill every mapped variable of one group occurrence into its deck's data (the others into
    ``unmapped``, each unit conversion into ``notes``); whether $ERTRAJ gave trajectory fields."""
    ertraj_inline = False
    table = {f.name: f for f in _table(group, mode)}
    traj_names = {f.name for f in TRAJECTORY_FIELDS}
    for key, value in body.items():
        if value is None or (isinstance(value, list) and not _trim(value)):
            continue  # NAME = (no value): not given
        f = table.get(key)
        if f is None:
            reason = KNOWN_UNMAPPED.get((group, key), "unknown field: not read")
            if group == "DATA" and key in {t.name for t in TOM_FIELDS} and key not in traj_names:
                reason = f"a TOM input: not read in {mode} mode (--mode tom reads it)"
            unmapped.append(Unmapped(group, key, value, reason))
            continue
        part, prefix = _part_of(group, key, mode, occ)
        if part == "ignored":
            unmapped.append(Unmapped(group, key, value, f"not read in {mode} mode"))
            continue
        if part == "traj" and group == "ERTRAJ":
            ertraj_inline = True
        _fill(tgt, part, prefix, f, value, src, group)
        if f.scale != 1.0:
            what = _loc_text(tuple(x for x in f.path if x != "*"))
            notes.append(f"${group}.{key} ({f.unit or 'namelist unit'}) x {f.scale:g} -> {what}")
    return ertraj_inline


def _part_of(group: str, key: str, mode: str, occ: int) -> tuple[str, tuple]:
    """Which deck a group's field fills, and the path prefix there."""
    traj_names = {f.name for f in TRAJECTORY_FIELDS}
    if group == "DATA":
        return ("tom" if mode == "tom" else "traj"), ()
    if group == "SMAG":
        return "tom", ()
    if group == "ERTRAJ":
        if key in {f.name for f in ERTRAJ_FIELDS}:
            return ("team" if mode != "propagate" else "ignored"), ()
        if key in traj_names:
            return "traj", ()
    if group in ("INSIM",):
        return "tsim", ()
    if group == "INMAN":
        return "tsim", ("maneuver", occ)
    if mode == "propagate":
        return "ignored", ()
    return "team", ()


def _assemble(
    tgt: _Target,
    mode: str,
    src: str,
    stem: str,
    notes: list[str],
    unmapped: list[Unmapped],
    ertraj_inline: bool,
) -> ImportResult:
    """Name the sub-decks, write the TOML texts, validate each by its schema."""
    parts = tgt.parts
    parts.pop("ignored", None)
    traj_name, team_name = f"{stem}_traj.toml", f"{stem}_team.toml"
    if mode in ("team", "tsim"):
        _name_sub_decks(parts, mode, src, notes, ertraj_inline, traj_name, team_name)
    if mode == "tom":
        tom = parts.pop("tom", {})
        tom = {"mode": "tom", **tom}
        parts = {"tom": tom}
    files = {"traj": traj_name, "team": team_name, "tom": None, "tsim": None}
    main = {"propagate": "traj", "tom": "tom", "team": "team", "tsim": "tsim"}[mode]
    if main not in parts:
        raise DeckError(
            f"{src}: no fields of the {mode} mode's namelists ({', '.join('$' + g for g in _MODE_GROUPS[mode])})"
        )
    texts = _validated_texts(parts, tgt, mode, src)
    decks = {part: parts[part] for part in texts}
    companions = {files[part]: text for part, text in texts.items() if part != main}
    head = _header(src, mode, unmapped)
    for fname in companions:
        companions[fname] = (
            f"# {'Imported'} by fracas import-namelist from {src} (a sub-deck of the {mode} deck)\n"
            + (companions[fname])
        )
    return ImportResult(
        toml=head + texts[main],
        mode=mode,
        companions=companions,
        unmapped=unmapped,
        notes=notes,
        mapped=tgt.mapped,
        decks=decks,
    )


def _name_sub_decks(
    parts: dict[str, dict],
    mode: str,
    src: str,
    notes: list[str],
    ertraj_inline: bool,
    traj_name: str,
    team_name: str,
) -> None:
    """A TEAM or TSIM import: its trajectory named by file (ertraj.deck) and a TSIM deck's TEAM
    study too (insim.team_deck), unless the deck names them itself; each part given its mode."""
    team = parts.setdefault("team", {})
    ertraj = team.setdefault("ertraj", {})
    has_team = any(k != "ertraj" for k in team) or "deck" in ertraj or ertraj_inline
    if mode == "tsim" and parts.get("tsim", {}).get("insim", {}).get("team_deck") and not has_team:
        parts.pop("team")
    else:
        if "deck" in ertraj and ertraj_inline:
            raise DeckError(
                f"{src}: $ERTRAJ.DECK: names a trajectory deck and $ERTRAJ also gives trajectory "
                "fields; give one or the other"
            )
        if "deck" not in ertraj:
            if "traj" not in parts:
                raise DeckError(f"{src}: $ERTRAJ: required (the reference trajectory's fields, or DECK)")
            ertraj["deck"] = traj_name
            notes.append(f"the $ERTRAJ trajectory is written as {traj_name} (ertraj.deck)")
        team = {"mode": "team", **team}
        parts["team"] = team
        if mode == "tsim":
            insim = parts.setdefault("tsim", {}).setdefault("insim", {})
            if insim.get("team_deck"):
                raise DeckError(
                    f"{src}: $INSIM.TEAMDK: names a TEAM deck and the deck also gives the TEAM "
                    "namelists; give one or the other"
                )
            insim["team_deck"] = team_name
            notes.append(f"the TEAM namelists are written as {team_name} (insim.team_deck)")
    if mode == "tsim":
        tsim = parts.setdefault("tsim", {})
        tsim.setdefault("insim", {})
        parts["tsim"] = {"mode": "tsim", **tsim}


def _validated_texts(parts: dict[str, dict], tgt: _Target, mode: str, src: str) -> dict[str, str]:
    """Each part's TOML text, validated by its deck's schema (an error names the namelist fields)."""
    from fracas.config.team import parse_team_deck
    from fracas.config.tom import parse_tom_deck
    from fracas.config.trajectory import parse_deck
    from fracas.config.tsim import parse_tsim_deck

    checks = {"traj": parse_deck, "team": parse_team_deck, "tom": parse_tom_deck, "tsim": parse_tsim_deck}
    texts = {}
    for part, data in parts.items():
        parse = checks[part]
        text = _toml_text(data, part)
        label = f"{src} (imported {part} deck)"
        try:
            parse(text, label)
        except DeckError as exc:
            raise _renamed(exc, label, src, part, tgt, mode) from None
        texts[part] = text
    return texts


_ARRAY = re.compile(r"= \[\n((?:    [^\[\]{}\n]*,\n)+)\]")


def _toml_text(data: dict, part: str) -> str:
    """TOML text of a deck's data: keys in the schema's order, short arrays on one line."""
    from fracas.config.team import TeamDeck
    from fracas.config.tom import TomDeck
    from fracas.config.trajectory import TrajectoryDeck
    from fracas.config.tsim import TsimDeck

    order = {
        "traj": list(TrajectoryDeck.model_fields),
        "team": list(TeamDeck.model_fields),
        "tom": list(TomDeck.model_fields) + list(TrajectoryDeck.model_fields),
        "tsim": list(TsimDeck.model_fields),
    }[part]
    rank = {k: i for i, k in enumerate(order)}
    data = dict(sorted(data.items(), key=lambda kv: rank.get(kv[0], len(rank))))
    text = tomli_w.dumps(data)

    def one_line(m: re.Match) -> str:
        items = [x.strip().rstrip(",") for x in m.group(1).splitlines()]
        line = "= [" + ", ".join(items) + "]"
        return line if len(line) <= 100 else m.group(0)

    return _ARRAY.sub(one_line, text)


def _header(src: str, mode: str, unmapped: list[Unmapped]) -> str:
    """The imported deck's header comment: where it came from and every field not mapped."""
    lines = [
        f"# Imported by fracas import-namelist from {src} ({mode} mode).",
        "# Units converted: see docs/namelist.md.",
    ]
    if unmapped:
        lines.append(f"# {len(unmapped)} namelist field(s) not mapped:")
        lines += [f"#   {u}" for u in unmapped]
    else:
        lines.append("# Every namelist field was mapped.")
    return "\n".join(lines) + "\n\n"


def _pattern_names(mode: str, part: str) -> list[tuple[str, str]]:
    """(TOML path pattern text, $GROUP.NAME) of every field that fills ``part`` (for error lines)."""
    out = []
    groups = {
        "traj": ("DATA" if mode in ("propagate", "tom") else "ERTRAJ",),
        "tom": ("DATA", "SMAG"),
        "team": ("ERRCON", "ERTRAJ", "ERANAL", "GENCOV"),
        "tsim": ("INSIM", "INMAN"),
    }[part]
    for g in groups:
        for f in _table(g, mode if mode != "propagate" else "tom"):
            if f.name == "ICOORD":
                continue
            parts = [p for p in f.path if not (isinstance(p, str) and p.startswith("@"))]
            pat = ""
            for p in parts:
                pat += "[*]" if p == "*" else (f"[{p}]" if isinstance(p, int) else ("." if pat else "") + p)
            if g == "INMAN":
                pat = "maneuver[*]." + pat
            out.append((pat, f"${g}.{f.name}"))
    return out


def _renamed(exc: DeckError, label: str, src: str, part: str, tgt: _Target, mode: str) -> DeckError:
    """A schema error of an imported deck, its TOML field named as the namelist field it came from."""
    patterns = _pattern_names(mode, part)
    lines = []
    for line in exc.problems or [str(exc)]:
        rest = line[len(label) + 2 :] if line.startswith(label + ": ") else line
        field_text = re.split(r" = |: ", rest, maxsplit=1)[0]
        name = tgt.origin.get((part, field_text))
        if name is None:
            best = ""
            for (p, loc), n in tgt.origin.items():
                if p == part and field_text.startswith(loc) and len(loc) > len(best):
                    best, name = loc, n
        if name is None:
            generic = re.sub(r"\[\d+\]", "[*]", field_text)
            index = re.findall(r"\[(\d+)\]", field_text)
            for pat, n in sorted(patterns, key=lambda x: -len(x[0])):
                if generic == pat or generic.startswith(pat + "."):
                    name = n + (f"({int(index[0]) + 1})" if "[*]" in pat and index else "")
                    break
        if name is None:
            inside = [n for pat, n in patterns if pat.startswith((generic + ".", generic + "["))]
            if inside:
                name = " / ".join(dict.fromkeys(inside[:3])) + (" ..." if len(inside) > 3 else "")
        where = f"{name} ({field_text})" if name else f"(no namelist field) {field_text}"
        lines.append(f"{src}: {where}{rest[len(field_text) :]}")
    from fracas.config.trajectory import deck_error

    return deck_error(lines)
