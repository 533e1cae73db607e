"""High-order methods of the batch core against heyoka and scipy, in the same run, at <= 1 m.

    .venv/bin/python benchmarks/bench_highorder.py            # full run (~15 min on 2 cores)
    .venv/bin/python benchmarks/bench_highorder.py --quick    # small batches (~4 min)

Every fracas row goes through the project's batch entry point
(``fracas.integrate.batch.propagate_batch``: the propagation loop with its events, breaks,
mass and thrust machinery in place, vmapped over lanes, chunked, sharded over host devices).

Sections:
  1. accuracy and tolerance: truth for 16 states of each case from heyoka in long double
     (benchmarks/heyoka_cases.py); for each method the loosest tolerance of a ladder that
     keeps every checked state within 1 m; heyoka's the same way;
  2. throughput: props/s of each (method, formulation) on 1 and 2 host devices against
     heyoka's ``taylor_adaptive_batch`` (one thread, SIMD batch) at its own <= 1 m tolerance;
     steps and force evaluations per propagation;
  3. the STM: explicit variational equations and forward-mode AD against heyoka's
     ``var_ode_sys`` (order 1);
  4. the 300-day cruise with thrust and planets against a scipy DOP853 loop;
  5. lane grouping on a batch of mixed orbits, chunk sizes;
  6. compile time per program, cold and from the persistent cache (fresh processes).
Ratios are props/s over the baseline's props/s measured in this run (the machine is shared).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _args():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--devices", type=int, default=2)
    ap.add_argument("--compile-probe", default=None, help=argparse.SUPPRESS)  # internal: section 6
    ap.add_argument(
        "--ceiling",
        nargs=2,
        type=float,
        metavar=("PROPS_S", "STEPS"),
        help="only section 7, for a measured one-device DPRKN12 LEO rate and its steps per propagation",
    )
    return ap.parse_args()


ARGS = _args()
os.environ["FRACAS_HOST_DEVICES"] = str(ARGS.devices)
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import numpy as np  # noqa: E402

from fracas.dynamics.model import IntegratorSettings  # noqa: E402
from fracas.integrate import highorder  # noqa: E402
from fracas.integrate.batch import host_devices, propagate_batch  # noqa: E402

DAY = 86400.0
TARGET_M = 1.0
TOLS = (1e-7, 3e-8, 1e-8, 3e-9, 1e-9, 3e-10, 1e-10, 3e-11, 1e-11, 3e-12, 1e-12)


# ----------------------------------------------------------------------------- models
from fracas_cases import fracas_problem  # noqa: E402  (shared with bench_heyoka_ratio.py)


def run_batch(m, p, x0s, t_final, devices, sens=None, repeat=2, chunk=None, group=False):
    """(Trajectory[, Sensitivities], best seconds, first-call seconds): a warm-up call on the
    full chunk shape (compile) and the best of ``repeat`` timed calls."""
    t_out = np.array([0.0, t_final])
    kw = {"devices": devices, "chunk_size": chunk, "group_lanes": group}
    if sens is not None:
        kw.update(with_sensitivities=True, sensitivity_method=sens)
    t0 = time.perf_counter()
    out = propagate_batch(m, p, None, 0.0, x0s, t_out, **kw)
    first = time.perf_counter() - t0
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = propagate_batch(m, p, None, 0.0, x0s, t_out, **kw)
        best = min(best, time.perf_counter() - t0)
    st = m.integrator
    require(out, f"fracas {st.formulation} {st.method} ({x0s.shape[0]} lanes, {t_final / DAY:g} d)", ok=(0,))
    return out, best, first


def final_states(out):
    tr = out if hasattr(out, "x") else out[0]  # a Trajectory, or (Trajectory, Sensitivities)
    return tr.x[:, -1, :], tr


# ----------------------------------------------------------------------------- output
from runs import failure, main_guard, require  # noqa: E402
from tables import emit, si, table  # noqa: E402


# ----------------------------------------------------------------------- sections 1-2
def loosest_fracas_tol(case, method, formulation, x_ref, truth_ref, devices):
    import heyoka_cases as hc

    tried = []
    ladder = (0.05, 0.03, 0.02, 0.015, 0.01, 0.007) if method == "rkn4" else TOLS
    for tol in ladder:
        m, p = fracas_problem(case, method, formulation, tol, c_nom=tol if method == "rkn4" else None)
        out = propagate_batch(m, p, None, 0.0, x_ref, np.array([0.0, case.t_final_s]), devices=devices)
        xf, tr = final_states(out)
        err = np.inf if failure(tr, ok=(0,)) else hc.pos_err_m(xf[:, :6], truth_ref[:, :6])  # failed: too large
        tried.append((tol, err))
        if err <= TARGET_M:
            return tol, err, tried
    return None, None, tried


def throughput(cases, n_lanes, methods_of, devs_all):
    import heyoka_cases as hc

    results = {}
    for name in cases:
        case = hc.CASES[name]
        n = n_lanes[name]
        x0s = hc.initial_states(case, n)
        x_ref = x0s[:16]
        truth_ref = hc.truth(case, x_ref)
        emit(f"\n--- {name}: {case.description}; {n:,} lanes, t = {case.t_final_s / DAY:g} d")
        tol_h, err_h, tried_h = hc.loosest_tol(case, x_ref, truth_ref, TARGET_M)
        hb = hc.HeyokaBatch(case, tol_h)
        hb.run(x0s[: 2 * hb.batch])  # warm
        final_h, steps_h, sec_h = hb.run(x0s)
        rate_h = n / sec_h
        rows = [
            [
                f"heyoka taylor_adaptive_batch (batch {hb.batch}, order {hb.order})",
                f"{tol_h:g}",
                f"{err_h:.3f}",
                f"{steps_h / n:.0f}",
                "-",
                f"{hb.compile_s:.2f}",
                "1 thread",
                si(rate_h),
                "1.00",
            ]
        ]
        results[(name, "heyoka")] = {"rate": rate_h, "tol": tol_h, "err": err_h, "steps": steps_h / n}
        for method, formulation in methods_of(case):
            tol, err, tried = loosest_fracas_tol(case, method, formulation, x_ref, truth_ref, devs_all[:1])
            if tol is None:
                rows.append([f"fracas {formulation} {method}", "-", "> 1 m", "-", "-", "-", "-", "-", "-"])
                continue
            m, p = fracas_problem(case, method, formulation, tol, c_nom=tol if method == "rkn4" else None)
            xs = x0s[: max(256, n // 10)] if method == "rkn4" else x0s  # today's core: a tenth of the lanes
            n_run = xs.shape[0]
            for nd in sorted({1, len(devs_all)}):
                out, best, first = run_batch(m, p, xs, case.t_final_s, devs_all[:nd])
                _, tr = final_states(out)
                steps = float(np.mean(tr.n_steps))
                evals = steps * highorder.stages_per_step(method)
                rate = n_run / best
                rows.append(
                    [
                        f"fracas {formulation} {method}" + (" c_nom (FRACAS)" if method == "rkn4" else ""),
                        f"{tol:g}",
                        f"{err:.3f}",
                        f"{steps:.0f} (max {int(np.max(tr.n_steps))}, rej {np.mean(tr.n_reject):.0f})",
                        f"{evals:.0f}",
                        f"{first:.1f}",
                        f"{nd} device{'s' if nd > 1 else ''}",
                        si(rate),
                        f"{rate / rate_h:.2f}",
                    ]
                )
                results[(name, method, formulation, nd)] = {"rate": rate, "ratio": rate / rate_h, "steps": steps}
        table(
            ["method", "tol", "err m", "steps/prop", "f evals", "first s", "devices", "props/s", "÷ heyoka"],
            rows,
            f"heyoka tolerances tried: {', '.join(f'{t:g}: {e:.2g} m' for t, e in tried_h)}",
        )
    return results


# ------------------------------------------------------------------------- section 3
def stm_section(n, devs_all):
    import heyoka_cases as hc

    out_rows = []
    for name, variants in (
        ("leo_j2", (("dprkn12", "cowell", "variational"), ("dprkn12", "cowell", "ad"))),
        ("leo_thrust", (("dop853", "cowell", "ad"),)),
    ):
        case = hc.CASES[name]
        x0s = hc.initial_states(case, n)
        x_ref = x0s[:16]
        truth_ref = hc.truth(case, x_ref)
        tol_h, _, _ = hc.loosest_tol(case, x_ref, truth_ref, TARGET_M)
        hv = hc.HeyokaBatch(case, tol_h, var=True)
        hv.run(x0s[: 2 * hv.batch])
        final_hv, _, sec_hv = hv.run(x0s)
        rate_hv = n / sec_hv
        nx = case.nx
        phi_h = hc.stm_of(final_hv, nx)
        out_rows.append([f"{name}: heyoka var_ode_sys (tol {tol_h:g})", "-", "-", "1 thread", si(rate_hv), "1.00", "-"])
        for method, formulation, sens in variants:
            tol, _, _ = loosest_fracas_tol(case, method, formulation, x_ref, truth_ref, devs_all[:1])
            m, p = fracas_problem(case, method, formulation, tol)
            for nd in sorted({1, len(devs_all)}):
                out, best, first = run_batch(m, p, x0s, case.t_final_s, devs_all[:nd], sens=sens)
                phi_f = out[1].stm[:, -1, :nx, :nx]
                rel = np.max(np.linalg.norm(phi_f - phi_h, axis=(1, 2)) / np.linalg.norm(phi_h, axis=(1, 2)))
                rate = n / best
                out_rows.append(
                    [
                        f"{name}: fracas {formulation} {method} STM by {sens}",
                        f"{tol:g}",
                        f"{first:.1f}",
                        f"{nd} device{'s' if nd > 1 else ''}",
                        si(rate),
                        f"{rate / rate_hv:.2f}",
                        f"{rel:.1e}",
                    ]
                )
    table(
        ["method", "tol", "first s", "devices", "props/s", "÷ heyoka var", "|dPhi|/|Phi| vs heyoka"],
        out_rows,
        f"{n:,} lanes; fracas gives the 7x7 STM (6x6 block compared); heyoka 6x6 (7x7 with thrust).",
    )


# ------------------------------------------------------------------------- section 4
def cruise_section(n, n_scipy, devs_all):
    import cruise_case as cc

    x0s = cc.cruise_states(n)
    rhs = cc._cruise_rhs()
    t0 = time.perf_counter()
    ref = np.array([cc.dop853(rhs, x, cc.CR_BREAKS, 1e-13, 1e-12)[0] for x in x0s[:n_scipy]])
    t_ref = (time.perf_counter() - t0) / n_scipy
    rows = []
    scipy_rate = None
    for tol in (1e-10, 1e-11, 1e-12, 1e-13):
        t0 = time.perf_counter()
        sc = [cc.dop853(rhs, x, cc.CR_BREAKS, tol, tol * 1e3) for x in x0s[:n_scipy]]
        sec = (time.perf_counter() - t0) / n_scipy
        err = max(np.linalg.norm(s[0][:3] - r[:3]) for s, r in zip(sc, ref))
        if err * 1e3 <= TARGET_M or tol == 1e-13:  # 1e-13: the reference itself (error 0 by definition)
            scipy_rate = 1.0 / sec
            rows.append([f"scipy DOP853 loop (rtol {tol:g})", f"{err * 1e3:.3f}", "-", "-", f"{scipy_rate:.2f}", "1"])
            break
    for method, formulation in (("dop853", "cowell"), ("dop853", "encke")):
        for tol in (1e-10, 1e-11, 1e-12, 1e-13):
            m = cc.cruise_model(0.5)
            import dataclasses

            m = dataclasses.replace(
                m,
                integrator=IntegratorSettings(
                    method=method, formulation=formulation, step_control="tolerance", tolerance=tol, dt_max_s=np.inf
                ),
            )
            out = propagate_batch(m, cc.CR_P, cc.CR_EPH, cc.CR_ET0, x0s[:n_scipy], cc.CR_T, devices=devs_all[:1])
            require(out, f"cruise fracas {formulation} {method} tol {tol:g}", ok=(0,))
            err = np.max(np.linalg.norm(out.x[:, -1, :3] - ref[:, :3], axis=1))
            dm = np.max(np.abs(out.x[:, -1, 6] - ref[:, 6]))
            if err * 1e3 <= TARGET_M:
                break
        for nd in sorted({1, len(devs_all)}):
            t_out = cc.CR_T
            kw = {"devices": devs_all[:nd]}
            propagate_batch(m, cc.CR_P, cc.CR_EPH, cc.CR_ET0, x0s, t_out, **kw)
            t0 = time.perf_counter()
            out = propagate_batch(m, cc.CR_P, cc.CR_EPH, cc.CR_ET0, x0s, t_out, **kw)
            sec = time.perf_counter() - t0
            require(out, f"cruise fracas {formulation} {method} tol {tol:g}, {n} lanes", ok=(0,))
            rate = n / sec
            rows.append(
                [
                    f"fracas {formulation} {method} (tol {tol:g}), {nd} dev",
                    f"{err * 1e3:.3f}",
                    f"{dm * 1e3:.2g}",
                    f"{np.mean(out.n_steps):.0f}",
                    si(rate),
                    f"{rate / scipy_rate:.0f}" if scipy_rate else "-",
                ]
            )
    table(
        ["method", "err m", "mass err g", "steps", "props/s", "÷ scipy"],
        rows,
        f"{n} lanes; reference scipy DOP853 rtol 1e-13 ({t_ref:.1f} s each) on {n_scipy} lanes, two-part JD "
        "ephemeris (benchmarks/cruise_case.py).",
    )


# ------------------------------------------------------------------------- section 5
def grouping_section(n, devs_all):
    import heyoka_cases as hc

    rng = np.random.default_rng(5)
    base = hc.initial_states(hc.CASES["leo_j2"], n)
    high = base.copy()  # the same orbits scaled to a = 26,600 km (12 h): ~7x fewer steps per day
    high[:, :3] *= 3.8
    high[:, 3:6] /= np.sqrt(3.8)
    pick = rng.random(n) < 0.5  # half and half, randomly interleaved
    x0s = np.where(pick[:, None], high, base)
    m, p = fracas_problem(hc.CASES["leo_j2"], "dprkn12", "cowell", 1e-9)
    rows = []
    for group in (False, True):
        out, best, _ = run_batch(m, p, x0s, DAY, devs_all[:1], group=group, repeat=1)
        rows.append([f"group_lanes={group}", f"{np.mean(out.n_steps):.0f}", si(n / best)])
    for chunk in (256, 512, 1024, 2048, 4096):
        out, best, _ = run_batch(m, p, base, DAY, devs_all[:1], chunk=chunk, repeat=1)
        rows.append([f"LEO, chunk {chunk}", f"{np.mean(out.n_steps):.0f}", si(n / best)])
    table(
        ["batch", "mean steps", "props/s"],
        rows,
        f"{n:,} lanes, DPRKN12 Cowell tol 1e-9, 1 device; grouping rows: LEO and 12 h orbits interleaved 50/50.",
    )


# ------------------------------------------------------------------------- section 6
PROBES = {
    "cowell_dprkn12": ("leo_j2", "dprkn12", "cowell", None),
    "cowell_dop853_thrust": ("leo_thrust", "dop853", "cowell", None),
    "encke_dprkn12": ("leo_j2", "dprkn12", "encke", None),
    "cowell_dprkn12_stm": ("leo_j2", "dprkn12", "cowell", "variational"),
    "encke_rkn4_fracas": ("leo_j2", "rkn4", "encke", None),
}


def compile_probe(key):
    """Child process: time the first batch call (compile or cache load) of one program."""
    import heyoka_cases as hc

    name, method, formulation, sens = PROBES[key]
    case = hc.CASES[name]
    if method == "rkn4":
        m, p = fracas_problem(case, None, None, None, c_nom=0.3)
    else:
        m, p = fracas_problem(case, method, formulation, 1e-9)
    x0s = hc.initial_states(case, 64)
    kw = {"devices": host_devices()[:1]}
    if sens:
        kw.update(with_sensitivities=True, sensitivity_method=sens)
    t0 = time.perf_counter()
    out = propagate_batch(m, p, None, 0.0, x0s, np.array([0.0, 3600.0]), **kw)
    require(out, f"compile probe {key}", ok=(0,))
    print(json.dumps({"first_s": time.perf_counter() - t0}))


def compile_section():
    cache = tempfile.mkdtemp(prefix="fracas-bench-cache-")
    rows = []
    for key in PROBES:
        times = []
        for _ in range(2):  # cold, then from the persistent cache
            env = dict(os.environ, FRACAS_CACHE_DIR=cache)
            t0 = time.perf_counter()
            res = subprocess.run(
                [sys.executable, __file__, "--compile-probe", key, "--devices", "1"],
                env=env,
                capture_output=True,
                text=True,
                check=True,
            )
            wall = time.perf_counter() - t0
            times.append((json.loads(res.stdout.strip().splitlines()[-1])["first_s"], wall))
        rows.append([key, f"{times[0][0]:.1f}", f"{times[1][0]:.2f}", f"{times[0][1]:.1f}", f"{times[1][1]:.1f}"])
    table(
        ["program", "first call cold s", "from cache s", "process cold s", "process cached s"],
        rows,
        "Fresh processes with an empty, then the filled, persistent cache ($FRACAS_CACHE_DIR); 64 lanes.",
    )


# ------------------------------------------------------------------------- section 7
def ceiling_section(measured_rate_1dev, steps_per_prop):
    """What this CPU allows for a DPRKN12 LEO + J2 propagation, from rates measured here in
    XLA (not from data sheets): lane-divisions+square-roots and lane-FMAs per second on one
    core, against the counts one propagation needs."""
    import jax
    import jax.numpy as jnp

    from fracas.integrate.tableaux import DPRKN12 as tab

    n, k = 1024, 2000
    x0 = jnp.linspace(1.0, 2.0, n)

    @jax.jit
    def divsqrt(x):
        return jax.lax.fori_loop(0, k, lambda i, y: jnp.sqrt(1.0 / y) + 1.0, x)

    @jax.jit
    def fma(x):
        def body(i, ys):
            return tuple(y * 0.999 + 0.001 for y in ys)  # 8 independent chains: throughput, not latency

        return sum(jax.lax.fori_loop(0, k, body, tuple(x + j for j in range(8))))

    rates = {}
    for name, f, ops in (("div+sqrt", divsqrt, 1), ("fma", fma, 8)):
        f(x0).block_until_ready()
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            f(x0).block_until_ready()
            best = min(best, time.perf_counter() - t0)
        rates[name] = n * k * ops / best  # lane-operations per second (one core)
    nnz = lambda a: int(np.count_nonzero(a))  # noqa: E731
    stages = highorder.stages_per_step("dprkn12")
    couple = sum(nnz(tab.a_bar[i, :i]) for i in range(tab.stages))
    fma_step = 3 * (couple + 2 * tab.stages + nnz(tab.bbar) + nnz(tab.b) + nnz(tab.ebar) + nnz(tab.e))
    fma_step += stages * 12 + 30  # central + J2 per stage (~12 FMA-equivalents), error norm and control
    div_step = stages + 4  # one division and one square root per stage; error norm, control
    per_prop_div = div_step * steps_per_prop
    per_prop_fma = fma_step * steps_per_prop
    ceil_div = rates["div+sqrt"] / per_prop_div
    ceil_fma = rates["fma"] / per_prop_fma
    ceil = min(ceil_div, ceil_fma)
    try:
        ghz = max(float(ln.split(":")[1]) for ln in open("/proc/cpuinfo") if ln.startswith("cpu MHz")) / 1e3
    except (OSError, ValueError):
        ghz = float("nan")
    peak = ghz * 1e9 * 2 * 4  # lane-FMAs/s of two 256-bit FMA pipes (AVX2, float64)
    table(
        ["quantity", "value"],
        [
            ["lane div+sqrt pairs/s, one core (XLA, measured)", si(rates["div+sqrt"])],
            ["lane FMAs/s, one core (XLA, measured)", si(rates["fma"])],
            [f"per propagation ({steps_per_prop:.0f} steps): div+sqrt pairs", f"{per_prop_div:.0f}"],
            ["per propagation: FMAs (tableau couplings, weights, forces)", f"{per_prop_fma:.0f}"],
            ["ceiling from the divider, props/s per core", si(ceil_div)],
            ["ceiling from XLA's fused-kernel FMA rate, props/s per core", si(ceil_fma)],
            [f"hardware FMA peak ({ghz:.2f} GHz x 2 pipes x 4 lanes), props/s per core", si(peak / per_prop_fma)],
            ["measured / hardware FMA peak", f"{measured_rate_1dev / (peak / per_prop_fma):.0%}"],
            ["two cores (x2)", si(2 * ceil)],
            ["measured, one device", si(measured_rate_1dev)],
            ["measured / XLA one-core ceiling", f"{measured_rate_1dev / ceil:.0%}"],
        ],
        "Counts: DPRKN12's nonzero couplings and weights (3 components each), 12 FMA-equivalents per\n"
        "central + J2 evaluation, one division and one square root per stage; rates measured here.",
    )


def main():
    if ARGS.compile_probe:
        compile_probe(ARGS.compile_probe)
        return
    if ARGS.ceiling:
        emit("\n=== 7. The ceiling on this CPU (DPRKN12 Cowell, LEO + J2)")
        ceiling_section(*ARGS.ceiling)
        return
    import platform

    import heyoka as hy
    import jax

    devs = host_devices()
    quick = ARGS.quick
    emit(f"# benchmarks/bench_highorder.py{' --quick' if quick else ''}, {time.strftime('%Y-%m-%d %H:%M')}")
    emit(
        f"# jax {jax.__version__}, heyoka {hy.__version__}, {os.cpu_count()} CPUs ({platform.machine()}), "
        f"{len(devs)} host devices; load {os.getloadavg()[0]:.2f}"
    )
    emit("\n=== 1-2. Throughput at <= 1 m against heyoka (truth: heyoka long double)")
    n_big = 2000 if quick else 10_000
    n_small = 1000 if quick else 4000
    n_lanes = {"leo_j2": n_big, "eccentric": n_small, "leo_thrust": n_small, "spiral": 400 if quick else 1000}

    def methods_of(case):
        if case.thrust_kg_km_s2 > 0:
            return (("dop853", "cowell"), ("dop853", "encke"))
        rows = (("dprkn12", "cowell"), ("dprkn8", "cowell"), ("dop853", "cowell"), ("dprkn12", "encke"))
        return rows + ((("rkn4", "encke"),) if case.name == "leo_j2" else ())

    cases = ("leo_j2", "leo_thrust", "eccentric", "spiral")
    res = throughput(cases, n_lanes, methods_of, devs)
    emit("\n=== 3. STM (explicit variational equations / AD) against heyoka var_ode_sys")
    stm_section(500 if quick else 2000, devs)
    emit("\n=== 4. 300-day cruise, thrust and planets, against a scipy DOP853 loop")
    cruise_section(64 if quick else 256, 2, devs)
    emit("\n=== 5. Lane grouping and chunk size")
    grouping_section(2048 if quick else 8192, devs)
    emit("\n=== 6. Compile time per program")
    compile_section()
    emit("\n=== 7. The ceiling on this CPU (DPRKN12 Cowell, LEO + J2)")
    best = res.get(("leo_j2", "dprkn12", "cowell", 1))
    if best:
        ceiling_section(best["rate"], best["steps"])


if __name__ == "__main__":
    main_guard(main)
