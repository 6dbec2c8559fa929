"""Run a script of ``scripts/`` or a ``warptissue`` command as a user would, in a process of
its own: for the tests of the examples, the benchmarks and Ctrl-C."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
"""The repository root."""


def run_script(
    path: str, *args: str, cwd: Path, expect_status: int = 0, timeout_s: float = 900.0
) -> str:
    """Run ``python ROOT/path args...`` in ``cwd``; return its stdout.

    Fails the test, with the end of the script's standard error, when the exit status is not
    ``expect_status``; with ``expect_status`` other than 0 it returns the standard error.
    ``timeout_s``: a safety net against a hung script, not a speed assertion.
    """
    completed = subprocess.run(
        [sys.executable, str(ROOT / path), *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=timeout_s,
    )
    assert completed.returncode == expect_status, completed.stderr[-4000:]
    return completed.stdout if expect_status == 0 else completed.stderr


@contextmanager
def cli_process(cwd: Path, *args: str) -> Iterator[subprocess.Popen]:
    """``warptissue ARGS`` in a process group of its own, with Ctrl-C's default handling (a
    shell's background job would ignore SIGINT), stdout and stderr piped as text. It runs in
    ``cwd``, outside the checkout: from the checkout's root, Python would import its
    ``warptissue/`` (which has no ``kernels/``) instead of the installed package. The group is
    killed on leaving if the command still runs."""
    process = subprocess.Popen(
        [sys.executable, "-m", "warptissue.cli", *args],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        yield process
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.communicate()


def ctrl_c(process: subprocess.Popen, *, timeout_s: float) -> tuple[str, str]:
    """SIGINT to the process's whole group, as a terminal's Ctrl-C sends it; its stdout and
    stderr once it has ended (``subprocess.TimeoutExpired`` after ``timeout_s``)."""
    os.killpg(process.pid, signal.SIGINT)
    return process.communicate(timeout=timeout_s)
