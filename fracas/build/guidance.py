"""From a TEAM deck's [[guidance]] and [control] to the core's guidance specs (GUIDM, XGUID §3.2).

Converts days to s, mrad and mm/s to rad and km/s, ties a low-thrust event to its thrust arc
(the cutoff is the arc's end; ``t_on`` is a control only when the event starts the arc),
checks the times against the trajectory and gives the initial control covariance.  Every
problem is a one-line :class:`~fracas.errors.DeckError` naming the deck and the field.
"""

from __future__ import annotations

import numpy as np

from fracas.config.team import APriori, TeamDeck
from fracas.config.trajectory import TrajectoryDeck
from fracas.constants import DAY_S
from fracas.errors import DeckError
from fracas.guidance.target_kinds import CONTROL_UNITS, LOW_THRUST_CONTROLS
from fracas.team.study import GuidanceSpec

__all__ = ["guidance_specs", "control_a_priori", "guidance_times", "ARC_CONTROL_LABELS"]

#: the Params label of each low-thrust control on arc j (fracas.params)
ARC_CONTROL_LABELS = {
    "proportionality": "arc_thrust_scale[{j}]",
    "alpha": "arc_alpha[{j}]",
    "beta": "arc_beta[{j}]",
    "t_on": "arc_t_on[{j}]",
    "t_off": "arc_t_off[{j}]",
}


def _err(src: str, field: str, value, expected: str) -> DeckError:
    return DeckError(f"{src}: {field} = {value!r}: {expected}")


def guidance_specs(deck: TeamDeck, tdeck: TrajectoryDeck, src: str) -> tuple[GuidanceSpec, ...]:
    """The deck's guidance events in canonical units, checked against the trajectory."""
    dur_d = tdeck.duration_days
    arcs = list(tdeck.thrust_arc)
    out = []
    for k, g in enumerate(deck.guidance):
        f = f"guidance[{k}]"
        t_f = g.target_time_days if g.target_time_days is not None else dur_d
        if t_f > dur_d * (1 + 1e-12):
            raise _err(src, f"{f}.target_time_days", t_f, f"must be within the trajectory (<= {dur_d:g} d)")
        cutoff = g.time_days
        labels: tuple[str, ...] = ()
        units: tuple[str, ...] = ()
        if g.type in ("primary", "vernier"):
            if not arcs:
                raise _err(src, f"{f}.type", g.type, "low-thrust guidance needs [[thrust_arc]]s in the trajectory deck")
            if g.arc >= len(arcs):
                raise _err(src, f"{f}.arc", g.arc, f"expected 0..{len(arcs) - 1} (the trajectory has {len(arcs)} arcs)")
            arc = arcs[g.arc]
            if not (arc.start_days - 1e-9 <= g.time_days < arc.stop_days):
                raise _err(
                    src,
                    f"{f}.time_days",
                    g.time_days,
                    f"must lie on thrust_arc[{g.arc}] ({arc.start_days:g} to {arc.stop_days:g} d)",
                )
            if "t_on" in g.controls and abs(g.time_days - arc.start_days) > 1e-9:
                raise _err(
                    src,
                    f"{f}.controls",
                    g.controls,
                    f"t_on is a control only when the guidance starts the arc (time_days = {arc.start_days:g})",
                )
            cutoff = arc.stop_days
            labels = tuple(ARC_CONTROL_LABELS[c].format(j=g.arc) for c in g.controls)
            units = tuple(CONTROL_UNITS[LOW_THRUST_CONTROLS.index(c)] for c in g.controls)
        if t_f < cutoff:
            raise _err(src, f"{f}.target_time_days", t_f, f"must not precede the cutoff ({cutoff:g} d)")
        verniers = any(
            h.type == "vernier" and h.arc == g.arc and h.time_days > g.time_days for h in deck.guidance[k + 1 :]
        )
        out.append(
            GuidanceSpec(
                name=g.name,
                type=g.type,
                time_s=g.time_days * DAY_S,
                cutoff_s=cutoff * DAY_S,
                target_time_s=t_f * DAY_S,
                targets=tuple(g.targets),
                target_body=g.target_body or "",
                arc=-1 if g.arc is None else int(g.arc),
                controls=tuple(g.controls) if labels else (),
                control_labels=labels,
                control_units=units,
                weights=None if g.weights is None else tuple(g.weights),
                tolerances=None if g.tolerances is None else tuple(g.tolerances),
                sigma_p=g.execution.proportionality,
                sigma_pointing_rad=g.execution.pointing_mrad * 1e-3,
                sigma_res_km_s=g.execution.resolution_m_s * 1e-3,
                verniers_follow=bool(g.type in ("primary", "vernier") and verniers),
            )
        )
    return tuple(out)


def guidance_times(specs) -> tuple[np.ndarray, np.ndarray]:
    """(event times, extra reference times) of the guidance events, s: the guidance epochs
    and cutoffs go on the schedule; the cutoffs and target times must be on an STM file."""
    ev = [g.time_s for g in specs] + [g.cutoff_s for g in specs if g.cutoff_s != g.time_s]
    extra = [g.cutoff_s for g in specs] + [g.target_time_s for g in specs]
    return np.array(sorted(set(ev)), dtype=np.float64), np.array(sorted(set(extra)), dtype=np.float64)


def control_a_priori(ap: APriori | None, src: str, nx: int, P0_true: np.ndarray, state_sigmas) -> np.ndarray | None:
    """The initial control covariance: the [control] state sigmas with the true a-priori's
    parameter blocks (a parameter's actual dispersion), or None (the true a-priori)."""
    if ap is None:
        return None
    if ap.from_punch is not None:
        raise _err(
            src,
            "control.from_punch",
            ap.from_punch,
            "a punched control covariance is reloaded with a_priori.from_punch (leave [control] out); give sigmas here",
        )
    P = np.array(P0_true, dtype=np.float64)
    P[:nx, :] = 0.0
    P[:, :nx] = 0.0
    P[:nx, :nx] = np.diag(np.asarray(state_sigmas(ap, nx)) ** 2)
    return P
