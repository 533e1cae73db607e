"""Benchmarks of the fracas trajectory core (Encke/Nystrom propagation, batches, STMs) on CPU.

    .venv/bin/python benchmarks/bench_core.py            # full run (< 15 min on 2 cores)
    .venv/bin/python benchmarks/bench_core.py --quick    # small sizes, preset step settings (< 2 min)

Two problems: LEO (1 day, Earth point mass + J2) and a 300-day heliocentric solar-electric
cruise (Sun primary; Venus, Earth, Mars, Jupiter perturbing; two thrust arcs, thrust in the
velocity frame).  Accuracy is always the final position error against scipy DOP853 at
rtol 1e-13 (Cowell, tests/reference.py right-hand side, DE421 via jplephem).

Sections: (1) references; (2) step settings for <= 1 m; (3) compile and warm single
propagations; (4) batches of LEO and cruise propagations with ``propagate_batch`` (with and
without the 7x7 STM) on one host device; (5) the same batches sharded over all host
devices; (6) baselines: scipy DOP853, heyoka ``taylor_adaptive_batch`` (batch 8) and
heyoka ``var_ode_sys`` (order-1 variational equations) for the STM; (7) Encke vs a plain
Cowell RKN4 (same Nystrom scheme and step rule, written below) at equal accuracy.

Host devices: the script puts ``--xla_force_host_platform_device_count=N`` (``--devices``,
default 2) into ``XLA_FLAGS`` before jax is imported, unless XLA_FLAGS already sets it.
Single-device rows pass ``devices=host_devices()[:1]``.  Compile times: unless
``--keep-cache`` (implied by ``--quick``), the persistent compilation cache is pointed at a
fresh empty directory, so "first call" times are cold compiles.  See benchmarks/README.md.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path


def _parse_args():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes and preset step settings (< 2 min)")
    ap.add_argument("--devices", type=int, default=2, help="host devices to force via XLA_FLAGS (default 2)")
    ap.add_argument(
        "--keep-cache",
        action="store_true",
        help="use the persistent compilation cache (first-call times are then cache loads)",
    )
    ap.add_argument(
        "--stm-10k",
        action="store_true",
        help="run the 10,000-propagation LEO STM batch instead of extrapolating it from 1,000",
    )
    ap.add_argument("--no-heyoka", action="store_true", help="skip the heyoka baselines")
    ap.add_argument("--repeat", type=int, default=None, help="repeats of the short timings (default 5, quick 3)")
    return ap.parse_args()


ARGS = _parse_args()
os.environ.pop("FRACAS_HOST_DEVICES", None)  # --devices (or a count already in XLA_FLAGS) decides
_flags = os.environ.get("XLA_FLAGS", "")
if "xla_force_host_platform_device_count" not in _flags:
    os.environ["XLA_FLAGS"] = f"{_flags} --xla_force_host_platform_device_count={ARGS.devices}".strip()
if not (ARGS.keep_cache or ARGS.quick):
    os.environ["FRACAS_CACHE_DIR"] = tempfile.mkdtemp(prefix="fracas-bench-jax-")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

T_START = time.perf_counter()

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from runs import FailedFigure, RunFailed, failure, heyoka_failure, main_guard, require  # noqa: E402

import tests.reference as ref  # noqa: E402
from fracas import _jax  # noqa: E402,F401
from fracas.dynamics import forces  # noqa: E402
from fracas.dynamics.model import ForceModel, IntegratorSettings, default_params  # noqa: E402
from fracas.integrate import encke  # noqa: E402
from fracas.integrate.batch import host_devices, propagate_batch  # noqa: E402
from fracas.integrate.propagate import propagate, propagate_with_sensitivities  # noqa: E402

QUICK = ARGS.quick
REPEAT = ARGS.repeat or (3 if QUICK else 5)
DAY = 86400.0
TARGET_M = 1.0  # accuracy target of the batch rows (final position error, m)


# =============================================================================== output
def banner(title: str) -> None:
    print(f"\n=== {title} " + "=" * max(0, 86 - len(title)), flush=True)


def table(headers, rows, note: str | None = None) -> None:
    cells = [[str(h) for h in headers]] + [[c if isinstance(c, str) else f"{c}" for c in r] for r in rows]
    w = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    fmt = lambda r: "  ".join(c.ljust(w[i]) if i == 0 else c.rjust(w[i]) for i, c in enumerate(r))  # noqa: E731
    print(fmt(cells[0]))
    print("  ".join("-" * x for x in w))
    for r in cells[1:]:
        print(fmt(r))
    if note:
        print(note)
    sys.stdout.flush()


def si(x: float, unit: str = "") -> str:
    """3 significant digits with k/M/G suffix."""
    if x is None or not math.isfinite(x):
        return "-"
    for f, s in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if abs(x) >= f:
            return f"{x / f:.3g}{s}{unit}"
    return f"{x:.3g}{unit}"


def fs(t: float) -> str:
    """Seconds, human scale."""
    if t is None or not math.isfinite(t):
        return "-"
    if t < 1e-3:
        return f"{t * 1e6:.0f} us"
    if t < 1.0:
        return f"{t * 1e3:.1f} ms"
    return f"{t:.2f} s"


def fm(e_km: float) -> str:
    """Error in m (given km); the FAILED text for the figure of a failed run (runs.FailedFigure)."""
    if isinstance(e_km, FailedFigure):
        return e_km.text
    if e_km is None or not math.isfinite(e_km):
        return "nan"
    m = e_km * 1e3
    return f"{m:.3g} m" if m < 1e3 else f"{m / 1e3:.3g} km"


def timed(fn, repeat: int):
    """(last output, best s, median s, cpu/wall) over ``repeat`` calls (outputs blocked on)."""
    ts, cpu = [], []
    out = None
    for _ in range(repeat):
        c0, t0 = time.process_time(), time.perf_counter()
        out = fn()
        jax.block_until_ready(out)
        dt = time.perf_counter() - t0
        ts.append(dt)
        cpu.append((time.process_time() - c0) / dt)
    return out, min(ts), statistics.median(ts), statistics.median(cpu)


def first_call(fn):
    t0 = time.perf_counter()
    out = fn()
    jax.block_until_ready(out)
    return out, time.perf_counter() - t0


def git_state() -> str:
    """Commit of the tree and the core files modified in the working tree (others edit it too)."""
    import subprocess

    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True, timeout=10
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "fracas"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.split("\n")
        dirty = [ln[3:] for ln in dirty if ln.strip()]
        return f"commit {head}" + (f" + uncommitted changes in {', '.join(dirty)}" if dirty else " (clean)")
    except (OSError, subprocess.SubprocessError):  # pragma: no cover
        return "git state unknown"


def loadavg() -> str:
    try:
        return "/".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:  # pragma: no cover
        return "?"


# ============================================================================ problems
MU_E, J2_E, R_E = 398600.4418, 1.08262668e-3, 6378.137
POLE_E = np.array([0.0, 0.0, 1.0])
LEO_X0 = np.array([7000.0, 0.0, 0.0, 0.0, 7.5, 1.0, 1000.0])
LEO_T = np.array([0.0, DAY])


def leo_model(c_nom: float) -> ForceModel:
    return ForceModel(bodies=("earth",), j2=True, integrator=IntegratorSettings(c_nom=c_nom, dt_max_s=4000.0))


LEO_P = default_params(leo_model(0.05), mu=[MU_E], j2=[J2_E], radius=[R_E], pole=[POLE_E])


def leo_states(n: int, seed: int = 0) -> np.ndarray:
    """Row 0 the nominal state; then a in [6800, 7400] km, e < 0.01, i < 100 deg, random angles."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(6800.0, 7400.0, n)
    e = rng.uniform(0.0, 0.01, n)
    inc = np.radians(rng.uniform(0.0, 100.0, n))
    raan, argp, nu = (rng.uniform(0.0, 2 * np.pi, n) for _ in range(3))
    p = a * (1 - e * e)
    r = p / (1 + e * np.cos(nu))
    rp = np.stack([r * np.cos(nu), r * np.sin(nu), np.zeros(n)], 1)
    vp = np.sqrt(MU_E / p)[:, None] * np.stack([-np.sin(nu), e + np.cos(nu), np.zeros(n)], 1)

    def rz(t):
        c, s = np.cos(t), np.sin(t)
        z, o = np.zeros_like(t), np.ones_like(t)
        return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)

    def rx(t):
        c, s = np.cos(t), np.sin(t)
        z, o = np.zeros_like(t), np.ones_like(t)
        return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)

    rot = rz(raan) @ rx(inc) @ rz(argp)
    x = np.concatenate([np.einsum("nij,nj->ni", rot, rp), np.einsum("nij,nj->ni", rot, vp), np.full((n, 1), 1000.0)], 1)
    x[0] = LEO_X0
    return x


from cruise_case import (  # noqa: E402  (benchmarks/: the shared cruise problem)
    CR_BREAKS,
    CR_EPH,
    CR_ET0,
    CR_P,
    CR_T,
    _cruise_rhs,
    cruise_model,
    cruise_states,
    dop853,
)


def _leo_rhs():
    return ref.cowell_rhs_factory(MU_E, "earth", (), None, j2=(J2_E, R_E, POLE_E))


def pos_err(x, xref) -> float:
    """Largest final position error (km) over rows."""
    x = np.atleast_2d(np.asarray(x))[:, :3]
    xref = np.atleast_2d(np.asarray(xref))[:, :3]
    return float(np.max(np.linalg.norm(x - xref, axis=1)))


# ====================================================================== Cowell RKN4 (JAX)
@jax.jit
def _noop(x):
    return x


def _cowell(model: ForceModel, params, ephem, epoch_et, x0, t_end, c_nom, dt_max, max_steps=2_000_000):
    """Plain Cowell with the Nystrom RKN4 of encke._nystrom_step and the same step rule:
    dt = min(c_nom |r|^1.5/sqrt(mu), dt_max, time to the next thrust switch or t_end)
    (|r| instead of the conic radius).  Forward in time only; returns (x_end, n_steps)."""
    mu = params.mu[model.primary]
    p = model.primary
    breaks = jnp.concatenate([params.arc_t_on, params.arc_t_off])
    eps_t = model.integrator.eps_t_s

    def acc(t, r, v, m, ctl):
        pos, _ = encke.body_states(model, params, ephem, epoch_et + t)
        a, f, md = encke.perturbation(model, params, t, r, v, p, pos, ctl)
        return forces.point_mass_accel(r, mu) + a + f / m, f, md

    def cond(s):
        t, _, _, _, n = s
        return (t_end - t > eps_t) & (n < max_steps)

    def body(s):
        t, r, v, m, n = s
        rn = jnp.linalg.norm(r)
        dt_nom = c_nom * rn * jnp.sqrt(rn / mu)
        t_brk = jnp.concatenate([jnp.where(breaks - t > eps_t, breaks, t_end), t_end[None]])
        dt = jnp.minimum(jnp.minimum(jnp.min(t_brk) - t, dt_nom), dt_max)
        ctl = encke.step_controls(model, params, t + 0.5 * dt)
        h = 0.5 * dt
        k1, _, md1 = acc(t, r, v, m, ctl)
        r_b = r + v * h + k1 * (dt * dt / 8.0)
        v_b = v + k1 * h
        m_b = m + md1 * h
        k2, f2, md2 = acc(t + h, r_b, v_b, m_b, ctl)
        m_c = m + md2 * h
        if model.velocity_dependent:
            k3, _, md3 = acc(t + h, r_b, v + k2 * h, m_c, ctl)
        else:
            k3, md3 = k2 + f2 * (1.0 / m_c - 1.0 / m_b), md2
        r_c = r + v * dt + k3 * (0.5 * dt * dt)
        k4, _, md4 = acc(t + dt, r_c, v + k3 * dt, m + md3 * dt, ctl)
        r1 = r + v * dt + (k1 + k2 + k3) * (dt * dt / 6.0)
        v1 = v + (k1 + 2.0 * k2 + 2.0 * k3 + k4) * (dt / 6.0)
        m1 = m + (md1 + 2.0 * md2 + 2.0 * md3 + md4) * (dt / 6.0)
        return t + dt, r1, v1, m1, n + 1

    x0 = jnp.asarray(x0)
    s = (jnp.zeros(()), x0[:3], x0[3:6], x0[6], jnp.zeros((), jnp.int32))
    t, r, v, m, n = jax.lax.while_loop(cond, body, s)
    return jnp.concatenate([r, v, m[None]]), n


def cowell_failure(xe, n, max_steps=2_000_000) -> str | None:
    """The plain Cowell loop has no status: a lane that used every step or went non-finite failed."""
    n, xe = np.atleast_1d(np.asarray(n)), np.atleast_2d(np.asarray(xe))
    codes = np.where(~np.all(np.isfinite(xe), axis=1), 3, np.where(n >= max_steps, 2, 0))
    return failure(codes, ok=(0,))


cowell_single = jax.jit(_cowell, static_argnums=(0,))
cowell_many = jax.jit(jax.vmap(_cowell, in_axes=(None, None, None, None, 0, None, None, None)), static_argnums=(0,))


# ============================================================================== tuning
def round2(x: float) -> float:
    return float(f"{x:.2g}")


def tune_step(err_fn, h0: float, target: float, order: float = 4.0, max_evals: int = 6, aim: float = 0.6):
    """Largest step-like setting h (error grows ~ h^order) with err_fn(h) <= target.

    Power-law steps toward ``aim * target``, values rounded to 2 significant digits.
    Returns (h, err) of the largest passing h (or the smallest tried if none passed) and the
    list of (h, err) tried.
    """
    tried: list[tuple[float, float]] = []
    h = round2(h0)
    for _ in range(max_evals):
        e = err_fn(h)
        tried.append((h, e))
        ok = [(hh, ee) for hh, ee in tried if ee <= target]
        bad = [hh for hh, ee in tried if not ee <= target]
        if ok and max(ok)[1] > 0.15 * target:
            break
        if not math.isfinite(e) or e <= 0.0:
            fac = 0.5 if not math.isfinite(e) else 4.0
        else:
            fac = min(max((aim * target / e) ** (1.0 / order), 0.25), 4.0)
        h_new = round2(h * fac)
        if bad and h_new >= min(bad):
            h_new = round2(0.5 * (max(ok)[0] if ok else h) + 0.5 * min(bad)) if ok else round2(min(bad) * 0.7)
        if any(abs(h_new - hh) <= 1e-12 * hh for hh, _ in tried):
            break
        h = h_new
    ok = [(hh, ee) for hh, ee in tried if ee <= target]
    best = max(ok) if ok else min(tried)
    return best, tried


def tune_tol(err_fn, tols, target: float):
    """First tolerance of ``tols`` (loose to tight) with err_fn(tol) <= target."""
    tried = []
    for tol in tols:
        e = err_fn(tol)
        tried.append((tol, e))
        if e <= target:
            return (tol, e), tried
    return tried[-1], tried


def fmt_tried(tried, unit_fmt=lambda h: f"{h:g}") -> str:
    return ", ".join(f"{unit_fmt(h)}: {fm(e)}" for h, e in tried)


# ================================================================================ main
def main() -> None:  # noqa: C901 - a linear script
    devs = host_devices()
    one_dev = devs[:1]
    n_ref_leo = 2 if QUICK else 8
    n_ref_cr = 1 if QUICK else 2
    leo_sizes = (100, 1000) if QUICK else (1000, 10_000)
    leo_chunk = 100 if QUICK else 1000  # one executable per chunk shape: every LEO batch reuses it
    leo_stm_n = 32 if QUICK else 1000
    cr_sizes = (8, 32) if QUICK else (64, 512)
    cr_chunk = 8 if QUICK else 64
    cr_stm_n = 0 if QUICK else 32
    dop_loop_leo = 3 if QUICK else 20
    dop_loop_cr = 1 if QUICK else 2

    try:
        cpu = next(ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name"))
    except (OSError, StopIteration):
        cpu = platform.processor()
    try:
        import heyoka as hy

        hy_version = hy.__version__
    except ImportError:
        hy = None
        hy_version = None
    if ARGS.no_heyoka:
        hy = None

    banner("fracas core benchmark" + (" (--quick)" if QUICK else ""))
    print(f"date {time.strftime('%Y-%m-%d %H:%M:%S')}  host {platform.node()}  python {platform.python_version()}")
    print(f"cpu: {cpu}; os.cpu_count() = {os.cpu_count()}; load average at start {loadavg()}")
    print(
        f"jax {jax.__version__}, backend {jax.default_backend()}, devices {len(devs)} "
        f"({', '.join(str(d) for d in devs)}); XLA_FLAGS='{os.environ.get('XLA_FLAGS', '')}'"
    )
    print(
        f"heyoka {hy_version if hy_version else 'not installed'}"
        + (f" (recommended SIMD batch size {hy.recommended_simd_size()})" if hy else "")
    )
    print(f"fracas: {git_state()}")
    print(
        f"compilation cache: {os.environ.get('FRACAS_CACHE_DIR', '~/.cache/fracas/jax (persistent)')}; "
        f"timings: best and median of {REPEAT} unless stated; wall-clock, one process"
    )

    # ------------------------------------------------------------------ 1. references
    banner("1. References: scipy DOP853 rtol 1e-13, atol 1e-12 (Cowell, tests/reference.py RHS)")
    x_leo_big = leo_states(max(leo_sizes))
    x_cr_big = cruise_states(max(cr_sizes))
    leo_rhs, cr_rhs = _leo_rhs(), _cruise_rhs()
    t0 = time.perf_counter()
    ref_leo = [dop853(leo_rhs, x, LEO_T, 1e-13, 1e-12) for x in x_leo_big[:n_ref_leo]]
    t_ref_leo = (time.perf_counter() - t0) / n_ref_leo
    t0 = time.perf_counter()
    ref_cr = [dop853(cr_rhs, x, CR_BREAKS, 1e-13, 1e-12) for x in x_cr_big[:n_ref_cr]]
    t_ref_cr = (time.perf_counter() - t0) / n_ref_cr
    y_leo = np.array([r[0] for r in ref_leo])
    y_cr = np.array([r[0] for r in ref_cr])
    rows = [
        ["LEO 1 day", n_ref_leo, f"{np.mean([r[1] for r in ref_leo]):.0f}", fs(t_ref_leo)],
        ["cruise 300 d", n_ref_cr, f"{np.mean([r[1] for r in ref_cr]):.0f}", fs(t_ref_cr)],
    ]
    if not QUICK:
        u_leo = pos_err(dop853(leo_rhs, x_leo_big[0], LEO_T, 1e-12, 1e-12)[0], y_leo[0])
        u_cr = pos_err(dop853(cr_rhs, x_cr_big[0], CR_BREAKS, 1e-12, 1e-12)[0], y_cr[0])
        rows[0].append(fm(u_leo))
        rows[1].append(fm(u_cr))
    table(
        ["problem", "states", "steps", "time/prop"] + ([] if QUICK else ["|rtol 1e-12 - 1e-13|"]),
        rows,
        "Accuracy below = max final position error over these reference states (row 0 = nominal).\n"
        "The cruise RHS uses a two-part Julian date (see helio_position_2part): with the one-part JD of\n"
        "tests/reference.py the reference itself is off by ~12 m after 300 days.",
    )

    # --------------------------------------------------------------- 2. step settings
    banner(f"2. Encke step settings for <= {TARGET_M:g} m (error vs the references)")
    # first call of propagate per problem: the cold compile.  The core traces the integrator
    # constants (propagate.split_model), so models that differ only in IntegratorSettings share
    # one executable (propagate_batch does the same).
    singles: dict = {}

    def encke_err(model, params, eph, epoch, xs, t, yref):
        out = []
        key = model.bodies
        for x in xs:
            if key not in singles:
                _, tc = first_call(lambda: propagate(model, params, eph, epoch, x, t))
                singles[key] = (tc, model.integrator)
            tr = propagate(model, params, eph, epoch, x, t)
            f = failure(tr, ok=(0,))
            if f:  # no distance to an abort point: the setting fails the target
                return FailedFigure(f)
            out.append(np.asarray(tr.x_final))
        return pos_err(np.array(out), yref)

    leo_err = lambda c: encke_err(leo_model(c), LEO_P, None, 0.0, x_leo_big[:n_ref_leo], LEO_T, y_leo)  # noqa: E731
    cr_err = lambda d: encke_err(cruise_model(d), CR_P, CR_EPH, CR_ET0, x_cr_big[:n_ref_cr], CR_T, y_cr)  # noqa: E731
    if QUICK:  # settings found by the full run
        c_leo, d_cr = 0.036, 0.12
        e_leo, e_cr = leo_err(c_leo), cr_err(d_cr)
        tried_leo = [(c_leo, e_leo)]
        tried_cr = [(d_cr, e_cr)]
    else:
        (c_leo, e_leo), tried_leo = tune_step(leo_err, 0.05, TARGET_M * 1e-3)
        (d_cr, e_cr), tried_cr = tune_step(cr_err, 0.25, TARGET_M * 1e-3)
    table(
        ["problem", "setting", "error", "tried"],
        [
            ["LEO", f"c_nom {c_leo:g} (dt_max 4000 s)", fm(e_leo), fmt_tried(tried_leo)],
            ["cruise", f"dt_max {d_cr:g} d (c_nom 0.05)", fm(e_cr), fmt_tried(tried_cr, lambda h: f"{h:g} d")],
        ],
        "In the cruise the step is set by dt_max: c_nom r^1.5/sqrt(mu_sun) at 1 AU is c_nom x 58 days."
        + ("  (--quick: preset settings, no tuning)" if QUICK else ""),
    )
    m_leo, m_cr = leo_model(c_leo), cruise_model(d_cr)

    # ------------------------------------------------------- 3. compile and single runs
    banner("3. Compile (first call) and warm single propagations (jit, one device)")
    rows = []
    x0l, x0c = x_leo_big[0], x_cr_big[0]
    tr, best, med, _ = timed(lambda: propagate(m_leo, LEO_P, None, 0.0, x0l, LEO_T), REPEAT)
    require(tr, f"LEO 1 d, c_nom {c_leo:g}", ok=(0,))
    n = int(tr.n_steps)
    rows.append(["LEO 1 d, propagate", fs(singles[m_leo.bodies][0]), fs(best), fs(med), n, f"{best / n * 1e6:.1f}"])
    if not QUICK:
        _, tc = first_call(lambda: propagate_with_sensitivities(m_leo, LEO_P, None, 0.0, x0l, LEO_T))
        out, best, med, _ = timed(lambda: propagate_with_sensitivities(m_leo, LEO_P, None, 0.0, x0l, LEO_T), REPEAT)
        require(out, f"LEO 1 d + STM, c_nom {c_leo:g}", ok=(0,))
        rows.append(["LEO 1 d, + 7x7 STM (jacfwd)", fs(tc), fs(best), fs(med), n, f"{best / n * 1e6:.1f}"])
    tr, best, med, _ = timed(lambda: propagate(m_cr, CR_P, CR_EPH, CR_ET0, x0c, CR_T), REPEAT)
    require(tr, f"cruise 300 d, dt_max {d_cr:g} d", ok=(0,))
    n = int(tr.n_steps)
    rows.append(["cruise 300 d, propagate", fs(singles[m_cr.bodies][0]), fs(best), fs(med), n, f"{best / n * 1e6:.1f}"])
    table(
        ["case", "first call", "warm best", "warm median", "steps", "us/step"],
        rows,
        f"LEO c_nom {c_leo:g}; cruise dt_max {d_cr:g} d.  First call = trace + XLA compile + one run"
        + (" (persistent cache may be warm: --quick)" if (QUICK or ARGS.keep_cache) else " (cold cache)")
        + f",\nat the first setting tried (LEO c_nom {singles[m_leo.bodies][1].c_nom:g}, cruise dt_max "
        f"{singles[m_cr.bodies][1].dt_max_s / DAY:g} d): later settings reuse the executable (the core\n"
        "traces c_nom, dt_max, rect_ratio ... as arguments: propagate.split_model).",
    )

    # ------------------------------------------------------------------- 4. batches
    banner("4. Batches with propagate_batch (vmap; one host device)")
    batch_results = {}

    def run_batch(label, model, params, eph, epoch, xs, t, chunk, sens, devices, repeat, yref, n_ref):
        def fn(tt=t):
            return propagate_batch(
                model, params, eph, epoch, xs, tt, chunk_size=chunk, with_sensitivities=sens, devices=devices
            )

        # compile: the same chunk program on a zero-length span (every lane is done at once)
        _, tcomp = first_call(lambda: fn(np.zeros_like(t)))
        out, best, med, cpu = timed(fn, repeat)
        tr = out[0] if sens else out
        n = xs.shape[0]
        steps = tr.n_steps.astype(float)
        rows_c = [steps[i : i + chunk] for i in range(0, n, chunk)]
        eff = sum(r.sum() for r in rows_c) / sum(len(r) * r.max() for r in rows_c)
        fail = failure(tr, ok=(0,))  # any lane short of the final time: no time, rate or error for the row
        err = FailedFigure(fail) if fail else pos_err(tr.x_final[:n_ref], yref)
        res = {
            "fail": fail,
            "label": label,
            "n": n,
            "chunk": chunk,
            "tcomp": tcomp,
            "best": best,
            "med": med,
            "cpu": cpu,
            "steps": steps.sum(),
            "eff": eff,
            "err": err,
            "out": out,
            "ndev": len(devices),
            "repeat": repeat,
        }
        batch_results[(label, len(devices), n)] = res
        return res

    def batch_row(r, extrapolate_to=None):
        scale = 1.0 if extrapolate_to is None else extrapolate_to / r["n"]
        n = r["n"] if extrapolate_to is None else extrapolate_to
        best, med = r["best"] * scale, r["med"] * scale
        if r["fail"]:
            return [r["label"], f"{n:,}", f"{r['chunk']}x{r['ndev']}", r["fail"]] + [""] * 7
        return [
            r["label"] + (" (extrapolated)" if extrapolate_to else ""),
            f"{n:,}",
            f"{r['chunk']}x{r['ndev']}",
            fs(r["tcomp"]) if extrapolate_to is None else "",
            fs(best),
            fs(med),
            si(n / best, "/s"),
            si(r["steps"] * scale / best, "/s"),
            f"{r['eff']:.2f}",
            fm(r["err"]),
            f"{r['cpu']:.2f}",
        ]

    hdr = [
        "batch",
        "N",
        "chunk x dev",
        "compile",
        "best",
        "median",
        "props/s",
        "steps/s",
        "lane eff",
        "error",
        "cpu/wall",
    ]
    rows = []
    for n in leo_sizes:
        rep = 3 if n <= 1000 else (1 if QUICK else 2)  # 10,000 = 10 chunks of 1,000
        r = run_batch(
            "LEO", m_leo, LEO_P, None, 0.0, x_leo_big[:n], LEO_T, leo_chunk, False, one_dev, rep, y_leo, n_ref_leo
        )
        rows.append(batch_row(r))
    r = run_batch(
        "LEO + STM",
        m_leo,
        LEO_P,
        None,
        0.0,
        x_leo_big[:leo_stm_n],
        LEO_T,
        leo_chunk,
        True,
        one_dev,
        1,
        y_leo,
        n_ref_leo,
    )
    rows.append(batch_row(r))
    if not QUICK:
        if ARGS.stm_10k:
            r10 = run_batch(
                "LEO + STM",
                m_leo,
                LEO_P,
                None,
                0.0,
                x_leo_big[:10_000],
                LEO_T,
                leo_chunk,
                True,
                one_dev,
                1,
                y_leo,
                n_ref_leo,
            )
            rows.append(batch_row(r10))
        else:
            rows.append(batch_row(r, extrapolate_to=10_000))
    for n in cr_sizes:
        r = run_batch(
            "cruise",
            m_cr,
            CR_P,
            CR_EPH,
            CR_ET0,
            x_cr_big[:n],
            CR_T,
            cr_chunk,
            False,
            one_dev,
            3 if n <= cr_chunk else 1,
            y_cr,
            n_ref_cr,
        )
        rows.append(batch_row(r))
    if cr_stm_n:
        r = run_batch(
            "cruise + STM",
            m_cr,
            CR_P,
            CR_EPH,
            CR_ET0,
            x_cr_big[:cr_stm_n],
            CR_T,
            cr_stm_n,
            True,
            one_dev,
            1,
            y_cr,
            n_ref_cr,
        )
        rows.append(batch_row(r))
    table(
        hdr,
        rows,
        "compile = first call on a zero-length span (trace + compile of the chunk program); props/s = N / best; steps/s =\n"  # noqa: E501
        "sum of per-propagation Encke steps / best; lane eff = useful lane-steps / (lanes x loop iterations)\n"
        "(a vmapped while loop runs every lane until the slowest of its chunk is done); error = max over the\n"
        "reference states, which are the first rows of each batch; cpu/wall = process CPU time / wall time.\n"
        "STM = 7x7 state transition matrix by jacfwd through the integrator (propagate_with_sensitivities).",
    )
    stm_run = batch_results[("LEO + STM", 1, leo_stm_n)]
    stm_leo = None if stm_run["fail"] else np.asarray(stm_run["out"][1].stm[:, -1])

    # ------------------------------------------------------------------- 5. sharded
    banner(f"5. Sharded batches: the same chunks split over {len(devs)} host devices (shard_map)")
    if len(devs) < 2:
        print("only one device: set XLA_FLAGS=--xla_force_host_platform_device_count=N before importing jax")
    else:
        rows = []
        pairs = [
            ("LEO", m_leo, LEO_P, None, 0.0, x_leo_big[: leo_sizes[-1]], LEO_T, leo_chunk, False, y_leo, n_ref_leo),
            ("cruise", m_cr, CR_P, CR_EPH, CR_ET0, x_cr_big[: cr_sizes[-1]], CR_T, cr_chunk, False, y_cr, n_ref_cr),
        ]
        if QUICK:
            pairs = pairs[:1]
        else:
            pairs.append(
                ("LEO + STM", m_leo, LEO_P, None, 0.0, x_leo_big[:leo_stm_n], LEO_T, leo_chunk, True, y_leo, n_ref_leo)
            )
        for label, *a in pairs:
            base = batch_results.get((label, 1, a[4].shape[0]))
            if base is None:
                base = run_batch(label, *a[:7], a[7], one_dev, 1, a[8], a[9])
            r = run_batch(label, *a[:7], a[7], devs, base["repeat"], a[8], a[9])
            rows.append(batch_row(base) + [""])
            rows.append(batch_row(r) + [f"{base['best'] / r['best']:.2f}x"])
            if r["fail"] or base["fail"]:
                continue
            same = np.max(
                np.abs(r["out"][0].x_final - base["out"][0].x_final)
                if a[7]
                else np.abs(r["out"].x_final - base["out"].x_final)
            )
            rows[-1][0] += f" [max |dx| vs 1 dev {same:.1e}]"
        table(
            hdr + ["speedup"],
            rows,
            f"Load average now {loadavg()} on {os.cpu_count()} cores: other processes compete for the cores, so\n"
            "the speedup is bounded by the idle cores, not by the code (cpu/wall shows the cores obtained).",
        )

    # ------------------------------------------------------------------ 6. baselines
    banner(f"6. Baselines at <= {TARGET_M:g} m")
    rows = []
    # scipy DOP853, Cowell, Python RHS
    dtols = [1e-8, 3e-9, 1e-9, 3e-10, 1e-10, 3e-11, 1e-11, 3e-12, 1e-12]
    dop_err_leo = (
        lambda tol: pos_err(
            [
                dop853(leo_rhs, x, LEO_T, tol, tol * 1e-3)[0]  # noqa: E731
                for x in x_leo_big[:n_ref_leo]
            ],
            y_leo,
        )
    )
    dop_err_cr = (
        lambda tol: pos_err(
            [
                dop853(cr_rhs, x, CR_BREAKS, tol, tol * 1e-3)[0]  # noqa: E731
                for x in x_cr_big[:n_ref_cr]
            ],
            y_cr,
        )
    )
    if QUICK:
        tol_l, tol_c = 1e-10, 1e-11
        e_l, e_c = dop_err_leo(tol_l), dop_err_cr(tol_c)
    else:
        (tol_l, e_l), _ = tune_tol(dop_err_leo, dtols, TARGET_M * 1e-3)
        (tol_c, e_c), _ = tune_tol(dop_err_cr, dtols[4:] + [3e-13], TARGET_M * 1e-3)
    for label, rhs, xs, brk, tol, e, nloop, sizes in (
        ("LEO", leo_rhs, x_leo_big, LEO_T, tol_l, e_l, dop_loop_leo, leo_sizes),
        ("cruise", cr_rhs, x_cr_big, CR_BREAKS, tol_c, e_c, dop_loop_cr, cr_sizes),
    ):
        t0 = time.perf_counter()
        st = [dop853(rhs, x, brk, tol, tol * 1e-3)[1] for x in xs[:nloop]]
        dt = (time.perf_counter() - t0) / nloop
        for n in sizes[-1:]:
            rows.append(
                [
                    f"scipy DOP853 {label} (rtol {tol:g}, atol {tol * 1e-3:g})",
                    f"{n:,}",
                    "",
                    fs(dt * n),
                    si(1 / dt, "/s"),
                    si(np.mean(st) / dt, "/s"),
                    fm(e),
                    f"loop of {nloop}, extrapolated",
                ]
            )
    stm_note = ""
    if hy is None:
        print("heyoka not installed" if hy_version is None else "heyoka skipped (--no-heyoka)")
    else:
        x, y, z, vx, vy, vz = hy.make_vars("x", "y", "z", "vx", "vy", "vz")
        r2 = x * x + y * y + z * z
        rr = hy.sqrt(r2)
        k = -MU_E / (r2 * rr)
        s = z / rr
        cj = -1.5 * MU_E * J2_E * R_E * R_E / (r2 * r2)
        odes = [
            (x, vx),
            (y, vy),
            (z, vz),
            (vx, k * x + cj * (1 - 5 * s * s) * x / rr),
            (vy, k * y + cj * (1 - 5 * s * s) * y / rr),
            (vz, k * z + cj * ((1 - 5 * s * s) * z / rr + 2 * s)),
        ]
        B = 8

        def hy_run(ta, xs, var0=None):
            """Propagate rows of xs (N, 7) in groups of B; returns (final states (N, nstate), steps, the
            FAILED text of the first group whose taylor_outcome is not time_limit, or None)."""
            n = xs.shape[0]
            fail = None
            nb = -(-n // B)
            pad = np.concatenate([xs, np.repeat(xs[-1:], nb * B - n, 0)])[:, :6]
            out = np.empty((nb * B, ta.state.shape[0]))
            steps = 0
            for g in range(nb):
                ta.state[:6] = pad[g * B : (g + 1) * B].T
                if var0 is not None:
                    ta.state[6:] = var0
                ta.set_time(0.0)
                ta.propagate_until(DAY)
                res = ta.propagate_res[: min(B, n - g * B)]
                fail = fail or heyoka_failure(list(res), hy.taylor_outcome.time_limit)
                steps += sum(r[3] for r in res)
                out[g * B : (g + 1) * B] = ta.state.T
            return out[:n], steps, fail

        st0 = np.tile(LEO_X0[:6, None], (1, B))
        comp = {}

        if not (ARGS.keep_cache or QUICK):  # cold LLVM compiles, like the jax rows
            hy.llvm_state.set_diskcache_enabled(False)

        def hy_err(tol):
            t0 = time.perf_counter()
            ta = hy.taylor_adaptive_batch(odes, st0, tol=tol)
            comp[tol] = (time.perf_counter() - t0, ta)
            comp.setdefault("first", comp[tol][0])
            final, _, fail = hy_run(ta, x_leo_big[:n_ref_leo])
            return FailedFigure(fail) if fail else pos_err(final, y_leo)

        htols = [1e-8, 3e-9, 1e-9, 3e-10, 1e-10, 3e-11, 1e-11, 3e-12, 1e-12, 1e-13, 1e-14, 1e-15]
        (tol_h, e_h), tried_h = tune_tol(hy_err, htols, TARGET_M * 1e-3)
        tcomp, ta = comp[tol_h]
        for n in leo_sizes:
            (_, st, fail), best, med, _ = timed(lambda: hy_run(ta, x_leo_big[:n]), 3 if n <= 1000 else 1)
            if fail:
                rows.append([f"heyoka batch {B} LEO (tol {tol_h:g})", f"{n:,}", fail] + [""] * 5)
                continue
            rows.append(
                [
                    f"heyoka batch {B} LEO (tol {tol_h:g}, order {ta.order})",
                    f"{n:,}",
                    f"{fs(comp['first'])}/{fs(tcomp)}",
                    fs(best),
                    si(n / best, "/s"),
                    si(st / best, "/s"),
                    fm(e_h),
                    f"median {fs(med)}",
                ]
            )
        t0 = time.perf_counter()
        vsys = hy.var_ode_sys(odes, hy.var_args.vars, order=1)
        tv = hy.taylor_adaptive_batch(vsys, st0, tol=tol_h)
        tcv = time.perf_counter() - t0
        var0 = tv.state[6:].copy()  # identity, set up by heyoka
        for n in (leo_stm_n,) if QUICK else (leo_stm_n, 10_000):
            (outv, st, fail), best, med, _ = timed(lambda: hy_run(tv, x_leo_big[:n], var0), 1)
            if fail:
                rows.append([f"heyoka var_ode_sys batch {B} LEO + 6x6 STM", f"{n:,}", fail] + [""] * 5)
                outv = None
                continue
            ev = pos_err(outv[:n_ref_leo], y_leo)
            rows.append(
                [
                    f"heyoka var_ode_sys batch {B} LEO + 6x6 STM",
                    f"{n:,}",
                    fs(tcv),
                    fs(best),
                    si(n / best, "/s"),
                    si(st / best, "/s"),
                    fm(ev),
                    "",
                ]
            )
        # STM agreement with fracas (6x6 block), rows 0..n_ref-1 (only when both runs succeeded)
        if outv is not None and stm_leo is not None:
            phi_h = outv[:n_ref_leo, 6:42].reshape(n_ref_leo, 6, 6)
            phi_f = stm_leo[:n_ref_leo, :6, :6]
            rel = f"{np.max(np.linalg.norm(phi_h - phi_f, axis=(1, 2)) / np.linalg.norm(phi_f, axis=(1, 2))):.1e}"
        else:
            rel = "not compared (a run FAILED)"
        stm_note = (
            f"\nSTM check: max ||Phi_heyoka - Phi_fracas|| / ||Phi_fracas|| over the reference states = "
            f"{rel} (6x6 block).\nheyoka tolerances tried: " + ", ".join(f"{t:g}: {fm(e)}" for t, e in tried_h)
        )
    fr = batch_results
    for n in leo_sizes:
        for nd in sorted({1, len(devs)}):
            r = fr.get(("LEO", nd, n))
            if r and r["fail"]:
                rows.append([f"fracas Encke LEO (c_nom {c_leo:g}), {nd} device(s)", f"{n:,}", r["fail"]] + [""] * 5)
            elif r:
                rows.append(
                    [
                        f"fracas Encke LEO (c_nom {c_leo:g}), {nd} device(s)",
                        f"{n:,}",
                        fs(r["tcomp"]),
                        fs(r["best"]),
                        si(n / r["best"], "/s"),
                        si(r["steps"] / r["best"], "/s"),
                        fm(r["err"]),
                        "",
                    ]
                )
    r = fr.get(("LEO + STM", 1, leo_stm_n))
    rows.append(
        ["fracas Encke LEO + 7x7 STM, 1 device", f"{leo_stm_n:,}", r["fail"]] + [""] * 5
        if r["fail"]
        else [
            "fracas Encke LEO + 7x7 STM, 1 device",
            f"{leo_stm_n:,}",
            fs(r["tcomp"]),
            fs(r["best"]),
            si(leo_stm_n / r["best"], "/s"),
            si(r["steps"] / r["best"], "/s"),
            fm(r["err"]),
            "",
        ]
    )
    table(
        ["method", "N", "compile", "time", "props/s", "steps/s", "error", "note"],
        rows,
        (
            "heyoka: Taylor method (LLVM JIT), Cowell, point mass + J2 with the same constants, one thread,\n"
            "states set group by group from Python; steps = accepted Taylor steps.  "
            if hy
            else ""
        )
        + "DOP853 time for N = N x time of one."
        + stm_note,
    )

    # -------------------------------------------------------- 7. Encke vs Cowell RKN4
    banner("7. Encke vs plain Cowell (same RKN4 scheme and step rule) at equal accuracy")
    rows = []
    targets = (1e3,) if QUICK else (1.0, 1e3)
    cases = [
        ("LEO", leo_model, LEO_P, None, 0.0, x_leo_big[:n_ref_leo], LEO_T, y_leo, "c_nom", x_leo_big[: leo_sizes[0]])
    ]
    if not QUICK:
        cases.append(
            (
                "cruise",
                cruise_model,
                CR_P,
                CR_EPH,
                CR_ET0,
                x_cr_big[:n_ref_cr],
                CR_T,
                y_cr,
                "dt_max",
                x_cr_big[: cr_sizes[0]],
            )
        )
    for label, mk, params, eph, epoch, xs, t, yref, knob, xs_b in cases:
        nb = xs_b.shape[0]
        base_model = mk(0.05) if knob == "c_nom" else mk(d_cr)
        t_end = float(t[-1])

        def cow_err(h, _m=base_model, _p=params, _e=eph, _ep=epoch, _x=xs, _y=yref, _k=knob, _te=t_end):
            c_nom, dtm = (h, 4000.0) if _k == "c_nom" else (0.05, h * DAY)
            xe, n = cowell_many(_m, _p, _e, _ep, jnp.asarray(_x), _te, c_nom, dtm)
            f = cowell_failure(xe, n)
            return FailedFigure(f) if f else pos_err(np.asarray(xe), _y)

        enc_err = leo_err if knob == "c_nom" else cr_err
        for target_m in targets:
            tgt = target_m * 1e-3
            for meth in ("Encke", "Cowell"):
                if meth == "Encke":
                    if target_m == TARGET_M:
                        h, e = (c_leo, e_leo) if knob == "c_nom" else (d_cr, e_cr)
                    elif QUICK:
                        h = 0.2
                        e = enc_err(h)
                    else:
                        (h, e), _ = tune_step(enc_err, (c_leo if knob == "c_nom" else d_cr) * 4.0, tgt)
                    model = mk(h)
                    fn = lambda: propagate(model, params, eph, epoch, xs[0], t)  # noqa: E731
                    tr, best, med, _ = timed(fn, REPEAT)
                    require(tr, f"{label} Encke {h:g}", ok=(0,))
                    nst = int(tr.n_steps)
                    fb = lambda: propagate_batch(
                        model,
                        params,
                        eph,
                        epoch,
                        xs_b,
                        t,
                        chunk_size=nb,  # noqa: E731
                        devices=one_dev,
                    )
                    first_call(fb)  # same executable as section 4 (integrator constants are traced)
                    out_b, tb, _, _ = timed(fb, 2)
                    require(out_b, f"{label} Encke {h:g}, batch of {nb}", ok=(0,))
                else:
                    h0 = (c_leo / 8 if knob == "c_nom" else d_cr / 2) * (target_m / TARGET_M) ** 0.25
                    (h, e), _ = tune_step(cow_err, h0, tgt)
                    c_nom, dtm = (h, 4000.0) if knob == "c_nom" else (0.05, h * DAY)
                    fn = lambda: cowell_single(
                        base_model,
                        params,
                        eph,
                        epoch,
                        jnp.asarray(xs[0]),  # noqa: E731
                        t_end,
                        c_nom,
                        dtm,
                    )
                    first_call(fn)
                    (xe, nst), best, med, _ = timed(fn, REPEAT)
                    f = cowell_failure(xe, nst)
                    if f:
                        raise RunFailed(f"{label} Cowell {h:g}: {f}")
                    nst = int(nst)
                    fb = lambda: cowell_many(
                        base_model,
                        params,
                        eph,
                        epoch,
                        jnp.asarray(xs_b),  # noqa: E731
                        t_end,
                        c_nom,
                        dtm,
                    )
                    first_call(fb)
                    (xe_b, n_b), tb, _, _ = timed(fb, 2)
                    f = cowell_failure(xe_b, n_b)
                    if f:
                        raise RunFailed(f"{label} Cowell {h:g}, batch of {nb}: {f}")
                setting = f"c_nom {h:g}" if knob == "c_nom" else f"dt_max {h:g} d"
                rows.append(
                    [
                        label,
                        f"{target_m:g} m",
                        meth,
                        setting,
                        fm(e),
                        nst,
                        fs(best),
                        fs(med),
                        f"{best / nst * 1e6:.1f}",
                        f"{nb:,}",
                        si(nb / tb, "/s"),
                        f"{tb / (nb * nst) * 1e6:.2f}",
                    ]
                )
    table(
        [
            "problem",
            "target",
            "method",
            "setting",
            "error",
            "steps",
            "single best",
            "median",
            "us/step",
            "batch N",
            "batch props/s",
            "us/lane-step",
        ],
        rows,
        "single = one propagation of the nominal state (jit, warm); batch = vmap over the first N states of\n"
        "section 4 (one device, best of 2); error = max over the reference states.  Both use\n"
        "dt = min(c_nom r^1.5/sqrt(mu), dt_max, next switch); Encke adds two Kepler solves per step.",
    )

    banner("done")
    print(f"total wall time {time.perf_counter() - T_START:.0f} s; load average at end {loadavg()}")


if __name__ == "__main__":
    main_guard(main)
