"""Issue 32 (hardening, round 3), the I/O classes, each tested as a class:

* an output path that is a file the run reads (the deck, a file it names, --stm, the source
  of an export...), through a symlink or a hard link too, refused before any work, for every
  command that writes;
* a full disk (a real 16 KiB tmpfs where mounting is allowed, else a write failing with
  ENOSPC): one line, exit 2, nothing left behind, the earlier file intact;
* a deck or text input that is not a regular file (a FIFO, /dev/zero) or too big: refused
  before it is read, without blocking and without reading it whole;
* a file name that is not UTF-8, or holds a newline: the run ends well, messages stay one line;
* ``fracas report`` on a sweep table reads it through the checked reader;
* ``-o`` forms click used to mangle (``newdir/``, an existing directory, ``''``);
* an interrupt: one line, exit 130, whatever the moment (a KeyboardInterrupt Python could
  only report as "Exception ignored" included).
"""

from __future__ import annotations

import errno
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from fracas.cli import main

REPO = Path(__file__).resolve().parents[2]
NAMELISTS = REPO / "namelists"


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("FORCE_COLOR", None)
    return env


def fracas(*args: str | bytes, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "fracas.cli", *args],
        cwd=cwd,
        env=_env(),
        capture_output=True,
        text=True,
        errors="replace",
        timeout=timeout,
    )


def _one_error_line(text: str) -> str:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1, text
    assert lines[0].startswith("fracas: error: "), text
    return lines[0]


@pytest.fixture
def decks(tmp_path: Path) -> Path:
    """A copy of namelists/ (decks and the files they name) to run in."""
    shutil.copytree(NAMELISTS, tmp_path / "n")
    return tmp_path / "n"


# ----------------------------------------------------------------------------- output over an input
# (command, deck, arguments): {d} the deck, {t} a file it names, {l} a symlink and {h} a hard link
# to the deck, {s} an existing file given as --stm (or exported).
OVER_INPUT = [
    ("propagate", "leo_j2.toml", ["-o", "{d}"]),
    ("propagate", "leo_j2.toml", ["--plot", "{d}"]),
    ("propagate", "leo_j2.toml", ["-o", "{l}"]),
    ("propagate", "leo_j2.toml", ["-o", "{h}"]),
    ("stm build", "mercury_approach_team.toml", ["-o", "{d}"]),
    ("stm build", "mercury_approach_team.toml", ["-o", "{t:mercury_approach_traj.toml}"]),
    ("run", "earth_mars_team.toml", ["-o", "{d}"]),
    ("run", "earth_mars_team.toml", ["-o", "{t:earth_mars_sep.toml}"]),
    ("run", "earth_mars_team.toml", ["--plot", "{l}"]),
    ("run", "earth_mars_team.toml", ["--stm", "{s}", "-o", "{s}"]),
    (
        "run",
        "near_earth_spiral_team.toml",
        [
            "--trajectory-deck",
            "{t:near_earth_spiral_tom_reference.toml}",
            "-o",
            "{t:near_earth_spiral_tom_reference.toml}",
        ],
    ),
    ("run", "near_earth_spiral_tom.toml", ["-o", "{d}"]),
    ("run", "near_earth_spiral_tom.toml", ["-o", "x.h5", "--reference-deck", "{d}"]),
    ("run", "earth_mars_tsim.toml", ["-o", "{d}"]),
    ("run", "earth_mars_tsim.toml", ["-o", "{t:earth_mars_guidance.toml}"]),
    ("run", "earth_mars_sweep.toml", ["-o", "{t:earth_mars_team.toml}"]),
    ("sweep", "earth_mars_sweep.toml", ["-o", "{d}"]),
    ("run", "apollo12_rendezvous.toml", ["-o", "{t:apollo12_lm_traj.toml}"]),
    ("import-namelist", "legacy/leo_j2.nml", ["-o", "{d}", "--force"]),
    ("export", "{s}", ["--oem", "{s}"]),
]


def _arg(text: str, folder: Path, deck: Path) -> str:
    if text == "{d}":
        return str(deck)
    if text == "{l}":
        link = folder / "link.toml"
        if not link.exists():
            link.symlink_to(deck)
        return str(link)
    if text == "{h}":
        hard = folder / "hard.toml"
        if not hard.exists():
            os.link(deck, hard)
        return str(hard)
    if text == "{s}":
        stm = folder / "given.h5"
        if not stm.exists():
            stm.write_bytes(b"an input the run reads, not to be replaced\n")
        return str(stm)
    if text == "{r}":
        return str(folder / "near_earth_spiral_tom_reference.toml")
    if text.startswith("{t:"):
        return str(folder / text[3:-1])
    return text


@pytest.mark.parametrize(("command", "deck", "args"), OVER_INPUT, ids=lambda x: str(x).replace(" ", "_"))
def test_an_output_over_an_input_is_refused_before_any_work(decks, command, deck, args):
    path = Path(_arg(deck, decks, decks / deck)) if deck.startswith("{") else decks / deck
    argv = [*command.split(), str(path), *(_arg(a, decks, path) for a in args)]
    before = {p: p.read_bytes() for p in decks.rglob("*") if p.is_file() and not p.is_symlink()}
    res = CliRunner().invoke(main, argv)
    assert res.exit_code == 2, (argv, res.output)
    line = _one_error_line(res.output)
    assert "is an input of this run" in line, line
    after = {p: p.read_bytes() for p in decks.rglob("*") if p.is_file() and not p.is_symlink()}
    assert after == before  # nothing written, nothing replaced


def test_atomic_path_refuses_a_noted_input(tmp_path):
    """The last guard: a writer that missed the check still cannot replace an input."""
    from fracas.errors import OutputPathError
    from fracas.io.atomic import atomic_path
    from fracas.io.inputs import input_scope, read_bounded

    deck = tmp_path / "deck.toml"
    deck.write_text("x = 1\n")
    with input_scope():
        read_bounded(deck, 100, OutputPathError, "a deck")
        with pytest.raises(OutputPathError, match="is an input of this run"):
            with atomic_path(deck) as tmp:
                tmp.write_text("results")
    assert deck.read_text() == "x = 1\n"
    with atomic_path(deck) as tmp:  # outside a run, nothing is an input
        tmp.write_text("y = 2\n")
    assert deck.read_text() == "y = 2\n"


# ----------------------------------------------------------------------------- a full disk
def _no_room(monkeypatch):
    """Every HDF5 image and every atomic text write fails half-way with ENOSPC."""
    import fracas.io.hdf5 as hdf5

    def fail(tmp, image):
        with open(tmp, "wb") as fh:
            fh.write(bytes(100))
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(hdf5, "_write_image", fail)


def test_a_full_disk_is_one_line_and_leaves_the_earlier_file(tmp_path, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    (out / "leo.h5").write_bytes(b"earlier")
    _no_room(monkeypatch)
    res = CliRunner().invoke(main, ["propagate", str(NAMELISTS / "leo_j2.toml"), "-o", str(out / "leo.h5")])
    assert res.exit_code == 2, res.output
    line = _one_error_line(res.output.split("└")[-1])
    assert line.endswith(f"{out / 'leo.h5'}: cannot write the trajectory file: No space left on device"), line
    assert sorted(p.name for p in out.iterdir()) == ["leo.h5"]
    assert (out / "leo.h5").read_bytes() == b"earlier"


def test_a_full_disk_under_a_text_writer_names_the_destination(tmp_path):
    from fracas.io.atomic import atomic_path

    dest = tmp_path / "deck.toml"
    with pytest.raises(OSError) as info:
        with atomic_path(dest) as tmp:
            tmp.write_text("x")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(dest)
    assert list(tmp_path.iterdir()) == []


def test_an_oserror_reaching_the_command_line_is_one_line(monkeypatch):
    import fracas.modes.propagate as prop

    def full(*a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), "/somewhere/x.png")

    monkeypatch.setattr(prop, "propagate_deck", full)
    res = CliRunner().invoke(main, ["propagate", str(NAMELISTS / "leo_j2.toml")])
    assert res.exit_code == 2
    assert _one_error_line(res.output) == "fracas: error: /somewhere/x.png: No space left on device"


@pytest.fixture
def tiny_tmpfs(tmp_path):
    """A 16 KiB tmpfs (root only: skipped where mounting is not permitted)."""
    where = tmp_path / "full"
    where.mkdir()
    try:
        done = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", "size=16k", "tmpfs", str(where)], capture_output=True, timeout=30
        )
    except (OSError, subprocess.SubprocessError):
        pytest.skip("mount is not available")
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.decode(errors='replace').strip()}")
    try:
        yield where
    finally:
        subprocess.run(["umount", str(where)], capture_output=True, timeout=30)


@pytest.mark.parametrize(
    ("command", "deck", "what"),
    [("propagate", "leo_j2.toml", "trajectory file"), ("stm build", "mercury_approach_team.toml", "STM file")],
)
def test_a_real_full_disk(tiny_tmpfs, command, deck, what):
    earlier = tiny_tmpfs / "x.h5"
    earlier.write_bytes(b"earlier results")
    res = fracas(*command.split(), str(NAMELISTS / deck), "-o", str(earlier), cwd=tiny_tmpfs.parent)
    assert res.returncode == 2, res.stderr
    assert _one_error_line(res.stderr) == f"fracas: error: {earlier}: cannot write the {what}: No space left on device"
    assert [p.name for p in tiny_tmpfs.iterdir()] == ["x.h5"]
    assert earlier.read_bytes() == b"earlier results"


def test_hdf5_files_built_in_memory_are_the_bytes_the_file_driver_writes(tmp_path):
    """atomic_h5 builds the file in memory: byte for byte what h5py wrote to disk before."""
    from fracas.io.hdf5 import atomic_h5
    from fracas.io.hdf5_integrity import USERBLOCK_SIZE

    def fill(f):
        f.attrs["file_kind"] = "test"
        g = f.create_group("g")
        g.create_dataset("p", data=np.random.default_rng(1).random((40, 7, 9)), chunks=(1, 7, 9))
        g.attrs["units"] = "km"
        f.create_dataset("s", data=["a", "bb"], dtype=h5py.string_dtype())

    with atomic_h5(tmp_path / "mem.h5") as f:
        fill(f)
    with h5py.File(tmp_path / "disk.h5", "w", userblock_size=USERBLOCK_SIZE) as f:
        fill(f)
    mem, disk = (tmp_path / "mem.h5").read_bytes(), (tmp_path / "disk.h5").read_bytes()
    assert mem[USERBLOCK_SIZE:] == disk[USERBLOCK_SIZE:]


# ----------------------------------------------------------------------------- what is read
def _oem_deck(folder: Path, oem: Path) -> Path:
    deck = folder / "oem_deck.toml"
    text = (NAMELISTS / "leo_j2.toml").read_text()
    cart = "[initial_state.cartesian]\nr_km = [7000.0, 0.0, 0.0]\nv_km_s = [0.0, 7.5, 1.0]"
    head = '[initial_state]\ncentre = "earth"\nframe = "EME2000"\n'
    assert cart in text and head in text
    text = text.replace(head, "[initial_state]\n").replace(cart, f'[initial_state.oem]\npath = "{oem}"\nat = "start"')
    deck.write_text(text)
    return deck


@pytest.mark.parametrize(
    "args",
    [
        ["validate", "{fifo}"],
        ["propagate", "{fifo}"],
        ["run", "{fifo}"],
        ["import-namelist", "{fifo}", "-o", "x.toml"],
        ["validate", "{oem_deck}"],
        ["validate", "/dev/zero"],
    ],
    ids=lambda a: "-".join(a[:2]),
)
def test_a_deck_that_is_not_a_regular_file_is_refused_without_blocking(tmp_path, args):
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)
    sub = {"{fifo}": str(fifo), "{oem_deck}": str(_oem_deck(tmp_path, fifo))}
    res = fracas(*(sub.get(a, a) for a in args), cwd=tmp_path, timeout=120)
    assert res.returncode == 2, res.stderr
    line = _one_error_line(res.stderr)
    assert ("is a FIFO" in line or "is a character device" in line) and "expected" in line, line


def test_compare_oem_refuses_a_fifo(tmp_path):
    fifo = tmp_path / "x.oem"
    os.mkfifo(fifo)
    from fracas.errors import ResultsFileError
    from fracas.io.ccsds import read_oem

    with pytest.raises(ResultsFileError, match="is a FIFO, expected an OEM file"):
        read_oem(fifo)


def test_a_huge_deck_is_refused_after_reading_little_of_it(tmp_path):
    big = tmp_path / "big.toml"
    with open(big, "wb") as fh:
        fh.truncate(7 * 1024**3)  # sparse: 7 GB that take no disk
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    res = fracas("validate", str(big), cwd=tmp_path)
    assert res.returncode == 2
    assert "is 7516192768 bytes; a TOML deck file is at most" in _one_error_line(res.stderr)
    rss_kib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    assert max(rss_kib, before) < 600 * 1024  # the file was not read (the interpreter: ~100 MB)


def test_a_growing_file_is_read_only_to_the_limit(tmp_path):
    from fracas.errors import DeckError
    from fracas.io.inputs import read_bounded

    deck = tmp_path / "d.toml"
    deck.write_bytes(b"x" * 11)
    with pytest.raises(DeckError, match="is 11 bytes; a deck is at most 10 bytes"):
        read_bounded(deck, 10, DeckError, "a deck")
    assert read_bounded(deck, 11, DeckError, "a deck") == b"x" * 11


# ----------------------------------------------------------------------------- names
def test_a_file_name_that_is_not_utf8_is_refused_up_front(tmp_path):
    """Not at the end of the run, writing its provenance (the result lost): before any work."""
    deck = os.fsencode(tmp_path) + b"/good\xff.toml"
    shutil.copy(NAMELISTS / "leo_j2.toml", deck)
    for argv in (["propagate", deck], ["run", deck], ["propagate", str(NAMELISTS / "leo_j2.toml"), "-o", b"x\xff.h5"]):
        res = subprocess.run(
            [sys.executable, "-m", "fracas.cli", *argv], cwd=tmp_path, env=_env(), capture_output=True, timeout=300
        )
        assert res.returncode == 2, res.stderr
        line = _one_error_line(res.stderr.decode("utf-8"))
        assert "\\xff" in line and "the file name is not UTF-8 text" in line, line
    assert not (tmp_path / "out").exists()


def test_provenance_stores_a_name_that_is_not_utf8():
    from fracas.io.hdf5 import provenance

    prov = provenance("x = 1", os.fsdecode(b"/d/good\xff.toml"))
    assert prov["deck_path"] == "/d/good\\xff.toml"
    prov["deck_path"].encode("utf-8")


def test_messages_are_one_line_whatever_the_file_name(tmp_path):
    deck = tmp_path / "bad\nname.toml"
    deck.write_text("junk = \n")
    for argv in (["validate", str(deck)], ["propagate", str(deck)]):
        res = CliRunner().invoke(main, argv)
        assert res.exit_code == 2
        _one_error_line(res.output)
    good = tmp_path / "ok\nname.toml"
    shutil.copy(NAMELISTS / "leo_j2.toml", good)
    res = CliRunner().invoke(main, ["validate", str(good)])
    assert res.exit_code == 0 and res.output.count("\n") == 1 and "ok\\nname.toml" in res.output


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        ("newdir/", "newdir/: trajectory file is a directory, expected a file name inside it"),
        ("{dir}", "{dir}: trajectory file is a directory, expected a file name inside it"),
        ("", "trajectory file: output path '' is not a file name, expected e.g. out/out.h5"),
    ],
)
def test_output_paths_click_used_to_mangle(tmp_path, monkeypatch, value, expected):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "adir").mkdir()
    value = value.replace("{dir}", "adir")
    res = CliRunner().invoke(main, ["propagate", str(NAMELISTS / "leo_j2.toml"), "-o", value])
    assert res.exit_code == 2
    assert _one_error_line(res.output) == "fracas: error: " + expected.replace("{dir}", "adir")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir"]  # no file named newdir


# ----------------------------------------------------------------------------- the sweep table
def _table(path: Path) -> None:
    from fracas.io.sweep_table import write_sweep_table

    rows = [
        {"index": i, "key": f"{i:016x}", "x": float(i), "y": 2.0 * i, "status": "ok", "error": "", "wall_s": 1.0}
        for i in range(2)
    ]
    attrs = {"title": "t", "base_hash": "ab" * 32, "study": "s", "combine": "grid"}
    write_sweep_table(path, rows, ["x"], ["y"], {"x": "km", "y": "km"}, attrs)


@pytest.mark.parametrize("damage", ["zeroed_block", "doubled_values", "unsealed_doubled", "bad_status"])
def test_report_reads_a_sweep_table_through_the_checked_reader(tmp_path, damage):
    from fracas.io.hdf5_integrity import USERBLOCK_SIZE, seal

    table = tmp_path / "t.h5"
    _table(table)
    res = CliRunner().invoke(main, ["report", str(table)])
    assert res.exit_code == 0 and "2 ok, 0 failed" in res.output
    if damage == "zeroed_block":
        b = bytearray(table.read_bytes())
        b[4096:8192] = bytes(4096)
        table.write_bytes(bytes(b))
    else:
        with h5py.File(table, "r+") as f:
            if damage == "bad_status":
                del f["status"]
                f.create_dataset("status", data=["ok", "?"], dtype=h5py.string_dtype())
            else:
                f["outputs/y"][...] = f["outputs/y"][()] * 2
        if damage == "unsealed_doubled":
            b = bytearray(table.read_bytes())
            b[:USERBLOCK_SIZE] = bytes(USERBLOCK_SIZE)  # no integrity header: the datasets' checksums decide
            table.write_bytes(bytes(b))
        else:
            seal(table, "fracas sweep table")  # a consistent header over changed data
    res = CliRunner().invoke(main, ["report", str(table)])
    assert res.exit_code == 2, res.output
    line = _one_error_line(res.output)
    assert str(table) in line


# ----------------------------------------------------------------------------- interrupts
def test_an_interrupt_python_could_not_raise_still_ends_the_command(capsys):
    """A KeyboardInterrupt inside a ``__del__`` (h5py's close) is "Exception ignored": the
    command still ends with one line and exit 130."""
    import gc

    from fracas.cli.console import _errors

    class Closing:
        def __del__(self):
            raise KeyboardInterrupt

    with pytest.raises(SystemExit) as info:
        with _errors(False):
            Closing()
            gc.collect()
    assert info.value.code == 130
    assert capsys.readouterr().err == "fracas: interrupted\n"


def test_a_second_interrupt_does_not_cut_the_clean_up_short(capsys):
    from fracas.cli.console import _errors

    cleaned = []
    with pytest.raises(SystemExit) as info:
        with _errors(False):
            try:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(5)
            finally:
                os.kill(os.getpid(), signal.SIGINT)  # during the clean-up: remembered, not raised
                time.sleep(0.05)
                cleaned.append(True)
    assert info.value.code == 130 and cleaned == [True]
    assert capsys.readouterr().err == "fracas: interrupted\n"


def _interrupted_after(argv: list[str], delay: float, cwd: Path, group: bool = True) -> subprocess.CompletedProcess:
    proc = subprocess.Popen(
        [sys.executable, "-m", "fracas.cli", *argv],
        cwd=cwd,
        env=_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    time.sleep(delay)
    if proc.poll() is None:
        if group:  # Ctrl-C: the whole foreground process group (Dask's workers too)
            os.killpg(proc.pid, signal.SIGINT)
        else:
            proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=300)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


@pytest.mark.parametrize("delay", [0.3, 1.5, 3.0, 6.0])
def test_an_interrupt_is_one_line_and_exit_130(tmp_path, delay):
    res = _interrupted_after(["propagate", str(NAMELISTS / "leo_j2.toml"), "-o", "x.h5"], delay, tmp_path)
    if res.returncode == 0:  # finished before the signal
        return
    assert res.returncode == 130, res.stderr
    assert res.stderr.splitlines()[-1:] == ["fracas: interrupted"], res.stderr
    assert [ln for ln in res.stderr.splitlines() if ln.strip() and "fracas: interrupted" not in ln] == []
    assert [p.name for p in tmp_path.iterdir() if p.name != "x.h5"] == []  # no temporary left


@pytest.mark.slow
@pytest.mark.parametrize("delay", [4.0, 10.0, 20.0])
def test_ctrl_c_during_a_sweep_on_dask_workers(tmp_path, delay):
    res = _interrupted_after(
        ["sweep", str(NAMELISTS / "earth_mars_sweep.toml"), "--workers", "2", "-o", "s.h5"], delay, tmp_path
    )
    if res.returncode in (0, 3):
        return
    assert res.returncode == 130, res.stderr
    assert [ln for ln in res.stderr.splitlines() if ln.strip()] == ["fracas: interrupted"], res.stderr


@pytest.mark.parametrize(
    ("name", "why"),
    [("x" * 5000 + ".h5", "File name too long"), ("a\0b.h5", "a NUL character in the name")],
)
def test_output_paths_no_file_system_takes_are_one_line_errors(tmp_path, name, why):
    """A name stat() itself refuses (longer than NAME_MAX) or cannot even pass to the OS (NUL)
    is an OutputPathError naming why, not an OSError or ValueError from deep in pathlib
    (found by tests/config/test_fuzz_decks.py through validate's output checks)."""
    from fracas.errors import OutputPathError
    from fracas.io.atomic import check_output_path

    with pytest.raises(OutputPathError) as exc:
        check_output_path(str(tmp_path / name), "results file")
    text = str(exc.value)
    assert "\n" not in text and "results file is not a usable path" in text and why in text
