"""A study that differs from another only in numbers, without building it again (sweeps).

:func:`derive_study` takes a :class:`~fracas.team.study.Study` built by
:func:`fracas.build.team.build_case` and a validated TEAM deck that differs from that study's
deck only in numeric fields (:data:`fracas.config.sweep.NUMERIC_FIELDS`: a-priori and
parameter sigmas, thrust-noise sigmas and correlation times, tracking and generalized
measurement sigmas) and returns the deck's study as ``dataclasses.replace`` of the given one:
its P0 (assumed and true), noise levels, observation and true measurement sigmas and noise
cell step are computed from the deck by build_case's own :func:`fracas.build.team_numbers.study_numbers`
(bit-identical arrays); the schedule, layout, labels, trajectory and
stations are shared.  It skips build_case's trajectory load and schedule build (most of a
study's build time).  Studies whose numbers do not come from the deck (a punched a-priori)
or that carry guidance or a [control] covariance are refused (``None``): build them whole.
"""

from __future__ import annotations

import dataclasses

from fracas.build.team_numbers import study_numbers
from fracas.config.team import TeamDeck
from fracas.constants import DAY_S
from fracas.team.study import Study

__all__ = ["derive_study", "derivable"]


def derivable(study: Study, deck: TeamDeck) -> bool:
    """Whether :func:`derive_study` can give ``deck``'s study from ``study`` (built from a deck
    with the same structure): no punched a-priori, no guidance, no [control], the same
    generalized-covariance switch and the same tracking entries."""
    gen = deck.gencov is not None and deck.gencov.enabled
    return (
        study.punched is None
        and deck.a_priori is not None
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
    role_of = dict(zip(study.labels, study.roles))
    gen = deck.gencov if (deck.gencov is not None and deck.gencov.enabled) else None
    roles = [(p.label, p.role) for p in deck.parameter]
    roles += [(g.label, "ignore") for g in (gen.parameter if gen is not None else []) if g.role == "ignore"]
    same = len(roles) == len(study.labels) and all(
        lab in role_of and role_of[lab].endswith(role) for lab, role in roles
    )  # "consider" is the study's dynamic_ or measurement_consider
    if not same:
        raise ValueError("derive_study: the deck's parameters are not the study's; build it whole")
    num = study_numbers(deck, src, study.nx, list(study.labels), study.layout.nw, bool(study.problem.model.thrust))
    return dataclasses.replace(
        study,
        **num,
        budget=bool(deck.budget.enabled and deck.errcon.propagation == "phi"),
        budget_at_s=tuple(t * DAY_S for t in deck.budget.at_days),
    )
