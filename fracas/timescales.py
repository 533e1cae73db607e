"""Calendar epochs <-> TDB seconds past J2000 (no JAX: the config layer uses it too).

TDB is a uniform scale (no leap seconds), so every day has 86400 s; 2000-01-01T12:00:00 TDB
maps to 0.  Epochs in decks are ISO calendar strings (TDB) or Julian dates (TDB).
"""

from __future__ import annotations

import math
import re
from fractions import Fraction

from fracas import constants
from fracas.errors import ConfigError

_ISO = re.compile(
    r"^\s*([+-]?\d{4,})-(\d{1,2})-(\d{1,2})"
    r"(?:[T ](\d{1,2}):(\d{2})(?::(\d{2})(\.\d*)?)?)?\s*(?:TDB)?\s*$",
    re.IGNORECASE,
)


def _gregorian_to_jdn(year: int, month: int, day: int) -> int:
    """Julian day number (the JD at noon) of a proleptic Gregorian date (integer arithmetic)."""
    a = (14 - month) // 12
    y = year + 4800 - a
    m = month + 12 * a - 3
    return day + (153 * m + 2) // 5 + 365 * y + y // 4 - y // 100 + y // 400 - 32045


def _jdn_to_gregorian(jdn: int) -> tuple[int, int, int]:
    a = jdn + 32044
    b = (4 * a + 3) // 146097
    c = a - 146097 * b // 4
    d = (4 * c + 3) // 1461
    e = c - 1461 * d // 4
    m = (5 * e + 2) // 153
    day = e - (153 * m + 2) // 5 + 1
    month = m + 3 - 12 * (m // 10)
    year = 100 * b + d - 4800 + m // 10
    return year, month, day


def calendar_to_et(iso: str) -> float:
    """TDB seconds past J2000 of an ISO date 'YYYY-MM-DD[THH:MM[:SS[.fff]]]' read as TDB.

    Plain Julian-date arithmetic on the proleptic Gregorian calendar: TDB is a uniform
    scale (no leap seconds), so every day has 86400 s; 2000-01-01T12:00:00 maps to 0.
    The result is the float64 nearest to the exact value.
    """
    match = _ISO.match(iso) if isinstance(iso, str) else None
    if match is None:
        raise ConfigError(f"date {iso!r}: expected ISO 'YYYY-MM-DDTHH:MM:SS[.fff]' (TDB)")
    year, month, day = (int(g) for g in match.group(1, 2, 3))
    hour = int(match.group(4) or 0)
    minute = int(match.group(5) or 0)
    second = int(match.group(6) or 0)
    frac = match.group(7) or ""
    if not 1 <= month <= 12:
        raise ConfigError(f"date {iso!r}: month {month} not in 1..12")
    days_in_month = _gregorian_to_jdn(*((year, month + 1, 1) if month < 12 else (year + 1, 1, 1))) - (
        _gregorian_to_jdn(year, month, 1)
    )
    if not 1 <= day <= days_in_month:
        raise ConfigError(f"date {iso!r}: day {day} not in 1..{days_in_month}")
    if hour > 23 or minute > 59 or second > 59:
        raise ConfigError(f"date {iso!r}: time of day out of range (TDB has no leap seconds)")
    jdn = _gregorian_to_jdn(year, month, day)
    whole = (jdn - int(constants.J2000_JD)) * constants.SECONDS_PER_DAY + (hour - 12) * 3600 + minute * 60 + second
    exact = Fraction(whole) + (Fraction(frac) if len(frac) > 1 else 0)
    return float(exact)


def et_to_calendar(et: float, digits: int = 3) -> str:
    """ISO 'YYYY-MM-DDTHH:MM:SS.fff' (TDB) of ``et`` TDB s past J2000, rounded to ``digits``."""
    et_f = float(et)
    if not math.isfinite(et_f):
        raise ConfigError(f"et_to_calendar: time {et!r} is not finite")
    scale = 10**digits
    ticks = round(Fraction(et_f) * scale) + 43200 * scale  # from 2000-01-01T00:00:00
    days, rem = divmod(ticks, constants.SECONDS_PER_DAY * scale)
    year, month, day = _jdn_to_gregorian(int(constants.J2000_JD) + days)
    secs, sub = divmod(rem, scale)
    hh, rest = divmod(secs, 3600)
    mm, ss = divmod(rest, 60)
    ystr = f"{year:04d}" if year >= 0 else f"-{-year:04d}"
    text = f"{ystr}-{month:02d}-{day:02d}T{hh:02d}:{mm:02d}:{ss:02d}"
    if digits > 0:
        text += f".{sub:0{digits}d}"
    return text


def epoch_to_et(value: str | float) -> float:
    """TDB seconds past J2000 of an ISO TDB string or a Julian date (TDB) number."""
    if isinstance(value, str):
        return calendar_to_et(value)
    return (float(value) - constants.J2000_JD) * constants.DAY_S


__all__ = ["calendar_to_et", "et_to_calendar", "epoch_to_et"]
