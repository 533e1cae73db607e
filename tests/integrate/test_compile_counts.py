"""How often one run compiles each program (JAX's compile log), issue 33 item 2.

The main job (``namelists/earth_mars_guidance.toml``) used to compile ``_propagate_var`` for 2,
3, 512, 1024 and 2048 output times and ``_jacobians_at`` for 512, 1024 and 2048 nodes (five and
three compilations of 6-14 s each).  Output and node counts are now padded to
``propagate.OUTPUT_BUCKETS`` (64, 4096, then powers of two): the run compiles
``_propagate_var`` once per distinct program (two label sets, the STM file's and the
guidance spans') and bucket, at most 3, and ``_jacobians_at`` once.  Upper bounds: in a
process that already compiled the programs the counts are lower, never higher.
"""

from __future__ import annotations

import collections
import logging
import re
from pathlib import Path

import jax
import pytest
from click.testing import CliRunner

from fracas.cli import main

ROOT = Path(__file__).resolve().parents[2]
LIMITS = {"_propagate_var": 3, "_jacobians_at": 1, "_propagate": 2, "_propagate_sens": 2}


class _Counter(logging.Handler):
    def __init__(self) -> None:
        super().__init__()
        self.counts: collections.Counter[str] = collections.Counter()

    def emit(self, record: logging.LogRecord) -> None:
        m = re.match(r"Compiling \w+\((\w+)\)", record.getMessage())
        if m:
            self.counts[m.group(1)] += 1


@pytest.mark.slow
def test_main_job_compiles_each_program_once_per_shape(tmp_path):
    counter = _Counter()
    log = logging.getLogger("jax")
    saved = (log.level, bool(jax.config.jax_log_compiles))
    log.addHandler(counter)
    log.setLevel(logging.WARNING)
    jax.config.update("jax_log_compiles", True)
    try:
        out = tmp_path / "emg.h5"
        res = CliRunner().invoke(
            main, ["run", str(ROOT / "namelists/earth_mars_guidance.toml"), "-o", str(out), "--quiet"]
        )
    finally:
        log.removeHandler(counter)
        log.setLevel(saved[0])
        jax.config.update("jax_log_compiles", saved[1])
    assert res.exit_code == 0, res.output
    over = {k: v for k, v in counter.counts.items() if k in LIMITS and v > LIMITS[k]}
    assert not over, f"compiled more often than its shapes need: {over} (all: {dict(counter.counts)})"
