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

from fracas.constants import body_names_at
from fracas.integrate.propagate import Trajectory, propagate_with_sensitivities
from fracas.products import TIME_TOL_S, ReferenceTrajectory, chain, time_indices
from fracas.status import RunStatus
from fracas.team.study import Study

__all__ = ["Reference", "integrate_reference", "noise_cell_times", "reference_from_product", "run_reference"]


@dataclass
class Reference:
    """States and transitions at the schedule times (K of them).

    states (K, 7) r km, v km/s, m kg relative to primary[k]; phi (K, 7, 7) Φ(t_k, t_{k-1})
    (identity at k = 0); theta (K, 7, n_dyn) Θ(t_k, t_{k-1}) for ``labels`` (the study's
    dynamic parameters); source: "integrated" or the STM file path; status: OK, or
    OUTSIDE_TRAJECTORY when the trajectory ended before ``failed_at_s`` (a schedule time;
    the matrices from there on are not finite); integrator_status: the propagation's own;
    product: the STM file's contents when the reference came from one (every file time, not
    only the schedule's: the fixed noise cells are taken from its grid without integrating,
    fracas.team.transitions.grid_noise), None for an in-line reference.
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
    product: ReferenceTrajectory | None = None


def run_reference(problem, t_out: np.ndarray, labels: list[str]):
    """Propagate ``problem`` from its x0 with sensitivities over ``t_out``: (traj, sens, status, failed_at_s)."""
    traj, sens = propagate_with_sensitivities(
        problem.model, problem.params, problem.ephem, problem.epoch_et_s, problem.x0, t_out, labels
    )
    finite = np.all(np.isfinite(np.asarray(sens.stm_step)), axis=(1, 2))
    if np.all(finite):
        return traj, sens, RunStatus.OK, float("nan")
    return traj, sens, RunStatus.OUTSIDE_TRAJECTORY, float(t_out[int(np.argmax(~finite))])


def noise_cell_times(study: Study) -> np.ndarray:
    """The extra output times of an in-line reference for the fixed-cell noise model: the
    noise cells (fracas.team.noise_cells) over the schedule and on to the last prediction
    target inside the trajectory, and those targets, so that neither the run nor its
    predictions integrate the reference again (empty for other models or without noise)."""
    from fracas.team.noise_cells import _noise_cells

    if study.propagation != "phi" or study.noise_model != "grid" or not study.has_noise:
        return np.zeros(0)
    times = study.schedule.times_s
    end = study.trajectory_end_s if study.trajectory_end_s > times[-1] else float(times[-1])
    targets = [t for ts in study.schedule.predict_to_s.values() for t in ts if times[-1] < t <= end]
    t1 = max([float(times[-1])] + targets)
    return np.concatenate([_noise_cells(study, float(times[0]), t1), targets])


def integrate_reference(study: Study) -> Reference:
    """PATH: integrate the reference and its sensitivities over the study's schedule times.

    With the fixed-cell noise model the integration also outputs at the noise-cell ends
    (:func:`noise_cell_times`); the schedule's matrices are then chained over those steps
    and the whole integration is kept as ``Reference.product``, which
    :func:`fracas.team.transitions.grid_noise` reads as it reads an STM file.
    """
    times = study.schedule.times_s
    labels = study.dynamic_labels
    extra = noise_cell_times(study)
    if extra.size:
        near = np.abs(extra[:, None] - times[None, :]).min(axis=1) <= TIME_TOL_S
        ex = np.unique(extra[~near])
        if ex.size:  # a target on a cell end is one time (every cell end may be a schedule time)
            ex = ex[np.concatenate([[True], np.diff(ex) > TIME_TOL_S])]
        t_all = np.unique(np.concatenate([[0.0], times, ex]))
        return _integrate_with_cells(study, times, t_all, labels)
    lead = times[0] > 0.0
    t_out = np.concatenate([[0.0], times]) if lead else times
    traj, sens, status, failed_at = run_reference(study.problem, t_out, labels)
    sl = slice(1, None) if lead else slice(None)
    phi, theta = _from_first(np.array(sens.stm_step)[sl], np.array(sens.par_step)[sl])
    prim = body_names_at(study.problem.model.bodies, np.asarray(traj.primary)[sl])
    return _integrated(times, np.array(traj.x)[sl], prim, phi, theta, labels, status, failed_at, traj)


def _from_first(phi: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Φ, Θ with their first step (from the first time to itself) set to I, 0 (in place)."""
    phi[0] = np.eye(7)
    theta[0] = 0.0
    return phi, theta


def _integrated(
    times: np.ndarray,
    states: np.ndarray,
    primary: list[str],
    phi: np.ndarray,
    theta: np.ndarray,
    labels: list[str],
    status: RunStatus,
    failed_at: float,
    traj: Trajectory,
    product: ReferenceTrajectory | None = None,
) -> Reference:
    """An in-line :class:`Reference` (source "integrated") of the propagation ``traj``."""
    return Reference(
        times,
        states,
        primary,
        phi,
        theta,
        labels,
        "integrated",
        status=status,
        failed_at_s=failed_at,
        integrator_status=int(traj.status),
        product=product,
    )


def _integrate_with_cells(study: Study, times: np.ndarray, t_all: np.ndarray, labels: list[str]) -> Reference:
    """The in-line reference over ``t_all`` (the schedule, the noise cells, 0), held as an
    in-memory ReferenceTrajectory and read back at the schedule times."""
    pr = study.problem
    traj, sens = propagate_with_sensitivities(pr.model, pr.params, pr.ephem, pr.epoch_et_s, pr.x0, t_all, labels)
    # t_all[0] = 0: from the epoch to itself
    stm_step, par_step = _from_first(np.array(sens.stm_step, np.float64), np.array(sens.par_step, np.float64))
    data = ReferenceTrajectory(
        times_s=t_all,
        epoch_et_s=float(pr.epoch_et_s),
        event_types=["grid"] * len(t_all),
        states=np.array(traj.x, np.float64),
        primary=body_names_at(pr.model.bodies, np.asarray(traj.primary)),
        stm_step=stm_step,
        par_step=par_step,
        param_labels=list(labels),
        param_units=[""] * len(labels),
        param_values=np.zeros(len(labels)),
        param_steps=np.full(len(labels), np.nan),
        deck_text="",
        deck_hash="",
        title="in-line reference",
    )
    idx = time_indices(data, times)
    phi, theta = _from_first(*chain(data, times))
    # a failure counts at the first schedule time whose transition is not finite (an
    # integration that ends after the schedule, on the way to a prediction target, does
    # not fail the reference: the prediction reports it)
    finite = np.all(np.isfinite(phi), axis=(1, 2)) & np.all(np.isfinite(data.states[idx]), axis=1)
    status, failed_at = RunStatus.OK, float("nan")
    if not np.all(finite):
        status, failed_at = RunStatus.OUTSIDE_TRAJECTORY, float(times[int(np.argmax(~finite))])
    return _integrated(
        times, data.states[idx], [data.primary[int(i)] for i in idx], phi, theta, labels, status, failed_at, traj, data
    )


def reference_from_product(study: Study, data: ReferenceTrajectory, source: str) -> Reference:
    """STMRDR: the study's columns and times from a reference-trajectory product, chained.

    ``data`` must hold the study's dynamic labels (in that order) and every schedule time
    (:func:`fracas.io.stm_file.read_stm_file` with ``labels`` and ``times_s`` checks both).
    """
    times = study.schedule.times_s
    phi, theta = _from_first(*chain(data, times))
    idx = time_indices(data, times)
    prim = [data.primary[int(i)] for i in idx]
    return Reference(
        times,
        np.asarray(data.states)[idx],
        prim,
        phi,
        theta,
        list(study.dynamic_labels),
        source,
        data.deck_text,
        product=data,
    )
