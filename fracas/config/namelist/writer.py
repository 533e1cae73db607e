"""A TOML deck -> a FRACAS-style namelist deck (:func:`namelist_from_deck`), the inverse of the
import for the fields the mapping covers: ``$DATA`` (+ ``$SMAG``) of a trajectory or TOM deck,
``$ERRCON``, ``$ERTRAJ``, ``$ERANAL``, ``$GENCOV`` of a TEAM deck, ``$INSIM`` and one ``$INMAN``
per maneuver of a TSIM deck; every TOML field with no namelist field listed in a ``!`` comment."""

from __future__ import annotations

import re
from typing import Any

import f90nml

from fracas.config.namelist.fields import TOM_FIELDS, TRAJECTORY_FIELDS, NmlField
from fracas.config.namelist.post import _STATE_NAMES, _parent
from fracas.config.namelist.results import _loc_text, _show
from fracas.config.namelist.team_fields import (
    ERANAL_FIELDS,
    ERRCON_FIELDS,
    ERTRAJ_FIELDS,
    GENCOV_FIELDS,
    INMAN_FIELDS,
    INSIM_FIELDS,
)
from fracas.config.trajectory import cut
from fracas.errors import DeckError
from fracas.measurements.kinds import SIGMA_UNITS


def _dump(cfg: Any) -> dict:
    """The fields a deck sets (JSON types)."""
    return cfg.model_dump(mode="json", exclude_unset=True)


def _leaves(data: Any, path: tuple = ()) -> list[tuple[tuple, Any]]:
    """(path, value) of every value that is not a table (lists of tables are walked)."""
    if isinstance(data, dict):
        out = []
        for k, v in data.items():
            out += _leaves(v, path + (k,))
        return out
    if isinstance(data, list) and data and all(isinstance(x, dict) for x in data):
        out = []
        for i, v in enumerate(data):
            out += _leaves(v, path + (i,))
        return out
    return [(path, data)]


def _unkey(data: dict, path: tuple, value_key: bool = False) -> None:
    """A TOML table keyed by name -> a list of entries with "*" keys (the inverse of
    :func:`~fracas.config.namelist.post._keyed`); ``value_key``: each value is one value."""
    cur = _parent(data, path)
    if cur is None:
        return
    table = cur.get(path[-1]) if isinstance(cur, dict) else None
    if isinstance(table, dict):
        cur[path[-1]] = [{"*": k, "@value": v} if value_key else {"*": k, **v} for k, v in table.items()]


def _code_of(f: NmlField, v: Any) -> Any:
    for c, n in f.codes:
        if n == v:
            return c
    return v


def _write_group(fields: tuple[NmlField, ...], data: dict, prefix: tuple = ()) -> tuple[list, set]:
    """[(NAME, namelist value)] of the fields ``data`` holds, and the leaf paths they took."""
    leaves = _leaves(data)
    taken: set = set()
    out = []
    for f in fields:
        fpath = prefix + f.path
        if f.kind == "key":
            fpath = fpath + ("*",)
        comp = fpath[-1] if isinstance(fpath[-1], int) else None
        if comp is not None:
            fpath = fpath[:-1]
        star = fpath.index("*") if "*" in fpath else None
        values: dict[int, Any] = {}
        for lp, v in leaves:
            if len(lp) != len(fpath):
                continue
            if all(a == b or (b == "*" and isinstance(a, int)) for a, b in zip(lp, fpath)):
                if v is None:
                    continue
                k = lp[star] if star is not None else 0
                val = v[comp] if comp is not None else v
                if f.kind == "code":
                    val = _code_of(f, val)
                if f.kind in ("real", "reals") and f.scale != 1.0:
                    val = [x / f.scale for x in val] if isinstance(val, list) else val / f.scale
                values[k] = val
                taken.add(lp)
        if not values:
            continue
        if star is None:
            out.append((f.name, values[0]))
        else:
            n = max(values) + 1
            arr = [values.get(k) for k in range(n)]
            if f.kind in ("reals", "strs"):
                width = max(len(a) for a in arr if a is not None)
                arr = _pad([a or [] for a in arr], width)
            out.append((f.name, arr))
    return out, taken


def _pad(rows: list[list], width: int) -> list[list]:
    """The rows of a 2-D array NAME(j,k), each filled to ``width`` with None (not written)."""
    return [r + [None] * (width - len(r)) for r in rows]


def _traj_block(tdump: dict) -> tuple[list, set]:
    """$DATA / $ERTRAJ trajectory values, ICOORD + X0 included."""
    ist = tdump.get("initial_state", {})
    extra = []
    if "cartesian" in ist:
        c = ist["cartesian"]
        extra = [("ICOORD", 1), ("X0", list(c["r_km"]) + list(c["v_km_s"]))]
    elif "elements" in ist:
        e = ist["elements"]
        true = "true_anomaly_deg" in e
        extra = [
            ("ICOORD", 3 if true else 2),
            (
                "X0",
                [
                    e["a_km"],
                    e["e"],
                    e["i_deg"],
                    e.get("raan_deg", 0.0),
                    e.get("argp_deg", 0.0),
                    e["true_anomaly_deg" if true else "mean_anomaly_deg"],
                ],
            ),
        ]
    elif "spherical" in ist:
        s = ist["spherical"]
        extra = [("ICOORD", 4), ("X0", [s[k] for k in _STATE_NAMES["spherical"]])]
    data = {k: v for k, v in tdump.items() if k != "mode"}
    data["initial_state"] = {k: v for k, v in ist.items() if k not in ("cartesian", "elements", "spherical")}
    _unkey(data, ("forces", "overrides"))
    _unkey(data, ("forces", "conic_bodies"))
    vals, taken = _write_group(tuple(f for f in TRAJECTORY_FIELDS if f.name not in ("ICOORD", "X0")), data)
    missed = {lp for lp, _ in _leaves(data) if lp not in taken and lp != ("initial_state",)}
    ordered = []
    for name, v in vals:
        ordered.append((name, v))
        if name in ("FRAME",) or (name == "CENTRE" and "FRAME" not in dict(vals)):
            ordered += extra
            extra = []
    return ordered + extra, missed


def _missed(data: dict, taken: set, skip: tuple = ()) -> list[str]:
    return [
        f"{_loc_text(lp)} = {cut(_show(v), 40)}"
        for lp, v in _leaves(data)
        if lp not in taken and not (skip and lp[: len(skip)] == skip) and lp != ("mode",)
    ]


def _nml(groups: list[tuple[str, list]]) -> str:
    """The groups as f90nml writes them (upper case, shortest round-trip floats)."""
    items = []
    for gname, values in groups:
        if not values:
            continue
        nml = f90nml.Namelist([(n.lower(), v) for n, v in values])
        items.append((gname.lower(), nml))
    out = f90nml.Namelist()
    for gname, nml in items:
        if gname in out:
            prev = out[gname]
            out[gname] = (prev if isinstance(prev, list) else [prev]) + [nml]
        else:
            out[gname] = nml
    out.uppercase = True
    out.float_format = ""
    out.end_comma = False
    return str(out) if items else ""


def namelist_from_deck(cfg: Any, dollar: bool = False, inline: bool = True) -> str:
    """A FRACAS-style namelist deck from a validated TOML deck (``fracas.modes.load_any``), any
    mode but sweep.

    The inverse of :func:`import_namelist` for the fields the mapping covers (same names and
    unit conversions); every TOML field it cannot write is listed in a ``!`` comment at the
    top.  ``dollar``: write ``$GROUP ... $END`` (FRACAS) instead of ``&GROUP ... /``;
    ``inline``: write a TEAM deck's trajectory into $ERTRAJ (and a TSIM deck's TEAM study into
    the TEAM namelists), else name them by file ($ERTRAJ.DECK, $INSIM.TEAMDK)."""
    from fracas.config.team import TeamDeck
    from fracas.config.tom import TomDeck
    from fracas.config.trajectory import TrajectoryDeck
    from fracas.config.tsim import TsimDeck

    missed: list[str] = []
    src = cfg.source_path or "<deck>"
    if isinstance(cfg, TrajectoryDeck):
        label, groups = "PROPAGATE", _trajectory_groups(cfg, missed)
    elif isinstance(cfg, TomDeck):
        label, groups = "TOM", _tom_groups(cfg, missed)
    elif isinstance(cfg, TeamDeck):
        label, groups = "TEAM", _team_groups(cfg, inline, missed)
    elif isinstance(cfg, TsimDeck):
        label, groups = "TSIM", _tsim_groups(cfg, inline, missed)
    else:
        raise DeckError(
            f"{src}: a {getattr(cfg, 'mode', type(cfg).__name__)} deck has no FRACAS namelist form "
            "(FRACAS reads TOM, TEAM and TSIM decks)"
        )
    head = [
        f"! FRACAS namelist deck written by fracas from {src}",
        "! units: km, km/s, kg, kW, deg, days (docs/namelist.md)",
    ]
    for m in missed:
        head.append(f"! not written (no namelist field): {m}")
    body = _nml(groups)
    if dollar:
        body = re.sub(r"^&(\w+)", r"$\1", body, flags=re.MULTILINE)
        body = re.sub(r"^/\s*$", "$END", body, flags=re.MULTILINE)
    return "\n".join(head) + "\n" + label + "\n" + body


def _group_values(fields: tuple[NmlField, ...], data: dict, missed: list[str], prefix: str = "") -> list:
    """:func:`_write_group`'s values of ``data``; every leaf no field took added to ``missed``
    (after ``prefix``)."""
    vals, taken = _write_group(fields, data)
    missed += [prefix + x for x in _missed(data, taken)]
    return vals


def _trajectory_groups(cfg: Any, missed: list[str]) -> list[tuple[str, list]]:
    """$DATA of a trajectory deck."""
    vals, miss = _traj_block(_dump(cfg))
    missed += [f"{_loc_text(lp)}" for lp in miss]
    return [("DATA", vals)]


def _tom_groups(cfg: Any, missed: list[str]) -> list[tuple[str, list]]:
    """$DATA (trajectory and TOM fields) and $SMAG of a TOM deck."""
    from fracas.config.tom import tom_trajectory_deck

    groups: list[tuple[str, list]] = []
    d = _dump(cfg)
    traj = tom_trajectory_deck(cfg)
    tvals, miss = _traj_block(_dump(traj))
    missed += [_loc_text(lp) for lp in miss]
    tomd = {k: v for k, v in d.items() if k in ("tom", "control", "target", "grid", "smag")}
    for c in tomd.get("control", []):
        if "links" in c:
            c["links"] = {"@name": list(c["links"]), "@value": list(c["links"].values())}
    smag = tomd.pop("smag", None)
    vals, taken = _write_group(TOM_FIELDS, tomd)
    vals = [(n, v) for n, v in vals if n not in ("ULINK", "ULCOEF")] + _links(tomd)
    taken |= {lp for lp, _ in _leaves(tomd) if "links" in lp}
    missed += _missed(tomd, taken)
    if "title" in d and "title" not in _dump(traj):
        tvals = [("TITLE", d["title"])] + tvals
    groups.append(("DATA", tvals + vals))
    if smag is not None:
        s_cols = [[row[j] for row in smag["s"]] for j in range(len(smag["g"]))] if smag["s"] else []
        groups.append(("SMAG", ([("S", s_cols)] if s_cols else []) + [("G", smag["g"])]))
    return groups


def _tsim_groups(cfg: Any, inline: bool, missed: list[str]) -> list[tuple[str, list]]:
    """$INSIM and one $INMAN per maneuver of a TSIM deck (+ its TEAM study's namelists if ``inline``)."""
    from fracas.config.tsim import tsim_team_deck

    groups: list[tuple[str, list]] = []
    d = _dump(cfg)
    insim = dict(d.get("insim", {}))
    if "team_changes" in insim:
        insim["team_changes"] = dict(insim["team_changes"])
    data = {"insim": insim, "output": d.get("output", {}), "title": d.get("title")}
    if data["title"] is None:
        data.pop("title")
    _unkey(data, ("insim", "team_changes"), value_key=True)
    if inline:
        insim.pop("team_deck", None)
    groups.append(("INSIM", _group_values(INSIM_FIELDS, data, missed)))
    for m in d.get("maneuver", []):
        groups.append(("INMAN", _group_values(INMAN_FIELDS, m, missed, "maneuver.")))
    if inline:
        groups += _team_groups(tsim_team_deck(cfg), True, missed)
    return groups


def _links(tomd: dict) -> list:
    """ULINK(j,k) and ULCOEF(j,k): the linked controls of control k, padded to one width."""
    controls = tomd.get("control", [])
    if not any("links" in c for c in controls):
        return []
    names = [c.get("links", {}).get("@name", []) for c in controls]
    coefs = [c.get("links", {}).get("@value", []) for c in controls]
    width = max(len(n) for n in names)
    return [("ULINK", _pad(names, width)), ("ULCOEF", _pad(coefs, width))]


def _team_groups(cfg: Any, inline: bool, missed: list[str]) -> list[tuple[str, list]]:
    """$ERRCON, $ERTRAJ, $ERANAL, $GENCOV of a TEAM deck."""
    d = _dump(cfg)
    d.pop("mode", None)
    _team_units(d)
    errcon = d.get("errcon", {})
    if "propagation" in errcon:
        errcon["@propagation"] = errcon.pop("propagation") == "pdot"
    out = []
    out.append(("ERRCON", _group_values(ERRCON_FIELDS, {"errcon": errcon}, missed)))
    out.append(("ERTRAJ", _ertraj_values(cfg, d, inline, missed)))
    rest = {k: v for k, v in d.items() if k not in ("errcon", "ertraj", "stm")}
    gen = rest.pop("gencov", None)
    if gen is not None and "enabled" in gen:
        rest["gencov"] = {"enabled": gen.pop("enabled")}
    av = _group_values(ERANAL_FIELDS, rest, missed)
    out.append(("ERANAL", av))
    if gen:
        gv = _group_values(GENCOV_FIELDS, {"gencov": gen}, missed)
        out.append(("GENCOV", gv if gv else []))
    if gen is not None and not gen and not any(n == "LGENCV" for n, _ in av):
        out[2][1].append(("LGENCV", True))  # an empty [gencov] table: enabled (its default)
    return out


def _team_units(d: dict) -> None:
    """A TEAM deck's dump in namelist units: arcs from 1, measurement sigmas in FRACAS units."""
    for g in d.get("guidance", []):
        if "arc" in g:
            g["@arc"] = g.pop("arc") + 1  # arcs from 1 in the namelist
    for t in d.get("tracking", []):
        if "sigma" in t:
            t["sigma"] = t["sigma"] * SIGMA_UNITS[t["type"]][1]
    gencov = d.get("gencov")
    if isinstance(gencov, dict) and "measurement_sigma" in gencov:
        gencov["measurement_sigma"] = {k: v * SIGMA_UNITS[k][1] for k, v in gencov["measurement_sigma"].items()}
        _unkey(d, ("gencov", "measurement_sigma"), value_key=True)


def _ertraj_values(cfg: Any, d: dict, inline: bool, missed: list[str]) -> list:
    """$ERTRAJ: its own fields, then (``inline``) the reference trajectory's."""
    from fracas.config.trajectory import load_deck

    ertraj_data = {"ertraj": dict(d.get("ertraj", {})), "stm": d.get("stm", {})}
    tvals: list = []
    if inline:
        ertraj_data["ertraj"].pop("deck", None)
        traj = load_deck(cfg.resolve(cfg.ertraj.deck))
        tvals, miss = _traj_block(_dump(traj))
        missed += ["ertraj.deck: " + _loc_text(lp) for lp in miss]
    return _group_values(ERTRAJ_FIELDS, ertraj_data, missed) + tvals
