"""TOM (targeting and final-mass optimization): AD against FEGS sensitivities, cost split, GRID.

    .venv/bin/python benchmarks/bench_tom.py            # Lambert, Hohmann, the spiral (+ Earth-Mars if present)
    .venv/bin/python benchmarks/bench_tom.py --quick    # Lambert and Hohmann only

Sections:
  1. AD against FEGS per example deck: ``fracas.modes.tom.run_tom`` with ``sensitivities = "ad"``
     and ``"fegs"``; each cold run in a fresh process with its own empty FRACAS_CACHE_DIR (so
     both pay their own compile), then a warm second run in the same process; the issue's goal
     is AD >= 5x faster than FEGS (cold wall time, compile included);
  2. the per-iteration cost split of the warm AD run (``product.timing``);
  3. one sensitivity evaluation, warm: ``exact_sensitivities`` (AD) against ``fegs`` (M + 1
     trajectories) against one plain ``evaluate``;
  4. GRID throughput: ``evaluate_batch`` (one vmapped core call) against a Python loop of
     ``evaluate`` over the same control vectors, and their agreement.
Ratios are against a baseline measured in this run (the machine is shared).
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
    ap.add_argument(
        "--with-earth-mars",
        action="store_true",
        help="also the Earth-Mars deck (its AD program compiles for several minutes per fresh process)",
    )
    ap.add_argument("--devices", type=int, default=os.cpu_count() or 1, help="host devices for evaluate_batch")
    ap.add_argument("--one", nargs=2, metavar=("DECK", "METHOD"), help=argparse.SUPPRESS)  # internal: section 1
    return ap.parse_args()


ARGS = _args()
os.environ.setdefault("FRACAS_HOST_DEVICES", str(ARGS.devices))
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import numpy as np  # noqa: E402

DECKS = {
    "lambert": ROOT / "namelists" / "lambert_tom.toml",
    "hohmann": ROOT / "tests" / "data" / "hohmann_tom.toml",
    "spiral": ROOT / "namelists" / "near_earth_spiral_tom.toml",
    "earth_mars": ROOT / "namelists" / "earth_mars_tom.toml",
}
# GRID section: the two controls swept and their half-span in deck units
GRID_AXES = {"hohmann": ((0, 1), (0.02, 0.02)), "spiral": ((1, 2), (1.0, 1.0))}
GOAL = 5.0


# ----------------------------------------------------------------------------- output
from runs import RunFailed, main_guard, tom_failure  # noqa: E402
from tables import emit, si, table  # noqa: E402


def ms(s):
    return f"{s * 1e3:.3g}"


# ----------------------------------------------------------------------------- decks
def deck_cfg(name, method=None):
    from fracas.config.tom import parse_tom_deck

    path = DECKS[name]
    text = path.read_text()
    if method is not None:
        text = text.replace("[tom]\n", f'[tom]\nsensitivities = "{method}"\n', 1)
    return parse_tom_deck(text, str(path))


def one(name, method):
    """Internal (section 1): run_tom twice in this process, cold then warm; one JSON line.

    build_tom is wrapped (here only) to read the problem's own counters afterwards: every
    plain-core propagation (FEGS's included) and every AD sensitivity run."""
    import fracas.build.tom as build_mod
    from fracas.modes.tom import run_tom

    built = []
    orig = build_mod.build_tom

    def spy(cfg):
        case = orig(cfg)
        built.append(case)
        return case

    build_mod.build_tom = spy
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(2):
            cfg = deck_cfg(name, method)
            t0 = time.perf_counter()
            product, _, _ = run_tom(cfg, output=Path(tmp) / f"r{k}.txt", reference_deck=Path(tmp) / f"ref{k}.toml")
            wall = time.perf_counter() - t0
            prob = built[-1].problem
            runs.append(
                {
                    "wall_s": wall,
                    "timing": {k2: float(v) for k2, v in product.timing.items()},
                    "iterations": len(product.iteration),
                    "trajectories": int(product.n_trajectories[-1]) if len(product.n_trajectories) else 0,
                    "core_trajectories": int(prob.n_trajectories),
                    "ad_runs": int(prob.n_sensitivity_runs),
                    "converged": bool(product.converged),
                    "final_mass_kg": float(product.final_mass_kg),
                    "stop_reason": product.stop_reason,
                }
            )
    print("JSON " + json.dumps({"deck": name, "method": method, "runs": runs}), flush=True)


def run_fresh(name, method):
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, FRACAS_CACHE_DIR=cache)
        t0 = time.perf_counter()
        p = subprocess.run(
            [sys.executable, __file__, "--one", name, method, "--devices", str(ARGS.devices)],
            env=env,
            capture_output=True,
            text=True,
        )
        proc_s = time.perf_counter() - t0
    for ln in p.stdout.splitlines():
        if ln.startswith("JSON "):
            out = json.loads(ln[5:])
            out["process_s"] = proc_s
            return out
    raise RuntimeError(f"--one {name} {method} failed (rc {p.returncode}):\n{p.stderr[-3000:]}")


# ----------------------------------------------------------------------------- section 1-2
def section_ad_fegs(names):
    res = {}
    for name in names:
        for method in ("ad", "fegs"):
            emit(f"  ... {name} {method} (fresh process)")
            res[(name, method)] = run_fresh(name, method)
    rows, times, goal_rows, notes = [], [], [], []
    r3 = lambda x: f"{x:.3g}"  # noqa: E731
    for name in names:
        for method in ("ad", "fegs"):
            r = res[(name, method)]
            c, w = r["runs"]
            tc, tw = c["timing"], w["timing"]
            label = f"{name} {method.upper()}"
            rows.append(
                [
                    label,
                    c["iterations"],
                    c["trajectories"],
                    c["core_trajectories"],
                    c["ad_runs"],
                    "yes" if c["converged"] else "NO",
                    tom_failure(c["converged"], c["stop_reason"]) or f"{c['final_mass_kg']:.4f}",
                ]
            )
            times.append(
                [
                    label,
                    f"{c['wall_s']:.2f}",
                    f"{tc['setup_s']:.2f}",
                    f"{tc['search_s']:.3f}",
                    f"{tc['verification_s']:.2f}",
                    f"{w['wall_s']:.3f}",
                    f"{tw['search_s']:.3f}",
                    f"{r['process_s']:.1f}",
                ]
            )
            if not c["converged"]:
                notes.append(f"  {name} {method}: {c['stop_reason']}")
        a, f = res[(name, "ad")]["runs"], res[(name, "fegs")]["runs"]
        cold = f[0]["wall_s"] / a[0]["wall_s"]
        ex = lambda r: r["wall_s"] - r["timing"]["verification_s"]  # noqa: E731
        goal_rows.append(
            [
                name,
                r3(cold),
                r3(ex(f[0]) / ex(a[0])),
                r3(f[0]["timing"]["search_s"] / a[0]["timing"]["search_s"]),
                r3(f[1]["wall_s"] / a[1]["wall_s"]),
                r3(f[1]["timing"]["search_s"] / a[1]["timing"]["search_s"]),
                "met" if cold >= GOAL else "not met",
            ]
        )
    table(
        ["deck / method", "iter", "traj (search)", "traj (core)", "AD runs", "conv", "m_f kg"],
        rows,
        "Cold run. traj (search): product.n_trajectories[-1] (FEGS's difference runs not\n"
        "counted); traj (core): all plain-core propagations of the TomProblem (FEGS's and\n"
        "the verification's included); AD runs: exact-sensitivity propagations.",
    )
    for n in notes:
        emit(n)
    emit()
    table(
        ["deck / method", "cold s", "setup", "search", "verif", "warm s", "search", "process"],
        times,
        "cold: first run_tom in a fresh process, empty FRACAS_CACHE_DIR (compile counts);\n"
        "setup: build + starting trajectory; verif: re-propagation + S, G at the final\n"
        "controls (by the run's own method); warm: second run_tom, same process;\n"
        "process: the subprocess's wall time (imports, both runs). Seconds.",
    )
    emit()
    table(
        ["deck", "FEGS/AD cold", "excl. verif", "search", "warm", "search", f"AD >= {GOAL:g}x"],
        goal_rows,
        "Ratios: FEGS wall time over AD wall time (> 1: AD faster); the goal is judged on\n"
        "the cold total. excl. verif: cold total minus the verification.",
    )
    return res


def section_split(res, names):
    rows = []
    for name in names:
        w = res[(name, "ad")]["runs"][1]
        t, it = w["timing"], max(w["iterations"], 1)
        parts = [t["sensitivities_s"], t["line_search_s"], t["bookkeeping_s"]]
        tot = sum(parts) or float("nan")
        rows.append(
            [name, w["iterations"]]
            + [ms(p / it) for p in parts]
            + [f"{p / tot:.0%}" for p in parts]
            + [f"{t['verification_s']:.2f}"]
        )
    table(
        ["deck (AD, warm)", "iter", "sens ms", "line ms", "book ms", "sens", "line", "book", "verif s"],
        rows,
        "Per iteration (ms) and share of their sum; verif: verification (s).",
    )


# ----------------------------------------------------------------------------- section 3
def med_time(fn, u0, scale, n=5):
    """Median wall time of fn(u) over n calls, u perturbed each call (defeats the cache)."""
    fn(u0 + 0.5e-12 * scale)  # warm (compile)
    ts = []
    for k in range(n):
        u = u0 + (k + 1) * 1e-12 * scale
        t0 = time.perf_counter()
        fn(u)
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def section_one_sens(names):
    from fracas.build.tom import build_tom

    rows = []
    for name in names:
        case = build_tom(deck_cfg(name))
        prob = case.problem
        u0 = np.asarray(case.u0, float)
        scale = np.where(np.abs(u0) > 0, np.abs(u0), 1.0)
        if not prob.evaluate(u0).ok:  # the timed trajectory must reach its end (status checked by the problem)
            raise RunFailed(f"{name}: FAILED (the trajectory at the starting controls did not end as asked)")
        t_ev = med_time(prob.evaluate, u0, scale)
        t_ad = med_time(prob.exact_sensitivities, u0, scale)
        t_fd = med_time(prob.fegs, u0, scale)
        rows.append(
            [
                name,
                len(u0),
                ms(t_ev),
                ms(t_ad),
                ms(t_fd),
                f"{t_ad / t_ev:.2f}",
                f"{t_fd / t_ev:.2f}",
                f"{t_fd / t_ad:.2f}",
            ]
        )
    table(
        ["deck", "M", "eval ms", "AD ms", "FEGS ms", "AD/eval", "FEGS/eval", "FEGS/AD"],
        rows,
        "Warm, median of 5, u perturbed by 1e-12 relative each call. AD:\n"
        "exact_sensitivities (includes its own plain evaluation); FEGS: M + 1\n"
        "trajectories; eval: one trajectory.",
    )


# ----------------------------------------------------------------------------- section 4
def section_grid(names, n_side):
    from fracas.build.tom import build_tom

    rows, checks = [], []
    for name in names:
        case = build_tom(deck_cfg(name))
        prob = case.problem
        (a, b), (ha, hb) = GRID_AXES[name]
        fac = case.control_factor
        u0 = np.asarray(case.u0, float)
        ga = u0[a] + np.linspace(-ha, ha, n_side) * fac[a]
        gb = u0[b] + np.linspace(-hb, hb, n_side) * fac[b]
        us = np.repeat(u0[None, :], n_side * n_side, axis=0)
        us[:, a] = np.repeat(ga, n_side)
        us[:, b] = np.tile(gb, n_side)
        us = np.clip(us, case.lower, case.upper)
        k = len(us)
        prob.evaluate_batch(us)  # compile
        t0 = time.perf_counter()
        vb, mb, okb = prob.evaluate_batch(us)
        t_batch = time.perf_counter() - t0
        prob.evaluate(u0 * (1 + 1e-12))  # warm the plain core
        prob._cache.clear()
        t0 = time.perf_counter()
        evs = [prob.evaluate(u) for u in us]
        t_loop = time.perf_counter() - t0
        vl = np.array([e.targets for e in evs])
        ml = np.array([e.performance for e in evs])
        okl = np.array([e.ok for e in evs])
        both = okb & okl
        dt = np.max(np.abs(vb[both] - vl[both]) / prob.targets.tolerance) if both.any() else float("nan")
        dm = np.max(np.abs(mb[both] - ml[both])) if both.any() else float("nan")
        rows.append(
            [
                name,
                k,
                f"{t_batch:.2f}",
                si(k / t_batch),
                f"{t_loop:.2f}",
                si(k / t_loop),
                f"{t_loop / t_batch:.2f}",
            ]
        )
        checks.append([name, k, int(okb.sum()), int(okl.sum()), int((okb != okl).sum()), f"{dt:.2e}", f"{dm:.2e}"])
    table(
        ["deck", "K", "batch s", "traj/s", "loop s", "traj/s", "loop/batch"],
        rows,
        f"Warm (second batch call; loop with the cache cleared); {ARGS.devices} host devices\n"
        f"for the batch; K = {n_side} x {n_side} over two controls (hohmann: dv0 along and\n"
        "radial +-0.02 km/s; spiral: both yaw angles +-1 deg).",
    )
    emit()
    table(
        ["deck", "K", "ok batch", "ok loop", "ok differ", "max|dT|/tol", "max|dm| (can)"],
        checks,
        "Agreement of the batch with the loop on lanes ok in both: targets in\n"
        "tolerances, final mass in canonical units.",
    )


# ----------------------------------------------------------------------------- main
def main():
    if ARGS.one:
        one(*ARGS.one)
        return
    import platform

    import jax

    quick = ARGS.quick
    names = ["lambert", "hohmann"]
    if not quick:
        names.append("spiral")
        if ARGS.with_earth_mars and DECKS["earth_mars"].exists():
            names.append("earth_mars")
    t_start = time.perf_counter()
    emit(f"# benchmarks/bench_tom.py{' --quick' if quick else ''}, {time.strftime('%Y-%m-%d %H:%M')}")
    emit(
        f"# jax {jax.__version__}, {os.cpu_count()} CPUs ({platform.machine()}, {platform.processor() or '?'}), "
        f"load {os.getloadavg()[0]:.2f}"
    )
    emit("# section 1: every cold run in a fresh process with an empty temporary")
    emit("# FRACAS_CACHE_DIR, so the persistent compilation cache hides no compile time;")
    emit("# sections 2-4 in this process (warm)")
    emit(f"# decks: {', '.join(names)}")

    emit("\n=== 1. AD against FEGS sensitivities, run_tom per example deck")
    res = section_ad_fegs(names)
    emit("\n=== 2. Per-iteration cost split (warm AD run)")
    section_split(res, names)
    emit("\n=== 3. One sensitivity evaluation (warm)")
    section_one_sens(names)
    emit("\n=== 4. GRID throughput: evaluate_batch against a loop of evaluate")
    section_grid(["hohmann"] if quick else ["hohmann", "spiral"], 9 if quick else 25)
    emit(f"\n# total {time.perf_counter() - t_start:.0f} s")


if __name__ == "__main__":
    main_guard(main)
