"""The trajectory deck's cross checks: what no single table can check (FRACAS TOM ``$DATA``).

Times inside the propagation span, arcs and impulses in order, the centre not a third body,
the force model's bodies (:func:`deck_bodies`), what a backward deck cannot ask for, and what
a propagation would refuse (a start inside the centre, a span outside the DE421 ephemeris),
so that ``fracas validate`` refuses it too.  Each check raises the first
:class:`~fracas.config.trajectory.problems.FieldProblem` it finds, in the order listed in
:func:`cross_checks` and :func:`run_checks`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from fracas.config.limits import count_text
from fracas.config.trajectory.problems import FieldProblem, _Given
from fracas.config.trajectory.sections import _span_text, output_count
from fracas.config.trajectory.state import initial_radius_km
from fracas.constants import BODIES, DAY_S, DE421_END_JD, DE421_START_JD, J2000_JD
from fracas.timescales import et_to_calendar

if TYPE_CHECKING:
    from fracas.config.trajectory.deck import TrajectoryDeck


def span_problem(deck: TrajectoryDeck, loc: tuple, t: float) -> FieldProblem | None:
    """The problem with a time ``t`` (days) outside the propagation span, if any."""
    dur = deck.duration_days
    if dur > 0.0:
        if t < 0.0:
            return FieldProblem(loc, t, "must be >= 0 (the epoch)")
        if t > dur * (1 + 1e-12):
            return FieldProblem(loc, t, f"must be <= the final time, {dur:g} days")
    else:
        if t > 0.0:
            return FieldProblem(loc, t, f"must be <= 0 (the epoch; a backward propagation spans {dur:g} to 0 days)")
        if t < dur * (1 + 1e-12):
            return FieldProblem(loc, t, f"must be >= the final time, {dur:g} days (a backward propagation)")
    return None


def backward_checks(deck: TrajectoryDeck) -> None:
    """What a backward deck cannot ask for (the core's event functions assume forward time)."""
    stop = deck.stop
    if stop.condition in ("soi_entry", "closest_approach"):
        raise FieldProblem(
            ("stop", "condition"),
            stop.condition,
            'not supported on a backward propagation (duration < 0); use "time" or "radius"',
        )
    if deck.forces.change_primary_at_soi:
        raise FieldProblem(
            ("forces", "change_primary_at_soi"), True, "not supported on a backward propagation (duration < 0)"
        )
    for k, imp in enumerate(deck.impulse):
        if imp.time_days == 0.0:
            raise FieldProblem(
                ("impulse", k, "time_days"),
                imp.time_days,
                "must be < 0 on a backward propagation (at the epoch it is ambiguous whether the "
                "initial state is before or after the impulse)",
            )


def cross_checks(deck: TrajectoryDeck) -> None:
    """The deck's cross checks, in order (the first problem found is raised)."""
    dur = _check_duration_and_step(deck)
    if dur < 0.0:
        backward_checks(deck)
    _check_centre_and_thrust(deck)
    _check_thrust_arcs(deck)
    _check_impulses(deck)
    _check_srp_and_conic_bodies(deck)
    _check_output(deck, dur)


def _check_duration_and_step(deck: TrajectoryDeck) -> float:
    """A finite, nonzero duration and an output step in its direction; the duration (days)."""
    dur = deck.duration_days
    if not math.isfinite(dur) or dur == 0.0:
        field = ("stop", "final_epoch") if deck.stop.final_epoch is not None else ("stop", "duration_days")
        value = deck.stop.final_epoch if deck.stop.final_epoch is not None else deck.stop.duration_days
        raise FieldProblem(field, value, "must differ from the epoch (a finite, nonzero duration)")
    step = deck.output.step_days
    if step is not None and (step == 0.0 or (step < 0.0 and dur > 0.0)):
        expected = "must be nonzero" if step == 0.0 else "must be > 0 on a forward propagation"
        raise FieldProblem(("output", "step_days"), step, expected + " (it runs in the direction of propagation)")
    return dur


def _check_centre_and_thrust(deck: TrajectoryDeck) -> None:
    """The centre is not a third body; thrust arcs need [propulsion] and a method that allows them."""
    centre = deck.initial_state.centre
    f = deck.forces
    if centre in f.third_bodies:
        k = f.third_bodies.index(centre)
        raise FieldProblem(
            ("forces", "third_bodies", k),
            centre,
            f'is the primary (initial_state.centre = "{centre}"); it cannot also be a third body',
        )
    if deck.thrust_arc and deck.propulsion is None:
        raise FieldProblem(("propulsion",), None, "a [propulsion] section is required when thrust arcs are given")
    if deck.thrust_arc and deck.integrator.method in ("dprkn12", "dprkn8"):
        raise FieldProblem(
            ("integrator", "method"),
            deck.integrator.method,
            "a special RKN method needs an acceleration independent of velocity and mass; with thrust arcs "
            'use "dop853" (or "auto"), or "rkn4"',
        )


def _check_thrust_arcs(deck: TrajectoryDeck) -> None:
    """Thrust arcs ordered, not overlapping, inside the span."""
    prev = None
    for k, arc in enumerate(deck.thrust_arc):
        if prev is not None and arc.start_days < prev.stop_days:
            raise FieldProblem(
                ("thrust_arc", k, "start_days"),
                arc.start_days,
                f"must be >= thrust_arc[{k - 1}].stop_days = {prev.stop_days:g} (arcs ordered, not overlapping)",
            )
        for name in ("start_days", "stop_days"):
            problem = span_problem(deck, ("thrust_arc", k, name), getattr(arc, name))
            if problem is not None:
                raise problem
        prev = arc


def _check_impulses(deck: TrajectoryDeck) -> None:
    """Impulses inside the span, in time order, all of one engine (one Isp)."""
    for k, imp in enumerate(deck.impulse):
        problem = span_problem(deck, ("impulse", k, "time_days"), imp.time_days)
        if problem is not None:
            raise problem
        if k > 0 and imp.time_days < deck.impulse[k - 1].time_days:
            raise FieldProblem(
                ("impulse", k, "time_days"),
                imp.time_days,
                f"must be >= impulse[{k - 1}].time_days (impulses in time order)",
            )
        if imp.isp_s != deck.impulse[0].isp_s:
            raise FieldProblem(
                ("impulse", k, "isp_s"),
                imp.isp_s,
                f"must equal impulse[0].isp_s = {deck.impulse[0].isp_s:g} (one impulsive engine)",
            )


def _check_srp_and_conic_bodies(deck: TrajectoryDeck) -> None:
    """SRP needs an area; conic bodies are the centre, a third body or the stop body, never the Sun."""
    centre = deck.initial_state.centre
    f = deck.forces
    if f.srp and deck.spacecraft.area_m2 <= 0.0:
        raise FieldProblem(("spacecraft", "area_m2"), deck.spacecraft.area_m2, "must be > 0 when forces.srp = true")
    for name in f.conic_bodies:
        if name == "sun":
            raise FieldProblem(
                ("forces", "conic_bodies", name), name, "the Sun cannot have heliocentric conic elements"
            )
        if name != centre and name not in f.third_bodies and name != deck.stop.body:
            raise FieldProblem(
                ("forces", "conic_bodies", name), name, "must be the centre, a third body or the stop body"
            )


def _check_output(deck: TrajectoryDeck, dur: float) -> None:
    """Output times inside the span, an soi_entry body other than the centre, and the number of
    output times within ``[limits] max_output_times``."""
    centre = deck.initial_state.centre
    for k, t in enumerate(deck.output.times_days):
        problem = span_problem(deck, ("output", "times_days", k), t)
        if problem is not None:
            raise problem
    if deck.stop.condition == "soi_entry" and deck.stop.body == centre:
        raise FieldProblem(("stop", "body"), deck.stop.body, "must differ from the centre for soi_entry")
    n = output_count(deck.output, dur)
    if n > deck.limits.max_output_times:
        field = ("output", "step_days") if deck.output.step_days is not None else ("output", "times_days")
        value = (
            deck.output.step_days
            if deck.output.step_days is not None
            else _Given(f"[{len(deck.output.times_days)} times]")
        )
        raise FieldProblem(
            field,
            value,
            f"gives {count_text(n)} output times over {_span_text(dur)} d "
            f"(limit {deck.limits.max_output_times}, [limits] max_output_times); use a longer step",
        )


def run_checks(deck: TrajectoryDeck) -> None:
    """What a propagation would refuse, checked here so that ``fracas validate`` refuses it
    too: a start inside the central body, a span outside the ephemeris, an override of a
    body the force model does not have."""
    bodies = deck_bodies(deck)
    for name in deck.forces.overrides:
        if name not in bodies:
            raise FieldProblem(
                ("forces", "overrides", name),
                _Given(name),
                f"is not in the force model ({', '.join(bodies)}); add it to forces.third_bodies or remove it",
            )
    problem = inside_centre(deck)
    if problem is not None:
        raise problem
    if needs_ephemeris(deck):
        problem = outside_ephemeris(deck, bodies)
        if problem is not None:
            raise problem


def inside_centre(deck: TrajectoryDeck) -> FieldProblem | None:
    """A start below the centre's radius (constants.BODIES, or forces.overrides)."""
    st = deck.initial_state
    centre = st.centre
    ov = deck.forces.overrides.get(centre)
    radius = ov.radius_km if ov is not None and ov.radius_km is not None else BODIES[centre].radius_km
    r = initial_radius_km(st)
    if r is None or not r < radius:
        return None
    table = st.kind
    loc: tuple = ("initial_state", table)
    value: Any = None
    if table == "cartesian":
        loc, value = (*loc, "r_km"), st.cartesian.r_km
    elif table == "spherical":
        loc, value = (*loc, "r_km"), st.spherical.r_km
    elif table == "oem":
        loc, value = (*loc, "path"), st.oem.path
    return FieldProblem(
        loc,
        value,
        f"starts {r:.6g} km from the centre of {centre}, inside its radius {radius:.10g} km "
        "(fracas.constants; forces.overrides to change it): the initial state must be outside the centre",
    )


def outside_ephemeris(deck: TrajectoryDeck, bodies: tuple[str, ...]) -> FieldProblem | None:
    """The epoch or the final time outside the DE421 span (constants.DE421_START_JD/END_JD)."""
    lo, hi = ((jd - J2000_JD) * DAY_S for jd in (DE421_START_JD, DE421_END_JD))
    span = f"{et_to_calendar(lo)[:10]} to {et_to_calendar(hi)[:10]} TDB"
    why = f"the DE421 ephemeris spans {span}, and the force model needs positions of {', '.join(bodies)}"
    t0 = deck.epoch.et
    if not lo <= t0 <= hi:
        field = "iso" if deck.epoch.iso is not None else "julian_date"
        value = deck.epoch.iso if deck.epoch.iso is not None else deck.epoch.julian_date
        return FieldProblem(("epoch", field), value, f"is outside the ephemeris: {why}")
    t1 = t0 + deck.duration_days * DAY_S
    if not lo <= t1 <= hi:
        if deck.stop.final_epoch is not None:
            loc, value = ("stop", "final_epoch"), deck.stop.final_epoch
        else:
            loc, value = ("stop", "duration_days"), deck.stop.duration_days
        when = et_to_calendar(t1)[:19] if math.isfinite(t1) else "never"
        return FieldProblem(loc, value, f"ends the trajectory at {when} TDB, outside the ephemeris: {why}")
    return None


def deck_bodies(deck: TrajectoryDeck) -> tuple[str, ...]:
    """Bodies whose GM/position the propagation needs, in catalogue order.

    The centre; third bodies; conic bodies; the stop body; the Sun when solar power drives
    thrust arcs or SRP is on; with change_primary_at_soi, the parents of all of these (the
    primary a spacecraft leaving a sphere of influence falls back to).
    """
    need = {deck.initial_state.centre, *deck.forces.third_bodies, *deck.forces.conic_bodies}
    if deck.stop.body:
        need.add(deck.stop.body)
    solar = deck.propulsion is not None and deck.propulsion.power_source == "solar"
    if deck.forces.srp or (solar and deck.thrust_arc):
        need.add("sun")
    if deck.forces.change_primary_at_soi:
        for name in list(need):
            parent = BODIES[name].parent
            while parent is not None:
                need.add(parent)
                parent = BODIES[parent].parent
    return tuple(b for b in BODIES if b in need)


def needs_ephemeris(deck: TrajectoryDeck) -> bool:
    """Whether the propagation reads DE421 (a body other than the Sun and the conic bodies
    needs a position: fracas.build.trajectory builds the table then)."""
    bodies = deck_bodies(deck)
    return len(bodies) > 1 and any(b != "sun" and b not in deck.forces.conic_bodies for b in bodies)
