"""Indirect (costate / shooting) solutions of the two published problems in tests/tom/published_problems.py.

    .venv/bin/python benchmarks/published_problems_indirect.py          # ~20 s on one core
    .venv/bin/python benchmarks/published_problems_indirect.py --warm   # Earth-Mars from the stored costates

Prints, for each problem: the published optimum, the optimum of our indirect solution
(scipy solve_bvp / solve_ivp DOP853 + scipy.optimize.root), their relative difference and
the solve time; then the Earth-Mars switch times and per-burn mean pointing, and the
Bryson & Ho thrust-angle history at a few times.  Pure numpy/scipy, no fracas import.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import numpy as np  # noqa: E402
from tables import emit, table  # noqa: E402

from tests.tom import published_problems as pp  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--warm", action="store_true", help="Earth-Mars: skip the random search and continuation")
    args = ap.parse_args()

    rows = []
    bh = {}
    for label, tf in (("tf = 3.32 (193 d)", pp.BRYSON_HO["tf"]), ("tf = 3.3155", pp.BRYSON_HO["tf_alternative"])):
        s = pp.bryson_ho_indirect(tf)
        bh[tf] = s
        rows.append(
            [
                f"Bryson & Ho max radius, {label}",
                f"{pp.BRYSON_HO_PUBLISHED_RF:.3f}",
                f"{s.r_f:.10f}",
                f"{(s.r_f - pp.BRYSON_HO_PUBLISHED_RF) / pp.BRYSON_HO_PUBLISHED_RF:+.2e}",
                f"{s.solve_time_s:.2f}",
            ]
        )

    if args.warm:
        em = pp.earth_mars_indirect(z0=np.array(pp.EARTH_MARS_COSTATES0), rhos=())
    else:
        em = pp.earth_mars_indirect()
    # the same problem with g0 = 9.8065 m/s^2 (the value that reproduces 603.935 kg)
    data = dict(pp.EARTH_MARS, g0_m_s2=9.8065)
    em_g = pp.earth_mars_indirect(z0=em.costates0, rhos=(), data=data)
    for label, s in (("g0 = 9.80665", em), ("g0 = 9.8065", em_g)):
        rows.append(
            [
                f"Taheri Earth-Mars min fuel m_f kg, {label}",
                f"{pp.EARTH_MARS_PUBLISHED_MF:.3f}",
                f"{s.m_f_kg:.6f}",
                f"{(s.m_f_kg - pp.EARTH_MARS_PUBLISHED_MF) / pp.EARTH_MARS_PUBLISHED_MF:+.2e}",
                f"{s.solve_time_s:.2f}",
            ]
        )
    emit("Published low-thrust optimal-control problems: published optimum vs our indirect solution")
    emit()
    table(["problem", "published", "indirect", "rel. diff", "time s"], rows)
    emit()
    emit(f"Bryson & Ho: {pp.BRYSON_HO_PUBLISHED_CITATION}")
    emit(f"Earth-Mars:  {pp.EARTH_MARS_PUBLISHED_CITATION}")
    emit()

    s = bh[pp.BRYSON_HO["tf"]]
    emit(
        f"Bryson & Ho, tf = {s.tf}: r_f = {s.r_f:.10f}, transfer angle {math.degrees(s.theta_f):.3f} deg, "
        f"shooting residual {s.bc_residual:.1e}, solve_bvp nodes {s.n_nodes}, "
        f"lam(0) = {np.array2string(s.costates0, precision=8)}"
    )
    idx = np.linspace(0, s.t.size - 1, 9).astype(int)
    table(
        ["t", "r", "phi from horizontal deg", "phi from velocity deg"],
        [
            [
                f"{s.t[i]:.3f}",
                f"{s.states[0, i]:.5f}",
                f"{math.degrees(s.phi_horizontal[i]):.2f}",
                f"{math.degrees(s.phi_velocity[i]):.2f}",
            ]
            for i in idx
        ],
    )
    emit()
    emit(
        f"Earth-Mars (g0 = 9.80665): m_f = {em.m_f_kg:.6f} kg, propellant {em.propellant_kg:.6f} kg, "
        f"bang-bang residual {em.residual:.1e}, random starts {em.random_starts}"
    )
    emit("switch times (days): " + ", ".join(f"{t:.4f}" for t in em.switch_times_days))
    table(
        ["burn", "start d", "end d", "length d", "in-plane deg", "out-of-plane deg", "from v deg"],
        [
            [
                str(k + 1),
                f"{b['start_days']:.4f}",
                f"{b['end_days']:.4f}",
                f"{b['duration_days']:.4f}",
                f"{b['in_plane_deg']:.2f}",
                f"{b['out_of_plane_deg']:.2f}",
                f"{b['from_velocity_deg']:.2f}",
            ]
            for k, b in enumerate(em.burns)
        ],
        note="in-plane: mean direction from the local horizontal towards the outward radial (RTN); "
        "from v: time-averaged angle to the velocity",
    )
    if em.continuation:
        table(
            ["rho", "m_f kg", "residual"],
            [[f"{r:.0e}", f"{m:.6f}", f"{e:.1e}"] for r, m, e in em.continuation],
            note="tanh-smoothing continuation (each warm-started from the previous)",
        )


if __name__ == "__main__":
    t0 = time.perf_counter()
    main()
    emit(f"\ntotal {time.perf_counter() - t0:.1f} s")
