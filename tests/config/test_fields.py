"""The table of recurring deck fields (fracas.config.fields): the models, the sweep's numeric
paths and docs/process_noise.md all read it."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from fracas.config import fields
from fracas.config.sweep import NUMERIC_FIELDS
from fracas.config.team import APriori, ThrustNoise
from fracas.constants import DAY_S, SPEED_OF_LIGHT_KM_S
from fracas.errors import DeckError

REPO = Path(__file__).resolve().parents[2]


def test_docs_hold_the_generated_table() -> None:
    doc = (REPO / "docs" / "process_noise.md").read_text(encoding="utf-8")
    assert fields.markdown_table() in doc, (
        "docs/process_noise.md is out of date: paste fracas.config.fields.markdown_table() "
        f"between {fields.DOCS_BEGIN!r} and {fields.DOCS_END!r}"
    )


def test_models_have_the_table_fields() -> None:
    assert tuple(ThrustNoise.model_fields) == tuple(c.name for c in fields.THRUST_NOISE_COMPONENTS)
    names = {f.name for f in fields.A_PRIORI_FIELDS}
    assert names <= set(APriori.model_fields)
    assert fields.LIGHT_KM_S == SPEED_OF_LIGHT_KM_S == 299_792.458


def test_units_convert_as_the_filter_expects() -> None:
    factors = [c.factor for c in fields.THRUST_NOISE_COMPONENTS]
    assert factors == [1.0, math.pi / 180.0, math.pi / 180.0]
    assert fields.THRUST_NOISE_TAU.factor == DAY_S


def test_sweep_numeric_paths_come_from_the_table() -> None:
    for table in fields.THRUST_NOISE_SECTIONS:
        assert set(fields.thrust_noise_paths(table)) <= NUMERIC_FIELDS
        assert len(fields.thrust_noise_paths(table)) == 6
    for table in fields.A_PRIORI_SECTIONS:
        assert set(fields.a_priori_paths(table)) <= NUMERIC_FIELDS


@pytest.mark.parametrize(
    ("component", "sigma", "message"),
    [
        ("proportionality", 1.5, "thrust_noise.proportionality.sigma = 1.5: must be <= 1 (100 %)"),
        ("in_plane_deg", 181.0, "thrust_noise.in_plane_deg.sigma = 181.0: must be <= 180 deg"),
        ("out_of_plane_deg", 200.0, "thrust_noise.out_of_plane_deg.sigma = 200.0: must be <= 180 deg"),
    ],
)
def test_thrust_noise_bounds_read_the_table(component: str, sigma: float, message: str) -> None:
    from fracas.config.team import parse_team_deck

    noise = f"{component} = {{sigma = {sigma}, tau_days = 1.0}}"
    text = f'[ertraj]\ndeck = "x.toml"\n[errcon]\nanalysis = false\n[thrust_noise]\n{noise}\n'
    with pytest.raises(DeckError) as err:
        parse_team_deck(text, "d.toml")
    assert str(err.value) == f"d.toml: {message}"
