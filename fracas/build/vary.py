"""A study that differs from another only in numbers, without building it again (sweeps).

:func:`derive_study` takes a :class:`~fracas.team.study.Study` built by
:func:`fracas.build.team.build_case` and a validated TEAM deck that differs from that study's
deck only in numeric fields (:data:`fracas.config.sweep.NUMERIC_FIELDS`: a-priori and
parameter sigmas, thrust-noise sigmas and correlation times, tracking and generalized
measurement sigmas) and returns the deck's study as ``dataclasses.replace`` of the given one:
its P0 (assumed and true), noise levels, observation and true measurement sigmas and noise
cell step are computed from the deck exactly as build_case computes them (the same helpers,
the same operations: bit-identical arrays); the schedule, layout, labels, trajectory and
stations are shared.  It skips build_case's trajectory load and schedule build (most of a
study's build time).  Studies whose numbers do not come from the deck (a punched a-priori)
or that carry guidance or a [control] covariance are refused (``None``): build them whole.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fracas.build.team import _err, _noise, _state_sigmas
from fracas.config.team import SIGMA_UNITS, TeamDeck
from fracas.constants import DAY_S
from fracas.measurements import trakm
from fracas.team.study import Study
from fracas.team.transitions import noise_cell_step

__all__ = ["derive_study", "derivable"]


def derivable(study: Study, deck: TeamDeck) -> bool:
    """Whether :func:`derive_study` can give ``deck``'s study from ``study`` (built from a deck
    with the same structure): no punched a-priori, no guidance, no [control], the same
    generalized-covariance switch and the same tracking entries."""
    gen = deck.gencov is not None and deck.gencov.enabled
    return (
        study.punched is None
        and not study.guidance
        and study.P0_control is None
        and not deck.guidance
        and deck.control is None
        and not (deck.a_priori is not None and deck.a_priori.from_punch)
        and gen == study.gencov
        and len(deck.tracking) == len(study.observations)
        and len(deck.parameter) + (len([g for g in deck.gencov.parameter if g.role == "ignore"]) if gen else 0)
        == len(study.labels)
    )


def derive_study(study: Study, deck: TeamDeck) -> Study:
    """``deck``'s study from ``study`` (same structure, other numbers; see the module
    docstring).  The same number checks as build_case (a thrust noise on a trajectory
    without thrust: the same one-line DeckError).  ValueError if not :func:`derivable`."""
    if not derivable(study, deck):
        raise ValueError("derive_study: the deck differs from the study in more than numbers; build it whole")
    src = deck.source_path or "<deck>"
    nx, layout = study.nx, study.layout
    dyn_of = dict(zip(study.labels, (bool(d) for d in study.dynamic)))

    # ---- parameters (build_case's order: solve-for, dynamic consider, measurement consider, ignore)
    groups: dict[str, list[tuple[str, float]]] = {"s": [], "u": [], "v": [], "w": []}
    true_sigma: dict[str, float] = {}
    for p in deck.parameter:
        role = {"solve_for": "s", "ignore": "w"}.get(p.role, "u" if dyn_of[p.label] else "v")
        groups[role].append((p.label, p.sigma))
    gen = deck.gencov if (deck.gencov is not None and deck.gencov.enabled) else None
    if gen is not None:
        for g in gen.parameter:
            if g.role == "ignore":
                groups["w"].append((g.label, g.sigma))
            else:
                true_sigma[g.label] = g.sigma
    ordered = groups["s"] + groups["u"] + groups["v"] + groups["w"]
    if [lab for lab, _ in ordered] != list(study.labels):
        raise ValueError("derive_study: the deck's parameters are not the study's; build it whole")
    p_sig_a = np.array([s for _, s in ordered], dtype=np.float64)
    p_sig_t = np.array([true_sigma.get(lab, s) for lab, s in ordered], dtype=np.float64)
    if layout.nw:
        p_sig_a[-layout.nw :] = 0.0
    xs_a = _state_sigmas(deck.a_priori, nx)
    xs_t = _state_sigmas(gen.a_priori, nx) if (gen is not None and gen.a_priori is not None) else xs_a
    P0a = np.diag(np.concatenate([xs_a, p_sig_a]) ** 2)
    P0t = np.diag(np.concatenate([xs_t, p_sig_t]) ** 2)

    # ---- thrust noise
    sig_a, tau_a = _noise(deck.thrust_noise)
    sig_t, tau_t = _noise(gen.thrust_noise) if (gen is not None and gen.thrust_noise is not None) else (sig_a, tau_a)
    if (np.any(sig_a > 0) or np.any(sig_t > 0)) and not study.problem.model.thrust:
        raise _err(src, "thrust_noise", None, "the trajectory deck has no thrust ([propulsion] and [[thrust_arc]])")

    # ---- measurement sigmas
    obs, tsig = [], []
    for t in deck.tracking:
        _, k = SIGMA_UNITS[t.type]
        obs.append(trakm.Observation(t.type, tuple(t.stations), t.sigma * k))
        tsig.append((gen.measurement_sigma.get(t.type, t.sigma) if gen is not None else t.sigma) * k)

    return dataclasses.replace(
        study,
        P0_assumed=P0a,
        P0_true=P0t,
        noise_sigma_assumed=sig_a,
        noise_tau_assumed=tau_a,
        noise_sigma_true=sig_t,
        noise_tau_true=tau_t,
        observations=obs,
        true_sigma=np.array(tsig, dtype=np.float64),
        noise_step_s=noise_cell_step(
            deck.errcon.noise_step_hours * 3600.0, (deck.stm.grid_hours or 0.0) * 3600.0, np.concatenate([tau_a, tau_t])
        ),
        budget=bool(deck.budget.enabled and deck.errcon.propagation == "phi"),
        budget_at_s=tuple(t * DAY_S for t in deck.budget.at_days),
    )
