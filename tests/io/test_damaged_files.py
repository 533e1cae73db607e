"""Damaged files of every kind fracas writes are refused in one line, within a time bound.

The class test of issue 22 section 4 ("no input file may hang fracas").  One small file of
each kind -- STM, TEAM results, punch, TOM results, TSIM results, TSIM checkpoint,
rendezvous results, trajectory, sweep table -- is written by its own writer (synthetic
products, no JAX program compiled) and then damaged:

* bytes: bits flipped at 8 offsets (integrity header, superblock, a quarter, half and three
  quarters into the file, last byte), a 4 KiB block zeroed at 4 offsets, truncated to half
  and by one byte, extended by 4 KiB, emptied -- 16 variants;
* contents, re-sealed so that the file passes its integrity header as a writer's bug or an
  older fracas would leave it: a dataset (or attribute) every reader needs deleted, and the
  schema version set to 99 -- 2 variants;
* files without the integrity header (as fracas wrote them before it sealed its files):
  a 4 KiB block zeroed where it makes the HDF5 library loop forever (offset 4096 of these
  files: the issue's hang, reproduced) and where it makes it fail.

Each variant goes to the kind's reader and through the command line (``fracas report`` for
every kind; ``stm info``, ``validate`` and ``run --stm`` for the STM file; ``validate`` for the
punch file): each must refuse with exactly one line naming the file (the reader: its error
class; the command: one ``fracas: error:`` line on stderr, exit status 2, no traceback) in
under ``BOUND_S`` seconds.  The reference is the property itself; the good files read back
(and the good unsealed copies through the probe) show that the refusals come from damage.
"""

from __future__ import annotations

import faulthandler
import re
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from fracas.cli import main
from fracas.errors import DeckError, FracasError, ResultsFileError, StmFileError
from fracas.io.hdf5 import MAGIC, PROBE_ENV, USERBLOCK_SIZE, provenance
from fracas.io.rendezvous_results import read_rendezvous_results, write_rendezvous_results
from fracas.io.stm_file import read_stm_file, write_stm_file
from fracas.io.sweep_table import read_sweep_table, write_sweep_table
from fracas.io.team_results import read_punch, read_team_results, write_punch, write_team_results
from fracas.io.tom_results import read_tom_results, write_tom_results
from fracas.io.trajectory_file import read_trajectory_file, write_trajectory_file
from fracas.io.tsim_results import (
    read_tsim_checkpoint,
    read_tsim_results,
    write_tsim_checkpoint,
    write_tsim_results,
)
from fracas.products import RendezvousProduct, TomProduct
from tests.io.damage import edited, unsealed
from tests.io.test_corrupt_files import _team_product
from tests.io.test_stm_file import _data as stm_data
from tests.io.test_trajectory_file import _data as trajectory_data
from tests.io.test_tsim_results import _blocks, synthetic_product

ROOT = Path(__file__).resolve().parents[2]
BOUND_S = 10.0  # every refusal, reader or command, within this
PROBE_S = "1"  # the probe's limit for files without the integrity header, in this test
WATCHDOG_S = 240.0  # a hang inside the HDF5 library cannot be interrupted: end the process


# --------------------------------------------------------------------------- the files


def _tom_product() -> TomProduct:
    """Two controls, two targets, three iterations (deck units)."""
    k = 3
    return TomProduct(
        title="synthetic TOM",
        source="decks/tom.toml",
        submode="target",
        optimizer="fracas",
        sensitivities="finite_difference",
        control_names=["arc_t_off[0]", "alpha[0]"],
        control_units=["days", "deg"],
        control_factor=np.array([86400.0, np.pi / 180]),
        u_start=np.array([10.0, 5.0]),
        u_final=np.array([10.5, 4.0]),
        lower=np.array([5.0, -90.0]),
        upper=np.array([20.0, 90.0]),
        target_names=["r", "vr"],
        target_bodies=["sun", "sun"],
        target_units=["km", "km/s"],
        target_factor=np.array([1.0, 1.0]),
        desired=np.array([1.5e8, 0.0]),
        tolerance=np.array([1e3, 1e-3]),
        achieved_start=np.array([1.4e8, 0.1]),
        achieved=np.array([1.5e8 + 10.0, 1e-4]),
        initial_mass_kg=1000.0,
        start_mass_kg=900.0,
        final_mass_kg=905.0,
        stop_reason="targets met",
        converged=True,
        search_converged=True,
        targets_met=True,
        iteration=np.arange(k, dtype=np.int64),
        submodes=["target"] * k,
        performance_kg=np.array([900.0, 903.0, 905.0]),
        error_rms=np.array([10.0, 1.0, 0.01]),
        angle_rad=np.array([0.1, 0.05, 0.01]),
        gamma=np.array([1.0, 1.0, 0.5]),
        n_trajectories=np.array([3, 3, 3], dtype=np.int64),
        controls=np.array([[10.0, 5.0], [10.4, 4.2], [10.5, 4.0]]),
        targets=np.array([[1.4e8, 0.1], [1.49e8, 0.01], [1.5e8 + 10.0, 1e-4]]),
        s_matrix=np.eye(2),
        g_vector=np.ones(2),
        timing={"total_s": 1.0},
        provenance=provenance("x = 1\n", "decks/tom.toml"),
    )


def _rendezvous_product() -> RendezvousProduct:
    """One role, twelve labels, three events, one maneuver, no single runs."""
    R, K, n, J = 1, 3, 12, 1
    rng = np.random.default_rng(5)
    a = rng.normal(size=(R, K, n, n))
    P = a @ np.swapaxes(a, -1, -2) + n * np.eye(n)
    return RendezvousProduct(
        title="synthetic rendezvous",
        source="decks/rdv.toml",
        epoch_et_s=6.5e8,
        centre="earth",
        chaser_name="chaser",
        target_name="target",
        roles=["solve_for"],
        labels=[f"{v}{ax}" for v in ("c_r", "c_v", "t_r", "t_v") for ax in "xyz"],
        units=["km", "km", "km", "km/s", "km/s", "km/s"] * 2,
        times_s=np.array([0.0, 600.0, 1200.0]),
        marks=np.ones((K, 4), dtype=np.int64),
        x_chaser=rng.normal(size=(K, 6)),
        x_target=rng.normal(size=(K, 6)),
        P_true=P,
        P_assumed=P,
        P_true_minus=P,
        P_assumed_minus=P,
        maneuver_names=["TPI"],
        maneuver_time_s=np.array([600.0]),
        maneuver_arrival_s=np.array([1200.0]),
        maneuver_dv_km_s=np.full((J, 3), 1e-3),
        maneuver_status=np.zeros(J, dtype=np.int64),
        maneuver_cov_true=np.tile(np.eye(3), (R, J, 1, 1)) * 1e-8,
        maneuver_cov_assumed=np.tile(np.eye(3), (R, J, 1, 1)) * 1e-8,
        reset_times_s=np.zeros(0),
        reference_sources=["two-body", "two-body"],
        team_rms=np.ones((R, K, 6)),
        assumed_rms=np.ones((R, K, 6)),
        timing={"total_s": 0.5},
        provenance=provenance("x = 1\n", "decks/rdv.toml"),
    )


def _sweep_table(path: Path) -> Path:
    rows = [
        {"index": i, "key": f"k{i}", "a": float(i), "y": 2.0 * i, "status": "ok", "error": "", "wall_s": 0.1}
        for i in range(3)
    ]
    return write_sweep_table(path, rows, ["a"], ["y"], {"a": "d", "y": "km"}, {"title": "t"}, csv=False)


@dataclass(frozen=True)
class Kind:
    """One kind of file: how to write it, read it back, and what its refusals look like."""

    write: Callable[[Path], Any]
    read: Callable[[Path], Any]
    error: type[FracasError]
    missing: str  # deleted in the "missing" variant; the reader names it
    schema_attr: str = "schema_version"
    cli: tuple[str, ...] = ("report",)  # commands that read the file (see _cli)


KINDS: dict[str, Kind] = {
    "stm": Kind(
        lambda p: write_stm_file(p, stm_data(4, 2)),
        read_stm_file,
        StmFileError,
        "stm/stm_step",
        cli=("report", "stm info", "validate", "run --stm"),
    ),
    "team": Kind(
        lambda p: write_team_results(p, _team_product()), read_team_results, ResultsFileError, "team/assumed/sigma"
    ),
    "punch": Kind(
        lambda p: write_punch(p, _team_product()),
        read_punch,
        DeckError,
        "punch_000/assumed",
        cli=("report", "validate"),
    ),
    "tom": Kind(
        lambda p: write_tom_results(p, _tom_product()), read_tom_results, ResultsFileError, "tom/history/gamma"
    ),
    "tsim": Kind(
        lambda p: write_tsim_results(p, synthetic_product(40)),
        read_tsim_results,
        ResultsFileError,
        "tsim/final/team_target_cov",
    ),
    "checkpoint": Kind(
        lambda p: write_tsim_checkpoint(p, "abc", _blocks(np.random.default_rng(3))),
        lambda p: read_tsim_checkpoint(p, "abc"),
        ResultsFileError,
        "plan_key",  # an attribute: the checkpoint has no fixed dataset
    ),
    "rendezvous": Kind(
        lambda p: write_rendezvous_results(p, _rendezvous_product()),
        read_rendezvous_results,
        ResultsFileError,
        "rendezvous/x_target",
    ),
    "trajectory": Kind(
        lambda p: write_trajectory_file(p, trajectory_data()),
        read_trajectory_file,
        StmFileError,
        "trajectory/r_km",
    ),
    "sweep": Kind(_sweep_table, read_sweep_table, ResultsFileError, "wall_s", schema_attr="version"),
}


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """One good file of every kind, written once for the module."""
    d = tmp_path_factory.mktemp("good")
    out = {}
    for name, kind in KINDS.items():
        out[name] = d / f"{name}.h5"
        kind.write(out[name])
    return out


@pytest.fixture(scope="module")
def decks(tmp_path_factory) -> dict[str, Path]:
    """Copies of the small TEAM deck naming ``stm.h5`` (errcon.stm_file) and ``punch.h5``
    (a_priori.from_punch) beside them, for ``validate``."""
    d = tmp_path_factory.mktemp("decks")
    shutil.copy(ROOT / "tests" / "data" / "team_small_traj.toml", d / "team_small_traj.toml")
    text = (ROOT / "tests" / "data" / "team_small.toml").read_text(encoding="utf-8")
    (d / "stm.toml").write_text(text + '\n[errcon]\nstm_file = "stm.h5"\n', encoding="utf-8")
    punch = text.replace("mass_sigma_kg = 0.5", 'mass_sigma_kg = 0.5\nfrom_punch = "punch.h5"', 1)
    assert punch != text
    (d / "punch.toml").write_text(punch, encoding="utf-8")
    return {"dir": d, "stm": d / "stm.toml", "punch": d / "punch.toml"}


@pytest.fixture(autouse=True)
def bounded(monkeypatch):
    """The probe's limit for files without the header, and a watchdog: a call stuck inside
    the HDF5 library cannot be interrupted, so the process is ended (with tracebacks)."""
    monkeypatch.setenv(PROBE_ENV, PROBE_S)
    faulthandler.dump_traceback_later(WATCHDOG_S, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()


# --------------------------------------------------------------------------- the damage


def _flip(off: Callable[[int], int]) -> Callable[[bytes], bytes]:
    def damage(b: bytes) -> bytes:
        x = bytearray(b)
        x[off(len(b))] ^= 0x04
        return bytes(x)

    return damage


def _zero(off: Callable[[int], int]) -> Callable[[bytes], bytes]:
    def damage(b: bytes) -> bytes:
        x = bytearray(b)
        start = min(off(len(b)), len(b) - 4096) // 4096 * 4096
        x[start : start + 4096] = bytes(4096)
        return bytes(x)

    return damage


BYTE_DAMAGE: dict[str, Callable[[bytes], bytes]] = {
    "flip-magic": _flip(lambda n: 3),
    "flip-header-sha": _flip(lambda n: 120),
    "flip-superblock-signature": _flip(lambda n: USERBLOCK_SIZE + 1),
    "flip-superblock": _flip(lambda n: USERBLOCK_SIZE + 40),
    "flip-quarter": _flip(lambda n: n // 4),
    "flip-half": _flip(lambda n: n // 2),
    "flip-three-quarters": _flip(lambda n: 3 * n // 4),
    "flip-last": _flip(lambda n: n - 1),
    "zero-block-0": _zero(lambda n: 0),
    "zero-block-4096": _zero(lambda n: 4096),
    "zero-block-half": _zero(lambda n: n // 2),
    "zero-block-last": _zero(lambda n: n),
    "truncate-half": lambda b: b[: len(b) // 2],
    "truncate-1": lambda b: b[:-1],
    "extend-4096": lambda b: b + bytes(4096),
    "empty": lambda b: b"",
}
BYTE_REFUSAL = r"damaged file: |not an HDF5 file \(no HDF5 signature; damaged\?\)"


def _drop(f: h5py.File, name: str) -> None:
    if name in f:
        del f[name]
    else:
        del f.attrs[name]


CONTENT_DAMAGE: dict[str, tuple[Callable[[h5py.File, Kind], None], Callable[[Kind], str]]] = {
    "missing": (lambda f, k: _drop(f, k.missing), lambda k: k.missing),
    "schema-99": (lambda f, k: f.attrs.__setitem__(k.schema_attr, 99), lambda k: rf"{k.schema_attr} = 99"),
}


# --------------------------------------------------------------------------- the checks


def _reader_refuses(kind: Kind, path: Path, pattern: str) -> float:
    """The reader raises the kind's error, one line naming the file and matching
    ``pattern``, within BOUND_S; returns the time taken."""
    t0 = time.perf_counter()
    with pytest.raises(FracasError) as err:
        kind.read(path)
    dt = time.perf_counter() - t0
    msg = str(err.value)
    assert isinstance(err.value, kind.error), msg
    assert "\n" not in msg and str(path) in msg, msg
    assert re.search(pattern, msg), (pattern, msg)
    assert dt < BOUND_S, (dt, msg)
    return dt


def _cli(command: str, path: Path, decks: dict[str, Path]) -> list[str]:
    d = decks["dir"]
    if command == "report":
        return ["report", str(path)]
    if command == "stm info":
        return ["stm", "info", str(path)]
    if command == "run --stm":
        return ["run", str(ROOT / "tests" / "data" / "team_small.toml"), "--stm", str(path), "-o", str(d / "r.h5")]
    assert command == "validate"
    name = "punch" if "punch" in path.name else "stm"
    shutil.copyfile(path, d / f"{name}.h5")  # the name the deck gives
    return ["validate", str(decks[name])]


def _cli_refuses(command: str, path: Path, decks: dict[str, Path], pattern: str | None) -> float:
    """``fracas <command>`` exits 2 with one ``fracas: error:`` line (matching ``pattern``)
    and no traceback, within BOUND_S; returns the time taken."""
    args = _cli(command, path, decks)
    t0 = time.perf_counter()
    r = CliRunner().invoke(main, args)
    dt = time.perf_counter() - t0
    lines = r.stderr.strip().splitlines()
    assert r.exit_code == 2, (args, r.exit_code, r.output, repr(r.exception))
    assert len(lines) == 1 and lines[0].startswith("fracas: error: "), (args, r.stderr)
    assert "Traceback" not in r.output and "internal error" not in r.output, r.output
    if command != "validate":  # validate names the file as its deck does
        assert str(path) in lines[0], (args, lines[0])
    if pattern is not None:
        assert re.search(pattern, lines[0]), (pattern, lines[0])
    assert dt < BOUND_S, (args, dt)
    return dt


def test_good_files_read_back(files):
    """Baseline: every good file starts with the integrity header and reads back without error."""
    for name, kind in KINDS.items():
        kind.read(files[name])
        assert files[name].read_bytes().startswith(MAGIC), name


def test_damaged_files_refused_in_one_line(files, decks, tmp_path, record_property):
    """Every kind x every byte and content damage: the reader and each command that reads
    the kind refuse in one line naming the file, exit 2, within BOUND_S."""
    worst, n_variants, t_start = 0.0, 0, time.perf_counter()
    for name, kind in KINDS.items():
        good = files[name].read_bytes()
        for label, damage in BYTE_DAMAGE.items():
            bad = tmp_path / f"{name}-{label}.h5"
            bad.write_bytes(damage(good))
            n_variants += 1
            worst = max(worst, _reader_refuses(kind, bad, BYTE_REFUSAL))
            for command in kind.cli:
                worst = max(worst, _cli_refuses(command, bad, decks, BYTE_REFUSAL))
        for label, (change, named) in CONTENT_DAMAGE.items():
            bad = tmp_path / f"{name}-{label}.h5"
            shutil.copyfile(files[name], bad)
            with edited(bad) as f:
                change(f, kind)
            n_variants += 1
            worst = max(worst, _reader_refuses(kind, bad, named(kind)))
            for command in kind.cli:
                worst = max(worst, _cli_refuses(command, bad, decks, None))
    total = time.perf_counter() - t_start
    record_property("variants", n_variants)
    record_property("worst_s", worst)
    print(f"{n_variants} damaged files, slowest refusal {worst:.2f} s, all in {total:.1f} s")


def _same(a: Any, b: Any) -> bool:
    """Equal products (arrays compared with NaN == NaN), for a damaged file that still reads."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a if k != "path")
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray):
        return np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
    if hasattr(a, "__dataclass_fields__"):
        return all(_same(getattr(a, k), getattr(b, k)) for k in a.__dataclass_fields__ if k != "source_path")
    return a == b or (a != a and b != b)


def test_files_without_the_integrity_header(files, decks, tmp_path, monkeypatch):
    """Files as fracas wrote them before the header (its user block cut off): the good
    ones of every kind read back equal through the probe (default limit); a 4 KiB block
    zeroed at offset 4096 (where the HDF5 library loops forever: the issue's STM and TOM
    hangs) is refused in one line within BOUND_S by the readers of every kind and by
    ``stm info``, ``validate``, ``run --stm`` and ``report``; every other block of the STM
    file zeroed: refused in one line, or (damage where nothing is read) read back equal."""
    worst = 0.0
    for name, kind in KINDS.items():
        old = tmp_path / f"{name}-old.h5"
        unsealed(files[name], old)
        with monkeypatch.context() as m:
            m.delenv(PROBE_ENV)
            assert _same(kind.read(old), kind.read(files[name])), name
        if name not in ("stm", "tom", "team"):
            continue
        raw = old.read_bytes()
        hang = tmp_path / f"{name}-old-zero-4096.h5"
        hang.write_bytes(raw[:4096] + bytes(4096) + raw[8192:])
        worst = max(worst, _reader_refuses(kind, hang, r"did not finish within 1 s \(damaged\?"))
        for command in kind.cli:
            worst = max(worst, _cli_refuses(command, hang, decks, r"did not finish within 1 s"))
    stm, raw = KINDS["stm"], (tmp_path / "stm-old.h5").read_bytes()
    good = stm.read(files["stm"])
    for start in range(0, len(raw), 4096):
        bad = tmp_path / f"stm-old-zero-{start}.h5"
        bad.write_bytes(raw[:start] + bytes(min(4096, len(raw) - start)) + raw[start + 4096 :])
        t0 = time.perf_counter()
        try:
            back = stm.read(bad)
        except StmFileError as exc:
            assert "\n" not in str(exc) and str(bad) in str(exc), str(exc)
        else:
            assert _same(back, good), start
        worst = max(worst, time.perf_counter() - t0)
        assert time.perf_counter() - t0 < BOUND_S
    print(f"files without the header: slowest refusal {worst:.2f} s")
