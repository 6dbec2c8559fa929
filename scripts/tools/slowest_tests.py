"""The slowest tests of a pytest run, as a Markdown table (docs/testing.md).

Reads the output of ``pytest --durations=N`` (``N = 0``: every phase of every test; the lines
``12.34s call     tests/test_x.py::test_y``) or a JUnit XML report (``pytest
--junitxml=report.xml``), adds each test's setup, call and teardown, and prints the ``--top``
slowest as a table with their share of the run's total, and the total. What the run left out
(``--durations`` hides phases under 0.005 s unless ``-vv``) is left out here too.

Usage::

    pytest -q -m slow --durations=0 | tee slow.txt
    python scripts/tools/slowest_tests.py slow.txt [--top 10] [--machine "2-core CPU, busy"]
    python scripts/tools/slowest_tests.py report.xml

Exit status 0; 2 with one line on standard error for a file that cannot be read or that holds
no test durations.
"""

from __future__ import annotations

import argparse
import re
import sys
import xml.etree.ElementTree as ElementTree
from collections import defaultdict
from pathlib import Path

DURATION_LINE = re.compile(r"^\s*(\d+(?:\.\d+)?)s\s+(setup|call|teardown)\s+(\S.*?)\s*$")
"""One line of pytest's ``--durations`` report: seconds, phase, test id."""


class DurationsError(Exception):
    """A report that cannot be read, or that holds no durations."""


def durations_from_text(text: str) -> dict[str, float]:
    """Seconds per test id (setup + call + teardown) from ``--durations`` output."""
    totals: dict[str, float] = defaultdict(float)
    for line in text.splitlines():
        match = DURATION_LINE.match(line)
        if match:
            totals[match.group(3)] += float(match.group(1))
    return dict(totals)


def durations_from_junit(text: str) -> dict[str, float]:
    """Seconds per test id from a JUnit XML report (``classname`` ``tests.test_x`` and
    ``name`` ``test_y[p]`` become ``tests/test_x.py::test_y[p]``; a class's tests keep it:
    ``tests/test_x.py::TestZ::test_y``)."""
    try:
        root = ElementTree.fromstring(text)
    except ElementTree.ParseError as error:
        raise DurationsError(f"not a JUnit XML report ({error})") from error
    totals: dict[str, float] = defaultdict(float)
    for case in root.iter("testcase"):
        parts = case.get("classname", "").split(".")
        module = next((i for i in range(len(parts), 0, -1) if parts[i - 1].startswith("test")), 0)
        path = "/".join(parts[:module]) + ".py" if module else ""
        test_id = "::".join(p for p in (path, *parts[module:], case.get("name", "")) if p)
        totals[test_id] += float(case.get("time", "0") or 0.0)
    return dict(totals)


def read_durations(path: Path) -> dict[str, float]:
    """Seconds per test id from a ``--durations`` output or a JUnit XML report.

    Raises:
        DurationsError: The file cannot be read, or holds no durations.
    """
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as error:
        raise DurationsError(f"{path}: cannot be read ({error.strerror})") from error
    if text.lstrip().startswith("<"):
        totals = durations_from_junit(text)
    else:
        totals = durations_from_text(text)
    if not totals:
        raise DurationsError(
            f"{path}: no test durations (run pytest with --durations=0 or --junitxml=FILE)"
        )
    return totals


def _minutes(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 60 else f"{seconds:.0f} s ({seconds / 60:.1f} min)"


def markdown_table(totals: dict[str, float], *, top: int = 10) -> str:
    """The ``top`` slowest tests as a Markdown table, with their share of the total and the
    total of every test in ``totals``."""
    ranked = sorted(totals.items(), key=lambda item: (-item[1], item[0]))[:top]
    total = sum(totals.values())
    rows = ["| # | test | time | share of the run |", "|---|---|---|---|"]
    for rank, (test_id, seconds) in enumerate(ranked, start=1):
        share = seconds / total if total > 0 else 0.0
        rows.append(f"| {rank} | `{test_id}` | {_minutes(seconds)} | {share:.0%} |")
    shown = sum(seconds for _, seconds in ranked)
    rows.append("")
    rows.append(
        f"{len(totals)} tests took {_minutes(total)} together; these {len(ranked)} took "
        f"{_minutes(shown)}."
    )
    return "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Print the table of the report named on the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("report", type=Path, help="pytest --durations output or JUnit XML")
    parser.add_argument("--top", type=int, default=10, help="rows of the table (default 10)")
    parser.add_argument("--machine", default=None, help="a line under the table: where it ran")
    arguments = parser.parse_args(argv)
    if arguments.top < 1:
        print(f"slowest_tests: --top must be 1 or more (got {arguments.top})", file=sys.stderr)
        return 2
    try:
        totals = read_durations(arguments.report)
    except DurationsError as error:
        print(f"slowest_tests: {error}", file=sys.stderr)
        return 2
    print(markdown_table(totals, top=arguments.top), end="")
    if arguments.machine:
        print(f"\nMeasured on: {arguments.machine}.")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
