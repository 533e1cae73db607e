"""The catalogue of guidance targets (FRACAS TARMAT §5.4.9): names, units, meanings (jax-free).

A target is one scalar function T(X_f, t_f) of the spacecraft state X_f relative to the
target body at the target time t_f; :mod:`fracas.guidance.targets` evaluates them and their
Jacobian A_T = ∂T/∂X_f (digest ``tom-tsim-guidance.md`` (G-2)).  Conics are the osculating
two-body conics about the target body (gravitational parameter μ); the B-plane reference
pole is the frame's z axis unless the caller gives another (as
:func:`fracas.dynamics.bplane.b_plane`).

This module imports neither JAX nor numpy, so the configuration layer can check a deck's
target names without starting JAX.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

__all__ = ["TargetKind", "TARGET_KINDS", "target_unit", "check_targets", "LOW_THRUST_CONTROLS", "CONTROL_UNITS"]


@dataclass(frozen=True)
class TargetKind:
    """One target: its name (as a deck spells it), unit and a one-line description."""

    name: str
    unit: str
    description: str


def _kinds(*rows: tuple[str, str, str]) -> dict[str, TargetKind]:
    return {n: TargetKind(n, u, d) for n, u, d in rows}


_ARRIVAL = "t_f plus the time from the state to periapsis on the osculating conic (the arrival time)"

#: Every target fracas knows, by name.
TARGET_KINDS: dict[str, TargetKind] = _kinds(
    ("b_dot_t", "km", "B·T of the osculating hyperbola about the target body (reference pole z)"),
    ("b_dot_r", "km", "B·R of the osculating hyperbola about the target body (reference pole z)"),
    ("time_of_flight", "s", "linearized time of flight: " + _ARRIVAL),
    ("closest_approach_radius", "km", "periapsis radius a(1 - e) of the osculating conic"),
    ("closest_approach_time", "s", "time of closest approach (same quantity as time_of_flight): " + _ARRIVAL),
    ("x", "km", "position x relative to the target body at t_f"),
    ("y", "km", "position y relative to the target body at t_f"),
    ("z", "km", "position z relative to the target body at t_f"),
    ("vx", "km/s", "velocity x relative to the target body at t_f"),
    ("vy", "km/s", "velocity y relative to the target body at t_f"),
    ("vz", "km/s", "velocity z relative to the target body at t_f"),
    ("a", "km", "osculating semi-major axis about the target body at t_f (a < 0: hyperbola)"),
    ("e", "1", "osculating eccentricity about the target body at t_f"),
    ("i", "rad", "osculating inclination about the target body at t_f"),
    ("raan", "rad", "osculating longitude of the ascending node about the target body at t_f"),
    ("argp", "rad", "osculating argument of periapsis about the target body at t_f"),
    ("M", "rad", "osculating mean anomaly about the target body at t_f"),
    ("radius", "km", "distance |r| from the target body at t_f"),
    ("speed", "km/s", "speed |v| relative to the target body at t_f"),
    ("radial_velocity", "km/s", "r·v/|r| relative to the target body at t_f (0: an apsis or circular)"),
    ("e_cos_argp", "1", "e cos(argp) of the osculating conic (smooth through e = 0)"),
    ("e_sin_argp", "1", "e sin(argp) of the osculating conic (smooth through e = 0)"),
    ("vinf", "km/s", "hyperbolic excess speed sqrt(v² - 2μ/r) about the target body"),
    ("vinf_x", "km/s", "x of the incoming-asymptote excess velocity v_inf S"),
    ("vinf_y", "km/s", "y of the incoming-asymptote excess velocity v_inf S"),
    ("vinf_z", "km/s", "z of the incoming-asymptote excess velocity v_inf S"),
    ("final_time", "s", "t_f itself: the time the propagation stopped (arrival at the stop condition)"),
)


def check_targets(names: Iterable[str]) -> None:
    """Raise ``KeyError`` naming the first unknown target and listing the known ones."""
    for name in names:
        if name not in TARGET_KINDS:
            raise KeyError(f"unknown target {name!r}; known targets: {', '.join(TARGET_KINDS)}")


def target_unit(name: str) -> str:
    """Unit of the target ``name`` (``KeyError`` listing the known names if unknown)."""
    check_targets((name,))
    return TARGET_KINDS[name].unit


#: Low-thrust guidance controls (GUIDM, report L1700): proportionality, the two pointing
#: angles, the guidance arc's start and stop times (fracas.guidance.low_thrust maps them to
#: the arc parameters arc_thrust_scale[j], arc_alpha[j], arc_beta[j], arc_t_on[j], arc_t_off[j]).
LOW_THRUST_CONTROLS = ("proportionality", "alpha", "beta", "t_on", "t_off")
CONTROL_UNITS = ("1", "rad", "rad", "s", "s")
