"""Sweep speed (issue 9 item 4): batched numeric sweeps, and schedule sweeps on 1 vs 2 workers.

(a) 100 Mercury-size studies over one STM file (namelists/mercury_approach_team.toml; 5 range
    sigmas x 5 thrust-noise correlation times x 4 QVLBI range sigmas): one group of studies
    that differ only in numbers, batched (fracas.team.batch) on a LocalCluster of two worker
    processes, against team_mode.run_team one study after another in this process (the
    baseline, measured in the same run on the first --baseline studies, each deck as the sweep
    makes it: fracas.modes.sweep.run.study_deck, no error budget).  Goal >= 20 studies/s.
(b) 20 studies that change the tracking schedule (Doppler interval_hours 1 ... 20 h): one task
    per study, 2 workers vs 1 worker.  Goal >= 1.6x faster.

"with start-up": cluster start, worker start-up and every compile counted (a fresh cluster
and its first sweep); "warm": the same sweep again on that cluster (new table, resume off),
compiled code and the worker's group setup cache warm.  The persistent compilation cache
($FRACAS_CACHE_DIR) is used as in normal runs.  Also reported: the agreement of the batched
numbers with run_team one by one (max relative difference over the compared studies).

    .venv/bin/python benchmarks/bench_sweep.py [--baseline 25] [--out benchmarks/results_sweep.txt]
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from runs import RunFailed, main_guard, require, sweep_failure  # noqa: E402

from fracas.config.sweep import parse_sweep_deck  # noqa: E402
from fracas.config.team import load_team_deck  # noqa: E402
from fracas.modes import stm as stm_mode  # noqa: E402
from fracas.modes import team as team_mode  # noqa: E402
from fracas.modes.sweep.run import outputs_of, run_sweep, study_deck  # noqa: E402

DECK = ROOT / "namelists" / "mercury_approach_team.toml"
OUTPUTS = ["position_rss_km", "velocity_rss_km_s", "sigma[thrust_scale]", "true_position_rss_km"]
NUMERIC = [
    ("tracking[3].sigma", [0.5, 1.0, 2.0, 4.0, 8.0]),  # range2, m
    ("thrust_noise.proportionality.tau_days", [0.25, 0.5, 1.0, 2.0, 4.0]),
    ("tracking[5].sigma", [5.0, 10.0, 20.0, 40.0]),  # QVLBI differenced range, m
]
SCHEDULE = [("tracking[0].interval_hours", [float(h) for h in range(1, 21)])]


def sweep_deck(folder: Path, name: str, stm: Path, vary) -> object:
    lines = [
        'mode = "sweep"',
        f'title = "{name}"',
        "[sweep]",
        f'study = "{DECK}"',
        f'stm_file = "{stm}"',
        f"outputs = {OUTPUTS!r}",
    ]
    for f, vals in vary:
        lines += ["[[sweep.vary]]", f'field = "{f}"', f"values = {vals!r}"]
    lines += ["[output]", f'table = "{folder / (name + ".h5")}"']
    p = folder / f"{name}.toml"
    p.write_text("\n".join(lines) + "\n")
    return parse_sweep_deck(p.read_text(), str(p))


def cluster(n: int):
    from distributed import Client, LocalCluster

    from fracas.cluster import worker_plugin

    t0 = time.perf_counter()
    c = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None)
    cl = Client(c)
    cl.register_plugin(worker_plugin())
    cl.wait_for_workers(n)
    return c, cl, time.perf_counter() - t0


def timed_sweep(cfg, n_workers: int, folder: Path, tag: str):
    """(cold wall incl. cluster start, cluster start, warm wall, rows of the warm run)."""
    c, cl, t_start = cluster(n_workers)
    try:
        t0 = time.perf_counter()
        run_sweep(cfg, scheduler=c.scheduler_address, resume=False, table=folder / f"{tag}_cold.h5")
        cold = time.perf_counter() - t0
        t0 = time.perf_counter()
        res = run_sweep(cfg, scheduler=c.scheduler_address, resume=False, table=folder / f"{tag}_warm.h5")
        warm = time.perf_counter() - t0
    finally:
        cl.close()
        c.close()
    failed = sweep_failure(res.rows)
    if failed:
        raise RunFailed(f"sweep {tag}, {n_workers} worker(s): {failed}")
    return t_start + cold, t_start, warm, res.rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--baseline", type=int, default=25, help="studies of (a) run one by one for the baseline")
    ap.add_argument("--out", type=Path, default=None, help="also write the table here")
    args = ap.parse_args()
    out: list[str] = []

    def say(line: str = "") -> None:
        print(line, flush=True)
        out.append(line)

    say(f"# bench_sweep.py  {datetime.datetime.now():%Y-%m-%d %H:%M}  {platform.processor() or platform.machine()}")
    say(f"# cores {os.cpu_count()}, load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        stm = folder / "mercury.h5"
        t0 = time.perf_counter()
        stm_mode.build_stm(load_team_deck(DECK), stm)
        say(f"STM file built once: {time.perf_counter() - t0:.1f} s (not counted below)")

        # (a) baseline: run_team one by one, in process
        cfg_a = sweep_deck(folder, "numeric", stm, NUMERIC)
        base = load_team_deck(DECK)
        studies = cfg_a.studies()
        nb = min(args.baseline, len(studies))
        t0 = time.perf_counter()
        first = None
        one = []
        for k, v in enumerate(studies[:nb]):
            product, _, _ = team_mode.run_team(study_deck(base, cfg_a.fields, v), stm=str(stm), write_results=False)
            require(product, f"baseline study {k}", ok=(0,))
            one.append(outputs_of(product, OUTPUTS)[0])
            if k == 0:
                first = time.perf_counter() - t0
        t_one = time.perf_counter() - t0
        rate_one_cold = nb / t_one
        rate_one_warm = (nb - 1) / (t_one - first)

        t0 = time.perf_counter()
        res0 = run_sweep(cfg_a, workers=0, resume=False, table=folder / "inproc.h5")
        t_in = time.perf_counter() - t0
        failed = sweep_failure(res0.rows)
        if failed:
            raise RunFailed(f"sweep in process: {failed}")
        cold_a, start_a, warm_a, rows_a = timed_sweep(cfg_a, 2, folder, "a")
        n = len(studies)
        worst = 0.0
        for r, want in zip(rows_a, one):
            for name in OUTPUTS:
                worst = max(worst, abs(r[name] - want[name]) / abs(want[name]))
        same = all(r0[o] == r[o] for r0, r in zip(res0.rows, rows_a) for o in OUTPUTS)

        say()
        say(f"(a) {n} Mercury studies differing only in numbers ({' x '.join(f for f, _ in NUMERIC)})")
        say(f"{'run':58s} {'wall s':>8s} {'studies/s':>10s} {'vs baseline':>12s}")
        rows = [
            (f"run_team one by one, in process ({nb} studies, first incl.)", t_one * n / nb, rate_one_cold),
            (f"run_team one by one, in process (warm, {nb - 1} studies)", (nb - 1) / rate_one_warm, rate_one_warm),
            ("batched, in process (workers=0, compile incl.)", t_in, n / t_in),
            ("batched, 2 workers, with start-up (cluster + compile)", cold_a, n / cold_a),
            (f"   of which cluster start {start_a:.1f} s; without it", cold_a - start_a, n / (cold_a - start_a)),
            ("batched, 2 workers, warm (same cluster, second sweep)", warm_a, n / warm_a),
        ]
        for label, wall, rate in rows:
            say(f"{label:58s} {wall:8.2f} {rate:10.1f} {rate / rate_one_warm:11.1f}x")
        say(
            f"goal >= 20 studies/s on 2 workers: warm {n / warm_a:.1f} -> {'met' if n / warm_a >= 20 else 'NOT met'}; "
            f"with start-up {n / cold_a:.1f} -> {'met' if n / cold_a >= 20 else 'not met'}"
        )
        say(
            f"agreement with run_team one by one ({nb} studies, {len(OUTPUTS)} outputs): "
            f"max relative difference {worst:.1e}"
        )
        say(f"2-worker chunks == in-process batches, bit for bit: {same}")

        # (b) schedule sweep: 2 workers vs 1
        cfg_b = sweep_deck(folder, "schedule", stm, SCHEDULE)
        cold1, start1, warm1, _ = timed_sweep(cfg_b, 1, folder, "b1")
        cold2, start2, warm2, _ = timed_sweep(cfg_b, 2, folder, "b2")
        say()
        say(f"(b) {len(cfg_b.studies())} studies changing the schedule ({SCHEDULE[0][0]} 1 ... 20 h), one task each")
        say(f"{'run':58s} {'1 worker s':>10s} {'2 workers s':>11s} {'speed-up':>9s}")
        for label, a, b in (
            ("with start-up (cluster + compile)", cold1, cold2),
            ("without cluster start (first sweep, compile incl.)", cold1 - start1, cold2 - start2),
            ("warm (same cluster, second sweep)", warm1, warm2),
        ):
            say(f"{label:58s} {a:10.2f} {b:11.2f} {a / b:8.2f}x")
        say(f"goal >= 1.6x (warm): {warm1 / warm2:.2f}x -> {'met' if warm1 / warm2 >= 1.6 else 'NOT met'}")
    if args.out is not None:
        args.out.write_text("\n".join(out) + "\n")


if __name__ == "__main__":
    main_guard(main)
