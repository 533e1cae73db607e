"""The TEAM deck's ``[[guidance]]`` events (GUIDM §5.3.6, XGUID §5.3.25) and their execution
errors; the guidance types and the guidance models ``[errcon] guidance_model`` names.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from fracas.config.team.bounds import NonNeg
from fracas.config.trajectory import FieldProblem, PositiveFloat, _Section, raise_problems
from fracas.guidance.target_kinds import LOW_THRUST_CONTROLS, TARGET_KINDS  # the jax-free catalogue

GUIDANCE_TYPES = ("impulsive", "primary", "vernier", "none")
GUIDANCE_MODELS = ("report", "orthogonal", "tsim")


class GuidanceExecution(_Section):
    """Execution errors of a guidance event (App. 9.1 high-thrust defaults, report L2722).

    Impulsive: proportionality (fraction of |ΔV|), two pointing angles of pointing_mrad each,
    resolution_m_s (isotropic); low thrust: proportionality is the fractional 1σ error of
    each control correction (a fracas choice: the report gives no low-thrust model)."""

    proportionality: Annotated[float, Field(ge=0, le=1)] = 0.01
    pointing_mrad: Annotated[float, Field(ge=0, le=1000)] = 7.0
    resolution_m_s: Annotated[float, Field(ge=0, le=1000)] = 0.01


class Guidance(_Section):
    """One [[guidance]] event (GUIDM §5.3.6, XGUID §5.3.25), computed statistically.

    type: "impulsive" (ΔV at time_days), "primary" (low-thrust correction of thrust arc
    ``arc`` from time_days to the arc's end, the cutoff), "vernier" (a later update of a
    primary on the same arc), "none" (target covariance only).  targets: names of
    :data:`fracas.guidance.target_kinds.TARGET_KINDS` at target_time_days (default: the
    reference trajectory's end) about target_body (default: the central body there).
    controls (low thrust): a subset of proportionality, alpha, beta, t_on, t_off.
    weights: one per control (impulsive: per ΔV component); tolerances: one per target.
    """

    name: Annotated[str, Field(pattern=r"^[A-Za-z][A-Za-z0-9_\-]*$", max_length=32)]
    type: Literal[GUIDANCE_TYPES]  # type: ignore[valid-type]
    time_days: NonNeg
    targets: list[str]
    target_time_days: PositiveFloat | None = None
    target_body: str | None = None
    arc: Annotated[int, Field(ge=0)] | None = None
    controls: list[str] = ["proportionality", "alpha", "beta"]
    weights: list[PositiveFloat] | None = None
    tolerances: list[PositiveFloat] | None = None
    execution: GuidanceExecution = GuidanceExecution()

    @model_validator(mode="after")
    def _consistent(self) -> Guidance:
        problems = []
        if not self.targets and self.type != "none":
            problems.append(FieldProblem("targets", [], "give at least one target"))
        for j, t in enumerate(self.targets):
            if t not in TARGET_KINDS:
                problems.append(
                    FieldProblem(("targets", j), t, f"unknown target (expected one of: {', '.join(TARGET_KINDS)})")
                )
        if len(set(self.targets)) != len(self.targets):
            problems.append(FieldProblem("targets", self.targets, "targets must not repeat"))
        low = self.type in ("primary", "vernier")
        if low:
            if self.arc is None:
                problems.append(
                    FieldProblem("arc", None, f'required for type "{self.type}" (the thrust arc it corrects)')
                )
            if not self.controls:
                problems.append(FieldProblem("controls", [], "give at least one control"))
            for j, c in enumerate(self.controls):
                if c not in LOW_THRUST_CONTROLS:
                    problems.append(
                        FieldProblem(
                            ("controls", j), c, f"unknown control (expected one of: {', '.join(LOW_THRUST_CONTROLS)})"
                        )
                    )
            if len(set(self.controls)) != len(self.controls):
                problems.append(FieldProblem("controls", self.controls, "controls must not repeat"))
            if self.type == "vernier" and "t_on" in self.controls:
                problems.append(FieldProblem("controls", self.controls, "a vernier cannot move the arc's start (t_on)"))
        elif self.arc is not None:
            problems.append(FieldProblem("arc", self.arc, "only for low-thrust guidance (primary, vernier)"))
        n_controls = len(self.controls) if low else 3
        if self.weights is not None and len(self.weights) != n_controls:
            problems.append(
                FieldProblem(
                    "weights",
                    self.weights,
                    f"expected {n_controls} values (one per {'control' if low else 'ΔV component'})",
                )
            )
        if self.tolerances is not None and len(self.tolerances) != len(self.targets):
            problems.append(
                FieldProblem("tolerances", self.tolerances, f"expected {len(self.targets)} values (one per target)")
            )
        raise_problems(problems)
        return self

    @property
    def n_controls(self) -> int:
        return len(self.controls) if self.type in ("primary", "vernier") else 3
