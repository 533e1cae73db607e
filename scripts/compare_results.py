"""Regression check of the example studies: run them, then compare two sets of files.

    python scripts/compare_results.py run OUTDIR          # every bundled deck -> OUTDIR/*.h5
    python scripts/compare_results.py compare OLD NEW     # dataset by dataset, 1e-12 relative
    python scripts/compare_results.py compare OLD NEW --exact   # bit for bit

``run`` drives the command line on every deck in namelists/ (each in the mode it names: the
propagations, TEAM studies, the sweep, the TOM decks with the reference decks they write,
the TSIM decks in this process, the rendezvous), the Mercury study through its STM file, and
the small test study in PHI and PDOT form; ``compare``
walks every HDF5 file present in OLD, and reports for each numeric dataset the largest
difference relative to the dataset's largest magnitude (NaNs must sit in the same places),
every string dataset or attribute that differs, and datasets the new files lack (new
datasets and attributes are counted, and listed with -v, but are not differences).
``--exact`` asks for the same dtype, shape and bytes in every dataset and attribute, and the
same text in every written deck (``*.toml``) and table (``*.csv``) beside them.
Provenance (times, versions, host) and wall-clock timings (``timing*``, ``wall_s``) are
skipped: they are meant to differ.  Exit 1 if anything
differs by more than ``--rtol`` (default 1e-12: "identical, or within 1e-12 relative where
the order of arithmetic had to change").
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from benchmarks.runs import failure  # noqa: E402  (one shared run-status check)

ROOT_FILE = "tree_root.txt"
TMP_NAME = re.compile(r"/tmp[a-z0-9_]{8}/")
SKIP = re.compile(r"(^|/)provenance(/|$)")
#: wall-clock measurements (seconds a stage took, missions per second): they differ between two
#: runs of the same code, so they are not compared
TIMING = re.compile(r"(^|[/@])(timing|wall_s|missions_per_s)|^wall_s$")
VERBOSE = "-v" in sys.argv


def _fracas(*args: str) -> None:
    cmd = [sys.executable, "-m", "fracas.cli", *args]
    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"failed ({r.returncode}): {' '.join(args)}\n{r.stderr}")
    print(r.stdout.strip().splitlines()[-1] if r.stdout.strip() else " ".join(args))


def _mode(deck: Path) -> str:
    m = re.search(r'(?m)^mode\s*=\s*"(\w+)"', deck.read_text(encoding="utf-8"))
    return m.group(1) if m else "propagate"


def run(out: Path) -> None:
    out = out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    (out / ROOT_FILE).write_text(str(ROOT), encoding="utf-8")  # paths under it compare as <root>
    for path in sorted((ROOT / "namelists").glob("*.toml")):
        deck, mode = path.stem, _mode(path)
        rel = f"namelists/{path.name}"
        if mode == "propagate":
            _fracas("propagate", rel, "-o", str(out / f"{deck}.h5"), "--json")
        elif mode == "sweep":
            _fracas("sweep", rel, "--workers", "0", "--no-resume", "-o", str(out / f"{deck}.h5"))
        elif mode == "tsim":
            _fracas("run", rel, "--workers", "0", "-o", str(out / f"{deck}.h5"), "--quiet")
        elif mode == "tom":
            ref = out / f"{deck}_reference.toml"
            _fracas("run", rel, "-o", str(out / f"{deck}.h5"), "--reference-deck", str(ref), "--quiet")
        else:
            _fracas("run", rel, "-o", str(out / f"{deck}.h5"), "--quiet")
    _fracas("stm", "build", "namelists/mercury_approach_team.toml", "-o", str(out / "mercury_approach_stm.h5"))
    _fracas(
        "run",
        "namelists/mercury_approach_team.toml",
        "--stm",
        str(out / "mercury_approach_stm.h5"),
        "-o",
        str(out / "mercury_approach_team_stm.h5"),
        "--quiet",
    )
    _fracas("run", "tests/data/team_small.toml", "-o", str(out / "team_small.h5"), "--quiet")
    # the same small study with PDOT time updates (a deck variant beside the original)
    src = (ROOT / "tests/data/team_small.toml").read_text(encoding="utf-8")
    with tempfile.TemporaryDirectory(dir=ROOT / "tests/data") as tmp:
        deck = Path(tmp) / "compare" / "team_small_pdot.toml"  # the same name in every run
        deck.parent.mkdir()
        text = src.replace('deck = "team_small_traj.toml"', f'deck = "{ROOT / "tests/data/team_small_traj.toml"}"')
        text = re.sub(r"(?m)^\[punch\][^\[]*", "", text)
        deck.write_text(text + '\n[errcon]\npropagation = "pdot"\n', encoding="utf-8")
        _fracas("run", str(deck), "-o", str(out / "team_small_pdot.h5"), "--quiet")


def _items(f: h5py.File) -> dict[str, object]:
    out: dict[str, object] = {}

    def visit(name: str, obj) -> None:
        if SKIP.search(name):
            return
        for k, v in obj.attrs.items():
            out[f"{name}@{k}"] = v
        if isinstance(obj, h5py.Dataset):
            out[name] = obj[()]

    for k, v in f.attrs.items():
        out[f"@{k}"] = v
    f.visititems(visit)
    return out


def _normal(text: str, folder: Path) -> str:
    """``text`` with the run's own output folder written as <out>, the tree it ran in as <root>
    and a temporary folder's random name as <tmp> (paths the files record)."""
    text = text.replace(str(folder.resolve()), "<out>")
    root = folder / ROOT_FILE
    if root.is_file():
        text = text.replace(root.read_text(encoding="utf-8"), "<root>")
    return TMP_NAME.sub("/<tmp>/", text)


def _text(v, folder: Path) -> np.ndarray:
    """String values with the run's folders normalised (:func:`_normal`)."""
    a = np.asarray(v)
    if a.dtype.kind in "OSU":
        f = np.vectorize(lambda x: _normal(x.decode() if isinstance(x, bytes) else str(x), folder), otypes=[object])
        return f(a) if a.size else a
    return a


def _numeric(v) -> np.ndarray | None:
    a = np.asarray(v)
    return a if a.dtype.kind in "fiub" else None


def _same_bits(x, y) -> bool:
    a, b = np.asarray(x), np.asarray(y)
    if a.dtype.kind in "OSU" or b.dtype.kind in "OSU":
        return a.shape == b.shape and bool(np.all(a == b))
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def run_failures(items: dict[str, object]) -> list[str]:
    """FAILED lines for a results file's own run status: every scalar dataset or attribute
    named ``status`` (a trajectory's, a TEAM run's) must be 0 or 1 (:mod:`fracas.status`); a
    file from a failed run is never "the same" as another (per-event or per-mission status
    arrays are outputs, compared like any other)."""
    out = []
    for k, v in items.items():
        if k.rsplit("@", 1)[-1].rsplit("/", 1)[-1] != "status":
            continue
        x = _numeric(v)
        if x is None or x.size != 1:
            continue
        f = failure(int(x.ravel()[0]))
        if f:
            out.append(f"{k}: {f}")
    return out


def compare_file(a: Path, b: Path, rtol: float, exact: bool = False) -> list[str]:
    with h5py.File(a, "r") as fa, h5py.File(b, "r") as fb:
        ia, ib = _items(fa), _items(fb)
    bad = [f"old {line}" for line in run_failures(ia)] + [f"new {line}" for line in run_failures(ib)]
    bad += [f"{k}: only in the old file" for k in sorted(set(ia) - set(ib))]
    added = sorted(set(ib) - set(ia))  # new datasets and attributes are reported, not failures
    worst = 0.0
    for k in sorted(set(ia) & set(ib)):
        if k.endswith(("@fracas_version", "@written_utc", "@created_utc")) or TIMING.search(k):
            continue
        x, y = _numeric(ia[k]), _numeric(ib[k])
        if exact and x is not None and y is not None:
            if not _same_bits(x, y):
                bad.append(f"{k}: not bit-identical ({x.dtype}{x.shape} vs {y.dtype}{y.shape})")
            continue
        if x is None or y is None:
            xa, xb = _text(ia[k], a.parent), _text(ib[k], b.parent)
            if not (xa.shape == xb.shape and np.all(xa == xb)):
                bad.append(f"{k}: {str(ia[k])[:60]!r} != {str(ib[k])[:60]!r}")
            continue
        if x.shape != y.shape:
            bad.append(f"{k}: shape {x.shape} != {y.shape}")
            continue
        x, y = x.astype(np.float64), y.astype(np.float64)
        if not np.array_equal(np.isnan(x), np.isnan(y)):
            bad.append(f"{k}: NaNs in different places")
            continue
        ok = ~np.isnan(x)
        if not ok.any():
            continue
        scale = max(float(np.max(np.abs(x[ok]))), 1e-300)
        d = float(np.max(np.abs(x[ok] - y[ok]))) / scale
        worst = max(worst, d)
        if d > rtol:
            bad.append(f"{k}: max |diff| / max |value| = {d:.3e} > {rtol:g}")
    print(
        f"{a.name:28s} {len(ia):4d} items (+{len(added)} new)  largest relative difference {worst:.2e}  "
        f"{'OK' if not bad else f'{len(bad)} DIFFER'}"
    )
    if added and VERBOSE:
        print("    new: " + ", ".join(added))
    return bad


def _without_timings(text: str) -> str:
    """A CSV table without its wall-clock columns (``wall_s``)."""
    import csv
    import io

    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        return text
    keep = [k for k, name in enumerate(rows[0]) if not TIMING.search(name)]
    return "\n".join(",".join(r[k] for k in keep if k < len(r)) for r in rows)


def compare_text(a: Path, b: Path) -> list[str]:
    """A written deck or table: the same text once each run's folders are normalised
    (:func:`_normal`) and a table's wall-clock columns are left out."""
    ta, tb = (_normal(p.read_text(encoding="utf-8"), p.parent) for p in (a, b))
    if a.suffix == ".csv":
        ta, tb = _without_timings(ta), _without_timings(tb)
    print(f"{a.name:28s} {len(ta.splitlines()):4d} lines  {'OK' if ta == tb else 'DIFFER'}")
    return [] if ta == tb else [f"{a.name}: text differs"]


def compare(old: Path, new: Path, rtol: float, exact: bool = False) -> int:
    files = sorted(old.glob("*.h5"))
    if not files:
        raise SystemExit(f"{old}: no .h5 files")
    texts = sorted([*old.glob("*.toml"), *old.glob("*.csv")]) if exact else []
    n_bad = 0
    for a in [*files, *texts]:
        b = new / a.name
        if not b.exists():
            print(f"{a.name}: missing in {new}")
            n_bad += 1
            continue
        lines = compare_file(a, b, rtol, exact) if a.suffix == ".h5" else compare_text(a, b)
        for line in lines:
            print("    " + line)
            n_bad += 1
    what = "bit-identical" if exact else f"within rtol {rtol:g}"
    print(
        f"{len(files)} results files, {len(texts)} decks and tables:",
        what if n_bad == 0 else f"DIFFERENCES ({what} asked)",
    )
    return 1 if n_bad else 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("out", type=Path)
    c = sub.add_parser("compare")
    c.add_argument("old", type=Path)
    c.add_argument("new", type=Path)
    c.add_argument("--rtol", type=float, default=1e-12)
    c.add_argument("--exact", action="store_true", help="bit for bit: same dtype, shape and bytes everywhere")
    c.add_argument("-v", action="store_true", help="list the datasets and attributes only the new files have")
    a = ap.parse_args()
    if a.cmd == "run":
        run(a.out)
    else:
        sys.exit(compare(a.old, a.new, a.rtol, a.exact))


if __name__ == "__main__":
    main()
