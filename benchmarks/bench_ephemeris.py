"""Time the heliocentric DE421 table (fracas.dynamics.ephemeris) against jplephem.

    .venv/bin/python benchmarks/bench_ephemeris.py [--n 10000] [--n-loop 1000]

Rows: one jitted ``body_states`` call (11 bodies, scalar time: mostly dispatch);
``body_states`` over N times in one call (vmapped); N evaluations inside a compiled
``lax.fori_loop`` (the propagator's use; loop overhead subtracted); jplephem's legacy ``Ephemeris``
for the same 11 heliocentric states (sun, earthmoon, moon, 8 planets: 11 series
evaluations per instant) in a Python loop, and vectorised over the N times.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def _best(fn, repeat: int) -> float:
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10_000, help="times in the vmapped call")
    ap.add_argument("--n-loop", type=int, default=1_000, help="times in the jplephem Python loop")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()

    t_imp = time.perf_counter()
    import jax
    import jax.numpy as jnp

    from fracas.dynamics import ephemeris as E

    t_imp = time.perf_counter() - t_imp
    import de421
    from jplephem.ephem import Ephemeris

    names = E.BODY_NAMES
    t0 = E.calendar_to_et("2025-01-01T00:00:00")
    t1 = E.calendar_to_et("2027-01-01T00:00:00")
    t_build = time.perf_counter()
    table = E.build_ephemeris(names, t0, t1)
    jax.block_until_ready(table)
    t_build = time.perf_counter() - t_build

    rng = np.random.default_rng(0)
    ets = rng.uniform(t0, t1, args.n)
    ets_j = jnp.asarray(ets)

    one = jax.jit(E.body_states)
    many = jax.jit(jax.vmap(E.body_states, in_axes=(None, 0)))
    tc = time.perf_counter()
    jax.block_until_ready(one(table, ets_j[0]))
    t_c1 = time.perf_counter() - tc
    tc = time.perf_counter()
    jax.block_until_ready(many(table, ets_j))
    t_cn = time.perf_counter() - tc

    scalars = [jnp.float64(t) for t in ets[:200]]  # device scalars made outside the timing
    t_one = _best(lambda: [jax.block_until_ready(one(table, t)) for t in scalars], args.repeat) / 200
    t_many = _best(lambda: jax.block_until_ready(many(table, ets_j)), args.repeat)

    # Per evaluation inside compiled code (how the propagator uses it): a fori_loop of N
    # evaluations at times 6000 s apart, minus the same loop without the ephemeris.
    def looped(with_eph):
        def run(tab, t0):
            def body(i, acc):
                t = t0 + i * 6000.0
                if not with_eph:
                    return acc + jnp.sin(t)
                p, v = E.body_states(tab, t)
                return acc + jnp.sin(t) + p[3, 0] + v[4, 1]

            return jax.lax.fori_loop(0, args.n, body, 0.0)

        return jax.jit(run)

    loop_eph, loop_bare = looped(True), looped(False)
    jax.block_until_ready(loop_eph(table, ets_j[0]))
    jax.block_until_ready(loop_bare(table, ets_j[0]))
    t_loop_in = _best(lambda: jax.block_until_ready(loop_eph(table, ets_j[0])), args.repeat) - _best(
        lambda: jax.block_until_ready(loop_bare(table, ets_j[0])), args.repeat
    )

    eph = Ephemeris(de421)
    series = ["sun", "earthmoon", "moon", "mercury", "venus", "mars", "jupiter", "saturn", "uranus", "neptune", "pluto"]
    for s in series:
        eph.load(s)
    tdb = 2451545.0 + ets / 86400.0

    def jpl_loop():
        for t in tdb[: args.n_loop]:
            for s in series:
                eph.position_and_velocity(s, t)

    def jpl_vec():
        for s in series:
            eph.position_and_velocity(s, tdb)

    t_loop = _best(jpl_loop, max(1, args.repeat // 2)) / args.n_loop
    t_vec = _best(jpl_vec, args.repeat)

    dev = jax.devices()[0]
    print(f"fracas EPHEM benchmark: 11 bodies, device {dev.platform}:{dev.device_kind}, N = {args.n}")
    print(
        f"(import {t_imp:.2f} s, build table {t_build * 1e3:.0f} ms, "
        f"compile scalar {t_c1:.2f} s, compile vmapped {t_cn:.2f} s)"
    )
    rows = [
        ("fracas body_states, jit, 1 time", t_one, 1),
        (f"fracas body_states, jit+vmap, {args.n} times", t_many, args.n),
        (f"fracas body_states in lax.fori_loop, {args.n} steps", t_loop_in, args.n),
        ("jplephem, Python loop, 1 time", t_loop, 1),
        (f"jplephem, numpy-vectorised, {args.n} times", t_vec, args.n),
    ]
    print(f"{'method':<50s} {'per call':>12s} {'per instant':>14s}")
    for label, t, n in rows:
        print(f"{label:<50s} {t * 1e6:>9.1f} us {t / n * 1e6:>11.3f} us")


if __name__ == "__main__":
    main()
