"""A layout check for matplotlib figures: every drawn text inside the figure, no two titles
overlapping (:func:`text_problems`, :func:`assert_layout`).

The figure is drawn with its renderer (layout engines run at draw time), then every visible
text artist that the draw shows -- suptitle, axes titles, axis labels, the tick labels of
ticks inside the view, offset texts, legend texts and titles, annotations and free texts,
in insets and colorbars too -- has its window extent compared with the figure's bbox."""

from __future__ import annotations

import itertools

from matplotlib.axis import Axis
from matplotlib.text import Text

__all__ = ["text_problems", "assert_layout", "drawn_texts"]


def _drawn_ticks(axis: Axis) -> list:
    """The ticks the last draw showed (inside the view interval)."""
    try:
        return list(axis._update_ticks())  # what Axis.draw itself draws
    except AttributeError:  # pragma: no cover - a matplotlib without the private helper
        lo, hi = sorted(axis.get_view_interval())
        return [t for t in axis.get_major_ticks() + axis.get_minor_ticks() if lo <= t.get_loc() <= hi]


def drawn_texts(artist, kind: str = "") -> list[tuple[str, Text]]:
    """(kind, text) of every visible, non-empty text under ``artist`` (a figure), skipping
    whatever an invisible ancestor hides and ticks outside the view."""
    out: list[tuple[str, Text]] = []
    if not artist.get_visible():
        return out
    if isinstance(artist, Text):
        if artist.get_text().strip():
            out.append((kind or type(artist).__name__, artist))
        return out
    if isinstance(artist, Axis):
        name = artist.axis_name
        out += drawn_texts(artist.label, f"{name} label")
        out += drawn_texts(artist.offsetText, f"{name} offset text")
        for tick in _drawn_ticks(artist):
            if tick.get_visible():
                out += drawn_texts(tick.label1, f"{name} tick label")
                out += drawn_texts(tick.label2, f"{name} tick label")
        return out
    titles = {id(getattr(artist, a, None)) for a in ("title", "_left_title", "_right_title")}
    for child in artist.get_children():
        k = kind
        if type(child).__name__ == "Legend":
            k = "legend"
        elif child is getattr(artist, "_suptitle", None):
            k = "suptitle"
        elif id(child) in titles:
            k = "title"
        out += drawn_texts(child, k)
    return out


def _titles(fig) -> list[tuple[str, Text]]:
    titles = []
    sup = getattr(fig, "_suptitle", None)
    if sup is not None and sup.get_visible() and sup.get_text().strip():
        titles.append(("suptitle", sup))

    def walk(ax, where):
        if not ax.get_visible():
            return
        for t in (ax.title, ax._left_title, ax._right_title):
            if t.get_visible() and t.get_text().strip():
                titles.append((f"title of {where}", t))
        for j, child in enumerate(getattr(ax, "child_axes", [])):
            walk(child, f"{where} inset {j}")

    for i, ax in enumerate(fig.axes):
        walk(ax, f"axes {i}")
    return titles


def text_problems(fig, tol_px: float = 0.5) -> list[str]:
    """Every text drawn (partly) outside the figure and every pair of overlapping titles,
    one line each; [] for a clean figure."""
    if fig.canvas is None or not hasattr(fig.canvas, "get_renderer"):
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        FigureCanvasAgg(fig)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    fb = fig.bbox
    problems = []
    for kind, t in drawn_texts(fig):
        bb = t.get_window_extent(renderer)
        if bb.x0 < fb.x0 - tol_px or bb.y0 < fb.y0 - tol_px or bb.x1 > fb.x1 + tol_px or bb.y1 > fb.y1 + tol_px:
            problems.append(
                f"{kind} {t.get_text()[:60]!r} clipped: extent x {bb.x0:.0f}..{bb.x1:.0f}, y {bb.y0:.0f}..{bb.y1:.0f} "
                f"outside the figure 0..{fb.x1:.0f} x 0..{fb.y1:.0f} px"
            )
    titles = _titles(fig)
    for (ka, a), (kb, b) in itertools.combinations(titles, 2):
        ba, bb = a.get_window_extent(renderer), b.get_window_extent(renderer)
        if ba.overlaps(bb):
            problems.append(f"{ka} {a.get_text()[:40]!r} overlaps {kb} {b.get_text()[:40]!r}")
    return problems


def assert_layout(fig, what: str = "figure") -> None:
    """Fail with every problem of :func:`text_problems`."""
    problems = text_problems(fig)
    assert not problems, f"{what}:\n  " + "\n  ".join(problems)
