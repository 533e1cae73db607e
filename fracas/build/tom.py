"""TOM deck -> :class:`TomCase` (the problem object, the search inputs) and the optimized
reference written back as a trajectory deck (FRACAS TOM's output to $ERTRAJ / $INSIM).

Units convert here and nowhere else: deck controls and targets are in days, deg, km, km/s,
1 (``fracas.params.CONTROL_KINDS``; targets: rad -> deg, s -> days); the problem object and
the search work in the core's canonical units (s, rad, km, km/s).
"""

from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np

from fracas import constants
from fracas.build.trajectory import _rotation_to_icrf, build_propagation
from fracas.config.tom import TomDeck, tom_trajectory_deck
from fracas.config.trajectory import TrajectoryDeck, load_toml
from fracas.dynamics.parameters import get_values
from fracas.errors import ConfigError
from fracas.guidance.target_kinds import TARGET_KINDS
from fracas.integrate.problem import Problem
from fracas.params import POINTING_LAW_FIELDS, STATE_CONTROLS, VINF_CONTROLS, ControlKind, parse_control
from fracas.tom.problem import ControlMap, TargetSet, TomProblem
from fracas.tom.search import SearchSettings

__all__ = ["TomCase", "build_tom", "reference_deck_text", "target_display"]

_ANGLE_TARGETS = ("i", "raan", "argp", "M")


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


def switch_order_constraints(cmap: ControlMap, params, n_arcs: int) -> tuple[np.ndarray, np.ndarray] | None:
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


def _err(src: str, field: str, value, expected: str) -> ConfigError:
    return ConfigError(f"{src}: {field} = {value!r}: {expected}")


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


def _steering_control(c) -> bool:
    """Does the control (or one of its links) move a pointing-law coefficient?"""
    names = list(c.links) if c.links else [c.name]
    return any(n.split("[")[0].strip() in POINTING_LAW_FIELDS for n in names)


def _wrap_deg(angle_deg: float) -> float:
    """An angle in degrees wrapped to (-180, 180]."""
    w = math.remainder(angle_deg, 360.0)
    return 180.0 if w == -180.0 else w


def build_tom(deck: TomDeck, trajectory: TrajectoryDeck | None = None) -> TomCase:
    """Validated TOM deck -> :class:`TomCase`; ConfigError naming the field for what the
    trajectory cannot support (an arc that does not exist, a body outside the model ...).
    ``trajectory``: the trajectory deck to stand on instead of the deck's own (the first
    guess's passes, :func:`first_guess_segments` and :func:`first_guess_burns`)."""
    src = deck.source_path or "<deck>"
    traj = tom_trajectory_deck(deck) if trajectory is None else trajectory
    base = build_propagation(traj)
    if any(_steering_control(c) for c in deck.control) and not base.model.steering:
        # a pointing-law coefficient is a control: the arcs evaluate their laws at every stage
        base = dataclasses.replace(base, model=dataclasses.replace(base.model, steering=True))
    model = base.model
    params = base.params
    n_arcs, n_imp = model.n_arcs, model.n_impulses
    m = len(deck.control)

    # ---- controls
    names, units, factor, members_all = [], [], np.zeros(m), []
    u_traj = np.zeros(m)  # the trajectory's own value of each control (canonical)
    u0 = np.zeros(m)
    lower = np.full(m, -np.inf)
    upper = np.full(m, np.inf)
    scale = np.zeros(m)
    floor = np.zeros(m)
    fd = np.zeros(m)
    label_index: dict[str, int] = {}
    labels: list[str] = []
    entries: list[tuple[int, int, float]] = []  # (label row, control col, coefficient)
    x0_entries: list[tuple[int, int, float]] = []
    vinf_index = [-1, -1, -1]
    final_index = -1
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
    durations = {idx[0] for pm in parsed for _, k, idx, _ in pm if k.name == "arc_duration"}

    for j, (c, pm) in enumerate(zip(deck.control, parsed)):
        kind0 = pm[0][1]
        f0 = kind0.to_canonical
        special = [k.name for _, k, _, _ in pm if k.name in VINF_CONTROLS or k.name == "final_time"]
        if special and len(pm) > 1:
            raise _err(
                src, f"control[{j}].links", special[0], "vinf, vinf_ra, vinf_dec and final_time cannot be linked"
            )
        values = []
        for name, kind, idx, coef in pm:
            if kind.to_canonical != f0:
                raise _err(src, f"control[{j}].links", name, f"a control in {kind0.unit}, like {pm[0][0]}")
            cc = coef  # canonical coefficient (same unit as the control)
            if kind.name in STATE_CONTROLS:
                row = STATE_CONTROLS.index(kind.name)
                x0_entries.append((row, j, cc))
                values.append(base.x0[row] / coef)
            elif kind.name in VINF_CONTROLS:
                vinf_index[VINF_CONTROLS.index(kind.name)] = j
                values.append(np.nan)  # filled below
            elif kind.name == "final_time":
                if traj.stop.condition != "time":
                    raise _err(src, f"control[{j}].name", name, 'only with stop.condition = "time"')
                final_index = j
                values.append(base.final_time_s)
            else:
                label = _member_label(kind, idx)
                if label not in label_index:
                    label_index[label] = len(labels)
                    labels.append(label)
                field_val = float(np.asarray(getattr(params, kind.label))[idx] if idx else getattr(params, kind.label))
                entries.append((label_index[label], j, cc))
                if kind.name == "arc_duration":
                    t_on = float(np.asarray(params.arc_t_on)[idx[0]])
                    values.append((field_val - t_on) / coef)
                else:
                    values.append(field_val / coef)
                if kind.name == "arc_t_on" and idx[0] in durations:
                    # the arc's duration is a control: moving its start moves its end too
                    lab = f"arc_t_off[{idx[0]}]"
                    if lab not in label_index:
                        label_index[lab] = len(labels)
                        labels.append(lab)
                    entries.append((label_index[lab], j, cc))
        names.append(c.name)
        units.append(kind0.unit)
        factor[j] = f0
        members_all.append(tuple((n, cf) for n, _, _, cf in pm))
        u_traj[j] = values[0]
        lo = c.lower if c.lower is not None else (kind0.bounds[0] if len(pm) == 1 else None)
        hi = c.upper if c.upper is not None else (kind0.bounds[1] if len(pm) == 1 else None)
        if len(pm) == 1 and kind0.name in ("arc_t_on", "arc_t_off", "impulse_t"):
            # an epoch within the propagation span (a forward one: [0, final time]) unless the deck says
            span = sorted((0.0, traj.duration_days))
            lo = span[0] if lo is None else lo
            hi = span[1] if hi is None else hi
        lower[j] = lo * f0 if lo is not None else -np.inf
        upper[j] = hi * f0 if hi is not None else np.inf
        scale[j] = c.scale
        floor[j] = f0
        fd[j] = c.fd_step * f0 if c.fd_step is not None else np.nan

    # the launch excess velocity
    v_dep = None
    if max(vinf_index) >= 0:
        dep = deck.tom.departure_body or traj.initial_state.centre
        if dep not in model.bodies:
            raise _err(src, "tom.departure_body", dep, f"a body of the trajectory's model ({', '.join(model.bodies)})")
        v_dep = (
            _body_velocity(base, dep, traj.initial_state.centre) if dep != traj.initial_state.centre else np.zeros(3)
        )
        vinf_vec = base.x0[3:6] - v_dep
        vmag = float(np.linalg.norm(vinf_vec))
        vals = (vmag, math.atan2(vinf_vec[1], vinf_vec[0]), math.asin(vinf_vec[2] / vmag) if vmag > 0 else 0.0)
        for k, j in enumerate(vinf_index):
            if j >= 0:
                u_traj[j] = vals[k]
        vinf_fixed = vals
    else:
        vinf_fixed = (0.0, 0.0, 0.0)

    for j, c in enumerate(deck.control):
        u0[j] = c.nominal * factor[j] if c.nominal is not None else u_traj[j]
        if not np.isfinite(fd[j]):
            fd[j] = 1e-6 * max(abs(u0[j]) / factor[j], 1.0) * factor[j]
        if not (lower[j] <= u0[j] <= upper[j]):
            raise _err(
                src,
                f"control[{j}].nominal",
                u0[j] / factor[j],
                f"within [{lower[j] / factor[j]:g}, {upper[j] / factor[j]:g}] {units[j]}",
            )

    n_lab = len(labels)
    a_mat = np.zeros((n_lab, m))
    for row, j, cc in entries:
        a_mat[row, j] += cc
    b_mat = np.zeros((7, m))
    for row, j, cc in x0_entries:
        b_mat[row, j] += cc
    p_traj = np.asarray(get_values(params, labels, model), dtype=float)
    # p(u) = p_traj + A (u - u_traj), x0(u) = x0_traj + B (u - u_traj)
    u_lin = np.where(np.isfinite(u_traj), u_traj, 0.0)
    cmap = ControlMap(
        names=tuple(names),
        param_labels=tuple(labels),
        param_base=p_traj - a_mat @ u_lin,
        param_matrix=a_mat,
        x0_base=base.x0 - b_mat @ u_lin,
        x0_matrix=b_mat,
        final_time_s=base.final_time_s,
        final_time_index=final_index,
        vinf_index=tuple(vinf_index),
        vinf_fixed=tuple(float(v) for v in vinf_fixed),
        v_departure=v_dep,
    )

    # ---- targets
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

    ts = deck.tom
    performance = None
    if ts.performance != "final_mass":
        body = ts.performance_body or default_body
        if body not in model.bodies:
            raise _err(
                src, "tom.performance_body", body, f"a body of the trajectory's model ({', '.join(model.bodies)})"
            )
        performance = (ts.performance, model.bodies.index(body), 1.0 if ts.maximize else -1.0)
    problem = TomProblem(
        model,
        params,
        base.ephem,
        base.epoch_et_s,
        cmap,
        targets,
        fd_steps=fd,
        sensitivity_method=deck.tom.sensitivities,
        performance=performance,
    )
    perf_unit, perf_factor = ("kg", 1.0) if performance is None else target_display(ts.performance)
    if ts.max_performance_change_kg is not None:
        dfmax = ts.max_performance_change_kg * perf_factor
    elif performance is None:
        dfmax = 0.005 * float(base.x0[6])
    else:
        # 0.5 % of the performance at the start (one propagation), as 0.5 % of m0 for the mass
        f0 = problem.evaluate(u0).performance
        dfmax = 0.005 * abs(f0) if math.isfinite(f0) and f0 != 0.0 else 1.0
    submode = {"nominal": "target", "grid": "target"}.get(ts.submode, ts.submode)
    settings = SearchSettings(
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
    tf = np.array(t_factor)
    given_s = given_g = None
    if deck.smag is not None:
        given_s = np.array(deck.smag.s, float) * tf[:, None] / factor[None, :]
        given_g = np.array(deck.smag.g, float) / factor
    grid = np.array(deck.grid.increments) * factor if deck.grid is not None else None
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
    return TomCase(
        deck=deck,
        trajectory=traj,
        base=base,
        problem=problem,
        u0=u0,
        lower=lower,
        upper=upper,
        scale=scale,
        floor=floor,
        settings=settings,
        control_names=tuple(names),
        control_units=tuple(units),
        control_factor=factor,
        target_names=tuple(t_names),
        target_bodies=tuple(t_bodies),
        target_units=tuple(t_units),
        target_factor=tf,
        members=tuple(members_all),
        given_s=given_s,
        given_g=given_g,
        grid_increments=grid,
        ineq_matrix=None if order is None else order[0],
        ineq_bound=None if order is None else order[1],
        performance_name=ts.performance,
        performance_unit=perf_unit,
        performance_factor=perf_factor,
        periodic=np.array(
            [
                len(pm) == 1
                and pm[0][1].name in ("arc_alpha", "vinf_ra")
                and not np.isfinite(lower[j])
                and not np.isfinite(upper[j])
                for j, pm in enumerate(parsed)
            ]
        ),
    )


# ------------------------------------------------------------------ the reference deck
def reference_deck_text(case: TomCase, u) -> str:
    """The trajectory deck of controls U: the TOM deck's trajectory with every control's
    final value written in (TOML text, for ``fracas propagate`` and TEAM's [ertraj])."""
    import tomli_w

    traj = case.trajectory
    data = copy.deepcopy(load_toml(traj.source_text, traj.source_path or "<deck>")) if traj.source_text else {}
    for k in ("tom", "control", "target", "smag", "grid", "trajectory"):
        data.pop(k, None)
    data["mode"] = "propagate"
    prob = case.problem
    cm = prob.controls
    u = np.asarray(u, float)
    prm = prob.params_at(u)
    # a state read from an OEM ([initial_state.oem]) is written out as the cartesian state it
    # gave, with its centre and epoch explicit: the reference deck is written elsewhere, where
    # the OEM's relative path would not resolve, and the OEM may have supplied both
    st0 = traj.initial_state
    if st0.oem is not None:
        ist = data.setdefault("initial_state", {})
        ist.pop("oem", None)
        ist["centre"], ist["frame"] = st0.centre, st0.frame
        ist["cartesian"] = {"r_km": [float(a) for a in st0.oem.r_km], "v_km_s": [float(a) for a in st0.oem.v_km_s]}
        if "epoch" not in data:
            data["epoch"] = traj.epoch.model_dump(mode="json", exclude_none=True)
    # initial state (when any state or v∞ control moved it): cartesian in the deck's frame
    if np.any(cm.x0_matrix) or max(cm.vinf_index) >= 0:
        x0 = cm.x0_of(u)
        st = traj.initial_state
        rot = _rotation_to_icrf(st.frame, st.centre)
        r_deck, v_deck = rot.T @ x0[:3], rot.T @ x0[3:6]
        ist = data.setdefault("initial_state", {})
        for key in ("elements", "spherical", "cartesian"):
            ist.pop(key, None)
        ist["cartesian"] = {"r_km": [float(a) for a in r_deck], "v_km_s": [float(a) for a in v_deck]}
    if case.arcs_rewritten:  # the first guess's arcs replace the deck's
        data["thrust_arc"] = [{"frame": a.frame} for a in traj.thrust_arc]
    arcs = data.get("thrust_arc", [])
    for k, arc in enumerate(arcs):
        arc["start_days"] = float(float(prm.arc_t_on[k]) / constants.DAY_S)
        arc["stop_days"] = float(float(prm.arc_t_off[k]) / constants.DAY_S)
        arc["alpha_deg"] = _wrap_deg(math.degrees(float(prm.arc_alpha[k])))
        arc["beta_deg"] = float(math.degrees(float(prm.arc_beta[k])))
        arc["throttle"] = float(float(prm.arc_throttle[k]))
        if prob.model.steering:
            for angle in ("alpha", "beta"):
                coeffs = [math.degrees(float(getattr(prm, f"arc_{angle}_p{i}")[k])) for i in (1, 2, 3)]
                while coeffs and coeffs[-1] == 0.0:
                    coeffs.pop()
                arc.pop(f"{angle}_legendre_deg", None)
                if coeffs:
                    arc[f"{angle}_legendre_deg"] = coeffs
    imps = data.get("impulse", [])
    for k, imp in enumerate(imps):
        imp["time_days"] = float(float(prm.impulse_t[k]) / constants.DAY_S)
        imp["dv_km_s"] = [float(float(a)) for a in np.asarray(prm.impulse_dv)[k]]
    if "propulsion" in data:
        pr = data["propulsion"]
        pr.pop("isp_s", None)
        pr["exhaust_velocity_km_s"] = float(float(prm.exhaust_velocity_km_s))
        pr["thrust_scale"] = float(float(prm.thrust_scale))
    if cm.final_time_index >= 0:
        stop = data.setdefault("stop", {})
        stop.pop("final_epoch", None)
        stop["duration_days"] = float(cm.final_time(u) / constants.DAY_S)
    if traj.stop.condition == "time":
        dur = cm.final_time(u) / constants.DAY_S
        out = data.get("output", {})
        if "times_days" in out:
            out["times_days"] = [t for t in out["times_days"] if t <= dur]
    title = data.get("title", "")
    data["title"] = (title + " (TOM optimum)").strip()
    body = tomli_w.dumps({"mode": data.pop("mode"), "title": data.pop("title"), **data})
    header = (
        "# Written by fracas TOM: the trajectory deck with the converged controls written in.\n"
        f"# TOM deck: {case.deck.source_path or '<deck>'}\n"
    )
    return header + body


# ------------------------------------------------------------------ the automatic first guess
_LAW_BOUND_DEG = 180.0  # bound on each Legendre coefficient of the first guess's pass 2


def _window(deck: TomDeck, traj: TrajectoryDeck) -> tuple[float, float]:
    fg = deck.tom.first_guess
    start = fg.start_days if fg.start_days is not None else 0.0
    stop = fg.stop_days if fg.stop_days is not None else traj.duration_days
    return start, stop


def _throttled(deck: TomDeck) -> bool:
    fg = deck.tom.first_guess
    return fg.throttle if fg.throttle is not None else deck.tom.performance == "final_mass"


def auto_segments(traj: TrajectoryDeck, window_days: float) -> int:
    """[tom.first_guess] segments by default: 12 per revolution of the initial osculating orbit
    about the centre over the window (a minimum-propellant burn pattern repeats about twice per
    revolution; 6 segments per half revolution resolve it), within [24, 120]; 24 when the orbit
    is not elliptic."""
    base = build_propagation(traj)
    mu = float(base.params.mu[base.model.primary])
    r = float(np.linalg.norm(base.x0[:3]))
    v2 = float(base.x0[3:6] @ base.x0[3:6])
    energy = v2 / 2.0 - mu / r
    if energy >= 0.0:
        return 24
    a = -mu / (2.0 * energy)
    revolutions = abs(window_days) * constants.DAY_S / (2.0 * math.pi * math.sqrt(a**3 / mu))
    return int(min(120, max(24, round(12 * revolutions))))


def first_guess_segments(deck: TomDeck, traj: TrajectoryDeck) -> tuple[TomDeck, TrajectoryDeck]:
    """Pass 1 of [tom.first_guess] (:mod:`fracas.tom.first_guess`): the thrust window cut into
    ``segments`` contiguous arcs at half throttle (full when the throttle is not a control),
    thrust along the velocity (alpha = beta = 0); controls: each segment's throttle, alpha and
    (``out_of_plane``) beta, then the deck's own controls."""
    from fracas.config.tom import ControlSpec
    from fracas.config.trajectory import ThrustArc

    fg = deck.tom.first_guess
    start, stop = _window(deck, traj)
    n_segments = fg.segments if fg.segments is not None else auto_segments(traj, stop - start)
    edges = np.linspace(start, stop, n_segments + 1)
    throttled = _throttled(deck)
    arcs = [
        ThrustArc(start_days=float(a), stop_days=float(b), frame=fg.frame, throttle=0.5 if throttled else 1.0)
        for a, b in zip(edges[:-1], edges[1:])
    ]
    controls = []
    for k in range(n_segments):
        if throttled:
            controls.append(ControlSpec(name=f"arc_throttle[{k}]"))
        controls.append(ControlSpec(name=f"arc_alpha[{k}]"))
        if fg.out_of_plane:
            controls.append(ControlSpec(name=f"arc_beta[{k}]"))
    controls += list(deck.control)
    return deck.model_copy(update={"control": controls}), traj.model_copy(update={"thrust_arc": arcs})


def first_guess_burns(deck: TomDeck, traj: TrajectoryDeck, burns) -> tuple[TomDeck, TrajectoryDeck]:
    """Pass 2 of [tom.first_guess]: the burns of pass 1 (``fracas.tom.first_guess.Burn`` lists, one
    list of contiguous arcs per burn) as full-throttle arcs with their Legendre pointing laws;
    controls: each burn's start and end (the joins between a burn's arcs stay fixed), each arc's
    mean angles and Legendre coefficients up to ``degree`` (within ±180°), then the deck's own
    controls."""
    from fracas.config.tom import ControlSpec
    from fracas.config.trajectory import ThrustArc

    fg = deck.tom.first_guess
    arcs, controls = [], []
    k = 0
    for pieces in burns:
        for i, b in enumerate(pieces):
            alpha_p = [math.degrees(c) for c in b.alpha_legendre[: fg.degree]]
            beta_p = [math.degrees(c) for c in b.beta_legendre[: fg.degree]] if fg.out_of_plane else []
            arcs.append(
                ThrustArc(
                    start_days=b.start_s / constants.DAY_S,
                    stop_days=b.stop_s / constants.DAY_S,
                    frame=fg.frame,
                    alpha_deg=_wrap_deg(math.degrees(b.alpha)),
                    beta_deg=min(max(math.degrees(b.beta), -89.0), 89.0) if fg.out_of_plane else 0.0,
                    alpha_legendre_deg=alpha_p,
                    beta_legendre_deg=beta_p,
                )
            )
            # the burn's ends are controls; the joins between its arcs stay where pass 1 put them
            # (as controls they let an arc collapse, seen on Bryson & Ho: three of four arcs closed)
            if i == 0:
                controls.append(ControlSpec(name=f"arc_t_on[{k}]"))
            if i == len(pieces) - 1:
                controls.append(ControlSpec(name=f"arc_t_off[{k}]"))
            angles = ["alpha"] + (["beta"] if fg.out_of_plane else [])
            for angle in angles:
                controls.append(ControlSpec(name=f"arc_{angle}[{k}]"))
                # a law coefficient beyond 180 deg turns the thrust more than a revolution within an
                # arc: bounded, so the search cannot wander into meaningless laws
                controls += [
                    ControlSpec(name=f"arc_{angle}_p{d}[{k}]", lower=-_LAW_BOUND_DEG, upper=_LAW_BOUND_DEG)
                    for d in range(1, fg.degree + 1)
                ]
            k += 1
    controls += list(deck.control)
    return deck.model_copy(update={"control": controls}), traj.model_copy(update={"thrust_arc": arcs})
