"""The plot of a sweep table: each output against the varied field (a contour for two
fields on a grid; against the study index otherwise), written with savefig_atomic."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from fracas.io.atomic import savefig_atomic
from fracas.io.sweep_table import read_sweep_table

__all__ = ["plot_sweep"]


def _log(x: np.ndarray) -> bool:
    x = x[np.isfinite(x)]
    return x.size > 1 and bool(np.all(x > 0)) and x.max() / x.min() >= 100


def plot_sweep(table: str | os.PathLike, path: str | os.PathLike) -> Path:
    """Plot every output of the sweep table ``table`` into the PNG ``path``; returns it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = read_sweep_table(table)
    ok = np.array([s == "ok" for s in t.status], dtype=bool)
    fields = list(t.inputs)
    names = list(t.outputs)
    numeric = [f for f in fields if t.inputs[f].dtype != object]
    n = max(1, len(names))
    fig, axes = plt.subplots(n, 1, figsize=(7, 3.2 * n), squeeze=False)
    lab = lambda c: f"{c} [{t.units.get(c, '')}]"  # noqa: E731
    for ax, name in zip(axes[:, 0], names):
        y = np.asarray(t.outputs[name], dtype=float)
        if len(fields) == 2 and len(numeric) == 2 and ok.sum() >= 3:
            x0, x1 = (np.asarray(t.inputs[f], dtype=float) for f in fields)
            try:
                cs = ax.tricontourf(x0[ok], x1[ok], y[ok], levels=12)
                fig.colorbar(cs, ax=ax, label=lab(name))
            except (ValueError, RuntimeError):  # collinear points: a coloured scatter
                sc = ax.scatter(x0[ok], x1[ok], c=y[ok])
                fig.colorbar(sc, ax=ax, label=lab(name))
            ax.set_xlabel(lab(fields[0]))
            ax.set_ylabel(lab(fields[1]))
            if _log(x0):
                ax.set_xscale("log")
            if _log(x1):
                ax.set_yscale("log")
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
    fig.suptitle(t.attrs.get("title") or "sweep")
    fig.tight_layout()
    try:
        return savefig_atomic(fig, path, dpi=110)
    finally:
        plt.close(fig)
