"""TOM deck -> :class:`TomCase` (the problem object, the search inputs) and the optimized
reference written back as a trajectory deck (FRACAS TOM's output to $ERTRAJ / $INSIM).

Units convert here and nowhere else: deck controls and targets are in days, deg, km, km/s,
1 (``fracas.params.CONTROL_KINDS``; targets: rad -> deg, s -> days); the problem object and
the search work in the core's canonical units (s, rad, km, km/s).

:func:`build_tom` is a sequence of builders: the controls (:mod:`fracas.build.tom_controls`),
the targets, the performance, the search settings, $SMAG and the switch order.  The case
itself is in :mod:`fracas.build.tom_case`, the reference deck in :mod:`fracas.build.tom_reference`
and the first guess's decks in :mod:`fracas.build.tom_first_guess`; their names are re-exported
here.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from fracas.build.tom_case import TomCase, _err, target_display
from fracas.build.tom_controls import (
    ControlTable,
    _steering_control,
    control_map,
    control_table,
    launch_vinf,
    nominal_controls,
    parse_controls,
    periodic_controls,
    switch_order_constraints,
)
from fracas.build.tom_first_guess import auto_segments, first_guess_burns, first_guess_segments
from fracas.build.tom_reference import _wrap_deg, reference_deck_text
from fracas.build.trajectory import build_propagation
from fracas.config.tom import TomDeck, TomSettings, tom_trajectory_deck
from fracas.config.trajectory import TrajectoryDeck
from fracas.config.trajectory.plausible import state_warnings, warn
from fracas.dynamics.model import ForceModel, Params
from fracas.integrate.problem import Problem
from fracas.tom.problem import ControlMap, TargetSet, TomProblem
from fracas.tom.search_types import SearchSettings

__all__ = [
    "TomCase",
    "_wrap_deg",
    "auto_segments",
    "build_tom",
    "first_guess_burns",
    "first_guess_segments",
    "reference_deck_text",
    "switch_order_constraints",
    "target_display",
]

_ANGLE_TARGETS = ("i", "raan", "argp", "M")
# a performance other than the final mass: (name, body index, +1 maximized / -1 minimized)
_Performance = tuple[str, int, float] | None


@dataclasses.dataclass
class _Targets:
    """The deck's targets: the problem's :class:`TargetSet` and, per target, its name, body,
    deck unit and canonical per deck unit."""

    targets: TargetSet
    names: list[str]
    bodies: list[str]
    units: list[str]
    factor: list[float]


def _base_problem(deck: TomDeck, traj: TrajectoryDeck) -> Problem:
    """The trajectory's propagation problem, its model steering when a control moves a pointing law."""
    warn(state_warnings(traj))  # a unit slip in the initial state, most likely (the run goes on)
    base = build_propagation(traj)
    if any(_steering_control(c) for c in deck.control) and not base.model.steering:
        # a pointing-law coefficient is a control: the arcs evaluate their laws at every stage
        base = dataclasses.replace(base, model=dataclasses.replace(base.model, steering=True))
    return base


def _targets(deck: TomDeck, src: str, traj: TrajectoryDeck, model: ForceModel) -> _Targets:
    """The deck's targets in canonical units, each about its body (default: the stop body, else
    the centre), which must be one of the model's."""
    t_names, t_bodies, t_units, t_factor, desired, tol, angle, body_idx = [], [], [], [], [], [], [], []
    default_body = traj.stop.body or traj.initial_state.centre
    for i, t in enumerate(deck.target):
        body = t.body or default_body
        if body not in model.bodies:
            raise _err(
                src,
                f"target[{i}].body",
                body,
                f"a body of the trajectory's model ({', '.join(model.bodies)}); add it to forces.third_bodies "
                "or make it the stop body",
            )
        unit, fac = target_display(t.name)
        t_names.append(t.name)
        t_bodies.append(body)
        body_idx.append(model.bodies.index(body))
        t_units.append(unit)
        t_factor.append(fac)
        desired.append(t.value * fac)
        tol.append(t.tolerance * fac)
        angle.append(t.name in _ANGLE_TARGETS)
    targets = TargetSet(tuple(t_names), tuple(body_idx), np.array(desired), np.array(tol), tuple(angle))
    return _Targets(targets, t_names, t_bodies, t_units, t_factor)


def _performance(ts: TomSettings, src: str, traj: TrajectoryDeck, model: ForceModel) -> _Performance:
    """The performance other than the final mass: (name, body index, +1 maximized / -1 minimized)."""
    default_body = traj.stop.body or traj.initial_state.centre
    performance = None
    if ts.performance != "final_mass":
        body = ts.performance_body or default_body
        if body not in model.bodies:
            raise _err(
                src, "tom.performance_body", body, f"a body of the trajectory's model ({', '.join(model.bodies)})"
            )
        performance = (ts.performance, model.bodies.index(body), 1.0 if ts.maximize else -1.0)
    return performance


def _max_performance_change(
    ts: TomSettings,
    problem: TomProblem,
    base: Problem,
    u0: np.ndarray,
    performance: _Performance,
    perf_factor: float,
) -> float:
    """ΔF_max (canonical): the deck's, else 0.5 % of m0 for the mass, else 0.5 % of the
    performance at the start (one propagation)."""
    if ts.max_performance_change_kg is not None:
        dfmax = ts.max_performance_change_kg * perf_factor
    elif performance is None:
        dfmax = 0.005 * float(base.x0[6])
    else:
        # 0.5 % of the performance at the start (one propagation), as 0.5 % of m0 for the mass
        f0 = problem.evaluate(u0).performance
        dfmax = 0.005 * abs(f0) if math.isfinite(f0) and f0 != 0.0 else 1.0
    return dfmax


def _search_settings(ts: TomSettings, dfmax: float) -> SearchSettings:
    """The search's settings from [tom] (GRID and nominal runs target only)."""
    submode = {"nominal": "target", "grid": "target"}.get(ts.submode, ts.submode)
    return SearchSettings(
        submode=submode,
        max_iterations=ts.max_iterations,
        max_performance_change=dfmax,
        correction_fraction=ts.correction_fraction,
        linearity_radius=ts.linearity_radius if ts.linearity_radius is not None else math.inf,
        max_scale_factor=ts.max_scale_factor,
        curve_fit_tolerance=ts.curve_fit_tolerance,
        dependent_angle_rad=math.radians(ts.dependent_angle_deg),
        convergence_angle_rad=ts.convergence_angle_rad,
        targeting_threshold=ts.targeting_threshold,
        optimization_threshold=ts.optimization_threshold,
        weighting=ts.weighting,
    )


def _problem(
    deck: TomDeck, base: Problem, cmap: ControlMap, tg: _Targets, tab: ControlTable, performance: _Performance
) -> TomProblem:
    """The :class:`TomProblem` of the controls and targets on the trajectory's model."""
    return TomProblem(
        base.model,
        base.params,
        base.ephem,
        base.epoch_et_s,
        cmap,
        tg.targets,
        fd_steps=tab.fd,
        sensitivity_method=deck.tom.sensitivities,
        performance=performance,
    )


def _smag_and_grid(
    deck: TomDeck, tf: np.ndarray, factor: np.ndarray
) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """$SMAG's S and G and GRID's increments in canonical units (None where the deck has none)."""
    given_s = given_g = None
    if deck.smag is not None:
        given_s = np.array(deck.smag.s, float) * tf[:, None] / factor[None, :]
        given_g = np.array(deck.smag.g, float) / factor
    grid = np.array(deck.grid.increments) * factor if deck.grid is not None else None
    return given_s, given_g, grid


def _switch_order(
    src: str, names: list[str], cmap: ControlMap, params: Params, n_arcs: int, u0: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """The arcs' switch-order rows (:func:`switch_order_constraints`); ConfigError when the
    nominal arc times break them."""
    order = switch_order_constraints(cmap, params, n_arcs)
    if order is not None and np.any(order[0] @ u0 > order[1] + 1e-6):
        bad = np.flatnonzero(order[0] @ u0 > order[1] + 1e-6)[0]
        raise _err(
            src,
            "control",
            [n for n, a in zip(names, order[0][bad]) if a != 0.0],
            "nominal arc times in order: each arc's start <= its end <= the next arc's start "
            "(thrust arcs cannot invert or overlap)",
        )
    return order


def build_tom(deck: TomDeck, trajectory: TrajectoryDeck | None = None) -> TomCase:
    """Validated TOM deck -> :class:`TomCase`; ConfigError naming the field for what the
    trajectory cannot support (an arc that does not exist, a body outside the model ...).
    ``trajectory``: the trajectory deck to stand on instead of the deck's own (the first
    guess's passes, :func:`first_guess_segments` and :func:`first_guess_burns`)."""
    src = deck.source_path or "<deck>"
    traj = tom_trajectory_deck(deck) if trajectory is None else trajectory
    base = _base_problem(deck, traj)
    model, params = base.model, base.params
    parsed = parse_controls(deck, src, model.n_arcs, model.n_impulses)
    tab = control_table(deck, src, traj, base, parsed)
    v_dep, vinf_fixed = launch_vinf(deck, src, traj, base, tab)
    u0 = nominal_controls(deck, src, tab)
    cmap = control_map(tab, base, v_dep, vinf_fixed)
    tg = _targets(deck, src, traj, model)
    ts = deck.tom
    performance = _performance(ts, src, traj, model)
    problem = _problem(deck, base, cmap, tg, tab, performance)
    perf_unit, perf_factor = ("kg", 1.0) if performance is None else target_display(ts.performance)
    settings = _search_settings(ts, _max_performance_change(ts, problem, base, u0, performance, perf_factor))
    tf = np.array(tg.factor)
    given_s, given_g, grid = _smag_and_grid(deck, tf, tab.factor)
    order = _switch_order(src, tab.names, cmap, params, model.n_arcs, u0)
    return TomCase(
        deck=deck,
        trajectory=traj,
        base=base,
        problem=problem,
        u0=u0,
        lower=tab.lower,
        upper=tab.upper,
        scale=tab.scale,
        floor=tab.floor,
        settings=settings,
        control_names=tuple(tab.names),
        control_units=tuple(tab.units),
        control_factor=tab.factor,
        target_names=tuple(tg.names),
        target_bodies=tuple(tg.bodies),
        target_units=tuple(tg.units),
        target_factor=tf,
        members=tuple(tab.members),
        given_s=given_s,
        given_g=given_g,
        grid_increments=grid,
        ineq_matrix=None if order is None else order[0],
        ineq_bound=None if order is None else order[1],
        performance_name=ts.performance,
        performance_unit=perf_unit,
        performance_factor=perf_factor,
        periodic=periodic_controls(parsed, tab),
    )
