"""The core's description of one propagation problem: a static spec plus a dynamic pytree.

``ForceModel`` is static (hashable; a jit static argument): which bodies exist, which
act, which terms are on, integrator constants and the stopping condition.  ``Params``
is a pytree of float64 arrays holding every number a study may differentiate or
disperse (GMs, J2, spacecraft and propulsion values, thrust-arc controls and their
biases, impulses).  ``build.py`` makes both from a validated deck; the numeric kernels
only ever see these two objects, in km, s, kg, kW and rad.

Thrust arcs (FRACAS EP, DETECT): arc ``k`` thrusts for ``t_on[k] <= t < t_off[k]``
(seconds from the propagation epoch) with in-plane angle ``alpha`` and out-of-plane
angle ``beta`` (rad) in EP's velocity frame (x along v, z along r x v, y = z x x) when
``arc_frame[k] == 0``, or as right ascension / declination of an inertially fixed
direction (ICRF) when ``arc_frame[k] == 1``, or in the velocity frame with beta's sign
following cos u (flipping at the antinodes, Edelbaum's steering) when ``arc_frame[k] == 2``;
``throttle`` scales thrust and mass flow.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from fracas import constants

if TYPE_CHECKING:
    import numpy.typing as npt
    from jax import Array

STOP_TIME = "time"
STOP_SOI_ENTRY = "soi_entry"
STOP_CLOSEST_APPROACH = "closest_approach"
STOP_RADIUS = "radius"
STOP_KINDS = (STOP_TIME, STOP_SOI_ENTRY, STOP_CLOSEST_APPROACH, STOP_RADIUS)

POWER_SOLAR = "solar"
POWER_NUCLEAR = "nuclear"

FRAME_VELOCITY = 0  # EP's (v, (r x v) x v ... ) frame
FRAME_INERTIAL = 1  # right ascension / declination in ICRF
FRAME_VELOCITY_YAW_SWITCH = 2  # velocity frame, out-of-plane sign = sign(cos u) (Edelbaum steering)


@dataclass(frozen=True)
class IntegratorSettings:
    """How the propagation loop steps (Doc. 4 sec. 4.3; FRACAS INTEG; ``fracas.integrate.highorder``).

    formulation: 'encke' (deviations from an osculating conic, FRACAS) or 'cowell' (the state
    itself); method: 'rkn4' (FRACAS's 4th-order Nystrom), 'dprkn8', 'dprkn12' (embedded
    RKN 8(6), 12(10)) or 'dop853' (first order: thrust, velocity-dependent forces);
    step_control: 'tolerance' (embedded error estimate: relative local error per step
    <= ``tolerance``) or 'c_nom' (FRACAS's rule dt_nom = c_nom r_con^(3/2)/sqrt(mu), the
    only choice for rkn4).  ``encke`` + ``rkn4`` + ``c_nom`` is FRACAS's integrator.

    c_nom: step constant (dimensionless, 0.3 in Doc. 4); dt_max_s: largest step (s; inf:
    none); rect_ratio: rectify when |delta| > ratio |r_con| or |nu| > ratio |v_con|;
    eps_t_s: time tolerance (s) for the final time and events; max_steps: hard cap on loop
    iterations, accepted and rejected (a propagation that hits it reports status 2).
    method, formulation and step_control are static (one compiled program each); the
    numbers are traced (changing them does not recompile).
    """

    c_nom: float = 0.3
    dt_max_s: float = 4000.0
    rect_ratio: float = 0.01
    eps_t_s: float = 1e-6
    max_steps: int = 200_000
    tolerance: float = 1e-12
    method: str = "rkn4"
    formulation: str = "encke"
    step_control: str = "c_nom"
    # how a high-order step runs its stages (a property of the compiled program, not of the
    # numbers: both give the same bits up to rounding order): "loop" -- the tableau as data
    # under lax.fori_loop, the force model traced once (small programs, fast compiles: single
    # propagations); "unrolled" -- one traced copy per stage, which XLA CPU fuses into a few
    # wide kernels (vmapped batches: fracas.integrate.batch sets it)
    stage_loop: str = "loop"

    @property
    def adaptive(self) -> bool:
        return self.step_control == "tolerance"

    def static_part(self) -> IntegratorSettings:
        """The settings with every number at its default (the static key of a compiled program)."""
        return IntegratorSettings(
            method=self.method,
            formulation=self.formulation,
            step_control=self.step_control,
            stage_loop=self.stage_loop,
        )


@dataclass(frozen=True)
class StopCondition:
    """How a propagation ends besides the final time (FRACAS stopping conditions).

    kind: 'time' | 'soi_entry' | 'closest_approach' | 'radius'; body: index into
    ``ForceModel.bodies``; radius_km: for 'radius' (distance from ``body``).
    """

    kind: str = STOP_TIME
    body: int = 0
    radius_km: float = 0.0


@dataclass(frozen=True)
class ForceModel:
    """Static structure of the force model (jit static argument; hashable).

    bodies: names of every body with a position in the ephemeris table (index order);
    primary: index of the initial primary (centre of the Encke conic and of the state);
    third_bodies: indices acting as point-mass perturbers (never the current primary); with
    change_primary_at_soi every body of the model acts (the primary left behind keeps pulling);
    j2: J2 of the current primary on/off; srp: solar radiation pressure on/off;
    thrust: any thrust arcs; velocity_dependent: the acceleration depends on v (thrust
    in the velocity frame), so Nystrom needs its fourth evaluation;
    power: 'solar' (P = P0 (1 AU / r_sun)^2) or 'nuclear' (P = P0 exp(-t/tau));
    change_primary_at_soi: switch the primary when entering/leaving a sphere of influence;
    steering: the arcs' pointing follows their Legendre laws (``Params.arc_alpha_p1`` ...), so
    the angles are evaluated at every stage instead of once per step;
    yaw_switch: some arc may use ``velocity_yaw_switch`` pointing (``arc_frame`` 2): the sign
    of cos u is then carried by the loop (``Carry.yaw_sign``, held over each step) and its
    changes are located as events, where the state transition matrix takes its saltation
    jump (:mod:`fracas.integrate.events`).  Without it (a model built by hand with frame 2
    but no flag) the sign is taken from the state at every evaluation, unlocated.
    """

    bodies: tuple[str, ...] = ("earth",)
    primary: int = 0
    third_bodies: tuple[int, ...] = ()
    j2: bool = False
    srp: bool = False
    thrust: bool = False
    velocity_dependent: bool = False
    power: str = POWER_SOLAR
    change_primary_at_soi: bool = False
    conic_bodies: tuple[int, ...] = ()  # bodies whose position comes from body_elements (EPHEM)
    n_arcs: int = 0
    steering: bool = False  # pointing varies within an arc (Params.arc_alpha_p1 ...): angles per evaluation
    n_impulses: int = 0
    yaw_switch: bool = False
    integrator: IntegratorSettings = field(default_factory=IntegratorSettings)
    stop: StopCondition = field(default_factory=StopCondition)

    def body_index(self, name: str) -> int:
        return self.bodies.index(name)

    def acting_third_bodies(self) -> tuple[int, ...]:
        """Bodies that can act as point-mass perturbers (the current primary is masked at run
        time).  With primary changes every body gravitates: the primary left behind at a sphere
        of influence (e.g. the Sun after entering Mars's) must keep acting as a third body."""
        if self.change_primary_at_soi:
            return tuple(range(len(self.bodies)))
        return tuple(self.third_bodies)


class Params(NamedTuple):
    """Every dynamic number of a propagation (a pytree of float64 arrays: numpy arrays as
    :func:`default_params` builds them, jax arrays in traced code, whence the annotations).

    Units: mu km^3/s^2; radius km; pole unit vectors; power kW; exhaust velocity km/s;
    angles rad; times s from the propagation epoch; dv km/s; area m^2; isp s.
    Per-body arrays have length ``len(ForceModel.bodies)``; per-arc arrays ``n_arcs``.
    """

    mu: Array  # (nb,) GM of each body
    j2: Array  # (nb,) unnormalised J2
    radius: Array  # (nb,) equatorial radius (J2 reference radius)
    pole: Array  # (nb, 3) unit pole vectors (ICRF)
    soi_radius: Array  # (nb,) sphere-of-influence radius (inf for the Sun)
    parent: Array  # (nb,) index of the parent body (-1 for none); float for pytree uniformity
    area_m2: Array  # () SRP area
    cr: Array  # () reflectivity coefficient (1 absorber .. 2 mirror)
    power_kw: Array  # () base power: at 1 AU (solar) or at t = 0 (nuclear)
    power_decay_s: Array  # () nuclear e-folding time
    efficiency: Array  # () thruster efficiency eta
    exhaust_velocity_km_s: Array  # () c
    thrust_scale: Array  # () overall thrust proportionality (1 nominal)
    bias_in_rad: Array  # () overall in-plane pointing bias
    bias_out_rad: Array  # () overall out-of-plane pointing bias
    arc_t_on: Array  # (na,)
    arc_t_off: Array  # (na,)
    arc_alpha: Array  # (na,) in-plane angle / right ascension
    arc_beta: Array  # (na,) out-of-plane angle / declination
    arc_throttle: Array  # (na,) thrust level factor
    arc_frame: Array  # (na,) 0 velocity frame, 1 inertial, 2 velocity + yaw switch (float codes)
    arc_thrust_scale: Array  # (na,) per-arc proportionality (1 nominal)
    arc_bias_in_rad: Array  # (na,)
    arc_bias_out_rad: Array  # (na,)
    # pointing that varies within an arc (``ForceModel.steering``): Legendre coefficients of the
    # in-plane and out-of-plane angles in the arc's normalised time s in [-1, 1] (rad); the angle
    # is arc_alpha + p1 P1(s) + p2 P2(s) + p3 P3(s), so arc_alpha stays the arc's mean angle
    arc_alpha_p1: Array  # (na,)
    arc_alpha_p2: Array  # (na,)
    arc_alpha_p3: Array  # (na,)
    arc_beta_p1: Array  # (na,)
    arc_beta_p2: Array  # (na,)
    arc_beta_p3: Array  # (na,)
    impulse_t: Array  # (ni,) time of each impulsive dV
    impulse_dv: Array  # (ni, 3) dV in the frame of impulse_frame
    impulse_frame: Array  # (ni,) 0 velocity frame, 1 inertial
    impulse_isp_s: Array  # () specific impulse of the impulsive engine
    body_elements: Array  # (nb, 6) heliocentric conic elements a km, e, i, raan, argp, M rad (EPHEM bodies)
    body_elements_et: Array  # (nb,) TDB seconds past J2000 at which body_elements hold


def default_params(model: ForceModel, **overrides: npt.ArrayLike) -> Params:
    """Params with catalogue values for ``model.bodies`` and no thrust; keyword overrides."""
    nb, na, ni = len(model.bodies), model.n_arcs, model.n_impulses
    cat = [constants.BODIES[b] for b in model.bodies]
    parent = [float(model.bodies.index(b.parent)) if b.parent in model.bodies else -1.0 for b in cat]
    f = np.float64
    p: dict[str, Any] = {
        "mu": np.array([b.mu_km3_s2 for b in cat], f),
        "j2": np.array([b.j2 for b in cat], f),
        "radius": np.array([b.radius_km for b in cat], f),
        "pole": np.array([constants.pole_unit_vector(b.name) for b in cat], f).reshape(nb, 3),
        "soi_radius": np.array([constants.soi_radius_km(b.name) for b in cat], f),
        "parent": np.array(parent, f),
        "area_m2": f(0.0),
        "cr": f(1.0),
        "power_kw": f(0.0),
        "power_decay_s": f(np.inf),
        "efficiency": f(1.0),
        "exhaust_velocity_km_s": f(30.0),
        "thrust_scale": f(1.0),
        "bias_in_rad": f(0.0),
        "bias_out_rad": f(0.0),
        "arc_t_on": np.zeros(na, f),
        "arc_t_off": np.zeros(na, f),
        "arc_alpha": np.zeros(na, f),
        "arc_beta": np.zeros(na, f),
        "arc_throttle": np.ones(na, f),
        "arc_frame": np.zeros(na, f),
        "arc_thrust_scale": np.ones(na, f),
        "arc_bias_in_rad": np.zeros(na, f),
        "arc_bias_out_rad": np.zeros(na, f),
        "arc_alpha_p1": np.zeros(na, f),
        "arc_alpha_p2": np.zeros(na, f),
        "arc_alpha_p3": np.zeros(na, f),
        "arc_beta_p1": np.zeros(na, f),
        "arc_beta_p2": np.zeros(na, f),
        "arc_beta_p3": np.zeros(na, f),
        "impulse_t": np.zeros(ni, f),
        "impulse_dv": np.zeros((ni, 3), f),
        "impulse_frame": np.zeros(ni, f),
        "impulse_isp_s": f(300.0),
        "body_elements": np.zeros((nb, 6), f),
        "body_elements_et": np.zeros(nb, f),
    }
    for k, v in overrides.items():
        if k not in p:
            raise KeyError(f"unknown parameter {k!r}; known: {sorted(p)}")
        p[k] = np.asarray(v, dtype=f)
    return Params(**p)
