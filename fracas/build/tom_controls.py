"""TOM's controls read from a deck against its trajectory (FRACAS TOM's $CONTROL): each control's
members, deck unit, bounds, weighting, finite-difference step and value on the trajectory, the
launch excess velocity, the nominal controls, the affine :class:`~fracas.tom.problem.ControlMap`
from controls to parameters and initial state, and the thrust arcs' switch order as linear
constraints.  Canonical units (s, rad, km, km/s) out; used by :func:`fracas.build.tom.build_tom`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from fracas.build.tom_case import _err
from fracas.config.tom import ControlSpec, TomDeck
from fracas.config.trajectory import TrajectoryDeck
from fracas.dynamics.model import Params
from fracas.dynamics.parameters import get_values
from fracas.integrate.problem import Problem
from fracas.params import POINTING_LAW_FIELDS, STATE_CONTROLS, VINF_CONTROLS, ControlKind, parse_control
from fracas.tom.problem import ControlMap

# one member of a control: (name, kind, index, coefficient)
_Member = tuple[str, ControlKind, tuple[int, ...], float]


def switch_order_constraints(cmap: ControlMap, params: Params, n_arcs: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The thrust arcs' order t_on[k] <= t_off[k] <= t_on[k+1] as rows A U <= b over the
    controls that move an arc time (each time is affine in U: ``ControlMap.params_of``); None
    when no arc time is a control.  Rows between two fixed times are left out (the deck's
    validation checked them)."""
    labels = cmap.param_labels
    m = cmap.n_controls

    def affine(name: str, k: int) -> tuple[np.ndarray, float]:
        label = f"{name}[{k}]"
        if label in labels:
            i = labels.index(label)
            return cmap.param_matrix[i].astype(float), float(cmap.param_base[i])
        return np.zeros(m), float(np.asarray(getattr(params, name))[k])

    times = []
    for k in range(n_arcs):
        times.append(affine("arc_t_on", k))
        times.append(affine("arc_t_off", k))
    rows, bounds = [], []
    for (a0, c0), (a1, c1) in zip(times[:-1], times[1:]):
        row = a0 - a1  # t_a - t_b <= 0  <=>  (a0 - a1) U <= c1 - c0
        if np.any(row != 0.0):
            rows.append(row)
            bounds.append(c1 - c0)
    if not rows:
        return None
    return np.array(rows), np.array(bounds)


def _member_label(kind: ControlKind, idx: tuple[int, ...]) -> str:
    if not idx:
        return kind.label
    return f"{kind.label}[{','.join(str(i) for i in idx)}]"


def _body_velocity(base: Problem, body: str, centre: str) -> np.ndarray:
    """Velocity (km/s) of ``body`` relative to ``centre`` at the epoch (the model's ephemeris)."""
    from fracas.integrate import encke

    model = base.model
    pos, vel = encke.body_states(model, base.params, base.ephem, base.epoch_et_s)
    return np.asarray(vel[model.bodies.index(body)] - vel[model.bodies.index(centre)], float)


def _steering_control(c: ControlSpec) -> bool:
    """Does the control (or one of its links) move a pointing-law coefficient?"""
    names = list(c.links) if c.links else [c.name]
    return any(n.split("[")[0].strip() in POINTING_LAW_FIELDS for n in names)


def parse_controls(deck: TomDeck, src: str, n_arcs: int, n_imp: int) -> list[list[_Member]]:
    """Each control's members (its links, or its own name with coefficient 1), parsed."""
    parsed = []
    for j, c in enumerate(deck.control):
        members = list(c.links.items()) if c.links else [(c.name, 1.0)]
        where = f"control[{j}]" + (".links" if c.links else ".name")
        pm = []
        for name, coef in members:
            try:
                kind, idx = parse_control(name, n_arcs, n_imp)
            except KeyError as exc:
                raise _err(src, where, name, str(exc).strip("'\"")) from None
            pm.append((name, kind, idx, coef))
        parsed.append(pm)
    return parsed


@dataclasses.dataclass
class ControlTable:
    """The deck's controls read against the trajectory (canonical units): names, deck units and
    canonical per deck unit (``factor``), members, the trajectory's own value of each control
    (``u_traj``), bounds, weightings k_j, floors, finite-difference steps; the parameter rows the
    controls move (``labels``) with the (label row, control col, coefficient) ``entries`` and the
    initial-state ones (``x0_entries``); the v∞ and final-time controls' columns (-1: none)."""

    names: list[str]
    units: list[str]
    factor: np.ndarray
    members: list[tuple[tuple[str, float], ...]]
    u_traj: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray
    floor: np.ndarray
    fd: np.ndarray
    label_index: dict[str, int]
    labels: list[str]
    entries: list[tuple[int, int, float]]
    x0_entries: list[tuple[int, int, float]]
    vinf_index: list[int]
    final_index: int = -1

    @classmethod
    def empty(cls, m: int) -> ControlTable:
        """A table of ``m`` controls, nothing read yet."""
        return cls(
            names=[],
            units=[],
            factor=np.zeros(m),
            members=[],
            u_traj=np.zeros(m),
            lower=np.full(m, -np.inf),
            upper=np.full(m, np.inf),
            scale=np.zeros(m),
            floor=np.zeros(m),
            fd=np.zeros(m),
            label_index={},
            labels=[],
            entries=[],
            x0_entries=[],
            vinf_index=[-1, -1, -1],
        )

    def label_row(self, label: str) -> int:
        """The row of a parameter label (added on first use)."""
        if label not in self.label_index:
            self.label_index[label] = len(self.labels)
            self.labels.append(label)
        return self.label_index[label]


def _member_value(
    tab: ControlTable,
    src: str,
    j: int,
    member: _Member,
    traj: TrajectoryDeck,
    base: Problem,
    durations: set[int],
) -> float:
    """One member of control j entered in the table; its value on the trajectory (in the
    control's unit per coefficient; nan for a v∞ member, filled in by :func:`launch_vinf`)."""
    name, kind, idx, coef = member
    params = base.params
    cc = coef  # canonical coefficient (same unit as the control)
    if kind.name in STATE_CONTROLS:
        row = STATE_CONTROLS.index(kind.name)
        tab.x0_entries.append((row, j, cc))
        return base.x0[row] / coef
    if kind.name in VINF_CONTROLS:
        tab.vinf_index[VINF_CONTROLS.index(kind.name)] = j
        return np.nan  # filled below
    if kind.name == "final_time":
        if traj.stop.condition != "time":
            raise _err(src, f"control[{j}].name", name, 'only with stop.condition = "time"')
        tab.final_index = j
        return base.final_time_s
    row = tab.label_row(_member_label(kind, idx))
    field_val = float(np.asarray(getattr(params, kind.label))[idx] if idx else getattr(params, kind.label))
    tab.entries.append((row, j, cc))
    if kind.name == "arc_duration":
        t_on = float(np.asarray(params.arc_t_on)[idx[0]])
        value = (field_val - t_on) / coef
    else:
        value = field_val / coef
    if kind.name == "arc_t_on" and idx[0] in durations:
        # the arc's duration is a control: moving its start moves its end too
        tab.entries.append((tab.label_row(f"arc_t_off[{idx[0]}]"), j, cc))
    return value


def _read_control(
    tab: ControlTable,
    src: str,
    j: int,
    c: ControlSpec,
    pm: list[_Member],
    traj: TrajectoryDeck,
    base: Problem,
    durations: set[int],
) -> None:
    """Control j entered in the table: its members, unit, value on the trajectory, bounds (an
    epoch within the propagation span unless the deck says), weighting, floor and FD step."""
    kind0 = pm[0][1]
    f0 = kind0.to_canonical
    special = [k.name for _, k, _, _ in pm if k.name in VINF_CONTROLS or k.name == "final_time"]
    if special and len(pm) > 1:
        raise _err(src, f"control[{j}].links", special[0], "vinf, vinf_ra, vinf_dec and final_time cannot be linked")
    values = []
    for member in pm:
        name, kind = member[0], member[1]
        if kind.to_canonical != f0:
            raise _err(src, f"control[{j}].links", name, f"a control in {kind0.unit}, like {pm[0][0]}")
        values.append(_member_value(tab, src, j, member, traj, base, durations))
    tab.names.append(c.name)
    tab.units.append(kind0.unit)
    tab.factor[j] = f0
    tab.members.append(tuple((n, cf) for n, _, _, cf in pm))
    tab.u_traj[j] = values[0]
    lo = c.lower if c.lower is not None else (kind0.bounds[0] if len(pm) == 1 else None)
    hi = c.upper if c.upper is not None else (kind0.bounds[1] if len(pm) == 1 else None)
    if len(pm) == 1 and kind0.name in ("arc_t_on", "arc_t_off", "impulse_t"):
        # an epoch within the propagation span (a forward one: [0, final time]) unless the deck says
        span = sorted((0.0, traj.duration_days))
        lo = span[0] if lo is None else lo
        hi = span[1] if hi is None else hi
    tab.lower[j] = lo * f0 if lo is not None else -np.inf
    tab.upper[j] = hi * f0 if hi is not None else np.inf
    tab.scale[j] = c.scale
    tab.floor[j] = f0
    tab.fd[j] = c.fd_step * f0 if c.fd_step is not None else np.nan


def control_table(
    deck: TomDeck, src: str, traj: TrajectoryDeck, base: Problem, parsed: list[list[_Member]]
) -> ControlTable:
    """The deck's controls, read in order (ConfigError naming the field of the first that the
    trajectory cannot support)."""
    tab = ControlTable.empty(len(deck.control))
    durations = {idx[0] for pm in parsed for _, k, idx, _ in pm if k.name == "arc_duration"}
    for j, (c, pm) in enumerate(zip(deck.control, parsed)):
        _read_control(tab, src, j, c, pm, traj, base, durations)
    return tab


def launch_vinf(
    deck: TomDeck, src: str, traj: TrajectoryDeck, base: Problem, tab: ControlTable
) -> tuple[np.ndarray | None, tuple[float, float, float]]:
    """The launch excess velocity: (the departure body's velocity about the centre, None without
    a v∞ control; the trajectory's (|v∞|, right ascension, declination), zeros without); the v∞
    controls' values on the trajectory are filled in."""
    model = base.model
    v_dep = None
    if max(tab.vinf_index) >= 0:
        dep = deck.tom.departure_body or traj.initial_state.centre
        if dep not in model.bodies:
            raise _err(src, "tom.departure_body", dep, f"a body of the trajectory's model ({', '.join(model.bodies)})")
        v_dep = (
            _body_velocity(base, dep, traj.initial_state.centre) if dep != traj.initial_state.centre else np.zeros(3)
        )
        vinf_vec = base.x0[3:6] - v_dep
        vmag = float(np.linalg.norm(vinf_vec))
        vals = (vmag, math.atan2(vinf_vec[1], vinf_vec[0]), math.asin(vinf_vec[2] / vmag) if vmag > 0 else 0.0)
        for k, j in enumerate(tab.vinf_index):
            if j >= 0:
                tab.u_traj[j] = vals[k]
        vinf_fixed = vals
    else:
        vinf_fixed = (0.0, 0.0, 0.0)
    return v_dep, vinf_fixed


def nominal_controls(deck: TomDeck, src: str, tab: ControlTable) -> np.ndarray:
    """U0: each control's nominal (else its value on the trajectory), within its bounds; the
    default FD steps (1e-6 of the control, at least 1e-6 of its unit) filled in."""
    factor, fd, lower, upper = tab.factor, tab.fd, tab.lower, tab.upper
    u0 = np.zeros(len(deck.control))
    for j, c in enumerate(deck.control):
        u0[j] = c.nominal * factor[j] if c.nominal is not None else tab.u_traj[j]
        if not np.isfinite(fd[j]):
            fd[j] = 1e-6 * max(abs(u0[j]) / factor[j], 1.0) * factor[j]
        if not (lower[j] <= u0[j] <= upper[j]):
            raise _err(
                src,
                f"control[{j}].nominal",
                u0[j] / factor[j],
                f"within [{lower[j] / factor[j]:g}, {upper[j] / factor[j]:g}] {tab.units[j]}",
            )
    return u0


def control_map(
    tab: ControlTable, base: Problem, v_dep: np.ndarray | None, vinf_fixed: tuple[float, float, float]
) -> ControlMap:
    """The affine map U -> (parameters, initial state): p(u) = p_traj + A (u - u_traj),
    x0(u) = x0_traj + B (u - u_traj)."""
    m = len(tab.names)
    n_lab = len(tab.labels)
    a_mat = np.zeros((n_lab, m))
    for row, j, cc in tab.entries:
        a_mat[row, j] += cc
    b_mat = np.zeros((7, m))
    for row, j, cc in tab.x0_entries:
        b_mat[row, j] += cc
    p_traj = np.asarray(get_values(base.params, tab.labels, base.model), dtype=float)
    # p(u) = p_traj + A (u - u_traj), x0(u) = x0_traj + B (u - u_traj)
    u_lin = np.where(np.isfinite(tab.u_traj), tab.u_traj, 0.0)
    return ControlMap(
        names=tuple(tab.names),
        param_labels=tuple(tab.labels),
        param_base=p_traj - a_mat @ u_lin,
        param_matrix=a_mat,
        x0_base=base.x0 - b_mat @ u_lin,
        x0_matrix=b_mat,
        final_time_s=base.final_time_s,
        final_time_index=tab.final_index,
        vinf_index=tuple(tab.vinf_index),
        vinf_fixed=tuple(float(v) for v in vinf_fixed),
        v_departure=v_dep,
    )


def periodic_controls(parsed: list[list[_Member]], tab: ControlTable) -> np.ndarray:
    """(M,) bool: the unbounded, unlinked arc_alpha / vinf_ra controls (wrapped by the search)."""
    lower, upper = tab.lower, tab.upper
    return np.array(
        [
            len(pm) == 1
            and pm[0][1].name in ("arc_alpha", "vinf_ra")
            and not np.isfinite(lower[j])
            and not np.isfinite(upper[j])
            for j, pm in enumerate(parsed)
        ]
    )
