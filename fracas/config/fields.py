"""Deck fields that recur: one table of their names, units, defaults, bounds and meanings.

The same few TEAM-deck fields appear in several decks and modules: the Gauss-Markov thrust
noise (``[thrust_noise]`` and ``[gencov.thrust_noise]``: FRACAS $ERANAL/$GENCOV, App. 9.3)
and the a-priori state sigmas (``[a_priori]``, ``[control]``, ``[gencov.a_priori]``).  This
module is the one place they are described; :mod:`fracas.config.team` takes their bounds from
it, :mod:`fracas.build.team` their conversion to km, s, rad, :mod:`fracas.config.sweep` the
paths a sweep may vary numerically, and :func:`markdown_table` writes their table in
``docs/process_noise.md`` (a test keeps that table up to date).  No JAX, no numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from fracas.constants import DAY_S, G0_KM_S2, SPEED_OF_LIGHT_KM_S

__all__ = [
    "DeckField",
    "THRUST_NOISE_COMPONENTS",
    "THRUST_NOISE_TAU",
    "THRUST_NOISE_SECTIONS",
    "A_PRIORI_FIELDS",
    "A_PRIORI_SECTIONS",
    "LIGHT_KM_S",
    "MAX_POSITION_SIGMA_KM",
    "MAX_DISTANCE_KM",
    "MAX_SPEED_KM_S",
    "MAX_IMPULSE_KM_S",
    "MAX_ANGLE_DEG",
    "MAX_MASS_KG",
    "MAX_POWER_KW",
    "MAX_AREA_M2",
    "MAX_DAYS",
    "MAX_ISP_S",
    "MAX_THRUST_SCALE",
    "MAX_MU_KM3_S2",
    "MIN_TOLERANCE",
    "thrust_noise_paths",
    "a_priori_paths",
    "markdown_table",
    "DOCS_BEGIN",
    "DOCS_END",
]

#: the speed of light (km/s): no velocity uncertainty can exceed it
LIGHT_KM_S = SPEED_OF_LIGHT_KM_S
#: the largest a-priori position sigma (km): 1e12 km (~6,700 AU) is no knowledge at all
MAX_POSITION_SIGMA_KM = 1e12

# The physical bounds of the decks' magnitudes (issue 32): a value beyond them is a typo
# (an exponent, a unit) that would otherwise validate and then run for minutes to nowhere
# (z = 8.3e18 km, an impulse of 1e6 km/s, alpha_deg = 1e300).  Each is far beyond any
# mission, so that no real deck meets it.
#: the largest distance from a centre (km): 1e12 km (~6,700 AU, 40 times Voyager 1's)
MAX_DISTANCE_KM = 1e12
#: the largest speed (km/s): the speed of light
MAX_SPEED_KM_S = SPEED_OF_LIGHT_KM_S
#: the largest impulsive ΔV (km/s, magnitude): no impulsive engine gives more (the largest
#: chemical stages give ~10 km/s)
MAX_IMPULSE_KM_S = 100.0
#: the largest free angle (deg, magnitude): two turns (an angle written either way round);
#: also each Legendre coefficient of a pointing law, so that the law's angle over an arc
#: stays within a few turns of its mean
MAX_ANGLE_DEG = 720.0
#: the largest mass (kg): a million tonnes (~300 Saturn Vs)
MAX_MASS_KG = 1e9
#: the largest power (kW): 1 GW (nuclear-electric concepts are 1-10 MW)
MAX_POWER_KW = 1e6
#: the largest area (m^2): 100 km^2 (the largest solar sails studied are ~1 km^2)
MAX_AREA_M2 = 1e8
#: the largest time from the epoch and trajectory duration (days): ~2,700 years
MAX_DAYS = 1e6
#: the largest Isp (s): an exhaust at the speed of light
MAX_ISP_S = SPEED_OF_LIGHT_KM_S / G0_KM_S2
#: the largest thrust scale factor (a multiplier of the modelled thrust)
MAX_THRUST_SCALE = 1000.0
#: the largest GM of a body override (km^3/s^2): 10 x the Sun's
MAX_MU_KM3_S2 = 1.5e12
#: the smallest integrator tolerance: a step's error estimate is a difference of two
#: solutions each rounded at float64's epsilon (2.2e-16) per operation, so its own noise is
#: a few epsilon; 1e-15 (~5 epsilon) is the tightest a step can be held to
MIN_TOLERANCE = 1e-15


@dataclass(frozen=True)
class DeckField:
    """One deck field: its key, the unit a deck writes it in ("" dimensionless), the default
    when left out (None: none), its bounds (``ge``/``gt`` below, ``le``/``lt`` above, None: no
    bound), how the upper bound's message names its unit (``bound_unit``), the factor from
    the deck's unit to fracas's canonical one (km, s, rad) and what it means."""

    name: str
    unit: str
    description: str
    default: float | None = None
    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    bound_unit: str = ""
    factor: float = 1.0

    def bounds_text(self) -> str:
        """The bounds as a documentation cell: ``>= 0, <= 180`` ("" if unbounded)."""
        parts = [
            f"{op} {v:.12g}"
            for op, v in ((">=", self.ge), (">", self.gt), ("<=", self.le), ("<", self.lt))
            if v is not None
        ]
        return ", ".join(parts)


# --------------------------------------------------------------------------- thrust noise

#: the Gauss-Markov thrust errors, in the filter's order (fracas.team.study.NOISE_COMPONENTS):
#: each is a table ``{sigma, tau_days}``; ``sigma`` is bounded as listed (a proportionality
#: of at most 1, i.e. 100 %, a pointing angle of at most 180 deg).  A component left out has
#: no noise (sigma 0, correlation time 1 day).
THRUST_NOISE_COMPONENTS: tuple[DeckField, ...] = (
    DeckField(
        "proportionality",
        "",
        "thrust-magnitude error, a fraction of the thrust (1σ)",
        default=0.0,
        ge=0.0,
        le=1.0,
        bound_unit="(100 %)",
        factor=1.0,
    ),
    DeckField(
        "in_plane_deg",
        "deg",
        "in-plane pointing error (1σ)",
        default=0.0,
        ge=0.0,
        le=180.0,
        bound_unit="deg",
        factor=math.pi / 180.0,
    ),
    DeckField(
        "out_of_plane_deg",
        "deg",
        "out-of-plane pointing error (1σ)",
        default=0.0,
        ge=0.0,
        le=180.0,
        bound_unit="deg",
        factor=math.pi / 180.0,
    ),
)
#: each thrust-noise component's correlation time (first-order Gauss-Markov)
THRUST_NOISE_TAU = DeckField("tau_days", "d", "correlation time of the component", default=1.0, gt=0.0, factor=DAY_S)
#: the deck tables that hold thrust noise: the filter's model and the true one
THRUST_NOISE_SECTIONS = ("thrust_noise", "gencov.thrust_noise")


def thrust_noise_paths(prefix: str) -> tuple[str, ...]:
    """The field paths of a thrust-noise table at ``prefix``: ``{prefix}.{component}.sigma``,
    ``{prefix}.{component}.tau_days`` for each component, in order."""
    return tuple(f"{prefix}.{c.name}.{f}" for c in THRUST_NOISE_COMPONENTS for f in ("sigma", THRUST_NOISE_TAU.name))


# --------------------------------------------------------------------------- a priori

#: the numbers of an a-priori table (1σ, ICRF axes): per-axis sigmas or an RSS split equally
A_PRIORI_FIELDS: tuple[DeckField, ...] = (
    DeckField("position_sigma_km", "km", "position sigmas (3)", ge=0.0, lt=MAX_POSITION_SIGMA_KM),
    DeckField("position_rss_km", "km", "position RSS (split equally over the axes)", gt=0.0, le=MAX_POSITION_SIGMA_KM),
    DeckField(
        "velocity_sigma_km_s",
        "km/s",
        "velocity sigmas (3), below the speed of light",
        ge=0.0,
        lt=LIGHT_KM_S,
        bound_unit=" (the speed of light)",
    ),
    DeckField("velocity_rss_km_s", "km/s", "velocity RSS (split equally over the axes)", gt=0.0, lt=LIGHT_KM_S),
    DeckField("mass_sigma_kg", "kg", "mass sigma", default=0.0, ge=0.0),
)
#: the deck tables that hold an a priori whose numbers a sweep may vary (``[control]`` too
#: holds one, but is structural for a sweep)
A_PRIORI_SECTIONS = ("a_priori", "gencov.a_priori")


def a_priori_paths(prefix: str) -> tuple[str, ...]:
    """The numeric field paths of an a-priori table at ``prefix``, in order."""
    return tuple(f"{prefix}.{f.name}" for f in A_PRIORI_FIELDS)


# --------------------------------------------------------------------------- documentation

DOCS_BEGIN = "<!-- deck-fields: generated by fracas.config.fields.markdown_table; do not edit -->"
DOCS_END = "<!-- /deck-fields -->"


def _default_text(f: DeckField) -> str:
    return "—" if f.default is None else f"{f.default:g}"


def _row(name: str, f: DeckField) -> str:
    return f"| `{name}` | {f.unit or '1'} | {_default_text(f)} | {f.bounds_text() or '—'} | {f.description} |"


def markdown_table() -> str:
    """The Markdown tables of the recurring deck fields, between :data:`DOCS_BEGIN` and
    :data:`DOCS_END` (docs/process_noise.md holds them)."""
    head = ["| field | unit | default | bounds | meaning |", "|---|---|---|---|---|"]
    noise = []
    for c in THRUST_NOISE_COMPONENTS:
        noise += [_row(f"{c.name}.sigma", c), _row(f"{c.name}.{THRUST_NOISE_TAU.name}", THRUST_NOISE_TAU)]
    apriori = [_row(f.name, f) for f in A_PRIORI_FIELDS]
    return "\n".join(
        [
            DOCS_BEGIN,
            "Thrust noise (" + ", ".join(f"`[{s}]`" for s in THRUST_NOISE_SECTIONS) + "): each component is a "
            "table `{sigma, tau_days}`; the default is that of a component left out (no noise).",
            "",
            *head,
            *noise,
            "",
            "A priori (" + ", ".join(f"`[{s}]`" for s in (*A_PRIORI_SECTIONS, "control")) + "): give "
            "`position_sigma_km` or `position_rss_km`, and `velocity_sigma_km_s` or `velocity_rss_km_s`.",
            "",
            *head,
            *apriori,
            DOCS_END,
        ]
    )
