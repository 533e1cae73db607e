"""TEAM guidance and error-budget cost: the Mercury B-plane study through its STM file.

Rows (median of --repeat warm runs in one process after one untimed warm-up; the cold
first run, compile included, is reported separately):
  1. baseline: namelists/mercury_approach_guidance.toml with its [[guidance]] removed and
     the budget off (the plain TEAM study, the same schedule without the guidance time);
  2. with the impulsive B-plane maneuver (GUIDM: Ψ from the STM file, P_ΔV, |ΔV|
     statistics, control covariance, the filter run again with the execution errors);
  3. with the maneuver and the error budget (one true-side pass per error source).
Ratios are against row 1 in the same run (the machine is shared and noisy).  No goal is
set by the issue; the figures size what guidance and budgets cost.

    .venv/bin/python benchmarks/bench_guidance.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from runs import main_guard, require  # noqa: E402

from fracas.config.team import load_team_deck  # noqa: E402
from fracas.modes.stm import build_stm  # noqa: E402
from fracas.modes.team import run_team  # noqa: E402

DECK = ROOT / "namelists" / "mercury_approach_guidance.toml"


def _time(deck, repeat: int) -> tuple[float, float]:
    t0 = time.perf_counter()
    require(run_team(deck, write_results=False)[0], "TEAM (cold)", ok=(0,))
    cold = time.perf_counter() - t0
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        product = run_team(deck, write_results=False)[0]
        ts.append(time.perf_counter() - t0)
        require(product, "TEAM (warm)", ok=(0,))
    return cold, statistics.median(ts)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    base = load_team_deck(DECK)
    stm = base.resolve(base.errcon.stm_file)
    if not stm.exists():
        print(f"building {stm} once (not timed)")
        build_stm(base, stm)
    plain = base.model_copy(update={"guidance": [], "budget": base.budget.model_copy(update={"enabled": False})})
    guided = base.model_copy(update={"budget": base.budget.model_copy(update={"enabled": False})})
    rows = [("plain TEAM study", plain), ("+ B-plane maneuver", guided), ("+ maneuver + error budget", base)]
    out = []
    for name, deck in rows:
        cold, warm = _time(deck, a.repeat)
        out.append((name, cold, warm))
    w0 = out[0][2]
    print(f"{'row':28s} {'cold s':>8s} {'warm s':>8s} {'warm / row 1':>13s}")
    for name, cold, warm in out:
        print(f"{name:28s} {cold:8.2f} {warm:8.3f} {warm / w0:13.2f}")
    n_src = len(require(run_team(base, write_results=False)[0], "TEAM with budget", ok=(0,)).budget.sources)
    print(f"(error budget: {n_src} sources)")


if __name__ == "__main__":
    main_guard(main)
