"""TEAM speed: the Mercury study through an STM file vs integrated in line (issue 3 goals).

Rows (each the median of --repeat warm runs in one process, after one untimed warm-up):
  1. the Mercury approach study (namelists/mercury_approach_team.toml: 40 days, DSN
     Doppler + range + QVLBI, 20 augmented parameters, generalized covariance on) through
     its STM file: deck -> study -> STM file read and chained -> filter -> predictions;
  2. the same study integrated in line (propagate_with_sensitivities over the schedule);
  3. a second study with a changed tracking schedule (Doppler every 3 h, range every 6 h,
     QVLBI every 2 h) through the same file.
Goals: row 1 under 0.5 s warm; row 2 / row 1 >= 10.  Writing the results file and the
printout are timed separately (not part of "the study").  The STM file build (STMGEN) is
timed once.  For scale: in 1972, 10 days of tracking with 91 measurements took 13.5 s on
a CDC 6600 (FRACAS App. 9.3).

    .venv/bin/python benchmarks/bench_team.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import copy
import statistics
import sys
import tempfile
import time
from pathlib import Path

import tomllib

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from runs import main_guard, require  # noqa: E402

from fracas.build.team import build_study  # noqa: E402
from fracas.config.team import TeamDeck, load_team_deck  # noqa: E402
from fracas.io.stm_file import write_stm_file  # noqa: E402
from fracas.team.engine import run_study  # noqa: E402
from fracas.team.reference import build_stm_data, integrate_reference, reference_from_stm  # noqa: E402

DECK = ROOT / "namelists" / "mercury_approach_team.toml"


def changed_deck() -> TeamDeck:
    d = tomllib.loads(DECK.read_text())
    d = copy.deepcopy(d)
    for t in d["tracking"]:
        t["interval_hours"] = {"doppler2": 3.0, "range2": 6.0, "diff_doppler": 2.0, "diff_range": 2.0}[t["type"]]
    deck = TeamDeck.model_validate(d)
    deck._source_path = str(DECK)
    return deck


def one(deck_fn, stm_path=None):
    t0 = time.perf_counter()
    st = build_study(deck_fn())
    t1 = time.perf_counter()
    ref = reference_from_stm(st, stm_path) if stm_path else integrate_reference(st)
    t2 = time.perf_counter()
    res = run_study(st, ref)
    t3 = time.perf_counter()
    # the reference (integrated or read) and the covariance history must be sound: no timing or
    # difference from a run that ran off its trajectory or lost its covariance
    require(res, f"TEAM {'through the STM file' if stm_path else 'in line'}", ok=(0,))
    return {"setup": t1 - t0, "reference": t2 - t1, "analysis": t3 - t2, "total": t3 - t0, "res": res}


def timed(label, fn, repeat):
    fn()  # warm-up (compiles; persistent cache)
    runs = [fn() for _ in range(repeat)]
    med = {k: statistics.median(r[k] for r in runs) for k in ("setup", "reference", "analysis", "total")}
    res = runs[-1]["res"]
    med["events"] = res.study.schedule.n
    med["meas"] = sum(r.used for r in res.meas.records)
    med["n"] = res.study.layout.n
    return label, med, res


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp())
    stm = tmp / "mercury.h5"
    st = build_study(load_team_deck(DECK))
    t0 = time.perf_counter()
    data = build_stm_data(st)
    write_stm_file(stm, data)
    t_build = time.perf_counter() - t0
    print(
        f"STM file build (STMGEN, cold process, includes compile): {t_build:.2f} s; "
        f"{data.n_times} times x {len(data.param_labels)} parameters, {stm.stat().st_size / 1e6:.1f} MB"
    )
    rows = [
        timed("Mercury study through the STM file", lambda: one(lambda: load_team_deck(DECK), stm), a.repeat),
        timed("same study integrated in line", lambda: one(lambda: load_team_deck(DECK)), a.repeat),
        timed("changed tracking schedule, same file", lambda: one(changed_deck, stm), a.repeat),
    ]
    hdr = f"{'case':<40s} {'events':>6s} {'meas':>5s} {'n':>3s} {'setup':>7s} {'reference':>9s} {'analysis':>8s} {'total s':>8s}"  # noqa: E501
    print(hdr)
    print("-" * len(hdr))
    for label, m, _ in rows:
        print(
            f"{label:<40s} {m['events']:6d} {m['meas']:5d} {m['n']:3d} {m['setup']:7.3f} {m['reference']:9.3f} "
            f"{m['analysis']:8.3f} {m['total']:8.3f}"
        )
    f, i = rows[0][1]["total"], rows[1][1]["total"]
    print(
        f"\nthrough the file: {f:.3f} s (goal < 0.5 s: {'met' if f < 0.5 else 'NOT met'}); "
        f"in line / file = {i / f:.1f}x (goal >= 10x: {'met' if i / f >= 10 else 'NOT met'})"
    )
    r = rows[0][2]
    b = rows[1][2]
    import numpy as np

    d = np.max(
        np.abs(r.Pa_plus - b.Pa_plus) / np.sqrt(np.abs(np.einsum("kii,kjj->kij", r.Pa_plus, r.Pa_plus)) + 1e-300)
    )
    print(f"file vs in-line: max |dP| / sqrt(P_ii P_jj) over all events = {d:.2e}")
    from fracas.io.team_results import write_team_results

    t0 = time.perf_counter()
    write_team_results(tmp / "res.h5", r, str(stm))
    print(
        f"writing the results file: {time.perf_counter() - t0:.3f} s ({(tmp / 'res.h5').stat().st_size / 1e6:.1f} MB)"
    )
    print("timings: " + "; ".join(f"{k} {v:.3f}" for k, v in r.timing.items()))


if __name__ == "__main__":
    main_guard(main)
