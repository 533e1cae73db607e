"""TSIM report: the 80-column summary and the three PNG plots, from a synthetic product."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fracas.report.tsim import plot_tsim, summary_text
from tests.io.test_tsim_results import synthetic_product


@pytest.fixture(scope="module")
def product():
    return synthetic_product()


def test_summary_fits_80_columns(product):
    text = summary_text(product)
    lines = text.splitlines()
    assert all(len(line) <= 80 for line in lines), [line for line in lines if len(line) > 80]
    for m in product.maneuvers:
        assert m.name in text
    assert "synthetic TSIM" in lines[0]
    assert "hopeless 2" in text and "failed 1" in text
    assert "[consistent]" in text and "[not compared]" in text
    # TEAM's mean |dV| of TCM1 in m/s
    assert "2.1" in next(line for line in lines if line.startswith("TCM1"))


def test_summary_long_names_and_no_successes(product):
    long = dataclasses.replace(
        product,
        title="T" * 200,
        maneuvers=[dataclasses.replace(m, name="M" * 60, law="nonlinear-with-a-long-name") for m in product.maneuvers],
        final_target_names=["a_very_long_target_component_name"] * 3,
        table={**product.table, "status": np.full(200, 3, np.int32)},
        statistics={},
    )
    lines = summary_text(long).splitlines()
    assert all(len(line) <= 80 for line in lines)


def test_plots(product, tmp_path):
    paths = plot_tsim(product, tmp_path / "run.png")
    assert [p.name for p in paths] == ["run.png", "run_dv.png", "run_errors.png"]
    for p in paths:
        assert p.exists() and p.stat().st_size > 1000
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bplane = dataclasses.replace(product, final_target_names=["b_dot_t", "b_dot_r", "lt"])
    assert len(plot_tsim(bplane, tmp_path / "b.png")) == 3
