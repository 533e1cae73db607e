"""The TOM case built from a deck (:class:`TomCase`, the search's inputs in canonical units) and the
display units of a target (deck unit and canonical per deck unit).  Built by
:func:`fracas.build.tom.build_tom`; FRACAS TOM's input processing ($DATA, $CONTROL, $TARGET).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from fracas import constants
from fracas.config.tom import TomDeck
from fracas.config.trajectory import TrajectoryDeck
from fracas.errors import ConfigError
from fracas.guidance.target_kinds import TARGET_KINDS
from fracas.integrate.problem import Problem
from fracas.tom.problem import TomProblem
from fracas.tom.search_types import SearchSettings


def target_display(name: str) -> tuple[str, float]:
    """(deck unit, canonical per deck unit) of a target: rad -> deg, s -> days."""
    unit = TARGET_KINDS[name].unit
    if unit == "rad":
        return "deg", math.pi / 180.0
    if unit == "s":
        return "days", constants.DAY_S
    return unit, 1.0


@dataclasses.dataclass
class TomCase:
    """Everything a TOM run needs, built from a deck (canonical units unless said).

    problem: the :class:`TomProblem`; u0, lower, upper, scale, floor: the search's inputs;
    settings: the search settings; control_units / control_factor: deck unit and canonical
    per deck unit of each control; target_units / target_factor likewise; given_s, given_g:
    $SMAG in canonical units (or None); trajectory: the trajectory deck; base: its Problem.
    """

    deck: TomDeck
    trajectory: TrajectoryDeck
    base: Problem
    problem: TomProblem
    u0: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray
    floor: np.ndarray
    settings: SearchSettings
    control_names: tuple[str, ...]
    control_units: tuple[str, ...]
    control_factor: np.ndarray
    target_names: tuple[str, ...]
    target_bodies: tuple[str, ...]
    target_units: tuple[str, ...]
    target_factor: np.ndarray
    members: tuple[tuple[tuple[str, float], ...], ...]
    given_s: np.ndarray | None = None
    given_g: np.ndarray | None = None
    grid_increments: np.ndarray | None = None
    # the arcs' switch order as linear constraints ineq_matrix @ U <= ineq_bound (None: no arc time
    # is a control); performance: what F is (name, deck unit, canonical per deck unit)
    ineq_matrix: np.ndarray | None = None
    ineq_bound: np.ndarray | None = None
    performance_name: str = "final_mass"
    performance_unit: str = "kg"
    performance_factor: float = 1.0
    periodic: np.ndarray | None = None  # (M,) bool: unbounded, unlinked arc_alpha / vinf_ra controls
    arcs_rewritten: bool = False  # the trajectory's thrust arcs are the first guess's, not the deck's


def _err(src: str, field: str, value: object, expected: str) -> ConfigError:
    return ConfigError(f"{src}: {field} = {value!r}: {expected}")
