"""Warnings for an initial state that is possible but implausible: a unit slip, most likely.

A state typed in the wrong unit is still a state: ``v_km_s = [0, 7500, 1000]`` (m/s in a
km/s field) is a hyperbola leaving the Earth at 7,566 km/s, and ``r_km`` in metres puts a
low orbit 7 million km out.  Both validate and run ("reached the final time" at 6.5e8 km),
so they are not errors; :func:`state_warnings` names them, one line each, naming the field
and the likely unit:

* a speed above :data:`ESCAPE_FACTOR` times the local escape speed ``sqrt(2 mu / r)``
  (specific energy 10,000 times ``mu / r``): hyperbolic by orders of magnitude about its
  centre ("likely m/s");
* a radius beyond :data:`SOI_FACTOR` times the centre's sphere of influence
  (:func:`fracas.constants.soi_radius_km`) where a thousandth of it would be above the
  centre's surface ("likely m"), or beyond :data:`FAR_SOI_FACTOR` times it whatever the
  unit; about the Sun (no sphere of influence) beyond :data:`SUN_LIMIT_AU` AU (well past
  the heliopause near 120 AU; a planet's orbit typed in metres is 300 AU or more).

Every bundled deck, the interplanetary and hyperbolic-flyby ones included, is well inside
these bounds (``tests/config/test_plausible.py``).  The state of ``[initial_state.oem]`` is
checked as read.  :func:`warn` prints them on stderr (``fracas: warning: ...``; the run
goes on), once per process and only in the process that runs the command, not in its Dask
workers; ``fracas validate`` and every run call it (:func:`fracas.validate.
trajectory_problems`, the modes' builds).
"""

from __future__ import annotations

import math
import multiprocessing
import sys
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

from fracas.config.trajectory.messages import cut
from fracas.constants import AU_KM, BODIES, soi_radius_km

if TYPE_CHECKING:
    from fracas.config.trajectory.deck import TrajectoryDeck

__all__ = ["ESCAPE_FACTOR", "SOI_FACTOR", "FAR_SOI_FACTOR", "SUN_LIMIT_AU", "state_warnings", "warn", "reset"]

#: a speed above this many local escape speeds is a unit slip (the fastest flybys are a few)
ESCAPE_FACTOR = 100.0
#: beyond this many sphere-of-influence radii, a radius whose thousandth is above the surface: metres
SOI_FACTOR = 5.0
#: beyond this many sphere-of-influence radii: implausible whatever the unit
FAR_SOI_FACTOR = 100.0
#: about the Sun: a start beyond this distance (AU)
SUN_LIMIT_AU = 200.0


def _fmt(x: float) -> str:
    return f"{x:.4g}"


def _speed(deck: TrajectoryDeck, r: float, mu: float) -> tuple[tuple, Any, float] | None:
    """(field, value, |v| km/s) of the initial state's speed, or None (not computable)."""
    st = deck.initial_state
    if st.cartesian is not None:
        return ("initial_state", "cartesian", "v_km_s"), st.cartesian.v_km_s, math.hypot(*st.cartesian.v_km_s)
    if st.spherical is not None:
        return ("initial_state", "spherical", "v_km_s"), st.spherical.v_km_s, st.spherical.v_km_s
    if st.oem is not None:
        return (("initial_state", "oem", "path"), st.oem.path, math.hypot(*st.oem.v_km_s)) if st.oem.v_km_s else None
    el = st.elements
    if el is None:
        return None
    v2 = mu * (2.0 / r - 1.0 / el.a_km) if el.a_km != 0.0 else math.inf
    return (("initial_state", "elements", "a_km"), el.a_km, math.sqrt(v2)) if 0.0 < v2 < math.inf else None


def _radius_field(deck: TrajectoryDeck) -> tuple[tuple, Any]:
    st = deck.initial_state
    if st.cartesian is not None:
        return ("initial_state", "cartesian", "r_km"), st.cartesian.r_km
    if st.spherical is not None:
        return ("initial_state", "spherical", "r_km"), st.spherical.r_km
    if st.oem is not None:
        return ("initial_state", "oem", "path"), st.oem.path
    return ("initial_state", "elements", "a_km"), st.elements.a_km if st.elements is not None else None


def _line(src: str, loc: tuple, value: Any, text: str) -> str:
    from fracas.config.trajectory.messages import _fmt_value

    return f"{src}: {'.'.join(loc)} = {cut(_fmt_value(value))}: {text}"


def _radius_warning(deck: TrajectoryDeck, r: float, src: str) -> str | None:
    centre = deck.initial_state.centre
    ov = deck.forces.overrides.get(centre)
    surface = ov.radius_km if ov is not None and ov.radius_km is not None else BODIES[centre].radius_km
    soi = soi_radius_km(centre)
    loc, value = _radius_field(deck)
    unit = loc[-1] == "r_km" or loc[-1] == "a_km"
    if not math.isfinite(soi):
        if r <= SUN_LIMIT_AU * AU_KM:
            return None
        guess = f"; likely m (the field is km: {_fmt(r / 1000 / AU_KM)} AU)" if unit else ""
        return _line(
            src,
            loc,
            value,
            f"starts {_fmt(r / AU_KM)} AU from the {centre}, beyond {SUN_LIMIT_AU:g} AU (the heliopause is near "
            f"120 AU){guess}",
        )
    ratio = r / soi
    metres = unit and r / 1000.0 > surface
    if ratio <= FAR_SOI_FACTOR and not (ratio > SOI_FACTOR and metres):
        return None
    guess = f"; likely m (the field is km: {_fmt(r / 1000.0)} km)" if metres else ""
    return _line(
        src,
        loc,
        value,
        f"starts {_fmt(r)} km from {centre}, {_fmt(ratio)} times its sphere of influence ({_fmt(soi)} km){guess}",
    )


def state_warnings(deck: TrajectoryDeck) -> list[str]:
    """The warnings of a trajectory deck's initial state (see the module docstring), one line
    each: ``source: field = value: what is implausible; likely unit``."""
    from fracas.config.trajectory.state import initial_radius_km

    src = deck.source_path or "<deck>"
    r = initial_radius_km(deck.initial_state)
    if r is None or not math.isfinite(r) or r <= 0.0:
        return []
    centre = deck.initial_state.centre
    ov = deck.forces.overrides.get(centre)
    mu = ov.mu_km3_s2 if ov is not None and ov.mu_km3_s2 is not None else BODIES[centre].mu_km3_s2
    out = []
    speed = _speed(deck, r, mu)
    if speed is not None:
        loc, value, v = speed
        v_esc = math.sqrt(2.0 * mu / r)
        if v_esc > 0.0 and math.isfinite(v) and v > ESCAPE_FACTOR * v_esc:
            guess = "likely m/s (the field is km/s)" if loc[-1] == "v_km_s" else "likely a unit slip"
            out.append(
                _line(
                    src,
                    loc,
                    value,
                    f"|v| = {_fmt(v)} km/s is {_fmt(v / v_esc)} times the escape speed from {centre} at "
                    f"{_fmt(r)} km ({_fmt(v_esc)} km/s): hyperbolic by orders of magnitude; {guess}",
                )
            )
    line = _radius_warning(deck, r, src)
    if line is not None:
        out.append(line)
    return out


_SHOWN: set[str] = set()


def warn(lines: Iterable[str]) -> None:
    """Print each line on stderr as ``fracas: warning: LINE`` (the run goes on): once per
    process, and only in the process that runs the command (a Dask worker's copy of a
    study says nothing: the command said it before handing the work out)."""
    if multiprocessing.parent_process() is not None:
        return
    for line in lines:
        if line in _SHOWN:
            continue
        _SHOWN.add(line)
        sys.stderr.write(f"fracas: warning: {line}\n")
        sys.stderr.flush()


def reset() -> None:
    """Forget the warnings already printed (tests; a long-lived process starting afresh)."""
    _SHOWN.clear()
