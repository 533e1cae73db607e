"""The compile budget: the size of the project's main compiled programs, which CI holds under a
limit (tests/test_compile_budget.py; table and new budgets: ``python scripts/hlo_sizes.py``).

XLA's compile time grows with the size of the program it is given, so each program below is
built from a bundled deck (by the same builders ``fracas run`` uses), *lowered* -- traced
and converted to XLA's input, ``jax.jit(f).lower(*args)``, with no XLA compilation -- and
its instructions are counted.  Lowering takes from 0.3 to 6 s per program (about 20 s in
all on two cores, imports and deck building included).

Counting rule (:func:`hlo_instruction_count`).  The text is ``lowered.as_text(dialect="hlo")``:
the unoptimized HLO module XLA receives.  It is a header line (``HloModule ...``) and a list
of computations, each a line ``name {`` (or ``ENTRY name {``), one instruction per line
(``name = shape opcode(operands), attributes``, the computation's result prefixed ``ROOT``),
and a line ``}``.  The count is the number of lines that lie inside a computation (between a
line ending in ``{`` and the next line ``}``) and contain ``" = "``: every instruction, the
``parameter`` and ``constant`` ones included, of every computation (entry, while bodies and
conditions, called and reduction computations), each computation counted once however many
times it is called.  The header and the braces are not counted.

The counts are deterministic for a given jax/jaxlib version and source tree, not across jax
versions (the lowering rules change), so the budgets record the jax version they were
measured with and the test skips on another major.minor version.

The programs (``name``: deck; the public call a run makes, and the jitted function it reaches).
Each is captured from that call (:func:`_capture`: the jitted function is replaced by a
recorder for the call's duration), so it is the program a run compiles, with the arguments
the run passes, whatever dispatch lies in between:

* ``propagate``: namelists/leo_j2.toml; ``fracas.integrate.propagate.propagate`` (``fracas
  run`` on the deck) -> ``fracas.integrate.propagate._propagate``;
* ``stm_variational``: the same deck and its parameter labels (none);
  ``propagate_with_sensitivities(..., method="variational")`` -> ``_propagate_var`` (the
  explicit variational equations; "auto" chooses them for this model);
* ``stm_ad``: the same; ``propagate_with_sensitivities(..., method="ad")`` ->
  ``_propagate_sens`` (forward-mode AD through the integrator);
* ``thrust_propagate``: namelists/near_earth_spiral.toml (thrust, DOP853); ``propagate`` ->
  ``_propagate``;
* ``team_reference``: namelists/earth_mars_guidance.toml; the reference and its STMs as
  STMGEN integrates them (``fracas stm build``, ``fracas.modes.stm.stm_product``):
  ``fracas.team.reference.run_reference(problem, stm_file_times(case), stm_file_labels(case))``
  -> ``propagate_with_sensitivities`` ("auto") -> ``_propagate_sens`` at the time of writing
  (the table names the function reached);
* ``team_filter``: the same deck; the covariance filter over the schedule,
  ``fracas.team.scan.run_filter`` with the guidance's execution-error arguments ->
  ``fracas.team.scan._scan`` (``filter_scan``); its inputs are zeros of the shapes a run
  passes (measurement rows: every scheduled observation used, rounded up to 4), so no
  reference is integrated;
* ``tom_sensitivities``: namelists/earth_mars_tom.toml; the call
  ``TomProblem.exact_sensitivities`` makes at the deck's starting controls,
  ``fracas.integrate.propagate.final_state_jacobian`` -> ``_final_jac``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import jax
import numpy as np

__all__ = [
    "BUDGET",
    "JAX_VERSION_MEASURED",
    "HEADROOM",
    "PROGRAM_NAMES",
    "Program",
    "Measurement",
    "hlo_instruction_count",
    "budget_for",
    "build_programs",
    "measure",
    "measure_program",
    "jax_version_matches",
]

#: Where the bundled decks live (the repository's namelists/ folder).
DECKS = Path(__file__).resolve().parents[2] / "namelists"

#: Headroom of a budget over the measured count.
HEADROOM = 0.10

# HLO instructions per program: the count measured on jax 0.10.2 (jaxlib 0.10.2, x64)
# at commit 38e149f (issue 23: stages as data, variational STMs), plus ~10 % headroom
# (budget_for: count * 1.1 rounded up to a multiple of 10).  Before issue 23 (210397f):
# propagate 1969, stm_variational 6011, stm_ad 4503, thrust_propagate 4745, team_reference
# 17002 (then AD through the integrator), team_filter 314, tom_sensitivities 20718.
# Re-measure and print a new dict with `python scripts/hlo_sizes.py --update`.
BUDGET = {
    "propagate": 880,  # measured 793
    "stm_variational": 1270,  # measured 1151 (the 6x6 block without a force)
    "stm_ad": 1350,  # measured 1227
    "thrust_propagate": 1840,  # measured 1672
    "team_reference": 3210,  # measured 2911
    "team_filter": 350,  # measured 314
    "tom_sensitivities": 9740,  # measured 8849
}
#: The jax version the budgets were measured with (the test skips on another major.minor).
JAX_VERSION_MEASURED = "0.10.2"

PROGRAM_NAMES = tuple(BUDGET)


def budget_for(count: int, headroom: float = HEADROOM) -> int:
    """The budget for a measured count: count * (1 + headroom), rounded up to a multiple of 10."""
    return int(math.ceil(count * (1.0 + headroom) / 10.0 - 1e-9)) * 10


def hlo_instruction_count(hlo_text: str) -> int:
    """Instructions in an HLO module's text (the module docstring's counting rule): lines
    containing ``" = "`` between a line ending in ``{`` and the next line ``}``."""
    n = 0
    inside = False
    for line in hlo_text.splitlines():
        s = line.strip()
        if not inside:
            inside = s.endswith("{") and not s.startswith("HloModule")
        elif s == "}":
            inside = False
        elif " = " in s:
            n += 1
    return n


def jax_version_matches(measured: str | None = None, installed: str | None = None) -> bool:
    """Whether jax ``installed`` (default the installed one) has the major.minor version of
    ``measured`` (default :data:`JAX_VERSION_MEASURED`, the budgets' version)."""
    measured = JAX_VERSION_MEASURED if measured is None else measured
    installed = jax.__version__ if installed is None else installed
    return installed.split(".")[:2] == measured.split(".")[:2]


@dataclasses.dataclass(frozen=True)
class Program:
    """One jitted program and the arguments a run of ``deck`` calls it with.

    name: the key of :data:`BUDGET`; deck: the deck's path relative to the repository;
    entry: the jitted function (dotted name); fn, args, kwargs: what :meth:`lower` lowers."""

    name: str
    deck: str
    entry: str
    fn: Callable
    args: tuple
    kwargs: dict = dataclasses.field(default_factory=dict)

    def lower(self):
        """``fn.lower(*args, **kwargs)``: traced and lowered, not compiled."""
        return self.fn.lower(*self.args, **self.kwargs)


@dataclasses.dataclass(frozen=True)
class Measurement:
    """A program's size: HLO instructions, its budget (None if it has none) and the seconds
    :meth:`Program.lower` took (tracing and lowering; not the conversion to HLO text)."""

    name: str
    deck: str
    entry: str
    instructions: int
    budget: int | None
    lowering_s: float
    hlo_text: str = dataclasses.field(default="", repr=False)

    @property
    def within_budget(self) -> bool:
        return self.budget is not None and self.instructions <= self.budget


# ----------------------------------------------------------------------------- the programs


def _rel(path: Path) -> str:
    try:
        return str(path.relative_to(DECKS.parent))
    except ValueError:
        return str(path)


class _Called(BaseException):  # not an Exception: nothing on the way may swallow it
    def __init__(self, name: str, args: tuple, kwargs: dict):
        super().__init__(name)
        self.name, self.args_, self.kwargs = name, args, kwargs


def _capture(module, names: tuple[str, ...], call: Callable[[], object]) -> tuple[str, Callable, tuple, dict]:
    """Run ``call()`` (a public entry point) with the jitted functions ``names`` of ``module``
    replaced by recorders, and stop it at the first of them it calls: (dotted name of the
    jitted function, the function, the arguments it was called with).  So a program is the
    one a run reaches, with the arguments the run passes, whatever the dispatch in between;
    nothing is traced or run."""
    originals = {n: getattr(module, n) for n in names}

    def recorder(name):
        def record(*args, **kwargs):
            raise _Called(name, args, kwargs)

        return record

    try:
        for n in names:
            setattr(module, n, recorder(n))
        call()
    except _Called as c:
        return f"{module.__name__}.{c.name}", originals[c.name], c.args_, c.kwargs
    finally:
        for n, f in originals.items():
            setattr(module, n, f)
    raise RuntimeError(f"the entry point called none of {module.__name__}.{{{', '.join(names)}}}")


_SENS = ("_propagate_var", "_propagate_sens")


def _program(name: str, deck: Path, module, names: tuple[str, ...], call: Callable[[], object]) -> Program:
    entry, fn, args, kwargs = _capture(module, names, call)
    return Program(name, _rel(deck), entry, fn, args, kwargs)


def _trajectory_programs(decks: Path) -> list[Program]:
    from fracas.build.trajectory import build_propagation
    from fracas.config.trajectory import load_deck
    from fracas.integrate import propagate as prop

    leo = decks / "leo_j2.toml"
    pr = build_propagation(load_deck(leo))
    args = (pr.model, pr.params, pr.ephem, pr.epoch_et_s, pr.x0, pr.t_out)
    labels = tuple(pr.param_labels)
    spiral = decks / "near_earth_spiral.toml"
    sp = build_propagation(load_deck(spiral))
    return [
        _program("propagate", leo, prop, ("_propagate",), lambda: prop.propagate(*args)),
        _program(
            "stm_variational",
            leo,
            prop,
            _SENS,
            lambda: prop.propagate_with_sensitivities(*args, labels, method="variational"),
        ),
        _program("stm_ad", leo, prop, _SENS, lambda: prop.propagate_with_sensitivities(*args, labels, method="ad")),
        _program(
            "thrust_propagate",
            spiral,
            prop,
            ("_propagate",),
            lambda: prop.propagate(sp.model, sp.params, sp.ephem, sp.epoch_et_s, sp.x0, sp.t_out),
        ),
    ]


def _measurement_rows(study, m_pad: int = 4) -> int:
    """H's row count when every scheduled observation is used (visibility can only lower the
    count; ``assemble_measurements`` rounds up to a multiple of ``m_pad``)."""
    most = max([len(t) for t in study.schedule.tracking] + [1])
    return int(math.ceil(most / m_pad) * m_pad)


def _team_programs(decks: Path) -> list[Program]:
    from fracas.build.team import build_case, stm_file_labels, stm_file_times
    from fracas.config.team import load_team_deck
    from fracas.integrate import propagate as prop
    from fracas.team import scan
    from fracas.team.measure import MeasurementSet
    from fracas.team.reference import run_reference

    path = decks / "earth_mars_guidance.toml"
    case = build_case(load_team_deck(path))
    study = case.study
    times, labels = stm_file_times(case), stm_file_labels(case)
    ref = _program("team_reference", path, prop, _SENS, lambda: run_reference(study.problem, times, labels))

    # the filter's inputs are zeros of the shapes a run gives it (their values do not change the program)
    K, n, nx, m = study.schedule.n, study.layout.n, study.nx, _measurement_rows(study)
    z = np.zeros
    meas = MeasurementSet(z((K, m, n)), z((K, m, m)), z((K, m, m)))
    q = z((K, nx, nx))
    filt = _program(
        "team_filter",
        path,
        scan,
        ("_scan",),
        lambda: scan.run_filter(study, z((K, n, n)), q, q, meas, q, q),  # Xa, Xt: as the guidance passes
    )
    return [ref, filt]


def _tom_programs(decks: Path) -> list[Program]:
    from fracas.build.tom import build_tom
    from fracas.config.tom import load_tom_deck
    from fracas.integrate import propagate as prop

    path = decks / "earth_mars_tom.toml"
    case = build_tom(load_tom_deck(path))
    tp, cm, u = case.problem, case.problem.controls, case.u0
    if tp.sensitivity_method != "ad":
        raise RuntimeError(f"{path}: expected AD sensitivities, the deck asks for {tp.sensitivity_method!r}")
    # the call TomProblem.exact_sensitivities makes at the starting controls (t_end is traced:
    # the final time stands in for the event time its propagation would find)
    dp_du = cm.param_matrix if cm.param_labels else np.zeros((0, cm.n_controls))

    def call():
        x0, t_end, p = cm.x0_of(u), cm.final_time(u), tp.params_at(u)
        return prop.final_state_jacobian(
            tp.model, p, tp.ephem, tp.epoch_et_s, x0, t_end, cm.param_labels, cm.x0_jacobian(u), dp_du
        )

    return [_program("tom_sensitivities", path, prop, ("_final_jac",), call)]


def build_programs(decks: str | Path | None = None) -> dict[str, Program]:
    """Every budgeted program, built from its deck (in ``decks``, default the repository's
    namelists/) but not lowered: {name: Program}, in :data:`BUDGET`'s order.  Builds the
    decks' models and ephemerides (about 2 s); integrates nothing."""
    decks = DECKS if decks is None else Path(decks)
    progs = _trajectory_programs(decks) + _team_programs(decks) + _tom_programs(decks)
    by_name = {p.name: p for p in progs}
    order = [n for n in BUDGET if n in by_name] + [n for n in by_name if n not in BUDGET]
    return {n: by_name[n] for n in order}


def measure_program(program: Program, keep_text: bool = False) -> Measurement:
    """Lower ``program`` and count its HLO instructions."""
    t0 = time.perf_counter()
    lowered = program.lower()
    dt = time.perf_counter() - t0
    text = lowered.as_text(dialect="hlo")
    return Measurement(
        name=program.name,
        deck=program.deck,
        entry=program.entry,
        instructions=hlo_instruction_count(text),
        budget=BUDGET.get(program.name),
        lowering_s=dt,
        hlo_text=text if keep_text else "",
    )


def measure(
    names: Iterable[str] | None = None, decks: str | Path | None = None, keep_text: bool = False
) -> list[Measurement]:
    """Build every program and measure those named (default all, in :data:`BUDGET`'s order)."""
    progs = build_programs(decks)
    wanted = list(progs) if names is None else list(names)
    unknown = [n for n in wanted if n not in progs]
    if unknown:
        raise KeyError(f"unknown program(s) {unknown}; known: {', '.join(progs)}")
    return [measure_program(progs[n], keep_text) for n in wanted]
