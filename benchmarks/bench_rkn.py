"""LEO + J2 one day, batch: the high-order Nystrom kernels (fracas.integrate.rkn) against a
scipy DOP853 loop in the same run.

    .venv/bin/python benchmarks/bench_rkn.py                 # 1000 lanes, ~1 min on 2 cores
    .venv/bin/python benchmarks/bench_rkn.py --lanes 200 --scipy-lanes 5

Problem: r0 = [7000, 0, 0] km, v0 = [0, 7.5, 1.0] km/s with small per-lane perturbations,
point mass + J2, one day (Cowell).  Accuracy: final position error of every tested lane
against scipy DOP853 at rtol 1e-13, atol 1e-9 km.  For each method the tolerance is the
loosest of a short ladder that keeps the worst sampled lane <= 1 m.  Rows: steps per day
(accepted / attempted, worst lane), force evaluations per propagation, batch wall time
(jit compile excluded, best of --repeat) and propagations per second; the ratio column is
props/s over the scipy DOP853 loop's at its own <= 1 m tolerance, measured in this run.
The vmapped while-loop runs every lane until the slowest is done.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
from runs import failure, scipy_failure  # benchmarks/runs.py: no figure from a failed run


def _args():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lanes", type=int, default=1000)
    ap.add_argument("--scipy-lanes", type=int, default=10, help="lanes timed with the scipy loop")
    ap.add_argument("--check-lanes", type=int, default=10, help="lanes checked against the reference")
    ap.add_argument("--repeat", type=int, default=3)
    return ap.parse_args()


MU = 398600.4418
J2 = 1.08262668e-3
RE = 6378.137
DAY = 86400.0
X0 = np.array([7000.0, 0.0, 0.0, 0.0, 7.5, 1.0])


def rhs_numpy(t, y):
    r = y[:3]
    x, yy, z = r
    rn2 = x * x + yy * yy + z * z
    rn = np.sqrt(rn2)
    k = 1.5 * J2 * MU * RE**2 / rn**5
    z2 = 5.0 * z * z / rn2
    a = -MU * r / rn**3 + k * np.array([x * (z2 - 1.0), yy * (z2 - 1.0), z * (z2 - 3.0)])
    return np.concatenate([y[3:], a])


def main():
    args = _args()
    import jax
    import jax.numpy as jnp
    from scipy.integrate import solve_ivp

    from fracas.integrate import rkn
    from fracas.integrate import tableaux as T

    ez = jnp.array([0.0, 0.0, 1.0])

    def accel(t, r):
        # vector form (no stacking of components: 1.4x faster compiled) and sqrt(1/r2), not
        # 1/sqrt(r2): no float64 rsqrt on XLA CPU (../shared/perf-notes.md)
        ir2 = 1.0 / jnp.dot(r, r)
        ir = jnp.sqrt(ir2)
        ir3 = ir * ir2
        z = r[2]
        k = 1.5 * J2 * MU * RE * RE * ir3 * ir2
        z2 = 5.0 * z * z * ir2
        return r * (k * (z2 - 1.0) - MU * ir3) - (2.0 * k * z) * ez

    rng = np.random.default_rng(1)
    n = args.lanes
    x0 = np.tile(X0, (n, 1))
    x0[:, :3] += rng.normal(0.0, 1.0, (n, 3))  # km
    x0[:, 3:] += rng.normal(0.0, 1e-3, (n, 3))  # km/s
    print(f"jax {jax.__version__}, {os.cpu_count()} CPUs, {jax.devices()[0].platform}; lanes {n}")

    nchk = min(args.check_lanes, n)
    t0 = time.perf_counter()
    ref_sols = [solve_ivp(rhs_numpy, (0.0, DAY), x0[i], method="DOP853", rtol=1e-13, atol=1e-9) for i in range(nchk)]
    for i, s in enumerate(ref_sols):
        if scipy_failure(s):
            sys.exit(f"error: reference lane {i}: {scipy_failure(s)}")  # one line, exit 1
    ref = np.array([s.y[:3, -1] for s in ref_sols])
    print(f"reference: scipy DOP853 rtol 1e-13 on {nchk} lanes, {time.perf_counter() - t0:.1f} s")

    # ---- scipy DOP853 loop at the loosest tolerance giving <= 1 m
    ns = min(args.scipy_lanes, nchk)
    scipy_row = None
    for tol in (1e-9, 1e-10, 1e-11, 1e-12):
        t0 = time.perf_counter()
        sols = [solve_ivp(rhs_numpy, (0.0, DAY), x0[i], method="DOP853", rtol=tol, atol=tol) for i in range(ns)]
        wall = time.perf_counter() - t0
        if any(scipy_failure(s) for s in sols):
            print(f"scipy DOP853 rtol {tol:.0e}: {next(scipy_failure(s) for s in sols if scipy_failure(s))}")
            continue
        err = max(np.linalg.norm(s.y[:3, -1] - ref[i]) for i, s in enumerate(sols)) * 1e3
        if err <= 1.0:
            steps = max(s.t.size - 1 for s in sols)
            nfev = max(s.nfev for s in sols)
            scipy_row = (tol, steps, nfev, err, ns / wall)
            break
    tol, steps, nfev, err, scipy_rate = scipy_row
    print()
    print(
        f"{'method':<18}{'rtol':>8}{'steps/day':>14}{'f evals':>9}{'max err m':>11}"
        f"{'wall s':>9}{'props/s':>11}{'ratio':>8}"
    )
    print(
        f"{'scipy DOP853 loop':<18}{tol:>8.0e}{steps:>14d}{nfev:>9d}{err:>11.3f}"
        f"{ns / scipy_rate:>9.2f}{scipy_rate:>11.1f}{1.0:>8.2f}"
    )

    for tab in (T.DPRKN12, T.DPRKN8, T.DOP853):
        acc = accel if isinstance(tab, T.NystromTableau) else (lambda t, r, v: accel(t, r))
        for tol in (1e-8, 1e-9, 1e-10, 1e-11, 1e-12):

            def one(x, tol=tol, acc=acc, tab=tab):
                return rkn.integrate_adaptive(acc, 0.0, x[:3], x[3:], DAY, tab, rtol=tol, atol=tol)

            run = jax.jit(jax.vmap(one))
            xs = jnp.asarray(x0)
            out = run(xs)
            out.r.block_until_ready()
            failed = failure(out, ok=(0,))  # every lane must reach the day's end
            if failed:
                print(f"{tab.name:<18}{tol:>8.0e}  {failed}")
                continue
            err = np.max(np.linalg.norm(np.asarray(out.r[:nchk]) - ref, axis=1)) * 1e3
            if err > 1.0:
                continue
            best = np.inf
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                run(xs).r.block_until_ready()
                best = min(best, time.perf_counter() - t0)
            st = f"{int(np.max(out.n_accept))}/{int(np.max(out.n_steps))}"
            per_step = tab.stages - (1 if tab.fsal else 0)
            if tab is T.DOP853:
                per_step = tab.stages  # 12 stages + the FSAL stage reused
            fe = int(np.max(out.n_steps)) * per_step
            rate = n / best
            name = tab.name
            print(
                f"{name:<18}{tol:>8.0e}{st:>14}{fe:>9d}{err:>11.3f}{best:>9.2f}{rate:>11.1f}{rate / scipy_rate:>8.1f}"
            )
            break


if __name__ == "__main__":
    main()
