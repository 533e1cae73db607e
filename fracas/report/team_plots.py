"""The PNG of a TEAM results file's knowledge history (:func:`team_figure`, :func:`plot_team`)
and every plot of the file (:func:`plot_all`: the history and the guidance plots of
:mod:`fracas.report.guidance_plots`).  Reads :func:`fracas.io.team_results.read_team_results`'s
dict (``r``); everything here is re-exported by :mod:`fracas.report.team`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from fracas.constants import DAY_S
from fracas.report._tables import _vfactor
from fracas.report.guidance_plots import (
    bplane_figure,
    budget_figure,
    correlation_figure,
    dv_figure,
    mark_guidance,
    save_figure,
)


def team_figure(r: dict, velocity_unit: str = "mm/s") -> Any:
    """Position and velocity RSS 1σ and parameter 1σ (relative to a priori) against time, a
    matplotlib figure; velocities in ``velocity_unit`` (the printout's).

    With guidance events in the file (``r["guidance"]``), vertical lines mark them; with a
    control covariance (``r["control"]``), its RSS 1σ (the actual dispersion about the
    reference) is a third curve.  Without either the figure is what it always was."""
    import matplotlib

    matplotlib.use("Agg")

    import matplotlib.pyplot as plt

    vf = _vfactor(velocity_unit)
    nx = int(r["attrs"].get("n_state", 7))
    t = r["times_s"] / DAY_S
    fig, ax = plt.subplots(3, 1, figsize=(8, 9), sharex=True)
    for which, style in (("assumed", "-"), ("true", "--")):
        if which not in r:
            continue
        P = r[which]["P_plus"]
        pos = np.sqrt(np.clip(np.einsum("kii->k", P[:, :3, :3]), 0, None))
        vel = np.sqrt(np.clip(np.einsum("kii->k", P[:, 3:6, 3:6]), 0, None)) * vf
        ax[0].semilogy(t, pos, style, label=which)
        ax[1].semilogy(t, vel, style, label=which)
    if r.get("control") is not None:
        P = np.asarray(r["control"]["P_plus"])
        pos = np.sqrt(np.clip(np.einsum("kii->k", P[:, :3, :3]), 0, None))
        vel = np.sqrt(np.clip(np.einsum("kii->k", P[:, 3:6, 3:6]), 0, None)) * vf
        ax[0].semilogy(t, pos, ":", label="control (actual dispersion)")
        ax[1].semilogy(t, vel, ":", label="control (actual dispersion)")
    ax[0].set_ylabel("position RSS 1σ (km)")
    ax[1].set_ylabel(f"velocity RSS 1σ ({velocity_unit})")
    A = r["assumed"]
    for i, lab in enumerate(r["labels"]):
        prior = A["a_priori_sigma"][i]
        if i >= nx and prior > 0 and r["roles"][i] == "solve_for":
            ax[2].plot(t, A["sigma"][:, i] / prior, label=lab)
    ax[2].set_ylabel("solve-for 1σ / a priori")
    ax[2].set_xlabel("days from the trajectory epoch")
    if r.get("guidance"):
        mark_guidance(r, ax)
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(f"TEAM knowledge: {r['attrs']['title']}")
    fig.tight_layout()
    return fig


def plot_team(r: dict, png: str | Path, velocity_unit: str = "mm/s") -> Path:
    """Write :func:`team_figure` as a PNG at ``png`` (atomically); returns the path."""
    return save_figure(team_figure(r, velocity_unit), png)


def plot_all(r: dict, png: str | Path, velocity_unit: str = "mm/s", dv_unit: str = "m/s") -> list[Path]:
    """Every plot of a results file: the knowledge history at ``png`` (:func:`plot_team`)
    and, where they apply, ``<stem>_bplane.png`` (guidance events targeting B·T and B·R),
    ``<stem>_correlation.png`` (an eigenvector event), ``<stem>_budget.png`` (an error
    budget) and ``<stem>_dv.png`` (guidance events) beside it; the paths written, in that
    order, each atomically.  Velocities in ``velocity_unit`` and ΔV in ``dv_unit``, the
    printout's (:func:`print_team`)."""
    png = Path(png)
    out = [plot_team(r, png, velocity_unit)]
    for suffix, fig in team_figures(r, velocity_unit, dv_unit, knowledge=False)[1:]:
        out.append(save_figure(fig, png.with_name(f"{png.stem}_{suffix}.png")))
    return out


def team_figures(r: dict, velocity_unit: str = "mm/s", dv_unit: str = "m/s", knowledge: bool = True) -> list:
    """(suffix, figure) of every plot :func:`plot_all` writes ("" for the knowledge
    history, first), built and not saved; the knowledge history is built only if
    ``knowledge`` (else its entry is ("", None))."""
    figs = [("", team_figure(r, velocity_unit) if knowledge else None)]
    for suffix, fig in (
        ("bplane", bplane_figure(r)),
        ("correlation", correlation_figure(r)),
        ("budget", budget_figure(r, velocity_unit, dv_unit)),
        ("dv", dv_figure(r, dv_unit)),
    ):
        if fig is not None:
            figs.append((suffix, fig))
    return figs
