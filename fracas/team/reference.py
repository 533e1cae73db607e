"""The reference trajectory of a study and its transition matrices (FRACAS PATH, STMGEN, STMRDR).

Either integrated in line (one :func:`propagate_with_sensitivities` over the schedule
times) or read from an STM file (only the study's parameter columns, matrices chained
over the file times the study skips).  Both give a :class:`Reference`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fracas.errors import NumericalError, StmFileError
from fracas.io import stm_file
from fracas.team.setup import Study, stm_file_labels, stm_file_times

__all__ = ["Reference", "integrate_reference", "reference_from_stm", "build_stm_data"]


@dataclass
class Reference:
    """States and transitions at the schedule times (K of them).

    states (K, 7) r km, v km/s, m kg relative to primary[k]; phi (K, 7, 7) Φ(t_k, t_{k-1})
    (identity at k = 0); theta (K, 7, n_dyn) Θ(t_k, t_{k-1}) for ``labels`` (the study's
    dynamic parameters); source: "integrated" or the STM file path.
    """

    times_s: np.ndarray
    states: np.ndarray
    primary: list[str]
    phi: np.ndarray
    theta: np.ndarray
    labels: list[str]
    source: str
    deck_text: str | None = None


def _run(study: Study, t_out: np.ndarray, labels: list[str]):
    from fracas.integrate.propagate import propagate_with_sensitivities

    pr = study.problem
    traj, sens = propagate_with_sensitivities(pr.model, pr.params, pr.ephem, pr.epoch_et_s, pr.x0, t_out, labels)
    if not np.all(np.isfinite(np.asarray(sens.stm_step))):
        bad = int(np.argmax(~np.all(np.isfinite(np.asarray(sens.stm_step)), axis=(1, 2))))
        raise NumericalError(
            f"{study.traj_deck.source_path}: the reference trajectory stopped before t = {t_out[bad] / 86400.0:.6g} d "
            f"(status {int(traj.status)}); the study's times must lie on the trajectory")
    return traj, sens


def integrate_reference(study: Study) -> Reference:
    """PATH: integrate the reference and its sensitivities over the study's schedule times."""
    times = study.schedule.times_s
    lead = times[0] > 0.0
    t_out = np.concatenate([[0.0], times]) if lead else times
    labels = study.dynamic_labels
    traj, sens = _run(study, t_out, labels)
    sl = slice(1, None) if lead else slice(None)
    phi = np.array(sens.stm_step)[sl]
    theta = np.array(sens.par_step)[sl]
    phi[0] = np.eye(7)
    theta[0] = 0.0
    bodies = study.problem.model.bodies
    prim = [bodies[int(i)] for i in np.asarray(traj.primary)[sl]]
    return Reference(times, np.array(traj.x)[sl], prim, phi, theta, labels, "integrated")


def build_stm_data(study: Study) -> stm_file.StmData:
    """STMGEN: integrate the reference once over every file time with every parameter column."""
    times = stm_file_times(study)
    labels = stm_file_labels(study)
    traj, sens = _run(study, times, labels)
    ev = []
    sched = study.schedule
    for t in times:
        k = int(np.argmin(np.abs(sched.times_s - t)))
        if abs(sched.times_s[k] - t) < 1e-6:
            ev.append("+".join(e for e in sched.events[k]))
        else:
            ev.append("grid")
    if ev and times[0] == 0.0 and "initial" not in ev[0]:
        ev[0] = "initial" if ev[0] == "grid" else "initial+" + ev[0]
    pr = dataclasses.replace(study.problem, t_out=times, param_labels=tuple(labels))
    tdeck = study.traj_deck
    return stm_file.stm_data_from_run(pr, traj, sens, ev, tdeck.source_text or "", stm_file.trajectory_hash(tdeck),
                                      tdeck.source_path)


def reference_from_stm(study: Study, path: str | Path) -> Reference:
    """STMRDR: read the study's columns and times from an STM file and chain the matrices."""
    labels = study.dynamic_labels
    times = study.schedule.times_s
    data = stm_file.read_stm_file(path, labels=labels, times_s=times)
    stm_file.check_trajectory(data, stm_file.trajectory_hash(study.traj_deck), path, study.traj_deck.source_path)
    phi, theta = stm_file.chain(data, times)
    phi[0] = np.eye(7)
    theta[0] = 0.0
    idx = stm_file.time_indices(data, times)
    prim = [data.primary[int(i)] for i in idx]
    if not np.allclose(data.epoch_et_s, study.problem.epoch_et_s, atol=1e-6):
        raise StmFileError(f"{path}: epoch differs from the study's trajectory deck")
    return Reference(times, np.asarray(data.states)[idx], prim, phi, theta, labels, str(path), data.deck_text)
