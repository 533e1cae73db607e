"""The compile budget (fracas/build/compile_budget.py): each main compiled program, built from
its bundled deck and lowered (no XLA compilation), has at most BUDGET[name] HLO instructions.

A program over its budget grew: look at what was added to it (``python scripts/hlo_sizes.py
--dump DIR`` writes the HLO texts to compare with a checkout before the change), and raise
the budget (``python scripts/hlo_sizes.py --update``) only if the growth is meant.  The
counts are deterministic for one jax version, so the budget tests skip on a jax whose
major.minor differs from the one the budgets were measured with.
"""

from __future__ import annotations

import jax
import pytest

from fracas.build import compile_budget as cb

_OTHER_JAX = pytest.mark.skipif(
    not cb.jax_version_matches(),
    reason=(
        f"the budgets were measured on jax {cb.JAX_VERSION_MEASURED} and jax {jax.__version__} is installed: "
        "HLO instruction counts are deterministic for one jax/XLA version, not across versions "
        "(re-measure with `python scripts/hlo_sizes.py --update`)"
    ),
)


@pytest.fixture(scope="module")
def programs():
    """Every budgeted program, built once from its deck (not lowered)."""
    return cb.build_programs()


@_OTHER_JAX
@pytest.mark.parametrize("name", cb.PROGRAM_NAMES)
def test_program_within_budget(programs, name):
    m = cb.measure_program(programs[name])
    assert m.instructions > 0, f"{name}: no instructions counted in the HLO text of {m.entry}"
    assert m.instructions <= cb.BUDGET[name], (
        f"{name} ({m.entry} on {m.deck}): {m.instructions} HLO instructions, budget {cb.BUDGET[name]} "
        f"(+{m.instructions - cb.BUDGET[name]}); see tests/test_compile_budget.py's docstring"
    )


def test_every_program_has_a_budget(programs):
    assert list(programs) == list(cb.BUDGET)
    assert all(isinstance(b, int) and b > 0 for b in cb.BUDGET.values())


_HLO = """HloModule jit_f, entry_computation_layout={(f64[3]{0})->f64[]}

region_0.1 {
  a.1 = f64[] parameter(0)
  b.2 = f64[] parameter(1)
  ROOT add.3 = f64[] add(a.1, b.2)
}

ENTRY main.4 {
  x.1 = f64[3]{0} parameter(0)
  c.2 = f64[] constant(0)
  ROOT r.3 = f64[] reduce(x.1, c.2), dimensions={0}, to_apply=region_0.1
}
"""


def test_counting_rule():
    # 3 + 3 instructions; the header (whose layout contains "=" but not " = ") and braces are not counted
    assert cb.hlo_instruction_count(_HLO) == 6
    assert cb.hlo_instruction_count("HloModule m, x = y {\n}\n") == 0


def test_count_of_a_lowered_program():
    f = jax.jit(lambda x: jax.numpy.sum(x * x))
    text = f.lower(jax.ShapeDtypeStruct((3,), jax.numpy.float64)).as_text(dialect="hlo")
    n = cb.hlo_instruction_count(text)
    assert n == sum(" = " in line for line in text.splitlines() if not line.startswith("HloModule"))
    assert n >= 4  # parameter, multiply, constant, reduce (and its add)


def test_budget_headroom():
    assert cb.budget_for(1969) == 2170
    assert cb.budget_for(314) == 350
    assert cb.budget_for(1000) == 1100
    assert cb.jax_version_matches("0.10.2", "0.10.7")
    assert not cb.jax_version_matches("0.10.2", "0.11.0")
