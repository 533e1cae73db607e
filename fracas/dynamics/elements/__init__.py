"""Conic elements, Kepler's equation, spherical coordinates and frame rotations.

Pure ``jax.numpy``: every function is jit-able, vmap-able and differentiable in forward
and reverse mode without NaN gradients on its domain (branches use the double-``where``
idiom: the branch not taken is evaluated on harmless dummy inputs).  Canonical units
km, s, rad; ``mu`` in km^3/s^2.  The inertial frame is ICRF/EME2000.

FRACAS subroutines covered (Doc. 5, sec. 5.1.1): CONIC, CONVRT, EULMX, PECEQ, and the
fixed-conic branch of EPHEM.  The report's equations survive only as an OCR-garbled scan;
the equations used here are rebuilt from standard astrodynamics (Bate, Mueller & White;
Vallado; Danby) and each docstring says what was rebuilt and how it relates to the scan.

Element vector layout (everywhere): ``[a, e, i, raan, argp, M]`` --
``a`` semi-major axis (km, ``a < 0`` for a hyperbola), ``e`` eccentricity, ``i``
inclination (rad, [0, pi]), ``raan`` longitude of the ascending node (rad, [0, 2 pi)),
``argp`` argument of periapsis (rad, [0, 2 pi)), ``M`` mean anomaly (rad; elliptic
``M = E - e sin E`` in [0, 2 pi), hyperbolic ``M = e sinh H - H``, any real, negative
before periapsis).  Parabolas (``e == 1`` exactly) and rectilinear orbits (``h == 0``)
are outside the domain.

Modules (every public name re-exported here): :mod:`.conic` (Kepler's equation, CONIC,
EPHEM's fixed conics), :mod:`.frames` (CONVRT, EULMX, PECEQ) and :mod:`._vectors` (safe norms,
angle wrapping).
"""

from __future__ import annotations

from fracas.dynamics.elements._vectors import TWO_PI
from fracas.dynamics.elements.conic import (
    CIRCULAR_E_TOL,
    EQUATORIAL_SIN_I_TOL,
    cartesian_to_elements,
    conic_body_state,
    elements_to_cartesian,
    mean_to_true_anomaly,
    perifocal_basis,
    solve_kepler,
    true_to_mean_anomaly,
)
from fracas.dynamics.elements.frames import (
    cartesian_to_spherical,
    ecliptic_to_equatorial_matrix,
    elementary_rotation,
    euler_matrix,
    planet_equatorial_matrix,
    spherical_to_cartesian,
)

__all__ = [
    "cartesian_to_elements",
    "elements_to_cartesian",
    "solve_kepler",
    "true_to_mean_anomaly",
    "mean_to_true_anomaly",
    "conic_body_state",
    "perifocal_basis",
    "spherical_to_cartesian",
    "cartesian_to_spherical",
    "elementary_rotation",
    "euler_matrix",
    "ecliptic_to_equatorial_matrix",
    "planet_equatorial_matrix",
]

_CONSTANTS = (TWO_PI, EQUATORIAL_SIN_I_TOL, CIRCULAR_E_TOL)  # module constants, read through this package
