"""The propagation's product: core outputs (JAX arrays) -> :class:`TrajectoryData` (numpy,
names, units, provenance), and the one-line description of the integrator."""

from __future__ import annotations

from typing import Any

import numpy as np

from fracas.build.trajectory import Problem
from fracas.constants import body_name_at
from fracas.io.hdf5 import provenance
from fracas.io.trajectory_file import SensitivityData, TrajectoryData

__all__ = ["trajectory_data", "describe_integrator"]


def describe_integrator(st: Any) -> str:
    """One line naming the method, formulation and step control (the results file, the summary)."""
    rule = f"tolerance {st.tolerance:g}" if st.adaptive else f"c_nom {st.c_nom:g}"
    return f"{st.method}, {st.formulation}, {rule}"


def _sensitivity_data(problem: Problem, sens: Any) -> SensitivityData:
    from fracas.params import param_unit

    return SensitivityData(
        stm=np.asarray(sens.stm, np.float64),
        stm_step=np.asarray(sens.stm_step, np.float64),
        par=np.asarray(sens.par, np.float64),
        par_step=np.asarray(sens.par_step, np.float64),
        param_labels=problem.param_labels,
        param_units=tuple(param_unit(lab, problem.model) for lab in problem.param_labels),
    )


def trajectory_data(problem: Problem, traj: Any, sens: Any) -> TrajectoryData:
    """Core outputs (JAX arrays) -> the :class:`TrajectoryData` product (numpy, names, provenance)."""
    from fracas.timescales import et_to_calendar

    bodies = problem.model.bodies
    t = np.asarray(traj.t, dtype=np.float64)
    x = np.asarray(traj.x, dtype=np.float64)
    pidx = np.asarray(traj.primary).astype(int)
    sdata = _sensitivity_data(problem, sens) if sens is not None else None
    xf = np.asarray(traj.x_final, dtype=np.float64)
    return TrajectoryData(
        epoch_et_s=float(problem.epoch_et_s),
        t_s=t,
        r_km=x[:, 0:3],
        v_km_s=x[:, 3:6],
        mass_kg=x[:, 6],
        primary=tuple(body_name_at(bodies, i) if np.isfinite(tk) else "" for i, tk in zip(pidx, t)),
        bodies=bodies,
        t_final_s=float(traj.t_final),
        r_final_km=xf[0:3],
        v_final_km_s=xf[3:6],
        mass_final_kg=float(xf[6]),
        primary_final=body_name_at(bodies, traj.primary_final),
        status=int(traj.status),
        n_steps=int(traj.n_steps),
        n_rect=int(traj.n_rect),
        n_reject=int(traj.n_reject),
        integrator=describe_integrator(problem.model.integrator),
        centre=problem.centre,
        title=problem.title,
        epoch_tdb=et_to_calendar(problem.epoch_et_s),
        sensitivities=sdata,
        provenance=provenance(problem.source_text, problem.source_path),
    )
