"""The imported fields that are not one-to-one, fixed after every variable is filled (:func:`_post`):
the initial state (``ICOORD`` + ``X0``), tables keyed by name (``OVBODY``, ``CBODY``, ``GMTYPE``,
``TCFLD``), TOM's linked controls and ``$SMAG.S``, TEAM's covariance mode, thrust-arc numbers
(from 1 -> from 0) and measurement sigmas (FRACAS units -> the TOML deck's, :func:`_msig`)."""

from __future__ import annotations

from typing import Any

from fracas.config.namelist.fields import SMAG_FIELDS
from fracas.config.namelist.results import _show, _where
from fracas.config.namelist.values import _as_list, _scalar, _trim
from fracas.config.trajectory import cut
from fracas.errors import DeckError
from fracas.measurements.kinds import SIGMA_UNITS


def _parent(data: dict, path: tuple) -> Any:
    """What holds ``path[-1]`` in ``data``: None where a table on the way is missing."""
    cur: Any = data
    for p in path[:-1]:
        cur = cur.get(p) if isinstance(cur, dict) else None
        if cur is None:
            return None
    return cur


def _keyed(data: dict, path: tuple, src: str, label: str) -> None:
    """A list of entries with "*" keys (OVBODY, CBODY, GMTYPE) -> a TOML table keyed by name."""
    cur = _parent(data, path)
    if cur is None:
        return
    items = cur.get(path[-1]) if isinstance(cur, dict) else None
    if not isinstance(items, list):
        return
    out: dict = {}
    for k, item in enumerate(items, start=1):
        if not isinstance(item, dict) or "*" not in item:
            raise DeckError(f"{src}: {label}({k}): not given (entry {k} needs its name)")
        key = item.pop("*")
        if key in out:
            raise DeckError(f"{src}: {label}({k}) = {key!r}: given twice")
        out[key] = item.pop("@value") if "@value" in item else item
    cur[path[-1]] = out


_STATE_KINDS = {1: "cartesian", 2: "elements", 3: "elements", 4: "spherical"}
_STATE_NAMES = {
    "cartesian": ("r_km", "v_km_s"),
    "elements": ("a_km", "e", "i_deg", "raan_deg", "argp_deg"),
    "spherical": ("r_km", "lat_deg", "lon_deg", "v_km_s", "gamma_deg", "sigma_deg"),
}


def _initial_state(data: dict, src: str, group: str, notes: list[str]) -> None:
    """ICOORD + X0(6) -> [initial_state.cartesian | elements | spherical] (ICOORD default 1)."""
    ist = data.get("initial_state")
    if not isinstance(ist, dict) or ("@kind" not in ist and "@x0" not in ist):
        return
    if "@kind" not in ist:
        notes.append(f"${group}.ICOORD not given: 1 (cartesian X0) assumed")
    code = ist.pop("@kind", 1)
    x0 = ist.pop("@x0", None)
    if code not in _STATE_KINDS:
        raise DeckError(
            f"{_where(src, group, 'ICOORD')} = {code}: expected 1 (cartesian), 2 (elements, mean "
            "anomaly), 3 (elements, true anomaly) or 4 (spherical)"
        )
    if x0 is None:
        raise DeckError(f"{_where(src, group, 'X0')}: required (the initial state, 6 values)")
    if len(x0) != 6:
        raise DeckError(f"{_where(src, group, 'X0')} = {cut(_show(x0), 40)}: expected 6 values, got {len(x0)}")
    kind = _STATE_KINDS[code]
    if kind == "cartesian":
        ist[kind] = {"r_km": x0[:3], "v_km_s": x0[3:]}
    elif kind == "elements":
        ist[kind] = dict(zip(_STATE_NAMES[kind], x0[:5]))
        ist[kind]["mean_anomaly_deg" if code == 2 else "true_anomaly_deg"] = x0[5]
    else:
        ist[kind] = dict(zip(_STATE_NAMES[kind], x0))


# C901 on purpose: one branch per namelist part whose fields are not one-to-one (FRACAS's own table)
def _post(data: dict, part: str, src: str, group: str, notes: list[str]) -> None:  # noqa: C901
    """The fields that are not one-to-one: initial state, keyed tables, codes, arc numbers, sigmas."""
    if part in ("traj", "tom"):
        _initial_state(data, src, group, notes)
        _keyed(data, ("forces", "overrides"), src, f"${group}.OVBODY")
        _keyed(data, ("forces", "conic_bodies"), src, f"${group}.CBODY")
    if part == "tom":
        for k, c in enumerate(data.get("control", [])):
            links = c.get("links") if isinstance(c, dict) else None
            if isinstance(links, dict):
                names, values = links.get("@name", []), links.get("@value", [])
                if len(names) != len(values):
                    raise DeckError(
                        f"{_where(src, group, 'ULCOEF', k + 1)}: expected {len(names)} coefficients "
                        f"(one per ULINK(j,{k + 1}))"
                    )
                c["links"] = dict(zip(names, values))
        smag = data.get("smag")
        if isinstance(smag, dict) and "@s" in smag:
            cols = smag.pop("@s")  # f90nml: S(i,j) -> [column j][row i]
            cols = [_trim(_as_list(c)) for c in cols] if any(isinstance(c, list) for c in cols) else [[c] for c in cols]
            rows = max((len(c) for c in cols), default=0)
            s = []
            for i in range(rows):
                row = []
                for j, c in enumerate(cols):
                    x = c[i] if i < len(c) else None
                    row.append(_scalar(SMAG_FIELDS[0], x, _where(src, "SMAG", "S", j + 1, i + 1)))
                s.append(row)
            smag["s"] = s
    if part == "tsim":
        _keyed(data, ("insim", "team_changes"), src, "$INSIM.TCFLD")
    if part == "team":
        errcon = data.get("errcon")
        if isinstance(errcon, dict) and "@propagation" in errcon:
            errcon["propagation"] = "pdot" if errcon.pop("@propagation") else "phi"
        for k, g in enumerate(data.get("guidance", [])):
            if isinstance(g, dict) and "@arc" in g:
                arc = g.pop("@arc")
                if arc < 1:
                    raise DeckError(f"{_where(src, 'ERANAL', 'GARC', k + 1)} = {arc}: expected an arc number >= 1")
                g["arc"] = arc - 1
                notes.append(
                    f"$ERANAL.GARC({k + 1}) = {arc}: thrust arc {arc} is guidance[{k}].arc = {arc - 1} "
                    "(arcs from 1 -> from 0)"
                )
        for k, t in enumerate(data.get("tracking", [])):
            if isinstance(t, dict) and "sigma" in t:
                t["sigma"] = _msig(t.get("type"), t["sigma"], _where(src, "ERANAL", "MSIGMA", k + 1), notes)
        gencov = data.get("gencov")
        if isinstance(gencov, dict) and isinstance(gencov.get("measurement_sigma"), list):
            for k, item in enumerate(gencov["measurement_sigma"], start=1):
                if isinstance(item, dict) and "@value" in item:
                    typ = item.get("*")
                    item["@value"] = _msig(typ, item["@value"], _where(src, "GENCOV", "GMSIG", k), notes)
            _keyed(data, ("gencov", "measurement_sigma"), src, "$GENCOV.GMTYPE")


def _msig(typ: Any, value: float, where: str, notes: list[str]) -> float:
    """A measurement sigma in FRACAS units (km, km/s, rad) -> the TOML deck's unit for its type."""
    unit = SIGMA_UNITS.get(str(typ).strip().lower()) if typ is not None else None
    if unit is None:
        raise DeckError(
            f"{where} = {value:g}: its data type {typ!r} is not known, so its unit is not either "
            f"(expected a type of: {', '.join(SIGMA_UNITS)})"
        )
    out = value / unit[1]
    notes.append(f"{where.split(': ', 1)[1]} = {value:g} (FRACAS units) -> sigma = {out:.12g} {unit[0]}")
    return out
