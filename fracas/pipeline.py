"""The stages in order: deck -> core objects -> propagation -> trajectory file.

Each command-line subcommand enters here; ``on_stage(text)`` (optional) is told which
stage is running so the command line can show progress.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from fracas.build import Problem, build_propagation
from fracas.config.trajectory import load_deck
from fracas.io.hdf5 import provenance
from fracas.io.trajectory_file import SensitivityData, TrajectoryData, write_trajectory_file

Stage = Callable[[str], None]


def default_output(deck_path: str | Path) -> Path:
    """``out/<deck stem>.h5`` (relative to the working directory)."""
    return Path("out") / f"{Path(deck_path).stem}.h5"


def run_propagation(problem: Problem):
    """Propagate ``problem`` (with STM and parameter matrices when it asks): (Trajectory, Sensitivities | None)."""
    from fracas.integrate.propagate import propagate, propagate_with_sensitivities

    args = (problem.model, problem.params, problem.ephem, problem.epoch_et_s, problem.x0, problem.t_out)
    if problem.sensitivities:
        traj, sens = propagate_with_sensitivities(*args, problem.param_labels)
    else:
        traj, sens = propagate(*args), None
    return traj, sens


def trajectory_data(problem: Problem, traj, sens) -> TrajectoryData:
    """Core outputs (JAX arrays) -> :class:`TrajectoryData` (numpy, names, provenance)."""
    from fracas.dynamics.ephemeris import et_to_calendar
    from fracas.params import param_unit

    bodies = problem.model.bodies
    t = np.asarray(traj.t, dtype=np.float64)
    x = np.asarray(traj.x, dtype=np.float64)
    pidx = np.asarray(traj.primary).astype(int)
    name = lambda i, ok=True: bodies[i] if ok and 0 <= i < len(bodies) else ""  # noqa: E731
    sdata = None
    if sens is not None:
        sdata = SensitivityData(
            stm=np.asarray(sens.stm, np.float64),
            stm_step=np.asarray(sens.stm_step, np.float64),
            par=np.asarray(sens.par, np.float64),
            par_step=np.asarray(sens.par_step, np.float64),
            param_labels=problem.param_labels,
            param_units=tuple(param_unit(lab, problem.model) for lab in problem.param_labels),
        )
    xf = np.asarray(traj.x_final, dtype=np.float64)
    return TrajectoryData(
        epoch_et_s=float(problem.epoch_et_s),
        t_s=t,
        r_km=x[:, 0:3],
        v_km_s=x[:, 3:6],
        mass_kg=x[:, 6],
        primary=tuple(name(int(i), bool(np.isfinite(tk))) for i, tk in zip(pidx, t)),
        bodies=bodies,
        t_final_s=float(traj.t_final),
        r_final_km=xf[0:3],
        v_final_km_s=xf[3:6],
        mass_final_kg=float(xf[6]),
        primary_final=name(int(traj.primary_final)),
        status=int(traj.status),
        n_steps=int(traj.n_steps),
        n_rect=int(traj.n_rect),
        centre=problem.centre,
        title=problem.title,
        epoch_tdb=et_to_calendar(problem.epoch_et_s),
        sensitivities=sdata,
        provenance=provenance(problem.source_text, problem.source_path),
    )


def propagate_deck(
    deck_path: str | Path, output: str | Path | None = None, on_stage: Stage | None = None
) -> tuple[TrajectoryData, Path]:
    """Read, validate and build the deck, propagate, write the trajectory file."""
    say = on_stage or (lambda _text: None)
    say("reading the deck")
    deck = load_deck(deck_path)
    say("building the force model and ephemeris")
    problem = build_propagation(deck)
    say("compiling and propagating" + (" with sensitivities" if problem.sensitivities else ""))
    traj, sens = run_propagation(problem)
    data = trajectory_data(problem, traj, sens)
    say("writing the trajectory file")
    path = write_trajectory_file(output or default_output(deck_path), data)
    return data, path


# ----------------------------------------------------------------------------- TEAM
def team_output(deck_path: str | Path) -> Path:
    return Path("out") / f"{Path(deck_path).stem}.h5"


def load_team(deck_path: str | Path):
    """Read and validate a TEAM deck and build its study (with a punched a-priori if named)."""
    from fracas.config.team import load_team_deck
    from fracas.io.team_results import read_punch
    from fracas.team.setup import build_study

    deck = load_team_deck(deck_path)
    punched = None
    if deck.a_priori is not None and deck.a_priori.from_punch:
        punched = read_punch(deck.resolve(deck.a_priori.from_punch), str(deck_path))
    return build_study(deck, punched)


def build_stm(deck_path: str | Path, output: str | Path | None = None, on_stage: Stage | None = None, study=None):
    """``fracas stm build``: integrate the study's reference once and write the STM file (STMGEN).

    ``study``: the deck's already-built study (``run_team`` with ``errcon.build_stm``)."""
    from fracas.io.stm_file import write_stm_file
    from fracas.team.reference import build_stm_data

    say = on_stage or (lambda _text: None)
    if study is None:
        say("reading the deck")
        study = load_team(deck_path)
    if output is None:
        if not study.deck.errcon.stm_file:
            output = Path("stm_files") / f"{Path(deck_path).stem}.h5"
        else:
            output = study.deck.resolve(study.deck.errcon.stm_file)
    say("integrating the reference and its sensitivities")
    data = build_stm_data(study)
    say("writing the STM file")
    write_stm_file(output, data)
    return Path(output), data


def run_team(
    deck_path: str | Path,
    stm: str | Path | None = None,
    output: str | Path | None = None,
    on_stage: Stage | None = None,
):
    """``fracas run`` on a TEAM deck: study -> reference (STM file or in line) -> filter -> results.

    Returns (TeamResult, results path, reference source).
    """
    import time

    from fracas.io.team_results import write_punch, write_team_results
    from fracas.team.engine import run_study
    from fracas.team.reference import integrate_reference, reference_from_stm

    say = on_stage or (lambda _text: None)
    t0 = time.perf_counter()
    say("reading the deck")
    study = load_team(deck_path)
    ec = study.deck.errcon
    stm_path = Path(stm) if stm is not None else (study.deck.resolve(ec.stm_file) if ec.stm_file else None)
    t1 = time.perf_counter()
    if ec.build_stm and stm is None:
        stm_path, _ = build_stm(deck_path, stm_path, on_stage, study=study)
    if stm_path is not None:
        if not stm_path.exists():
            from fracas.errors import StmFileError

            raise StmFileError(f"{stm_path}: no such STM file (build it with: fracas stm build {deck_path} -o {stm_path})")
        say("reading the STM file")
        ref = reference_from_stm(study, stm_path)
    else:
        say("integrating the reference and its sensitivities")
        ref = integrate_reference(study)
    t2 = time.perf_counter()
    if not ec.analysis:
        return None, None, ref.source
    res = run_study(study, ref, say)
    t3 = time.perf_counter()
    res.timing.update({"setup_s": t1 - t0, "reference_s": t2 - t1, "analysis_s": t3 - t2})
    out = Path(output) if output is not None else (
        study.deck.resolve(study.deck.output.results) if study.deck.output.results else team_output(deck_path))
    say("writing the results file")
    write_team_results(out, res, ref.source)
    if study.deck.punch is not None:
        idx = [k for k, e in enumerate(study.schedule.events) if "punch" in e]
        write_punch(study.deck.resolve(study.deck.punch.file), res, idx)
    res.timing["total_s"] = time.perf_counter() - t0
    return res, out, ref.source
