"""The integrators the accuracy and derivative tests run for (``pytest.mark.parametrize("kind", KINDS)``).

* ``"fracas"``: FRACAS's own integrator, Encke deviations with the 4th-order Nystrom step and
  the c_nom step rule (``IntegratorSettings()`` defaults: rkn4 / encke / c_nom); the test's
  own settings (c_nom, dt_max_s, rect_ratio, ...) are used unchanged.  This is the faithful
  option and the one the c_nom-specific tests (convergence order, rectification threshold,
  exact Kepler) are about.
* ``"cowell"``: the state itself integrated by a high-order embedded method with tolerance
  step control (relative local error per step <= ``tolerance``).
* ``"encke"``: the same method and step control on Encke deviations from the osculating conic.

The high-order method is ``dprkn12`` (RKN 12(10), y'' = f(t, y)) for ballistic models and
``dop853`` with thrust (the acceleration then depends on the mass, a first-order variable,
and possibly on v, which the special RKN methods cannot take).  Their steps are not capped
(``dt_max_s`` inf) unless a test sets ``high_order_dt_max_s``; ``eps_t_s``,
``max_steps`` and ``rect_ratio`` are kept from the test's settings when it gives them, so
event and time tolerances are the same for every kind.  Every test keeps its reference and
tolerance for every kind.
"""

from __future__ import annotations

import numpy as np

from fracas.dynamics.model import IntegratorSettings

KINDS = ("fracas", "cowell", "encke")
#: For the most expensive tests (finite-difference sweeps, STMs, the 300-day cruise): the
#: Encke high-order kind is left out there to keep the suite's time (each (method,
#: formulation, model) compiles once, and the Encke stages add a vectorised Kepler solve);
#: it is still run for LEO, events, impulses and changes of primary.
KINDS_NO_ENCKE = ("fracas", "cowell")
HIGH_ORDER = ("cowell", "encke")
_KEPT = ("eps_t_s", "max_steps", "rect_ratio")


def integrator(
    kind: str, thrust: bool = False, tolerance: float = 1e-12, high_order_dt_max_s: float = np.inf, **fracas_kwargs
):
    """IntegratorSettings for ``kind`` (see the module docstring).

    ``fracas_kwargs``: the test's settings of FRACAS's integrator (``c_nom``, ``dt_max_s``,
    ``rect_ratio``, ...), used unchanged for ``"fracas"``; for the high-order kinds only
    ``eps_t_s``, ``max_steps`` and ``rect_ratio`` carry over, the step cap is
    ``high_order_dt_max_s`` (default: none) and the local error ``tolerance``.
    """
    if kind == "fracas":
        return IntegratorSettings(**fracas_kwargs)
    if kind not in HIGH_ORDER:
        raise ValueError(f"kind = {kind!r}: expected one of {KINDS}")
    kept = {k: v for k, v in fracas_kwargs.items() if k in _KEPT}
    return IntegratorSettings(
        method="dop853" if thrust else "dprkn12",
        formulation=kind,
        step_control="tolerance",
        tolerance=tolerance,
        dt_max_s=high_order_dt_max_s,
        **kept,
    )
