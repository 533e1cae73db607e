"""Accuracy the bundled trajectory decks get from their [integrator] settings.

    .venv/bin/python benchmarks/deck_accuracy.py          # ~2 min

For every trajectory deck in namelists/: the final position with the deck's own settings,
against (a) the same deck at a 100x tighter tolerance with DOP853 and DPRKN12 (a
self-convergence estimate, Cowell), and (b) FRACAS's Encke/RKN4 at the deck default c_nom
0.3 (what the deck gave before tolerances), so the table shows the error an analyst gets by
default and what the old default gave.  The independent checks of each method against scipy
DOP853 are in tests/integrate/.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fracas.build import build_propagation  # noqa: E402
from fracas.config.trajectory import load_deck  # noqa: E402
from fracas.dynamics.model import IntegratorSettings  # noqa: E402
from fracas.integrate.propagate import propagate  # noqa: E402


def run(prob, st):
    m = dataclasses.replace(prob.model, integrator=st)
    t0 = time.perf_counter()
    tr = propagate(m, prob.params, prob.ephem, prob.epoch_et_s, prob.x0, prob.t_out)
    x = np.asarray(tr.x_final)
    return x, int(tr.n_steps), time.perf_counter() - t0, int(tr.status)


def main():
    rows = []
    for path in sorted((ROOT / "namelists").glob("*.toml")):
        text = path.read_text()
        if "mode =" in text and 'mode = "propagate"' not in text:
            continue
        prob = build_propagation(load_deck(path))
        st = prob.model.integrator
        x, n, _, status = run(prob, st)
        method_ref = "dop853" if prob.model.thrust else "dprkn12"
        tight = dataclasses.replace(
            st, method=method_ref, formulation="cowell", step_control="tolerance", tolerance=1e-14, dt_max_s=np.inf
        )
        x_ref, n_ref, _, _ = run(prob, tight)
        old = IntegratorSettings(max_steps=st.max_steps, eps_t_s=st.eps_t_s)
        x_old, n_old, _, _ = run(prob, old)
        rule = f"tol {st.tolerance:g}" if st.adaptive else f"c_nom {st.c_nom:g}"
        rows.append(
            (
                path.name,
                f"{st.method} {st.formulation} {rule}",
                n,
                np.linalg.norm(x[:3] - x_ref[:3]) * 1e3,
                abs(x[6] - x_ref[6]) * 1e3,
                np.linalg.norm(x_old[:3] - x_ref[:3]) * 1e3,
                n_old,
                status,
            )
        )
    print(f"{'deck':<28}{'integrator':<34}{'steps':>7}{'err m':>11}{'mass g':>9}{'c_nom 0.3 m':>14}{'steps':>7}")
    for r in rows:
        print(f"{r[0]:<28}{r[1]:<34}{r[2]:>7}{r[3]:>11.3g}{r[4]:>9.2g}{r[5]:>14.3g}{r[6]:>7}")
    print("err: final position against the same deck by DOP853/DPRKN12 (Cowell) at tolerance 1e-14.")


if __name__ == "__main__":
    main()
