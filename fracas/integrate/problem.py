"""One propagation in canonical units: the core object the application layer builds from a deck.

:class:`Problem` carries the force model, its parameters, the ephemeris table, the epoch,
the initial state and the output times -- arrays and core objects only, with descriptive
strings for provenance (title, the deck's path and text); nothing in it refers back to a
deck object.  :func:`fracas.build.build_propagation` makes one from a trajectory deck; TOM
will make them from its decision vector, TSIM from its samples.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fracas.dynamics.model import ForceModel, Params

__all__ = ["Problem"]


@dataclass(frozen=True)
class Problem:
    """Everything one propagation needs, in canonical units (km, s, kg, kW, rad; ICRF).

    model, params: the core's static spec and dynamic pytree; ephem: DE421 table over the
    propagation window (None when no body position is needed); epoch_et_s: TDB s past J2000
    of t = 0; x0 (7,): r km, v km/s, mass kg relative to the primary; t_out (n,): output
    times, s from the epoch; param_labels: columns of the parameter sensitivity matrices;
    sensitivities: whether to propagate the STM and parameter matrices.
    """

    model: ForceModel
    params: Params
    ephem: object | None
    epoch_et_s: float
    x0: np.ndarray
    t_out: np.ndarray
    param_labels: tuple[str, ...] = ()
    sensitivities: bool = False
    # descriptive
    title: str = ""
    source_path: str | None = None
    source_text: str | None = None
    centre: str = ""
    frame: str = "ICRF"
    final_time_s: float = 0.0
    info: dict = field(default_factory=dict)
