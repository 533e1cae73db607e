"""The plot of a sweep table: each output against the varied field (a contour for two
fields on a grid, marked at every computed study; against the study index otherwise),
written with savefig_atomic."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from fracas.io.atomic import savefig_atomic
from fracas.io.sweep_table import SweepTable, read_sweep_table

__all__ = ["plot_sweep", "sweep_figure"]


def _log(x: np.ndarray) -> bool:
    x = x[np.isfinite(x)]
    return x.size > 1 and bool(np.all(x > 0)) and x.max() / x.min() >= 100


def sweep_figure(t: SweepTable):
    """Every output of the sweep table ``t`` (a :class:`~fracas.io.sweep_table.SweepTable`)
    in one matplotlib figure: a filled contour over two numeric fields, with a marker at
    every computed study (failed studies as red crosses); a line against one field or the
    study index otherwise."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = np.array([s == "ok" for s in t.status], dtype=bool)
    fields = list(t.inputs)
    names = list(t.outputs)
    numeric = [f for f in fields if t.inputs[f].dtype != object]
    n = max(1, len(names))
    fig, axes = plt.subplots(n, 1, figsize=(7, 3.3 * n + 0.4), squeeze=False)
    lab = lambda c: f"{c} ({t.units.get(c) or '1'})"  # noqa: E731
    for ax, name in zip(axes[:, 0], names):
        y = np.asarray(t.outputs[name], dtype=float)
        if len(fields) == 2 and len(numeric) == 2 and ok.sum() >= 3:
            x0, x1 = (np.asarray(t.inputs[f], dtype=float) for f in fields)
            try:
                cs = ax.tricontourf(x0[ok], x1[ok], y[ok], levels=12)
                fig.colorbar(cs, ax=ax, label=lab(name))
                ax.plot(x0[ok], x1[ok], "o", ms=4, mfc="white", mec="k", mew=0.8, clip_on=False, label="computed study")
            except (ValueError, RuntimeError):  # collinear points: a coloured scatter
                sc = ax.scatter(x0[ok], x1[ok], c=y[ok], edgecolors="k", label="computed study")
                fig.colorbar(sc, ax=ax, label=lab(name))
            if (~ok).any():
                ax.plot(x0[~ok], x1[~ok], "x", color="red", ms=7, mew=1.5, clip_on=False, label="failed study")
            ax.set_xlabel(lab(fields[0]))
            ax.set_ylabel(lab(fields[1]))
            if _log(x0):
                ax.set_xscale("log")
            if _log(x1):
                ax.set_yscale("log")
            ax.set_title(name, fontsize=9)
            ax.legend(fontsize=7, loc="best", framealpha=0.8)
        else:
            if len(fields) == 1 and numeric:
                x = np.asarray(t.inputs[fields[0]], dtype=float)
                xl = lab(fields[0])
            else:
                x = np.asarray(t.index, dtype=float)
                xl = "study index"
            order = np.argsort(x[ok])
            ax.plot(x[ok][order], y[ok][order], "o-")
            ax.set_xlabel(xl)
            ax.set_ylabel(lab(name))
            if _log(x):
                ax.set_xscale("log")
            if _log(y):
                ax.set_yscale("log")
        ax.grid(True, alpha=0.3)
    fig.suptitle(t.attrs.get("title") or "sweep", fontsize="medium", wrap=True)
    fig.tight_layout()
    return fig


def plot_sweep(table: str | os.PathLike, path: str | os.PathLike) -> Path:
    """Plot every output of the sweep table ``table`` (:func:`sweep_figure`) into the PNG
    ``path``; returns it."""
    import matplotlib.pyplot as plt

    fig = sweep_figure(read_sweep_table(table))
    try:
        return savefig_atomic(fig, path, dpi=110)
    finally:
        plt.close(fig)
