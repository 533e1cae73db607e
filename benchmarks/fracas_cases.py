"""The fracas side of the heyoka_cases problems (bench_highorder.py, bench_heyoka_ratio.py).

``fracas_problem(case, method, formulation, tol, c_nom=None)``: ForceModel and Params of a
``heyoka_cases.Case`` with the same constants; thrust as a nuclear source of constant power
with T = 2 eta P / ve, eta = 1, pointed along the velocity.  fracas is imported when the
function is called, so a caller may first choose which fracas to import (bench_heyoka_ratio's
``--ref``).
"""

from __future__ import annotations

import numpy as np


def fracas_problem(case, method, formulation, tol, c_nom=None):
    """(ForceModel, Params): tolerance step control with no dt_max, or FRACAS's c_nom rule
    when ``c_nom`` is given (then ``method``, ``formulation``, ``tol`` are not used)."""
    import heyoka_cases as hc

    from fracas.dynamics.model import ForceModel, IntegratorSettings, default_params

    if c_nom is not None:
        ig = IntegratorSettings(c_nom=c_nom)
    else:
        ig = IntegratorSettings(
            method=method, formulation=formulation, step_control="tolerance", tolerance=tol, dt_max_s=np.inf
        )
    common = {"mu": [hc.MU_E], "j2": [hc.J2_E], "radius": [hc.R_E], "pole": [[0.0, 0.0, 1.0]]}
    if case.thrust_kg_km_s2 > 0:
        m = ForceModel(
            bodies=("earth",), j2=True, thrust=True, velocity_dependent=True, power="nuclear", n_arcs=1, integrator=ig
        )
        p = default_params(
            m,
            **common,
            power_kw=case.thrust_kg_km_s2 * case.ve_km_s / 2e-3,
            power_decay_s=1e30,
            efficiency=1.0,
            exhaust_velocity_km_s=case.ve_km_s,
            arc_t_on=[0.0],
            arc_t_off=[2.0 * case.t_final_s],
        )
    else:
        m = ForceModel(bodies=("earth",), j2=True, integrator=ig)
        p = default_params(m, **common)
    return m, p
