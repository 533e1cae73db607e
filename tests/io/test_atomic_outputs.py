"""Atomic outputs (fracas.io.atomic): permissions as ``open()`` would give them under the
umask, recognisable temporary names, stale temporaries of killed runs removed (only ours),
a failed write leaving the previous file intact, and check_output_path's refusals.

References: the POSIX rule for a new file's mode (``0o666 & ~umask``, as ``open(path, "w")``
creates it, checked side by side); byte equality of the previous file after a failure.
"""

from __future__ import annotations

import os
import stat
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from fracas.errors import FracasError, OutputPathError
from fracas.io.atomic import (
    TEMP_PATTERN,
    atomic_path,
    check_output_path,
    file_mode,
    host_tag,
    remove_stale_temps,
    savefig_atomic,
)
from fracas.io.hdf5 import atomic_h5


def _mode(p: Path) -> int:
    return stat.S_IMODE(p.stat().st_mode)


def _figure():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [1, 0])
    return fig


@pytest.fixture
def umask():
    """Set the umask for one test (restored after)."""
    old = os.umask(0o022)
    os.umask(old)
    yield lambda m: os.umask(m)
    os.umask(old)


@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002, 0o027])
def test_permissions_follow_the_umask_like_open(tmp_path, umask, mask):
    umask(mask)
    plain = tmp_path / "plain.txt"
    plain.write_text("x")  # what open() gives: the reference
    assert file_mode() == _mode(plain) == 0o666 & ~mask
    with atomic_h5(tmp_path / "a.h5") as f:
        f["x"] = np.arange(3)
    fig = _figure()
    savefig_atomic(fig, tmp_path / "p.png", dpi=50)
    with atomic_path(tmp_path / "b.bin") as tmp:
        tmp.write_bytes(b"abc")
    for name in ("a.h5", "p.png", "b.bin"):
        assert _mode(tmp_path / name) == _mode(plain), name


def test_umask_read_in_a_fresh_process_is_left_unchanged(tmp_path):
    code = (
        "import os; os.umask(0o007); from fracas.io.atomic import file_mode, atomic_path\n"
        "m = file_mode()\n"
        "with atomic_path(os.path.join(os.environ['D'], 'x')) as t: t.write_bytes(b'1')\n"
        "old = os.umask(0); print(oct(m), oct(old))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=True,
        cwd=Path(__file__).resolve().parents[2],
        env={**os.environ, "D": str(tmp_path)},
    ).stdout.split()
    assert out == [oct(0o660), oct(0o007)]
    assert _mode(tmp_path / "x") == 0o660


def test_temp_name_is_recognisable_and_in_the_target_folder(tmp_path):
    with atomic_path(tmp_path / "sub" / "out.h5") as tmp:
        m = TEMP_PATTERN.match(tmp.name)
        assert tmp.parent == tmp_path / "sub" and tmp.exists()
        assert m and m.group("name") == "out.h5" and int(m.group("pid")) == os.getpid()
        assert m.group("host") == host_tag() and tmp.name.startswith(f".out.h5.{os.getpid()}-{host_tag()}.")
        assert not (tmp_path / "sub" / "out.h5").exists()  # invisible until complete
        tmp.write_bytes(b"done")
    assert (tmp_path / "sub" / "out.h5").read_bytes() == b"done"
    assert sorted(p.name for p in (tmp_path / "sub").iterdir()) == ["out.h5"]


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_stale_temps_removed_only_ours(tmp_path):
    dead, alive, host = _dead_pid(), os.getppid(), host_tag()
    other = "0123abcd" if host != "0123abcd" else "fedc9876"
    names = {
        "dead": f".out.h5.{dead}-{host}.abcd1234.tmp",  # process gone: removed
        "old": f".out.h5.{alive}-{host}.zzzz_999.tmp",  # alive pid but 2 h old (pid reuse): removed
        "fresh": f".out.h5.{alive}-{host}.qwer5678.tmp",  # a live write elsewhere: kept
        "mine": f".out.h5.{os.getpid()}-{host}.mine0000.tmp",  # this process, recent: kept
        "remote": f".out.h5.{dead}-{other}.rmte0000.tmp",  # another host's pid: judged by age only, kept
        "remote_old": f".out.h5.{dead}-{other}.rmte1111.tmp",  # ... removed when 2 h old
        "other_tmp": ".out.h5.tmp",  # not our pattern: kept
        "plain": "notes.tmp",
        "no_host": f".out.h5.{dead}.abcd1234.tmp",
        "upper": f".out.h5.{dead}-{host}.ABCD1234.tmp",  # tempfile never writes capitals: kept
    }
    for n in names.values():
        (tmp_path / n).write_text("x")
    two_h = time.time() - 7200
    os.utime(tmp_path / names["old"], (two_h, two_h))
    os.utime(tmp_path / names["remote_old"], (two_h, two_h))
    folder = f".dir.{dead}-{host}.abcdefgh.tmp"
    (tmp_path / folder).mkdir()  # a directory: never touched
    removed = {p.name for p in remove_stale_temps(tmp_path)}
    assert removed == {names["dead"], names["old"], names["remote_old"]}
    left = {p.name for p in tmp_path.iterdir()}
    assert left == (set(names.values()) - removed) | {folder}


def test_next_write_to_the_folder_removes_stale_temps(tmp_path):
    stale = tmp_path / f".x.h5.{_dead_pid()}-{host_tag()}.abcdefgh.tmp"
    stale.write_bytes(b"partial")
    with atomic_h5(tmp_path / "y.h5") as f:
        f["a"] = 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["y.h5"]


def test_failing_write_keeps_the_previous_file(tmp_path):
    path = tmp_path / "r.h5"
    with atomic_h5(path) as f:
        f["v"] = np.arange(4.0)
    before = path.read_bytes()
    with pytest.raises(RuntimeError, match="midway"):
        with atomic_h5(path) as f:
            f["v"] = np.zeros(1000)
            raise RuntimeError("midway")
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.h5"]
    with h5py.File(path, "r") as f:
        assert list(f["v"][()]) == [0.0, 1.0, 2.0, 3.0]


def test_failing_savefig_keeps_the_previous_png(tmp_path):
    png = tmp_path / "p.png"
    fig = _figure()
    savefig_atomic(fig, png, dpi=40)
    before = png.read_bytes()
    assert before.startswith(b"\x89PNG")
    with pytest.raises(ValueError):
        savefig_atomic(fig, png, format="no-such-format")
    assert png.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.png"]
    savefig_atomic(fig, tmp_path / "q.svg")  # format from the suffix, not ".tmp"
    assert (tmp_path / "q.svg").read_text().lstrip().startswith("<?xml")


# --------------------------------------------------------------------------- check_output_path


def _path_refused(path, *patterns) -> str:
    with pytest.raises(OutputPathError) as err:
        check_output_path(path, "results file")
    msg = str(err.value)
    assert "\n" not in msg and "results file" in msg, msg
    assert isinstance(err.value, FracasError) and err.value.exit_code == 2
    for p in patterns:
        assert p in msg, msg
    return msg


def test_check_output_path_accepts_and_creates_nothing(tmp_path):
    new = tmp_path / "a" / "b" / "r.h5"
    assert check_output_path(new, "results file") == new
    assert list(tmp_path.iterdir()) == []  # the folders are not created
    (tmp_path / "old.h5").write_bytes(b"x")
    assert check_output_path(str(tmp_path / "old.h5"), "results file") == tmp_path / "old.h5"


def test_check_output_path_refusals(tmp_path):
    _path_refused("", "not a file name")
    _path_refused(".", "not a file name")
    _path_refused(tmp_path, str(tmp_path), "is a directory")
    _path_refused(f"{tmp_path}/new/", "is a directory")
    (tmp_path / "f").write_text("x")
    _path_refused(tmp_path / "f" / "r.h5", "folder", "is a file")
    _path_refused(tmp_path / "f" / "deeper" / "r.h5", "is a file")
    os.mkfifo(tmp_path / "fifo")
    _path_refused(tmp_path / "fifo", "not a regular file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f", "fifo"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_check_output_path_unwritable_folder(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        _path_refused(ro / "r.h5", "is not writable")
        _path_refused(ro / "sub" / "r.h5", "cannot create folder")
    finally:
        ro.chmod(0o700)


def test_check_output_path_unwritable_folder_by_access(tmp_path, monkeypatch):
    """The same refusals whatever the user (root included): os.access says no."""
    ro = tmp_path / "ro"
    ro.mkdir()
    monkeypatch.setattr("fracas.io.atomic.os.access", lambda p, mode: Path(p) != ro)
    _path_refused(ro / "r.h5", f"folder {ro} is not writable")
    _path_refused(ro / "sub" / "r.h5", "cannot create folder", f"({ro} is not writable)")


def test_results_write_failure_is_one_line_and_keeps_the_previous_file(tmp_path, monkeypatch):
    from fracas.errors import ResultsFileError
    from fracas.io.team_results import write_punch, write_team_results
    from tests.io.test_corrupt_files import _team_product

    prod = _team_product()
    path = tmp_path / "r.h5"
    write_team_results(path, prod)
    before = path.read_bytes()

    def full(*_a, **_k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("fracas.io.team_results.write_provenance", full)
    with pytest.raises(ResultsFileError, match=r"r\.h5: cannot write the results file: No space left on device$"):
        write_team_results(path, prod)
    with pytest.raises(ResultsFileError, match=r"p\.h5: cannot write the punch file: No space left on device$"):
        write_punch(tmp_path / "p.h5", prod)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.h5"]
