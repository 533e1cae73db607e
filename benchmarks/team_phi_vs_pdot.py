"""PHI vs PDOT on the Mercury study (FRACAS Appendix 9.3, Table 2) and the effective-bias
relation sigma_bias ~ (0.30 + 0.05 tau[days]) sigma_noise (Appendix 9.3 eq. 5).

1. The Mercury approach study (namelists/mercury_approach_team.toml) is run with
   transition matrices + DYNO's Q~ (PHI) and with the covariance differential equations
   and augmented Gauss-Markov noise states (PDOT).  Printed like Table 2: 1-sigma and
   correlations of the state after the tracking, and the ratio PHI/PDOT.
2. Effective bias: the same trajectory with no tracking, the a-priori state tiny, thrust
   errors either as Gauss-Markov noise (PDOT: exact for the Gauss-Markov model) with
   sigma_noise and correlation time tau, or as constant biases of sigma 1 x sigma_noise.
   Position errors of a bias scale linearly with its sigma, so the effective-bias ratio
   is RSS(noise) / RSS(unit bias) at the end of the propagation.

    .venv/bin/python benchmarks/team_phi_vs_pdot.py [--days 40]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from runs import main_guard, require  # noqa: E402

from fracas.build.team import build_study  # noqa: E402
from fracas.config.team import parse_team_deck  # noqa: E402
from fracas.team.eigen import eigen_summary  # noqa: E402
from fracas.team.engine import run_study  # noqa: E402
from fracas.team.reference import integrate_reference  # noqa: E402

DECK = ROOT / "namelists" / "mercury_approach_team.toml"


def study_from_text(text: str):
    return build_study(parse_team_deck(text, str(DECK)))


def run(text: str):
    st = study_from_text(text)
    ref = integrate_reference(st)
    t0 = time.perf_counter()
    res = run_study(st, ref)
    return require(res, "TEAM study", ok=(0,)), time.perf_counter() - t0


def table(title, P, labels):
    e = eigen_summary(P)
    print(f"\n{title}")
    print("STD DEV        " + "".join(f"{c:>10s}" for c in labels[:6]))
    for i in range(6):
        print(f"{labels[i]:<3s} {e.sigma[i]:12.6g}  " + "".join(f"{e.corr[i, j]:10.6f}" for j in range(i + 1)))
    return e


def phi_vs_pdot(at_days: float):
    text = DECK.read_text()
    out = {}
    for mode in ("phi", "pdot"):
        t = text.replace('propagation = "phi"', f'propagation = "{mode}"')
        res, dt = run(t)
        k = int(np.argmin(np.abs(res.times_s / 86400.0 - at_days)))
        out[mode] = (res.Pa_plus[k][:6, :6], dt, res.times_s[k] / 86400.0)
    labels = ["X", "Y", "Z", "VX", "VY", "VZ"]
    ep = table(f"PDOT state errors at t = {out['pdot'][2]:.2f} d (assumed knowledge; km, km/s)", out["pdot"][0], labels)
    eh = table(f"PHI state errors at t = {out['phi'][2]:.2f} d", out["phi"][0], labels)
    r = eh.sigma[:6] / ep.sigma[:6]
    print("\nPHI / PDOT 1-sigma ratio: " + "  ".join(f"{lab} {v:.3f}" for lab, v in zip(labels, r)))
    print(f"position RSS  PHI {eh.pos_rss:.4g} km  PDOT {ep.pos_rss:.4g} km  ratio {eh.pos_rss / ep.pos_rss:.3f}")
    print(
        f"velocity RSS  PHI {eh.vel_rss * 1e6:.4g} mm/s  PDOT {ep.vel_rss * 1e6:.4g} mm/s  ratio {eh.vel_rss / ep.vel_rss:.3f}"  # noqa: E501
    )
    print(f"max |corr difference| (state block): {np.max(np.abs(eh.corr[:6, :6] - ep.corr[:6, :6])):.3f}")
    print(f"run time (warm-ish, one run each): PHI {out['phi'][1]:.2f} s, PDOT {out['pdot'][1]:.2f} s")


def study_from_dict(d: dict):
    from fracas.config.team import TeamDeck

    deck = TeamDeck.model_validate(d)
    deck._source_path = str(DECK)
    return build_study(deck)


def run_dict(d: dict):
    st = study_from_dict(d)
    ref = integrate_reference(st)
    return require(run_study(st, ref), "TEAM study", ok=(0,))


def effective_bias(days: float):
    import copy

    import tomllib

    base = tomllib.loads(DECK.read_text())
    for key in ("tracking", "event", "parameter", "gencov", "punch", "thrust_noise"):
        base.pop(key, None)
    base["a_priori"] = {"position_rss_km": 1e-6, "velocity_rss_km_s": 1e-9}
    base["filter"]["stop_days"] = days
    sig = {"proportionality": 0.02, "in_plane_deg": 0.5, "out_of_plane_deg": 0.5}
    print(
        f"\nEffective bias after {days:g} days without tracking (Appendix 9.3 eq. 5); "
        "noise 2 %, 0.5 deg, 0.5 deg; bias of the same sigmas"
    )
    print(f"{'tau (d)':>8s} {'RSS noise (km)':>15s} {'RSS unit bias (km)':>19s} {'ratio':>8s} {'0.30+0.05tau':>13s}")
    bias = copy.deepcopy(base)
    bias["parameter"] = [
        {"label": "thrust_scale", "sigma": 0.02, "role": "consider"},
        {"label": "bias_in_rad", "sigma": 0.0087266, "role": "consider"},
        {"label": "bias_out_rad", "sigma": 0.0087266, "role": "consider"},
    ]
    rss_b = eigen_summary(run_dict(bias).Pa_plus[-1]).pos_rss
    for tau in (0.5, 1.0, 2.0, 5.0, 10.0):
        noise = copy.deepcopy(base)
        noise["thrust_noise"] = {k: {"sigma": v, "tau_days": tau} for k, v in sig.items()}
        noise["errcon"] = {"propagation": "pdot"}
        rss_n = eigen_summary(run_dict(noise).Pa_plus[-1]).pos_rss
        print(f"{tau:8.2f} {rss_n:15.5g} {rss_b:19.5g} {rss_n / rss_b:8.3f} {0.30 + 0.05 * tau:13.3f}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--at-days", type=float, default=40.0, help="time of the Table-2 comparison")
    ap.add_argument("--bias-days", type=float, default=40.0, help="propagation span of the effective-bias check")
    a = ap.parse_args()
    phi_vs_pdot(a.at_days)
    effective_bias(a.bias_days)


if __name__ == "__main__":
    main_guard(main)
