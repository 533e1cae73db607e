"""TOM's automatic first guess as decks (FRACAS has none; [tom.first_guess], :mod:`fracas.tom.first_guess`):
the default segment count, pass 1's throttle segments and pass 2's burns with their Legendre
pointing laws, each as a TOM deck and trajectory deck for :func:`fracas.build.tom.build_tom`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from fracas import constants
from fracas.build.tom_reference import _wrap_deg
from fracas.build.trajectory import build_propagation
from fracas.config.tom import TomDeck
from fracas.config.trajectory import TrajectoryDeck
from fracas.tom.first_guess import Burn

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


def first_guess_burns(
    deck: TomDeck, traj: TrajectoryDeck, burns: Sequence[Sequence[Burn]]
) -> tuple[TomDeck, TrajectoryDeck]:
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
