"""A toy mode, the whole of it in one package: the period of a circular orbit.

Everything a mode declares (:class:`fracas.modes.base.Mode`): its deck (a pydantic model),
its orchestrator (deck -> product -> results file), its results-file kind and reader, its
report, its ``fracas validate`` checks.  :mod:`tests.modes.test_registry` adds it with one
registry line and drives it through ``load_any``, ``fracas run``, ``validate``, ``report``
and ``sweep``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from fracas.config.trajectory import SourcedDeck, parse_sourced
from fracas.io.atomic import check_output_path
from fracas.io.hdf5 import atomic_h5, provenance, read_kind, write, write_provenance
from fracas.modes.base import Console, Mode, ReportOptions, RunOptions, Stage, results_path, say_to

FILE_KIND = "fracas-toy-results"


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Orbit(_Section):
    radius_km: float = Field(gt=0.0, description="circular orbit radius (km)")
    mu_km3_s2: float = Field(398600.4418, gt=0.0, description="GM of the central body (km^3/s^2)")


class Output(_Section):
    results: str | None = None


class ToyDeck(SourcedDeck):
    mode: Literal["toy"] = "toy"
    title: str = ""
    orbit: Orbit
    output: Output = Output()


def parse_toy_deck(text: str, source: str = "<deck>") -> ToyDeck:
    return parse_sourced(text, source, ToyDeck)


def run_toy(deck: ToyDeck, output: str | Path | None = None, on_stage: Stage | None = None) -> tuple[float, Path]:
    """deck -> the period (s) -> results file."""
    say = say_to(on_stage)
    out = check_output_path(results_path(deck, output), "results file")
    say("computing the period")
    period_s = 2.0 * math.pi * math.sqrt(deck.orbit.radius_km**3 / deck.orbit.mu_km3_s2)
    with atomic_h5(out) as f:
        f.attrs["file_kind"] = FILE_KIND
        write_provenance(f, provenance(deck.source_text, deck.source_path))
        write(f, "period_s", period_s, "s")
    return period_s, out


def read_toy_results(path: Path) -> float:
    import h5py

    read_kind(path)
    with h5py.File(path, "r") as f:
        return float(f["period_s"][()])


def command(deck: Path, opts: RunOptions, console: Console) -> None:
    cfg = parse_toy_deck(deck.read_text(encoding="utf-8"), str(deck))
    with console.progress(not opts.quiet) as stage:
        period_s, path = run_toy(cfg, opts.output, on_stage=stage)
    console.say(json.dumps({"period_s": period_s}) if opts.as_json else f"period {period_s:.3f} s; results: {path}")


def report(file: Path, opts: ReportOptions, console: Console) -> None:
    console.say(f"toy results file: {file}: period {read_toy_results(file):.3f} s")


def toy_problems(deck: ToyDeck) -> list[str]:
    return [f"{deck.source_path}: orbit.radius_km: inside the Earth"] if deck.orbit.radius_km < 6378.137 else []


MODE = Mode(
    name="toy",
    noun="toy",
    summary="the period of a circular orbit",
    parse=parse_toy_deck,
    run=run_toy,
    command=command,
    results_kinds=(FILE_KIND,),
    report=report,
    problems=toy_problems,
)
