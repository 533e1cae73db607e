"""Printing helpers shared by the benchmarks: aligned tables, SI-prefixed numbers."""

from __future__ import annotations


def emit(s=""):
    print(s, flush=True)


def table(headers, rows, note=None):
    """A left-aligned first column, right-aligned others, a dashed rule under the header."""
    cells = [list(map(str, headers))] + [[str(c) for c in r] for r in rows]
    w = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    for k, r in enumerate(cells):
        emit("  ".join(c.ljust(w[i]) if i == 0 else c.rjust(w[i]) for i, c in enumerate(r)))
        if k == 0:
            emit("  ".join("-" * x for x in w))
    if note:
        emit(note)


def si(x):
    """3 significant digits with a k/M suffix."""
    for f, s in ((1e6, "M"), (1e3, "k")):
        if abs(x) >= f:
            return f"{x / f:.3g}{s}"
    return f"{x:.3g}"
