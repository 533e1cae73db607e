"""Runge-Kutta(-Nystrom) tableaux kept as data, each with its source.

Two kinds of tableau:

* :class:`NystromTableau` -- special Runge-Kutta-Nystrom methods for r'' = a(t, r) (the
  acceleration must not depend on velocity).  Stage i (c_i, row i of ``a_bar``) evaluates

      k_i = a(t + c_i h,  r + c_i h v + h^2 sum_j a_bar[i, j] k_j)

  and the step is  r1 = r + h v + h^2 sum_i bbar_i k_i,  v1 = v + h sum_i b_i k_i.  ``bbar`` and
  ``b`` are the weights of the propagated (higher-order) solution -- Dormand's b-hat and
  b-hat' -- and ``bbar_low``/``b_low`` those of the embedded solution (Dormand's b and b'),
  whose difference is the local error estimate (local extrapolation).
* :class:`RungeKuttaTableau` -- an explicit first-order method y' = f(t, y) on y = (r, v); it
  serves accelerations that depend on velocity (thrust in a velocity frame).

The coefficients of the DPRKN pairs are kept as the exact rationals of their source (strings
in :mod:`.dprkn`) and rounded once to float64; :func:`exact` returns the rationals (for the order-condition
tests).  The arrays of a tableau are read-only numpy float64 arrays; a tableau is hashable by
identity, so it can be a static argument of ``jax.jit``.

One module per family, their names re-exported here: :mod:`.forms` (the two tableau classes,
their builders, :func:`exact`), :mod:`.rkn4` (RKN4, FRACAS INTEG's classical step), :mod:`.dprkn`
(DPRKN8, DPRKN12), :mod:`.dop853` (DOP853).
"""

from __future__ import annotations

from fracas.integrate.tableaux.dop853 import DOP853
from fracas.integrate.tableaux.dprkn import DPRKN8, DPRKN12
from fracas.integrate.tableaux.forms import NystromTableau, RungeKuttaTableau, exact
from fracas.integrate.tableaux.rkn4 import RKN4

__all__ = [
    "NystromTableau",
    "RungeKuttaTableau",
    "RKN4",
    "DPRKN8",
    "DPRKN12",
    "DOP853",
    "NYSTROM_TABLEAUX",
    "TABLEAUX",
    "exact",
]

NYSTROM_TABLEAUX = {t.name: t for t in (RKN4, DPRKN8, DPRKN12)}
TABLEAUX = {**NYSTROM_TABLEAUX, DOP853.name: DOP853}
