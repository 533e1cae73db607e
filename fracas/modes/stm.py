"""The STM file between modes (FRACAS STMGEN / STMRDR): a TEAM case's reference integrated
once over every STM-file time with every parameter column and written (``fracas stm
build``, ``errcon.build_stm``, TOM's ``[tom] stm_file``), and read back for a study."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from fracas.constants import DAY_S
from fracas.errors import NumericalError
from fracas.io.atomic import check_output_path
from fracas.io.inputs import reading_inputs
from fracas.modes.base import Stage, default_output, say_to
from fracas.status import RunStatus

__all__ = ["load_team", "stm_product", "build_stm", "reference_from_stm", "read_reference", "reference_failed"]


def load_team(deck: Any) -> Any:
    """TEAM deck (path or TeamDeck) -> :class:`fracas.build.team.TeamCase` (with a punched
    a-priori when the deck names one)."""
    from fracas.build.team import build_case
    from fracas.config.team import TeamDeck, load_team_deck
    from fracas.io.team_results import read_punch

    cfg = deck if isinstance(deck, TeamDeck) else load_team_deck(deck)
    punched = None
    if cfg.a_priori is not None and cfg.a_priori.from_punch:
        punched = read_punch(cfg.resolve(cfg.a_priori.from_punch), cfg.source_path or "<deck>")
    return build_case(cfg, punched)


def reference_failed(case: Any, failed_at_s: float, integrator_status: int) -> NumericalError:
    """The one-line error of a reference trajectory that stopped before a study time."""
    return NumericalError(
        f"{case.traj_deck.source_path}: the reference trajectory stopped before t = {failed_at_s / DAY_S:.6g} d "
        f"(status {int(integrator_status)}); the study's times must lie on the trajectory"
    )


def _event_names(sched: Any, times: np.ndarray) -> list[str]:
    """The schedule's event names at each STM-file time ("grid" between events)."""
    ev = []
    for t in times:
        k = int(np.argmin(np.abs(sched.times_s - t)))
        ev.append("+".join(sched.events[k]) if abs(sched.times_s[k] - t) < 1e-6 else "grid")
    if ev and times[0] == 0.0 and "initial" not in ev[0]:
        ev[0] = "initial" if ev[0] == "grid" else "initial+" + ev[0]
    return ev


def stm_product(case: Any) -> Any:
    """STMGEN: integrate the case's reference once over every STM-file time with every
    parameter column -> :class:`fracas.products.ReferenceTrajectory`."""
    import dataclasses

    from fracas.build.reference import reference_product
    from fracas.build.team import stm_file_labels, stm_file_times
    from fracas.config.trajectory import trajectory_hash
    from fracas.team.reference import run_reference

    study = case.study
    times = stm_file_times(case)
    labels = stm_file_labels(case)
    traj, sens, status, failed_at = run_reference(study.problem, times, labels)
    if status != RunStatus.OK:
        raise reference_failed(case, failed_at, traj.status)
    ev = _event_names(study.schedule, times)
    pr = dataclasses.replace(study.problem, t_out=times, param_labels=tuple(labels))
    tdeck = case.traj_deck
    return reference_product(pr, traj, sens, ev, tdeck.source_text or "", trajectory_hash(tdeck), tdeck.source_path)


@reading_inputs
def build_stm(
    deck: Any, output: str | Path | None = None, on_stage: Stage | None = None, case: Any = None
) -> tuple[Path, Any]:
    """``fracas stm build``: the reference product of a TEAM deck, written as an STM file.

    ``case``: the deck's already-built case (``run_team`` with ``errcon.build_stm``)."""
    from fracas.io.stm_file import write_stm_file

    say = say_to(on_stage)
    if case is None:
        say("reading the deck")
        case = load_team(deck)
    if output is None:
        ec = case.deck.errcon
        output = case.deck.resolve(ec.stm_file) if ec.stm_file else default_output(case.deck.source_path, "stm_files")
    output = check_output_path(output, "STM file", (case.deck.source_path,))
    say("integrating the reference and its sensitivities")
    data = stm_product(case)
    say("writing the STM file")
    write_stm_file(output, data)
    return Path(output), data


def reference_from_stm(study: Any, stm_path: str | Path) -> Any:
    """STMRDR: a study's columns and times from an STM file, checked against its trajectory."""
    return read_reference(study, stm_path)[0]


def read_reference(study: Any, stm_path: str | Path) -> tuple[Any, Any]:
    """STMRDR: (the study's Reference, the file's ReferenceTrajectory with the study's
    columns), checked against its trajectory; guidance reads cutoff and target times from it."""
    from fracas.io.stm_file import check_trajectory, read_stm_file
    from fracas.team.reference import reference_from_product

    data = read_stm_file(
        stm_path,
        labels=study.dynamic_labels,
        times_s=study.schedule.times_s,
        epoch_et_s=float(study.problem.epoch_et_s),
    )  # within 1e-6 s, absolute
    check_trajectory(data, study.trajectory_hash, stm_path, study.trajectory_source)
    return reference_from_product(study, data, str(stm_path)), data
