"""Field problems: a validation failure that knows its field and value (the trajectory deck's
and every other deck's one-line errors, :mod:`fracas.config.trajectory.messages`).
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel


class FieldProblem(ValueError):
    """A validation failure that knows which (sub)field it concerns and its offending value.

    ``field`` is a path relative to the model being validated (``("stop", "radius_km")``);
    :func:`format_validation_error` appends it to pydantic's location.
    """

    def __init__(self, field: tuple[str | int, ...] | str, value: Any, expected: str):
        self.field = (field,) if isinstance(field, str) else tuple(field)
        self.value = value
        self.expected = expected
        super().__init__(expected)


class FieldProblems(ValueError):
    """Several :class:`FieldProblem` found by one validator (all of them are reported)."""

    def __init__(self, problems: list[FieldProblem]):
        self.problems = list(problems)
        super().__init__("; ".join(p.expected for p in problems))


def raise_problems(problems: list[FieldProblem]) -> None:
    """Raise the problems a cross-check collected (nothing if none)."""
    if len(problems) == 1:
        raise problems[0]
    if problems:
        raise FieldProblems(problems)


class _Given(str):
    """A value printed as is in an error line (the set of keys given in a table)."""


def _given(model: BaseModel, keys: tuple[str, ...]) -> _Given:
    return _Given("{" + ", ".join(k for k in keys if getattr(model, k) is not None) + "}")


def _exactly_one(model: BaseModel, keys: tuple[str, ...], what: str = "") -> None:
    """Raise the one-line deck error unless exactly one of ``keys`` is given."""
    if sum(getattr(model, k) is not None for k in keys) != 1:
        raise FieldProblem((), _given(model, keys), f"give exactly one of {what}{', '.join(keys)}")
