"""Issue 13: the two-vehicle (rendezvous) engine on the Apollo 12 example against plain loops.

Rows (each a ratio to a baseline timed in the same run; this machine is shared):

1. covariance analysis, 3 roles x 92 events x 352 scalar marks: the jitted scan
   (fracas.team.two_vehicle.run_rendezvous_study, warm and with its compile) against a plain
   numpy loop of the same stacked Joseph updates;
2. linear single runs, 400 per role: the vmapped jitted kernel against a numpy loop over the
   runs (same recursion);
3. EKF single runs on the conics, 200 per role: the vmapped kernel (warm and with compile),
   against the same kernel called one run at a time (n_runs = 1, a Python loop).

Usage: .venv/bin/python benchmarks/bench_rendezvous.py [--quick]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from runs import main_guard, require  # noqa: E402
from tables import emit, table  # noqa: E402

DECK = "namelists/apollo12_rendezvous.toml"


def _numpy_scan(study, run_inputs):
    """The covariance analysis as a plain numpy loop (baseline): same algebra as the scan."""
    from fracas.team.two_vehicle import _phi_aug, measurement_rows, role_setup

    phi, Qt = _phi_aug(study)
    H, ra, rt, _ = measurement_rows(study)
    out = []
    for role in study.roles:
        c = role_setup(study, role, Qt)
        Pa, Pt = c.P0_assumed.copy(), study.P0_true.copy()
        n = Pa.shape[0]
        for k in range(len(study.times_s)):
            Pa = phi[k] @ Pa @ phi[k].T + c.Q_assumed[k]
            Pt = phi[k] @ Pt @ phi[k].T + Qt[k]
            if c.reset_flag[k]:
                Pa[:6, :] = 0.0
                Pa[:, :6] = 0.0
                Pa[:6, :6] = c.reset_cov[k]
            for j in range(4):
                if not study.marks[k, j]:
                    continue
                h = H[k, j]
                g = c.est * (Pa @ h) / (h @ Pa @ h + ra[k, j])
                IKH = np.eye(n) - np.outer(g, h)
                Pa = IKH @ Pa @ IKH.T + ra[k, j] * np.outer(g, g)
                Pt = IKH @ Pt @ IKH.T + rt[k, j] * np.outer(g, g)
                Pa, Pt = 0.5 * (Pa + Pa.T), 0.5 * (Pt + Pt.T)
        out.append(Pt)
    return out


def _numpy_runs(study, run, n_runs, seed):
    from fracas.team.two_vehicle import _phi_aug

    phi, Qt = _phi_aug(study)
    rng = np.random.default_rng(seed)
    L0 = np.linalg.cholesky(study.P0_true + 1e-30 * np.eye(study.n))
    K = len(study.times_s)
    errs = np.zeros((len(study.roles), n_runs, K, study.n))
    for r in range(len(study.roles)):
        for i in range(n_runs):
            e = L0 @ rng.standard_normal(study.n)
            for k in range(K):
                e = phi[k] @ e if k else e
                noise = np.sqrt(run.r_true[k]) * rng.standard_normal(4)
                for j in range(4):
                    e = e - run.gains[r, k, j] * (run.H[k, j] @ e + noise[j])
                errs[r, i, k] = e
    return errs


def _t(f, repeat=3):
    best = np.inf
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = f()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    from fracas.build.rendezvous import build_rendezvous
    from fracas.config.rendezvous import load_rendezvous_deck
    from fracas.team.two_vehicle import nonlinear_single_runs, run_rendezvous_study, single_runs

    emit(f"# bench_rendezvous  {time.strftime('%Y-%m-%d %H:%M')}  {platform.processor() or platform.machine()}")
    emit(f"# cores {os.cpu_count()}  load {os.getloadavg()[0]:.2f}")
    t0 = time.perf_counter()
    study = build_rendezvous(load_rendezvous_deck(DECK))
    t_build = time.perf_counter() - t0
    emit(f"# build (both references + STMs + maneuvers, compile included): {t_build:.2f} s")
    K, marks = len(study.times_s), int(study.marks.sum())

    t0 = time.perf_counter()
    run = run_rendezvous_study(study)
    t_cold = time.perf_counter() - t0
    t_warm, _ = _t(lambda: run_rendezvous_study(study))
    t_np, ref = _t(lambda: _numpy_scan(study, None), repeat=1 if args.quick else 3)
    # the references and maneuvers are checked by build_rendezvous (it refuses a failed one);
    # the covariance run: status 7 (non-finite covariance) makes no timing or difference
    require(0 if np.all(np.isfinite(run.P_true)) else 7, "rendezvous covariance analysis", ok=(0,))
    dev = max(float(np.max(np.abs(run.P_true[r, -1] - ref[r])) / np.max(np.abs(ref[r]))) for r in range(3))
    rows = [
        ["numpy loop (baseline)", f"{t_np * 1e3:.1f}", "1.00"],
        ["jitted scan, warm", f"{t_warm * 1e3:.1f}", f"{t_np / t_warm:.1f}"],
        ["jitted scan, with compile", f"{t_cold * 1e3:.1f}", f"{t_np / t_cold:.2f}"],
    ]
    emit(f"\n## covariance analysis: 3 roles, {K} events, {marks} scalar marks; max rel. difference {dev:.1e}")
    table(["", "ms", "speed-up"], rows)

    n_lin = 100 if args.quick else 400
    t0 = time.perf_counter()
    single_runs(run, n_lin, 1)
    t_lin_cold = time.perf_counter() - t0
    t_lin, _ = _t(lambda: single_runs(run, n_lin, 1))
    n_np = 20 if args.quick else 50
    t_np_runs, _ = _t(lambda: _numpy_runs(study, run, n_np, 1), repeat=1)
    per_np = t_np_runs / (3 * n_np)
    rows = [
        ["numpy loop over runs (baseline)", f"{1 / per_np:.0f}", "1.00"],
        ["vmapped kernel, warm", f"{3 * n_lin / t_lin:.0f}", f"{per_np * 3 * n_lin / t_lin:.0f}"],
        ["vmapped kernel, with compile", f"{3 * n_lin / t_lin_cold:.0f}", f"{per_np * 3 * n_lin / t_lin_cold:.1f}"],
    ]
    emit(f"\n## linear single runs: {n_lin} per role (baseline: {n_np} per role)")
    table(["", "runs/s", "speed-up"], rows)

    n_nl = 50 if args.quick else 200
    t0 = time.perf_counter()
    nonlinear_single_runs(run, n_nl, 1)
    t_nl_cold = time.perf_counter() - t0
    t_nl, _ = _t(lambda: nonlinear_single_runs(run, n_nl, 1), repeat=1 if args.quick else 2)
    nonlinear_single_runs(run, 1, 1)  # compile the one-run shape
    n_one = 3 if args.quick else 8
    t0 = time.perf_counter()
    for i in range(n_one):
        nonlinear_single_runs(run, 1, 1 + i)
    per_one = (time.perf_counter() - t0) / (3 * n_one)
    rows = [
        ["one run per call, Python loop (baseline)", f"{1 / per_one:.1f}", "1.00"],
        ["vmapped kernel, warm", f"{3 * n_nl / t_nl:.1f}", f"{per_one * 3 * n_nl / t_nl:.1f}"],
        ["vmapped kernel, with compile", f"{3 * n_nl / t_nl_cold:.1f}", f"{per_one * 3 * n_nl / t_nl_cold:.1f}"],
    ]
    emit(f"\n## EKF single runs on the conics: {n_nl} per role ({K} events, Kepler + its Jacobian per vehicle)")
    table(["", "runs/s", "speed-up"], rows)


if __name__ == "__main__":
    main_guard(main)
