"""The table helpers the TEAM printouts and plots share (:mod:`fracas.report.team`,
:mod:`fracas.report.guidance`, :mod:`fracas.report.guidance_plots`): one compact number
format, rich tables that fit a terminal (text columns fold, number columns never wrap), one
velocity unit per printout (ΔV in its own unit)."""

from __future__ import annotations

from typing import Any

import numpy as np

#: velocity units the printout can use -> factor from km/s
VELOCITY_UNITS = {"km/s": 1.0, "m/s": 1e3, "mm/s": 1e6}


def _vfactor(velocity_unit: str) -> float:
    if velocity_unit not in VELOCITY_UNITS:
        raise ValueError(f"velocity_unit must be one of {', '.join(VELOCITY_UNITS)}, not {velocity_unit!r}")
    return VELOCITY_UNITS[velocity_unit]


def _unit(u: str, velocity_unit: str) -> tuple[float, str]:
    """(factor, unit shown) of a value in unit ``u``: km/s becomes ``velocity_unit``."""
    return (_vfactor(velocity_unit), velocity_unit) if u == "km/s" else (1.0, u)


def _dv(x_km_s: float, dv_unit: str) -> float:
    """A ΔV of ``x_km_s`` km/s in ``dv_unit``."""
    return float(x_km_s) * _vfactor(dv_unit)


def _output_unit(name: str, unit: str, velocity_unit: str, dv_unit: str) -> tuple[float, str]:
    """(factor, unit shown) of a budget output: a ΔV (name with "dv"/"ΔV") in km/s goes to
    ``dv_unit``, another velocity to ``velocity_unit``."""
    if unit == "km/s" and ("dv" in name.lower() or "δv" in name.lower()):
        return _vfactor(dv_unit), dv_unit
    return _unit(unit, velocity_unit)


def _fmt(x: float) -> str:
    """The one compact number format of the tables (at most 10 characters)."""
    return f"{x:.4g}" if np.isfinite(x) else ("nan" if np.isnan(x) else f"{x}")


def _table(title: str, boxed: bool = True) -> Any:
    from rich import box
    from rich.table import Table

    return Table(
        title=title,
        title_justify="left",
        show_edge=False,
        pad_edge=False,
        box=box.HEAVY_HEAD if boxed else None,
        header_style="bold",
    )


def _num_col(t: Any, header: str) -> None:
    t.add_column(header, justify="right", no_wrap=True)


def _text_col(t: Any, header: str, justify: str = "left") -> None:
    t.add_column(header, justify=justify, overflow="fold")


def fit_line(line: str, width: int = 80) -> str:
    """A line as it is when it fits ``width`` columns, else wrapped at word boundaries with
    indented continuation lines: never cut, never broken mid-word (a word longer than a
    line, such as a long path, stays whole on a line of its own)."""
    if len(line) <= width:
        return line
    import textwrap

    lead = line[: len(line) - len(line.lstrip())]
    lines = textwrap.wrap(
        line.strip(),
        width,
        initial_indent=lead,
        subsequent_indent=lead + "    ",
        break_long_words=False,
        break_on_hyphens=False,
    )
    return "\n".join(s if len(s) <= width else s.lstrip() for s in lines)  # a long word: no indent
