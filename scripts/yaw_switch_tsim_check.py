"""TSIM against TEAM through a yaw-switch flip (issue 32, item 1a): the Monte Carlo check.

    python scripts/yaw_switch_tsim_check.py [--missions N] [--seed S]

Flies the missions of tests/data/tsim_yaw_switch.toml (default its 2,048; thrust noise only
through the flip at 3.18 d, no maneuvers: tests/tsim/test_yaw_switch_tsim.py says how) and
prints, at every TEAM output time, the TSIM/TEAM sigma ratio of each state component with
its count of standard errors (SE = 1 / sqrt(2 (N - 1))) and the Wishart p-value of the
position-velocity covariance; then the same sample against the independent reference without
the saltation jump (tests/team/test_yaw_switch_reference.py), which it must reject; and the
wall times.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.team.test_yaw_switch_reference import load_case, reference_covariances  # noqa: E402
from tests.tsim.test_yaw_switch_tsim import DAY_S, compare, monte_carlo, print_table, yaw_plan  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--missions", type=int, default=None, help="default: the deck's")
    ap.add_argument("--seed", type=int, default=None, help="default: the deck's")
    args = ap.parse_args()
    t0 = time.perf_counter()
    plan, prod, times, x_ref = yaw_plan(args.missions)
    if args.seed is not None:
        plan = dataclasses.replace(plan, seed=args.seed)
    t1 = time.perf_counter()
    dev = monte_carlo(plan, times, x_ref)
    t2 = time.perf_counter()
    c = compare(dev, np.asarray(prod.assumed.P_plus))
    print_table(f"TSIM/TEAM sigma ratios, {plan.missions} missions, seed {plan.seed}", times, c)
    worst = np.unravel_index(np.argmax(np.abs(c["z"])), c["z"].shape)
    print(
        f"worst: {c['ratio'][worst]:.4f} ({c['z'][worst]:+.2f} SE) at {times[1:][worst[0]] / DAY_S:g} d, "
        f"component {worst[1]}; ratio range {c['ratio'].min():.4f} to {c['ratio'].max():.4f}; "
        f"smallest Wishart p {c['p'].min():.3g}; largest |mean| {np.max(np.abs(c['mean'])):.3f} TEAM sigma"
    )
    case = load_case()
    P_nj, flips = reference_covariances(case, jump=False)
    c_nj = compare(dev, P_nj)
    print_table(f"TSIM / the reference without the jump (flip at {flips[0] / DAY_S:.4f} d)", times, c_nj)
    print(
        f"wall: plan (TEAM run, reference through the hold grid) {t1 - t0:.1f} s, "
        f"{plan.missions} missions {t2 - t1:.1f} s (first block's compile included)"
    )


if __name__ == "__main__":
    main()
