"""The whole trajectory deck (FRACAS TOM ``$DATA``, sec. 3.1): :class:`TrajectoryDeck`, and
:class:`SourcedDeck`, the base of every deck kind (it remembers where it came from).

The tables are :mod:`fracas.config.trajectory.state` and
:mod:`fracas.config.trajectory.sections`; the cross checks run by the deck's validators are
:mod:`fracas.config.trajectory.checks`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

from pydantic import PrivateAttr, ValidationError, ValidationInfo, model_validator

from fracas.config.limits import Limits
from fracas.config.trajectory import checks
from fracas.config.trajectory.problems import FieldProblem
from fracas.config.trajectory.sections import (
    Forces,
    Impulse,
    Integrator,
    Output,
    Propulsion,
    Spacecraft,
    Stop,
    ThrustArc,
)
from fracas.config.trajectory.state import Epoch, InitialState, _oem_at, _oem_sample
from fracas.config.trajectory.values import _Section
from fracas.constants import DAY_S
from fracas.timescales import epoch_to_et, et_to_calendar

BACKWARD_TEAM_PROBLEM = "is a backward trajectory (final time before the epoch); TEAM needs a forward one"


class SourcedDeck(_Section):
    """A whole deck that remembers where it came from (``source_path``, ``source_text``)."""

    _source_path: str | None = PrivateAttr(None)
    _source_text: str | None = PrivateAttr(None)

    @property
    def source_path(self) -> str | None:
        return self._source_path

    def resolve(self, rel: str) -> Path:
        """A path named in the deck, relative to the deck's folder."""
        p = Path(rel)
        if p.is_absolute() or self._source_path is None:
            return p
        return Path(self._source_path).parent / p

    @property
    def source_text(self) -> str | None:
        return self._source_text


class TrajectoryDeck(SourcedDeck):
    """A whole trajectory deck (frozen).  ``source_path``/``source_text`` say where it came from.

    ``mode = "propagate"`` may be written; a deck without ``mode`` is a trajectory deck."""

    mode: Literal["propagate"] = "propagate"
    title: str = ""
    epoch: Epoch
    initial_state: InitialState
    spacecraft: Spacecraft
    propulsion: Propulsion | None = None
    thrust_arc: list[ThrustArc] = []
    impulse: list[Impulse] = []
    forces: Forces = Forces()
    integrator: Integrator = Integrator()
    stop: Stop
    output: Output = Output()
    limits: Limits = Limits()

    @model_validator(mode="before")
    @classmethod
    def _from_oem(cls, data: Any, info: ValidationInfo) -> Any:
        """With ``[initial_state.oem]``: ``[epoch]`` and ``initial_state.centre`` from the OEM when left out."""
        ist = data.get("initial_state") if isinstance(data, dict) else None
        oem = ist.get("oem") if isinstance(ist, dict) else None
        if not isinstance(oem, dict) or not isinstance(oem.get("path"), str) or not oem["path"]:
            return data
        if "epoch" in data and "centre" in ist:
            return data
        try:
            at = _oem_at(oem["at"]) if "at" in oem else "start"
        except ValueError:
            return data  # the field's own validation reports it
        if "at" not in oem and "epoch" in data:
            try:
                at = Epoch.model_validate(data["epoch"]).et
            except ValidationError:
                return data
        source = (info.context or {}).get("source") if info is not None else None
        et, _, _, seg, _ = _oem_sample(oem, at, source)
        data = dict(data)
        if "epoch" not in data:
            data["epoch"] = {"iso": et_to_calendar(et, 9)}
        if "centre" not in ist:
            data["initial_state"] = {**ist, "centre": seg.centre}
        return data

    @model_validator(mode="after")
    def _oem_state(self, info: ValidationInfo) -> TrajectoryDeck:
        """Read the initial state of ``[initial_state.oem]`` at the deck's epoch."""
        source = (info.context or {}).get("source") if info is not None else None
        st = self.initial_state
        if st.oem is None:
            return self
        at = st.oem.at if st.oem.at is not None else self.epoch.et
        et, r, v, seg, how = _oem_sample(st.oem.model_dump(), at, source)
        if abs(et - self.epoch.et) > 1e-6:
            raise FieldProblem(
                ("initial_state", "oem", "at"),
                st.oem.at,
                f"is {et_to_calendar(et, 6)} TDB but [epoch] is {et_to_calendar(self.epoch.et, 6)} TDB: "
                "they must agree (or leave one out)",
            )
        if seg.centre != st.centre:
            raise FieldProblem(
                ("initial_state", "centre"),
                st.centre,
                f"the OEM's segment at that epoch has CENTER_NAME = {seg.centre.upper()}: they must agree",
            )
        st.oem._r_km, st.oem._v_km_s = tuple(map(float, r)), tuple(map(float, v))
        st.oem._et, st.oem._how = float(et), how
        return self

    @property
    def primary(self) -> str:
        return self.initial_state.centre

    @property
    def duration_days(self) -> float:
        """Final time in days from the epoch."""
        if self.stop.duration_days is not None:
            return self.stop.duration_days
        return (epoch_to_et(self.stop.final_epoch) - self.epoch.et) / DAY_S

    @property
    def backward(self) -> bool:
        """Whether the final time is before the epoch (backward propagation)."""
        return self.duration_days < 0.0

    @model_validator(mode="after")
    def _cross_checks(self) -> TrajectoryDeck:
        """:func:`fracas.config.trajectory.checks.cross_checks`."""
        checks.cross_checks(self)
        return self

    @model_validator(mode="after")
    def _run_checks(self) -> TrajectoryDeck:
        """:func:`fracas.config.trajectory.checks.run_checks`."""
        checks.run_checks(self)
        return self
