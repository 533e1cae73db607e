"""fracas's batch propagator against heyoka per CPU-second, three LEO problems, one run.

    FRACAS_CACHE_DIR=/tmp/bench_cache .venv/bin/python benchmarks/bench_heyoka_ratio.py            # ~2 min (2 cores)
    FRACAS_CACHE_DIR=/tmp/bench_cache .venv/bin/python benchmarks/bench_heyoka_ratio.py --quick    # ~1 min
    .venv/bin/python benchmarks/bench_heyoka_ratio.py --ref HEAD   # fracas/ as committed, not the working tree's edits

Options: --quick (0.6 CPU-s fracas calls, 0.5 CPU-s heyoka, a 9-step tolerance ladder instead of 29,
one timed call instead of best of 2); --devices N (fracas host devices); --target-cpu-s S; --ref REF.

Problems (Earth point mass mu 398600.4418 km^3/s^2 + J2 1.08262668e-3, R 6378.137 km, pole +z;
1 day; benchmarks/heyoka_cases.py ``leo_j2`` and ``leo_thrust``):

  P1  LEO + J2, state only;
  P2  LEO + J2 with the 6x6 STM (fracas: ``propagate_batch(..., with_sensitivities=True)``,
      7x7 by the default "auto" method; heyoka: ``var_ode_sys`` order 1, 6x6);
  P3  LEO + J2 + 0.5 N along the velocity, 1000 kg, exhaust velocity 30 km/s, mass integrated.

Every lane is a distinct random LEO orbit (a 6800-7400 km, e < 0.01, i 0-100 deg, random RAAN,
argument of perigee and true anomaly, 1000 kg; seed 0), the same states for both sides.

Accuracy: the truth is heyoka's scalar integrator in long double (heyoka_cases.truth) for the
first 8 lanes; each side runs at the loosest tolerance of a ladder whose worst final position
error over those 8 lanes is <= 1 m, searched for each fracas method and for heyoka at batch 8;
heyoka's other batch sizes (and fast_math) start from the tolerance found at batch 8 and go on
down the ladder if it fails for them (heyoka's lanes step independently: the errors agree across
batch sizes).  The error of each timed run on the same 8 lanes is printed.

fracas: ``fracas.integrate.batch.propagate_batch`` with the settings a deck's defaults give
(Cowell, step_control "tolerance", no dt_max; DPRKN12 without thrust, DOP853 with thrust;
DPRKN8 as an extra P1 row), the library's default host devices (1 unless --devices), the
default chunking (1024 lanes a chunk, 256 with the STM) and lane grouping.

heyoka: ``taylor_adaptive_batch`` at batch sizes 1, 4 and 8 with default LLVM options, groups
of ``batch`` lanes set from Python (heyoka_cases.HeyokaBatch.run); one thread.  An extra row
(not in the goals) gives heyoka batch 8 with ``fast_math=True``.

Timing: ``time.process_time()`` (CPU seconds of the whole process: every thread, so it counts
both cores when XLA's runtime uses both) around warm calls, best of 2 (1 with --quick); wall
seconds beside it.  Lane counts are sized so that fracas's timed call takes >= 2.5 CPU-s
(0.6 with --quick), from a calibration call on one chunk; heyoka propagates the same states,
in as many passes over them as make >= 1.25 CPU-s (0.5 with --quick).
"first s": fracas's first call on one full chunk (trace + XLA compile or load from
$FRACAS_CACHE_DIR + one chunk's run); heyoka's cold LLVM compile (disk and memory caches off
for that construction) and its first run of one group.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import subprocess
import sys
import time
from pathlib import Path


def _args():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer lanes (0.6 CPU-s a call), a coarser tolerance ladder")
    ap.add_argument("--devices", type=int, default=None, help="fracas host devices (default: the library's, 1)")
    ap.add_argument("--target-cpu-s", type=float, default=None, help="CPU-s of fracas's timed call (default 2.5)")
    ap.add_argument(
        "--ref",
        default=None,
        help="benchmark fracas/ as committed at this git ref (git archive into a temporary directory, imported "
        "instead of the working tree; the working tree is not touched), e.g. HEAD while the core is being edited",
    )
    return ap.parse_args()


ARGS = _args()
if ARGS.devices:
    os.environ["FRACAS_HOST_DEVICES"] = str(ARGS.devices)
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
REF_DIR = None
if ARGS.ref:
    import atexit
    import shutil
    import tempfile

    REF_DIR = tempfile.mkdtemp(prefix="fracas-bench-ref-")
    atexit.register(shutil.rmtree, REF_DIR, True)
    _arch = subprocess.run(["git", "archive", ARGS.ref, "fracas"], cwd=ROOT, capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", REF_DIR], input=_arch, check=True)
    sys.path.insert(0, REF_DIR)  # before ROOT: this copy of fracas is imported

import fracas_cases  # noqa: E402
import heyoka as hy  # noqa: E402
import heyoka_cases as hc  # noqa: E402
import numpy as np  # noqa: E402
from runs import failure, main_guard, require  # noqa: E402
from tables import emit, si, table  # noqa: E402

from fracas.integrate.batch import auto_chunk_size, host_devices, propagate_batch  # noqa: E402

TARGET_M = 1.0
N_REF = 8  # lanes checked against the long-double truth
MAX_LANES = 1 << 17
HEYOKA_BATCHES = (1, 4, 8)
GOALS = {"P1": 3.0, "P2": 2.0, "P3": 1.0}
LADDER_FULL = (1e-6, 5e-7, 3e-7, 2e-7, 1e-7, 7e-8, 5e-8, 3e-8, 2e-8, 1.5e-8, 1e-8, 7e-9, 5e-9, 3e-9, 2e-9, 1.5e-9,
               1e-9, 7e-10, 5e-10, 3e-10, 2e-10, 1.5e-10, 1e-10, 5e-11, 2e-11, 1e-11, 3e-12, 1e-12, 1e-13)  # fmt: skip
LADDER_QUICK = (1e-7, 3e-8, 1e-8, 3e-9, 1e-9, 3e-10, 1e-10, 1e-11, 1e-12)


# ----------------------------------------------------------------------------- states
def leo_orbits(n: int, seed: int = 0) -> np.ndarray:
    """(n, 7) distinct random LEO states (km, km/s, kg): a U(6800, 7400) km, e U(0, 0.01),
    i U(0, 100) deg, RAAN, argument of perigee and true anomaly U(0, 2 pi), mass 1000 kg.
    Row k does not depend on n (rows are drawn in order from one generator)."""
    u = np.random.default_rng(seed).random((n, 6))
    a = 6800.0 + 600.0 * u[:, 0]
    e = 0.01 * u[:, 1]
    inc = np.radians(100.0 * u[:, 2])
    raan, argp, nu = (2 * np.pi * u[:, k] for k in (3, 4, 5))
    p = a * (1 - e * e)
    r = p / (1 + e * np.cos(nu))
    rp = np.stack([r * np.cos(nu), r * np.sin(nu), np.zeros(n)], 1)
    vp = np.sqrt(hc.MU_E / p)[:, None] * np.stack([-np.sin(nu), e + np.cos(nu), np.zeros(n)], 1)

    def rz(t):
        c, s, z, o = np.cos(t), np.sin(t), np.zeros_like(t), np.ones_like(t)
        return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)

    def rx(t):
        c, s, z, o = np.cos(t), np.sin(t), np.zeros_like(t), np.ones_like(t)
        return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)

    rot = rz(raan) @ rx(inc) @ rz(argp)
    pos = np.einsum("nij,nj->ni", rot, rp)
    vel = np.einsum("nij,nj->ni", rot, vp)
    return np.concatenate([pos, vel, np.full((n, 1), 1000.0)], 1)


# ----------------------------------------------------------------------------- fracas side
def fracas_problem(case, method, tol):
    """As a deck's defaults build it: Cowell, tolerance control, no dt_max (fracas_cases)."""
    return fracas_cases.fracas_problem(case, method, "cowell", tol)


def loosest(ladder, err_at):
    """(the first tolerance of ``ladder`` (loosest first) whose error is <= TARGET_M, or None;
    [(tol, error m)] tried)."""
    tried = []
    for t in ladder:
        tried.append((t, err_at(t)))
        if tried[-1][1] <= TARGET_M:
            return t, tried
    return None, tried


def _fracas_call(case, m, p, x0s, stm):
    kw = {"with_sensitivities": True} if stm else {}
    return propagate_batch(m, p, None, 0.0, x0s, np.array([0.0, case.t_final_s]), **kw)


def _traj(out):
    return out if hasattr(out, "x") else out[0]  # a Trajectory (a NamedTuple), or (Trajectory, Sensitivities)


def fracas_side(case, method, stm, pool, truth_ref, ladder, target_cpu_s, repeat):
    """Tolerance search on the reference lanes, calibration, timed calls.  Returns a dict."""
    ref = pool[:N_REF]

    def err_at(t):
        m, p = fracas_problem(case, method, t)
        tr = _traj(_fracas_call(case, m, p, ref, stm))
        return np.inf if failure(tr, ok=(0,)) else hc.pos_err_m(tr.x[:, -1, :6], truth_ref)  # failed: too large

    tol, tried = loosest(ladder, err_at)
    if tol is None:
        return {"tol": None, "tried": tried}
    m, p = fracas_problem(case, method, tol)
    chunk = auto_chunk_size(len(host_devices()), stm)
    c0, w0 = time.process_time(), time.perf_counter()
    _fracas_call(case, m, p, pool[:chunk], stm)  # first call on the chunk shape: compile or cache load
    first_s = time.perf_counter() - w0
    first_cpu = time.process_time() - c0
    c0 = time.process_time()
    _fracas_call(case, m, p, pool[chunk : 2 * chunk], stm)  # calibration: one warm chunk
    per_lane = max(time.process_time() - c0, 1e-3) / chunk
    n = min(MAX_LANES, max(2 * chunk, chunk * math.ceil(target_cpu_s / per_lane / chunk)))
    x0s = pool[:n]
    best = None
    for _ in range(repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        out = _fracas_call(case, m, p, x0s, stm)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        if best is None or cpu < best[0]:
            best = (cpu, wall)
    tr = require(_traj(out), f"fracas {case.name} {method} tol {tol:g}", ok=(0,))  # every timed lane
    res = {
        "tol": tol,
        "tried": tried,
        "n": n,
        "props": n,
        "err": hc.pos_err_m(tr.x[:N_REF, -1, :6], truth_ref),
        "cpu": best[0],
        "wall": best[1],
        "first_s": first_s,
        "first_cpu": first_cpu,
        "steps": float(np.mean(tr.n_steps)),
        "reject": float(np.mean(tr.n_reject)),
        "chunk": chunk,
    }
    if stm:
        res["stm"] = np.asarray(out[1].stm[:, -1, :6, :6])
    return res


# ----------------------------------------------------------------------------- heyoka side
class HB(hc.HeyokaBatch):
    """heyoka_cases.HeyokaBatch with extra keyword arguments for taylor_adaptive_batch (fast_math)."""

    def __init__(self, case, tol, batch, var=False, **kw):
        self.case, self.tol, self.var, self.fp_type = case, tol, var, float
        self.batch, self.nx = int(batch), case.nx
        t0 = time.perf_counter()
        odes = hc.make_odes(case, var=var)
        st0 = np.tile(np.asarray(case.x0[: self.nx], dtype=np.float64)[:, None], (1, self.batch))
        self.ta = hy.taylor_adaptive_batch(odes, st0, tol=tol, **kw)
        self.compile_s = time.perf_counter() - t0
        self.nstate = int(self.ta.state.shape[0])
        self.var0 = self.ta.state[self.nx :].copy() if var else None


def heyoka_side(case, var, batch, x0s, truth_ref, ladder, repeat, min_cpu_s, **kw):
    """Tolerance search (from the first entry of ``ladder``) on the reference lanes, a cold compile, timed passes.

    A timed measurement is as many passes over ``x0s`` as make >= ``min_cpu_s`` CPU-s (heyoka
    is often much faster than the fracas call that sized ``x0s``); best of ``repeat``."""
    ref = x0s[:N_REF]
    tol, tried = loosest(ladder, lambda t: hc.pos_err_m(HB(case, t, batch, var, **kw).run(ref)[0], truth_ref))
    if tol is None:
        return {"tol": None, "tried": tried}
    hc.set_cold(True)  # a cold LLVM compile for the "first s" column
    try:
        hb = HB(case, tol, batch, var, **kw)
    finally:
        hc.set_cold(False)
    w0 = time.perf_counter()
    hb.run(x0s[:batch])
    first_run = time.perf_counter() - w0
    n = x0s.shape[0]
    c0 = time.process_time()
    final, steps, _ = hb.run(x0s)
    passes = max(1, math.ceil(min_cpu_s / max(time.process_time() - c0, 1e-3)))
    best = None
    for _ in range(repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        for _ in range(passes):
            final, steps, _ = hb.run(x0s)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        if best is None or cpu < best[0]:
            best = (cpu, wall)
    res = {
        "tol": tol,
        "tried": tried,
        "n": n,
        "props": n * passes,
        "passes": passes,
        "err": hc.pos_err_m(final[:N_REF], truth_ref),
        "cpu": best[0],
        "wall": best[1],
        "compile_s": hb.compile_s,
        "first_run": first_run,
        "steps": steps / n,
        "order": hb.order,
    }
    if var:
        res["stm"] = hc.stm_of(final, hb.nx)[:, :6, :6]
    return res


# ----------------------------------------------------------------------------- output
def _git(*a):
    try:
        return subprocess.run(["git", *a], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "?"


def _cpu_model():
    try:
        for ln in open("/proc/cpuinfo"):
            if ln.startswith("model name"):
                return ln.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _fmt_tried(tried):
    return ", ".join(f"{t:g}: {e:.2g}" for t, e in tried)


PROBLEMS = (
    ("P1", "leo_j2", False, ("dprkn12", "dprkn8"), "LEO + J2, state"),
    ("P2", "leo_j2", True, ("dprkn12",), "LEO + J2 + 6x6 STM"),
    ("P3", "leo_thrust", False, ("dop853",), "LEO + J2 + 0.5 N along v, mass"),
)


def main():
    import jax

    quick = ARGS.quick
    ladder = LADDER_QUICK if quick else LADDER_FULL
    repeat = 1 if quick else 2
    target = ARGS.target_cpu_s or (0.6 if quick else 2.5)
    devs = host_devices()
    import fracas

    dirty = _git("status", "--porcelain", "--", "fracas")
    t_start = time.perf_counter()
    emit(f"# benchmarks/bench_heyoka_ratio.py{' --quick' if quick else ''}, {time.strftime('%Y-%m-%d %H:%M %Z')}")
    emit(
        f"# commit {_git('rev-parse', '--short', 'HEAD')} checked out; "
        f"fracas imported from {Path(fracas.__file__).parent}"
    )
    if ARGS.ref:
        emit(
            f"# fracas/ = git archive of --ref {ARGS.ref} ({_git('rev-parse', '--short', ARGS.ref)}); working-tree "
            "changes to fracas/ not used" + (f" (there were: {dirty.replace(chr(10), ' |')})" if dirty else "")
        )
    else:
        emit(
            "# fracas/ = the working tree" + (f"; uncommitted: {dirty.replace(chr(10), ' |')}" if dirty else ", clean")
        )
    emit(
        f"# jax {jax.__version__}, heyoka {hy.__version__} (recommended simd {hy.recommended_simd_size()}), "
        f"numpy {np.__version__}, python {platform.python_version()}"
    )
    emit(
        f"# {os.cpu_count()} CPUs ({_cpu_model()}), fracas host devices {len(devs)}; "
        f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}"
    )
    emit(f"# FRACAS_CACHE_DIR={os.environ.get('FRACAS_CACHE_DIR', '(default ~/.cache/fracas/jax)')}")
    emit(f"# truth: {hc.TRUTH_KIND}, first {N_REF} lanes; target <= {TARGET_M:g} m after 1 day")
    emit(f"# tolerance ladder ({len(ladder)}): {', '.join(f'{t:g}' for t in ladder)}")
    emit(f"# timed calls: best of {repeat} by CPU-s; fracas sized to >= {target:g} CPU-s a call")

    pool = leo_orbits(MAX_LANES, seed=0)
    summary = []
    extra_notes = []
    for pid, cname, var, methods, title in PROBLEMS:
        case = hc.CASES[cname]
        t0 = time.perf_counter()
        truth_ref = hc.truth(case, pool[:N_REF])[:, :6]
        t_truth = time.perf_counter() - t0
        emit(f"\n=== {pid}: {title} ({case.description}); truth {t_truth:.2f} s")
        rows = []
        fr = {}
        for method in methods:
            r = fracas_side(case, method, var, pool, truth_ref, ladder, target, repeat)
            fr[method] = r
            emit(f"  fracas {method} tolerances tried (tol: err m): {_fmt_tried(r['tried'])}")
            if r["tol"] is None:
                rows.append([f"fracas cowell {method}", "-", "> 1 m"] + ["-"] * 9)
                continue
            rows.append(
                [
                    f"fracas cowell {method}" + (" + STM (auto)" if var else ""),
                    f"{r['tol']:g}",
                    f"{r['err']:.3f}",
                    f"{r['n']:,}",
                    f"{r['steps']:.0f} (rej {r['reject']:.0f})",
                    f"{r['first_s']:.1f}",
                    f"{r['cpu']:.2f}",
                    f"{r['wall']:.2f}",
                    f"{r['cpu'] / r['wall']:.2f}",
                    si(r["props"] / r["cpu"]),
                    si(r["props"] / r["wall"]),
                ]
            )
        n = fr[methods[0]].get("n") or 8 * 1024
        x0s = pool[:n]
        hy_res = {}
        min_cpu = max(0.5, target / 2)
        # the ladder is searched at batch 8; the other batch sizes and fast_math start from the tolerance found there
        # (heyoka's lanes step independently, so the errors agree across batch sizes) and go on down if it fails
        hy_res[8] = heyoka_side(case, var, 8, x0s, truth_ref, ladder, repeat, min_cpu)
        sub = ladder[ladder.index(hy_res[8]["tol"]) :] if hy_res[8]["tol"] is not None else ladder
        for b in HEYOKA_BATCHES:
            if b != 8:
                hy_res[b] = heyoka_side(case, var, b, x0s, truth_ref, sub, repeat, min_cpu)
        hy_res["fm8"] = heyoka_side(case, var, 8, x0s, truth_ref, sub, repeat, min_cpu, fast_math=True)
        hy_res = {k: hy_res[k] for k in (*HEYOKA_BATCHES, "fm8")}
        for key, r in hy_res.items():
            label = f"heyoka batch {key}" if key != "fm8" else "heyoka batch 8 fast_math (extra)"
            label += " var_ode_sys" if var else ""
            emit(f"  {label} tolerances tried (tol: err m): {_fmt_tried(r['tried'])}")
            if r["tol"] is None:
                rows.append([label, "-", "> 1 m"] + ["-"] * 9)
                continue
            rows.append(
                [
                    f"{label} (order {r['order']})",
                    f"{r['tol']:g}",
                    f"{r['err']:.3f}",
                    f"{r['n']:,}" + (f" x{r['passes']}" if r["passes"] > 1 else ""),
                    f"{r['steps']:.0f}",
                    f"{r['compile_s']:.2f}+{r['first_run'] * 1e3:.1f}ms",
                    f"{r['cpu']:.2f}",
                    f"{r['wall']:.2f}",
                    f"{r['cpu'] / r['wall']:.2f}",
                    si(r["props"] / r["cpu"]),
                    si(r["props"] / r["wall"]),
                ]
            )
        table(
            [
                "method",
                "tol",
                "err m",
                "lanes",
                "steps/prop",
                "first s",
                "CPU s",
                "wall s",
                "cpu/wall",
                "props/CPU-s",
                "props/wall-s",
            ],  # fmt: skip
            rows,
            "err m: worst final position error of the timed run's first 8 lanes against the truth.  lanes xK: heyoka\n"
            "timed K passes over the same lanes (CPU s / wall s are for all K).  first s: fracas's first call on one\n"
            "chunk (compile or cache load + run); heyoka's cold LLVM compile + its first group's run.",
        )
        ok = [b for b in HEYOKA_BATCHES if hy_res[b]["tol"] is not None]
        best_b = max(ok, key=lambda b: hy_res[b]["props"] / hy_res[b]["cpu"]) if ok else None
        for method in methods:
            r = fr[method]
            if r["tol"] is None or best_b is None:
                summary.append([pid, f"fracas {method}", "-", "-", "-", "-", "-", "-"])
                continue
            h = hy_res[best_b]
            rate_f, rate_h = r["props"] / r["cpu"], h["props"] / h["cpu"]
            ratio = rate_f / rate_h
            wall_ratio = (r["props"] / r["wall"]) / (h["props"] / h["wall"])
            main = method == methods[0]
            goal = GOALS[pid] if main else None
            summary.append(
                [
                    pid + ("" if main else " (extra)"),
                    f"fracas {method} tol {r['tol']:g}",
                    si(rate_f),
                    f"{si(rate_h)} (batch {best_b}, tol {h['tol']:g})",
                    f"{ratio:.2f}",
                    f"{wall_ratio:.2f}",
                    f">= {goal:g}x" if goal else "-",
                    ("met" if ratio >= goal else "not met") if goal else "-",
                ]
            )
            fm = hy_res["fm8"]
            if main and fm["tol"] is not None:
                extra_notes.append(
                    f"{pid}: heyoka batch 8 fast_math {si(fm['props'] / fm['cpu'])}/CPU-s (tol {fm['tol']:g}); "
                    f"fracas {method} ÷ that = {rate_f / (fm['props'] / fm['cpu']):.2f}"
                )
        if var and fr[methods[0]].get("stm") is not None and best_b is not None:
            pf, ph = fr[methods[0]]["stm"], hy_res[best_b]["stm"]
            rel = np.linalg.norm(pf - ph, axis=(1, 2)) / np.linalg.norm(ph, axis=(1, 2))
            emit(f"STM agreement, fracas 7x7 (6x6 block) vs heyoka 6x6, all {pf.shape[0]:,} lanes: "
                 f"|dPhi|/|Phi| max {np.max(rel):.1e}, median {np.median(rel):.1e}")  # fmt: skip

    emit("\n=== Summary: propagations per CPU-second, fracas ÷ heyoka's best batch size")
    table(
        [
            "problem",
            "fracas",
            "fracas props/CPU-s",
            "heyoka best props/CPU-s",
            "ratio",
            "wall ratio",
            "goal",
            "status",
        ],  # fmt: skip
        summary,
        "CPU-s = time.process_time() of this process (all threads: fracas's count both cores when XLA runs its\n"
        "threads on both; heyoka runs on one thread).  wall ratio: the same with wall-clock seconds.\n"
        "heyoka's best is over batch sizes 1, 4, 8 with default LLVM options (fast_math not counted):\n  "
        + "\n  ".join(extra_notes),
    )
    emit(f"\n# total {time.perf_counter() - t_start:.0f} s; load average at the end "
         f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")  # fmt: skip


if __name__ == "__main__":
    main_guard(main)
