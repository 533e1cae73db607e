"""A reference-trajectory product from a propagation (FRACAS STMGEN's assembly step).

Any mode that has propagated a reference with its sensitivities (TEAM's STM build, TOM's
converged trajectory) turns it into a :class:`~fracas.products.ReferenceTrajectory` here,
which :func:`fracas.io.stm_file.write_stm_file` stores.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fracas.constants import body_names_at
from fracas.dynamics.parameters import get_values
from fracas.errors import StmFileError
from fracas.io.hdf5 import provenance
from fracas.params import param_unit
from fracas.products import TIME_TOL_S, ReferenceTrajectory, _days
from fracas.status import status_text

__all__ = ["stm_data_from_run", "reference_product"]


def stm_data_from_run(
    problem: Any,
    traj: Any,
    sens: Any,
    event_types: Any,
    deck_text: str | None,
    deck_hash: str,
    deck_path: str | None = None,
) -> ReferenceTrajectory:
    """Assemble the :class:`~fracas.products.ReferenceTrajectory` from a propagation with sensitivities (FRACAS STMGEN).

    ``problem``: :class:`fracas.build.Problem` whose ``t_out`` are the schedule times (s,
    ``t_out[0]`` must be 0: the propagation starts at the epoch) and ``param_labels`` the
    columns; ``traj``, ``sens``: from
    :func:`fracas.integrate.propagate.propagate_with_sensitivities` on that problem;
    ``event_types``: one string per time.  Refuses (StmFileError) a trajectory that did not
    reach every scheduled time.
    """
    where = deck_path or problem.source_path or "<deck>"
    t_out = np.asarray(problem.t_out, np.float64)
    t = np.asarray(traj.t, np.float64)
    n = t_out.shape[0]
    if n == 0:
        raise StmFileError(f"{where}: cannot build an STM file: the schedule has no times")
    if abs(float(t_out[0])) > TIME_TOL_S:
        raise StmFileError(
            f"{where}: cannot build an STM file: the schedule starts at t = {t_out[0]:.6f} s "
            f"({_days(t_out[0])}), expected 0 (the propagation starts at the epoch)"
        )
    event_types = [str(e) for e in event_types]
    if len(event_types) != n:
        raise StmFileError(f"{where}: {len(event_types)} event types for {n} schedule times")
    bad = np.nonzero(~np.isfinite(t))[0]
    if bad.size:
        k = int(bad[0])
        status = int(np.asarray(traj.status))
        raise StmFileError(
            f"{where}: cannot build an STM file: the trajectory ended at t = {_days(np.asarray(traj.t_final))} "
            f"({status_text(status)}) before scheduled time {k} at {_days(t_out[k])} "
            f"({event_types[k]}); shorten the schedule or fix the deck"
        )
    model = problem.model
    labels = [str(x) for x in problem.param_labels]
    stm_step = np.asarray(sens.stm_step, np.float64)
    par_step = np.asarray(sens.par_step, np.float64).reshape(n, 7, len(labels))
    if not (np.all(np.isfinite(stm_step)) and np.all(np.isfinite(par_step))):
        raise StmFileError(f"{where}: cannot build an STM file: non-finite transition matrices")
    return ReferenceTrajectory(
        times_s=t_out,  # the schedule itself (the integrator lands within eps_t of each)
        epoch_et_s=float(problem.epoch_et_s),
        event_types=event_types,
        states=np.asarray(traj.x, np.float64),
        primary=body_names_at(model.bodies, np.asarray(traj.primary)),
        stm_step=stm_step,
        par_step=par_step,
        param_labels=labels,
        param_units=[param_unit(lab, model) for lab in labels],
        param_values=np.asarray(get_values(problem.params, labels, model), np.float64).reshape(len(labels)),
        param_steps=np.full(len(labels), np.nan),
        deck_text=str(deck_text or ""),
        deck_hash=str(deck_hash),
        deck_path=deck_path,
        title=problem.title,
        centre=problem.centre,
        frame=problem.frame,
        sensitivity_method="ad",
        provenance=provenance(deck_text, deck_path),
    )


reference_product = stm_data_from_run
