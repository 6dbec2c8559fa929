"""Run a script of ``scripts/`` as a user would, for the tests of the examples and benchmarks."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
"""The repository root."""


def run_script(path: str, *args: str, cwd: Path, expect_status: int = 0) -> str:
    """Run ``python ROOT/path args...`` in ``cwd``; return its stdout.

    Fails the test, with the end of the script's standard error, when the exit status is not
    ``expect_status``; with ``expect_status`` other than 0 it returns the standard error.
    """
    completed = subprocess.run(
        [sys.executable, str(ROOT / path), *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=900,
    )
    assert completed.returncode == expect_status, completed.stderr[-4000:]
    return completed.stdout if expect_status == 0 else completed.stderr
