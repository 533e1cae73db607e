"""Where the time of an Encke/Nystrom step goes: ablations of the core, patched in memory.

    .venv/bin/python benchmarks/profile_core.py [--quick]

Each variant is the real ``fracas.integrate.encke`` / ``propagate`` source with one change,
loaded as a separate module (no file is modified), timed as a single propagation (N = 1:
per-iteration overhead dominates) and as a vmapped batch (per-lane cost dominates), in
microseconds per lane-step (wall time / (lanes x loop iterations)):

  baseline             the core as it is
  kepler: n_newton 1   one Newton step after the step's predictor instead of encke._N_NEWTON
  kepler: n_newton 0   no Newton step (kepler_fg's final differentiable Newton step only)
  kepler: trig stumpff short_arc=False: Stumpff functions from sin/sinh instead of polynomials
  kepler: Laguerre     n_newton=None: the general Laguerre-Conway while loop to convergence
  kepler: none         the conic replaced by r0 + v0 tau (wrong answers: the cost of Kepler at all)
  STM: dt no-grad      propagate_with_sensitivities with the step-size rule under stop_gradient

(the Kepler variants follow the core of early 2026-11-22: ``kepler_fg(..., n_newton, short_arc)``;
a variant the current core does not support is reported as n/a), plus the ephemeris cost
(``body_states`` of the cruise's five bodies, vmapped inside a loop;
the step calls it three times), a while loop with a trivial body (loop overhead) and the
number of Laguerre iterations the warm-started solves take.  Numbers are wall clock on a shared machine:
compare rows of one run, not runs.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from runs import RunFailed, failure, main_guard  # noqa: E402  (benchmarks/runs.py)

import fracas.dynamics.kepler as K  # noqa: E402
import fracas.integrate.encke as E  # noqa: E402
import fracas.integrate.propagate as PR  # noqa: E402
from fracas import _jax  # noqa: E402,F401

DAY = 86400.0


def load_variant(name, module, replace=(), attrs=None):
    """A fresh copy of ``module`` with source replacements and attribute overrides."""
    src = Path(module.__file__).read_text()
    for old, new in replace:
        assert old in src, (name, old)
        src = src.replace(old, new)
    mod = types.ModuleType(f"{module.__name__}_{name}")
    mod.__file__ = module.__file__
    exec(compile(src, module.__file__, "exec"), mod.__dict__)
    for k, v in (attrs or {}).items():
        setattr(mod, k, v)
    return mod


def kepler_none(r0_vec, v0_vec, tau, mu, x_start=None, **_):
    z = jnp.zeros(())
    x = z if x_start is None else jnp.asarray(x_start) + z
    return K.ConicState(r0_vec + v0_vec * tau, v0_vec, x, z, z, z, z)


def kepler_with(**force):
    """kepler_fg with some keyword arguments forced (e.g. short_arc=False, n_newton=None)."""

    def fn(*a, **k):
        k.update(force)
        return K.kepler_fg(*a, **k)

    return fn


def make_propagate(encke_mod):
    pr = load_variant("pr_" + encke_mod.__name__.rsplit("_", 1)[-1], PR)
    pr.encke = encke_mod
    return pr


def build_variants():
    """name -> (propagate module or None, reason)."""
    mk = {
        "kepler: n_newton 1": lambda: load_variant("n1", E, attrs={"_N_NEWTON": 1}),
        "kepler: n_newton 0": lambda: load_variant("n0", E, attrs={"_N_NEWTON": 0}),
        "kepler: trig stumpff": lambda: load_variant("ts", E, attrs={"kepler_fg": kepler_with(short_arc=False)}),
        "kepler: Laguerre": lambda: load_variant("lc", E, attrs={"kepler_fg": kepler_with(n_newton=None)}),
        "kepler: none": lambda: load_variant("kn", E, attrs={"kepler_fg": kepler_none}),
    }
    v = {"baseline": PR}
    for name, f in mk.items():
        if "n_newton" in name and not hasattr(E, "_N_NEWTON"):
            v[name] = None
            continue
        v[name] = make_propagate(f())
    return v


def stm_nograd_variant():
    import re

    src = Path(E.__file__).read_text()
    m = re.search(r"dt_nom = (st\.c_nom[^\n]*)", src)
    enc = load_variant("sg", E, replace=[(m.group(0), f"dt_nom = jax.lax.stop_gradient({m.group(1)})")])
    return make_propagate(enc)


def ephemeris_cost(table, et0, n_lanes, n_iter=2000):
    """us per body_states call per lane inside a vmapped fori_loop (minus the bare loop)."""
    from fracas.dynamics.ephemeris import body_states

    def run(with_eph):
        def one(t0):
            def body(i, acc):
                t = t0 + i * 9000.0
                if not with_eph:
                    return acc + jnp.sin(t)
                p, v = body_states(table, t)
                return acc + jnp.sin(t) + p[2, 0] + v[3, 1]

            return jax.lax.fori_loop(0, n_iter, body, 0.0)

        return jax.jit(jax.vmap(one))

    ts = et0 + jnp.arange(n_lanes) * 1000.0
    out = []
    for w in (True, False):
        f = run(w)
        jax.block_until_ready(f(ts))
        out.append(best_of(lambda: f(ts), 3)[1])
    return (out[0] - out[1]) / (n_iter * n_lanes) * 1e6


def best_of(fn, repeat):
    ts = []
    out = None
    for _ in range(repeat):
        t = time.perf_counter()
        out = jax.block_until_ready(fn())
        ts.append(time.perf_counter() - t)
    return out, min(ts)


def prepare_variant(pr, model, params, eph, epoch, xs, t_out, sens=False):
    """Compiled single and vmapped propagations of one variant (warmed up)."""
    f = pr.propagate_with_sensitivities if sens else pr.propagate
    single = jax.jit(lambda x: f(model, params, eph, epoch, x, t_out))
    many = jax.jit(jax.vmap(lambda x: f(model, params, eph, epoch, x, t_out)))
    x0 = jnp.asarray(xs[0])
    xb = jnp.asarray(xs)
    o1 = jax.block_until_ready(single(x0))
    ob = jax.block_until_ready(many(xb))
    tr1 = o1[0] if sens else o1
    trb = ob[0] if sens else ob
    return {
        "fail": failure(tr1, ok=(0,)) or failure(trb, ok=(0,)),  # no timing or |dx| from a failed run
        "single": lambda: single(x0),
        "many": lambda: many(xb),
        "it1": int(tr1.n_steps),
        "it": int(np.max(np.asarray(trb.n_steps))),
        "n": xs.shape[0],
        "out": ob,
        "t1": np.inf,
        "tb": np.inf,
    }


def round_robin(preps: dict, rounds: int, single_reps: int = 3) -> None:
    """Time every variant once per round, in turn, keeping the best: slow drifts of the load from
    other processes then hit every variant alike.  Fills us1 / usb (us per lane-step)."""
    for _ in range(rounds):
        for v in preps.values():
            v["t1"] = min(v["t1"], best_of(v["single"], single_reps)[1])
            v["tb"] = min(v["tb"], best_of(v["many"], 1)[1])
    for v in preps.values():
        v["us1"] = v["t1"] / v["it1"] * 1e6
        v["usb"] = v["tb"] / (v["it"] * v["n"]) * 1e6


def loop_overhead(n_lanes, n_iter, width=40):
    """A vmapped while loop with a trivial body and ~``width`` float carry per lane."""

    def one(c):
        def body(s):
            i, a = s
            return i + 1, a * 1.0000001 + 1e-9

        return jax.lax.while_loop(lambda s: s[0] < n_iter, body, (jnp.zeros((), jnp.int32), c))[1]

    f1 = jax.jit(one)
    fb = jax.jit(jax.vmap(one))
    c1 = jnp.ones(width)
    cb = jnp.ones((n_lanes, width))
    jax.block_until_ready(f1(c1))
    jax.block_until_ready(fb(cb))
    _, t1 = best_of(lambda: f1(c1), 5)
    _, tb = best_of(lambda: fb(cb), 3)
    return t1 / n_iter * 1e6, tb / (n_iter * n_lanes) * 1e6


def kepler_iterations(model_c):
    """Laguerre-Conway iterations of the warm-started solves along a LEO conic (as in a step)."""
    mu = 398600.4418
    r0 = jnp.array([7000.0, 0.0, 0.0])
    v0 = jnp.array([0.0, 7.5, 1.0])
    rn = 7000.0
    dt = model_c * rn * np.sqrt(rn / mu)
    sqrt_mu = np.sqrt(mu)
    sigma0 = float(r0 @ v0) / sqrt_mu
    alpha = 2.0 / rn - float(v0 @ v0) / mu
    x, tau, its = 0.0, 0.0, []
    r_prev = rn
    for _ in range(200):  # 200 half steps along the conic, warm start as in encke._nystrom_step
        tau_new = tau + 0.5 * dt
        xs = x + sqrt_mu * (tau_new - tau) / r_prev
        x, k = K.solve_universal_x(rn, sigma0, alpha, sqrt_mu, tau_new, xs)
        its.append(int(k))
        x = float(x)
        _, r_prev, _, _, _ = K._time_of_x(x, rn, sigma0, alpha, sqrt_mu)
        r_prev = float(r_prev)
        tau = tau_new
    return np.bincount(its)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    n_leo = 256 if args.quick else 1000
    n_cr = 16 if args.quick else 64
    rep = 3 if args.quick else 5
    print(
        f"fracas core profile (ablations); jax {jax.__version__}, {jax.devices()[0].platform}, "
        f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"
    )

    # LEO
    sys.argv = [sys.argv[0], "--quick"]  # bench_core parses its own arguments at import
    import benchmarks.bench_core as B  # noqa: E402  (problem definitions)

    m_leo = B.leo_model(0.036)
    xs_leo = B.leo_states(n_leo)
    m_cr = B.cruise_model(0.12)
    xs_cr = B.cruise_states(n_cr)
    rows = []
    for label, model, params, eph, epoch, xs, t in (
        ("LEO", m_leo, B.LEO_P, None, 0.0, xs_leo, B.LEO_T),
        ("cruise", m_cr, B.CR_P, B.CR_EPH, B.CR_ET0, xs_cr, B.CR_T),
    ):
        preps = {}
        for name, pr in build_variants().items():
            try:
                if pr is None:
                    raise NotImplementedError("not in this core")
                preps[name] = prepare_variant(pr, model, params, eph, epoch, xs, t)
            except Exception as exc:  # a variant the current core does not support
                preps[name] = f"{type(exc).__name__}: {str(exc)[:40]}"
        ok = {k: v for k, v in preps.items() if isinstance(v, dict)}
        round_robin(ok, rep)
        base = ok["baseline"]
        for name, r in preps.items():
            if not isinstance(r, dict):
                rows.append((label, name, "n/a", "n/a", "", "", r))
                continue
            if r["fail"] or base["fail"]:
                rows.append((label, name, r["fail"] or f"baseline {base['fail']}", "", "", r["it"], ""))
                print(*rows[-1], sep="  |  ", flush=True)
                continue
            dx = np.max(
                np.linalg.norm(np.asarray(r["out"].x_final)[:, :3] - np.asarray(base["out"].x_final)[:, :3], axis=1)
            )
            rows.append(
                (
                    label,
                    name,
                    f"{r['us1']:.2f}",
                    f"{r['usb']:.2f}",
                    f"{r['usb'] / base['usb']:.2f}",
                    r["it"],
                    f"{dx * 1e3:.2g} m",
                )
            )
            print(*rows[-1], sep="  |  ", flush=True)
    for label, model, params, eph, epoch, xs, t in (
        ("LEO", m_leo, B.LEO_P, None, 0.0, xs_leo[: max(8, n_leo // 8)], B.LEO_T),
        ("cruise", m_cr, B.CR_P, B.CR_EPH, B.CR_ET0, xs_cr[: max(4, n_cr // 8)], B.CR_T),
    ):
        base = prepare_variant(PR, model, params, eph, epoch, xs, t, sens=True)
        ng = prepare_variant(stm_nograd_variant(), model, params, eph, epoch, xs, t, sens=True)
        for r, what in ((base, "STM jacfwd"), (ng, "STM dt no-grad")):
            if r["fail"]:  # no timing or STM difference from a failed run
                raise RunFailed(f"{label} {what}: {r['fail']}")
        round_robin({"base": base, "ng": ng}, max(2, rep // 2), single_reps=1)
        s0 = np.asarray(base["out"][1].stm[:, -1])
        s1 = np.asarray(ng["out"][1].stm[:, -1])
        rel = np.max(np.linalg.norm(s1 - s0, axis=(1, 2)) / np.linalg.norm(s0, axis=(1, 2)))
        for name, r, note in (("STM: jacfwd (as is)", base, ""), ("STM: dt no-grad", ng, f"dSTM {rel:.1e} rel")):
            rows.append(
                (
                    label + f" (N={xs.shape[0]})",
                    name,
                    f"{r['us1']:.2f}",
                    f"{r['usb']:.2f}",
                    f"{r['usb'] / base['usb']:.2f}",
                    r["it"],
                    note,
                )
            )
            print(*rows[-1], sep="  |  ", flush=True)

    print()
    w = [
        max(
            len(str(r[i]))
            for r in rows
            + [
                (
                    "problem",
                    "variant",
                    "us/step N=1",
                    "us/lane-step batch",
                    "vs baseline",
                    "loop iters",
                    "max |dr| vs baseline",
                )
            ]
        )
        for i in range(7)
    ]
    hdr = (
        "problem",
        "variant",
        "us/step N=1",
        "us/lane-step batch",
        "vs baseline",
        "loop iters",
        "max |dr| vs baseline",
    )
    print("  ".join(str(h).ljust(w[i]) for i, h in enumerate(hdr)))
    for r in rows:
        print("  ".join(str(c).ljust(w[i]) for i, c in enumerate(r)))
    print(f"batch: LEO N = {n_leo}, cruise N = {n_cr} (STM rows: N as shown); single = the first state.")

    e1 = ephemeris_cost(B.CR_EPH, B.CR_ET0, 1)
    eb = ephemeris_cost(B.CR_EPH, B.CR_ET0, n_cr)
    print(
        f"\nephemeris, 5 bodies (positions + velocities): {e1:.2f} us/call (N=1), {eb:.2f} us/lane-call "
        f"(N={n_cr}); the Nystrom step makes 3 calls"
    )
    o1, ob = loop_overhead(n_leo, 20_000)
    print(
        f"while loop with a trivial body, 40 floats of carry: {o1:.2f} us/iteration (N=1), "
        f"{ob * 1e3:.1f} ns/lane-iteration (N={n_leo})"
    )
    hist = kepler_iterations(0.036)
    print(
        "Laguerre-Conway iterations of warm-started (first-order predictor) half-step solves, LEO "
        "c_nom 0.036: "
        + ", ".join(f"{k}: {c}" for k, c in enumerate(hist) if c)
        + " (the last iteration only confirms convergence)"
    )


if __name__ == "__main__":
    main_guard(main)
