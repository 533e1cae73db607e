"""The compile budget's table: each main compiled program's HLO instruction count and lowering time.

    python scripts/hlo_sizes.py                    # table: program, deck, instructions, budget, lowering s
    python scripts/hlo_sizes.py --update           # ... and the BUDGET dict to paste (measured + 10 %)
    python scripts/hlo_sizes.py stm_ad team_filter # only these programs
    python scripts/hlo_sizes.py --dump DIR         # also write each program's HLO text to DIR/<name>.hlo
    python scripts/hlo_sizes.py -v                 # also the jitted function lowered for each program

The programs, the decks they are built from and the counting rule are in
fracas/build/compile_budget.py; tests/test_compile_budget.py holds the counts to its BUDGET.
Lowering only (no XLA compilation): about 20 s for all of them on two cores.  Exit status 1
when a program is over its budget or fails to lower (each failure is reported, after the table).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax

from fracas.build import compile_budget as cb


def update_text(measured: list[cb.Measurement]) -> str:
    """The BUDGET dict for fracas/build/compile_budget.py: each count plus the headroom."""
    import jaxlib

    commit = _commit()
    versions = f"jax {jax.__version__} (jaxlib {jaxlib.__version__}, x64)"
    where = f"at commit {commit}, " if commit else ""
    lines = [
        f"# HLO instructions per program: the count measured on {versions}",
        f"# {where}plus ~{cb.HEADROOM * 100:g} % headroom (budget_for: count * {1 + cb.HEADROOM:g} rounded up to a"
        " multiple of 10).",
        "# Re-measure and print a new dict with `python scripts/hlo_sizes.py --update`.",
        "BUDGET = {",
    ]
    if [m.name for m in measured] != list(cb.PROGRAM_NAMES):
        lines.insert(-1, "# (only the programs measured here: paste their entries)")
    lines += [f'    "{m.name}": {cb.budget_for(m.instructions)},  # measured {m.instructions}' for m in measured]
    lines.append("}")
    lines.append("#: The jax version the budgets were measured with (the test skips on another major.minor).")
    lines.append(f'JAX_VERSION_MEASURED = "{jax.__version__}"')
    return "\n".join(lines)


def _commit() -> str:
    """The checkout's short commit ("" outside git), with " + local changes" when tracked files differ."""
    import subprocess

    root = Path(__file__).resolve().parents[1]
    try:
        r = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True)
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"], cwd=root, capture_output=True, text=True
        )
    except OSError:
        return ""
    if r.returncode != 0:
        return ""
    return r.stdout.strip() + (" + local changes" if dirty.stdout.strip() else "")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("programs", nargs="*", help=f"programs to measure (default all: {', '.join(cb.PROGRAM_NAMES)})")
    ap.add_argument("--update", action="store_true", help="print the BUDGET dict to paste (measured + headroom)")
    ap.add_argument("--dump", metavar="DIR", help="write each program's HLO text to DIR/<name>.hlo")
    ap.add_argument("--decks", metavar="DIR", help="the folder of bundled decks (default the repository's namelists/)")
    ap.add_argument("-v", "--verbose", action="store_true", help="also show the jitted function lowered")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    programs = cb.build_programs(args.decks)
    names = args.programs or list(programs)
    unknown = [n for n in names if n not in programs]
    if unknown:
        ap.error(f"unknown program(s) {', '.join(unknown)}; known: {', '.join(programs)}")
    measured, failed = [], []
    for name in names:
        try:
            measured.append(cb.measure_program(programs[name], keep_text=bool(args.dump)))
        except Exception as exc:  # noqa: BLE001 - report every program, then fail
            failed.append((programs[name], exc))
    total = time.perf_counter() - t0

    head = ("program", "deck", "HLO instructions", "budget", "lowering s")
    rows = [
        (
            m.name,
            m.deck,
            str(m.instructions),
            "-" if m.budget is None else str(m.budget) + ("" if m.within_budget else " OVER"),
            f"{m.lowering_s:.2f}",
        )
        for m in measured
    ]
    if args.verbose:
        head += ("jitted function",)
        rows = [r + (m.entry,) for r, m in zip(rows, measured)]
    width = [max(len(r[i]) for r in [head, *rows]) for i in range(len(head))]
    right = {2, 3, 4}

    def fmt(r):
        return "  ".join(c.rjust(w) if i in right else c.ljust(w) for i, (c, w) in enumerate(zip(r, width))).rstrip()

    print(fmt(head))
    print("  ".join("-" * w for w in width))
    for r in rows:
        print(fmt(r))
    note = "" if cb.jax_version_matches() else f"; budgets measured on jax {cb.JAX_VERSION_MEASURED}: not comparable"
    print(f"\njax {jax.__version__}{note}; {total:.1f} s (building the decks and lowering)")

    if args.dump:
        out = Path(args.dump)
        out.mkdir(parents=True, exist_ok=True)
        for m in measured:
            (out / f"{m.name}.hlo").write_text(m.hlo_text)
        print(f"HLO texts written to {out}/")
    for prog, exc in failed:
        print(f"FAILED {prog.name} ({prog.entry} on {prog.deck}): {type(exc).__name__}: {exc}", file=sys.stderr)
    if args.update:
        if failed:
            print("\nno BUDGET dict: some programs failed to lower", file=sys.stderr)
        else:
            print("\n" + update_text(measured))
    over = [m.name for m in measured if m.budget is not None and not m.within_budget]
    return 1 if failed or (over and cb.jax_version_matches()) else 0


if __name__ == "__main__":
    sys.exit(main())
