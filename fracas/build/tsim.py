"""TSIM deck + its TEAM run -> :class:`fracas.tsim.plan.TsimPlan` (FRACAS DATAS, digest C.3).

The one place where the TSIM deck's km, km/s, days and the TEAM run's products become the
plan the engine flies:

* the injection and parameter dispersions: the TEAM study's control a-priori (its
  ``[control]``, else its true a-priori) over the whole augmented state, with the state block
  replaced by ``[insim.injection]`` when given, in its frame (RTN rotated to inertial at the
  injection state: a 1 km radial σ is 1 km along r, not spread over the axes);
* one maneuver per TEAM guidance event (``enabled = false`` drops one): TEAM's guidance
  matrix Γ, its true knowledge covariance at the event (or the deck's), the target set and
  tolerances, K = ∂T/∂U about the reference with its weighted pseudo-inverse, TEAM's
  predictions for the comparison;
* the Gauss-Markov hold grid (every maneuver and target time is a node);
* the reference itself, flown by the engine with every deviation zero through the same grid
  (so the null run, digest S1, deviates by exactly zero).

``scale`` multiplies every σ (injection, parameters, knowledge, thrust noise, execution).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fracas.constants import DAY_S
from fracas.dynamics.parameters import get_values
from fracas.errors import DeckError, NumericalError
from fracas.guidance.low_thrust import weighted_correction_matrix
from fracas.guidance.target_kinds import TARGET_KINDS
from fracas.guidance.targets import target_values
from fracas.tsim import engine
from fracas.tsim.plan import ManeuverPlan, TargetPlan, TsimPlan
from fracas.tsim.sampling import covariance_factor, rotate_state_covariance, rtn_matrix

__all__ = ["build_plan", "default_tolerance"]

_DEFAULT_TOL = {"km": 0.1, "km/s": 1e-6, "rad": 1e-7, "s": 1.0, "": 1e-6, "kg": 1e-3}


def default_tolerance(unit: str) -> float:
    """A nonlinear design's default tolerance for a target in ``unit`` (0.1 km, 1 mm/s, ...)."""
    return _DEFAULT_TOL.get(unit, 1e-6)


def _body_offset(study, body: str, centre: str, t_s: float) -> np.ndarray:
    if body == centre:
        return np.zeros(6)
    from fracas.team.guidance import _relative_body_state  # the TEAM guidance's own DE421 lookup

    return np.asarray(_relative_body_state(study, body, centre, t_s))


def _grid(key_times: list[float], t_end: float, step_s: float | None) -> np.ndarray:
    pts = {float(t) for t in key_times} | {0.0, float(t_end)}
    if step_s is not None and np.isfinite(step_s) and step_s > 0:
        pts |= set(np.arange(0.0, t_end, step_s).tolist())
    g = np.array(sorted(pts))
    keep = np.concatenate([[True], np.diff(g) > 1.0])  # drop cells under 1 s
    g = g[keep]
    for t in key_times:  # key times stay exact nodes
        g[np.argmin(np.abs(g - t))] = t
    return g


def _injection_factor(cfg: Any, study: Any, src: str) -> np.ndarray:
    """The sampling factor of the injection and parameter dispersions (scaled): the study's
    control a-priori (else its true one), its state block replaced by ``[insim.injection]``."""
    ins = cfg.insim
    k = float(ins.scale)
    pr = study.problem
    nx = study.nx
    p0 = np.array(study.P0_control if study.P0_control is not None else study.P0_true, dtype=np.float64)
    if ins.injection is not None:
        inj = ins.injection
        d = np.diag(
            np.concatenate(
                [np.square(inj.position_sigma_km), np.square(inj.velocity_sigma_km_s), [inj.mass_sigma_kg**2]]
            )
        )
        if inj.frame == "rtn":
            c = np.asarray(rtn_matrix(pr.x0[:3], pr.x0[3:6]))
            d6 = np.asarray(rotate_state_covariance(d[:6, :6], c))
            d[:6, :6] = d6
        p0[:nx, :] = 0.0
        p0[:, :nx] = 0.0
        p0[:nx, :nx] = d[:nx, :nx]
    try:
        return covariance_factor(k * k * p0, ins.sampling)
    except ValueError as exc:
        raise DeckError(f"{src}: insim.sampling = {ins.sampling!r}: the injection covariance: {exc}") from None


def _hold_grid(study: Any, ins: Any) -> tuple[float, list[float], float | None, np.ndarray]:
    """(final target time s, key times s, noise hold step s or None, the hold grid s): every
    maneuver and target time is a node; the step is the deck's or a tenth of the shortest τ."""
    t_end = max(g.target_time_s for g in study.guidance)
    key_times = sorted({0.0} | {g.time_s for g in study.guidance} | {g.target_time_s for g in study.guidance})
    if np.any(study.noise_sigma_true > 0):
        step = ins.noise_step_days * DAY_S if ins.noise_step_days else float(np.min(study.noise_tau_true)) / 10.0
    else:
        step = None
    return t_end, key_times, step, _grid(key_times, t_end, step)


def _skeleton(study: Any, grid: np.ndarray, n_key: int, t_end: float) -> TsimPlan:
    """A plan without a reference yet: the engine flies it (all deviations zero) to make one."""
    pr = study.problem
    model, params = pr.model, pr.params
    nx, n = study.nx, study.layout.n
    labels = tuple(study.labels)
    dyn_labels = tuple(lab for lab, d in zip(labels, study.dynamic) if d)
    dyn_index = np.array([nx + i for i, d in enumerate(study.dynamic) if d], dtype=np.int64)
    est_roles = ("solve_for",) if study.guidance_estimates == "state_and_solve_for" else ()
    est_dyn = np.array([study.roles[i] in est_roles for i, d in enumerate(study.dynamic) if d], dtype=bool)
    blank_t = TargetPlan((), (), t_end, np.zeros(0), np.zeros(6), 1.0, np.zeros(0))
    return TsimPlan(
        model=model, params=params, ephem=pr.ephem, epoch_et_s=float(pr.epoch_et_s), x0=np.asarray(pr.x0, float),
        nx=nx, labels=labels, dyn_labels=dyn_labels, dyn_index=dyn_index, est_dyn=est_dyn,
        init_factor=np.zeros((n, n)), noise_sigma=np.zeros(3), noise_tau_s=np.asarray(study.noise_tau_true, float),
        grid_s=grid, x_ref=np.zeros((n_key, 7)), maneuvers=(), final=blank_t, final_team={},
        seed=0, near_success_factor=1.0, isp_s=float(np.asarray(params.impulse_isp_s)), first_mission=0, missions=1,
    )  # fmt: skip


def _reference_at(cfg: Any, skeleton: TsimPlan, key_times: list[float]) -> dict[float, np.ndarray]:
    """The reference state at each key time, flown through the hold grid."""
    x_key, failed_at = engine.reference_states(skeleton, key_times)
    if np.isfinite(failed_at):
        raise NumericalError(
            f"{cfg.source_path}: insim.team_deck: the reference trajectory of {cfg.insim.team_deck} could not be "
            f"flown through the Monte Carlo hold grid to {failed_at / DAY_S:.6g} d (expected a trajectory that "
            "reaches every maneuver and target time)"
        )
    return dict(zip(key_times, x_key))


@dataclass
class _Targets:
    """Target plans about the reference: the target values at the target time, relative to the
    target body (default the centre), whose mu is looked up once."""

    study: Any
    centre: str
    ref_at: dict[float, np.ndarray]
    mu_of: dict[str, float] = field(default_factory=dict)

    def plan(self, names: Any, units: Any, t_s: float, body: str | None, tolerance: Any) -> TargetPlan:
        pr = self.study.problem
        body = body or self.centre
        if body not in self.mu_of:
            self.mu_of[body] = float(np.asarray(get_values(pr.params, [f"mu[{body}]"], pr.model))[0])
        off = _body_offset(self.study, body, self.centre, t_s)
        ref = np.asarray(target_values(tuple(names), self.ref_at[t_s][:6] - off, float(t_s), self.mu_of[body]))
        return TargetPlan(
            tuple(names), tuple(units), float(t_s), ref, off, self.mu_of[body], np.asarray(tolerance, float)
        )


def _tolerances(g: Any, s: Any, units: list[str]) -> list[float]:
    """A maneuver's target tolerances: the TSIM deck's, else the guidance event's, else the defaults."""
    if s is not None and s.tolerance is not None:
        return list(s.tolerance)
    if g.tolerances is not None:
        return list(g.tolerances)
    return [default_tolerance(u) for u in units]


def _knowledge_factor(g: Any, s: Any, ev: Any, hist: Any, n: int, k: float, method: str, src: str) -> np.ndarray:
    """The sampling factor of the knowledge error at a maneuver: the deck's sigmas, or TEAM's
    true knowledge covariance there (scaled)."""
    if s is not None and s.knowledge == "deck":
        pk = np.zeros((n, n))
        sig = np.concatenate([s.knowledge_position_sigma_km, s.knowledge_velocity_sigma_km_s])
        pk[:6, :6] = np.diag(sig**2)
    else:
        # over the study's states: the exact model's noise states (issue 24) are never
        # estimated and the law's columns for them are zero
        pk = np.array(hist.P_plus[ev.index], dtype=np.float64)[:n, :n]
    try:
        return covariance_factor(k * k * pk, method)
    except ValueError as exc:
        raise DeckError(f"{src}: insim.sampling = {method!r}: the knowledge covariance at {g.name}: {exc}") from None


def _maneuver(g: Any, s: Any, ev: Any, tp: TargetPlan, kfac: np.ndarray, k: float, n: int) -> ManeuverPlan:
    """One maneuver: TEAM's K = ∂T/∂U and Γ, the weighted pseudo-inverse, the execution σ
    (scaled) and TEAM's predictions for the comparison."""
    psi = np.asarray(ev.psi)
    m = len(g.targets)
    w, tl = g.weights, g.tolerances
    if g.type == "impulsive":
        k_mat = psi[:, 3:6]
        ctrl, units_u = ("dv_x", "dv_y", "dv_z"), ("km/s",) * 3
        dv_jac = np.zeros(3)
    else:
        k_mat = np.asarray(ev.control_matrix, float)  # TEAM's K = Ψ S (not integrated again)
        ctrl, units_u = tuple(g.control_labels), tuple(g.control_units)
        dv_jac = np.asarray(ev.dv_jacobian if ev.dv_jacobian is not None else np.zeros(len(ctrl)), float)
    k_pinv = np.asarray(weighted_correction_matrix(k_mat, np.eye(m), w, tl)[0])
    kk = np.asarray(weighted_correction_matrix(k_mat, k_mat, w, tl)[0])
    return ManeuverPlan(
        name=g.name, type=g.type, time_s=float(g.time_s),
        law=s.law if s is not None else "linear", max_iterations=s.max_iterations if s is not None else 8,
        target=tp, gamma=np.asarray(ev.gamma, float)[:, :n], knowledge_factor=kfac, control_labels=ctrl,
        control_units=units_u, k_pinv=k_pinv, kk=kk, dv_jacobian=dv_jac,
        sigma_p=k * g.sigma_p, sigma_pointing_rad=k * g.sigma_pointing_rad, sigma_res_km_s=k * g.sigma_res_km_s,
        team={
            "correction_cov": np.asarray(ev.correction_cov) * k * k,
            "dv_mean_km_s": k * ev.dv_mean_km_s,
            "dv_99_km_s": k * ev.dv_99_km_s,
            "target_cov_before": np.asarray(ev.target_cov_before) * k * k,
            "target_cov_after": np.asarray(ev.target_cov_after) * k * k,
        },
    )  # fmt: skip


def _maneuvers(cfg: Any, study: Any, team: Any, targets: _Targets, src: str) -> list[ManeuverPlan]:
    """One maneuver per enabled TEAM guidance event (type "none" flies none)."""
    ins = cfg.insim
    k = float(ins.scale)
    n = study.layout.n
    settings = {m.name: m for m in cfg.maneuver}
    events = {g.name: g for g in team.guidance}
    hist = team.true if team.true is not None else team.assumed
    maneuvers = []
    for g in study.guidance:
        s = settings.get(g.name)
        if s is not None and not s.enabled:
            continue
        if g.type == "none":
            continue
        ev = events[g.name]
        units = [TARGET_KINDS[t].unit for t in g.targets]
        tol = _tolerances(g, s, units)
        tp = targets.plan(g.targets, units, g.target_time_s, g.target_body, tol)
        kfac = _knowledge_factor(g, s, ev, hist, n, k, ins.sampling, src)
        maneuvers.append(_maneuver(g, s, ev, tp, kfac, k, n))
    if not maneuvers:
        raise DeckError(f"{src}: maneuver: every guidance event is disabled (TSIM needs at least one to fly)")
    return maneuvers


def build_plan(cfg: Any, case: Any, team: Any) -> TsimPlan:
    """The plan of TSIM deck ``cfg`` (TsimDeck) on TEAM case ``case`` with its TEAM product
    ``team`` (run with the ``tsim`` guidance model).  DeckError for what only now shows.

    The steps: the injection dispersions, the hold grid, the reference flown through it, the
    maneuvers, then the plan."""
    study = case.study
    src = cfg.source_path or "<deck>"
    ins = cfg.insim
    k = float(ins.scale)
    model = study.problem.model
    centre = model.bodies[model.primary]
    init_factor = _injection_factor(cfg, study, src)
    t_end, key_times, step, grid = _hold_grid(study, ins)
    skeleton = _skeleton(study, grid, len(key_times), t_end)
    ref_at = _reference_at(cfg, skeleton, key_times)
    maneuvers = _maneuvers(cfg, study, team, _Targets(study, centre, ref_at), src)
    last = maneuvers[-1]
    final = last.target
    x_ref = np.stack([ref_at[m.time_s] for m in maneuvers] + [ref_at[final.t_s]])
    plan = dataclasses.replace(
        skeleton,
        init_factor=init_factor,
        noise_sigma=k * np.asarray(study.noise_sigma_true, float),
        x_ref=x_ref,
        maneuvers=tuple(maneuvers),
        final=final,
        final_team={"target_cov": last.team["target_cov_after"], "event": last.name},
        seed=int(ins.seed),
        near_success_factor=float(ins.near_success_factor),
        first_mission=int(ins.first_mission),
        missions=int(ins.missions),
        impulse_propellant=ins.impulse_propellant,
        info={"grid_step_s": step, "sampling": ins.sampling, "scale": k},
    )
    return plan
