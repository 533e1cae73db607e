"""Command-line timings in cold processes: this checkout against a baseline git ref.

Each command runs as a fresh ``python -m fracas.cli ...`` process (what ``fracas ...`` does,
less the console-script shim) with the tree under test as working directory and PYTHONPATH, so
the checkout's own ``fracas`` is imported, not the editable install.  The baseline ref is
checked out with ``git worktree add`` into a temporary directory and run with the same
interpreter; current and baseline runs are interleaved (alternating which goes first) so that
both see the same machine noise.  Every command runs once per tree before timing, so the
persistent JAX compilation cache is warm for both.  Prints the median of N runs.

    .venv/bin/python benchmarks/bench_cli.py --quick                  # N=3, baseline 50a1e8b
    .venv/bin/python benchmarks/bench_cli.py --baseline main --repeat 7
    .venv/bin/python benchmarks/bench_cli.py --no-baseline
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_BASELINE = "50a1e8b"  # the last commit before the restructuring ("One house for three modes")
HELP_LIMIT_S = 0.3

# (label, arguments of `fracas`); {out} is a per-tree temporary directory.
COMMANDS = [
    ("--help", ["--help"]),
    ("--version", ["--version"]),
    ("propagate leo_j2.toml --json", ["propagate", "namelists/leo_j2.toml", "-o", "{out}/x.h5", "--json"]),
    ("run earth_mars_team.toml --quiet", ["run", "namelists/earth_mars_team.toml", "-o", "{out}/y.h5", "--quiet"]),
    (
        "stm build mercury_approach_team.toml",
        ["stm", "build", "namelists/mercury_approach_team.toml", "-o", "{out}/m.h5"],
    ),
    (
        "run mercury_approach_team.toml --stm --quiet",
        ["run", "namelists/mercury_approach_team.toml", "--stm", "{out}/m.h5", "-o", "{out}/z.h5", "--quiet"],
    ),
]


def git(*args: str, cwd: Path = ROOT) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True, text=True).stdout.strip()


class Tree:
    def __init__(self, name: str, path: Path):
        self.name, self.path = name, path
        self.out = Path(tempfile.mkdtemp(prefix=f"bench_cli_{name}_"))
        self.env = dict(os.environ, PYTHONPATH=str(path))

    def argv(self, args: list[str]) -> list[str]:
        if args is None:  # the interpreter floor
            return [sys.executable, "-c", "pass"]
        return [sys.executable, "-m", "fracas.cli", *(a.format(out=self.out) for a in args)]

    def run(self, args) -> tuple[float, subprocess.CompletedProcess]:
        t0 = time.perf_counter()
        proc = subprocess.run(self.argv(args), cwd=self.path, env=self.env, capture_output=True, text=True)
        return time.perf_counter() - t0, proc

    def check_shadowing(self) -> None:
        proc = subprocess.run(
            [sys.executable, "-c", "import fracas; print(fracas.__file__)"],
            cwd=self.path,
            env=self.env,
            capture_output=True,
            text=True,
            check=True,
        )
        got = Path(proc.stdout.strip()).resolve()
        want = (self.path / "fracas" / "__init__.py").resolve()
        if got != want:
            sys.exit(f"{self.name}: imports {got}, not {want}")


def header(current: str, baseline: str | None, n: int) -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    lines = [
        f"# fracas command-line timings, {datetime.datetime.now().isoformat(timespec='seconds')}",
        f"# machine: {platform.node()}, {cpu}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}",
        f"# python {platform.python_version()} ({sys.executable})",
        f"# current: {current}",
        f"# baseline: {baseline or '(none)'}",
        f"# median of {n} cold processes `python -m fracas.cli ...`, current and baseline interleaved;",
        "# each command ran once per tree first, so the persistent JAX cache is warm for both.",
    ]
    return "\n".join(lines)


def describe_current() -> str:
    head = git("rev-parse", "--short", "HEAD")
    dirty = git("status", "--porcelain", "--untracked-files=no")
    return f"{ROOT} at {head}" + (" + uncommitted changes" if dirty else "")


# C901 on purpose: its argument parsing and one table row per command, read top to bottom
def main() -> None:  # noqa: C901
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="3 runs per command instead of 5")
    ap.add_argument("--repeat", type=int, default=None, help="runs per command (default 5, 3 with --quick)")
    ap.add_argument(
        "--baseline", default=DEFAULT_BASELINE, help=f"git ref to compare with (default {DEFAULT_BASELINE})"
    )
    ap.add_argument("--no-baseline", action="store_true", help="time this checkout only")
    opts = ap.parse_args()
    n = opts.repeat or (3 if opts.quick else 5)

    trees = [Tree("current", ROOT)]
    base_dir = None
    baseline_desc = None
    if not opts.no_baseline:
        commit = git("rev-parse", "--verify", f"{opts.baseline}^{{commit}}")
        base_dir = Path(tempfile.mkdtemp(prefix="bench_cli_baseline_")) / "tree"
        git("worktree", "add", "--detach", str(base_dir), commit)
        baseline_desc = f"{opts.baseline} = {commit[:10]} (git worktree in {base_dir})"
        trees.append(Tree("baseline", base_dir))
    try:
        for tree in trees:
            tree.check_shadowing()
        print(header(describe_current(), baseline_desc, n), flush=True)
        rows = [("python -c pass (interpreter floor)", None)] + [(f"fracas {label}", args) for label, args in COMMANDS]
        times: dict[tuple[str, str], list[float]] = {}
        failed: dict[tuple[str, str], str] = {}
        print("  warm-up", file=sys.stderr, flush=True)
        for tree in trees:  # warm-up: JAX cache, pyc files, page cache
            for label, args in rows:
                _, proc = tree.run(args)
                if proc.returncode:
                    failed[(tree.name, label)] = (proc.stderr or proc.stdout).strip().splitlines()[-1:]
        for i in range(n):
            print(f"  round {i + 1}/{n}", file=sys.stderr, flush=True)
            order = trees if i % 2 == 0 else trees[::-1]
            for label, args in rows:
                for tree in order:
                    if (tree.name, label) in failed:
                        continue
                    dt, proc = tree.run(args)
                    if proc.returncode:
                        failed[(tree.name, label)] = (proc.stderr or proc.stdout).strip().splitlines()[-1:]
                    times.setdefault((tree.name, label), []).append(dt)

        def cell(tree: str, label: str) -> float | None:
            if (tree, label) in failed or (tree, label) not in times:
                return None
            return statistics.median(times[(tree, label)])

        print()
        print(f"{'command':<51} {'current s':>9} {'baseline s':>10} {'ratio':>6}")
        print("-" * 79)
        for label, _ in rows:
            cur, base = cell("current", label), cell("baseline", label)
            c = f"{cur:9.3f}" if cur is not None else f"{'fail':>9}"
            b = f"{base:10.3f}" if base is not None else f"{('fail' if base_dir else '-'):>10}"
            r = f"{cur / base:6.2f}" if cur is not None and base else f"{'-':>6}"
            print(f"{label[:51]:<51} {c} {b} {r}")
        print("-" * 79)
        help_s = cell("current", "fracas --help")
        if help_s is not None:
            verdict = "ok" if help_s < HELP_LIMIT_S else "OVER THE LIMIT"
            print(f"fracas --help: {help_s:.3f} s, limit {HELP_LIMIT_S} s: {verdict}")
        for (tree, label), msg in sorted(failed.items()):
            print(f"FAILED ({tree}) {label}: {' '.join(msg)}")
    finally:
        for tree in trees:
            shutil.rmtree(tree.out, ignore_errors=True)
        if base_dir is not None:
            subprocess.run(["git", "worktree", "remove", "--force", str(base_dir)], cwd=ROOT, capture_output=True)
            shutil.rmtree(base_dir.parent, ignore_errors=True)


if __name__ == "__main__":
    main()
