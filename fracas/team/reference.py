"""The reference trajectory of a study and its transition matrices (FRACAS PATH, STMRDR).

Either integrated in line (one :func:`propagate_with_sensitivities` over the schedule
times) or taken from a :class:`~fracas.products.ReferenceTrajectory` product (an STM file's
contents: only the study's parameter columns, matrices chained over the times the study
skips).  Both give a :class:`Reference`.  Nothing here raises on a failed integration: the
Reference carries a :class:`~fracas.status.RunStatus` and the time it failed at.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fracas.integrate.propagate import propagate_with_sensitivities
from fracas.products import ReferenceTrajectory, chain, time_indices
from fracas.status import RunStatus
from fracas.team.study import Study

__all__ = ["Reference", "integrate_reference", "reference_from_product", "run_reference"]


@dataclass
class Reference:
    """States and transitions at the schedule times (K of them).

    states (K, 7) r km, v km/s, m kg relative to primary[k]; phi (K, 7, 7) Φ(t_k, t_{k-1})
    (identity at k = 0); theta (K, 7, n_dyn) Θ(t_k, t_{k-1}) for ``labels`` (the study's
    dynamic parameters); source: "integrated" or the STM file path; status: OK, or
    OUTSIDE_TRAJECTORY when the trajectory ended before ``failed_at_s`` (a schedule time;
    the matrices from there on are not finite); integrator_status: the propagation's own.
    """

    times_s: np.ndarray
    states: np.ndarray
    primary: list[str]
    phi: np.ndarray
    theta: np.ndarray
    labels: list[str]
    source: str
    deck_text: str | None = None
    status: RunStatus = RunStatus.OK
    failed_at_s: float = float("nan")
    integrator_status: int = 0


def run_reference(problem, t_out: np.ndarray, labels: list[str]):
    """Propagate ``problem`` from its x0 with sensitivities over ``t_out``: (traj, sens, status, failed_at_s)."""
    traj, sens = propagate_with_sensitivities(
        problem.model, problem.params, problem.ephem, problem.epoch_et_s, problem.x0, t_out, labels
    )
    finite = np.all(np.isfinite(np.asarray(sens.stm_step)), axis=(1, 2))
    if np.all(finite):
        return traj, sens, RunStatus.OK, float("nan")
    return traj, sens, RunStatus.OUTSIDE_TRAJECTORY, float(t_out[int(np.argmax(~finite))])


def integrate_reference(study: Study) -> Reference:
    """PATH: integrate the reference and its sensitivities over the study's schedule times."""
    times = study.schedule.times_s
    lead = times[0] > 0.0
    t_out = np.concatenate([[0.0], times]) if lead else times
    labels = study.dynamic_labels
    traj, sens, status, failed_at = run_reference(study.problem, t_out, labels)
    sl = slice(1, None) if lead else slice(None)
    phi = np.array(sens.stm_step)[sl]
    theta = np.array(sens.par_step)[sl]
    phi[0] = np.eye(7)
    theta[0] = 0.0
    bodies = study.problem.model.bodies
    prim = [bodies[int(i)] if 0 <= int(i) < len(bodies) else "" for i in np.asarray(traj.primary)[sl]]
    return Reference(
        times,
        np.array(traj.x)[sl],
        prim,
        phi,
        theta,
        labels,
        "integrated",
        status=status,
        failed_at_s=failed_at,
        integrator_status=int(traj.status),
    )


def reference_from_product(study: Study, data: ReferenceTrajectory, source: str) -> Reference:
    """STMRDR: the study's columns and times from a reference-trajectory product, chained.

    ``data`` must hold the study's dynamic labels (in that order) and every schedule time
    (:func:`fracas.io.stm_file.read_stm_file` with ``labels`` and ``times_s`` checks both).
    """
    times = study.schedule.times_s
    phi, theta = chain(data, times)
    phi[0] = np.eye(7)
    theta[0] = 0.0
    idx = time_indices(data, times)
    prim = [data.primary[int(i)] for i in idx]
    return Reference(
        times, np.asarray(data.states)[idx], prim, phi, theta, list(study.dynamic_labels), source, data.deck_text
    )
