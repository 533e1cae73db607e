"""The numbers a TEAM deck alone fixes (FRACAS DATA, sec. 5.3.2): the a-priori covariances
(assumed and true, diagonal or UNF-shaped), the Gauss-Markov thrust-noise levels, the white
process noise, the observations with their sigmas and the noise cell step; and the
reference trajectory of ``[ertraj]`` they are built on.

:func:`study_numbers` is shared by :func:`fracas.build.team.build_case` and
:func:`fracas.build.vary.derive_study` (a sweep's studies that differ only in numbers).
The units and bounds of the thrust-noise and a-priori fields are :mod:`fracas.config.fields`.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from fracas.build.onboard import onboard_config
from fracas.build.trajectory import Problem, build_propagation
from fracas.config.fields import THRUST_NOISE_COMPONENTS
from fracas.config.limits import check_team_sizes
from fracas.config.team import SIGMA_UNITS, APriori, GenCov, TeamDeck, ThrustNoise, WhiteNoise
from fracas.config.team.span import check_team_span
from fracas.config.trajectory import BACKWARD_TEAM_PROBLEM, TrajectoryDeck, load_deck
from fracas.config.trajectory.plausible import state_warnings, warn
from fracas.constants import DAY_S
from fracas.errors import DeckError
from fracas.filters.apriori import shaped_covariance
from fracas.integrate.propagate import propagate
from fracas.measurements import trakm
from fracas.team.transitions import noise_cell_step

__all__ = ["trajectory_problem", "start_state", "study_numbers"]


def _err(src: str, field: str, value: Any, expected: str) -> DeckError:
    v = f' = "{value}"' if isinstance(value, str) else (f" = {value}" if value is not None else "")
    return DeckError(f"{src}: {field}{v}: {expected}")


def trajectory_problem(deck: TeamDeck, src: str) -> tuple[TrajectoryDeck, Problem]:
    """Load the [ertraj] trajectory deck and build its propagation problem."""
    path = deck.resolve(deck.ertraj.deck)
    if not path.exists():
        raise _err(src, "ertraj.deck", deck.ertraj.deck, f"no such trajectory deck ({path})")
    tdeck = load_deck(path)
    if tdeck.backward:
        raise _err(src, "ertraj.deck", deck.ertraj.deck, BACKWARD_TEAM_PROBLEM)
    warn(state_warnings(tdeck))  # a unit slip in the initial state, most likely (the run goes on)
    check_team_span(deck, tdeck)  # refuse a study that runs past its trajectory (it would be cut short)
    check_team_sizes(deck, tdeck)  # refuse a study too big for its trajectory before building anything
    return tdeck, build_propagation(tdeck)


def _gencov(deck: TeamDeck) -> GenCov | None:
    """The deck's [gencov] when enabled (generalized covariance), else None."""
    return deck.gencov if (deck.gencov is not None and deck.gencov.enabled) else None


def _state_sigmas(ap: APriori, nx: int) -> np.ndarray:
    pos, vel = ap.sigmas()
    s = list(pos) + list(vel) + ([ap.mass_sigma_kg] if nx == 7 else [])
    return np.asarray(s, dtype=np.float64)


def _noise(tn: ThrustNoise) -> tuple[np.ndarray, np.ndarray]:
    """(sigma, tau s) of the three Gauss-Markov thrust errors (proportionality, in-plane rad,
    out-of-plane rad); a component left out has sigma 0, tau 1 day (fracas.config.fields)."""
    sig, tau = np.zeros(3), np.full(3, DAY_S)
    for i, field in enumerate(THRUST_NOISE_COMPONENTS):
        c = getattr(tn, field.name)
        if c is not None:
            sig[i], tau[i] = c.sigma * field.factor, c.tau_days * DAY_S
    return sig, tau


def start_state(deck: TeamDeck, src: str, problem: Problem | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """(r km (3,), v km/s (3,), mu km^3/s^2): the reference state at the filter's start
    (filter.start_days) relative to its primary, and that primary's gravitational parameter
    (the shaped a-priori's pseudo measurements are evaluated there).  Integrates the
    trajectory from its epoch (loading it when ``problem`` is None)."""
    if problem is None:
        _, problem = trajectory_problem(deck, src)
    t0 = deck.filter.start_days * DAY_S
    x, prim = np.asarray(problem.x0, np.float64), int(problem.model.primary)
    if t0 > 0:
        pr = dataclasses.replace(problem, sensitivities=False)
        traj = propagate(pr.model, pr.params, pr.ephem, pr.epoch_et_s, pr.x0, np.array([0.0, t0]))
        x, prim = np.asarray(traj.x, np.float64)[-1], int(np.asarray(traj.primary)[-1])
        if not np.all(np.isfinite(x)):
            raise _err(
                src, "a_priori.shaped", None, f"the trajectory does not reach filter.start_days = {t0 / DAY_S:g}"
            )
    return x[:3], x[3:6], float(np.asarray(problem.params.mu)[prim])


def _shape(P: np.ndarray | None, ap: APriori | None, state: tuple | None) -> np.ndarray | None:
    """P with its 6x6 state block replaced by ``ap.shaped``'s correlated a-priori (UNF)."""
    if ap is None or ap.shaped is None or P is None:
        return P
    sh = ap.shaped
    r, v, mu = state
    P = np.array(P, dtype=np.float64)
    P[:6, :6] = np.asarray(
        shaped_covariance(
            r,
            v,
            mu,
            sh.sigma_r_km,
            sh.sigma_v_km_s,
            sh.sigma_energy_km2_s2,
            sh.sigma_h_km2_s,
            sh.lv_crosstrack_sigma_r_km,
            sh.lv_crosstrack_sigma_v_km_s,
        )
    )
    return P


def _white(pn: WhiteNoise, base: tuple[float, str]) -> tuple[float, str]:
    q = base[0] if pn.white_acceleration_km2_s3 is None else float(pn.white_acceleration_km2_s3)
    return q, base[1] if pn.direction is None else pn.direction


def study_numbers(
    deck: TeamDeck, src: str, nx: int, labels: list[str], nw: int, thrust: bool, state: tuple | None = None
) -> dict:
    """The numbers of a study that its deck alone fixes (DATA), as build_case computes them:
    the diagonal a-priori covariances (assumed, with the ignore parameters at zero, and
    true; None without [a_priori] sigmas), the Gauss-Markov levels, the observations with
    their assumed sigmas, the true sigmas and the noise cell step.  ``labels``: the study's
    parameters in layout order, the last ``nw`` of them ignore parameters; ``state``: the
    :func:`start_state` for a shaped a-priori (None: computed here when needed).  Shared with
    :func:`fracas.build.vary.derive_study` (a sweep's studies that differ only in numbers)."""
    gen = _gencov(deck)
    sigma = {p.label: p.sigma for p in deck.parameter}
    true_sigma: dict[str, float] = {}
    if gen is not None:
        for g in gen.parameter:
            if g.role == "ignore":
                sigma[g.label] = g.sigma
            else:
                true_sigma[g.label] = g.sigma
    p_sig_a = np.array([sigma[lab] for lab in labels], dtype=np.float64)
    p_sig_t = np.array([true_sigma.get(lab, sigma[lab]) for lab in labels], dtype=np.float64)
    if nw:  # the filter does not know its ignore parameters
        p_sig_a[-nw:] = 0.0
    P0a = P0t = None
    if deck.a_priori is not None and not deck.a_priori.from_punch:
        xs_a = _state_sigmas(deck.a_priori, nx)
        xs_t = _state_sigmas(gen.a_priori, nx) if (gen is not None and gen.a_priori is not None) else xs_a
        P0a = np.diag(np.concatenate([xs_a, p_sig_a]) ** 2)
        P0t = np.diag(np.concatenate([xs_t, p_sig_t]) ** 2)
        ap_t = gen.a_priori if (gen is not None and gen.a_priori is not None) else deck.a_priori
        if deck.a_priori.shaped is not None or ap_t.shaped is not None:
            state = start_state(deck, src) if state is None else state
            P0a, P0t = _shape(P0a, deck.a_priori, state), _shape(P0t, ap_t, state)
    sig_a, tau_a = _noise(deck.thrust_noise)
    sig_t, tau_t = _noise(gen.thrust_noise) if (gen is not None and gen.thrust_noise is not None) else (sig_a, tau_a)
    if (np.any(sig_a > 0) or np.any(sig_t > 0)) and not thrust:
        raise _err(src, "thrust_noise", None, "the trajectory deck has no thrust ([propulsion] and [[thrust_arc]])")
    wq_a = _white(deck.process_noise, (0.0, "full"))
    wq_t = _white(gen.process_noise, wq_a) if (gen is not None and gen.process_noise is not None) else wq_a
    if gen is not None and gen.process_noise is not None and gen.process_noise.quadrature_step_hours is not None:
        raise _err(
            src, "gencov.process_noise.quadrature_step_hours", None, "set the quadrature step in [process_noise]"
        )
    obs, tsig = [], []
    for t in deck.tracking:
        _, k = SIGMA_UNITS[t.type]
        obs.append(trakm.Observation(t.type, tuple(t.stations), t.sigma * k, *onboard_config(t)))
        tsig.append((gen.measurement_sigma.get(t.type, t.sigma) if gen is not None else t.sigma) * k)
    return {
        "P0_assumed": P0a,
        "P0_true": P0t,
        "noise_sigma_assumed": sig_a,
        "noise_tau_assumed": tau_a,
        "noise_sigma_true": sig_t,
        "noise_tau_true": tau_t,
        "observations": obs,
        "true_sigma": np.array(tsig, dtype=np.float64),
        "white_q_assumed": wq_a[0],
        "white_q_true": wq_t[0],
        "white_direction_assumed": wq_a[1],
        "white_direction_true": wq_t[1],
        "white_step_s": (deck.process_noise.quadrature_step_hours or deck.errcon.noise_step_hours) * 3600.0,
        "noise_step_s": noise_cell_step(  # on the deck's STM grid: in-line and file runs share the cells
            deck.errcon.noise_step_hours * 3600.0, (deck.stm.grid_hours or 0.0) * 3600.0, np.concatenate([tau_a, tau_t])
        ),
    }
