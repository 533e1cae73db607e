"""Accuracy the bundled trajectory decks get from their [integrator] settings.

    .venv/bin/python benchmarks/deck_accuracy.py          # ~2-4 min

For every trajectory deck in namelists/: the final position with the deck's own settings,
against (a) the same deck at a 100x tighter tolerance with DOP853 and DPRKN12 (a
self-convergence estimate, Cowell), and (b) FRACAS's Encke/RKN4 at the deck default c_nom
0.3 (what the deck gave before tolerances), so the table shows the error an analyst gets by
default and what the old default gave.  The independent checks of each method against scipy
DOP853 are in tests/integrate/.

Every run's status is checked (benchmarks/runs.py): a figure that involves a run that did not
end as asked (status 2 maximum steps, 3 non-finite, ...) is printed as "FAILED (status N:
meaning)" instead of a distance to the abort point (issue 32 1b), and the script then exits 1.
The status column gives the three runs' codes: deck / reference / c_nom 0.3.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from runs import failure, statuses  # noqa: E402

from fracas.build import build_propagation  # noqa: E402
from fracas.config.trajectory import load_deck  # noqa: E402
from fracas.dynamics.model import IntegratorSettings  # noqa: E402
from fracas.integrate.propagate import propagate  # noqa: E402


def run(prob, st):
    m = dataclasses.replace(prob.model, integrator=st)
    t0 = time.perf_counter()
    tr = propagate(m, prob.params, prob.ephem, prob.epoch_et_s, prob.x0, prob.t_out)
    return tr, time.perf_counter() - t0


def diff(a, b, fmt, part):
    """``fmt`` of |part(a) - part(b)| * 1e3, or the FAILED text of whichever run failed."""
    for tr in (a, b):
        f = failure(tr)
        if f is not None:
            return f
    return format(float(np.linalg.norm(part(np.asarray(a.x_final)) - part(np.asarray(b.x_final)))) * 1e3, fmt)


def main():
    rows = []
    for path in sorted((ROOT / "namelists").glob("*.toml")):
        text = path.read_text()
        if "mode =" in text and 'mode = "propagate"' not in text:
            continue
        prob = build_propagation(load_deck(path))
        st = prob.model.integrator
        tr, _ = run(prob, st)
        method_ref = "dop853" if prob.model.thrust else "dprkn12"
        tight = dataclasses.replace(
            st, method=method_ref, formulation="cowell", step_control="tolerance", tolerance=1e-14, dt_max_s=np.inf
        )
        tr_ref, _ = run(prob, tight)
        old = IntegratorSettings(max_steps=st.max_steps, eps_t_s=st.eps_t_s)
        tr_old, _ = run(prob, old)
        rule = f"tol {st.tolerance:g}" if st.adaptive else f"c_nom {st.c_nom:g}"
        rows.append(
            (
                path.name,
                f"{st.method} {st.formulation} {rule}",
                int(tr.n_steps),
                diff(tr, tr_ref, ".3g", lambda x: x[:3]),
                diff(tr, tr_ref, ".2g", lambda x: x[6:7]),
                diff(tr_old, tr_ref, ".3g", lambda x: x[:3]),
                int(tr_old.n_steps),
                "/".join(str(int(statuses(t)[0])) for t in (tr, tr_ref, tr_old)),
                any(failure(t) for t in (tr, tr_ref, tr_old)),
            )
        )
    w0 = max(28, max(len(r[0]) for r in rows) + 2)
    print(
        f"{'deck':<{w0}}{'integrator':<34}{'steps':>7}{'err m':>11}{'mass g':>9}{'c_nom 0.3 m':>14}{'steps':>7}"
        f"{'status':>9}"
    )
    for r in rows:
        print(f"{r[0]:<{w0}}{r[1]:<34}{r[2]:>7}{r[3]:>11}{r[4]:>9}{r[5]:>14}{r[6]:>7}{r[7]:>9}")
    print("err: final position against the same deck by DOP853/DPRKN12 (Cowell) at tolerance 1e-14.")
    print("status: deck / reference / c_nom 0.3 runs (0 reached the final time, 1 stop condition met,")
    print("2 max steps, 3 non-finite); a figure from a run that did not end as asked reads FAILED (status N: meaning).")
    failed = [r[0] for r in rows if r[8]]
    if failed:
        sys.exit(f"error: runs failed for {len(failed)} deck(s): {', '.join(failed)}")


if __name__ == "__main__":
    main()
