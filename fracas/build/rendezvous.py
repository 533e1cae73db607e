"""Rendezvous deck -> :class:`fracas.team.two_vehicle.RendezvousStudy` (the one place the
deck's length unit, minutes and mrad become km, km/s, s and rad).

* each vehicle's reference: its trajectory deck propagated with its STM over the study's
  event times (target times shifted by the epoch difference), or read from its STM file
  (``stm_file``: read when it exists and was built from that trajectory deck, else
  integrated and written there), each with its own transition matrices;
* the event times: t = 0 (the a priori), every mark, reset and maneuver time;
* the a priori: block-diagonal [chaser; target; biases] (the vehicles' errors start
  uncorrelated, R-649 Fig. II-4: G_0 = 0), or with the target's given relative to the
  chaser's (``relative_a_priori``: E_T = E_A + E_rel, G_0 = E_A);
* each maneuver's intercept solved on the reference states and its 3 x 12 sensitivity.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from fracas.build.trajectory import Problem, build_propagation
from fracas.config.rendezvous import RELATIVE_KIND_NAMES, RendezvousDeck, rendezvous_problems, vehicle_deck
from fracas.config.trajectory import TrajectoryDeck, trajectory_hash
from fracas.constants import body_names_at
from fracas.errors import ConfigError, DeckError
from fracas.guidance.intercept import intercept, intercept_sensitivity
from fracas.status import RunStatus
from fracas.team.reference import run_reference
from fracas.team.two_vehicle import BiasSpec, ManeuverSpec, RendezvousStudy, ResetSpec

__all__ = ["build_rendezvous", "event_times"]

_TOL_S = 1e-6
#: canonical unit per deck unit of each relative kind's sigma: [length, length/s, mrad, mrad]
_ANGLE = 1e-3


def _kind_factor(kind: str, km: float) -> float:
    return km if kind in ("range", "range_rate") else _ANGLE


def event_times(deck: RendezvousDeck) -> tuple[np.ndarray, np.ndarray]:
    """(times_s (K,), marks (K, 4) bool): t = 0, every mark, reset and maneuver time, merged
    within 1e-6 s."""
    groups: list[tuple[np.ndarray, tuple[str, ...]]] = [(np.zeros(1), ())]
    for t in deck.tracking:
        n = int(np.floor((t.stop_min - t.start_min) * 60.0 / t.step_s + 1e-9)) + 1
        groups.append((t.start_min * 60.0 + t.step_s * np.arange(n), tuple(t.measurements)))
    groups.append((np.array([r.time_min * 60.0 for r in deck.reset]), ()))
    groups.append((np.array([m.time_min * 60.0 for m in deck.maneuver]), ()))
    allt = np.unique(np.concatenate([g[0] for g in groups]))
    keep = np.concatenate([[True], np.diff(allt) > _TOL_S])
    times = allt[keep]
    marks = np.zeros((len(times), 4), dtype=bool)
    for ts, kinds in groups:
        if not kinds or ts.size == 0:
            continue
        idx = np.searchsorted(times, ts - _TOL_S)
        for kind in kinds:
            marks[idx, RELATIVE_KIND_NAMES.index(kind)] = True
    return times, marks


def _index(times: np.ndarray, t: float) -> int:
    return int(np.argmin(np.abs(times - t)))


def _covariance(v: Any, km: float) -> np.ndarray:
    if v.covariance is not None:
        return np.asarray(v.covariance, dtype=np.float64) * km**2
    return np.diag(np.r_[np.asarray(v.position_sigma), np.asarray(v.velocity_sigma)] * km) ** 2


def _reference(
    deck: RendezvousDeck, which: str, tdeck: TrajectoryDeck, t_out: np.ndarray, marks: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float, Problem, str]:
    """(states (K, 6), step STMs (K, 6, 6), mu km^3/s^2, problem, source) of one vehicle at
    t_out (s from its own epoch): from its STM file when the deck names one that exists
    (checked against the trajectory deck's hash), else integrated in line, and then written
    to the named STM file if there is one (so the next study reuses it)."""
    from fracas.io.atomic import check_output_path
    from fracas.io.stm_file import check_trajectory, read_stm_file, write_stm_file
    from fracas.products import chain, time_indices

    problem = build_propagation(tdeck)
    bodies = problem.model.bodies
    centre = tdeck.initial_state.centre
    mu = float(np.asarray(problem.params.mu)[bodies.index(centre)])
    v = getattr(deck, which)
    stm_path = deck.resolve(v.stm_file) if v.stm_file else None
    if stm_path is not None and stm_path.exists():
        data = read_stm_file(stm_path, labels=[], times_s=t_out, epoch_et_s=float(problem.epoch_et_s))
        check_trajectory(data, trajectory_hash(tdeck), stm_path, tdeck.source_path)
        idx = time_indices(data, t_out)
        phi = chain(data, t_out)[0][:, :6, :6]
        states = np.asarray(data.states)[idx, :6]
        prim = [data.primary[int(i)] for i in idx]
        source = str(stm_path)
    else:
        if stm_path is not None:
            check_output_path(stm_path, f"{which}.stm_file")
        lead = t_out[0] > 0.0
        t_int = np.concatenate([[0.0], t_out]) if lead else t_out
        traj, sens, status, failed_at = run_reference(problem, t_int, [])
        if status != RunStatus.OK or int(traj.status) != 0:
            raise ConfigError(
                f"{deck.source_path}: {which}.trajectory: the reference failed at t = {failed_at / 60.0:.3f} min "
                f"(integrator status {int(traj.status)}); expected a trajectory covering the study"
            )
        sl = slice(1, None) if lead else slice(None)
        states = np.array(traj.x)[sl, :6]
        phi = np.array(sens.stm_step)[sl, :6, :6]
        prim = body_names_at(bodies, np.asarray(traj.primary)[sl])
        source = "integrated"
        if stm_path is not None:
            from dataclasses import replace

            from fracas.build.reference import reference_product

            ev = ["initial"] if lead else []
            ev += ["measurement" if np.any(m) else "propagation" for m in marks]
            if not lead:
                ev[0] = "initial"
            data = reference_product(
                replace(problem, t_out=t_int, param_labels=()),
                traj,
                sens,
                ev,
                tdeck.source_text or "",
                trajectory_hash(tdeck),
                tdeck.source_path,
            )
            write_stm_file(stm_path, data)
            source = f"integrated, written to {stm_path}"
    if any(p != centre for p in prim):
        raise ConfigError(
            f"{deck.source_path}: {which}.trajectory: the vehicle leaves {centre}'s sphere of influence "
            f"during the study; expected one centre"
        )
    return states, phi, mu, problem, source


def _check_marks(deck: RendezvousDeck, times: np.ndarray, marks: np.ndarray, xa: np.ndarray, xt: np.ndarray) -> None:
    """DeckError naming the tracking entry and time of a mark whose geometry is degenerate:
    the vehicles at one place (range 1 m or less: no range rate or angle there) or the
    line of sight along the sensor's i_ym axis (beta undefined)."""
    r = xt[:, :3] - xa[:, :3]
    rho = np.linalg.norm(r, axis=1)
    s = r @ np.asarray(deck.sensor.axes, dtype=np.float64).T
    flat = np.hypot(s[:, 0], s[:, 2]) <= 1e-9 * np.maximum(rho, 1e-300)
    angles = marks[:, 2] | marks[:, 3]
    bad = np.any(marks, axis=1) & ((rho <= 1e-3) | ~np.isfinite(rho) | (angles & flat))
    if np.any(bad):
        k = int(np.argmax(bad))
        t_min = times[k] / 60.0
        i = next((i for i, t in enumerate(deck.tracking) if t.start_min - 1e-9 <= t_min <= t.stop_min + 1e-9), 0)
        raise DeckError(
            f"{deck.source_path}: tracking[{i}]: a mark at {t_min:.3f} min has range {rho[k] * 1e3:.3g} m"
            + (" along the sensor's i_ym axis" if rho[k] > 1e-3 else "")
            + " (expected two separated vehicles: no relative measurement is defined there)"
        )


def _is_two_body(problem: Problem) -> bool:
    """Point-mass, ballistic, one centre: the conic is the exact reference."""
    m = problem.model
    return not (m.third_bodies or m.j2 or m.srp or m.thrust or m.n_impulses or m.change_primary_at_soi)


@dataclass(frozen=True)
class _References:
    """Both vehicles' references at the study's times: states (K, 6), step STMs (K, 6, 6)
    with Φ(t_0, t_0) = I, the centre and its mu, the chaser's problem, the sources, two-body or not."""

    xa: np.ndarray
    phia: np.ndarray
    xt: np.ndarray
    phit: np.ndarray
    mu: float
    centre: str
    prob_a: Problem
    sources: tuple[str, str]
    two_body: bool


def _references(deck: RendezvousDeck, times: np.ndarray, marks: np.ndarray) -> _References:
    """The chaser's and the target's references (the target's epoch at or before the chaser's)."""
    da, dt = vehicle_deck(deck, "chaser"), vehicle_deck(deck, "target")
    shift = da.epoch.et - dt.epoch.et
    if shift < -_TOL_S:
        raise DeckError(
            f"{deck.source_path}: target.trajectory: its epoch is {-shift:.1f} s after the chaser's; "
            "expected the target's epoch at or before the chaser's"
        )
    xa, phia, mu, prob_a, src_a = _reference(deck, "chaser", da, times, marks)
    xt, phit, _, prob_t, src_t = _reference(deck, "target", dt, times + max(shift, 0.0), marks)
    two_body = _is_two_body(prob_a) and _is_two_body(prob_t)
    if deck.single_runs.dynamics == "two_body" and not two_body:
        raise DeckError(
            f'{deck.source_path}: single_runs.dynamics = "two_body": a trajectory deck has third bodies, J2, SRP, '
            'thrust or impulses; expected point-mass ballistic references (or dynamics = "linear")'
        )
    # the first step: Phi(t_0, t_0) = I (the a priori holds at t_0 = 0)
    phia[0] = np.eye(6)
    phit[0] = np.eye(6)
    return _References(xa, phia, xt, phit, mu, da.initial_state.centre, prob_a, (src_a, src_t), two_body)


def _noise_models(deck: RendezvousDeck, km: float) -> tuple[np.ndarray, np.ndarray]:
    """(assumed, true) noise (sigma, fraction, floor) of each relative kind, in km and rad."""
    nz = lambda n: np.array([n.sigma, n.fraction, n.floor], dtype=np.float64)  # noqa: E731
    noise_a = np.zeros((4, 3))
    noise_t = np.zeros((4, 3))
    for i, kind in enumerate(RELATIVE_KIND_NAMES):
        n = getattr(deck.noise, kind)
        if n is None:
            noise_a[i] = noise_t[i] = [1.0, 0.0, 0.0]  # unused: no marks of this kind
            continue
        f = _kind_factor(kind, km)
        a = nz(n) * np.array([f, 1.0, f])
        t = np.array(n.true_model(), dtype=np.float64) * np.array([f, 1.0, f])
        noise_a[i], noise_t[i] = a, t
    return noise_a, noise_t


def _biases(deck: RendezvousDeck, km: float) -> tuple[BiasSpec, ...]:
    """The [[bias]] entries: kind index, sigma in km or rad, role, τ (s; inf: constant)."""
    return tuple(
        BiasSpec(
            b.name,
            RELATIVE_KIND_NAMES.index(b.measurement),
            b.sigma * _kind_factor(b.measurement, km),
            b.role,
            b.tau_s if b.tau_s is not None else float("inf"),
        )
        for b in deck.bias
    )


def _a_priori(deck: RendezvousDeck, km: float, biases: tuple[BiasSpec, ...]) -> np.ndarray:
    """The true a-priori covariance of [chaser, target, biases] (km, km/s)."""
    nb = len(biases)
    P0 = np.zeros((12 + nb, 12 + nb))
    P0[:6, :6] = _covariance(deck.chaser, km)
    P0[6:12, 6:12] = _covariance(deck.target, km)
    if deck.target.relative_a_priori:  # x_T = x_A + x_rel with x_rel independent of x_A
        P0[6:12, 6:12] += P0[:6, :6]
        P0[:6, 6:12] = P0[:6, :6]
        P0[6:12, :6] = P0[:6, :6]
    for j, b in enumerate(biases):
        P0[12 + j, 12 + j] = b.sigma**2
    return P0


def _resets(deck: RendezvousDeck, times: np.ndarray, km: float) -> tuple[ResetSpec, ...]:
    """The [[reset]] entries: the time index, the sigmas (km, km/s) and the roles reset."""
    return tuple(
        ResetSpec(
            _index(times, r.time_min * 60.0),
            np.r_[np.asarray(r.position_sigma), np.asarray(r.velocity_sigma)] * km,
            tuple(r.roles),
        )
        for r in deck.reset
    )


def _maneuvers(deck: RendezvousDeck, times: np.ndarray, refs: _References) -> tuple[ManeuverSpec, ...]:
    """Each [[maneuver]]: the conic intercept of the target and its sensitivity."""
    xa, xt, mu = refs.xa, refs.xt, refs.mu
    mans = []
    for m in deck.maneuver:
        k = _index(times, m.time_min * 60.0)
        tof = (m.arrival_min - m.time_min) * 60.0
        dv, v1, miss, status = intercept(xa[k], xt[k], tof, mu)
        if int(status) != 0:
            j = deck.maneuver.index(m)
            raise DeckError(
                f"{deck.source_path}: maneuver[{j}].arrival_min = {m.arrival_min:g}: no intercept of the target "
                f"found from {m.time_min:g} min (miss {float(miss):.3g} km after the iterations; expected a "
                "transfer the conic targeting can reach: change the times, avoid a 180-deg transfer)"
            )
        M = np.asarray(intercept_sensitivity(xa[k], xt[k], v1, tof, mu))
        mans.append(ManeuverSpec(m.name, k, float(times[k]), m.arrival_min * 60.0, M, np.asarray(dv), int(status)))
    return tuple(mans)


def build_rendezvous(deck: RendezvousDeck) -> RendezvousStudy:
    """The study of a validated rendezvous deck (module docstring); DeckError / ConfigError
    (one line, naming the field) for what the schema cannot see.

    The steps: the deck's cross-vehicle checks, the event times, both references, the noise
    models, the biases and the a priori, the marks' geometry, the resets and the maneuvers."""
    probs = rendezvous_problems(deck)
    if probs:
        raise DeckError(probs[0] + (f" (and {len(probs) - 1} more errors)" if len(probs) > 1 else ""), problems=probs)
    km = deck.km_per_unit
    times, marks = event_times(deck)
    refs = _references(deck, times, marks)
    noise_a, noise_t = _noise_models(deck, km)
    biases = _biases(deck, km)
    P0 = _a_priori(deck, km, biases)
    _check_marks(deck, times, marks, refs.xa, refs.xt)
    load = None
    if deck.chaser.filter_position_sigma is not None:
        load = np.r_[np.asarray(deck.chaser.filter_position_sigma), np.asarray(deck.chaser.filter_velocity_sigma)] * km
    resets = _resets(deck, times, km)
    mans = _maneuvers(deck, times, refs)
    return RendezvousStudy(
        title=deck.title,
        source=deck.source_path or "<deck>",
        chaser_name=deck.chaser.name,
        target_name=deck.target.name,
        centre=refs.centre,
        mu_km3_s2=refs.mu,
        times_s=times,
        x_chaser=refs.xa,
        x_target=refs.xt,
        phi_chaser=refs.phia,
        phi_target=refs.phit,
        marks=marks,
        noise_assumed=noise_a,
        noise_true=noise_t,
        axes=np.asarray(deck.sensor.axes, dtype=np.float64),
        P0_true=P0,
        chaser_load=load,
        biases=biases,
        roles=tuple(deck.roles),
        resets=resets,
        maneuvers=mans,
        length_unit=deck.units,
        km_per_unit=km,
        epoch_et_s=float(refs.prob_a.epoch_et_s),
        two_body=refs.two_body,
        reference_sources=refs.sources,
    )


def trajectory_hashes(deck: RendezvousDeck) -> dict[str, str]:
    """The two trajectory decks' hashes (provenance)."""
    return {w: trajectory_hash(vehicle_deck(deck, w)) for w in ("chaser", "target")}
