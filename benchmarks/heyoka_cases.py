"""heyoka baselines (Taylor integrator, LLVM JIT) for side-by-side runs against fracas's batch propagator.

    .venv/bin/python benchmarks/heyoka_cases.py          # self-test: truth, loosest tol for <= 1 m, timings, STM check
    .venv/bin/python benchmarks/heyoka_cases.py --cold   # the same, with cold LLVM compiles in the table

Units: km, km/s, kg, s (thrust in kg km/s^2, so 1 N = 1e-3 kg km/s^2).  Dynamics: Earth point mass + zonal J2
(pole +z), optionally a constant thrust along the velocity direction with mass flow mdot = -T / ve.

Contents:

* ``CASES``: name -> :class:`Case` (``leo_j2``, ``eccentric``, ``leo_thrust``, ``spiral``).
* :func:`make_odes`: heyoka ODE list (6 states, or 7 with the mass when the case thrusts); ``var=True`` gives the
  order-1 variational system (6x6 or 7x7 STM).
* :func:`initial_states`: row 0 the nominal state, other rows small dispersions.
* :class:`HeyokaBatch`: one ``taylor_adaptive_batch`` built once, run over any number of initial states.
* :func:`truth`: reference final states from a scalar long-double (80-bit x87 on x86) Taylor integrator at its
  default tolerance (long-double epsilon); see ``TRUTH_KIND``.
* :func:`pos_err_m`, :func:`loosest_tol`: accuracy and tolerance tuning.
* :func:`set_cold`: turn heyoka's on-disk LLVM compile cache off, so ``compile_s`` is a cold compile.

Layouts (checked in the self-test): heyoka batch states are (nstate, batch) arrays; ``ta.propagate_res`` of a batch
integrator is a list (one per batch element) of tuples ``(outcome, min_h, max_h, n_steps)``, so the accepted step
count is field 3.  The order-1 ``var_ode_sys`` state is ``[x (nx), dx_0/dx0_0, dx_0/dx0_1, ..., dx_{nx-1}/dx0_{nx-1}]``,
so ``state[nx:].reshape(nx, nx)`` is the STM ``Phi[i, j] = d x_i(t) / d x_j(0)`` (row-major), which is what
:func:`stm_of` returns; the self-test compares it against central finite differences.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass

import heyoka as hy
import numpy as np
from runs import require_heyoka  # benchmarks/runs.py: no figure from a failed run

MU_E = 398600.4418  # km^3/s^2
J2_E = 1.08262668e-3
R_E = 6378.137  # km
DAY = 86400.0  # s


def _longdouble_ok() -> bool:
    """True when numpy's longdouble is wider than float64 and heyoka accepts it as fp_type."""
    if np.finfo(np.longdouble).eps >= np.finfo(np.float64).eps:
        return False
    try:
        x, v = hy.make_vars("x", "v")
        hy.taylor_adaptive([(x, v), (v, -x)], np.array([1.0, 0.0], dtype=np.longdouble), fp_type=np.longdouble)
    except Exception:  # noqa: BLE001 - any failure means: no long-double support here
        return False
    return True


_LD = _longdouble_ok()
TRUTH_FP = np.longdouble if _LD else np.float64
TRUTH_TOL: float | None = None if _LD else 1e-16  # None: heyoka's default (the fp type's epsilon)
TRUTH_KIND = (
    f"scalar heyoka taylor_adaptive, long double (eps {float(np.finfo(np.longdouble).eps):.1e}), default tol"
    if _LD
    else "scalar heyoka taylor_adaptive, float64 at tol 1e-16 (long double not supported here)"
)


@dataclass(frozen=True, eq=False)  # eq=False: identity hash/eq (x0 is an array)
class Case:
    """One propagation problem.

    name: key in ``CASES``; t_final_s: propagation time (s), from t = 0; x0: (7,) nominal state
    [x, y, z (km), vx, vy, vz (km/s), m (kg)]; thrust_kg_km_s2: thrust along v/|v| (kg km/s^2, 1 N = 1e-3),
    0 for none (then the mass is not integrated); ve_km_s: exhaust velocity (km/s), mdot = -T / ve;
    description: one line.
    """

    name: str
    t_final_s: float
    x0: np.ndarray
    thrust_kg_km_s2: float
    ve_km_s: float
    description: str

    @property
    def nx(self) -> int:
        """Number of integrated states: 7 (r, v, m) with thrust, else 6 (r, v)."""
        return 7 if self.thrust_kg_km_s2 > 0 else 6


def _eccentric_x0(r_p: float = 6778.0, e: float = 0.7, inc_deg: float = 28.5, m: float = 1000.0) -> np.ndarray:
    """State at perigee (km, km/s, kg) for perigee radius r_p (km), eccentricity e, inclination inc_deg."""
    v_p = math.sqrt(MU_E * (1 + e) / r_p)
    i = math.radians(inc_deg)
    return np.array([r_p, 0.0, 0.0, 0.0, v_p * math.cos(i), v_p * math.sin(i), m])


def _x0(*vals: float) -> np.ndarray:
    a = np.array(vals, dtype=np.float64)
    a.setflags(write=False)
    return a


CASES: dict[str, Case] = {
    "leo_j2": Case(
        "leo_j2", DAY, _x0(7000.0, 0.0, 0.0, 0.0, 7.5, 1.0, 1000.0), 0.0, 0.0, "LEO, point mass + J2, 1 day"
    ),
    "eccentric": Case(
        "eccentric", 3 * DAY, _x0(*_eccentric_x0()), 0.0, 0.0, "r_p 6778 km, e 0.7, i 28.5 deg, point mass + J2, 3 days"
    ),
    "leo_thrust": Case(
        "leo_thrust",
        DAY,
        _x0(7000.0, 0.0, 0.0, 0.0, 7.5, 1.0, 1000.0),
        0.5e-3,
        30.0,
        "LEO + J2 + 0.5 N along v, 1000 kg, ve 30 km/s, 1 day",
    ),
    "spiral": Case(
        "spiral",
        10 * DAY,
        _x0(7000.0, 0.0, 0.0, 0.0, math.sqrt(MU_E / 7000.0), 0.0, 500.0),
        1.0e-3,
        20.0,
        "circular 7000 km + J2, 1 N along v, 500 kg, ve 20 km/s, 10 days",
    ),
}


def make_odes(case: Case, var: bool = False):
    """heyoka ODEs for ``case`` in state order (x, y, z, vx, vy, vz[, m]) (km, km/s, kg; time in s).

    Point mass MU_E + zonal J2 (pole +z); with thrust T > 0 adds T/m * v/|v| and dm/dt = -T/ve (mass integrated
    only then). Returns the list of (variable, rhs) pairs, or with ``var=True`` the order-1 variational system
    ``hy.var_ode_sys(odes, hy.var_args.vars, order=1)`` (nx*nx extra states, see :func:`stm_of`).
    """
    x, y, z, vx, vy, vz = hy.make_vars("x", "y", "z", "vx", "vy", "vz")
    r2 = x * x + y * y + z * z
    r = hy.sqrt(r2)
    k = -MU_E / (r2 * r)
    s2 = (z * z) / r2
    cj = -1.5 * MU_E * J2_E * R_E * R_E / (r2 * r2 * r)  # includes the 1/r of x/r, y/r, z/r
    ax = k * x + cj * (1.0 - 5.0 * s2) * x
    ay = k * y + cj * (1.0 - 5.0 * s2) * y
    az = k * z + cj * (3.0 - 5.0 * s2) * z
    odes = [(x, vx), (y, vy), (z, vz)]
    if case.thrust_kg_km_s2 > 0:
        m = hy.make_vars("m")
        kt = case.thrust_kg_km_s2 / (m * hy.sqrt(vx * vx + vy * vy + vz * vz))
        odes += [
            (vx, ax + kt * vx),
            (vy, ay + kt * vy),
            (vz, az + kt * vz),
            (m, hy.expression(-case.thrust_kg_km_s2 / case.ve_km_s)),
        ]
    else:
        odes += [(vx, ax), (vy, ay), (vz, az)]
    if var:
        return hy.var_ode_sys(odes, hy.var_args.vars, order=1)
    return odes


def initial_states(case: Case, n: int, seed: int = 0) -> np.ndarray:
    """(n, 7) initial states (km, km/s, kg): row 0 is ``case.x0``; rows 1.. add Gaussian dispersions of sigma
    1 km in position and 1e-3 km/s (1 m/s) in velocity, mass unchanged."""
    rng = np.random.default_rng(seed)
    xs = np.tile(np.asarray(case.x0, dtype=np.float64), (n, 1))
    if n > 1:
        xs[1:, 0:3] += rng.normal(0.0, 1.0, (n - 1, 3))
        xs[1:, 3:6] += rng.normal(0.0, 1e-3, (n - 1, 3))
    return xs


def stm_of(final: np.ndarray, nx: int) -> np.ndarray:
    """STMs (N, nx, nx), Phi[k, i, j] = d x_i(t_f) / d x_j(0), from final var_ode_sys states (N, nx + nx*nx)."""
    return np.asarray(final)[:, nx : nx + nx * nx].reshape(-1, nx, nx)


def set_cold(cold: bool = True) -> None:
    """cold=True: disable heyoka's on-disk LLVM compile cache (``hy.llvm_state.set_diskcache_enabled(False)``), so
    each :class:`HeyokaBatch` construction is a cold compile (heyoka's in-memory cache still holds compiles made
    earlier in this process; :func:`set_cold` also clears it). cold=False turns the disk cache back on."""
    hy.llvm_state.set_diskcache_enabled(not cold)
    if cold:
        hy.llvm_state.clear_memcache()


class HeyokaBatch:
    """One ``hy.taylor_adaptive_batch`` for ``case`` at relative/absolute tolerance ``tol``, built once.

    batch: SIMD batch width (default ``hy.recommended_simd_size()``, 8 on AVX-512); var: integrate the order-1
    variational equations too (STM); fp_type: heyoka floating-point type. Attributes: ``ta`` (the integrator),
    ``nx`` (6 or 7), ``nstate`` (nx, or nx + nx*nx with var), ``compile_s`` (construction time, s, including the
    LLVM compile unless cached), ``var0`` (identity variational block, (nx*nx, batch), with var).
    """

    def __init__(self, case: Case, tol: float, batch: int | None = None, var: bool = False, fp_type=float) -> None:
        self.case, self.tol, self.var, self.fp_type = case, tol, var, fp_type
        self.batch = int(batch or hy.recommended_simd_size())
        self.nx = case.nx
        t0 = time.perf_counter()
        sys = make_odes(case, var=var)
        st0 = np.tile(np.asarray(case.x0[: self.nx], dtype=np.float64)[:, None], (1, self.batch))
        self.ta = hy.taylor_adaptive_batch(sys, st0, tol=tol, fp_type=fp_type)
        self.compile_s = time.perf_counter() - t0
        self.nstate = int(self.ta.state.shape[0])
        self.var0 = self.ta.state[self.nx :].copy() if var else None  # identity, as heyoka sets it up

    @property
    def order(self) -> int:
        """Taylor order heyoka chose for ``tol``."""
        return int(self.ta.order)

    def run(self, x0s: np.ndarray) -> tuple[np.ndarray, int, float]:
        """Propagate each row of x0s ((N, >= nx), km, km/s, kg) from t = 0 to ``case.t_final_s``.

        Rows go in groups of ``batch`` (the last group padded with copies of the last row). Returns (final
        states (N, nstate), accepted steps summed over the N real rows, wall seconds). With var, the STMs are
        ``stm_of(final, nx)``.
        """
        x0s = np.asarray(x0s, dtype=np.float64)
        n, b, nx, ta = x0s.shape[0], self.batch, self.nx, self.ta
        ng = -(-n // b)
        pad = np.concatenate([x0s[:, :nx], np.repeat(x0s[-1:, :nx], ng * b - n, 0)])
        out = np.empty((ng * b, self.nstate))
        steps = 0
        tf = self.case.t_final_s
        t0 = time.perf_counter()
        for g in range(ng):
            ta.state[:nx] = pad[g * b : (g + 1) * b].T
            if self.var0 is not None:
                ta.state[nx:] = self.var0
            ta.set_time(0.0)
            ta.propagate_until(tf)
            res = ta.propagate_res[: min(b, n - g * b)]  # (outcome, min_h, max_h, n_steps) per element
            require_heyoka(list(res), f"heyoka {self.case.name} (tol {self.tol:g})")  # no figure from a failed run
            steps += sum(int(r[3]) for r in res)
            out[g * b : (g + 1) * b] = ta.state.T
        return out[:n], steps, time.perf_counter() - t0


def _truth_fp(case: Case, x0s: np.ndarray, var: bool = False) -> tuple[np.ndarray, int]:
    """Final states at ``case.t_final_s`` in TRUTH_FP (N, nstate), and total steps; scalar integrator, one row at
    a time. ODE constants are the float64 values of the module constants (the problem fracas solves)."""
    x0s = np.asarray(x0s, dtype=np.float64)
    nx = case.nx
    sys = make_odes(case, var=var)
    kw = {} if TRUTH_TOL is None else {"tol": TRUTH_TOL}
    ta = hy.taylor_adaptive(sys, np.asarray(case.x0[:nx], dtype=TRUTH_FP), fp_type=TRUTH_FP, **kw)
    var0 = ta.state[nx:].copy()
    out = np.empty((x0s.shape[0], ta.state.shape[0]), dtype=TRUTH_FP)
    steps = 0
    for k, row in enumerate(x0s):
        ta.state[:nx] = row[:nx].astype(TRUTH_FP)
        ta.state[nx:] = var0
        ta.time = TRUTH_FP(0.0)
        res = ta.propagate_until(TRUTH_FP(case.t_final_s))
        require_heyoka(res, f"heyoka truth {case.name} (row {k})")
        steps += int(res[3])
        out[k] = ta.state
    return out, steps


def truth(case: Case, x0s: np.ndarray) -> np.ndarray:
    """Reference final states (N, nx) at ``case.t_final_s`` (km, km/s, kg), float64; see ``TRUTH_KIND``."""
    return _truth_fp(case, x0s)[0].astype(np.float64)


def pos_err_m(final: np.ndarray, truth: np.ndarray) -> float:
    """Max over rows of the final position error |r - r_truth| (m); both (N, >= 3) in km."""
    d = np.asarray(final, dtype=np.float64)[:, :3] - np.asarray(truth, dtype=np.float64)[:, :3]
    return float(np.max(np.linalg.norm(d, axis=1)) * 1e3)


def loosest_tol(
    case: Case,
    x0s_ref: np.ndarray,
    truth_ref: np.ndarray,
    target_m: float = 1.0,
    tols: tuple[float, ...] = (
        1e-6,
        3e-7,
        1e-7,
        3e-8,
        1e-8,
        3e-9,
        1e-9,
        3e-10,
        1e-10,
        3e-11,
        1e-11,
        1e-12,
        1e-13,
        1e-14,
        1e-15,
    ),
    **batch_kw,
) -> tuple[float, float, list[tuple[float, float]]]:
    """First tolerance of ``tols`` (loose to tight) whose max final position error (m) over x0s_ref against
    truth_ref is <= target_m. Returns (tol, err_m, tried [(tol, err_m), ...]); if none meets the target, the
    tightest tried. ``batch_kw`` go to :class:`HeyokaBatch` (batch, var, fp_type)."""
    tried: list[tuple[float, float]] = []
    for tol in tols:
        final, _, _ = HeyokaBatch(case, tol, **batch_kw).run(x0s_ref)
        err = pos_err_m(final, truth_ref)
        tried.append((tol, err))
        if err <= target_m:
            return tol, err, tried
    return tried[-1][0], tried[-1][1], tried


def _stm_fd_check(case: Case, x0: np.ndarray, tol: float) -> tuple[float, float]:
    """STM from var_ode_sys (float64 batch at ``tol``) against central differences of the TRUTH_FP integrator
    (steps 1e-3 km, 1e-6 km/s, 1e-3 kg). Returns (max over columns j of |Phi_var[:, j] - Phi_fd[:, j]| /
    |Phi_fd[:, j]|, ||Phi_var - Phi_fd||_F / ||Phi_fd||_F)."""
    nx = case.nx
    steps = np.array([1e-3] * 3 + [1e-6] * 3 + [1e-3])[:nx]
    xs = [x0.copy()]
    for j in range(nx):
        for sgn in (1.0, -1.0):
            xp = x0.copy()
            xp[j] += sgn * steps[j]
            xs.append(xp)
    fin, _ = _truth_fp(case, np.array(xs))
    fin = fin[:, :nx]
    phi_fd = np.empty((nx, nx))
    for j in range(nx):
        dx = TRUTH_FP(xs[1 + 2 * j][j]) - TRUTH_FP(xs[2 + 2 * j][j])  # the steps as actually represented
        phi_fd[:, j] = ((fin[1 + 2 * j] - fin[2 + 2 * j]) / dx).astype(np.float64)
    hb = HeyokaBatch(case, tol, var=True)
    phi = stm_of(hb.run(x0[None])[0], nx)[0]
    col = np.max(np.linalg.norm(phi - phi_fd, axis=0) / np.linalg.norm(phi_fd, axis=0))
    fro = np.linalg.norm(phi - phi_fd) / np.linalg.norm(phi_fd)
    return float(col), float(fro)


def _self_test(cold: bool = False) -> None:
    """Truth for 16 states per case, loosest tol for <= 1 m, timings of 2000 propagations (800 with the STM for
    leo_j2 and leo_thrust), and the leo_j2 STM finite-difference check. Under a minute on 2 cores.

    cold: disk cache off and the in-memory cache cleared before each timed construction, so the table's
    compile s are cold LLVM compiles; otherwise they may be cache hits (the tolerance search compiles first).
    """
    if cold:
        set_cold(True)
    print(f"heyoka {hy.__version__}, simd {hy.recommended_simd_size()}, truth: {TRUTH_KIND}")
    print(f"disk cache enabled: {hy.llvm_state.get_diskcache_enabled()}; cold compiles in the table: {cold}")
    n_ref, n_time, n_var = 16, 2000, 800
    rows = []
    t_all = time.perf_counter()
    for name, case in CASES.items():
        xs_ref = initial_states(case, n_ref, seed=1)
        t0 = time.perf_counter()
        tr, tr_steps = _truth_fp(case, xs_ref)
        tr = tr.astype(np.float64)
        t_tr = time.perf_counter() - t0
        tol, err, tried = loosest_tol(case, xs_ref, tr)
        print(
            f"{name}: truth {t_tr:.1f} s ({tr_steps / n_ref:.0f} steps/prop); tried "
            + ", ".join(f"{t:g}: {e:.3g} m" for t, e in tried)
        )
        xs = initial_states(case, n_time, seed=2)
        for var in (False, True) if name in ("leo_j2", "leo_thrust") else (False,):
            if cold:
                hy.llvm_state.clear_memcache()
            hb = HeyokaBatch(case, tol, var=var)
            hb.run(xs[: hb.batch])  # warm-up
            n = n_var if var else n_time
            _, st, sec = hb.run(xs[:n])
            e = pos_err_m(hb.run(xs_ref)[0], tr)
            label = f"{name}{' +STM' if var else ''}"
            rows.append((label, tol, e, n / sec, st / n, hb.compile_s, hb.order))
    hdr = f"{'case':<18}{'tol':>8}{'err m':>10}{'props/s':>11}{'steps/prop':>12}{'compile s':>11}{'order':>7}"
    print("\n" + hdr + "\n" + "-" * len(hdr))
    for label, tol, e, ps, spp, cs, order in rows:
        print(f"{label:<18}{tol:>8.0e}{e:>10.3g}{ps:>11.0f}{spp:>12.1f}{cs:>11.2f}{order:>7}")
    case = CASES["leo_j2"]
    for tol in (1e-15, rows[0][1]):
        col, fro = _stm_fd_check(case, np.asarray(case.x0, dtype=np.float64), tol)
        print(f"leo_j2 STM (var_ode_sys, tol {tol:g}) vs central differences: max column rel {col:.1e}, ", end="")
        print(f"Frobenius rel {fro:.1e}")
    print(f"self-test total {time.perf_counter() - t_all:.0f} s")


if __name__ == "__main__":
    _self_test(cold="--cold" in sys.argv[1:])
