"""TSIM Monte Carlo throughput: the batched engine against a plain loop, and Dask scaling.

    .venv/bin/python benchmarks/bench_tsim.py               # Earth-Mars, three maneuvers
    .venv/bin/python benchmarks/bench_tsim.py --missions 512 --loop-missions 4

The case is namelists/earth_mars_tsim_noise.toml (the main job's Earth-Mars cruise: an impulsive
clean-up at 5 d, a low-thrust correction at 12 d and its vernier at 18 d, 150 days, the
Gauss-Markov thrust noise held over 0.2-day cells: 750 integrator restarts per mission).

Rows (missions/s; the TEAM run TSIM stands on is timed apart, once):
  * plain loop: one mission at a time, every hold cell a single (jitted, not vmapped)
    ``fracas.integrate.propagate.propagate`` call, the guidance in numpy — the baseline;
  * engine in process: ``fracas.tsim.engine.simulate_block`` over the blocks (one device);
  * Dask LocalCluster, 1 and 2 single-threaded worker processes (``run_tsim``), cold
    (workers start and compile: the cost a user pays) and the same run's mission phase.
The loop's missions are checked against the engine's (same draws): final position within
1e-6 relative.  Goals (issue 12): engine ≥ 50× the loop; 2 workers ≥ 1.7× 1 worker.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))


def _args():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--missions", type=int, default=1024)
    ap.add_argument("--loop-missions", type=int, default=4)
    ap.add_argument("--dask-missions", type=int, default=8192)
    ap.add_argument("--no-dask", action="store_true")
    return ap.parse_args()


ARGS = _args()
os.environ.setdefault("FRACAS_HOST_DEVICES", "1")

import numpy as np  # noqa: E402
from runs import TSIM_TEXT, main_guard, require  # noqa: E402
from tables import emit, table  # noqa: E402

DECK = ROOT / "namelists" / "earth_mars_tsim_noise.toml"


def loop_mission(plan, i, propagate_one):
    """One mission by a plain Python loop of single propagations (the baseline)."""
    import jax.numpy as jnp

    from fracas.constants import G0_KM_S2
    from fracas.dynamics.parameters import get_values, set_values
    from fracas.tsim import sampling as smp

    key = smp.mission_key(plan.seed, plan.first_mission + i)
    dx0 = np.asarray(smp.sample_normal(smp.stream_key(key, smp.STREAM_INITIAL), jnp.asarray(plan.init_factor)))
    eta = np.asarray(
        smp.gauss_markov(
            smp.stream_key(key, smp.STREAM_NOISE), plan.noise_sigma, plan.noise_tau_s, np.diff(plan.grid_s)
        )
    )
    model, nx = plan.model, plan.nx
    dyn_nom = np.asarray(get_values(plan.params, plan.dyn_labels, model))
    ctrl_labels = plan.control_labels
    ctrl_nom = np.asarray(get_values(plan.params, ctrl_labels, model))
    ctrl_act = np.zeros(len(ctrl_labels))
    ctrl_cmd = np.zeros(len(ctrl_labels))
    x = plan.x0.copy()
    x[:nx] += dx0[:nx]

    def params():
        p = set_values(plan.params, plan.dyn_labels, jnp.asarray(dyn_nom + dx0[plan.dyn_index]), model)
        return set_values(p, ctrl_labels, jnp.asarray(ctrl_nom + ctrl_act), model)

    def fly(x, t_a, t_b):
        p = params()
        i0 = int(np.searchsorted(plan.grid_s, t_a - 1e-6))
        i1 = int(np.searchsorted(plan.grid_s, t_b - 1e-6))
        for c in range(i0, i1):
            pc = p._replace(
                thrust_scale=p.thrust_scale + eta[c, 0],
                bias_in_rad=p.bias_in_rad + eta[c, 1],
                bias_out_rad=p.bias_out_rad + eta[c, 2],
            )
            tr = propagate_one(
                model, pc, plan.ephem, plan.epoch_et_s, x, np.array([plan.grid_s[c], plan.grid_s[c + 1]])
            )
            require(tr, f"loop mission {i}, hold cell {c}", ok=(0,))  # no state from an abort point
            x = np.array(tr.x_final)
        return x

    t_prev = 0.0
    for j, m in enumerate(plan.maneuvers):
        x = fly(x, t_prev, m.time_s)
        dev = x - plan.x_ref[j]
        know = np.asarray(
            smp.sample_normal(smp.stream_key(key, smp.STREAM_KNOWLEDGE, j), jnp.asarray(m.knowledge_factor))
        )
        est = np.concatenate([dev[:nx], dx0[nx:]]) + know
        ek = smp.stream_key(key, smp.STREAM_EXECUTION, j)
        if m.impulsive:
            dv = -m.gamma @ est
            err = np.asarray(
                smp.gates_error(ek, dv, m.sigma_p, m.sigma_pointing_rad, m.sigma_pointing_rad, m.sigma_res_km_s)
            )
            x[3:6] += dv + err
            x[6] *= np.exp(-np.linalg.norm(dv + err) / (G0_KM_S2 * plan.isp_s))
        else:
            idx = [ctrl_labels.index(c) for c in m.control_labels]
            du = -m.gamma @ est - m.kk @ ctrl_cmd[idx]
            err = np.asarray(smp.proportional_error(ek, du, m.sigma_p))
            ctrl_cmd[idx] += du
            ctrl_act[idx] += du + err
        t_prev = m.time_s
    return fly(x, t_prev, plan.final.t_s)


def main():
    from fracas.build.tsim import build_plan
    from fracas.config.tsim import load_tsim_deck
    from fracas.integrate.propagate import propagate
    from fracas.modes.tsim.run import _team_for, run_tsim
    from fracas.tsim import engine

    cfg = load_tsim_deck(DECK)
    t0 = time.perf_counter()
    _, case, team = _team_for(cfg, emit)
    t_team = time.perf_counter() - t0
    t0 = time.perf_counter()
    plan = build_plan(cfg, case, team)
    t_plan = time.perf_counter() - t0
    plan = dataclasses.replace(plan, missions=ARGS.missions)
    emit(f"Earth-Mars TSIM: {len(plan.maneuvers)} maneuvers, {len(plan.grid_s) - 1} hold cells, block {plan.block}")
    emit(f"TEAM run {t_team:.1f} s, plan (reference through the grid, compile) {t_plan:.1f} s")

    # engine in process: first block (compile), then the rest
    t0 = time.perf_counter()
    first = engine.simulate_block(plan, 0)
    t_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    rest = [engine.simulate_block(plan, b) for b in range(1, plan.n_blocks)]
    t_rest = time.perf_counter() - t0
    # TSIM counts hopeless missions (2) as outcomes; an integration failure (3) makes no rate
    for b, blk in enumerate([first, *rest]):
        require(blk["status"], f"engine block {b}", ok=(0, 1, 2), texts=TSIM_TEXT)
    eng_rate = (plan.n_blocks - 1) * plan.block / t_rest

    # plain loop (warm: one mission first to compile the single propagate)
    loop_mission(plan, 0, propagate)  # compile the single propagation first
    t0 = time.perf_counter()
    xs = [loop_mission(plan, i, propagate) for i in range(ARGS.loop_missions)]
    t_loop = time.perf_counter() - t0
    loop_rate = ARGS.loop_missions / t_loop
    # agreement: the loop's final states against the engine's (target error + reference)
    require(first["status"][: ARGS.loop_missions], "engine missions compared with the loop", texts=TSIM_TEXT)
    te = first["target_error"][: ARGS.loop_missions]
    x_eng = plan.x_ref[-1][None, :3] + te  # x, y, z targets are the heliocentric position
    rel = np.max(np.abs(np.array(xs)[:, :3] - x_eng) / np.linalg.norm(plan.x_ref[-1][:3]))

    rows = [
        ["plain loop (single propagations)", f"{loop_rate:.3g}", "1.0", f"{ARGS.loop_missions} missions"],
        ["engine, in process (warm)", f"{eng_rate:.3g}", f"{eng_rate / loop_rate:.0f}", f"first block {t_first:.1f} s"],
    ]
    dask = {}
    if not ARGS.no_dask:
        import tempfile

        for w in (1, 2):
            stamps = []
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                prod, _ = run_tsim(
                    _with_missions(cfg, ARGS.dask_missions), Path(tmp) / "r.h5", workers=w, force_dask=True,
                    batch_missions=512, progress=lambda d, n: stamps.append((time.perf_counter(), d)),
                )  # fmt: skip
                wall = time.perf_counter() - t0
            require(prod.table["status"], f"Dask run, {w} worker(s)", ok=(0, 1, 2), texts=TSIM_TEXT)
            ms = prod.timing["missions_s"]
            (ta, da), (tb, db) = stamps[1], stamps[-1]  # first task done -> last: warm workers
            warm = (db - da) / (tb - ta)
            dask[w] = warm
            rows.append(
                [
                    f"Dask LocalCluster, {w} worker{'s' if w > 1 else ''} (warm)",
                    f"{warm:.3g}",
                    f"{warm / loop_rate:.0f}",
                    f"{ARGS.dask_missions} missions: {ARGS.dask_missions / ms:.3g}/s with start + compile "
                    f"({ms:.1f} s), whole run {wall:.1f} s",
                ]
            )
    emit()
    table(["", "missions/s", "x loop", "notes"], rows)
    emit(f"loop vs engine final position: max relative difference {rel:.1e}")
    emit(f"goal engine >= 50x loop: {'met' if eng_rate / loop_rate >= 50 else 'NOT met'} ({eng_rate / loop_rate:.0f}x)")
    if dask:
        s = dask[2] / dask[1]
        emit(f"goal 2 workers >= 1.7x 1 worker: {'met' if s >= 1.7 else 'NOT met'} ({s:.2f}x)")


def _with_missions(cfg, n):
    from fracas.config.tsim import parse_tsim_deck

    text = cfg.source_text.replace(f"missions = {cfg.insim.missions}\n", f"missions = {n}\n", 1)
    return parse_tsim_deck(text, cfg.source_path)


if __name__ == "__main__":
    main_guard(main)
