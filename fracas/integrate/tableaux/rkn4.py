"""RKN4: the classical 4th-order Runge-Kutta method in Nystrom form (FRACAS INTEG's step).

Part of :mod:`fracas.integrate.tableaux` (which re-exports :data:`RKN4`).
"""

from __future__ import annotations

from fracas.integrate.tableaux.forms import _nystrom

# RKN4: the classical 4th-order Runge-Kutta method written as a Nystrom method (Kutta 1901;
# Nystrom 1925), exactly the step of fracas.integrate.encke._nystrom_step (Doc. 4 sec. 4.3,
# FRACAS INTEG): stages at t, t + h/2 (twice), t + h with position couplings h^2/8, h^2/8,
# h^2/2; r1 = r + h v + h^2 (k1 + k2 + k3)/6, v1 = v + h (k1 + 2 k2 + 2 k3 + k4)/6.  Without
# velocity dependence stages 2 and 3 coincide (the kernels evaluate it once: 3 evaluations).
_RKN4 = {
    "c": ("0", "1/2", "1/2", "1"),
    "a_bar": (("1/8",), ("1/8", "0"), ("0", "0", "1/2")),
    "bbar": ("1/6", "1/6", "1/6", "0"),
    "b": ("1/6", "1/3", "1/3", "1/6"),
}

RKN4 = _nystrom(
    "RKN4",
    _RKN4,
    order=4,
    embedded_order=None,
    source="classical RK4 in Nystrom form, as fracas.integrate.encke._nystrom_step (Doc. 4 sec. 4.3)",
)
